"""Measurements on the simulator itself: how many returns a drone gives at a range."""

from __future__ import annotations

import math

import numpy as np

from clusterfilter_ros.sim.raycast import CLASS_DRONE
from clusterfilter_ros.sim.scenarios import ScenarioSpec, Simulation
from clusterfilter_ros.sim.trajectory import Waypoint

_PROBE = "probe"


def _probe_flight(position: tuple[float, float, float]):
    def plan(rng: np.random.Generator, duration: float, size: float) -> list[Waypoint]:
        return [Waypoint(position, hold=duration + 5.0)]

    return plan


def drone_hits_per_frame(
    model: str,
    distance: float,
    elevation_deg: float,
    azimuth_deg: float = -60.0,
    frames: int = 50,
    seed: int = 0,
) -> dict[str, float]:
    """Mean drone points per frame for each sensor, the drone hovering at a fixed spot.

    The drone hovers (with wind drift) ``distance`` metres from the Mid360 at the given
    elevation and azimuth, in the car park without people, cars or birds.
    """
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    pos = (
        distance * math.cos(el) * math.cos(az),
        distance * math.cos(el) * math.sin(az),
        distance * math.sin(el),
    )
    spec = ScenarioSpec(
        _PROBE,
        "fixed hover",
        frames * 0.1,
        model,
        _probe_flight(pos),
        people=0,
        cars=0,
        birds_low=0,
    )
    sim = Simulation(spec, seed, frames * 0.1)
    counts: dict[str, list[int]] = {}
    for sf in sim.iter_frames():
        counts.setdefault(sf.frame.sensor, []).append(int((sf.classes == CLASS_DRONE).sum()))
    return {k: float(np.mean(v)) for k, v in counts.items()}
