"""The ``clusterfilter`` command.

Each subcommand lives in its own module in this package and exposes
``register(subparsers)``, which adds its parser and sets ``func`` (a callable taking
the parsed ``argparse.Namespace`` and returning an exit code). Modules import heavy
dependencies (rclpy, matplotlib, rosbags) inside ``func`` so ``--help`` stays fast.

Errors meant for the user (:class:`~clusterfilter_ros.errors.ClusterfilterError`)
print one line and exit with code 2; ``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import pkgutil
import signal
import sys
import threading
from collections.abc import Sequence

from clusterfilter_ros import __version__
from clusterfilter_ros.errors import ClusterfilterError

#: Subcommands listed first in ``--help``; any other module of this package that has
#: ``register`` follows in alphabetical order (modules are discovered, not registered).
PREFERRED_ORDER = ["detect", "evaluate", "simulate", "replay", "detector", "demo"]


def command_modules() -> list[str]:
    names = [m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_")]
    return sorted(
        names, key=lambda n: (PREFERRED_ORDER.index(n) if n in PREFERRED_ORDER else 99, n)
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="clusterfilter",
        description="Training-free drone detection in Livox lidar point clouds.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument(
        "--debug", action="store_true", help="show full tracebacks instead of one-line errors"
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in command_modules():
        module = importlib.import_module(f"{__name__}.{name}")
        if hasattr(module, "register"):
            module.register(subparsers)
    return parser


#: Subcommands (file readers/writers without rclpy) for which SIGTERM raises
#: KeyboardInterrupt, so their atomic writers delete temporary files before exiting.
#: rclpy-based subcommands keep rclpy's own SIGTERM handling.
SIGTERM_AS_INTERRUPT = frozenset({"detect", "evaluate", "convert", "info", "simulate"})


#: Set when SIGTERM arrived: the KeyboardInterrupt it raises can be caught inside a
#: library call and come out as another error (numpy's ``tofile`` turns it into a
#: TypeError), which is still an interruption, not a failure.
_SIGTERM_RECEIVED = threading.Event()


def _terminate(signum: int, frame: object) -> None:
    """SIGTERM unwinds like Ctrl-C, so partial outputs are removed on the way out."""
    _SIGTERM_RECEIVED.set()
    raise KeyboardInterrupt


def _interrupted(command: str) -> int:
    print(f"clusterfilter {command}: interrupted", file=sys.stderr)
    return 130


def _printable_output() -> None:
    """Let stdout and stderr print any file name: bytes that are not valid in their
    encoding (a folder name that is not UTF-8) become escapes instead of an error."""
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None:
            with contextlib.suppress(ValueError, OSError):
                reconfigure(errors="backslashreplace")


def main(argv: Sequence[str] | None = None) -> int:
    _printable_output()
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    if (
        args.command in SIGTERM_AS_INTERRUPT
        and threading.current_thread() is threading.main_thread()
        and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    ):
        signal.signal(signal.SIGTERM, _terminate)
    _SIGTERM_RECEIVED.clear()
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return _interrupted(args.command)
    except Exception as exc:
        if _SIGTERM_RECEIVED.is_set():
            return _interrupted(args.command)
        if not isinstance(exc, ClusterfilterError) or args.debug:
            raise
        print(f"clusterfilter {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
