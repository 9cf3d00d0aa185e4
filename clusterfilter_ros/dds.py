"""Keep DDS traffic on this machine by default.

DDS discovery multicasts on every network interface unless told otherwise. Every
entry point of this package that creates an rclpy context (the node, replay, record,
demo, tests, benchmarks) calls :func:`apply_loopback_defaults` *before* ``rclpy.init``:

- ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (discovery only with local processes),
- ``FASTRTPS_DEFAULT_PROFILES_FILE`` = the package's ``fastdds_loopback.xml``
  (shared memory with an 8 MB segment, UDPv4 only on 127.0.0.1),
- ``RMW_IMPLEMENTATION=rmw_fastrtps_cpp`` (the profile is a Fast DDS profile).

Values the user already exported are kept, so a deployment that needs the network can
opt in explicitly (``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` and its own profile).
This module is ROS-free.
"""

from __future__ import annotations

import os
import random
from collections.abc import MutableMapping

from clusterfilter_ros.resources import config_file

PROFILE_NAME = "fastdds_loopback.xml"


def loopback_settings(domain_id: int | None = None) -> dict[str, str]:
    """The environment variables that confine DDS to loopback (and a domain, if given)."""
    settings = {
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "FASTRTPS_DEFAULT_PROFILES_FILE": str(config_file(PROFILE_NAME)),
        "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
    }
    if domain_id is not None:
        settings["ROS_DOMAIN_ID"] = str(int(domain_id))
    return settings


def apply_loopback_defaults(
    environ: MutableMapping[str, str] | None = None, domain_id: int | None = None
) -> dict[str, str]:
    """Set the loopback settings in ``environ`` (default ``os.environ``) where unset.

    Returns the settings now in force. ``domain_id`` is only applied when
    ``ROS_DOMAIN_ID`` is unset.
    """
    env = os.environ if environ is None else environ
    for key, value in loopback_settings(domain_id).items():
        env.setdefault(key, value)
    return {
        k: env[k]
        for k in (
            "ROS_AUTOMATIC_DISCOVERY_RANGE",
            "FASTRTPS_DEFAULT_PROFILES_FILE",
            "RMW_IMPLEMENTATION",
            "ROS_DOMAIN_ID",
        )
        if k in env
    }


def random_domain_id(rng: random.Random | None = None) -> int:
    """A domain id for one test or demo run (Fast DDS accepts 0-232; 0 is avoided)."""
    return (rng or random.SystemRandom()).randint(100, 200)
