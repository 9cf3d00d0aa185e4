"""Run the detector, a replay and a recorder as separate processes (demo and tests).

ROS-free: it only starts ``python -m clusterfilter_ros.cli ...`` children with an
environment confined to loopback DDS and one ROS domain, and stops them the way a user
would (SIGINT, as Ctrl-C). Each child's output goes to a log file.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from clusterfilter_ros.dds import apply_loopback_defaults, random_domain_id


def demo_environment(
    base: Mapping[str, str] | None = None, domain_id: int | None = None
) -> dict[str, str]:
    """``base`` (default ``os.environ``) with the loopback DDS settings and a ROS domain.

    The domain is ``domain_id`` or a random one: a run never joins another run's graph.
    """
    env = dict(os.environ if base is None else base)
    apply_loopback_defaults(env)
    env["ROS_DOMAIN_ID"] = str(random_domain_id() if domain_id is None else int(domain_id))
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


def cli_command(*args: str) -> list[str]:
    """The command line of ``clusterfilter ARGS`` with this interpreter."""
    return [sys.executable, "-m", "clusterfilter_ros.cli", *args]


@dataclass
class Child:
    """A started child process and its log file."""

    name: str
    process: subprocess.Popen
    log_path: Path

    def log_tail(self, lines: int = 20) -> str:
        try:
            text = self.log_path.read_text(errors="replace")
        except OSError:
            return ""
        return "\n".join(text.splitlines()[-lines:])

    def running(self) -> bool:
        return self.process.poll() is None

    def wait(self, timeout: float) -> int | None:
        """Exit code, or None if still running after ``timeout`` s."""
        try:
            return self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            return None

    def interrupt(self, timeout: float = 15.0) -> int:
        """Send SIGINT (Ctrl-C) and wait; SIGTERM then SIGKILL if it does not exit."""
        if self.running():
            self.process.send_signal(signal.SIGINT)
        code = self.wait(timeout)
        if code is None:
            self.process.terminate()
            code = self.wait(5.0)
        if code is None:
            self.process.kill()
            code = self.process.wait()
        return code


def start(name: str, command: Sequence[str], env: Mapping[str, str], log_dir: Path) -> Child:
    """Start ``command`` with ``env``, output to ``log_dir/<name>.log``."""
    log_dir.mkdir(parents=True, exist_ok=True)
    log_path = log_dir / f"{name}.log"
    with open(log_path, "wb") as log:
        process = subprocess.Popen(
            list(command), env=dict(env), stdout=log, stderr=subprocess.STDOUT
        )
    return Child(name, process, log_path)


def wait_for_log(child: Child, text: str, timeout: float) -> bool:
    """Wait until ``text`` appears in the child's log (False on timeout or exit)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if text in child.log_path.read_text(errors="replace"):
                return True
        except OSError:
            pass
        if not child.running():
            return False
        time.sleep(0.1)
    return False
