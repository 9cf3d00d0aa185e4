"""The B-spline trajectory: accuracy on smooth paths, no estimate outside the evidence."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clusterfilter_ros.core.trajectory import (
    chord_strays,
    fit_trajectory,
    merge_trajectories,
    time_samples,
    weighted_line,
    weighted_quadratic,
)


def test_time_samples_average_per_bin():
    t = np.array([0.0, 0.0, 0.1, 0.1, 0.1])
    xyz = np.array([[0, 0, 0], [2, 0, 0], [1, 1, 1], [1, 1, 1], [4, 4, 4]], dtype=float)
    ts, ps, ws = time_samples(t, xyz, 0.05)
    assert np.allclose(ts, [0.0, 0.1]) and ws.tolist() == [2, 3]
    assert np.allclose(ps, [[1, 0, 0], [2, 2, 2]])


def test_spline_follows_a_smooth_curve_and_respects_support():
    rng = np.random.default_rng(0)
    t = np.repeat(np.arange(0, 10, 0.1), 3)
    truth = np.column_stack([3 * t, 10 * np.sin(0.3 * t), 20 + 0.5 * t])
    traj = fit_trajectory(
        t, truth + rng.normal(0, 0.1, truth.shape), max_gap=1.0, max_extrapolation=0.3
    )
    assert traj is not None and len(traj.segments) == 1
    q = np.linspace(0.5, 9.4, 50)
    q_truth = np.column_stack([3 * q, 10 * np.sin(0.3 * q), 20 + 0.5 * q])
    assert np.sqrt(np.mean(np.sum((traj(q) - q_truth) ** 2, axis=1))) < 0.1
    outside = traj(np.array([-0.5, 9.9 + 0.31, 20.0]))
    assert np.isnan(outside).all()
    assert np.isfinite(traj(np.array([-0.2, 10.1]))).all()  # within max_extrapolation


def test_gaps_split_segments_and_leave_holes():
    t = np.concatenate([np.arange(0, 3, 0.1), np.arange(6, 9, 0.1)])
    xyz = np.column_stack([t, np.zeros_like(t), np.full_like(t, 10.0)])
    traj = fit_trajectory(t, xyz, max_gap=1.0, max_extrapolation=0.2)
    assert len(traj.segments) == 2
    pos = traj(np.array([1.0, 4.5, 7.0]))
    assert np.isfinite(pos[[0, 2]]).all() and np.isnan(pos[1]).all()
    assert np.allclose(pos[[0, 2], 0], [1.0, 7.0], atol=0.05)


def test_short_segments_use_line_or_constant_and_empty_gives_none():
    assert fit_trajectory(np.empty(0), np.empty((0, 3)), max_gap=1, max_extrapolation=0) is None
    one = fit_trajectory(np.array([5.0]), np.array([[1.0, 2, 3]]), max_gap=1, max_extrapolation=0.1)
    assert one.segments[0].kind == "constant"
    assert np.allclose(one(np.array([5.05])), [[1, 2, 3]])
    line = fit_trajectory(
        np.array([0.0, 0.1, 0.2]),
        np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]),
        max_gap=1,
        max_extrapolation=0.1,
    )
    assert line.segments[0].kind == "line"
    assert np.allclose(line(np.array([0.25])), [[2.5, 0, 0]])


def test_nan_points_are_ignored():
    t = np.arange(0, 2, 0.1)
    xyz = np.column_stack([t, t, t])
    xyz[3] = np.nan
    traj = fit_trajectory(t, xyz, max_gap=1, max_extrapolation=0.1)
    assert np.isfinite(traj(np.array([0.3]))).all()


def test_reported_positions_apply_surface_depth_then_target_offset():
    from clusterfilter_ros.core.estimate import reported_positions
    from clusterfilter_ros.core.params import detector_params

    centres = np.array([[10.0, 0.0, 0.0], [0.0, 3.0, 4.0], [1.0, 1.0, 1.0]])
    params = detector_params(
        {"surface_depth": 0.5, "viewpoint": [1.0, 1.0, 1.0], "target_offset": [0.0, 0.0, 0.25]}
    )
    out = reported_positions(centres, params)
    ray = centres[0] - [1.0, 1.0, 1.0]
    assert np.allclose(out[0], centres[0] + 0.5 * ray / np.linalg.norm(ray) + [0, 0, 0.25])
    ray = centres[1] - [1.0, 1.0, 1.0]
    assert np.allclose(out[1], centres[1] + 0.5 * ray / np.linalg.norm(ray) + [0, 0, 0.25])
    # At the viewpoint itself there is no direction: only the offset applies.
    assert np.allclose(out[2], [1.0, 1.0, 1.25])
    # Off by default: the offset alone.
    assert np.allclose(reported_positions(centres, detector_params()), centres)


def test_a_short_piece_after_a_gap_moves_with_its_neighbours_velocity():
    # A track at 8 m/s for 2 s, then one return 1.3 s after its end.
    t = np.concatenate([np.arange(0.0, 2.0, 0.1), [3.2]])
    xyz = np.column_stack([8.0 * t, np.zeros_like(t), np.full_like(t, 20.0)])
    alone = fit_trajectory(t, xyz, max_gap=1.0, max_extrapolation=0.3)
    assert alone.segments[-1].kind == "constant"
    with_ctx = fit_trajectory(t, xyz, max_gap=1.0, max_extrapolation=0.3, context_gap=2.0)
    assert [s.kind for s in with_ctx.segments] == ["spline", "line"]
    pos = with_ctx(np.array([3.0, 3.4]))
    assert np.allclose(pos[:, 0], [24.0, 27.2], atol=0.05)
    # Spans stay their own: nothing inside the gap.
    assert np.isnan(with_ctx(np.array([2.6]))).all()
    # A neighbour further than context_gap gives no context.
    far = fit_trajectory(t, xyz, max_gap=1.0, max_extrapolation=0.3, context_gap=1.0)
    assert far.segments[-1].kind == "constant"


def test_a_lone_return_between_two_pieces_keeps_its_own_position():
    # A pass slowing at 2 m/s^2 (x = 10 t - t^2; fast_pass seed 1800 curves 50 m out):
    # dense pieces before 1.0 s and after 3.4 s, one return at 2.1 s between them (gaps
    # over max_gap on both sides). A line through the neighbours' windows misses that
    # return by almost 3 m (the chord); the piece's line goes through it with their
    # velocity.
    t = np.concatenate([np.arange(0.0, 1.0, 0.1), [2.1], np.arange(3.4, 4.4, 0.1)])
    xyz = np.column_stack([10.0 * t - t * t, np.zeros_like(t), np.full_like(t, 20.0)])
    traj = fit_trajectory(t, xyz, max_gap=1.0, max_extrapolation=0.3, context_gap=2.0)
    assert [s.kind for s in traj.segments] == ["spline", "line", "spline"]
    at = traj(np.array([1.9, 2.1, 2.3]))
    truth = 10.0 * np.array([1.9, 2.1, 2.3]) - np.array([1.9, 2.1, 2.3]) ** 2
    assert np.abs(at[:, 0] - truth).max() < 0.15


def test_weighted_line_recovers_a_line_and_handles_one_instant():
    t = np.array([0.0, 1.0, 2.0])
    xyz = np.array([[0.0, 1, 2], [2, 1, 2], [4, 1, 2]])
    slope, mean, tc = weighted_line(t, xyz, np.array([1.0, 2.0, 1.0]))
    assert np.allclose(slope, [2, 0, 0]) and np.isclose(tc, 1.0) and np.allclose(mean, [2, 1, 2])
    slope, mean, _ = weighted_line(np.zeros(2), xyz[:2], np.ones(2))
    assert np.allclose(slope, 0) and np.allclose(mean, [1, 1, 2])
    # The same numbers as np.average, bit for bit; no weights, no line.
    rng = np.random.default_rng(3)
    tt, pp, ww = rng.random(9) + 1e3, rng.normal(size=(9, 3)) * 10, rng.integers(1, 9, 9) * 1.0
    _, mean, tc = weighted_line(tt, pp, ww)
    assert tc == float(np.average(tt, weights=ww))
    assert np.array_equal(mean, np.average(pp, axis=0, weights=ww))
    with pytest.raises(ValueError, match="weights"):
        weighted_line(t, xyz, np.zeros(3))


def _track_with_strays():
    """A drone at 8 m/s (4 returns per 0.1 s frame for 6 s) and another object's returns
    joined to it: two inside the track, 6-10 m off, and the last return, 12 m off."""
    rng = np.random.default_rng(7)
    t = np.repeat(np.arange(60) * 0.1, 4) + rng.uniform(0, 0.01, 240)
    truth = lambda s: np.column_stack([8.0 * s - 20.0, 2.0 + 0.0 * s, 25.0 + 0.3 * s])  # noqa: E731
    xyz = truth(t) + rng.normal(0.0, 0.15, (t.size, 3))
    stray_t = np.array([2.02, 3.51, 6.3])
    stray = truth(stray_t) + np.array([[0.0, 6.0, -3.0], [5.0, 8.0, 0.0], [-6.0, 10.0, 2.0]])
    return np.concatenate([t, stray_t]), np.vstack([xyz, stray]), truth


def test_stray_returns_are_left_out_of_the_track():
    t, xyz, truth = _track_with_strays()
    stamps = np.arange(0.0, 6.0, 0.05)
    args = dict(max_gap=1.0, max_extrapolation=0.5, bin_seconds=0.05)
    plain = fit_trajectory(t, xyz, **args)
    robust = fit_trajectory(t, xyz, **args, stray_distance=2.0, stray_speed=15.0)
    err_plain = np.linalg.norm(plain(stamps) - truth(stamps), axis=1)
    err_robust = np.linalg.norm(robust(stamps) - truth(stamps), axis=1)
    assert np.nanmax(err_plain) > 1.0  # the strays pull the plain fit off the track
    assert np.all(np.isfinite(err_robust)) and err_robust.max() < 0.3
    # The last return (12 m off, 0.3 s after the drone's last) ends no segment.
    assert robust.segments[-1].t_end < 6.0


def test_stray_refit_leaves_a_clean_track_alone_and_keeps_a_mixed_cloud():
    rng = np.random.default_rng(8)
    t = np.repeat(np.arange(50) * 0.1, 3)
    xyz = np.column_stack([3.0 * t, np.zeros_like(t), np.full_like(t, 20.0)])
    xyz += rng.normal(0.0, 0.1, xyz.shape)
    args = dict(max_gap=1.0, max_extrapolation=0.5)
    stamps = np.arange(0.0, 4.9, 0.1)
    a = fit_trajectory(t, xyz, **args)(stamps)
    b = fit_trajectory(t, xyz, **args, stray_distance=2.0, stray_speed=15.0)(stamps)
    np.testing.assert_array_equal(a, b)
    # Two objects 10 m apart in equal shares: more than half would be "stray" for any
    # fit between them, so nothing is left out.
    two = xyz.copy()
    two[::2, 1] += 10.0
    c = fit_trajectory(t, two, **args)(stamps)
    d = fit_trajectory(t, two, **args, stray_distance=2.0)(stamps)
    np.testing.assert_array_equal(c, d)


def test_a_lone_stray_between_two_returns_is_left_out_by_the_chord():
    # take-off 6303 (62nd set), 5-12 s of the offline track: a drone speeding up from
    # 5 to 7 m/s along y, unseen from 7.61 s to 9.20 s but for one noise return the
    # clustering joined to it at 8.22 s, 5.6 m off its path.
    data = np.load(Path(__file__).parent / "data" / "takeoff_6303_lone_stray.npz")
    t, xyz, gt_t, gt_xyz = data["t"], data["xyz"], data["gt_t"], data["gt_xyz"]
    args = dict(
        max_gap=1.0,
        max_extrapolation=0.3,
        bin_seconds=0.05,
        stray_distance=2.0,
        stray_speed=15.0,
        stray_accel=4.0,
        stray_window=1.0,
        stray_span=0.2,
    )
    distance_only = fit_trajectory(t, xyz, **args)
    chord = fit_trajectory(t, xyz, **args, stray_chord_span=2.0, stray_chord_lone=0.2)
    # The smoothing spline passes through the stray, so its distance to the fit never
    # finds it, and the estimates across the gap swing up to 6 m off the drone.
    err = np.linalg.norm(distance_only(gt_t) - gt_xyz, axis=1)
    assert np.nanmax(err) > 5.0
    assert len(distance_only.segments) == 1
    # Left out, the 1.6 s gap is longer than max_gap: no estimate inside it, and the
    # estimates on both sides stay on the drone.
    assert [round(s.t_end, 2) for s in chord.segments] == [7.61, 11.72]
    got = chord(gt_t)
    inside = (gt_t > 7.61 + 0.3) & (gt_t < 9.20 - 0.3)
    assert inside.any() and np.isnan(got[inside]).all()
    err = np.linalg.norm(got[~inside] - gt_xyz[~inside], axis=1)
    assert np.all(np.isfinite(err)) and err.max() < 1.0


def test_chord_strays_needs_both_neighbours_within_the_span():
    ts = np.array([0.0, 0.6, 1.6, 2.0])
    ps = np.array([[0.0, 0.0, 0.0], [0.0, 6.0, 0.0], [0.0, 1.6, 0.0], [0.0, 2.0, 0.0]])
    assert chord_strays(ts, ps, 2.0, 4.0, 2.0).tolist() == [False, True, False, False]
    # Neighbours 1.6 s apart: beyond a 1.5 s span nothing is judged.
    assert not chord_strays(ts, ps, 2.0, 4.0, 1.5).any()
    # Within the allowance (2 m + 4 x 0.6 x 1.0 / 2 = 3.2 m): kept.
    near = ps.copy()
    near[1, 1] = 0.6 + 3.1
    assert not chord_strays(ts, near, 2.0, 4.0, 2.0).any()
    assert not chord_strays(ts, ps, 0.0, 4.0, 2.0).any()
    # Only lone samples are judged with lone_gap: 0.6 s and 1.0 s from its neighbours
    # it is; with a neighbour 0.1 s away (another object's samples alternating with the
    # drone's) it is not.
    assert chord_strays(ts, ps, 2.0, 4.0, 2.0, lone_gap=0.2).tolist() == [0, 1, 0, 0]
    close = ts.copy()
    close[0] = 0.5
    assert chord_strays(close, ps, 2.0, 4.0, 2.0).tolist() == [0, 1, 0, 0]
    assert not chord_strays(close, ps, 2.0, 4.0, 2.0, lone_gap=0.2).any()


def test_returns_off_the_track_heading_end_no_segment():
    # The drone (8 m/s along x) ends at 6 s. Another object's returns follow: one 0.7 s
    # later, 4 m from the drone's last position (within reach at link speed, but far
    # from where the drone was heading), and three more after a 1.5 s gap near it.
    rng = np.random.default_rng(9)
    t = np.repeat(np.arange(61) * 0.1, 3)
    xyz = np.column_stack([8.0 * t, np.zeros_like(t), np.full_like(t, 20.0)])
    xyz += rng.normal(0.0, 0.1, xyz.shape)
    other_t = np.array([6.7, 8.2, 8.4, 8.6])
    other = np.array([[45.0, 2.0, 19.0], [44.0, 3.0, 18.0], [43.8, 3.2, 17.8], [43.6, 3.4, 17.6]])
    t, xyz = np.concatenate([t, other_t]), np.vstack([xyz, other])
    args = dict(max_gap=1.0, max_extrapolation=0.5, stray_distance=2.0, stray_speed=15.0)
    speed_only = fit_trajectory(t, xyz, **args)
    heading = fit_trajectory(t, xyz, **args, stray_accel=4.0, stray_window=1.0)
    later = np.array([6.7, 8.3, 8.6])
    assert np.isfinite(speed_only(later)).all()
    assert np.isnan(heading(later)).all()
    inside = np.arange(0.0, 6.0, 0.1)
    err = np.linalg.norm(
        heading(inside) - np.column_stack([8 * inside, 0 * inside, 20 + 0 * inside]), axis=1
    )
    assert err.max() < 0.3


def test_weighted_quadratic_recovers_a_parabola_whatever_the_weights():
    dt = np.linspace(-1.0, 1.0, 9)
    coef_true = np.array([[1.0, -2.0, 3.0], [0.5, 0.0, -1.0], [1.5, 0.25, 0.0]])
    xyz = coef_true[0] + dt[:, None] * coef_true[1] + (dt * dt)[:, None] * coef_true[2]
    w = np.arange(1.0, 10.0)
    np.testing.assert_allclose(weighted_quadratic(dt, xyz, w), coef_true, atol=1e-12)
    # A heavier sample pulls a noisy fit towards itself.
    noisy = xyz.copy()
    noisy[4] += 1.0
    light = weighted_quadratic(dt, noisy, np.ones(9))
    heavy = weighted_quadratic(dt, noisy, np.where(np.arange(9) == 4, 100.0, 1.0))
    assert heavy[0, 0] - coef_true[0, 0] > light[0, 0] - coef_true[0, 0] > 0


@pytest.mark.parametrize("n_samples", [10, 20, 80, 110])
def test_a_constant_confidence_is_kept_exactly(n_samples):
    # The mean of n copies of 0.6 is 0.5999999999999999 for these n: a piece given
    # exactly min_confidence (offline, deviation 80) was then never reported.
    t = np.arange(n_samples) * 0.05
    xyz = np.column_stack([2.0 * t, np.zeros_like(t), np.full_like(t, 30.0)])
    assert float(np.average(np.full(n_samples, 0.6), weights=np.ones(n_samples))) < 0.6
    traj = fit_trajectory(
        t, xyz, max_gap=1.0, max_extrapolation=0.3, confidence=np.full(n_samples, 0.6)
    )
    assert traj is not None
    assert all(seg.confidence == 0.6 for seg in traj.segments)
    assert (traj.confidence(t) >= 0.6).all()


def test_overlapping_segments_prefer_the_one_holding_the_stamp_then_the_longer():
    # Deviation 120: two selected clusters at once. A bird's leg (8 s, 0-8 s) and the
    # drone's track (10 s, 5-15 s) overlap for 3 s: there the longer track is taken, not
    # the one that began first, whatever their confidences. Outside the overlap, a
    # segment's own span goes before the other's extrapolation.
    t_bird = np.arange(0.0, 8.0, 0.1)
    t_drone = np.arange(5.0, 15.0, 0.1)
    bird = np.column_stack([t_bird, np.full_like(t_bird, 10.0), np.full_like(t_bird, 8.0)])
    drone = np.column_stack([-t_drone, np.zeros_like(t_drone), np.full_like(t_drone, 4.0)])
    kw = dict(max_gap=1.0, max_extrapolation=0.5)
    parts = [
        fit_trajectory(t_bird, bird, confidence=np.full(t_bird.size, 0.9), **kw),
        fit_trajectory(t_drone, drone, confidence=np.full(t_drone.size, 0.6), **kw),
    ]
    traj = merge_trajectories(parts, 0.5)
    pos = traj(np.array([2.0, 6.0, 7.9, 8.2]))
    assert np.allclose(pos[0], [2.0, 10.0, 8.0], atol=0.05)  # the bird alone
    assert np.allclose(pos[1:, 1], 0.0, atol=0.05)  # the drone where both are, and after
    # 0.2 s before the drone's first return: the bird's own span, not the drone's
    # extrapolation.
    assert np.allclose(traj(np.array([4.8]))[0, 1], 10.0, atol=0.05)
    # Spans alike: the earlier segment, as before.
    t_same = np.arange(5.0, 13.0, 0.1)
    same = np.column_stack([-t_same, np.zeros_like(t_same), np.full_like(t_same, 4.0)])
    alike = [parts[0], fit_trajectory(t_same, same, **kw)]
    assert np.allclose(merge_trajectories(alike, 0.5)(np.array([6.0]))[0, 1], 10.0, atol=0.05)


@pytest.mark.parametrize("span", [0.0, 0.2])
def test_a_heading_is_read_over_two_frame_periods_at_least(span):
    # Deviation 123, fast_pass 5604 of the fifty-fifth set: a pass at 10 m/s, seen to
    # 0.9 s, gave two returns 0.06 s apart (0.3 m apart across its way) 1 s later, and a
    # lone return 1 s after those, on its line. The two alone (the last second's
    # samples) "headed" 5 m/s sideways, and the lone return was thrown out as
    # unreachable; read over 0.2 s at least (the nearest further in join them), the
    # heading is the pass's and the return is kept.
    t = np.concatenate([np.arange(0.0, 0.91, 0.1), [1.88, 1.94, 2.92]])
    xyz = np.column_stack([10.0 * t, np.zeros_like(t), np.full_like(t, 20.0)])
    xyz[-3, 1], xyz[-2, 1] = 0.15, -0.15
    traj = fit_trajectory(
        t,
        xyz,
        max_gap=1.0,
        max_extrapolation=0.5,
        bin_seconds=0.05,
        stray_distance=2.0,
        stray_speed=15.0,
        stray_accel=4.0,
        stray_window=1.0,
        stray_span=span,
    )
    late = traj(np.array([2.92, 3.2]))
    if span:
        np.testing.assert_allclose(late[:, 0], [29.2, 32.0], atol=0.3)
    else:
        assert np.isnan(late).all()
