"""Ctrl-C and SIGTERM as a stop request for a spin loop.

rclpy's own signal handler shuts the context down from the signal, and Python raises
KeyboardInterrupt wherever the main thread happens to be: now and then inside the
executor, which then reports "the given context is not valid" or leaves a half-built
task whose ``__del__`` prints a traceback at exit. The entry points here init rclpy with
``SignalHandlerOptions.NO`` and spin in short steps until :func:`stop_on_signals` says
stop.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import rclpy


@contextmanager
def stop_on_signals() -> Iterator[threading.Event]:
    """An event that SIGINT or SIGTERM sets while the block runs; the previous handlers
    are restored after it. Signals reach the main thread only: called from another
    thread, the event is returned but no handler is installed."""
    stop = threading.Event()
    previous: dict[int, Any] = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, lambda *_: stop.set())
    try:
        yield stop
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def shutdown_race(exc: BaseException, context: Any = None) -> bool:
    """True when ``exc`` is how rclpy reports a shutdown it raced with: when the context
    is shut down (by another thread, or rclpy's own signal handler) while an executor
    builds its wait set, ``spin`` raises ``RCLError`` ("the given context is not
    valid"), a RuntimeError, instead of ``ExternalShutdownException``. Any other
    RuntimeError, or one while the context is still up, is a real error."""
    return isinstance(exc, RuntimeError) and not rclpy.ok(context=context)
