"""Streaming ``report_lag``: each frame estimated again once the stream has moved on
(fixed-lag smoothing), and :func:`smoothed_position` on samples with known answers."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import pytest

from clusterfilter_ros.core import streaming
from clusterfilter_ros.core.estimate import Estimate
from clusterfilter_ros.core.frame import AVIA, MID360, Frame
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


def _drone_gone_after(frames: list[Frame], stamp: float) -> list[Frame]:
    """The scene's frames with the drone's returns (the last three of each frame of a
    ``drone_points=3`` scene) removed after ``stamp``."""
    return [Frame(f.stamp, f.sensor, f.xyz[:-3]) if f.stamp > stamp else f for f in frames]


def test_delayed_estimates_cover_the_warm_up_and_follow_the_drone(scene, drone_path_fn):
    frames, _, _ = scene(duration=10.0, wall_points=400)
    det = StreamingDetector(detector_params({"report_lag": LAG, "report_backfill": 0.0}))
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
    # one report_lag earlier (the confirmed track's returns reach back further, but
    # without report_backfill the frames before were released before the confirmation)
    # and from then on every frame.
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
    frames = _drone_gone_after(frames, 1006.0)
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
    frames = _drone_gone_after(frames, 1004.0)
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
    # (Without report_hold_new_runs, whose held frames beyond 7 would be decided at once.)
    det = StreamingDetector(detector_params({"report_lag": LAG, "report_hold_new_runs": False}))
    for f in frames:  # push() only, delayed() never called
        det.push(f)
    made = det.flush()
    assert len(made) == 7 and det.stats()["delayed_dropped"] > 0
    assert made[-1].stamp == frames[-1].stamp


def _late_pieces_only(monkeypatch, cut: float) -> None:
    """Make every re-clustering after ``cut`` + 1 s select a track that starts at
    ``cut`` (as when the selected cluster is a later piece of the flight)."""
    real = streaming._recluster_snapshot

    def later_piece(snap):
        choice = real(snap)
        if choice.samples is None or snap.now < cut + 1.0:
            return choice
        kept = [s for s in choice.samples if s.t >= cut]
        return dataclasses.replace(choice, samples=kept or None)

    monkeypatch.setattr(streaming, "_recluster_snapshot", later_piece)


def _delayed_run(frames, lag):
    det = StreamingDetector(detector_params({"report_lag": lag}))
    _, delayed, _ = _push_all(frames, det)
    return det, delayed + det.flush()


def test_frames_the_current_track_no_longer_reaches_come_from_the_earlier_piece(
    scene, drone_path_fn, monkeypatch
):
    frames, _, _ = scene(duration=12.0, wall_points=200)
    lag, cut = 5.0, 1006.0
    _, reference = _delayed_run(frames, lag)
    _late_pieces_only(monkeypatch, cut)
    det, delayed = _delayed_run(frames, lag)
    # From 1007 s on the track starts at 1006 s; the frames between the first report and
    # 1006 s are estimated after that (5 s late), from the pieces of the track archived
    # when the re-clusterings cut them off, which the track continues.
    before_cut = [e.stamp for e in reference if e.stamp < cut - 0.5]
    assert len(before_cut) >= 20
    assert [e.stamp for e in delayed] == [e.stamp for e in reference]
    stamps = np.array([e.stamp for e in delayed])
    pos = np.array([e.position for e in delayed])
    err = np.linalg.norm(pos - drone_path_fn(stamps - 1000.0), axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.3
    # Only pieces some waiting frame may still need are kept.
    assert 0 < len(det._archive) <= 12
    p = det.params
    span = p.report_lag + max(p.track_window, p.link_max_gap) + max(p.max_gap, p.max_extrapolation)
    assert min(piece.ts[-1] for piece in det._archive) >= det._now - span


def test_without_the_archive_those_frames_would_be_lost(scene, monkeypatch):
    frames, _, _ = scene(duration=12.0, wall_points=200)
    _late_pieces_only(monkeypatch, 1006.0)
    monkeypatch.setattr(StreamingDetector, "_archive_piece", lambda self, *a: None)
    _, delayed = _delayed_run(frames, 5.0)
    # The frames released after 1007 s and before the track reaches them (5 s late).
    assert delayed and not [e for e in delayed if 1002.5 <= e.stamp <= 1005.5]


def _piece(ts, ps, conf=0.8):
    return streaming._TrackPiece(ts, ps, np.full(ts.size, 3.0), conf)


def test_a_piece_continues_the_same_object_not_another_one():
    ts = np.arange(0.0, 2.0, 0.1)
    drone = _piece(ts, _line(ts))
    later = np.arange(2.6, 4.0, 0.1)
    assert streaming._continues(drone, _piece(later, _line(later)), P)
    # 10 m off, or beyond link_max_gap: another object.
    assert not streaming._continues(drone, _piece(later, _line(later) + [0.0, 10.0, 0.0]), P)
    far = np.arange(2.0 + P.link_max_gap + 0.2, 5.0, 0.1)
    assert not streaming._continues(drone, _piece(far, _line(far)), P)


def test_could_continue_reads_a_velocity_only_where_one_was_measured():
    ts = np.arange(0.0, 2.0, 0.1)
    drone = _piece(ts, _line(ts))  # 2.2 m/s
    later = np.arange(3.5, 5.0, 0.1)  # 1.5 s on
    assert streaming._could_continue(drone, _piece(later, _line(later)), P)
    assert not streaming._could_continue(drone, _piece(later, _line(later) + [0, 8.0, 0]), P)
    # Still returns 8 m from where the drone appeared: neither line reaches the other.
    still = _piece(ts, np.tile([0.0, -5.0, 10.0], (ts.size, 1)))
    assert not streaming._could_continue(still, _piece(later, _line(later)), P)
    # A lone sample before the gap has no velocity: the later line carried back to it.
    lone = _piece(np.array([1.9]), _line(np.array([1.9])))
    assert streaming._could_continue(lone, _piece(later, _line(later)), P)
    assert not streaming._could_continue(
        _piece(np.array([1.9]), _line(np.array([1.9])) + [0, 12.0, 0]),
        _piece(later, _line(later)),
        P,
    )
    # Two lone samples: nothing to tell.
    assert streaming._could_continue(lone, _piece(np.array([3.5]), _line(np.array([3.5]))), P)


def test_another_objects_returns_before_the_track_are_not_reported_late():
    # A re-clustering linked 1 s of still returns 8 m off (a crown's edge) to the drone's
    # track 1.9 s later; the live output never reported them.
    head_t, drone_t = np.arange(0.0, 1.0, 0.1), np.arange(2.9, 5.0, 0.1)
    head = np.tile([0.0, -5.0, 10.0], (head_t.size, 1))
    ts = np.concatenate([head_t, drone_t])
    chain = _piece(ts, np.concatenate([head, _line(drone_t)]), conf=0.8)
    det = _detector_with([])
    np.testing.assert_array_equal(det._without_unreported_head(chain).ts, drone_t)
    # Reported live there: kept (the live output's own object).
    det._live_reports.append((0.5, head[0]))
    np.testing.assert_array_equal(det._without_unreported_head(chain).ts, ts)
    # The drone's own earlier returns, on its line: kept.
    det = _detector_with([])
    own = _piece(ts, _line(ts), conf=0.8)
    np.testing.assert_array_equal(det._without_unreported_head(own).ts, ts)


def test_a_bird_that_met_the_drones_path_is_cut_at_a_gap_shorter_than_max_gap():
    # A bird flying across (5 m/s along y, 8 m off) for 1 s, then the drone's own returns
    # 0.8 s later (default 3003 of the twenty-ninth set: the late output reported the
    # bird, which the live output never did, for 2 s): the gap is under max_gap (1 s) but
    # over report_head_gap (0.5 s), and the lines at its sides do not meet.
    head_t, drone_t = np.arange(0.0, 1.0, 0.1), np.arange(1.7, 4.0, 0.1)
    n = head_t.size
    bird = np.stack([np.full(n, -4.6), 1.3 + 5.0 * (head_t - 1.7), np.full(n, 10.0)], axis=1)
    ts = np.concatenate([head_t, drone_t])
    chain = _piece(ts, np.concatenate([bird, _line(drone_t)]), conf=0.8)
    det = _detector_with([])
    assert ts[head_t.size] - ts[head_t.size - 1] < det.params.max_gap
    np.testing.assert_array_equal(det._without_unreported_head(chain).ts, drone_t)
    # report_head_gap 1 s, as before deviation 91: kept.
    det.update_params({"report_head_gap": 1.0})
    np.testing.assert_array_equal(det._without_unreported_head(chain).ts, ts)


def test_returns_off_the_path_the_track_traces_back_are_not_reported_late():
    # A bird's returns 6 m off the drone's path began the cluster the live output
    # confirmed later (fast_pass 4300 of the forty-second set: the late output followed
    # the bird, 2-15 m off, for 1.1 s); the gap after them (0.3 s) is under
    # report_head_gap, so only the path the drone's own returns trace back tells them
    # apart. A lone return of something else among the drone's early ones goes too.
    bird_t, drone_t = np.array([0.0, 0.1, 0.2]), np.arange(0.5, 4.0, 0.1)
    stray_t = 1.05
    ts = np.sort(np.concatenate([bird_t, drone_t, [stray_t]]))
    ps = _line(ts)
    ps[: bird_t.size] += [0.0, 6.0, 0.0]
    stray = int(np.flatnonzero(ts == stray_t)[0])
    ps[stray] += [0.0, 0.0, 5.0]
    chain = _piece(ts, ps, conf=0.8)
    det = _detector_with([])
    # Never reported live: nothing to trace back from (the gap rule alone decides).
    np.testing.assert_array_equal(det._without_unreported_head(chain).ts, ts)
    det._live_reports.append((2.0, _line(np.array([2.0]))[0]))
    np.testing.assert_allclose(det._without_unreported_head(chain).ts, drone_t)
    det.update_params({"report_head_path": False})
    np.testing.assert_array_equal(det._without_unreported_head(chain).ts, ts)
    # The drone's own head, accelerating at 3 m/s^2 (under link_max_accel) before the
    # live output took it: kept whole.
    ts = np.arange(0.0, 4.0, 0.1)
    ps = _line(ts) + np.outer(0.5 * 3.0 * (ts - 2.0).clip(max=0.0) ** 2, [1.0, 0.0, 0.0])
    det = _detector_with([])
    det._live_reports.append((3.0, ps[30]))
    np.testing.assert_array_equal(det._without_unreported_head(_piece(ts, ps)).ts, ts)


def test_off_path_before_walks_back_from_the_trusted_samples():
    ts = np.arange(0.0, 3.0, 0.1)
    ps = _line(ts)
    ws = np.ones(ts.size)
    assert not streaming._off_path_before(ts, ps, ws, 10, P).any()
    ps[[2, 5]] += [0.0, 4.0, 0.0]  # two returns of something else, 4 m off
    np.testing.assert_array_equal(
        np.flatnonzero(streaming._off_path_before(ts, ps, ws, 10, P)), [2, 5]
    )
    # Only before start: the trusted samples are not judged.
    assert not streaming._off_path_before(ts, ps, ws, 2, P)[2:].any()
    # A sample more than max_gap (1 s) before the next kept one is not judged: across
    # such a gap a drone may have turned (avia_only 4203 of the forty-first set).
    ts_gap = np.concatenate([[0.0], np.arange(1.2, 3.0, 0.1)])
    ps_gap = _line(ts_gap) + np.outer(ts_gap == 0.0, [0.0, 9.0, 0.0])
    assert not streaming._off_path_before(ts_gap, ps_gap, np.ones(ts_gap.size), 1, P).any()
    # Trusted samples spanning under two frame periods give no velocity: the sample
    # before them is kept, however far off.
    assert not streaming._off_path_before(ts[4:7], ps[4:7], ws[4:7], 1, P).any()
    assert streaming._off_path_before(ts[4:10], ps[4:10], ws[4:10], 2, P)[1]


def test_a_stray_beside_a_gap_does_not_cut_the_drones_own_head():
    # The drone's own returns with a 0.75 s gap; the sample just before the gap is a lone
    # return of something else 4 m off, which bent the earlier side's line enough that
    # the two sides seemed not to meet (default 2800 of the twenty-eighth set). Strays go
    # first, so the drone's head is kept.
    ts = np.concatenate([np.arange(0.0, 1.4, 0.1), [1.45], np.arange(2.2, 4.0, 0.1)])
    ps = _line(ts)
    ps[14] += [0.0, 0.0, 4.0]
    chain = _piece(ts, ps, conf=0.8)
    det = _detector_with([])
    tracks = _detector_with([chain])._delayed_tracks()
    assert len(tracks) == 1
    np.testing.assert_array_equal(tracks[0].ts, np.delete(ts, 14))
    # Judged with the stray in place, the head would have been cut.
    assert det._without_unreported_head(chain).ts[0] > 1.0


def _detector_with(archive, track_t=None, offset=(0.0, 0.0, 0.0)):
    # No live run length rule: these detectors have no record of live estimates.
    values = {"report_lag": 5.0, "report_lag_min_run": 0.0, "report_hold_new_runs": False}
    det = StreamingDetector(detector_params(values))
    det._archive.extend(archive)
    if track_t is not None:
        # The current track, on the line (``offset`` from it).
        for t, xyz in zip(track_t, _line(track_t) + offset, strict=True):
            det._track.append(streaming._TrackSample(float(t), xyz, np.zeros((3, 3), np.float32)))
        det._selected_conf = 0.9
    return det


def _release_all(det, stamps):
    det._last_live = max(stamps)
    det._lagged.extend(stamps)
    det._release_delayed(np.inf)
    return {round(e.stamp, 3): e.confidence for e in det.delayed()}


def test_delayed_tracks_join_the_pieces_they_continue_and_not_another_object():
    bird_t, drone_t, track_t = np.arange(0, 1, 0.1), np.arange(1.2, 3, 0.1), np.arange(3.3, 5, 0.1)
    drone = _piece(drone_t, _line(drone_t), conf=0.7)
    bird = dataclasses.replace(
        _piece(bird_t, _line(bird_t) + [30.0, 0.0, 0.0], conf=0.6), reported_until=-np.inf
    )
    det = _detector_with([bird, drone], track_t)
    chains = det._delayed_tracks()
    assert len(chains) == 2
    np.testing.assert_array_equal(chains[0].ts, np.concatenate([drone_t, track_t]))
    assert chains[0].confidence == 0.9 and chains[0].reported_until == np.inf
    np.testing.assert_array_equal(chains[1].ts, bird_t)
    # The bird's piece was never reported live: its frames get nothing.
    assert _release_all(det, [0.5, 2.0, 4.0]) == {2.0: 0.9, 4.0: 0.9}
    # Reported live up to 0.9 s: frames up to then take it (the track does not reach them).
    det = _detector_with([dataclasses.replace(bird, reported_until=0.9), drone], track_t)
    assert _release_all(det, [0.5, 2.0, 4.0]) == {0.5: 0.6, 2.0: 0.9, 4.0: 0.9}
    # Without a current track: the kept pieces (a track dropped once stale).
    det = _detector_with([bird, drone])
    assert _release_all(det, [0.5, 2.0, 4.0]) == {2.0: 0.7}
    assert _detector_with([])._delayed_tracks() == []


def test_a_track_the_live_output_has_not_reported_takes_no_frame_from_the_one_before():
    # The drone's piece, reported live up to 2.9 s; then a re-clustering chose another
    # object 30 m away, seen since 1.0 s, which push() has not reported.
    drone_t, other_t = np.arange(0.0, 3.0, 0.1), np.arange(1.0, 4.0, 0.1)
    drone = dataclasses.replace(_piece(drone_t, _line(drone_t), conf=0.7), reported_until=2.9)
    other = (30.0, 0.0, 0.0)
    assert _release_all(_detector_with([drone], other_t, other), [1.5, 2.5]) == {1.5: 0.7, 2.5: 0.7}
    # Once push() has reported it (at 3.5 s), it takes them.
    det = _detector_with([drone], other_t, other)
    det._live_reports.append((3.5, _line(np.array([3.5]))[0] + other))
    assert _release_all(det, [1.5, 2.5]) == {1.5: 0.9, 2.5: 0.9}


def test_a_kept_piece_is_reported_until_the_newest_live_estimate_on_it():
    det = _detector_with([])
    ts = np.arange(0.0, 2.0, 0.1)
    piece = _piece(ts, _line(ts))
    assert det._reported_until(piece) == -np.inf
    det._live_reports.extend([(0.5, _line(np.array([0.5]))[0]), (1.0, _line(np.array([1.0]))[0])])
    det._live_reports.append((1.5, _line(np.array([1.5]))[0] + [5.0, 0.0, 0.0]))  # elsewhere
    det._live_reports.append((9.0, _line(np.array([9.0]))[0]))  # beyond the piece
    assert det._reported_until(piece) == 1.0


def test_frames_before_a_long_silence_keep_their_track_after_a_new_one_is_selected(
    scene, drone_path_fn, monkeypatch
):
    # No drone return from 1006 to 1008.5 s, longer than link_max_gap: the track selected
    # after the silence does not continue the one before. 8 s late, the frames before the
    # silence are released once the new track is selected; the earlier track's kept piece
    # serves them, as the live output reported positions on it.
    frames, _, _ = scene(duration=16.0, wall_points=200)
    frames = [
        Frame(f.stamp, f.sensor, f.xyz[:-3]) if 1006.0 < f.stamp < 1008.5 else f for f in frames
    ]
    _, delayed = _delayed_run(frames, 8.0)
    before = [e for e in delayed if 1005.0 <= e.stamp <= 1006.0]
    assert len(before) >= 18
    err = np.linalg.norm(
        np.array([e.position for e in before])
        - drone_path_fn(np.array([e.stamp for e in before]) - 1000.0),
        axis=1,
    )
    assert err.max() < 0.5
    monkeypatch.setattr(StreamingDetector, "_reported_until", lambda self, piece: -np.inf)
    _, without = _delayed_run(frames, 8.0)
    assert len([e for e in without if 1005.0 <= e.stamp <= 1006.0]) < len(before) // 2


def _old_track(ts, offset=0.0):
    return [
        streaming._TrackSample(float(t), xyz + offset, np.zeros((2, 3), np.float32))
        for t, xyz in zip(ts, _line(ts), strict=True)
    ]


def test_a_drone_that_went_silent_is_reported_late_up_to_its_last_returns(scene, monkeypatch):
    # The drone's returns stop at 6 s. Its cluster stays selected while its returns are
    # in the 10 s local history; once they leave it (14 s) the track is dropped, before
    # the frames of its last seconds are 12 s old: they take the lost track's kept
    # samples (without them, nothing after 3 s would be reported late).
    frames, _, _ = scene(duration=20.0, wall_points=200, drone_points=3)
    frames = _drone_gone_after(frames, 1006.0)
    det, delayed = _delayed_run(frames, 12.0)
    last_live = det._last_live
    assert 1006.0 <= last_live <= 1006.6
    assert max(e.stamp for e in delayed) >= last_live - 0.15
    monkeypatch.setattr(StreamingDetector, "_archive_piece", lambda self, *a: None)
    _, without = _delayed_run(frames, 12.0)
    assert not [e for e in without if e.stamp >= 1003.0]


def test_a_rejected_track_is_forgotten_and_a_lost_one_is_kept():
    det = _detector_with([_piece(np.arange(0, 1, 0.1), _line(np.arange(0, 1, 0.1)))])
    window = det.params.reacquire_window  # 3 s
    old = _old_track(np.arange(1.0, 2.9, 0.1))  # newest return at 2.8 s
    # Dropped 1.5 s after its newest return, while it could still have been re-acquired:
    # rejected by the re-clustering; it and the pieces before it are forgotten.
    det._now = 2.8 + 1.5
    det._archive_piece(old, 0.8, det._now)
    assert len(det._archive) == 0
    # Dropped once nothing was left to re-acquire: lost, its samples stay for the
    # frames still waiting.
    det._now = 2.8 + window + 0.2
    det._archive_piece(old, 0.8, det._now)
    assert len(det._archive) == 1 and det._archive[0].ts.size == 19
    # Replaced by a track starting at 2.0 s: only its samples before that are kept.
    det = _detector_with([], np.arange(2.0, 3.0, 0.1))
    det._now = 3.0
    det._archive_piece(_old_track(np.arange(0.0, 2.95, 0.1)), 0.8, det._now)
    assert len(det._archive) == 1 and det._archive[0].ts[-1] < 2.0 - 1e-9
    # Pieces no waiting frame can need any more are dropped.
    det._now = 30.0
    det._archive_piece(_old_track(np.arange(0.0, 2.95, 0.1)), 0.8, det._now)
    assert len(det._archive) == 0


def test_a_rejected_track_the_live_output_held_for_seconds_is_kept():
    # Deviation 93: rejected 1.5 s after its newest return, but reported live over 2 s
    # (report_backfill_min_run) of it: its samples stay, up to the newest live estimate.
    old = _old_track(np.arange(1.0, 4.9, 0.1))  # newest return at 4.8 s

    def archive_after_live(report_t, offset=(0.0, 0.0, 0.0)):
        det = _detector_with([])
        det._live_reports.extend((t, _line(np.array([t]))[0] + offset) for t in report_t)
        det._now = 4.8 + 1.5
        det._archive_piece(old, 0.8, det._now)
        return det._archive

    archive = archive_after_live(np.arange(2.5, 4.55, 0.1))
    assert len(archive) == 1
    assert abs(archive[0].reported_until - 4.5) < 1e-9
    # Reported live over 1 s only: forgotten, as before.
    assert len(archive_after_live(np.arange(3.5, 4.55, 0.1))) == 0
    # Reported over 2 s, but 8 m off the track (another object): forgotten.
    assert len(archive_after_live(np.arange(2.5, 4.55, 0.1), (0.0, 8.0, 0.0))) == 0


def test_a_reported_tracks_newer_returns_stay_when_an_older_cluster_is_chosen():
    # Deviation 105: the reported track ran 1.0-4.8 s, reported live over 2.5-4.5 s;
    # the re-clustering at 6.3 s chose a cluster that ended at 2.0 s (its recent one
    # rejected). With report_keep_newer the samples after 2.0 s stay, as their own chain
    # after the current track's, and the frames up to the newest live estimate (4.5 s)
    # are reported late from them; without it, or with the live output having reported
    # them for 1 s only, they are forgotten.
    old = _old_track(np.arange(1.0, 4.9, 0.1))

    def late_tracks(keep, report_t):
        det = _detector_with([], np.arange(0.0, 2.05, 0.1))
        det.params = det.params.copy(report_keep_newer=keep)
        det._live_reports.extend((t, _line(np.array([t]))[0]) for t in report_t)
        det._now = 4.8 + 1.5
        det._archive_piece(old, 0.8, det._now)
        return det._delayed_tracks()

    chains = late_tracks(True, np.arange(2.5, 4.55, 0.1))
    assert chains[0].ts[-1] > 4.7 and abs(chains[0].reported_until - 4.5) < 1e-9
    assert chains[0].ts[0] < 0.1  # the current track continues into them: one chain
    for keep, report_t in ((False, np.arange(2.5, 4.55, 0.1)), (True, np.arange(3.5, 4.55, 0.1))):
        assert max(c.ts[-1] for c in late_tracks(keep, report_t)) < 2.1


def test_a_kept_newer_piece_that_begins_at_the_tracks_newest_sample_is_not_dropped():
    # Flyover 4805 of the forty-seventh set: the current track's grown tail took the very
    # return the kept newer piece (deviation 105) begins with. Counted among the older
    # pieces, the piece was then dropped as one the current track reaches back over, and
    # the late output lost the frames up to its newest live estimate (4.5 s here).
    newer_t = np.arange(2.0, 4.85, 0.1)
    newer = dataclasses.replace(_piece(newer_t, _line(newer_t), conf=0.8), reported_until=4.5)
    det = _detector_with([newer], np.arange(0.0, 2.05, 0.1))
    assert det._track[-1].t == newer_t[0]
    chains = det._delayed_tracks()
    assert chains[0].ts[-1] > 4.7 and abs(chains[0].reported_until - 4.5) < 1e-9
    assert chains[0].ts[0] < 0.1  # the current track continues into it: one chain


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


def test_the_first_returns_after_a_pause_take_the_velocity_across_it():
    # A pass at 2.2 m/s; 1.5 s without returns (longer than max_gap 1 s, within
    # link_max_gap 2 s), then two samples 0.05 s apart: no velocity of their own.
    ts = np.concatenate([np.arange(0.0, 2.01, 0.1), [3.5, 3.55]])
    ps = _line(ts)
    w = np.ones(ts.size)
    for stamp in (3.1, 3.6, 3.9):
        np.testing.assert_allclose(
            smoothed_position(ts, ps, w, stamp, P), _line(np.array([stamp]))[0], atol=1e-9
        )
    # Across a pause longer than link_max_gap, and than extend_far_gap (3 s, which
    # report_extend_far allows: a far lone return), nothing says where the object went
    # meanwhile: the samples are where it was.
    ts[-2:] += 2.0
    got = smoothed_position(ts, _line(ts), w, 5.7, P)
    np.testing.assert_allclose(got, _line(ts[-2:]).mean(axis=0), atol=1e-9)


@pytest.mark.parametrize("far", [True, False])
def test_a_lone_last_return_seconds_after_the_rest_takes_the_velocity_across(far):
    # A pass at 2.2 m/s, then 2.5 s without returns (beyond link_max_gap, within
    # extend_far_gap) and two samples 0.05 s apart at its end: past them (deviation 122)
    # and beside the first samples of a track that begins so, the chord's velocity.
    # Without report_extend_far they are where they were.
    params = P.copy(report_extend_far=far)
    ts = np.concatenate([np.arange(0.0, 2.01, 0.1), [4.5, 4.55]])
    w = np.ones(ts.size)
    for stamp in (4.3, 4.8, 5.0):
        got = smoothed_position(ts, _line(ts), w, stamp, params)
        want = _line(np.array([stamp]))[0] if far else _line(ts[-2:]).mean(axis=0)
        np.testing.assert_allclose(got, want, atol=1e-9)
    first = ts[-1] + 0.05 - ts[::-1]  # the same in reverse: a track's first samples
    got = smoothed_position(first, _line(first), w, -0.3, params)
    want = _line(np.array([-0.3]))[0] if far else _line(first[:2]).mean(axis=0)
    np.testing.assert_allclose(got, want, atol=1e-9)


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


def test_an_object_reported_live_for_a_moment_is_not_reported_over_its_history(scene):
    # The drone's returns stop at 4.2 s, just after the warm-up: the live output reports
    # it from 4.0 to 4.7 s (0.7 s, coasting max_extrapolation past its last return).
    frames, _, _ = scene(duration=10.0, wall_points=200, drone_points=3)
    frames = _drone_gone_after(frames, 1004.2)
    late = {}
    for shortest in (0.0, 1.0):
        values = {
            "report_lag": 3.0,
            "warmup": 4.0,
            "report_lag_min_run": shortest,
            "report_hold_new_runs": False,  # the test below
        }
        det = StreamingDetector(detector_params(values))
        live, delayed, _ = _push_all(frames, det)
        late[shortest] = [e.stamp - 1000.0 for e in delayed + det.flush()]
        last_live = max(e.stamp for e in live) - 1000.0
        assert 4.6 <= last_live <= 4.8
    assert min(late[0.0]) < 1.1 and max(late[0.0]) == last_live  # its whole history
    # With a 1 s minimum run: only the frames that fell due while the live run could
    # still have gone on (up to max_gap after its newest estimate).
    p = detector_params()
    assert late[1.0] == [s for s in late[0.0] if s + 3.0 <= last_live + p.max_gap + 1e-6]


def test_frames_before_a_new_live_run_wait_until_it_has_lasted(scene):
    # The drone's returns stop 1 s after its confirmation (a live run of about 1.5 s).
    # The frames up to report_lag (2 s) before the confirmation fall due after it:
    # without report_hold_new_runs they are reported then, from the track's history;
    # with it each waits until the run has lasted as long as the frame is before it (at
    # most report_backfill_min_run), so only the last 1.5 s before it are reported.
    # (report_backfill_min_points off: deviation 98 would take the others back.)
    frames, _, _ = scene(duration=10.0, wall_points=200, drone_points=3)
    first_live = min(e.stamp for e in run_streaming(frames))
    short = _drone_gone_after(frames, first_live + 1.0)
    live = run_streaming(short)
    run = max(e.stamp for e in live) - first_live
    assert 1.2 <= run <= 1.8
    values = {"report_lag": LAG, "report_backfill_min_points": 0}
    held = run_streaming(short, detector_params(values))
    assert first_live - run - 0.15 <= min(e.stamp for e in held) <= first_live - run + 0.15
    free = run_streaming(short, detector_params({**values, "report_hold_new_runs": False}))
    assert min(e.stamp for e in free) < first_live - LAG + 0.15
    # A run that lasts: every frame is reported, each once the run has lasted as long as
    # the frame is before it, and in stamp order.
    det = StreamingDetector(detector_params(values))
    live, delayed, released_at = _push_all(frames, det)
    delayed += det.flush()
    stamps = np.array([e.stamp for e in delayed])
    assert np.all(np.diff(stamps) > 0)
    assert stamps.min() < first_live - LAG + 0.15
    for e, at in zip(delayed, released_at, strict=False):
        if e.stamp < first_live:
            assert at >= first_live + min(first_live - e.stamp, 2.0) - 0.11


def test_at_the_end_of_a_stream_a_run_still_going_has_ended(scene):
    # The stream stops 1 s into the drone's first live run. flush() takes the run as
    # ended there: the frames before it are estimated from a track with
    # report_backfill_min_points returns (deviation 98), as after a run cut short
    # mid-stream; with that exception off only those the 1 s run covers (deviation 107).
    frames, _, _ = scene(duration=10.0, wall_points=200, drone_points=3)
    first_live = min(e.stamp for e in run_streaming(frames))
    cut = [f for f in frames if f.stamp <= first_live + 1.0]
    kept = run_streaming(cut, detector_params({"report_lag": LAG}))
    assert min(e.stamp for e in kept) < first_live - LAG - 0.5
    strict = {"report_lag": LAG, "report_backfill_min_points": 0}
    covered = run_streaming(cut, detector_params(strict))
    assert first_live - 1.15 <= min(e.stamp for e in covered) <= first_live - 0.85


def test_before_new_run_only_for_a_run_after_a_silence():
    det = StreamingDetector(detector_params({"report_lag": 3.0}))
    assert det.params.link_max_gap == 2.0 and det.params.report_backfill_min_run == 2.0
    first = [round(0.1 * i, 1) for i in range(11)]  # 0.0-1.0 s, a run of 1 s
    second = [4.0, 4.1, 4.2]  # after 3 s of silence, still going
    det._live_reports.extend((s, np.zeros(3)) for s in first + second)
    det._now = 4.2
    assert not det._before_new_run(0.5)  # reported live itself
    assert det._before_new_run(3.5)  # 2.5 s after the last report: a new run, 0.2 s so far
    assert not det._before_new_run(2.5)  # within link_max_gap of one: report_bridge's
    assert not det._before_new_run(3.9)  # 0.1 s before a run that has lasted 0.2 s
    # The new run pauses for 1.5 s (less than link_max_gap) and goes on: one run, which
    # has lasted 1.8 s, longer than the frame at 3.5 s is before it.
    paused = StreamingDetector(detector_params({"report_lag": 3.0}))
    paused._live_reports.extend((s, np.zeros(3)) for s in [*first, *second, 5.7, 5.8])
    paused._now = 5.8
    assert not paused._before_new_run(3.5)
    # Paused for 2.5 s: the run of 0.2 s ended; the frame still waits (to be dropped).
    ended = StreamingDetector(detector_params({"report_lag": 3.0}))
    ended._live_reports.extend((s, np.zeros(3)) for s in [*first, *second, 6.7, 6.8])
    ended._now = 6.8
    assert ended._before_new_run(3.5)
    off = StreamingDetector(detector_params({"report_lag": 3.0, "report_hold_new_runs": False}))
    off._live_reports.extend((s, np.zeros(3)) for s in first + second)
    off._now = 4.2
    assert not off._before_new_run(3.5)


def test_the_late_tail_stops_short_of_static_structure():
    from clusterfilter_ros.core import voxel
    from clusterfilter_ros.core.streaming import _short_of_structure, _TrackSample

    p = detector_params({"report_lag": 3.0})
    # Five grown tail samples 2 m apart along x; static structure at the third's voxel.
    xs = [0.0, 2.0, 4.0, 6.0, 8.0]
    samples = tuple(
        _TrackSample(float(i), np.array([x, 20.0, 5.0]), np.array([[x, 20.0, 5.0]], np.float32))
        for i, x in enumerate(xs)
    )
    structure = np.sort(voxel.voxel_keys(np.array([[4.0, 20.0, 5.0]]), p.static_voxel))
    # 1.5 m voxels: the samples are in voxels 0, 1, 2, 4 and 5 along x; the second and
    # the third are in or next to the structure's (26 neighbours): the tail stops before
    # the second, and what lies beyond is not taken either.
    assert [s.t for s in _short_of_structure(samples, structure, p)] == [0.0]
    assert _short_of_structure(samples, structure, p.copy(report_grow_max_contact=1.0)) == samples
    assert _short_of_structure(samples, np.empty(0, np.int64), p) == samples
    assert _short_of_structure((), structure, p) == ()
    # Half of a sample's returns next to structure is not more than half.
    two = (
        _TrackSample(
            0.0, np.array([3.0, 20.0, 5.0]), np.array([[2.0, 20, 5], [8.0, 20, 5]], np.float32)
        ),
    )
    assert _short_of_structure(two, structure, p) == two


def test_live_run_seconds_finds_the_run_after_a_stamp():
    det = StreamingDetector(detector_params({"report_lag": 3.0}))
    first = [round(0.1 * i, 1) for i in range(11)]  # 0.0-1.0 s
    second = [3.0, 3.1, 3.2]  # 2 s later: a run of its own
    det._live_reports.extend((s, np.zeros(3)) for s in first + second)
    det._now = 6.0
    assert det._live_run_seconds(0.5) == 1.0
    assert det._live_run_seconds(1.5) == 3.2 - 3.0
    assert det._live_run_seconds(3.1) == 3.2 - 3.0
    assert det._live_run_seconds(3.5) == 0.0  # nothing reported after it
    det._now = 3.5  # the second run may still go on
    assert det._live_run_seconds(1.5) == np.inf
    assert det._live_run_seconds(0.5) == 1.0


def test_a_lone_stray_sample_is_left_out_of_the_delayed_estimate():
    from clusterfilter_ros.core.streaming import _stray_samples, _TrackPiece, _without_strays

    p = detector_params({"report_lag": 3.0})
    # A pass at 6 m/s, a sample every 0.2 s, and at 1.1 s one 8 m off its line (a return
    # of something else the track took; flyover seed 3201 of the thirty-first set).
    ts = np.round(np.arange(0.0, 2.01, 0.2), 6)
    ps = np.column_stack([6.0 * ts, np.zeros(ts.size), np.full(ts.size, 40.0)])
    ts = np.insert(ts, 6, 1.1)
    ps = np.insert(ps, 6, [6.6 - 6.0, 5.0, 35.0], axis=0)
    stray = _stray_samples(ts, ps, p)
    assert stray.tolist() == [i == 6 for i in range(ts.size)]
    # A sample 1 m off (within stray_distance) stays, and so do the ends.
    near = ps.copy()
    near[6] = [6.6, 1.0, 40.0]
    assert not _stray_samples(ts, near, p).any()
    ends = ps.copy()
    ends[[0, -1]] += [0.0, 8.0, 0.0]
    assert not _stray_samples(ts, ends, p)[[0, -1]].any()
    det = StreamingDetector(p)
    piece = _without_strays(_TrackPiece(ts, ps, np.full(ts.size, 3.0), 0.9), p)
    assert piece.ts.size == ts.size - 1 and 1.1 not in piece.ts
    est = det._delayed_estimate(1.1, piece)
    assert est is not None and np.linalg.norm(est.position - [6.6, 0.0, 40.0]) < 0.3


def test_with_report_backfill_a_late_confirmed_drone_is_reported_from_its_first_returns(
    scene, drone_path_fn
):
    # The drone is in view from the start; the live output confirms it after the warm-up
    # (3 s), more than report_lag after its first returns.
    frames, _, _ = scene(duration=10.0, wall_points=400)
    det = StreamingDetector(detector_params({"report_lag": LAG, "report_backfill": 5.0}))
    live, delayed, released_at = _push_all(frames, det)
    first_live = min(e.stamp for e in live)
    start = frames[0].stamp
    assert first_live - start > LAG + 0.5
    # At the confirmation the waiting frames come at once, oldest first: no later than
    # report_lag + report_backfill after their stamp, and never before report_lag.
    delays = np.array([at - e.stamp for e, at in zip(delayed, released_at, strict=True)])
    assert np.all(delays >= LAG - 1e-9) and np.all(delays <= LAG + 5.0 + 1e-9)
    assert delays.max() > LAG + 0.5
    delayed += det.flush()
    stamps = np.array([e.stamp for e in delayed])
    assert np.all(np.diff(stamps) > 0)
    assert stamps.min() <= start + 0.3  # the track's returns reach back to the start
    pos = np.array([e.position for e in delayed])
    err = np.linalg.norm(pos - drone_path_fn(stamps - 1000.0), axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.3
    # Without it, the frames more than report_lag before the confirmation are lost.
    det = StreamingDetector(detector_params({"report_lag": LAG, "report_backfill": 0.0}))
    _, without, _ = _push_all(frames, det)
    without += det.flush()
    assert min(e.stamp for e in without) > first_live - LAG - 0.2
    assert {e.stamp for e in without} < set(stamps.tolist())
    # The frames report_lag reaches anyway are estimated when they fall due, as without
    # it (held back only to keep the order).
    by_stamp = {e.stamp: e.position for e in delayed}
    for e in without:
        np.testing.assert_array_equal(by_stamp[e.stamp], e.position)


def _sparse_head(frames: list[Frame], until: float, every: int) -> list[Frame]:
    """The scene's frames (``drone_points=3``) with the drone's returns before ``until``
    cut to one Mid360 return every ``every`` frame periods: a far approach, too sparse for
    the clustering to keep."""
    out = []
    for i, f in enumerate(frames):
        if f.stamp < until:
            keep = f.sensor == MID360 and (i // 2) % every == 0
            f = Frame(f.stamp, f.sensor, f.xyz[:-2] if keep else f.xyz[:-3])
        out.append(f)
    return out


def test_the_late_output_reaches_back_over_a_sparse_head(scene, drone_path_fn):
    # One return every 0.8 s for the first 4 s, then three a frame: the clustered track
    # begins at about 3.5 s; grown back (report_extend_head) it reaches the start.
    frames, _, _ = scene(duration=10.0, wall_points=400)
    frames = _sparse_head(frames, 1004.0, every=8)
    runs = {}
    for grow in (False, True):
        det = StreamingDetector(detector_params({"report_lag": LAG, "report_extend_head": grow}))
        live, delayed, _ = _push_all(frames, det)
        runs[grow] = (live, delayed + det.flush())
    (live_off, late_off), (live_on, late_on) = runs[False], runs[True]
    assert min(e.stamp for e in late_off) > 1003.0
    assert min(e.stamp for e in late_on) <= 1000.1
    stamps = np.array([e.stamp for e in late_on])
    truth = drone_path_fn(stamps - 1000.0)
    err = np.linalg.norm(np.array([e.position for e in late_on]) - truth, axis=1)
    assert err.max() < 1.0 and np.sqrt(np.mean(err**2)) < 0.5
    # Where both report, away from the clustered track's start (whose estimates now have
    # samples on both sides), the same estimate; the live output does not use the head.
    by_stamp = {e.stamp: e.position for e in late_on}
    start = min(e.stamp for e in late_off)
    for e in late_off:
        if e.stamp > start + 1.0:
            np.testing.assert_array_equal(by_stamp[e.stamp], e.position)
    assert [(e.stamp, e.position.tolist()) for e in live_on] == [
        (e.stamp, e.position.tolist()) for e in live_off
    ]


def test_report_backfill_leaves_the_live_output_alone(scene):
    frames, _, _ = scene(duration=7.0, wall_points=200)
    base = run_streaming(frames)
    det = StreamingDetector(detector_params({"report_lag": LAG, "report_backfill": 4.0}))
    live, _, _ = _push_all(frames, det)
    assert [(e.stamp, e.position.tolist()) for e in live] == [
        (e.stamp, e.position.tolist()) for e in base
    ]


def test_frames_wait_at_most_report_backfill_when_nothing_is_confirmed():
    # An empty stream: frames wait report_lag + report_backfill, then are let go.
    backfill = 3.0
    det = StreamingDetector(detector_params({"report_lag": LAG, "report_backfill": backfill}))
    xyz = np.zeros((0, 3), np.float32)
    for k in range(200):
        det.push(Frame(1000.0 + 0.1 * k, MID360, xyz))
        assert det.delayed() == []
    waiting = det.stats()["delayed_pending"]
    assert (LAG + backfill) * 10 - 1 <= waiting <= (LAG + backfill) * 10 + 1
    assert det.flush() == []


def test_an_object_confirmed_after_its_returns_stopped_stays_unreported_with_backfill(scene):
    frames, _, _ = scene(duration=8.0, wall_points=200, drone_points=3)
    frames = _drone_gone_after(frames, 1004.0)
    values = {"report_lag": 3.0, "warmup": 4.6, "report_backfill": 5.0}
    det = StreamingDetector(detector_params(values))
    live, delayed, _ = _push_all(frames, det)
    assert live == [] and delayed + det.flush() == []


def test_a_track_reported_live_for_a_moment_is_not_backfilled(scene):
    # The drone's returns stop 1 s after its confirmation: the live run lasts about 1.5
    # s, less than report_backfill_min_run (2 s), so the frames before the confirmation
    # beyond report_lag stay unreported; with the minimum at 0 they are reported.
    # (report_backfill_min_points off: the test below is about it.)
    frames, _, _ = scene(duration=10.0, wall_points=200, drone_points=3)
    first_live = min(e.stamp for e in run_streaming(frames))
    cut = first_live + 1.0
    frames = _drone_gone_after(frames, cut)
    values = {
        "report_lag": LAG,
        "report_backfill": 5.0,
        "report_backfill_min_run": 2.0,
        "report_backfill_min_points": 0,
    }
    live = run_streaming(frames)
    assert min(e.stamp for e in live) == first_live
    assert max(e.stamp for e in live) - first_live < 2.0
    late = run_streaming(frames, detector_params(values))
    assert late and min(e.stamp for e in late) >= first_live - LAG - 0.15
    short = run_streaming(frames, detector_params({**values, "report_backfill_min_run": 0.0}))
    assert min(e.stamp for e in short) < first_live - LAG - 0.5


def test_a_short_live_run_is_backfilled_from_a_track_with_many_returns(scene, drone_path_fn):
    # The same short live run (about 1.5 s), but the confirmed track holds six returns a
    # frame pair for seconds (deviation 98: a drone confirmed in the last second of a
    # close pass): with report_backfill_min_points at or below what the track holds, its
    # frames before the confirmation are reported late after all, from the track's
    # returns; above it they are not.
    frames, _, _ = scene(duration=10.0, wall_points=200, drone_points=3)
    first_live = min(e.stamp for e in run_streaming(frames))
    frames = _drone_gone_after(frames, first_live + 1.0)
    values = {"report_lag": LAG, "report_backfill": 5.0, "report_backfill_min_run": 2.0}
    kept = run_streaming(frames, detector_params({**values, "report_backfill_min_points": 100}))
    assert min(e.stamp for e in kept) < first_live - LAG - 0.5
    stamps = np.array([e.stamp for e in kept])
    assert np.all(np.diff(stamps) > 0)
    pos = np.array([e.position for e in kept])
    err = np.linalg.norm(pos - drone_path_fn(stamps - 1000.0), axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.3
    # At most 6 returns a frame pair over the stream's 10 s: fewer than 1000.
    strict = {**values, "report_backfill_min_points": 1000}
    dropped = run_streaming(frames, detector_params(strict))
    assert dropped and min(e.stamp for e in dropped) >= first_live - LAG - 0.15


def test_frames_whose_live_run_ended_too_soon_wait_for_the_next_run(scene, drone_path_fn):
    # Deviation 110: the drone's returns pause for 2 s, 1 s after its confirmation at the
    # end of the warm-up. The live output holds it for about 1.5 s, pauses, then holds it
    # to the end. The frames before the confirmation waited for that first run to last
    # report_backfill_min_run and were dropped when it ended; with report_next_run they
    # wait for the next run instead, within report_backfill, and are reported from the
    # drone's track.
    frames, _, _ = scene(duration=16.0, wall_points=200, drone_points=3)
    first_live = min(e.stamp for e in run_streaming(frames))
    frames = [
        Frame(f.stamp, f.sensor, f.xyz[:-3])
        if first_live + 1.0 < f.stamp <= first_live + 3.0
        else f
        for f in frames
    ]
    live = np.array([e.stamp for e in run_streaming(frames)])
    pause = np.diff(live).max()
    assert 1.5 <= pause <= 2.5 and live[np.argmax(np.diff(live))] - first_live < 2.0
    values = {"report_lag": LAG, "report_backfill_min_points": 0}
    late = run_streaming(frames, detector_params(values))
    stamps = np.array([e.stamp for e in late])
    assert np.all(np.diff(stamps) > 0)
    assert stamps.min() < 1000.2  # the stream's first frames
    pos = np.array([e.position for e in late])
    err = np.linalg.norm(pos - drone_path_fn(stamps - 1000.0), axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.3
    dropped = run_streaming(frames, detector_params({**values, "report_next_run": False}))
    assert min(e.stamp for e in dropped) > 1000.9


def test_a_frame_is_decided_when_its_own_run_allows_whatever_the_frames_before_it():
    # Deviation 110: a held frame waiting for the next live run does not hold back the
    # decision of the frames behind it, only their emission: each is decided from the
    # tracks when its own run has lasted, and all come out in stamp order.
    det = StreamingDetector(detector_params({"report_lag": LAG}))
    decided: list[float] = []

    def decide(frame, until, forced, tracks):
        if frame.stamp > 1.0:
            frame.decided = True
            frame.estimate = Estimate(frame.stamp, np.zeros(3), 1.0, 10)
            decided.append(frame.stamp)
        return tracks

    det._decide_held = decide  # type: ignore[method-assign]
    det._held.extend(streaming._HeldFrame(s) for s in (1.0, 2.0, 3.0))
    det._resolve_held(10.0)
    assert decided == [2.0, 3.0] and det.delayed() == []
    det._held[0].decided = True
    det._resolve_held(10.0)
    assert [e.stamp for e in det.delayed()] == [2.0, 3.0] and not det._held


def test_after_a_short_run_only_an_object_the_next_run_could_be_is_taken():
    # Deviation 110: a frame that waited past a short live run for the next one is
    # estimated from the short run's track only if a track of the next run could continue
    # it; another object reported in the next run does not confirm it.
    det = StreamingDetector(P)
    ts = np.arange(0.0, 2.0, 0.1)
    short = dataclasses.replace(_piece(ts, _line(ts)), reported_until=1.9)
    later = np.arange(3.5, 6.0, 0.1)
    same = dataclasses.replace(_piece(later, _line(later)), reported_until=5.9)
    other = dataclasses.replace(same, ps=_line(later) + [0.0, 30.0, 0.0])
    assert det._continued_in(short, [short, same], since=3.5)
    assert not det._continued_in(short, [short, other], since=3.5)
    assert det._tracks_estimate(1.0, [short, same], reported_since=3.5) is not None
    assert det._tracks_estimate(1.0, [short, other], reported_since=3.5) is None
    assert det._tracks_estimate(1.0, [short, other]) is not None  # no run waited for


@pytest.mark.parametrize("next_run", [True, False])
def test_a_frame_reached_only_by_newer_returns_not_kept_waits_for_the_next_run(next_run):
    # Deviation 112: report_keep_newer did not keep a replaced track's newer returns (held
    # live too briefly). A frame they reached, with no track left for it when due, waits
    # for the next live run instead of being dropped.
    det = StreamingDetector(detector_params({"report_lag": LAG, "report_next_run": next_run}))
    det._now = 12.0 + LAG
    for stamp in np.arange(9.5, 12.05, 0.1):
        det._live_reports.append((float(stamp), np.zeros(3)))
    det._last_live = det._live_reports[-1][0]
    det._unkept.append((9.0, 11.0, None))
    det._lagged.extend([8.5, 10.0])
    det._release_delayed(10.0)
    if not next_run:
        assert not det._held
        return
    (held,) = det._held  # 8.5 lies before the returns: dropped as before
    last = det._live_reports[-1][0]  # that run's last estimate (12.0 in float steps)
    assert held.stamp == 10.0 and not held.decided and held.after > last  # after that run
    assert held.dropped is None  # newer returns of a replaced track: no agreement asked


@pytest.mark.parametrize("next_dropped", [True, False])
def test_a_dropped_track_held_live_briefly_leaves_its_span_to_wait_for_the_next_run(
    next_dropped,
):
    # Deviation 133: a re-clustering dropped the reported track (no confident track
    # after it) 1.5 s after its newest return, and the live output had held it for 1 s
    # only, so its samples are forgotten (deviation 93). With report_next_dropped the
    # span from its first sample to its newest live estimate is remembered as unkept,
    # so that a frame in it that finds no track when due waits for the next live run
    # (deviation 112's path) instead of being dropped.
    old = _old_track(np.arange(1.0, 4.9, 0.1))  # newest return at 4.8 s
    det = _detector_with([])
    det.params = det.params.copy(report_next_dropped=next_dropped)
    det._live_reports.extend((t, _line(np.array([t]))[0]) for t in np.arange(3.5, 4.55, 0.1))
    det._now = 4.8 + 1.5
    det._archive_piece(old, 0.8, det._now)
    assert len(det._archive) == 0  # forgotten either way
    if not next_dropped:
        assert not det._unkept
        return
    ((first, until, piece),) = det._unkept
    assert abs(first - 1.0) < 1e-9 and abs(until - 4.5) < 1e-9
    assert piece.ts.size == 39  # kept for the agreement test of the frames it holds
    # A frame in that span, due with no track, waits for the next run with the piece.
    det._lagged.append(3.0)
    det._last_live = det._live_reports[-1][0]
    det._release_delayed(3.0)
    (held,) = det._held
    assert held.stamp == 3.0 and held.dropped is piece and held.after > det._last_live


def test_a_held_frame_of_a_dropped_track_takes_only_an_estimate_where_it_was():
    # Deviation 133: the next run's track must put the frame within track_gate of where
    # the dropped track was; not 8 m off (another object), and not where the dropped
    # track gives no position at all; nor away from what the live output reported there.
    det = _detector_with([])
    ts = np.arange(1.0, 4.9, 0.1)
    piece = _piece(ts, _line(ts))
    at = _line(np.array([3.0]))[0]
    assert det._agrees(Estimate(3.0, at + [0.0, 1.5, 0.0], 0.8, 5), piece)
    assert not det._agrees(Estimate(3.0, at + [0.0, 8.0, 0.0], 0.8, 5), piece)
    assert not det._agrees(Estimate(9.0, _line(np.array([9.0]))[0], 0.8, 5), piece)
    assert not det._agrees(None, piece)
    # Where the live output reported a position at that stamp (within half a frame
    # period), the estimate must lie near it too: not the dropped track's other object.
    det._live_reports.append((3.02, at + [0.0, 6.0, 0.0]))
    assert not det._agrees(Estimate(3.0, at, 0.8, 5), piece)
    assert det._agrees(Estimate(3.1, _line(np.array([3.1]))[0], 0.8, 5), piece)  # 0.08 s off
    det._live_reports.append((3.18, _line(np.array([3.2]))[0]))
    assert det._agrees(Estimate(3.2, _line(np.array([3.2]))[0], 0.8, 5), piece)


def test_a_dropped_track_never_reported_live_leaves_nothing_to_wait_for():
    # The live output never reported it: no frame can have been due on it.
    det = _detector_with([])
    det._now = 4.8 + 1.5
    det._archive_piece(_old_track(np.arange(1.0, 4.9, 0.1)), 0.8, det._now)
    assert not det._archive and not det._unkept
    # Reported live, but 8 m off its track (another object): nothing either.
    det._live_reports.extend(
        (t, _line(np.array([t]))[0] + [0.0, 8.0, 0.0]) for t in np.arange(3.5, 4.55, 0.1)
    )
    det._archive_piece(_old_track(np.arange(1.0, 4.9, 0.1)), 0.8, det._now)
    assert not det._unkept


def test_after_a_reset_the_stream_is_backfilled_as_a_new_one(scene):
    # A looped recording: the node resets the detector when stamps jump back. The first
    # pass's drone vanishes at 5 s, so its later frames fall due with nothing reported
    # live; that must not make the second pass's frames count as waiting ones.
    frames, _, _ = scene(duration=10.0, wall_points=200, drone_points=3)
    gone = _drone_gone_after(frames, 1005.0)
    values = {"report_lag": LAG, "report_backfill": 5.0}
    _, fresh, fresh_at = _push_all(frames, StreamingDetector(detector_params(values)))
    det = StreamingDetector(detector_params(values))
    _push_all(gone, det)
    assert det._unreported_until > 1006.0  # the frames after the drone vanished waited
    det.reset()
    assert det._unreported_until == -np.inf
    det.delayed()
    _, again, again_at = _push_all(frames, det)
    # The same estimates, released at the same frames.
    got = [(e.stamp, e.position.tolist(), at) for e, at in zip(again, again_at, strict=True)]
    want = [(e.stamp, e.position.tolist(), at) for e, at in zip(fresh, fresh_at, strict=True)]
    assert got == want


def test_the_late_output_follows_a_track_forward_into_its_sparse_returns(scene, drone_path_fn):
    # After 6 s the drone gives one return every 1.2 s (the live tracker waits at most
    # max_gap, 1 s, for the next; the growth bridges extend_max_gap, 1.5 s): the live
    # output stops soon after 6 s, the late output reports the frames near those returns
    # too, from the track grown forward (deviation 99), and only with report_extend_tail.
    frames, _, _ = scene(duration=10.0, wall_points=200, drone_points=3)
    sparse = {1007.2, 1008.4, 1009.6}
    cut = []
    for f in frames:
        if f.stamp <= 1006.0:
            cut.append(f)
        elif f.sensor == MID360 and round(f.stamp, 1) in sparse:
            cut.append(Frame(f.stamp, f.sensor, f.xyz[:-2]))  # one drone return left
        else:
            cut.append(Frame(f.stamp, f.sensor, f.xyz[:-3]))
    values = {"report_lag": LAG, "report_backfill": 0.0}
    live = run_streaming(cut, detector_params(values | {"report_lag": 0.0}))
    assert max(e.stamp for e in live) < 1007.0
    late = run_streaming(cut, detector_params(values))
    off = run_streaming(cut, detector_params(values | {"report_extend_tail": False}))
    assert max(e.stamp for e in off) < 1007.0
    # Between and around the returns 1.2 s apart: frames within max_extrapolation (0.5 s)
    # of one, or between two less than max_gap apart once a grown sample joins them.
    after = [e for e in late if e.stamp > 1006.6]
    stamps = np.array([e.stamp for e in after])
    assert len(after) >= 30 and stamps.max() >= 1008.8
    pos = np.array([e.position for e in after])
    assert np.linalg.norm(pos - drone_path_fn(stamps - 1000.0), axis=1).max() < 1.0


def _straight_pass(
    frames: list[Frame], returns: Callable[[float, str], int], height: float = 30.0
) -> tuple[list[Frame], Callable[[np.ndarray], np.ndarray]]:
    """The scene's frames (built with ``drone=False``) with a drone passing in a straight
    line at 10 m/s, ``height`` m up; ``returns(t, sensor)`` gives its number of returns in
    the frame ``t`` s into the scene. Returns (frames, path function of t)."""

    def path(t):
        t = np.asarray(t, dtype=float)
        return np.stack([-50.0 + 10.0 * t, np.full_like(t, 5.0), np.full_like(t, height)], -1)

    rng = np.random.default_rng(1)
    out = []
    for f in frames:
        t = f.stamp - 1000.0
        pts = path(t) + rng.normal(0, 0.1, (returns(round(t, 1), f.sensor), 3))
        out.append(Frame(f.stamp, f.sensor, np.vstack([f.xyz, pts]).astype(np.float32)))
    return out, path


def _pass_with_a_sparse_gap(scene) -> tuple[list[Frame], Callable[[np.ndarray], np.ndarray]]:
    """The straight pass, three returns a frame, but from 5.0 to 6.6 s only one Mid360
    return at 5.5 s and one at 6.1 s: (frames, path function of t)."""
    frames, _, _ = scene(duration=10.0, wall_points=200, drone=False)

    def returns(t, sensor):
        if 5.0 < t < 6.6:
            return int(sensor == MID360 and t in (5.5, 6.1))
        return 3

    return _straight_pass(frames, returns)


def test_the_late_output_fills_a_long_gap_of_its_track_with_returns_on_its_path(scene):
    # The clustering leaves the two returns in the gap as noise and links the two
    # sides, whose 1.6 s gap (longer than max_gap) the late output's estimate would not
    # cross; filled with them (report_fill, as offline fills a track) it does, and the
    # live output is unchanged.
    frames, path = _pass_with_a_sparse_gap(scene)
    runs, _ = _runs_with_and_without(
        frames, {"report_lag": LAG, "report_backfill": 0.0}, "report_fill"
    )
    _assert_only_the_switched_run_fills_the_gap(runs, path)


def test_the_late_output_fills_a_gap_with_its_returns_clustered_with_another_object(scene):
    # The same pass and gap, but beside each of the two returns in the gap another
    # object's 20 returns 3.4 m off the path: the clustering joins them into a cluster
    # too large for the noise pool (hover 5904 of the fifty-eighth set: a bird crossing
    # a sparse hover). With report_fill_clustered the gap is filled from that cluster's
    # returns within track_gate (2 m) of the chord, the other object's are not taken
    # (deviation 129); without, the late output leaves the gap empty.
    frames, path = _pass_with_a_sparse_gap(scene)
    rng = np.random.default_rng(2)
    crowded = []
    for f in frames:
        t = round(f.stamp - 1000.0, 1)
        if f.sensor == MID360 and t in (5.5, 6.1):
            other = path(t) + (0.0, 3.0, 1.5) + rng.normal(0, 0.2, (20, 3))
            f = Frame(f.stamp, f.sensor, np.vstack([f.xyz, other]).astype(np.float32))
        crowded.append(f)
    values = {"report_lag": LAG, "report_backfill": 0.0}
    runs, _ = _runs_with_and_without(crowded, values, "report_fill_clustered")
    _assert_only_the_switched_run_fills_the_gap(runs, path)
    # Both lidars' frames of the gap from the pass's own two returns: none near the
    # other object.
    gap = [e for e in runs[True][1] if 1005.2 <= e.stamp <= 1006.4]
    stamps = np.array([e.stamp for e in gap])
    err = np.linalg.norm(np.array([e.position for e in gap]) - path(stamps - 1000), axis=1)
    assert err.max() < 0.5


def test_the_late_output_follows_a_leaving_pass_to_a_lone_far_return(scene):
    # The pass leaves the lidars: three returns a frame up to 7.5 s (39 m out, receding at
    # 6.3 m/s), then one Mid360 return at 9.9 s, 58 m out on its line, 2.4 s later
    # (beyond extend_max_gap, within extend_far_gap). With report_extend_far the late
    # output's tail takes it as offline's growth does, and the estimates beside it take
    # the velocity of the chord across the gap (deviation 122); without, the late output
    # stops with the cluster.
    frames, _, _ = scene(duration=12.0, wall_points=200, drone=False)

    def returns(t, sensor):
        if t > 7.5:
            return int(sensor == MID360 and t == 9.9)
        return 3

    frames, path = _straight_pass(frames, returns)
    runs, _ = _runs_with_and_without(
        frames, {"report_lag": LAG, "report_backfill": 0.0}, "report_extend_far"
    )
    assert runs[False][0] == runs[True][0]  # the live output is the same
    beside = {on: [e for e in late if e.stamp >= 1009.4] for on, (_, late) in runs.items()}
    assert not beside[False]
    assert len(beside[True]) >= 8
    stamps = np.array([e.stamp for e in beside[True]])
    pos = np.array([e.position for e in beside[True]])
    assert np.linalg.norm(pos - path(stamps - 1000.0), axis=1).max() < 1.0


def _runs_with_and_without(
    frames: list[Frame], values: dict, switch: str
) -> tuple[dict[bool, tuple[list, list]], dict[bool, StreamingDetector]]:
    """Stream ``frames`` with the bool parameter ``switch`` off and on: ({on: (live
    (stamp, position) pairs, late estimates)}, {on: the detector after the stream})."""
    runs, dets = {}, {}
    for on in (False, True):
        det = StreamingDetector(detector_params(values | {switch: on}))
        live, delayed, _ = _push_all(frames, det)
        runs[on] = ([(e.stamp, e.position.tolist()) for e in live], delayed + det.flush())
        dets[on] = det
    return runs, dets


def _assert_only_the_switched_run_fills_the_gap(runs: dict, path: Callable) -> None:
    """The live outputs are the same; only the run with the switch on reports the frames
    of 5.6-6.0 s late, and every late estimate lies within 0.5 m of ``path``."""
    assert runs[False][0] == runs[True][0]
    inside = {
        on: [e for e in late if 1005.6 <= e.stamp <= 1006.0] for on, (_, late) in runs.items()
    }
    assert inside[False] == []
    assert len(inside[True]) >= 8  # both lidars' frames
    late = runs[True][1]
    stamps = np.array([e.stamp for e in late])
    err = np.linalg.norm(np.array([e.position for e in late]) - path(stamps - 1000), axis=1)
    assert err.max() < 0.5


def test_the_late_output_fills_a_gap_with_returns_the_denoise_dropped(scene):
    # As above, 60 m up, but the two returns inside the gap come from the Avia, alone in
    # their neighbourhood over the past denoise_window: the denoise drops them, so they
    # reach neither the clustering nor the fill, unless the late output keeps them for
    # its growth and fill (report_denoised, as offline's growth takes them). The live
    # output is unchanged (track_denoised off).
    frames, _, _ = scene(duration=10.0, wall_points=200, drone=False)
    frames, path = _straight_pass(frames, _avia_returns_in_gap, height=60.0)
    values = {"report_lag": LAG, "report_backfill": 0.0, "track_denoised": False}
    runs, dets = _runs_with_and_without(frames, values, "report_denoised")
    assert dets[False]._dropped_points == 0 and dets[True]._dropped_points > 0
    _assert_only_the_switched_run_fills_the_gap(runs, path)


def _avia_returns_in_gap(t: float, sensor: str) -> int:
    """Three returns a frame, but from 5.0 to 6.6 s one Avia return at 5.5 and 6.1 s."""
    if 5.0 < t < 6.6:
        return int(sensor == AVIA and t in (5.5, 6.1))
    return 3


def test_the_live_track_takes_far_returns_the_denoise_dropped(scene):
    # The same pass: with track_denoised the live track takes the two dropped Avia
    # returns where it is heading and is reported through the gap; without, the live
    # output stops max_extrapolation (0.5 s) after 5.0 s. Nearer than
    # denoised_min_range (a pass 30 m up, 30-31 m out then) they are not taken.
    frames, _, _ = scene(duration=10.0, wall_points=200, drone=False)
    inside = {}
    for height, taken in ((60.0, False), (60.0, True), (30.0, True)):
        moved, path = _straight_pass(frames, _avia_returns_in_gap, height=height)
        values = {"track_denoised": taken, "denoised_min_range": 40.0}
        live = run_streaming(moved, detector_params(values))
        inside[height, taken] = [e for e in live if 1005.6 <= e.stamp <= 1006.5]
        if inside[height, taken]:
            e = inside[height, taken]
            err = np.linalg.norm(
                np.array([x.position for x in e]) - path(np.array([x.stamp for x in e]) - 1000),
                axis=1,
            )
            assert err.max() < 1.0
    assert inside[60.0, False] == [] and inside[30.0, True] == []
    assert len(inside[60.0, True]) >= 12


def test_the_denoise_dropped_points_are_kept_only_for_the_late_growth(scene):
    # Kept only with report_lag and a growth or fill to read them, for local_history.
    frames, _, _ = scene(duration=4.0)
    for values, kept in (
        ({"report_lag": 0.0}, False),
        ({"report_lag": LAG}, True),
        ({"report_lag": LAG, "report_denoised": False}, False),
        (
            {
                "report_lag": LAG,
                "report_extend_head": False,
                "report_extend_tail": False,
                "report_fill": False,
            },
            False,
        ),
    ):
        det = StreamingDetector(detector_params({"report_denoised": True} | values))
        for f in frames:
            det.push(f)
        assert (det._dropped_points > 0) == kept, values
        if kept:
            oldest = det._dropped[0].stamp
            assert oldest >= frames[-1].stamp - det.params.local_history
            assert det.stats()["local_bytes"] > 0


def test_a_frame_between_two_live_runs_on_one_track_is_reported_late(scene):
    # The pass's returns stop at 6.0 s and come back for 0.1 s at 7.7 s: the live output
    # reports it to 6.5 s (max_extrapolation), lets go, and takes it up again at 8.0 s for
    # 0.2 s. With report_lag_min_run 1 s that short run alone would keep the frames
    # before it out of the late output; the run before them lasted, both runs are on one
    # track 1.5 s apart (within link_max_gap), so they are reported (report_bridge)
    # where the track's samples support an estimate: near its returns at 7.7 s.
    frames, _, _ = scene(duration=10.0, wall_points=200, drone=False)
    frames, path = _straight_pass(frames, lambda t, _: 3 if t <= 6.0 or 7.7 <= t <= 7.8 else 0)
    values = {"report_lag": LAG, "report_backfill": 0.0, "report_lag_min_run": 1.0}
    live = run_streaming(frames, detector_params(values | {"report_lag": 0.0}))
    gap = [e for e in live if 1006.6 <= e.stamp < 1008.0]
    assert gap == [] and any(e.stamp >= 1008.0 for e in live)
    late = {
        bridge: [
            e
            for e in run_streaming(frames, detector_params(values | {"report_bridge": bridge}))
            if 1006.6 <= e.stamp < 1008.0
        ]
        for bridge in (False, True)
    }
    # Without it, only the frames that fell due while the short run could still go on.
    assert late[False] and max(e.stamp for e in late[False]) < 1007.4
    stamps = np.array([e.stamp for e in late[True]])
    assert len(stamps) >= 10 and stamps.min() <= 1007.3 and stamps.max() >= 1007.9
    err = np.linalg.norm(np.array([e.position for e in late[True]]) - path(stamps - 1000), axis=1)
    assert err.max() < 0.5


def test_the_late_tail_grows_from_the_tracks_own_end_not_the_clusters():
    # fast_pass 5200: a bird crossing the drone's path joined its cluster after the
    # drone's returns thinned out; grown from the cluster's end, the late tail followed
    # the bird for 1.7 s after the drone's track (deviation 117).
    from clusterfilter_ros.core.streaming import _grown, _grown_ends, _track_samples

    p = detector_params({"report_lag": 3.0})
    t_drone = np.arange(0.0, 2.01, 0.1)
    drone = np.stack([10.0 * t_drone, np.zeros_like(t_drone), np.full_like(t_drone, 20.0)], 1)
    t_bird = np.arange(2.1, 3.01, 0.1)
    bird = np.stack(
        [22.0 - 12.0 * (t_bird - 2.1), np.full_like(t_bird, 4.0), np.full_like(t_bird, 20.0)], 1
    )
    t_far = np.array([2.6, 3.1])  # the drone's lone far returns, on its line
    far = np.stack([10.0 * t_far, np.zeros(2), np.full(2, 20.0)], 1)
    t_on = np.arange(3.1, 4.01, 0.1)  # the bird flying on
    on = np.stack(
        [22.0 - 12.0 * (t_on - 2.1), np.full_like(t_on, 4.0), np.full_like(t_on, 20.0)], 1
    )
    xyz = np.vstack([drone, bird, far, on]).astype(np.float32)
    t = np.concatenate([t_drone, t_bird, t_far, t_on])
    n_cluster = t_drone.size + t_bird.size
    mask = np.arange(t.size) < n_cluster
    pool = ~mask
    samples = _track_samples(np.arange(t.size) < t_drone.size, xyz, t, p)
    head, tail = _grown_ends(mask, pool, xyz, t, samples, p)
    assert head == ()
    np.testing.assert_allclose([s.t for s in tail], t_far)
    np.testing.assert_allclose([s.position[1] for s in tail], 0.0)
    # From the cluster's end, the tail is the bird's.
    from_cluster = _grown(mask, pool, xyz, t, samples[-1].t, p, forward=True)
    assert from_cluster and all(s.position[1] == pytest.approx(4.0) for s in from_cluster)


@pytest.mark.parametrize("forward", [True, False], ids=["tail", "head"])
def test_the_late_growth_finds_a_hover_after_a_braking_end_with_report_extend_brake(forward):
    # Take-off 5801 of the fifty-seventh set: the drone braked from a climb into a stop
    # 34 m out and was seen there only in lone returns; offline's growth (deviation 124,
    # extend_brake_hover) takes the stop's returns, the late output's did not. Here a
    # track at 7.6 m/s (2 returns a frame) whose last return is at 9.95 s, and a hover's
    # returns from 1.75 s later, 3.67 m on, 5.1 m short of where the track was heading
    # (beyond the linking reach and beyond extend_max_gap): taken with the switch, not
    # without. Mirrored in time, the head grows back to the hover the drone left.
    rng = np.random.default_rng(3)
    track_t = np.repeat(np.arange(8.0, 9.96, 0.15), 2)
    track = np.column_stack(
        [26.0 + 7.6 * (track_t - 9.95), np.zeros_like(track_t), np.full_like(track_t, 14.0)]
    )
    hover_t = np.linspace(11.7, 15.1, 10)
    hover = np.column_stack([np.full(10, 29.67), np.zeros(10), np.full(10, 14.0)])
    hover += rng.normal(0.0, 0.05, hover.shape)
    xyz = np.concatenate([track, hover]).astype(np.float32)
    t = np.concatenate([track_t, hover_t])
    if not forward:
        t = 20.0 - t
    mask = np.arange(t.size) < track_t.size
    edge = float(t[mask].max() if forward else t[mask].min())

    def grown(on: bool) -> tuple:
        params = detector_params({"report_extend_brake": on})
        return streaming._grown(mask, ~mask, xyz, t, edge, params, forward=forward)

    assert grown(False) == ()
    samples = grown(True)
    assert len(samples) == 10
    assert all(abs(s.position[0] - 29.67) < 0.3 for s in samples)


def _take_off(duration: float = 12.0, seed: int = 3) -> list[Frame]:
    """Mid360 and Avia frames at 10 Hz: ground returns 1.3 m below the Mid360 (at or
    below ``mid360_min_z``, every frame; none in the drone's 1.5 m static voxels), and
    a drone seen from 3.6 s, on the ground 6 m out until 4 s, that then climbs at 2 m/s,
    crossing the Mid360's height at 4.5 s; three returns a Mid360 frame."""
    rng = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(np.arange(-10.0, 4.4, 0.7), np.arange(-10.0, 10.0, 0.7)), -1)
    ground = np.column_stack([grid.reshape(-1, 2), np.full(grid.size // 2, -1.3)])
    frames = []
    for i in range(int(duration * 10)):
        stamp = 1000.0 + i * 0.1
        z = -1.0 + 2.0 * max(stamp - 1004.0, 0.0)
        drone = np.array([6.0, -3.0, z]) + rng.normal(0, 0.08, (3, 3))
        mid = ground + rng.normal(0, 0.02, ground.shape)
        if stamp >= 1003.55:
            mid = np.vstack([mid, drone])
        frames.append(Frame(stamp, MID360, mid.astype(np.float32)))
        sky = rng.normal(size=(20, 3))
        sky[:, 2] = np.abs(sky[:, 2]) + 1.0
        sky *= rng.uniform(20, 400, (20, 1)) / np.linalg.norm(sky, axis=1, keepdims=True)
        frames.append(Frame(stamp + 0.004, AVIA, sky.astype(np.float32)))
    return frames


def test_the_late_output_grows_into_a_lift_off_below_the_mid360s_floor():
    frames = _take_off()
    first, live_runs = {}, {}
    for below in (False, True):
        det = StreamingDetector(detector_params({"report_lag": LAG, "report_below_floor": below}))
        live, delayed, _ = _push_all(frames, det)
        late = delayed + det.flush()
        assert live and late
        first[below] = min(e.stamp for e in late)
        live_runs[below] = [(e.stamp, e.position.tolist()) for e in live]
    # The live estimates are the same either way.
    assert live_runs[True] == live_runs[False]
    # The kept returns count in the state's size, and stay bounded by the history.
    det = StreamingDetector(detector_params({"report_lag": LAG}))
    off = StreamingDetector(detector_params({"report_lag": LAG, "report_below_floor": False}))
    for f in frames:
        det.push(f)
        off.push(f)
    extra = det.stats()["local_bytes"] - off.stats()["local_bytes"]
    ground = sum(int((f.xyz[:, 2] <= 0.0).sum()) for f in frames if f.sensor == MID360) / 120
    assert 0 < extra <= 1.01 * ground * 10 * 10 * 20  # 10 s of 10 Hz frames, 20 B a return
    # Without the floor's returns the late output starts max_extrapolation (0.5 s)
    # before the drone crossed the Mid360's height; with them, from its first returns
    # on the ground, as offline's extend_below_floor does.
    assert first[False] >= 1003.95
    assert first[True] <= 1003.65


def test_transient_below_floor_keeps_the_returns_near_the_track_ends():
    # The selection the late output shares with offline's extend_below_floor; the ends
    # are the track's first and newest sample positions.
    from clusterfilter_ros.core.offline import transient_below_floor

    params = detector_params()
    ends = np.array([[6.0, -3.0, 0.5], [6.0, -3.0, 8.5]])
    # Ground every 0.1 s in the voxels beside the lift-off's (static_voxel 1.5 m).
    t_ground = np.repeat(np.arange(0.0, 9.0, 0.1), 2)
    ground = np.column_stack(
        [np.tile([4.0, 8.0], t_ground.size // 2), np.full(t_ground.size, -3.0), -1.3 + 0 * t_ground]
    )
    lift = np.array([[6.0, -3.0, -0.4], [6.0, -3.0, -0.2]])
    far = np.array([[30.0, -3.0, -0.3]])
    xyz = np.vstack([ground, lift, far]).astype(np.float32)
    t = np.concatenate([t_ground, [4.7, 4.8], [4.8]])
    fxyz, ft = transient_below_floor(xyz, t, ends, params)
    np.testing.assert_array_equal(ft, [4.7, 4.8])
    np.testing.assert_allclose(fxyz, lift, atol=1e-6)
