"""Locate the package's installed config files (colcon, pip, or a source checkout)."""

from __future__ import annotations

import sys
from pathlib import Path

from clusterfilter_ros.errors import InputError

PACKAGE = "clusterfilter_ros"


def config_dir() -> Path:
    """The folder holding ``detector.yaml`` and ``fastdds_loopback.xml``.

    Looks, in order, in a source checkout next to this package, in the ament index
    (colcon install), and in ``<sys.prefix>/share/clusterfilter_ros/config`` (pip).
    """
    candidates = [Path(__file__).resolve().parents[1] / "config"]
    try:  # ament_index_python is present with ROS; optional otherwise
        from ament_index_python.packages import (
            PackageNotFoundError,
            get_package_share_directory,
        )

        try:
            candidates.append(Path(get_package_share_directory(PACKAGE)) / "config")
        except (PackageNotFoundError, OSError):  # OSError: AMENT_PREFIX_PATH unset
            pass
    except ImportError:
        pass
    candidates.append(Path(sys.prefix) / "share" / PACKAGE / "config")
    for path in candidates:
        if (path / "fastdds_loopback.xml").is_file():
            return path
    raise InputError(
        "cannot find clusterfilter_ros config files; looked in "
        + ", ".join(str(c) for c in candidates)
    )


def config_file(name: str) -> Path:
    path = config_dir() / name
    if not path.is_file():
        raise InputError(f"config file {path} does not exist")
    return path
