"""Ray-primitive kernels, angular culling and the culled cast against brute force."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

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
from clusterfilter_ros.sim.raycast import (
    PrimitiveBuilder,
    _culled_pairs,
    angular_bounds,
    cast_rays,
)

ORIGIN = np.zeros(3)


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_box_hit_distance_miss_and_yaw():
    dirs = _unit([[1, 0, 0], [1, 0, 0], [-1, 0, 0], [1, 0.5, 0]])
    centre = np.array([[10.0, 0, 0], [10.0, 3.0, 0], [10.0, 0, 0], [10.0, 0, 0]])
    half = np.array([[1.0, 1.0, 1.0]] * 4)
    c, s = np.ones(4), np.zeros(4)
    t = intersect_box(ORIGIN, dirs, centre, half, c, s)
    assert t[0] == pytest.approx(9.0)
    assert np.isinf(t[1]) and np.isinf(t[2])
    # A box 2 m long in x rotated by 90 deg presents its 0.5 m half width to the ray.
    yawed = intersect_box(
        ORIGIN,
        dirs[:1],
        np.array([[10.0, 0, 0]]),
        np.array([[2.0, 0.5, 1.0]]),
        np.array([0.0]),
        np.array([1.0]),
    )
    assert yawed[0] == pytest.approx(9.5)


def test_box_ray_from_inside_is_a_miss():
    t = intersect_box(
        ORIGIN, _unit([[1, 0, 0]]), np.zeros((1, 3)), np.ones((1, 3)), np.ones(1), np.zeros(1)
    )
    assert np.isinf(t[0])


def test_cylinder_side_and_cap():
    dirs = _unit([[1, 0, 0], [0, 0, 1], [1, 0, 0]])
    centre = np.array([[5.0, 0, 0], [0.0, 0.0, 10.0], [5.0, 0, 5.0]])
    radius = np.array([0.5, 1.0, 0.5])
    half_h = np.array([1.0, 1.0, 1.0])
    t = intersect_cylinder(ORIGIN, dirs, centre, radius, half_h)
    assert t[0] == pytest.approx(4.5)
    assert t[1] == pytest.approx(9.0)  # bottom cap of a cylinder straight above
    assert np.isinf(t[2])


def test_ellipsoid_entry_exit_and_inside():
    dirs = _unit([[0, 1, 0], [0, 1, 0]])
    centre = np.array([[0.0, 10.0, 0.0], [0.0, 0.0, 0.0]])
    semi = np.array([[1.0, 2.0, 1.0], [1.0, 2.0, 1.0]])
    t_in, t_out = intersect_ellipsoid(ORIGIN, dirs, centre, semi, np.ones(2), np.zeros(2))
    assert t_in[0] == pytest.approx(8.0) and t_out[0] == pytest.approx(12.0)
    assert t_in[1] == 0.0 and t_out[1] == pytest.approx(2.0)


def test_ground_plane():
    dirs = _unit([[1, 0, -1], [1, 0, 0.1]])
    t = intersect_ground(ORIGIN, dirs, -2.0)
    assert t[0] == pytest.approx(2.0 * np.sqrt(2.0))
    assert np.isinf(t[1])


def test_surface_normals_point_outwards():
    kinds = np.array([BOX, CYLINDER, ELLIPSOID])
    centre = np.array([[10.0, 0, 0], [0.0, 10.0, 0.0], [0.0, 0.0, 10.0]])
    half = np.array([[1.0, 1.0, 1.0], [0.5, 0.5, 2.0], [1.0, 1.0, 1.0]])
    points = np.array([[9.0, 0.2, 0.1], [0.0, 9.5, 0.3], [0.0, 0.0, 9.0]])
    n = surface_normals(kinds, points, centre, half, np.ones(3), np.zeros(3))
    np.testing.assert_allclose(n, [[-1, 0, 0], [0, -1, 0], [0, 0, -1]], atol=1e-9)


boxes = st.tuples(
    st.floats(-60, 60),
    st.floats(-60, 60),
    st.floats(-3, 30),
    st.floats(0.1, 10),
    st.floats(0.1, 10),
    st.floats(0.1, 10),
)


@settings(max_examples=60, deadline=None)
@given(boxes)
def test_angular_bounds_contain_every_point_of_the_box(box):
    cx, cy, cz, hx, hy, hz = box
    lo = np.array([[cx - hx, cy - hy, cz - hz]])
    hi = np.array([[cx + hx, cy + hy, cz + hz]])
    az_lo, az_hi, el_lo, el_hi = angular_bounds(ORIGIN, lo, hi)
    rng = np.random.default_rng(0)
    pts = lo + rng.random((500, 3)) * (hi - lo)
    pts = pts[np.linalg.norm(pts, axis=1) > 1e-6]
    az = np.arctan2(pts[:, 1], pts[:, 0])
    el = np.arctan2(pts[:, 2], np.hypot(pts[:, 0], pts[:, 1]))
    rel = (az - az_lo[0]) % (2 * np.pi)
    assert np.all(rel <= az_hi[0] - az_lo[0] + 1e-9)
    assert np.all(el >= el_lo[0] - 1e-9) and np.all(el <= el_hi[0] + 1e-9)


def _random_scene(rng):
    b = PrimitiveBuilder()
    for _ in range(40):
        c = rng.uniform([-50, -50, -1.5], [50, 50, 10])
        h = rng.uniform(0.2, 4.0, 3)
        kind = rng.integers(0, 3)
        if kind == 0:
            b.box(c - h, c + h, 0.3, yaw=rng.uniform(0, np.pi))
        elif kind == 1:
            b.cylinder(c[0], c[1], c[2] - h[2], c[2] + h[2], h[0], 0.3)
        else:
            b.ellipsoid(tuple(c), tuple(h), 0.3, yaw=rng.uniform(0, np.pi))
    # One box straddling the azimuth wrap-around behind the sensor.
    b.box((-30.0, -2.0, -1.0), (-25.0, 2.0, 3.0), 0.3)
    return b.build()


def test_culled_cast_equals_brute_force():
    rng = np.random.default_rng(3)
    table = _random_scene(rng)
    n = 4000
    az = rng.uniform(-np.pi, np.pi, n)
    el = rng.uniform(-0.3, 0.9, n)
    dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
    lo, hi = table.bounding_boxes(0.0)
    bounds = angular_bounds(ORIGIN, lo, hi)
    hits = cast_rays(
        ORIGIN, dirs, np.zeros(n), table, bounds, -1.75, 0.15, np.random.default_rng(0), (az, el)
    )
    full = np.full(n, np.inf)
    cos_y, sin_y = np.cos(table.yaw), np.sin(table.yaw)
    for p in range(len(table)):
        c = np.repeat(table.centre[p : p + 1], n, 0)
        h = np.repeat(table.half[p : p + 1], n, 0)
        if table.kind[p] == BOX:
            t = intersect_box(ORIGIN, dirs, c, h, np.full(n, cos_y[p]), np.full(n, sin_y[p]))
        elif table.kind[p] == CYLINDER:
            t = intersect_cylinder(ORIGIN, dirs, c, h[:, 0], h[:, 2])
        else:
            t, _ = intersect_ellipsoid(
                ORIGIN, dirs, c, h, np.full(n, cos_y[p]), np.full(n, sin_y[p])
            )
        full = np.minimum(full, t)
    full = np.minimum(full, intersect_ground(ORIGIN, dirs, -1.75))
    got = np.full(n, np.inf)
    got[hits.ray] = hits.t
    np.testing.assert_allclose(got, full, rtol=1e-9)
    pr, pp = _culled_pairs(az, el, bounds)
    assert len(pr) < 0.2 * n * len(table)  # culling removes most pairs
