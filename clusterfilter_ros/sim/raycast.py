"""Casting one lidar frame's rays into a table of primitives, with angular culling.

A :class:`PrimitiveTable` holds every solid of a frame as flat arrays (static scene
parts, swaying canopies, moving actors). Each primitive may move linearly during the
frame (``velocity``), so a ray fired at time ``t`` meets it at ``centre + velocity * t``
(``t`` relative to the frame start) - at 12 m/s a drone moves 1.2 m within one 100 ms
frame, which a frame-constant pose would smear.

Culling: rays are sorted by azimuth once per frame; every primitive's azimuth interval
(as seen from the sensor, over its swept bounding box) selects a contiguous slice of
rays with ``searchsorted``, which is then filtered by the elevation interval. The
surviving (ray, primitive) pairs go through one vectorised kernel call per primitive
kind, and the nearest hit per ray wins.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clusterfilter_ros.sim.geometry import (
    BOX,
    CYLINDER,
    ELLIPSOID,
    intersect_box,
    intersect_cylinder,
    intersect_ellipsoid,
    intersect_ground,
    surface_normals,
)

#: Point class codes used in the per-point labels.
CLASS_STRUCTURE = 0
CLASS_GROUND = 1
CLASS_VEGETATION = 2
CLASS_PERSON = 3
CLASS_CAR = 4
CLASS_BIRD = 5
CLASS_DRONE = 6
CLASS_NOISE = 7
CLASS_NAMES = {
    CLASS_STRUCTURE: "structure",
    CLASS_GROUND: "ground",
    CLASS_VEGETATION: "vegetation",
    CLASS_PERSON: "person",
    CLASS_CAR: "car",
    CLASS_BIRD: "bird",
    CLASS_DRONE: "drone",
    CLASS_NOISE: "noise",
}


@dataclass
class PrimitiveTable:
    """Primitives of one frame as parallel arrays (M rows).

    Attributes:
        kind: (M,) int8, one of ``geometry.BOX``, ``CYLINDER``, ``ELLIPSOID``.
        centre: (M, 3) centre at the frame start (metres, world frame).
        velocity: (M, 3) linear velocity during the frame (m/s).
        half: (M, 3) half extents (box), semi-axes (ellipsoid) or (radius, radius, half
            height) (cylinder).
        yaw: (M,) rotation about z (radians).
        reflectivity: (M,) diffuse reflectivity 0..1.
        label: (M,) int8 class code (``CLASS_*``).
        cross_area: (M,) area (m^2) of the whole object the part belongs to, used to
            scale the returned energy when the beam footprint is larger; 0 = extended.
        mean_free_path: (M,) > 0 makes an ellipsoid a porous volume (a canopy): a ray
            entering it stops after an exponentially distributed length with this mean,
            or passes through. 0 = solid.
        actor: (M,) int32 id of the object the part belongs to (-1 for static scene).
        solidity: (M,) probability that a ray meeting the part is stopped by it (a
            spinning rotor disc is mostly air); a ray that is not stopped goes on.
    """

    kind: np.ndarray
    centre: np.ndarray
    velocity: np.ndarray
    half: np.ndarray
    yaw: np.ndarray
    reflectivity: np.ndarray
    label: np.ndarray
    cross_area: np.ndarray
    mean_free_path: np.ndarray
    actor: np.ndarray
    solidity: np.ndarray

    def __len__(self) -> int:
        return int(self.kind.shape[0])

    @staticmethod
    def empty() -> PrimitiveTable:
        return PrimitiveTable(
            kind=np.zeros(0, np.int8),
            centre=np.zeros((0, 3)),
            velocity=np.zeros((0, 3)),
            half=np.zeros((0, 3)),
            yaw=np.zeros(0),
            reflectivity=np.zeros(0),
            label=np.zeros(0, np.int8),
            cross_area=np.zeros(0),
            mean_free_path=np.zeros(0),
            actor=np.zeros(0, np.int32),
            solidity=np.zeros(0),
        )

    @staticmethod
    def concat(tables: list[PrimitiveTable]) -> PrimitiveTable:
        tables = [t for t in tables if len(t)]
        if not tables:
            return PrimitiveTable.empty()
        fields = PrimitiveTable.__dataclass_fields__
        return PrimitiveTable(
            **{name: np.concatenate([getattr(t, name) for t in tables]) for name in fields}
        )

    def bounding_boxes(self, duration: float) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned (lo, hi) boxes enclosing each primitive over ``duration`` seconds."""
        radius = np.where(
            (self.kind == CYLINDER)[:, None],
            self.half,
            np.linalg.norm(self.half[:, :2], axis=1, keepdims=True).repeat(3, axis=1),
        )
        radius = radius.copy()
        radius[:, 2] = self.half[:, 2]
        end = self.centre + self.velocity * duration
        lo = np.minimum(self.centre, end) - radius
        hi = np.maximum(self.centre, end) + radius
        return lo, hi


def angular_bounds(
    origin: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Conservative azimuth and elevation intervals of boxes ``[lo, hi]`` seen from ``origin``.

    Returns ``(az_lo, az_hi, el_lo, el_hi)`` in radians. ``az_lo`` is in [-pi, pi) and
    ``az_hi`` may exceed pi (wrap-around); a box around the vertical through the origin
    gets the full circle.
    """
    x0, y0, z0 = (lo - origin).T
    x1, y1, z1 = (hi - origin).T
    cx = np.stack([x0, x1, x1, x0], axis=1)
    cy = np.stack([y0, y0, y1, y1], axis=1)
    centre_az = np.arctan2(0.5 * (y0 + y1), 0.5 * (x0 + x1))
    corner_az = np.arctan2(cy, cx)
    rel = (corner_az - centre_az[:, None] + np.pi) % (2 * np.pi) - np.pi
    az_lo = centre_az + rel.min(axis=1)
    az_hi = centre_az + rel.max(axis=1)
    contains = (x0 <= 0) & (x1 >= 0) & (y0 <= 0) & (y1 >= 0)
    az_lo = np.where(contains, -np.pi, az_lo)
    az_hi = np.where(contains, np.pi, az_hi)
    shift = np.where(az_lo < -np.pi, 2 * np.pi, 0.0)
    az_lo += shift
    az_hi += shift
    # Horizontal distance range from the origin to the rectangle.
    dx_near = np.maximum(np.maximum(x0, -x1), 0.0)
    dy_near = np.maximum(np.maximum(y0, -y1), 0.0)
    rho_min = np.hypot(dx_near, dy_near)
    rho_max = np.hypot(np.maximum(np.abs(x0), np.abs(x1)), np.maximum(np.abs(y0), np.abs(y1)))
    el_hi = np.where(z1 >= 0, np.arctan2(z1, rho_min), np.arctan2(z1, rho_max))
    el_lo = np.where(z0 >= 0, np.arctan2(z0, rho_max), np.arctan2(z0, rho_min))
    return az_lo, az_hi, el_lo, el_hi


@dataclass
class Hits:
    """The rays that met a surface (K of the frame's N) and what they met."""

    ray: np.ndarray  # (K,) index of the ray
    t: np.ndarray  # (K,) distance
    normal: np.ndarray  # (K, 3)
    reflectivity: np.ndarray  # (K,)
    label: np.ndarray  # (K,) int8
    cross_area: np.ndarray  # (K,)
    volumetric: np.ndarray  # (K,) bool, hit inside a porous volume
    actor: np.ndarray  # (K,) int32


#: Azimuth bin width (rad) of the culling grid.
AZ_BIN = np.radians(2.0)
_N_BINS = int(np.ceil(2 * np.pi / AZ_BIN))


def _culled_pairs(
    az: np.ndarray,
    el: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """(ray index, primitive index) pairs whose ray lies inside the primitive's angular box.

    Rays are sorted by (azimuth bin, elevation); each primitive visits the bins its
    azimuth interval covers and takes, per bin, the contiguous run of rays inside its
    elevation interval (two ``searchsorted`` per primitive-bin, all vectorised). The
    runs are expanded into pairs and trimmed to the exact azimuth interval.
    """
    az_lo, az_hi, el_lo, el_hi = bounds
    if len(az_lo) == 0 or len(az) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    keep = np.flatnonzero((el_hi >= el.min()) & (el_lo <= el.max()))
    if len(keep) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    ray_bin = np.minimum(((az + np.pi) / AZ_BIN).astype(np.int64), _N_BINS - 1)
    key = ray_bin * 4.0 + (el + np.pi / 2)
    order = np.argsort(key)
    key_sorted = key[order]
    # Bins covered by each primitive (az_hi may run past pi: wrap the bin index).
    b0 = np.floor((az_lo[keep] + np.pi) / AZ_BIN).astype(np.int64)
    b1 = np.floor((az_hi[keep] + np.pi) / AZ_BIN).astype(np.int64)
    nb = np.minimum(b1 - b0 + 1, _N_BINS)
    prim = np.repeat(keep, nb)
    local = np.arange(int(nb.sum())) - np.repeat(np.cumsum(nb) - nb, nb)
    bins = (np.repeat(b0, nb) + local) % _N_BINS
    lo_key = bins * 4.0 + (el_lo[prim] + np.pi / 2)
    hi_key = bins * 4.0 + (el_hi[prim] + np.pi / 2)
    first = np.searchsorted(key_sorted, lo_key, side="left")
    last = np.searchsorted(key_sorted, hi_key, side="right")
    counts = np.maximum(last - first, 0)
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    pair_prim = np.repeat(prim, counts)
    offsets = np.repeat(first - (np.cumsum(counts) - counts), counts)
    pair_ray = order[np.arange(total) + offsets]
    # Exact azimuth test, modulo a full turn.
    rel = (az[pair_ray] - az_lo[pair_prim]) % (2 * np.pi)
    ok = rel <= (az_hi[pair_prim] - az_lo[pair_prim])
    return pair_ray[ok], pair_prim[ok]


def cast_rays(
    origin: np.ndarray,
    dirs: np.ndarray,
    ray_time: np.ndarray,
    table: PrimitiveTable,
    bounds: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    ground_z: float,
    ground_reflectivity: float,
    rng: np.random.Generator,
    az_el: tuple[np.ndarray, np.ndarray] | None = None,
) -> Hits:
    """Nearest hit of every ray against the ground plane and the primitives in ``table``.

    Args:
        origin: (3,) sensor position.
        dirs: (N, 3) unit ray directions.
        ray_time: (N,) firing time of each ray relative to the frame start (seconds).
        table: the frame's primitives; ``bounds`` their angular intervals from
            :func:`angular_bounds` (computed over the frame's motion).
        ground_z: height of the ground plane; ``ground_reflectivity`` its reflectivity.
        rng: draws the stopping depth inside porous volumes.
        az_el: the rays' azimuth and elevation if already known.
    """
    n = dirs.shape[0]
    if az_el is None:
        az = np.arctan2(dirs[:, 1], dirs[:, 0])
        el = np.arcsin(np.clip(dirs[:, 2], -1.0, 1.0))
    else:
        az, el = az_el
    nearest = intersect_ground(origin, dirs, ground_z)
    pair_ray, pair_prim = _culled_pairs(az, el, bounds)
    if len(pair_ray):
        t_pair, porous_pair = _pair_distances(
            origin, dirs, ray_time, table, pair_ray, pair_prim, rng
        )
        finite = np.isfinite(t_pair)
        pair_ray, pair_prim = pair_ray[finite], pair_prim[finite]
        t_pair, porous_pair = t_pair[finite], porous_pair[finite]
        np.minimum.at(nearest, pair_ray, t_pair)
        win = np.flatnonzero(t_pair <= nearest[pair_ray])
        # Keep one winner per ray (exact ties are possible where primitives touch).
        _, first = np.unique(pair_ray[win], return_index=True)
        win = win[first]
    else:
        win = np.zeros(0, np.int64)
    ray = np.flatnonzero(np.isfinite(nearest))
    k = len(ray)
    slot = np.full(n, -1, np.int64)
    slot[ray] = np.arange(k)
    hits = Hits(
        ray=ray,
        t=nearest[ray],
        normal=np.tile(np.array([0.0, 0.0, 1.0]), (k, 1)),
        reflectivity=np.full(k, ground_reflectivity),
        label=np.full(k, CLASS_GROUND, np.int8),
        cross_area=np.zeros(k),
        volumetric=np.zeros(k, bool),
        actor=np.full(k, -1, np.int32),
    )
    if len(win):
        rays, prims = pair_ray[win], pair_prim[win]
        s = slot[rays]
        t_win = t_pair[win]
        centre = table.centre[prims] + table.velocity[prims] * ray_time[rays, None]
        points = origin + dirs[rays] * t_win[:, None]
        hits.normal[s] = surface_normals(
            table.kind[prims],
            points,
            centre,
            table.half[prims],
            np.cos(table.yaw[prims]),
            np.sin(table.yaw[prims]),
        )
        hits.reflectivity[s] = table.reflectivity[prims]
        hits.label[s] = table.label[prims]
        hits.cross_area[s] = table.cross_area[prims]
        hits.volumetric[s] = porous_pair[win]
        hits.actor[s] = table.actor[prims]
    return hits


def _pair_distances(
    origin: np.ndarray,
    dirs: np.ndarray,
    ray_time: np.ndarray,
    table: PrimitiveTable,
    pair_ray: np.ndarray,
    pair_prim: np.ndarray,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Hit distance of every (ray, primitive) pair (inf on a miss) and whether it is porous."""
    t_pair = np.full(len(pair_ray), np.inf)
    porous_pair = np.zeros(len(pair_ray), bool)
    kind = table.kind[pair_prim]
    moving = np.any(table.velocity != 0.0, axis=1)
    cos_all, sin_all = np.cos(table.yaw), np.sin(table.yaw)
    for k in (BOX, CYLINDER, ELLIPSOID):
        sel = np.flatnonzero(kind == k)
        if len(sel) == 0:
            continue
        prim = pair_prim[sel]
        ray = pair_ray[sel]
        centre = table.centre[prim]
        mv = np.flatnonzero(moving[prim])
        if len(mv):
            centre[mv] += table.velocity[prim[mv]] * ray_time[ray[mv], None]
        d = dirs[ray]
        half = table.half[prim]
        if k == BOX:
            t = intersect_box(origin, d, centre, half, cos_all[prim], sin_all[prim])
        elif k == CYLINDER:
            t = intersect_cylinder(origin, d, centre, half[:, 0], half[:, 2])
        else:
            t, t_out = intersect_ellipsoid(origin, d, centre, half, cos_all[prim], sin_all[prim])
            mfp = table.mean_free_path[prim]
            porous = (mfp > 0) & np.isfinite(t)
            if porous.any():
                depth = rng.exponential(1.0, size=int(porous.sum())) * mfp[porous]
                stop = t[porous] + depth
                t[porous] = np.where(stop < t_out[porous], stop, np.inf)
                porous_pair[sel[porous]] = True
        t_pair[sel] = t
    solidity = table.solidity[pair_prim]
    partial = np.flatnonzero((solidity < 1.0) & np.isfinite(t_pair))
    if len(partial):
        passes = rng.random(len(partial)) >= solidity[partial]
        t_pair[partial[passes]] = np.inf
    return t_pair, porous_pair


class PrimitiveBuilder:
    """Collects static primitives one by one and builds a :class:`PrimitiveTable`."""

    def __init__(self) -> None:
        self._rows: list[tuple] = []

    def _add(self, kind, centre, half, yaw, reflectivity, label, cross_area, mfp, solidity):
        self._rows.append((kind, centre, half, yaw, reflectivity, label, cross_area, mfp, solidity))

    def box(
        self,
        lo: tuple[float, float, float],
        hi: tuple[float, float, float],
        reflectivity: float,
        label: int = CLASS_STRUCTURE,
        yaw: float = 0.0,
    ) -> None:
        """An upright box between corners ``lo`` and ``hi`` (before rotation by ``yaw``)."""
        lo_a, hi_a = np.asarray(lo, float), np.asarray(hi, float)
        self._add(BOX, (lo_a + hi_a) / 2, (hi_a - lo_a) / 2, yaw, reflectivity, label, 0, 0, 1)

    def cylinder(
        self,
        x: float,
        y: float,
        z0: float,
        z1: float,
        radius: float,
        reflectivity: float,
        label: int = CLASS_STRUCTURE,
    ) -> None:
        """A vertical cylinder from height ``z0`` to ``z1``."""
        half = (radius, radius, (z1 - z0) / 2)
        self._add(CYLINDER, (x, y, (z0 + z1) / 2), half, 0.0, reflectivity, label, 0, 0, 1)

    def ellipsoid(
        self,
        centre: tuple[float, float, float],
        semi_axes: tuple[float, float, float],
        reflectivity: float,
        label: int = CLASS_STRUCTURE,
        yaw: float = 0.0,
        mean_free_path: float = 0.0,
    ) -> None:
        """An ellipsoid; ``mean_free_path`` > 0 makes it a porous volume (foliage)."""
        self._add(ELLIPSOID, centre, semi_axes, yaw, reflectivity, label, 0, mean_free_path, 1)

    def build(self) -> PrimitiveTable:
        if not self._rows:
            return PrimitiveTable.empty()
        cols = list(zip(*self._rows, strict=True))
        m = len(self._rows)
        return PrimitiveTable(
            kind=np.array(cols[0], np.int8),
            centre=np.array(cols[1], float).reshape(m, 3),
            velocity=np.zeros((m, 3)),
            half=np.array(cols[2], float).reshape(m, 3),
            yaw=np.array(cols[3], float),
            reflectivity=np.array(cols[4], float),
            label=np.array(cols[5], np.int8),
            cross_area=np.array(cols[6], float),
            mean_free_path=np.array(cols[7], float),
            actor=np.full(m, -1, np.int32),
            solidity=np.array(cols[8], float),
        )
