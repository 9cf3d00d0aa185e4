"""``clusterfilter detector``: run the ROS 2 detector node (same as ``ros2 run ... detector``)."""

from __future__ import annotations

import argparse

from clusterfilter_ros.config import all_param_specs
from clusterfilter_ros.core.params import ParamSpec, parse_assignments
from clusterfilter_ros.errors import InputError, ParameterError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "detector",
        help="run the ROS 2 detector node (subscribes to the lidars, publishes /uav/pose)",
        description="Run the detector node. Topics, QoS and parameters: docs/node.md. "
        "Anything after the options (e.g. --ros-args -r __node:=other) goes to ROS.",
    )
    p.add_argument("--params-file", help="ROS parameter YAML, e.g. config/detector.yaml")
    p.add_argument(
        "--param",
        "-p",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set one parameter (repeatable), e.g. -p eps=1.5 -p frame_id=world",
    )
    p.add_argument(
        "--ros-args",
        dest="ros_args_tail",
        nargs=argparse.REMAINDER,
        default=None,
        help="everything after this goes to ROS as is (remappings, -p name:=value, ...)",
    )
    p.add_argument("ros_args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    p.set_defaults(func=run)


def ros_value(spec: ParamSpec, value: object) -> str:
    """A value as ROS's ``-p name:=value`` parses it back to the spec's type."""
    v = spec.validate(value)
    if spec.kind == "float":
        return repr(float(v))
    if spec.kind == "float_list":
        return "[" + ",".join(repr(float(x)) for x in v) + "]"
    if spec.kind == "str_list":
        return "[" + ",".join(f"'{x}'" for x in v) + "]"
    if spec.kind == "bool":
        return "true" if v else "false"
    if spec.kind == "str":
        return f"'{v}'" if v == "" or v.lower() in ("true", "false") else str(v)
    return str(v)


def ros_arguments(params_file: str | None, assignments: list[str], extra: list[str]) -> list[str]:
    """The rclpy argument list for the node: program name, then one ``--ros-args`` block
    with the params file, the ``-p`` values and ``extra`` (ROS arguments given after
    ``--`` or ``--ros-args`` on the command line)."""
    from pathlib import Path

    specs = {s.name: s for s in all_param_specs()}
    args = ["clusterfilter-detector"]
    extra = list(extra)
    if extra and extra[0] == "--":
        extra = extra[1:]
    ros: list[str] = []
    if params_file:
        if not Path(params_file).is_file():
            raise InputError(f"params file {params_file} does not exist")
        ros += ["--params-file", str(params_file)]
    for name, value in parse_assignments(assignments).items():
        if name not in specs:
            raise ParameterError(f"unknown parameter '{name}'")
        ros += ["-p", f"{name}:={ros_value(specs[name], value)}"]
    if extra and extra[0] == "--ros-args":
        extra = extra[1:]
    if ros or extra:  # one ROS block: ours, then the user's ROS arguments
        args += ["--ros-args", *ros, *extra]
    return args


def run(args: argparse.Namespace) -> int:
    from clusterfilter_ros.ros.node import main

    extra = list(args.ros_args)
    if args.ros_args_tail is not None:
        extra = ["--ros-args", *args.ros_args_tail]
    return main(args=ros_arguments(args.params_file, args.param, extra))
