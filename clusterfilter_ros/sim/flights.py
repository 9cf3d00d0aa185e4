"""Flight plans of the scenarios: waypoint lists for drones and distractors.

Every planner takes a random generator and the wanted duration (seconds) and returns
waypoints in the world frame (origin at the Mid360, ground at ``GROUND_Z``). Scripted
plans that end before the wanted duration are continued with random manoeuvres
(:func:`mixed_manoeuvres`), so any duration - an hour for a benchmark - has a drone
that keeps flying.

The scene's buildings stand beyond about 50 m from the rig (office block east up to
24 m high, a 38 m tower west, lower blocks north and south), so low flights stay
within ~50 m horizontally and long-range legs climb above 30 m or run between blocks.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from clusterfilter_ros.sim.scene import GROUND_Z, LANE_X, LANE_Y
from clusterfilter_ros.sim.trajectory import Waypoint

#: Where the drones take off and land: a pad 6.7 m from the rig.
PAD_XY = (6.0, -3.0)

Planner = Callable[[np.random.Generator, float, float], list[Waypoint]]


def _estimate_duration(waypoints: list[Waypoint], default_speed: float) -> float:
    total = 0.0
    for a, b in zip(waypoints[:-1], waypoints[1:], strict=True):
        dist = math.dist(a.position, b.position)
        total += dist / (b.speed or default_speed) * 1.3 + 1.0 + b.hold
    return total


def _rotated(rng: np.random.Generator, pts: list[tuple[float, float, float]], max_deg: float):
    """Rotate plan points about the vertical by a random angle and jitter them a little."""
    a = math.radians(rng.uniform(-max_deg, max_deg))
    c, s = math.cos(a), math.sin(a)
    out = []
    for x, y, z in pts:
        jx, jy, jz = rng.normal(0.0, [1.5, 1.5, 1.0])
        out.append((c * x - s * y + jx, s * x + c * y + jy, z + jz))
    return out


def mixed_manoeuvres(
    rng: np.random.Generator, start: tuple[float, float, float], duration: float
) -> list[Waypoint]:
    """Random passes, hovers, climbs and out-and-back legs for ``duration`` seconds."""
    out: list[Waypoint] = []
    here = start
    elapsed = 0.0
    while elapsed < duration:
        kind = rng.choice(["pass", "hover", "far", "overhead"], p=[0.45, 0.2, 0.15, 0.2])
        if kind == "pass":
            r, a = rng.uniform(8.0, 48.0), rng.uniform(-math.pi, math.pi)
            wp = Waypoint(
                (r * math.cos(a), r * math.sin(a), GROUND_Z + rng.uniform(6.0, 30.0)),
                speed=rng.uniform(3.0, 12.0),
            )
        elif kind == "hover":
            r, a = rng.uniform(10.0, 45.0), rng.uniform(-math.pi, math.pi)
            wp = Waypoint(
                (r * math.cos(a), r * math.sin(a), GROUND_Z + rng.uniform(8.0, 30.0)),
                hold=rng.uniform(2.0, 8.0),
                speed=rng.uniform(3.0, 8.0),
            )
        elif kind == "far":
            a = rng.uniform(-math.pi, math.pi)
            r = rng.uniform(90.0, 160.0)
            wp = Waypoint(
                (r * math.cos(a), r * math.sin(a), GROUND_Z + rng.uniform(45.0, 70.0)),
                speed=rng.uniform(8.0, 12.0),
            )
        else:
            wp = Waypoint(
                (rng.normal(0, 6.0), rng.normal(0, 6.0), GROUND_Z + rng.uniform(30.0, 100.0)),
                speed=rng.uniform(4.0, 10.0),
            )
        if kind != "far" and math.dist(here[:2], (0.0, 0.0)) > 80.0:
            # Coming back from far away: climb above the roofs first.
            out.append(Waypoint((here[0] * 0.6, here[1] * 0.6, GROUND_Z + 50.0), speed=10.0))
        out.append(wp)
        elapsed += _estimate_duration([Waypoint(here), wp], 6.0)
        here = wp.position
    return out


def _continue(
    rng: np.random.Generator, scripted: list[Waypoint], duration: float
) -> list[Waypoint]:
    remaining = duration - _estimate_duration(scripted, 6.0)
    if remaining <= 0:
        return scripted
    return scripted + mixed_manoeuvres(rng, scripted[-1].position, remaining + 10.0)


def default_flight(rng: np.random.Generator, duration: float, size: float) -> list[Waypoint]:
    """Arrives from ~40 m, hovers 4 s at ~13 m range, climbs over the rig through the
    Avia's cone at ~25 m up, and leaves on the far side towards ~35 m."""
    pts = _rotated(
        rng,
        [
            (36.0, 18.0, 16.0),
            (12.0, 6.0, 10.0),
            (10.0, 7.0, 11.0),
            (1.0, -2.0, 24.0),
            (-18.0, -14.0, 20.0),
        ],
        40.0,
    )
    plan = [
        Waypoint(pts[0]),
        Waypoint(pts[1], speed=5.0),
        Waypoint(pts[2], hold=4.0, speed=1.5),
        Waypoint(pts[3], speed=5.0),
        Waypoint(pts[4], speed=6.0),
        Waypoint((pts[4][0] - 12.0, pts[4][1] - 8.0, 16.0), speed=6.0),
    ]
    return _continue(rng, plan, duration)


def _pad(size: float) -> tuple[float, float, float]:
    return (PAD_XY[0], PAD_XY[1], GROUND_Z + size / 2)


def takeoff_landing_flight(
    rng: np.random.Generator, duration: float, size: float
) -> list[Waypoint]:
    """Waits on the pad, climbs, flies a loop with a hover, comes back and lands."""
    pad = _pad(size)
    up = (pad[0], pad[1], GROUND_Z + 10.0)
    loop = _rotated(rng, [(25.0, 15.0, 14.0), (-15.0, 25.0, 12.0)], 30.0)
    plan = [
        Waypoint(pad, hold=2.0),
        Waypoint(up, speed=2.5),
        Waypoint(loop[0], hold=4.0, speed=5.0),
        Waypoint(loop[1], speed=6.0),
        Waypoint((pad[0], pad[1], GROUND_Z + 8.0), speed=5.0),
        Waypoint(pad, hold=max(duration, 1.0), speed=1.5),
    ]
    return plan


def flyover_flight(rng: np.random.Generator, duration: float, size: float) -> list[Waypoint]:
    """Overhead pass at ~40 m, a wide turn, and a second overhead pass at ~90 m."""
    a = rng.uniform(-math.pi, math.pi)
    c, s = math.cos(a), math.sin(a)

    def rot(x: float, y: float, z: float) -> tuple[float, float, float]:
        return (c * x - s * y, s * x + c * y, GROUND_Z + z)

    plan = [
        Waypoint(rot(-70.0, 5.0, 40.0)),
        Waypoint(rot(0.0, 0.0, 42.0), speed=8.0),
        Waypoint(rot(70.0, -5.0, 60.0), speed=8.0),
        Waypoint(rot(80.0, 40.0, 85.0), speed=9.0),
        Waypoint(rot(0.0, 2.0, 92.0), speed=9.0),
        Waypoint(rot(-80.0, -20.0, 100.0), speed=10.0),
    ]
    return _continue(rng, plan, duration)


def fast_pass_flight(rng: np.random.Generator, duration: float, size: float) -> list[Waypoint]:
    """Two 12 m/s passes from ~95 m out to ~5 m from the rig and away again."""
    plan = [
        Waypoint((-88.0, 34.0, GROUND_Z + 16.0)),
        Waypoint((-10.0, 6.0, GROUND_Z + 6.0), speed=12.0),
        Waypoint((2.5, 3.5, GROUND_Z + 5.0), speed=12.0),
        Waypoint((40.0, -30.0, GROUND_Z + 20.0), speed=12.0),
        Waypoint((78.0, -46.0, GROUND_Z + 28.0), speed=12.0),
        Waypoint((30.0, -10.0, GROUND_Z + 18.0), speed=12.0),
        Waypoint((-4.0, -4.0, GROUND_Z + 8.0), speed=12.0),
        Waypoint((-40.0, 40.0, GROUND_Z + 24.0), speed=12.0),
    ]
    return _continue(rng, plan, duration)


def hover_flight(rng: np.random.Generator, duration: float, size: float) -> list[Waypoint]:
    """Hovers at ~25 m range and ~12 m height for the whole sequence (wind drift only)."""
    a = rng.uniform(-math.pi, math.pi)
    r = rng.uniform(18.0, 30.0)
    return [Waypoint((r * math.cos(a), r * math.sin(a), GROUND_Z + 12.0), hold=duration + 5.0)]


def avia_only_flight(rng: np.random.Generator, duration: float, size: float) -> list[Waypoint]:
    """High and steep: always above 60 deg elevation, above 40 m, inside the Avia cone."""
    out: list[Waypoint] = []
    elapsed = 0.0
    here = (rng.uniform(-8, 8), rng.uniform(-8, 8), GROUND_Z + rng.uniform(45.0, 55.0))
    out.append(Waypoint(here))
    while elapsed < duration:
        z = GROUND_Z + rng.uniform(42.0, 85.0)
        r = rng.uniform(0.0, 0.35) * (z - GROUND_Z)  # tan(19 deg): well inside 52 deg limit
        a = rng.uniform(-math.pi, math.pi)
        wp = Waypoint(
            (r * math.cos(a), r * math.sin(a), z),
            hold=float(rng.choice([0.0, rng.uniform(1.0, 4.0)])),
            speed=rng.uniform(3.0, 8.0),
        )
        elapsed += _estimate_duration([Waypoint(here), wp], 5.0)
        out.append(wp)
        here = wp.position
    return out


def long_mixed_flight(rng: np.random.Generator, duration: float, size: float) -> list[Waypoint]:
    """Take-off, passes, hover, out beyond sensor range and back, overhead, landing.

    Longer durations get random manoeuvres (:func:`mixed_manoeuvres`) before the landing.
    """
    pad = _pad(size)
    p = _rotated(rng, [(30.0, 20.0, 15.0), (-25.0, 30.0, 20.0)], 20.0)
    a = rng.uniform(-math.pi, math.pi)
    far = (130.0 * math.cos(a), 130.0 * math.sin(a), GROUND_Z + 55.0)
    start = [
        Waypoint(pad, hold=3.0),
        Waypoint((pad[0], pad[1], GROUND_Z + 12.0), speed=3.0),
        Waypoint(p[0], speed=7.0),
        Waypoint(p[1], hold=6.0, speed=8.0),
        Waypoint((far[0] * 0.3, far[1] * 0.3, GROUND_Z + 40.0), speed=10.0),
        Waypoint(far, hold=4.0, speed=12.0),
        Waypoint((far[0] * 0.3, far[1] * 0.3, GROUND_Z + 45.0), speed=12.0),
        Waypoint((0.0, 3.0, GROUND_Z + 70.0), speed=8.0),
        Waypoint((-30.0, -10.0, GROUND_Z + 14.0), speed=12.0),
        Waypoint((20.0, 10.0, GROUND_Z + 18.0), hold=4.0, speed=9.0),
    ]
    landing = [
        Waypoint((pad[0], pad[1], GROUND_Z + 8.0), speed=5.0),
        Waypoint(pad, hold=max(duration, 5.0), speed=1.5),
    ]
    remaining = duration - _estimate_duration(start + landing[:1], 6.0) - 8.0
    if remaining > 20.0:
        start += mixed_manoeuvres(rng, start[-1].position, remaining)
    return _fit_before_landing(start, landing, duration)


def _fit_before_landing(
    start: list[Waypoint], landing: list[Waypoint], duration: float
) -> list[Waypoint]:
    """Drop legs before the landing until the drone is down by the end of ``duration``."""
    from clusterfilter_ros.sim.trajectory import Path

    keep = len(start)
    while keep > 3:
        path = Path(start[:keep] + landing, max_speed=12.0, max_acceleration=4.0)
        if path.knot_times[-2] <= duration - 2.0:
            break
        keep -= 1
    return start[:keep] + landing


# --- distractors -------------------------------------------------------------------


def walking_route(rng: np.random.Generator, duration: float) -> list[Waypoint]:
    """A pedestrian strolling between lanes and bays with pauses (feet on the ground)."""
    pts: list[Waypoint] = []
    x, y = rng.uniform(-30.0, 30.0), float(rng.choice(LANE_Y[:2]))
    elapsed = 0.0
    while elapsed < duration:
        if rng.random() < 0.6:
            nx, ny = float(np.clip(x + rng.uniform(-25, 25), -38, 38)), y
        else:
            nx, ny = x, float(rng.choice([*LANE_Y[:2], rng.uniform(-30, 30)]))
        if math.hypot(nx, ny) < 3.0:  # keep off the rig
            ny += 4.0
        speed = rng.uniform(1.1, 1.6)
        hold = float(rng.choice([0.0, 0.0, rng.uniform(1.0, 6.0)]))
        pts.append(Waypoint((nx, ny, GROUND_Z), hold=hold, speed=speed))
        elapsed += math.hypot(nx - x, ny - y) / speed + hold + 1.0
        x, y = nx, ny
    return [Waypoint((pts[0].position[0] - 1.0, pts[0].position[1], GROUND_Z)), *pts]


def driving_route(rng: np.random.Generator, duration: float) -> list[Waypoint]:
    """A car circling the car park's perimeter lanes, now and then stopping."""
    x0, x1 = LANE_X
    corners = [(x0, LANE_Y[2]), (x1, LANE_Y[2]), (x1, LANE_Y[1]), (x0, LANE_Y[1])]
    start = int(rng.integers(0, 4))
    pts: list[Waypoint] = []
    elapsed = 0.0
    i = start
    while elapsed < duration or len(pts) < 2:
        cx, cy = corners[i % 4]
        nx, ny = corners[(i + 1) % 4]
        mid = ((cx + nx) / 2, (cy + ny) / 2, GROUND_Z)
        speed = rng.uniform(5.0, 8.0)
        pts.append(Waypoint((cx, cy, GROUND_Z), speed=4.0))
        hold = float(rng.choice([0.0, 0.0, 0.0, rng.uniform(2.0, 5.0)]))
        pts.append(Waypoint(mid, hold=hold, speed=speed))
        elapsed += math.hypot(nx - cx, ny - cy) / speed + hold + 3.0
        i += 1
    return pts


def bird_route(
    rng: np.random.Generator,
    duration: float,
    overhead: bool,
) -> list[Waypoint]:
    """Random legs of 15-60 m; ``overhead`` keeps the bird above the rig (Avia's cone)."""
    pts: list[Waypoint] = []
    elapsed = 0.0
    here = None
    while elapsed < duration + 5.0:
        if overhead:
            z = rng.uniform(12.0, 70.0)
            r = rng.uniform(0.0, 0.6) * z
        else:
            z = rng.uniform(3.0, 30.0)
            r = rng.uniform(8.0, 55.0)
        a = rng.uniform(-math.pi, math.pi)
        p = (r * math.cos(a), r * math.sin(a), GROUND_Z + z)
        speed = rng.uniform(7.0, 14.0)
        pts.append(Waypoint(p, speed=speed))
        if here is not None:
            elapsed += math.dist(here, p) / speed + 0.5
        here = p
    return pts
