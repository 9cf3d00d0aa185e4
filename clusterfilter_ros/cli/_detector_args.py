"""Shared CLI options for commands that run the detector (``--params-file``, ``--param``)."""

from __future__ import annotations

import argparse

from clusterfilter_ros.core.params import DETECTOR_PARAMS, ParamSet, detector_params


def add_detector_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--params-file YAML`` and repeatable ``--param name=value``."""
    parser.add_argument(
        "--params-file",
        metavar="YAML",
        help="detector parameters (ROS params YAML such as config/detector.yaml, or a flat "
        "mapping); node-only parameters in it are ignored, unknown names are an error",
    )
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set one detector parameter (repeatable; overrides --params-file); "
        "see `clusterfilter params --markdown`",
    )


def detector_params_from_args(args: argparse.Namespace) -> ParamSet:
    """Defaults, then the params file's detector entries, then ``--param`` assignments."""
    from clusterfilter_ros.config import load_params_file
    from clusterfilter_ros.core.params import parse_assignments

    names = {s.name for s in DETECTOR_PARAMS}
    values = {}
    if getattr(args, "params_file", None):
        values.update({k: v for k, v in load_params_file(args.params_file).items() if k in names})
    values.update(parse_assignments(getattr(args, "param", []) or []))
    return detector_params(values)
