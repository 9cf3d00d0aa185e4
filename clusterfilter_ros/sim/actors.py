"""Moving objects: the five MMAUD drones, walking people, a car and birds.

An actor is a set of parts (boxes, cylinders, ellipsoids) fixed in its body frame,
carried along a smooth :class:`~.trajectory.Path` plus an optional :class:`~.trajectory.Wobble`
and turned to face its direction of travel. For each lidar frame it reports its parts'
positions at the frame start and their velocity, so rays fired later in the frame see
it where it has moved to.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clusterfilter_ros.sim.geometry import BOX, CYLINDER, ELLIPSOID
from clusterfilter_ros.sim.raycast import (
    CLASS_BIRD,
    CLASS_CAR,
    CLASS_DRONE,
    CLASS_PERSON,
    PrimitiveTable,
)
from clusterfilter_ros.sim.scene import GROUND_Z
from clusterfilter_ros.sim.trajectory import Path, Wobble


@dataclass(frozen=True)
class DroneModel:
    """A drone's published unfolded size (metres) and surface properties.

    ``length`` x ``width`` is the footprint, ``height`` the vertical size, following the
    MMAUD size list (largest two dimensions horizontal).
    """

    name: str
    length: float
    width: float
    height: float
    reflectivity: float
    landing_gear: bool

    @property
    def size(self) -> float:
        """Largest dimension (m)."""
        return max(self.length, self.width, self.height)


#: The five MMAUD drones, sizes in mm as published: Mavic2 322x242x84, Mavic3 283x108x348,
#: Phantom4 350x350x198, Avata 180x80x180, M300 810x670x430.
DRONE_MODELS: dict[str, DroneModel] = {
    "mavic2": DroneModel("mavic2", 0.322, 0.242, 0.084, 0.25, False),
    "mavic3": DroneModel("mavic3", 0.348, 0.283, 0.108, 0.25, False),
    "phantom4": DroneModel("phantom4", 0.350, 0.350, 0.198, 0.6, True),
    "avata": DroneModel("avata", 0.180, 0.180, 0.080, 0.2, False),
    "m300": DroneModel("m300", 0.810, 0.670, 0.430, 0.3, True),
}


@dataclass(frozen=True)
class Part:
    """One solid of an actor, in its body frame (x forward, z up)."""

    kind: int
    offset: tuple[float, float, float]
    half: tuple[float, float, float]
    yaw: float = 0.0
    reflectivity: float = 0.3
    solidity: float = 1.0


def drone_parts(model: DroneModel) -> list[Part]:
    """Body box, two crossed arms, four rotor discs (mostly air) and optional landing gear."""
    L, W, H = model.length, model.width, model.height
    rho = model.reflectivity
    gear = 0.35 * H if model.landing_gear else 0.0
    body_h = H - gear
    z_body = gear / 2  # body centre above the body-frame origin (frame origin = bbox centre)
    parts = [Part(BOX, (0.0, 0.0, z_body), (0.3 * L, 0.19 * W, 0.4 * body_h), 0.0, rho)]
    rotor_r = 0.22 * min(L, W)
    rx, ry = 0.5 * L - rotor_r, 0.5 * W - rotor_r
    arm_len = math.hypot(rx, ry)
    arm_yaw = math.atan2(ry, rx)
    for sign in (1.0, -1.0):
        parts.append(
            Part(
                BOX,
                (0.0, 0.0, z_body),
                (arm_len, 0.015 + 0.02 * L, 0.012 + 0.02 * H),
                sign * arm_yaw,
                rho,
            )
        )
    z_rotor = H / 2 - 0.01
    for sx in (1.0, -1.0):
        for sy in (1.0, -1.0):
            parts.append(
                Part(
                    ELLIPSOID, (sx * rx, sy * ry, z_rotor), (rotor_r, rotor_r, 0.008), 0.0, 0.3, 0.3
                )
            )
    if model.landing_gear:
        for sy in (1.0, -1.0):
            parts.append(
                Part(
                    BOX,
                    (0.0, sy * 0.3 * W, -H / 2 + gear / 2),
                    (0.3 * L, 0.01 + 0.01 * W, gear / 2),
                    0.0,
                    rho,
                )
            )
    return parts


def person_parts(height: float) -> list[Part]:
    """Legs and torso as one cylinder, a head ellipsoid; origin at the feet."""
    torso_top = height - 0.25
    return [
        Part(CYLINDER, (0.0, 0.0, torso_top / 2), (0.19, 0.19, torso_top / 2), 0.0, 0.35),
        Part(ELLIPSOID, (0.0, 0.0, height - 0.12), (0.1, 0.09, 0.12), 0.0, 0.3),
    ]


def car_parts(reflectivity: float) -> list[Part]:
    """Body and cabin boxes of a 4.5 m hatchback; origin at the ground under its centre."""
    return [
        Part(BOX, (0.0, 0.0, 0.55), (2.25, 0.9, 0.4), 0.0, reflectivity),
        Part(BOX, (-0.3, 0.0, 1.2), (1.2, 0.8, 0.28), 0.0, 0.1),
    ]


def bird_parts(span: float, flap: float) -> list[Part]:
    """Body and a wing pair whose span and thickness follow the wing-beat phase (0..1)."""
    return [
        Part(ELLIPSOID, (0.0, 0.0, 0.0), (0.4 * span, 0.12 * span, 0.12 * span), 0.0, 0.25),
        Part(
            ELLIPSOID,
            (0.0, 0.0, 0.03),
            (0.12 * span, span * (0.25 + 0.25 * flap), 0.01 + 0.1 * span * (1 - flap)),
            0.0,
            0.25,
        ),
    ]


def _segment_headings(knots: np.ndarray) -> np.ndarray:
    """Heading (rad) of each path segment; stationary segments inherit a neighbour's."""
    seg = np.diff(knots[:, :2], axis=0)
    if len(seg) == 0:
        return np.zeros(1)
    moving = np.hypot(seg[:, 0], seg[:, 1]) > 1e-6
    if not moving.any():
        return np.zeros(len(seg))
    heading = np.arctan2(seg[:, 1], seg[:, 0])
    idx = np.where(moving, np.arange(len(seg)), -1)
    idx = np.maximum.accumulate(idx)  # forward fill from the last moving segment
    idx[idx < 0] = np.flatnonzero(moving)[0]  # leading stops take the first leg's heading
    return heading[idx]


class Actor:
    """Something moving through the scene along ``path`` (+ ``wobble``), facing its motion.

    Attributes:
        label: point class code of its returns.
        actor_id: integer id reported with each hit.
        cross_area: its projected area (m^2) for the small-target return model.
    """

    def __init__(
        self,
        label: int,
        actor_id: int,
        path: Path,
        parts: list[Part],
        cross_area: float,
        wobble: Wobble | None = None,
        wobble_gain_height: float | None = None,
    ) -> None:
        self.label = label
        self.actor_id = actor_id
        self.path = path
        self.cross_area = cross_area
        self.wobble = wobble
        self.wobble_gain_height = wobble_gain_height
        self._set_parts(parts)
        self._segment_heading = _segment_headings(path.knots)

    def _set_parts(self, parts: list[Part]) -> None:
        self.parts = parts
        self._kind = np.array([p.kind for p in parts], np.int8)
        self._offset = np.array([p.offset for p in parts], float)
        self._half = np.array([p.half for p in parts], float)
        self._yaw = np.array([p.yaw for p in parts], float)
        self._refl = np.array([p.reflectivity for p in parts], float)
        self._solid = np.array([p.solidity for p in parts], float)

    def _wobble_gain(self, position: np.ndarray) -> np.ndarray:
        if self.wobble_gain_height is None:
            return np.ones(position.shape[:-1])
        return np.clip((position[..., 2] - GROUND_Z) / self.wobble_gain_height, 0.0, 1.0)

    def position(self, t: np.ndarray | float) -> np.ndarray:
        """Body-frame origin in the world at times ``t`` (..., 3)."""
        p = self.path.position(t)
        if self.wobble is not None:
            p = p + self.wobble.position(t) * self._wobble_gain(p)[..., None]
        return p

    def velocity(self, t: np.ndarray | float) -> np.ndarray:
        v = self.path.velocity(t)
        if self.wobble is not None:
            v = v + self.wobble.velocity(t) * self._wobble_gain(self.path.position(t))[..., None]
        return v

    def acceleration(self, t: np.ndarray | float) -> np.ndarray:
        a = self.path.acceleration(t)
        if self.wobble is not None:
            a = (
                a
                + self.wobble.acceleration(t) * self._wobble_gain(self.path.position(t))[..., None]
            )
        return a

    def heading(self, t: float) -> float:
        """Direction of travel (rad): of the velocity when moving, else of the current leg."""
        v = self.path.velocity(t)
        if math.hypot(v[0], v[1]) > 0.5:
            return math.atan2(v[1], v[0])
        seg = int(
            np.clip(
                np.searchsorted(self.path.knot_times, t, side="right") - 1,
                0,
                len(self._segment_heading) - 1,
            )
        )
        return float(self._segment_heading[seg])

    def headings(self, t: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`heading` for an array of times."""
        t = np.asarray(t, dtype=np.float64)
        v = self.path.velocity(t)
        last = len(self._segment_heading) - 1
        seg = np.clip(np.searchsorted(self.path.knot_times, t, side="right") - 1, 0, last)
        moving = np.hypot(v[..., 0], v[..., 1]) > 0.5
        return np.where(moving, np.arctan2(v[..., 1], v[..., 0]), self._segment_heading[seg])

    def update_shape(self, t: float) -> None:
        """Hook for actors whose shape changes with time (birds' wing beat)."""

    def table(self, t0: float, duration: float) -> PrimitiveTable:
        """Parts at frame start ``t0`` with their mean velocity over ``duration`` seconds."""
        self.update_shape(t0)
        times = np.array([t0, t0 + duration])
        base = self.path.position(times)
        pos = base
        if self.wobble is not None:
            pos = base + self.wobble.position(times) * self._wobble_gain(base)[:, None]
        p0 = pos[0]
        vel = (pos[1] - pos[0]) / duration
        step = base[1] - base[0]
        if math.hypot(step[0], step[1]) > 0.5 * duration:  # moving faster than 0.5 m/s
            yaw = math.atan2(step[1], step[0])
        else:
            yaw = self.heading(t0 + duration / 2)
        c, s = math.cos(yaw), math.sin(yaw)
        off = self._offset
        world = np.stack(
            [c * off[:, 0] - s * off[:, 1], s * off[:, 0] + c * off[:, 1], off[:, 2]], axis=1
        )
        m = len(self.parts)
        return PrimitiveTable(
            kind=self._kind,
            centre=p0 + world,
            velocity=np.tile(vel, (m, 1)),
            half=self._half,
            yaw=self._yaw + yaw,
            reflectivity=self._refl,
            label=np.full(m, self.label, np.int8),
            cross_area=np.full(m, self.cross_area),
            mean_free_path=np.zeros(m),
            actor=np.full(m, self.actor_id, np.int32),
            solidity=self._solid,
        )


class Drone(Actor):
    """A drone of a given model; ``path`` gives its body centre."""

    def __init__(self, model: DroneModel, actor_id: int, path: Path, wobble: Wobble | None) -> None:
        area = 0.5 * model.length * model.width
        super().__init__(CLASS_DRONE, actor_id, path, drone_parts(model), area, wobble, 1.0)
        self.model = model


class Bird(Actor):
    """A bird: fast erratic flight (path + strong wobble) and a beating wing pair."""

    def __init__(
        self, actor_id: int, path: Path, wobble: Wobble, span: float, beat_hz: float, phase: float
    ) -> None:
        super().__init__(
            CLASS_BIRD, actor_id, path, bird_parts(span, 0.5), 0.25 * span * span, wobble
        )
        self.span = span
        self.beat_hz = beat_hz
        self.phase = phase

    def update_shape(self, t: float) -> None:
        flap = 0.5 + 0.5 * math.sin(2 * math.pi * self.beat_hz * t + self.phase)
        parts = bird_parts(self.span, flap)
        self._half = np.array([p.half for p in parts], float)


def make_person(actor_id: int, path: Path, height: float) -> Actor:
    """A walking person; ``path`` runs at ground level (feet)."""
    return Actor(CLASS_PERSON, actor_id, path, person_parts(height), 0.0)


def make_car(actor_id: int, path: Path, reflectivity: float) -> Actor:
    """A car driving along ``path`` (at ground level)."""
    return Actor(CLASS_CAR, actor_id, path, car_parts(reflectivity), 0.0)
