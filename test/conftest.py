"""Shared fixtures. DDS is confined to loopback for every test, whatever the caller set.

Every test session gets its own ROS_DOMAIN_ID, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
and the package's Fast DDS profile (shared memory + UDPv4 on 127.0.0.1 only). Tests
that start subprocesses pass ``ros_env`` so children inherit the same confinement.
"""

from __future__ import annotations

import os
import random

import pytest

from clusterfilter_ros.dds import loopback_settings

_DOMAIN_ID = random.SystemRandom().randint(100, 200)
# Applied at import time, before any test module can import or init rclpy.
os.environ.update(loopback_settings(_DOMAIN_ID))


@pytest.fixture(scope="session")
def ros_env() -> dict[str, str]:
    """Environment for child processes: the current one plus the loopback DDS settings."""
    env = dict(os.environ)
    env.update(loopback_settings(_DOMAIN_ID))
    return env


@pytest.fixture
def rclpy_context():
    """An initialised rclpy context (loopback, per-run domain), shut down afterwards."""
    rclpy = pytest.importorskip("rclpy")
    context = rclpy.context.Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        if context.ok():
            rclpy.shutdown(context=context)
