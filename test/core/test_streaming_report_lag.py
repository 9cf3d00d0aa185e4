"""Streaming ``report_lag``: each frame estimated again once the stream has moved on
(fixed-lag smoothing), and :func:`smoothed_position` on samples with known answers."""

from __future__ import annotations

import numpy as np

from clusterfilter_ros.core import streaming
from clusterfilter_ros.core.frame import MID360, Frame
from clusterfilter_ros.core.params import detector_params
from clusterfilter_ros.core.streaming import StreamingDetector, run_streaming, smoothed_position

LAG = 2.0


def _push_all(frames, det):
    """Push every frame; (live estimates, delayed estimates, newest stamp at each release)."""
    live, delayed, released_at = [], [], []
    for f in frames:
        e = det.push(f)
        if e is not None:
            live.append(e)
        got = det.delayed()
        delayed.extend(got)
        released_at.extend([f.stamp] * len(got))
    return live, delayed, released_at


def test_delayed_estimates_cover_the_warm_up_and_follow_the_drone(scene, drone_path_fn):
    frames, _, _ = scene(duration=10.0, wall_points=400)
    det = StreamingDetector(detector_params({"report_lag": LAG}))
    live, delayed, released_at = _push_all(frames, det)
    # Released only once the stream is report_lag past the frame.
    assert all(e.stamp <= at - LAG + 1e-9 for e, at in zip(delayed, released_at, strict=True))
    assert det.stats()["delayed_pending"] > 0
    delayed += det.flush()
    assert det.stats()["delayed_pending"] == 0 and det.delayed() == []
    stamps = np.array([e.stamp for e in delayed])
    assert np.all(np.diff(stamps) >= 0)
    assert len(np.unique(stamps)) == len(stamps)
    # The live output starts once the track is confirmed, after the warm-up; the delayed
    # one report_lag earlier (the confirmed track's returns reach back further, but the
    # frames before were released before the confirmation) and from then on every frame.
    start = frames[0].stamp
    first_live = min(e.stamp for e in live)
    assert first_live >= start + det.params.warmup
    assert stamps.min() <= first_live - LAG + 0.05
    assert len(stamps) >= np.count_nonzero([f.stamp >= stamps.min() for f in frames]) - 2
    pos = np.array([e.position for e in delayed])
    err = np.linalg.norm(pos - drone_path_fn(stamps - 1000.0), axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.3
    assert all(0.5 <= e.confidence <= 1 and e.n_points >= 1 for e in delayed)


def test_nothing_is_reported_late_after_the_newest_live_estimate(scene):
    # The drone's returns stop at 6 s; the stream goes on to 10 s.
    frames, _, _ = scene(duration=10.0, wall_points=200, drone_points=3)
    frames = [Frame(f.stamp, f.sensor, f.xyz[:-3]) if f.stamp > 1006.0 else f for f in frames]
    det = StreamingDetector(detector_params({"report_lag": LAG}))
    live, delayed, _ = _push_all(frames, det)
    delayed += det.flush()
    last_live = max(e.stamp for e in live)
    assert 1006.0 <= last_live <= 1006.0 + det.params.max_extrapolation + 0.11
    assert delayed and max(e.stamp for e in delayed) <= last_live


def test_an_object_confirmed_only_after_its_returns_stopped_is_not_reported_late(scene):
    # The drone's returns stop at 4 s, and the warm-up (no re-clustering) lasts until
    # 4.6 s: the first re-clustering finds its track already 0.6 s old, too old for
    # push() to report (max_extrapolation 0.5 s), so the delayed output stays silent too.
    frames, _, _ = scene(duration=8.0, wall_points=200, drone_points=3)
    frames = [Frame(f.stamp, f.sensor, f.xyz[:-3]) if f.stamp > 1004.0 else f for f in frames]
    values = {"report_lag": 3.0, "warmup": 4.6}
    det = StreamingDetector(detector_params(values))
    live, delayed, _ = _push_all(frames, det)
    assert live == [] and delayed + det.flush() == []
    # It was selected, confidently: only the rule above keeps it out.
    assert det.stats()["reclusters"] > 0


def test_live_estimates_do_not_depend_on_report_lag(scene):
    frames, _, _ = scene(duration=7.0, wall_points=200)
    base = run_streaming(frames)
    det = StreamingDetector(detector_params({"report_lag": LAG}))
    live, _, _ = _push_all(frames, det)
    assert len(base) == len(live) > 0
    for a, b in zip(base, live, strict=True):
        assert a.stamp == b.stamp and np.array_equal(a.position, b.position)


def test_without_report_lag_nothing_is_delayed(scene):
    frames, _, _ = scene(duration=5.0, wall_points=200)
    det = StreamingDetector()
    _, delayed, _ = _push_all(frames, det)
    assert delayed == [] and det.flush() == [] and det.stats()["delayed_pending"] == 0


def test_run_streaming_returns_the_delayed_estimates_with_report_lag(scene):
    frames, _, _ = scene(duration=7.0, wall_points=200)
    params = detector_params({"report_lag": LAG})
    det = StreamingDetector(params)
    _, delayed, _ = _push_all(frames, det)
    delayed += det.flush()
    by_run = run_streaming(frames, params)
    assert len(by_run) == len(delayed) > 0
    for a, b in zip(delayed, by_run, strict=True):
        assert a.stamp == b.stamp and np.array_equal(a.position, b.position)


def test_a_reset_estimates_the_waiting_frames_first(scene):
    frames, _, _ = scene(duration=7.0, wall_points=200)
    det = StreamingDetector(detector_params({"report_lag": LAG}))
    _push_all(frames, det)
    waiting = int(det.stats()["delayed_pending"])
    assert waiting >= 2 * LAG * 10 - 2  # two lidars at 10 Hz
    det.reset()
    assert det.stats()["delayed_pending"] == 0
    kept = det.delayed()
    # The drone is in every frame and the track was confident: none is lost.
    assert len(kept) == waiting
    assert [e.stamp for e in kept] == sorted(f.stamp for f in frames[-waiting:])


def test_the_waiting_queue_is_bounded(monkeypatch):
    monkeypatch.setattr(streaming, "_MAX_LAGGED", 5)
    det = StreamingDetector(detector_params({"report_lag": LAG}))
    xyz = np.zeros((1, 3), np.float32) + [10.0, 0.0, 5.0]
    for _ in range(20):  # a stream whose stamps stop advancing
        det.push(Frame(1000.0, MID360, xyz))
    assert det.stats()["delayed_pending"] == 5


def test_delayed_estimates_nobody_takes_are_bounded(scene, monkeypatch):
    monkeypatch.setattr(streaming, "_MAX_LAGGED", 7)
    frames, _, _ = scene(duration=7.0, wall_points=200)
    det = StreamingDetector(detector_params({"report_lag": LAG}))
    for f in frames:  # push() only, delayed() never called
        det.push(f)
    made = det.flush()
    assert len(made) == 7 and det.stats()["delayed_dropped"] > 0
    assert made[-1].stamp == frames[-1].stamp


# --------------------------------------------------------------- smoothed_position

P = detector_params()  # max_gap 1 s, max_extrapolation 0.5 s, track_window 1 s


def _line(t):
    return np.stack([2.0 * t, -1.0 * t + 3.0, np.full_like(t, 10.0)], axis=1)


def test_a_gap_shorter_than_max_gap_is_interpolated():
    ts = np.concatenate([np.arange(0.0, 2.0, 0.1), np.arange(2.7, 4.0, 0.1)])
    ps = _line(ts)
    got = smoothed_position(ts, ps, np.ones(ts.size), 2.3, P)
    np.testing.assert_allclose(got, _line(np.array([2.3]))[0], atol=1e-9)


def test_inside_a_long_gap_only_near_its_ends():
    ts = np.concatenate([np.arange(0.0, 2.0, 0.1), np.arange(5.0, 7.0, 0.1)])
    ps = _line(ts)
    w = np.ones(ts.size)
    assert smoothed_position(ts, ps, w, 3.5, P) is None
    # 0.3 s past the last sample before the gap: continued at the track's velocity.
    np.testing.assert_allclose(
        smoothed_position(ts, ps, w, 2.2, P), _line(np.array([2.2]))[0], atol=1e-9
    )
    np.testing.assert_allclose(
        smoothed_position(ts, ps, w, 4.7, P), _line(np.array([4.7]))[0], atol=1e-9
    )
    assert smoothed_position(ts, ps, w, -0.6, P) is None
    assert smoothed_position(ts, ps, w, 7.5, P) is None
    assert smoothed_position(ts[:0], ps[:0], w[:0], 1.0, P) is None


def test_a_sparse_track_is_not_read_as_standing_still():
    # One sample every 0.5 s at 8 m/s: only one lies within 0.4 s past the last; the
    # four nearest give the velocity.
    ts = np.arange(0.0, 3.01, 0.5)
    ps = np.stack([8.0 * ts, np.zeros_like(ts), np.full_like(ts, 20.0)], axis=1)
    got = smoothed_position(ts, ps, np.ones(ts.size), 3.4, P)
    np.testing.assert_allclose(got, [8.0 * 3.4, 0.0, 20.0], atol=1e-9)


def test_a_turning_track_is_fitted_with_its_curvature():
    ts = np.arange(0.0, 4.0, 0.1)
    ps = np.stack([1.5 * ts**2, np.zeros_like(ts), np.full_like(ts, 5.0)], axis=1)  # 3 m/s^2
    got = smoothed_position(ts, ps, np.ones(ts.size), 2.05, P)
    np.testing.assert_allclose(got, [1.5 * 2.05**2, 0.0, 5.0], atol=1e-9)


def test_an_implausible_curvature_falls_back_to_a_line():
    accel = 20.0  # m/s^2, above max_accel
    ts = np.arange(0.0, 2.0, 0.1)
    ps = np.stack([0.5 * accel * ts**2, np.zeros_like(ts), np.zeros_like(ts)], axis=1)
    got = smoothed_position(ts, ps, np.ones(ts.size), 1.0, P)
    # A line through the samples within 1 s: not the exact quadratic value.
    assert abs(got[0] - 0.5 * accel) > 0.5


def test_no_sample_within_reach_gives_none_not_an_error():
    # max_extrapolation set beyond track_window and link_max_gap: 3 s past the last
    # sample is "supported", but no sample is near enough to fit.
    params = detector_params({"max_extrapolation": 5.0, "track_window": 0.5, "link_max_gap": 1.0})
    ts = np.arange(0.0, 2.0, 0.1)
    assert smoothed_position(ts, _line(ts), np.ones(ts.size), 5.0, params) is None
