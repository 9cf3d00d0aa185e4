"""Scan patterns, the return model and the smooth paths."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clusterfilter_ros.sim.sensors import avia, mid360
from clusterfilter_ros.sim.trajectory import Path, Waypoint


def test_mid360_rays_fov_and_time():
    m = mid360()
    for k, rows in ((0, 19968), (1, 20064), (2, 19968)):
        dirs, times = m.scan(k)
        assert dirs.shape == (rows, 3)
        assert np.all((times >= 0) & (times < m.frame_period))
        el = np.degrees(np.arcsin(dirs[:, 2]))
        assert el.min() >= -7.0 - 1e-6 and el.max() <= 52.0 + 1e-6
        np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-6)
    az = np.degrees(np.arctan2(dirs[:, 1], dirs[:, 0]))
    assert np.histogram(az, bins=36, range=(-180, 180))[0].min() > 0.8 * rows / 36


def test_avia_rosette_points_up_within_its_field_of_view():
    a = avia()
    dirs, times = a.scan(5)
    assert dirs.shape == (24000, 3)
    theta_x = np.degrees(np.arctan2(dirs[:, 0], dirs[:, 2]))
    theta_y = np.degrees(np.arctan2(dirs[:, 1], dirs[:, 2]))
    assert np.all(dirs[:, 2] > 0.7)  # within ~45 deg of the zenith
    assert np.abs(theta_x).max() <= 70.4 / 2 + 0.5
    assert np.abs(theta_y).max() <= 77.2 / 2 + 1.0
    # The rosette reaches the edge of the field and passes through the centre.
    assert np.abs(theta_x).max() > 33 and np.abs(theta_y).max() > 36
    assert (np.hypot(theta_x, theta_y) < 2.0).sum() > 20


@pytest.mark.parametrize("make", [mid360, avia])
def test_scan_is_non_repetitive_and_fills_in(make):
    lidar = make()

    def covered(frames):
        cells = set()
        for k in frames:
            d, _ = lidar.scan(k)
            az = np.floor(np.degrees(np.arctan2(d[:, 1], d[:, 0])) / 0.5)
            el = np.floor(np.degrees(np.arcsin(d[:, 2])) / 0.5)
            cells.update(zip(az.astype(int).tolist(), el.astype(int).tolist(), strict=True))
        return len(cells)

    d0, _ = lidar.scan(0)
    d2, _ = lidar.scan(2)  # same ray count as frame 0
    assert not np.allclose(d0, d2)
    assert covered(range(10)) > 1.3 * covered([0])


def test_return_model_matches_the_data_sheet_points():
    m, a = mid360(), avia()
    assert m.detection_range(np.array(0.1)) == pytest.approx(40.0)
    assert m.detection_range(np.array(0.8)) == pytest.approx(70.0)
    assert a.detection_range(np.array(0.1)) == pytest.approx(190.0)
    assert a.detection_range(np.array(0.8)) == pytest.approx(320.0)
    r = np.array([5.0, 30.0, 45.0, 60.0, 90.0])
    one = np.ones_like(r)
    p = m.return_probability(r, 0.2 * one, one, 0 * one)
    assert np.all(np.diff(p) < 0) and p[0] > 0.95 and p[-1] < 0.05
    bright = m.return_probability(r, 0.8 * one, one, 0 * one)
    assert np.all(bright >= p)
    # A target smaller than the beam footprint returns less at long range.
    tiny = a.return_probability(
        np.array([300.0]), np.array([0.3]), np.array([1.0]), np.array([1e-3])
    )
    big = a.return_probability(np.array([300.0]), np.array([0.3]), np.array([1.0]), np.array([0.0]))
    assert tiny[0] < 0.5 * big[0]


def test_path_is_smooth_limited_and_holds():
    wps = [
        Waypoint((0.0, 0.0, 0.0)),
        Waypoint((0.0, 0.0, 10.0), speed=3.0),
        Waypoint((60.0, 20.0, 15.0), hold=4.0, speed=12.0),
        Waypoint((-30.0, 40.0, 20.0), speed=12.0),
    ]
    path = Path(wps, start_time=-1.0, max_speed=12.0, max_acceleration=4.0)
    t = np.linspace(path.start_time - 2, path.end_time + 2, 20001)
    p, v, a = path.position(t), path.velocity(t), path.acceleration(t)
    assert np.linalg.norm(v, axis=1).max() <= 12.0 + 1e-6
    assert np.linalg.norm(a, axis=1).max() <= 4.0 + 1e-6
    # Continuous position (no jumps) and exact waypoints.
    assert np.linalg.norm(np.diff(p, axis=0), axis=1).max() < 12.0 * (t[1] - t[0]) * 1.01
    np.testing.assert_allclose(path.position(path.knot_times), path.knots, atol=1e-9)
    # Hold: stationary at the third waypoint for 4 s.
    k = int(np.flatnonzero(np.all(path.knots == (60.0, 20.0, 15.0), axis=1))[0])
    t_hold = np.linspace(path.knot_times[k], path.knot_times[k + 1], 50)
    np.testing.assert_allclose(path.position(t_hold), np.tile((60.0, 20.0, 15.0), (50, 1)))
    assert path.knot_times[k + 1] - path.knot_times[k] == pytest.approx(4.0)
    # Before the start and after the end it waits.
    np.testing.assert_allclose(path.position(path.start_time - 5), wps[0].position)
    np.testing.assert_allclose(path.position(path.end_time + 5), wps[-1].position)
    assert math.isclose(path.start_time, -1.0)
