"""``colcon build`` in a temporary workspace installs the package the ROS way.

Checks what ``ros2 run clusterfilter_ros detector`` relies on: the ament index marker,
``lib/clusterfilter_ros/detector`` found through the ament index, the installed
``package.xml`` and config files; then starts the installed detector with the installed
``detector.yaml`` and stops it with Ctrl-C (SIGINT), expecting exit code 0.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import sysconfig
import threading
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
PACKAGE = "clusterfilter_ros"
SKIP_DIRS = {".venv", "build", "install", "log", ".git", "__pycache__", ".pytest_cache"}
SKIP_DIRS |= {".ruff_cache", ".hypothesis"}


def _colcon() -> Path | None:
    sibling = Path(sys.executable).with_name("colcon")
    if sibling.is_file():
        return sibling
    found = shutil.which("colcon")
    return Path(found) if found else None


def _source_files() -> list[Path]:
    """The files a clean checkout would have (tracked + untracked-not-ignored)."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"],
            cwd=REPO,
            capture_output=True,
            check=True,
            timeout=60,
        ).stdout
        names = [n for n in out.decode().split("\0") if n]
    except (OSError, subprocess.SubprocessError):
        names = [
            str(p.relative_to(REPO))
            for p in REPO.rglob("*")
            if p.is_file() and not (set(p.relative_to(REPO).parts) & SKIP_DIRS)
        ]
    return [Path(n) for n in names if not n.endswith(".egg-info") and ".egg-info/" not in n]


@pytest.fixture(scope="module")
def colcon_install(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Build the package with colcon in a fresh workspace; return ``install/``."""
    colcon = _colcon()
    if colcon is None:
        pytest.skip("colcon is not installed (pip install colcon-common-extensions)")
    ws = tmp_path_factory.mktemp("ws")
    src = ws / "src" / PACKAGE
    for rel in _source_files():
        source = REPO / rel
        if not source.is_file():  # deleted in the working tree
            continue
        dest = src / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(source, dest)
    env = dict(os.environ)
    env.pop("AMENT_PREFIX_PATH", None)
    env.pop("COLCON_PREFIX_PATH", None)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    proc = subprocess.run(
        [str(colcon), "build", "--base-paths", "src", "--event-handlers", "console_cohesion+"],
        cwd=ws,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, (
        f"colcon build failed:\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}"
    )
    return ws / "install"


def test_colcon_installs_executable_and_share_files(colcon_install: Path) -> None:
    prefix = colcon_install / PACKAGE
    executable = prefix / "lib" / PACKAGE / "detector"
    assert executable.is_file() and os.access(executable, os.X_OK)
    assert (prefix / "lib" / PACKAGE / "clusterfilter").is_file()
    share = prefix / "share" / PACKAGE
    assert (share / "package.xml").is_file()
    assert (share / "config" / "detector.yaml").is_file()
    assert (share / "config" / "fastdds_loopback.xml").is_file()
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE).is_file()
    assert (share / "package.xml").read_text() == (REPO / "package.xml").read_text()


def _resolve_like_ros2_run(install_prefix: Path, executable: str) -> Path:
    """``ros2 run PKG EXE``: the package prefix from the ament index, then lib/PKG/EXE."""
    from ament_index_python.packages import get_package_prefix

    old = os.environ.get("AMENT_PREFIX_PATH")
    os.environ["AMENT_PREFIX_PATH"] = str(install_prefix)
    try:
        prefix = Path(get_package_prefix(PACKAGE))
    finally:
        if old is None:
            os.environ.pop("AMENT_PREFIX_PATH", None)
        else:
            os.environ["AMENT_PREFIX_PATH"] = old
    candidates = [
        p
        for p in (prefix / "lib" / PACKAGE).iterdir()
        if p.name == executable and os.access(p, os.X_OK)
    ]
    assert len(candidates) == 1, f"ros2 run would find {candidates}"
    return candidates[0]


def _installed_env(install_prefix: Path, ros_env: dict[str, str]) -> dict[str, str]:
    """Environment like ``source install/setup.bash``: the install's Python path first."""
    py = f"python{sys.version_info.major}.{sys.version_info.minor}"
    site = install_prefix / "lib" / py / "site-packages"
    assert site.is_dir(), f"no {site}"
    env = dict(ros_env)
    env["AMENT_PREFIX_PATH"] = str(install_prefix)
    env["PYTHONPATH"] = os.pathsep.join([str(site), sysconfig.get_paths()["purelib"]])
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONUNBUFFERED"] = "1"
    return env


def test_installed_detector_starts_and_stops_on_sigint(
    colcon_install: Path, ros_env: dict[str, str]
) -> None:
    if not (REPO / PACKAGE / "ros" / "node.py").is_file():
        pytest.skip("clusterfilter_ros/ros/node.py does not exist yet")
    pytest.importorskip("rclpy")
    prefix = colcon_install / PACKAGE
    executable = _resolve_like_ros2_run(prefix, "detector")
    assert executable == prefix / "lib" / PACKAGE / "detector"
    params = prefix / "share" / PACKAGE / "config" / "detector.yaml"
    env = _installed_env(prefix, ros_env)
    where = subprocess.run(
        [sys.executable, "-c", f"import {PACKAGE}; print({PACKAGE}.__file__)"],
        env=env,
        cwd=colcon_install.parent,  # not the checkout: `python -c` puts the cwd on sys.path
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert where.returncode == 0 and str(prefix) in where.stdout, where.stdout + where.stderr
    proc = subprocess.Popen(
        [str(executable), "--ros-args", "--params-file", str(params)],
        env=env,
        cwd=colcon_install.parent,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
    reader.start()
    try:
        # Up once it has logged its first INFO line (imports can be slow on a busy CI
        # machine); give it ~3 s of running after that before Ctrl-C.
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and proc.poll() is None:
            if any("INFO" in line for line in lines):
                break
            time.sleep(0.1)
        time.sleep(3.0)
        alive = proc.poll() is None
        started = any("INFO" in line for line in lines)
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    reader.join(timeout=10)
    out = "".join(lines)
    assert alive, f"detector exited early with {proc.returncode}:\n{out}"
    assert started, f"detector logged nothing at INFO level:\n{out}"
    assert proc.returncode == 0, f"exit code {proc.returncode}:\n{out}"
    assert "Traceback" not in out, out
