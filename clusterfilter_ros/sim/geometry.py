"""Vectorised ray intersection with the simulator's solid primitives.

Every kernel takes *pairs*: row ``i`` tests ray ``i`` against primitive ``i``, so one call
handles many rays against many primitives (the caller builds the pairs by angular
culling, see :mod:`clusterfilter_ros.sim.raycast`). Rays start at ``origin`` (a shared
(3,) sensor position or one per pair) and have unit directions ``dirs`` (P, 3).
Primitives can be rotated about the vertical axis only (yaw), which is all a car park
needs. A miss is reported as ``t = inf``.

Kinds:
- box: centre, half extents (hx, hy, hz) in its own yawed frame (slab test);
- vertical cylinder: centre (x, y, z_mid), radius, half height, with flat caps;
- ellipsoid: centre, semi-axes (a, b, c) in its own yawed frame; also returns the exit
  distance so a volume (a tree canopy) can stop a ray somewhere inside it.
"""

from __future__ import annotations

import numpy as np

BOX = 0
CYLINDER = 1
ELLIPSOID = 2
KIND_NAMES = {BOX: "box", CYLINDER: "cylinder", ELLIPSOID: "ellipsoid"}


def _local_rays(origin, dirs, centre, cos_yaw, sin_yaw):
    """Ray origin and direction components in the primitive's yawed frame (6 arrays)."""
    rx = origin[0] - centre[:, 0] if origin.ndim == 1 else origin[:, 0] - centre[:, 0]
    ry = origin[1] - centre[:, 1] if origin.ndim == 1 else origin[:, 1] - centre[:, 1]
    rz = origin[2] - centre[:, 2] if origin.ndim == 1 else origin[:, 2] - centre[:, 2]
    ox = cos_yaw * rx + sin_yaw * ry
    oy = cos_yaw * ry - sin_yaw * rx
    dx = cos_yaw * dirs[:, 0] + sin_yaw * dirs[:, 1]
    dy = cos_yaw * dirs[:, 1] - sin_yaw * dirs[:, 0]
    return ox, oy, rz, dx, dy, dirs[:, 2]


def intersect_box(
    origin: np.ndarray,
    dirs: np.ndarray,
    centre: np.ndarray,
    half: np.ndarray,
    cos_yaw: np.ndarray,
    sin_yaw: np.ndarray,
) -> np.ndarray:
    """Entry distance into a yawed box (inf on a miss or when the origin is inside)."""
    ox, oy, oz, dx, dy, dz = _local_rays(origin, dirs, centre, cos_yaw, sin_yaw)
    t_near = np.full(len(ox), -np.inf)
    t_far = np.full(len(ox), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for o, d, h in ((ox, dx, half[:, 0]), (oy, dy, half[:, 1]), (oz, dz, half[:, 2])):
            inv = 1.0 / d
            t1 = (-h - o) * inv
            t2 = (h - o) * inv
            # fmin/fmax ignore the nan of a ray lying exactly on a slab plane.
            np.fmax(t_near, np.fmin(t1, t2), out=t_near)
            np.fmin(t_far, np.fmax(t1, t2), out=t_far)
    hit = (t_near <= t_far) & (t_near > 0.0)
    return np.where(hit, t_near, np.inf)


def intersect_cylinder(
    origin: np.ndarray,
    dirs: np.ndarray,
    centre: np.ndarray,
    radius: np.ndarray,
    half_height: np.ndarray,
) -> np.ndarray:
    """Entry distance into a vertical capped cylinder (inf on a miss)."""
    ox = origin[0] - centre[:, 0]
    oy = origin[1] - centre[:, 1]
    oz = origin[2] - centre[:, 2]
    dx, dy, dz = dirs[:, 0], dirs[:, 1], dirs[:, 2]
    a = dx * dx + dy * dy
    b = ox * dx + oy * dy
    c = ox * ox + oy * oy - radius * radius
    disc = b * b - a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        t_side = (-b - np.sqrt(np.maximum(disc, 0.0))) / a
        z_side = oz + t_side * dz
        side_ok = (disc > 0) & (a > 1e-12) & (t_side > 0) & (np.abs(z_side) <= half_height)
        cap_z = np.where(dz < 0, half_height, -half_height)
        t_cap = (cap_z - oz) / dz
        cx = ox + t_cap * dx
        cy = oy + t_cap * dy
        cap_ok = (t_cap > 0) & (cx * cx + cy * cy <= radius * radius) & (np.abs(oz) > half_height)
    return np.minimum(np.where(side_ok, t_side, np.inf), np.where(cap_ok, t_cap, np.inf))


def intersect_ellipsoid(
    origin: np.ndarray,
    dirs: np.ndarray,
    centre: np.ndarray,
    semi_axes: np.ndarray,
    cos_yaw: np.ndarray,
    sin_yaw: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit distances through a yawed ellipsoid (inf, inf on a miss).

    If the origin is inside, the entry distance is 0.
    """
    ox, oy, oz, dx, dy, dz = _local_rays(origin, dirs, centre, cos_yaw, sin_yaw)
    ia, ib, ic = 1.0 / semi_axes[:, 0], 1.0 / semi_axes[:, 1], 1.0 / semi_axes[:, 2]
    ox, oy, oz = ox * ia, oy * ib, oz * ic
    dx, dy, dz = dx * ia, dy * ib, dz * ic
    a = dx * dx + dy * dy + dz * dz
    b = ox * dx + oy * dy + oz * dz
    c = ox * ox + oy * oy + oz * oz - 1.0
    disc = b * b - a * c
    root = np.sqrt(np.maximum(disc, 0.0))
    t_in = (-b - root) / a
    t_out = (-b + root) / a
    hit = (disc > 0) & (t_out > 0)
    return np.where(hit, np.maximum(t_in, 0.0), np.inf), np.where(hit, t_out, np.inf)


def surface_normals(
    kind: np.ndarray,
    points: np.ndarray,
    centre: np.ndarray,
    half: np.ndarray,
    cos_yaw: np.ndarray,
    sin_yaw: np.ndarray,
) -> np.ndarray:
    """Outward unit normals (K, 3) at surface points of the given primitives."""
    rx, ry, rz = (points - centre).T
    lx = cos_yaw * rx + sin_yaw * ry
    ly = cos_yaw * ry - sin_yaw * rx
    local = np.stack([lx, ly, rz], axis=1)
    scaled = local / half
    normal = np.zeros_like(local)
    box = kind == BOX
    if box.any():
        axis = np.argmax(np.abs(scaled[box]), axis=1)
        rows = np.flatnonzero(box)
        normal[rows, axis] = np.sign(local[rows, axis])
    cyl = kind == CYLINDER
    if cyl.any():
        on_cap = cyl & (np.abs(scaled[:, 2]) >= 0.999)
        side = cyl & ~on_cap
        normal[on_cap, 2] = np.sign(local[on_cap, 2])
        normal[side, :2] = local[side, :2]
    ell = kind == ELLIPSOID
    if ell.any():
        normal[ell] = scaled[ell] / half[ell]
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    wx = cos_yaw * normal[:, 0] - sin_yaw * normal[:, 1]
    wy = sin_yaw * normal[:, 0] + cos_yaw * normal[:, 1]
    return np.stack([wx, wy, normal[:, 2]], axis=1)


def intersect_ground(origin: np.ndarray, dirs: np.ndarray, ground_z: float) -> np.ndarray:
    """Distance along each ray to the horizontal plane ``z = ground_z`` (inf if never)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ground_z - origin[2]) / dirs[:, 2]
    return np.where((dirs[:, 2] < -1e-9) & (t > 0), t, np.inf)
