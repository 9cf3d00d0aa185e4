"""Named MMAUD-like scenarios and the simulation that renders them frame by frame.

Entry points:
- :data:`SCENARIOS` - the named :class:`ScenarioSpec` objects.
- :func:`simulate` - a whole :class:`SimulatedSequence` in memory (short sequences).
- :func:`stream_frames` - ``(Frame, drone_mask)`` in time order with bounded memory,
  for hour-long streams.
- :class:`Simulation` - the underlying object: frames with per-point class labels,
  dense drone truth and total-station ground truth on demand.

Everything is deterministic for a given (scenario, seed, duration, drone): the scene
and flights come from one generator, and every frame draws its noise from its own
generator seeded by (seed, sensor, frame index), so streamed and in-memory runs agree.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from clusterfilter_ros.core.frame import AVIA, MID360, Frame, Sequence, TimedPositions
from clusterfilter_ros.errors import ParameterError
from clusterfilter_ros.sim import flights
from clusterfilter_ros.sim.actors import (
    DRONE_MODELS,
    Actor,
    Bird,
    Drone,
    make_car,
    make_person,
)
from clusterfilter_ros.sim.raycast import (
    CLASS_DRONE,
    CLASS_NOISE,
    PrimitiveTable,
    angular_bounds,
    cast_rays,
)
from clusterfilter_ros.sim.scene import GROUND_Z, Scene, build_car_park
from clusterfilter_ros.sim.sensors import LidarModel, avia, mid360
from clusterfilter_ros.sim.trajectory import Path, Waypoint, Wobble

#: Rig clock at the start of every simulated sequence (a January 2024 epoch like MMAUD's).
START_EPOCH = 1706255600.0
#: Default prism position above the drone's body centre, body frame (m).
DEFAULT_PRISM_OFFSET = (0.0, 0.0, 0.25)
#: Rows per file in the challenge format (Mid360 alternates, Avia fixed).
PAD_ROWS = {MID360: [19968, 20064], AVIA: 24000}
GRAVITY = 9.81
#: Longest sequence the flight planners are asked for (s).
MAX_DURATION = 86400.0


@dataclass(frozen=True)
class ScenarioSpec:
    """A named scenario: how long, which drone and flight, which distractors.

    Attributes:
        name, description: identification and a one-line summary.
        duration: default length (s).
        drone: default drone model name (a key of ``DRONE_MODELS``) or None (no drone).
        flight: planner returning the drone's waypoints (see :mod:`.flights`).
        lead_time: seconds the flight has been going before the sequence starts.
        cruise_speed, max_speed, max_acceleration: drone path limits.
        people, cars: walking people and driving cars.
        birds_low, birds_overhead, birds_near_drone: birds flying around the car park,
            above the rig (Avia cone), and circling the drone 3-10 m away.
    """

    name: str
    description: str
    duration: float
    drone: str | None
    flight: flights.Planner | None
    lead_time: float = 0.0
    cruise_speed: float = 5.0
    max_speed: float = 12.0
    max_acceleration: float = 4.0
    people: int = 3
    cars: int = 1
    birds_low: int = 1
    birds_overhead: int = 0
    birds_near_drone: int = 0


def _scenarios() -> dict[str, ScenarioSpec]:
    specs = [
        ScenarioSpec(
            "default",
            "drone arrives, hovers at ~13 m, climbs over the rig (Avia cone), leaves; "
            "car park with people, a car, trees",
            20.0,
            "phantom4",
            flights.default_flight,
            lead_time=2.0,
        ),
        ScenarioSpec(
            "takeoff_landing",
            "take-off from a pad beside the rig, loop with a hover, return and landing",
            45.0,
            "phantom4",
            flights.takeoff_landing_flight,
        ),
        ScenarioSpec(
            "flyover",
            "two overhead passes at ~40 m and ~90 m altitude (mostly seen by the Avia)",
            40.0,
            "m300",
            flights.flyover_flight,
            lead_time=3.0,
            cruise_speed=8.0,
        ),
        ScenarioSpec(
            "fast_pass",
            "12 m/s passes from ~95 m out to within 5 m of the rig and away",
            20.0,
            "mavic3",
            flights.fast_pass_flight,
            lead_time=3.0,
            cruise_speed=12.0,
        ),
        ScenarioSpec(
            "hover",
            "hovering at 18-30 m range, 12 m up, drifting in the wind",
            20.0,
            "avata",
            flights.hover_flight,
        ),
        ScenarioSpec(
            "birds",
            "the default flight with birds around, three of them circling the drone",
            20.0,
            "mavic2",
            flights.default_flight,
            lead_time=2.0,
            birds_low=3,
            birds_overhead=2,
            birds_near_drone=3,
        ),
        ScenarioSpec(
            "no_drone",
            "no drone: people, a car, two birds, swaying trees",
            20.0,
            None,
            None,
            people=4,
            birds_low=2,
        ),
        ScenarioSpec(
            "no_drone_birds",
            "no drone: a dozen birds, some overhead, plus people and a car",
            20.0,
            None,
            None,
            people=2,
            birds_low=7,
            birds_overhead=5,
        ),
        ScenarioSpec(
            "avia_only",
            "drone 42-85 m up, always above 60 deg elevation: only the Avia sees it",
            20.0,
            "phantom4",
            flights.avia_only_flight,
            lead_time=2.0,
            birds_low=1,
        ),
        ScenarioSpec(
            "long_mixed",
            "2.5 min: take-off, passes, hover, out of range and back, overhead, landing",
            150.0,
            "mavic3",
            flights.long_mixed_flight,
            birds_low=2,
            birds_overhead=1,
        ),
    ]
    for model in DRONE_MODELS:
        specs.append(
            ScenarioSpec(
                f"model_{model}",
                f"the default flight with the {model}",
                20.0,
                model,
                flights.default_flight,
                lead_time=2.0,
            )
        )
    return {s.name: s for s in specs}


#: Every named scenario.
SCENARIOS: dict[str, ScenarioSpec] = _scenarios()


class _OrbitPath:
    """Path of a bird circling another actor at a varying radius (duck-types :class:`Path`)."""

    def __init__(self, target: Actor, rng: np.random.Generator) -> None:
        self.target = target
        self.radius = rng.uniform(3.0, 8.0)
        self.radius_swing = rng.uniform(0.5, 2.5)
        self.omega = rng.choice([-1.0, 1.0]) * rng.uniform(0.6, 1.4)
        self.phase = rng.uniform(0, 2 * np.pi)
        self.height = rng.uniform(-2.0, 3.0)
        self.knots = np.zeros((2, 3))
        self.knots[1, 0] = 1.0
        self.knot_times = np.array([-1e9, 1e9])

    def _offset(self, t: np.ndarray, derivative: int) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        ang = self.omega * t + self.phase
        r = self.radius + self.radius_swing * np.sin(0.37 * t)
        if derivative == 0:
            return np.stack([r * np.cos(ang), r * np.sin(ang), np.full_like(t, self.height)], -1)
        if derivative == 1:
            dr = self.radius_swing * 0.37 * np.cos(0.37 * t)
            vx = dr * np.cos(ang) - r * self.omega * np.sin(ang)
            vy = dr * np.sin(ang) + r * self.omega * np.cos(ang)
            return np.stack([vx, vy, np.zeros_like(t)], -1)
        w2 = self.omega**2
        return np.stack([-r * w2 * np.cos(ang), -r * w2 * np.sin(ang), np.zeros_like(t)], -1)

    def position(self, t):
        p = self.target.position(t) + self._offset(t, 0)
        p[..., 2] = np.maximum(p[..., 2], GROUND_Z + 1.5)
        return p

    def velocity(self, t):
        return self.target.velocity(t) + self._offset(t, 1)

    def acceleration(self, t):
        return self.target.acceleration(t) + self._offset(t, 2)


@dataclass
class SimFrame:
    """One rendered lidar frame with per-point truth.

    ``classes`` are ``raycast.CLASS_*`` codes, ``actor_ids`` the id of the moving object
    that produced each point (-1 for scene and noise); ``index`` counts this sensor's frames.
    """

    frame: Frame
    classes: np.ndarray
    actor_ids: np.ndarray
    index: int

    @property
    def drone_mask(self) -> np.ndarray:
        return self.classes == CLASS_DRONE


class Simulation:
    """A scenario instance: scene, sensors and actors, rendered on demand.

    Args:
        scenario: a key of :data:`SCENARIOS`, or a :class:`ScenarioSpec`.
        seed: seeds every random choice.
        duration: seconds (None: the scenario's default).
        drone: drone model overriding the scenario's (a key of ``DRONE_MODELS``).
        prism_offset: prism position above the body centre in the body frame (m).
    """

    def __init__(
        self,
        scenario: str | ScenarioSpec = "default",
        seed: int = 0,
        duration: float | None = None,
        drone: str | None = None,
        prism_offset: tuple[float, float, float] = DEFAULT_PRISM_OFFSET,
    ) -> None:
        if isinstance(scenario, ScenarioSpec):
            spec = scenario
            scenario = spec.name
        elif scenario in SCENARIOS:
            spec = SCENARIOS[scenario]
        else:
            raise ParameterError(
                f"unknown scenario '{scenario}'; choose one of: {', '.join(SCENARIOS)}"
            )
        if duration is None:
            duration = spec.duration
        if not (isinstance(duration, int | float) and math.isfinite(duration) and duration > 0):
            raise ParameterError(f"duration must be a positive number of seconds, got {duration!r}")
        if duration > MAX_DURATION:
            raise ParameterError(
                f"duration {duration:g} s is longer than the {MAX_DURATION:g} s (24 h) the "
                "simulator plans flights for"
            )
        if drone is not None:
            if drone not in DRONE_MODELS:
                raise ParameterError(
                    f"unknown drone '{drone}'; choose one of: {', '.join(DRONE_MODELS)}"
                )
            if spec.drone is None:
                raise ParameterError(f"scenario '{scenario}' has no drone; --drone does not apply")
        if not isinstance(seed, int | np.integer) or seed < 0:
            raise ParameterError(f"seed must be a non-negative integer, got {seed!r}")
        self.spec = spec
        self.seed = int(seed)
        self.duration = float(duration)
        self.prism_offset = np.asarray(prism_offset, dtype=np.float64).reshape(3)
        self.start_epoch = START_EPOCH
        rng = np.random.default_rng([self.seed, 0x5EED])
        self.scene: Scene = build_car_park(rng)
        self.sensors: list[LidarModel] = [mid360(), avia()]
        self.actors: list[Actor] = []
        self.drone: Drone | None = None
        model_name = drone or spec.drone
        if model_name is not None and spec.flight is not None:
            model = DRONE_MODELS[model_name]
            waypoints = spec.flight(rng, self.duration + spec.lead_time, model.height)
            path = Path(
                waypoints,
                start_time=-spec.lead_time,
                cruise_speed=spec.cruise_speed,
                max_speed=spec.max_speed,
                max_acceleration=spec.max_acceleration,
            )
            wobble = Wobble(rng, (0.15, 0.15, 0.06), (3.0, 9.0))
            self.drone = Drone(model, 0, path, wobble)
            self.actors.append(self.drone)
        next_id = 1
        for _ in range(spec.people):
            route = flights.walking_route(rng, self.duration + 5)
            path = Path(route, start_time=-rng.uniform(0, 5), max_speed=1.8, max_acceleration=1.0)
            self.actors.append(make_person(next_id, path, rng.uniform(1.55, 1.9)))
            next_id += 1
        for _ in range(spec.cars):
            route = flights.driving_route(rng, self.duration + 5)
            path = Path(route, start_time=-rng.uniform(0, 5), max_speed=8.0, max_acceleration=2.5)
            self.actors.append(make_car(next_id, path, float(rng.choice([0.2, 0.5, 0.8]))))
            next_id += 1
        bird_kinds = ["low"] * spec.birds_low + ["overhead"] * spec.birds_overhead
        if self.drone is not None:
            bird_kinds += ["near"] * spec.birds_near_drone
        for kind in bird_kinds:
            wobble = Wobble(rng, (1.0, 1.0, 0.6), (0.7, 2.5))
            if kind == "near":
                path = _OrbitPath(self.drone, rng)
            else:
                route = flights.bird_route(rng, self.duration, overhead=kind == "overhead")
                path = Path(
                    route, start_time=-rng.uniform(0, 3), max_speed=16.0, max_acceleration=12.0
                )
            bird = Bird(
                next_id,
                path,  # type: ignore[arg-type]
                wobble,
                span=rng.uniform(0.25, 0.45),
                beat_hz=rng.uniform(3.0, 7.0),
                phase=rng.uniform(0, 2 * np.pi),
            )
            self.actors.append(bird)
            next_id += 1

    # --- timing -----------------------------------------------------------------

    def frame_count(self, sensor: LidarModel) -> int:
        return int(math.floor(self.duration / sensor.frame_period + 1e-9))

    def frame_start(self, sensor: LidarModel, index: int) -> float:
        """Start of a frame in seconds since the sequence start (stamp minus the epoch)."""
        sid = self.sensors.index(sensor)
        jitter = np.random.default_rng([self.seed, 0x57A3, sid, index]).normal(
            0, sensor.stamp_jitter
        )
        return (
            index * sensor.frame_period
            + sensor.stamp_offset
            + float(np.clip(jitter, -0.002, 0.002))
        )

    # --- rendering ----------------------------------------------------------------

    def render(self, sensor: LidarModel, index: int) -> SimFrame:
        """Ray-cast one frame of one sensor."""
        sid = self.sensors.index(sensor)
        rng = np.random.default_rng([self.seed, sid, index])
        t0 = self.frame_start(sensor, index)
        period = sensor.frame_period
        dirs, ray_time, az_el = sensor.scan_angles(index)
        origin = sensor.origin
        scene_table = self.scene.table_at(t0)
        actor_tables = [a.table(t0, period) for a in self.actors]
        actor_table = PrimitiveTable.concat(actor_tables)
        small = np.flatnonzero(actor_table.cross_area > 0)
        if len(small):
            # A small target anywhere inside the beam footprint returns light: grow it by
            # the footprint radius at its range (a 0.2 deg beam is ~9 cm wide at 25 m).
            distance = np.linalg.norm(actor_table.centre[small] - origin, axis=1)
            actor_table.half[small] += (0.5 * distance * sensor.divergence_rad)[:, None]
        static_bounds = self.scene.bounds_from(origin)
        if len(actor_table):
            lo, hi = actor_table.bounding_boxes(period)
            dyn_bounds = angular_bounds(origin, lo, hi)
            bounds = tuple(
                np.concatenate([s, d]) for s, d in zip(static_bounds, dyn_bounds, strict=True)
            )
        else:
            bounds = static_bounds
        table = PrimitiveTable.concat([scene_table, actor_table])
        hits = cast_rays(
            origin,
            dirs,
            ray_time,
            table,
            bounds,
            self.scene.ground_z,
            self.scene.ground_reflectivity,
            rng,
            az_el,
        )
        hit_dirs = dirs[hits.ray]
        cos_inc = np.abs(np.einsum("ij,ij->i", hits.normal, hit_dirs))
        # Foliage and small bodies (rounded shells, rotors) scatter about as a sphere does.
        cos_inc = np.where(hits.volumetric | (hits.cross_area > 0), 0.7, cos_inc)
        prob = sensor.return_probability(hits.t, hits.reflectivity, cos_inc, hits.cross_area)
        keep = (hits.t > sensor.min_range) & (rng.random(len(hits.t)) < prob)
        idx = np.flatnonzero(keep)
        ray_idx = hits.ray[idx]
        rng_noise = rng.normal(0.0, sensor.range_sigma, len(idx))
        dist = hits.t[idx] + rng_noise
        d = hit_dirs[idx] + rng.normal(0.0, math.radians(sensor.angle_sigma_deg), (len(idx), 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        xyz = origin + d * dist[:, None]
        refl = hits.reflectivity[idx] * np.clip(cos_inc[idx], 0.2, 1.0)
        intensity = np.clip(refl * 255.0 * rng.uniform(0.8, 1.2, len(idx)), 1.0, 255.0)
        classes = hits.label[idx].astype(np.int8)
        actor_ids = hits.actor[idx].astype(np.int32)
        times = ray_time[ray_idx]
        if sensor.sky_noise_per_frame > 0:
            lam = rng.gamma(1.0, sensor.sky_noise_per_frame)
            n_noise = int(rng.poisson(lam))
            returned = np.zeros(len(dirs), bool)
            returned[ray_idx] = True
            free = np.flatnonzero(~returned)
            if n_noise and len(free):
                pick = rng.choice(free, size=min(n_noise, len(free)), replace=False)
                pick.sort()
                r0, r1 = sensor.sky_noise_range
                noise_dist = np.exp(rng.uniform(math.log(r0), math.log(r1), len(pick)))
                noise_xyz = origin + dirs[pick] * noise_dist[:, None]
                xyz = np.concatenate([xyz, noise_xyz])
                intensity = np.concatenate([intensity, rng.uniform(1.0, 8.0, len(pick))])
                classes = np.concatenate([classes, np.full(len(pick), CLASS_NOISE, np.int8)])
                actor_ids = np.concatenate([actor_ids, np.full(len(pick), -1, np.int32)])
                times = np.concatenate([times, ray_time[pick]])
                order = np.argsort(times, kind="stable")
                xyz, intensity, classes = xyz[order], intensity[order], classes[order]
                actor_ids, times = actor_ids[order], times[order]
        frame = Frame(
            stamp=self.start_epoch + t0,
            sensor=sensor.sensor,
            xyz=xyz.astype(np.float32),
            intensity=intensity.astype(np.float32),
            point_time=times,
        )
        return SimFrame(frame, classes, actor_ids, index)

    def iter_frames(self) -> Iterator[SimFrame]:
        """All frames of both sensors in stamp order, rendered one at a time."""
        counts = [self.frame_count(s) for s in self.sensors]
        nxt = [0 for _ in self.sensors]
        starts = [
            self.frame_start(s, 0) if c else math.inf
            for s, c in zip(self.sensors, counts, strict=True)
        ]
        while True:
            i = int(np.argmin(starts))
            if not math.isfinite(starts[i]):
                return
            sensor = self.sensors[i]
            yield self.render(sensor, nxt[i])
            nxt[i] += 1
            starts[i] = self.frame_start(sensor, nxt[i]) if nxt[i] < counts[i] else math.inf

    # --- truth ----------------------------------------------------------------------

    def drone_truth(self, rate_hz: float = 100.0) -> TimedPositions:
        """True body centre of the drone on a regular grid (empty without a drone).

        ``extra`` holds ``velocity`` (M, 3) and ``yaw`` (M,).
        """
        if self.drone is None:
            return TimedPositions(np.zeros(0), np.zeros((0, 3)))
        t = np.arange(0.0, self.duration + 1e-9, 1.0 / rate_hz)
        return TimedPositions(
            self.start_epoch + t,
            self.drone.position(t),
            extra={"velocity": self.drone.velocity(t), "yaw": self.drone.headings(t)},
        )

    def prism_positions(self, t: np.ndarray) -> np.ndarray:
        """Prism position at times ``t`` (s since start): the body offset tilted with thrust."""
        drone = self.drone
        assert drone is not None
        p = drone.position(t)
        thrust = drone.acceleration(t) + np.array([0.0, 0.0, GRAVITY])
        z_b = thrust / np.linalg.norm(thrust, axis=1, keepdims=True)
        yaw = drone.headings(t)
        fwd = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=1)
        x_b = fwd - np.einsum("ij,ij->i", fwd, z_b)[:, None] * z_b
        x_b /= np.linalg.norm(x_b, axis=1, keepdims=True)
        y_b = np.cross(z_b, x_b)
        o = self.prism_offset
        return p + o[0] * x_b + o[1] * y_b + o[2] * z_b

    def ground_truth(self) -> TimedPositions:
        """Total-station track of the prism: 10-20 Hz, irregular spacing, ~3 mm noise.

        Empty when there is no drone.
        """
        if self.drone is None:
            return TimedPositions(np.zeros(0), np.zeros((0, 3)))
        rng = np.random.default_rng([self.seed, 0x6E0])
        n_max = int(self.duration / 0.05) + 2
        steps = rng.uniform(0.05, 0.1, n_max)
        t = rng.uniform(0.0, 0.05) + np.concatenate([[0.0], np.cumsum(steps[:-1])])
        t = t[t < self.duration]
        xyz = self.prism_positions(t) + rng.normal(0.0, 0.003, (len(t), 3))
        return TimedPositions(self.start_epoch + t, xyz)

    def drone_inside_scene(self, t: np.ndarray) -> np.ndarray:
        """Whether the drone's body centre is within the Mid360's nominal 70 m range."""
        assert self.drone is not None
        return np.linalg.norm(self.drone.position(t), axis=-1) <= 70.0


@dataclass
class SimulatedSequence:
    """A simulated recording with everything the detector must not see, for scoring.

    Attributes:
        sequence: frames of both lidars in stamp order (padding removed) and the
            total-station prism track as ground truth.
        drone_truth: dense (100 Hz) true body centre; empty without a drone.
        prism_offset: prism position above the body centre (body frame, m).
        pad_rows: rows per challenge file (``mid360``: list used cyclically, ``avia``: int).
        labels: frame index (in ``sequence.frames``) -> bool mask of drone points.
        classes: frame index -> int8 class code per point (``raycast.CLASS_*``).
        scenario, seed, drone_model: what was simulated.
    """

    sequence: Sequence
    drone_truth: TimedPositions
    prism_offset: np.ndarray
    pad_rows: dict[str, int | list[int]]
    labels: dict[int, np.ndarray]
    classes: dict[int, np.ndarray]
    scenario: str
    seed: int
    drone_model: str | None = None
    sensor_positions: dict[str, np.ndarray] = field(default_factory=dict)


def simulate(
    scenario: str = "default",
    seed: int = 0,
    duration: float | None = None,
    drone: str | None = None,
    prism_offset: tuple[float, float, float] = DEFAULT_PRISM_OFFSET,
    progress=None,
) -> SimulatedSequence:
    """Render a whole scenario in memory.

    ``progress`` (optional) is called with the number of frames done after each frame.
    """
    sim = Simulation(scenario, seed, duration, drone, prism_offset)
    frames: list[Frame] = []
    labels: dict[int, np.ndarray] = {}
    classes: dict[int, np.ndarray] = {}
    for i, sf in enumerate(sim.iter_frames()):
        frames.append(sf.frame)
        labels[i] = sf.drone_mask
        classes[i] = sf.classes
        if progress is not None:
            progress(i + 1)
    name = f"sim_{scenario}_s{seed}"
    return SimulatedSequence(
        sequence=Sequence(name, frames, sim.ground_truth()),
        drone_truth=sim.drone_truth(),
        prism_offset=sim.prism_offset.copy(),
        pad_rows={k: (list(v) if isinstance(v, list) else v) for k, v in PAD_ROWS.items()},
        labels=labels,
        classes=classes,
        scenario=scenario,
        seed=seed,
        drone_model=sim.drone.model.name if sim.drone is not None else None,
        sensor_positions={s.sensor: s.origin for s in sim.sensors},
    )


def total_frames(scenario: str = "default", duration: float | None = None) -> int:
    """Number of frames (both sensors) a run of ``scenario`` produces."""
    spec = SCENARIOS[scenario]
    d = spec.duration if duration is None else duration
    return 2 * int(math.floor(d / 0.1 + 1e-9))


def stream_frames(
    scenario: str = "default",
    seed: int = 0,
    duration: float | None = None,
    drone: str | None = None,
) -> Iterator[tuple[Frame, np.ndarray]]:
    """Yield ``(frame, drone_mask)`` in stamp order, one frame in memory at a time."""
    sim = Simulation(scenario, seed, duration, drone)
    for sf in sim.iter_frames():
        yield sf.frame, sf.drone_mask


def iter_simulate(
    scenario: str = "default",
    seed: int = 0,
    duration: float | None = None,
    drone: str | None = None,
) -> Iterator[SimFrame]:
    """Yield :class:`SimFrame` (frame, per-point classes and actor ids) in stamp order."""
    return Simulation(scenario, seed, duration, drone).iter_frames()


__all__ = [
    "PAD_ROWS",
    "SCENARIOS",
    "ScenarioSpec",
    "SimFrame",
    "SimulatedSequence",
    "Simulation",
    "Waypoint",
    "iter_simulate",
    "simulate",
    "stream_frames",
    "total_frames",
]
