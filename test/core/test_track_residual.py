"""The smoothness feature: a quadratic fit's residual tells smooth tracks from erratic ones."""

from __future__ import annotations

import numpy as np
import pytest

from clusterfilter_ros.core.params import detector_params
from clusterfilter_ros.core.scoring import frame_spread, score_clusters, track_residual


def _track(erratic: bool, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """20 s at 10 Hz, 3 points per frame on a 0.3 m body; smooth turn or bird-like wobble."""
    rng = np.random.default_rng(seed)
    t = np.repeat(np.arange(0.0, 20.0, 0.1), 3)
    centre = np.stack([5.0 * np.cos(0.2 * t), 5.0 * np.sin(0.2 * t), 10.0 + 0.1 * t], axis=1)
    if erratic:  # sum of sinusoids, 1 m amplitude, periods 0.8-1.9 s (simulated birds)
        for period, phase in ((0.8, 0.3), (1.3, 1.9), (1.9, 4.0)):
            centre += 0.5 * np.sin(2 * np.pi * t[:, None] / period + phase + np.arange(3))
    return t, centre + rng.normal(0.0, 0.1, size=centre.shape)


def test_smooth_track_has_small_residual_and_erratic_large() -> None:
    lab = np.zeros(600, dtype=np.int64)
    t_s, p_s = _track(False)
    t_e, p_e = _track(True)
    smooth = track_residual(lab, p_s, t_s, 1, 2.0, 0.0)[0]
    erratic = track_residual(lab, p_e, t_e, 1, 2.0, 0.0)[0]
    assert 0.1 < smooth < 0.25  # the body/noise spread only
    assert erratic > 0.5


def test_sparse_cluster_without_a_full_window_has_no_evidence() -> None:
    t = np.array([0.0, 0.1, 0.2])
    p = np.array([[0.0, 0.0, 5.0], [1.0, 3.0, 5.0], [0.0, -2.0, 5.0]])
    assert track_residual(np.zeros(3, np.int64), p, t, 1, 2.0, 0.0)[0] == 0.0
    assert track_residual(
        np.empty(0, np.int64), np.empty((0, 3)), np.empty(0), 2, 2.0, 0.0
    ).shape == (2,)


def test_erratic_cluster_loses_confidence_smooth_keeps_it() -> None:
    t_s, p_s = _track(False)
    t_e, p_e = _track(True, seed=1)
    p_e[:, 0] += 40.0  # far apart
    labels = np.repeat([0, 1], 600)
    xyz = np.concatenate([p_s, p_e])
    t = np.concatenate([t_s, t_e])
    params = detector_params()
    scores = score_clusters(labels, xyz, t, params, n_clusters=2)
    assert scores.residual[0] <= params.smooth_residual
    assert scores.residual[1] >= params.max_residual
    assert scores.confidence[1] == 0.0
    off = score_clusters(
        labels,
        xyz,
        t,
        params.copy(max_residual=100.0, max_excess=100.0, max_accel=1000.0),
        n_clusters=2,
    )
    assert off.confidence[1] > 0.0
    assert np.isclose(off.confidence[0], scores.confidence[0])


def test_frame_spread_explains_body_size_not_wander() -> None:
    """A dense smooth track's residual is its body spread (excess ~0); a sparse track
    wandering 0.5 m off any smooth path with one point per frame has it all as excess."""
    rng = np.random.default_rng(2)
    t_s, p_s = _track(False)
    t_w = np.arange(0.0, 20.0, 0.1)
    p_w = np.stack([2.0 * t_w, np.zeros_like(t_w), np.full_like(t_w, 12.0)], axis=1)
    p_w += rng.normal(0.0, 0.5 / np.sqrt(3.0), size=p_w.shape)  # 0.5 m RMS wander
    p_w[:, 0] += 40.0
    labels = np.concatenate([np.zeros(t_s.size, np.int64), np.ones(t_w.size, np.int64)])
    params = detector_params()
    scores = score_clusters(
        labels, np.concatenate([p_s, p_w]), np.concatenate([t_s, t_w]), params, n_clusters=2
    )
    assert scores.excess_residual[0] < 0.1
    assert scores.excess_residual[1] > params.max_excess
    assert scores.confidence[1] == 0.0
    assert scores.confidence[0] > 0.0


def test_frame_spread_counts_points_alone_in_their_frame() -> None:
    # Frame 0 holds two points 2 m apart (1 m from their mean), frames 1-6 one point each:
    # over all eight points the RMS is sqrt(2 / 8) = 0.5 m, not the pair's 1 m.
    pts = np.array([[0.0, 0, 10], [2.0, 0, 10]] + [[0.5 * i, 0, 10] for i in range(1, 7)])
    lab = np.zeros(8, np.int64)
    frame_bin = np.array([0, 0, 1, 2, 3, 4, 5, 6])
    assert frame_spread(lab, pts, frame_bin, 1)[0] == pytest.approx(0.5)
    # A cluster with one point per frame has no visible spread at all.
    assert frame_spread(lab[1:], pts[1:], frame_bin[1:], 1)[0] == 0.0


def test_sparse_far_wall_returns_keep_their_excess_residual() -> None:
    """The sparse returns of a far wall, linked into a slow "track": one return in most
    frames, wandering 1.5 m off any smooth path, and a few frames with two returns 8 m
    apart. Those pairs must not excuse the wander as the object's own size (the spread
    averaged over the pairs alone was 4 m, above the 3.2 m residual: excess 0 and
    confidence 0.15)."""
    rng = np.random.default_rng(5)
    t1 = np.arange(0.0, 20.0, 0.5)
    path = np.stack([np.full_like(t1, 78.0), -48.0 - 0.3 * t1, 10.0 + 0.2 * t1], axis=1)
    p1 = path + rng.normal(0.0, 1.5 / np.sqrt(3.0), size=path.shape) * [0.0, 1.0, 1.0]
    t2 = np.repeat([2.05, 7.05, 12.05, 17.05], 2)
    p2 = np.stack([np.full_like(t2, 78.0), -48.0 - 0.3 * t2, 10.0 + 0.2 * t2], axis=1)
    p2[:, 2] += np.tile([-4.0, 4.0], 4)
    t = np.concatenate([t1, t2])
    xyz = np.concatenate([p1, p2])
    params = detector_params()
    scores = score_clusters(np.zeros(t.size, np.int64), xyz, t, params, n_clusters=1)
    assert scores.residual[0] > 1.0
    assert scores.excess_residual[0] > params.max_excess
    assert scores.confidence[0] == 0.0


def test_window_with_two_instants_gives_no_evidence():
    # Six points at two instants 0.8 s apart: a quadratic is undetermined there, so the
    # window says nothing (no enormous acceleration, no perfect-fit residual).
    t = np.array([0.0, 0.0, 0.0, 0.8, 0.8, 0.8])
    p = np.array([[0, 0, 20], [0.1, 0, 20], [0, 0.1, 20], [5, 0, 20], [5.1, 0, 20], [5, 0.1, 20]])
    lab = np.zeros(6, np.int64)
    r, has = track_residual(lab, p.astype(float), t, 1, 1.0, 0.0, evidence=True, acceleration=True)
    assert not has[0] and r[0] == 0.0


def test_min_track_seconds_scales_short_tracks():
    t = np.repeat(np.arange(0.0, 2.0, 0.1), 3)
    xyz = np.stack([5.0 * t, np.zeros_like(t), np.full_like(t, 20.0)], axis=1)
    xyz += np.random.default_rng(0).normal(0, 0.05, xyz.shape)
    labels = np.zeros(t.size, np.int64)
    off = detector_params({"min_track_seconds": 0.0})
    base = score_clusters(labels, xyz, t, off, n_clusters=1)
    short = score_clusters(
        labels, xyz, t, detector_params({"min_track_seconds": 4.0}), n_clusters=1
    )
    assert base.confidence[0] > 0.1
    assert short.confidence[0] == pytest.approx(base.confidence[0] * 1.9 / 4.0, rel=1e-6)
    # The streaming detector passes its own value.
    stream = score_clusters(labels, xyz, t, off, n_clusters=1, min_track_seconds=2.0)
    assert stream.confidence[0] == pytest.approx(base.confidence[0] * 1.9 / 2.0, rel=1e-6)


def test_acceleration_over_several_window_phases_depends_little_on_where_windows_start():
    # A sparse straight track at 9 m/s (true acceleration 0): a frame with returns now and
    # then, 0.3 m of body scatter. One window grid measures 3.5-8 m/s^2 depending on
    # where it starts; eight grids pooled vary much less.
    rng = np.random.default_rng(3)
    frames = np.sort(rng.choice(np.arange(0, 6.0, 0.1), 18, replace=False))
    t = np.repeat(frames, 3) + rng.uniform(0, 0.08, frames.size * 3)
    xyz = np.column_stack([9.0 * t, np.zeros_like(t), np.full_like(t, 40.0)])
    xyz += rng.normal(0, 0.3, (t.size, 3))
    lab = np.zeros(t.size, np.int64)
    shifts = np.arange(0.0, 1.0, 0.1)

    def spread(phases: int) -> float:
        acc = [
            track_residual(lab, xyz, t, 1, 1.0, -s, acceleration=True, phases=phases)[0]
            for s in shifts
        ]
        return float(np.std(acc))

    assert spread(8) < 0.5 * spread(1)
    # The residual (not the acceleration) keeps one grid whatever `phases` says.
    one = track_residual(lab, xyz, t, 1, 1.0, 0.0)
    assert np.array_equal(one, track_residual(lab, xyz, t, 1, 1.0, 0.0, phases=8))


def test_a_stray_return_metres_away_does_not_make_a_smooth_track_erratic(monkeypatch) -> None:
    from clusterfilter_ros.core import scoring

    lab = np.zeros(600, dtype=np.int64)
    t, p = _track(False)
    clean = track_residual(lab, p, t, 1, 2.0, 0.0)[0]
    # One point 7 m off the track in every other 2 s window (a noise return the clusterer
    # joined to the drone): without the outlier rule the RMS of those windows triples.
    stray = p.copy()
    stray[np.arange(30, 600, 120)] += [5.0, 4.0, -2.7]
    with_stray = track_residual(lab, stray, t, 1, 2.0, 0.0)[0]
    # The fit itself still leans a little toward the stray point (0.17 -> 0.21 m).
    assert clean <= with_stray < clean + 0.06 < detector_params().smooth_residual
    # A bird's wobble moves every point: it is not mistaken for outliers.
    t_e, p_e = _track(True)
    assert track_residual(lab, p_e, t_e, 1, 2.0, 0.0)[0] > 0.5
    monkeypatch.setattr(scoring, "RESIDUAL_OUTLIER_FACTOR", np.inf)
    assert track_residual(lab, stray, t, 1, 2.0, 0.0)[0] > 0.5  # every point counted


def test_stray_returns_do_not_bend_the_fitted_acceleration(monkeypatch) -> None:
    from clusterfilter_ros.core import scoring

    lab = np.zeros(600, dtype=np.int64)
    t, p = _track(False)

    def accel(points: np.ndarray) -> float:
        return track_residual(lab, points, t, 1, 1.0, 0.0, acceleration=True, phases=8)[0]

    # One return in 30 (one per second) 4 m off the smooth turn: noise the clusterer
    # joined to the drone. The acceleration is refitted without them, as the residual is.
    stray = p.copy()
    stray[np.arange(7, 600, 30)] += [3.0, 2.0, -1.5]
    assert accel(stray) == pytest.approx(accel(p), abs=0.05)
    monkeypatch.setattr(scoring, "RESIDUAL_OUTLIER_FACTOR", np.inf)
    assert accel(stray) > 3 * accel(p)  # with them, the turn looks three times as sharp
