"""``clusterfilter params``: print the parameter definitions as YAML or a Markdown table."""

from __future__ import annotations

import argparse

from clusterfilter_ros.config import all_param_specs, detector_yaml
from clusterfilter_ros.core.params import markdown_table


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "params",
        help="print every parameter (YAML for --params-file, or a Markdown table)",
        description="Print the parameter definitions shared by the node, the CLI and "
        "config/detector.yaml.",
    )
    p.add_argument("--markdown", action="store_true", help="a Markdown table instead of YAML")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    print(markdown_table(all_param_specs()) if args.markdown else detector_yaml(), end="")
    if args.markdown:
        print()
    return 0
