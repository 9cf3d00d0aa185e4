"""Simulated sequences against the real MMAUD statistics, truth, determinism, scenarios."""

from __future__ import annotations

import numpy as np
import pytest

from clusterfilter_ros.core.frame import AVIA, MID360
from clusterfilter_ros.errors import ParameterError
from clusterfilter_ros.sim.analysis import drone_hits_per_frame
from clusterfilter_ros.sim.raycast import CLASS_DRONE
from clusterfilter_ros.sim.scenarios import (
    PAD_ROWS,
    SCENARIOS,
    Simulation,
    simulate,
    stream_frames,
)


@pytest.fixture(scope="module")
def default_seq():
    return simulate("default", seed=0, duration=4.0)


def _by_sensor(seq, sensor):
    return [f for f in seq.sequence.frames if f.sensor == sensor]


def test_per_frame_point_counts_match_the_real_recordings(default_seq):
    mid = [len(f) for f in _by_sensor(default_seq, MID360)]
    avia_counts = [len(f) for f in _by_sensor(default_seq, AVIA)]
    assert len(mid) == len(avia_counts) == 40
    # Real Mid360 files: 19,968/20,064 rows of which ~3.9k-4.4k are points.
    assert 3700 <= np.median(mid) <= 4600
    assert max(mid) < 19968
    # Real Avia files: 24,000 rows of which 0-178 are points; mostly near empty.
    assert np.median(avia_counts) < 30
    assert max(avia_counts) < 400
    assert default_seq.pad_rows == {MID360: [19968, 20064], AVIA: 24000}
    assert default_seq.pad_rows == PAD_ROWS


def test_frames_time_ordered_with_offset_stamps_and_point_times(default_seq):
    frames = default_seq.sequence.frames
    stamps = np.array([f.stamp for f in frames])
    assert np.all(np.diff(stamps) > 0)
    mid = np.array([f.stamp for f in _by_sensor(default_seq, MID360)])
    av = np.array([f.stamp for f in _by_sensor(default_seq, AVIA)])
    np.testing.assert_allclose(np.diff(mid), 0.1, atol=0.005)
    offset = av - mid
    assert np.all((offset > 0.0005) & (offset < 0.01))  # a few ms apart, jittered
    assert np.std(np.diff(mid)) > 1e-5
    for f in frames:
        assert f.xyz.dtype == np.float32 and f.point_time is not None
        assert np.all((f.point_time >= 0) & (f.point_time < 0.1))
        assert np.all(np.diff(f.point_time) >= 0)
        assert not np.any(np.all(f.xyz == 0, axis=1))  # no padding rows


def test_scene_extent_like_mmaud(default_seq):
    xyz = np.concatenate([f.xyz for f in _by_sensor(default_seq, MID360)])
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    # Real: x, y about -70..90 m, z -2..40 m.
    assert -80 < lo[0] < -45 and -80 < lo[1] < -45
    assert 50 < hi[0] < 100 and 45 < hi[1] < 100
    assert -2.5 < lo[2] < -1.5 and 30 < hi[2] < 45


def test_ground_truth_is_a_prism_track_at_10_to_20_hz(default_seq):
    gt = default_seq.sequence.ground_truth
    dt = np.diff(gt.stamps)
    assert np.all((dt >= 0.05 - 1e-9) & (dt <= 0.1 + 1e-9))
    assert 10.0 <= 1.0 / dt.mean() <= 20.0
    assert dt.std() > 0.01  # irregular
    truth = default_seq.drone_truth
    body = np.stack([np.interp(gt.stamps, truth.stamps, truth.xyz[:, i]) for i in range(3)], 1)
    offset = gt.xyz - body
    np.testing.assert_allclose(np.linalg.norm(offset, axis=1), 0.25, atol=0.03)
    assert np.all(offset[:, 2] > 0.2)  # above the body, tilted only a little
    assert default_seq.prism_offset.tolist() == [0.0, 0.0, 0.25]
    np.testing.assert_allclose(np.diff(truth.stamps), 0.01, atol=1e-6)


def test_labels_mark_drone_points(default_seq):
    n_drone = 0
    for i, f in enumerate(default_seq.sequence.frames):
        mask = default_seq.labels[i]
        assert mask.dtype == bool and mask.shape == (len(f),)
        n_drone += int(mask.sum())
        if mask.any():
            t = f.stamp + f.point_time[mask]
            truth = default_seq.drone_truth
            body = np.stack([np.interp(t, truth.stamps, truth.xyz[:, k]) for k in range(3)], 1)
            assert np.linalg.norm(f.xyz[mask] - body, axis=1).max() < 1.0
    assert n_drone > 0


def test_deterministic_per_seed_and_streaming_agrees():
    a = simulate("birds", seed=3, duration=0.5)
    b = simulate("birds", seed=3, duration=0.5)
    c = simulate("birds", seed=4, duration=0.5)
    for fa, fb in zip(a.sequence.frames, b.sequence.frames, strict=True):
        assert fa.stamp == fb.stamp
        np.testing.assert_array_equal(fa.xyz, fb.xyz)
    np.testing.assert_array_equal(a.sequence.ground_truth.xyz, b.sequence.ground_truth.xyz)
    assert not np.array_equal(a.sequence.frames[0].xyz[:100], c.sequence.frames[0].xyz[:100])
    streamed = list(stream_frames("birds", seed=3, duration=0.5))
    assert len(streamed) == len(a.sequence.frames)
    for i, (frame, mask) in enumerate(streamed):
        np.testing.assert_array_equal(frame.xyz, a.sequence.frames[i].xyz)
        np.testing.assert_array_equal(mask, a.labels[i])


def test_no_drone_scenarios_have_no_drone_points():
    for name in ("no_drone", "no_drone_birds"):
        seq = simulate(name, seed=1, duration=1.0)
        assert not any(m.any() for m in seq.labels.values())
        assert len(seq.sequence.ground_truth) == 0 and len(seq.drone_truth) == 0
        assert seq.drone_model is None


def test_avia_only_drone_is_never_in_the_mid360():
    sim = Simulation("avia_only", seed=0, duration=5.0)
    hits = {MID360: 0, AVIA: 0}
    for sf in sim.iter_frames():
        hits[sf.frame.sensor] += int(sf.drone_mask.sum())
    assert hits[MID360] == 0
    assert hits[AVIA] > 10
    # Geometry: always above the Mid360's 52 deg and inside the Avia's cone.
    truth = sim.drone_truth(20).xyz
    el = np.degrees(np.arctan2(truth[:, 2], np.hypot(truth[:, 0], truth[:, 1])))
    assert el.min() > 55.0


def test_drone_hits_fall_with_range():
    # A 0.35 m drone (Phantom 4) at 50 m gives well under one Mid360 point per frame.
    far = drone_hits_per_frame("phantom4", 50.0, 15.0, frames=40)
    near = drone_hits_per_frame("phantom4", 10.0, 15.0, frames=40)
    assert far[MID360] < 0.5
    assert near[MID360] > 1.0 > far[MID360]
    assert near[AVIA] == 0.0  # 15 deg elevation is outside the Avia's upward cone
    big = drone_hits_per_frame("m300", 25.0, 15.0, frames=30)
    small = drone_hits_per_frame("avata", 25.0, 15.0, frames=30)
    assert big[MID360] > 2 * small[MID360]
    overhead = drone_hits_per_frame("m300", 100.0, 80.0, frames=30)
    assert overhead[AVIA] > 0.2 and overhead[MID360] == 0.0


def test_every_scenario_flies_within_realistic_limits():
    assert {"default", "takeoff_landing", "flyover", "fast_pass", "hover", "birds"} <= set(
        SCENARIOS
    )
    assert {"no_drone", "no_drone_birds", "avia_only", "long_mixed"} <= set(SCENARIOS)
    assert SCENARIOS["long_mixed"].duration >= 120
    for name, spec in SCENARIOS.items():
        sim = Simulation(name, seed=2)
        if spec.drone is None:
            assert sim.drone is None
            continue
        t = np.arange(0.0, sim.duration, 0.02)
        v = np.linalg.norm(sim.drone.velocity(t), axis=1)
        a = np.linalg.norm(sim.drone.acceleration(t), axis=1)
        p = sim.drone.position(t)
        assert v.max() <= 12.5, name
        assert a.max() <= 4.5, name
        assert p[:, 2].max() - (-1.75) <= 105.0, name
    fly = Simulation("flyover", seed=0).drone.position(np.arange(0, 40, 0.1))
    assert fly[:, 2].max() > 80.0
    fast = Simulation("fast_pass", seed=0).drone
    t = np.arange(0, 20, 0.05)
    r = np.linalg.norm(fast.position(t), axis=1)
    assert r.min() < 8.0 and r.max() > 80.0
    assert np.linalg.norm(fast.velocity(t), axis=1).max() > 11.0
    land = Simulation("takeoff_landing", seed=0)
    z = land.drone.position(np.array([0.0, land.duration - 0.1]))[:, 2]
    assert np.all(z < -1.75 + 0.3)  # on the pad at both ends
    lm = Simulation("long_mixed", seed=0)
    r = np.linalg.norm(lm.drone.position(np.arange(0, lm.duration, 0.5))[:, :2], axis=1)
    assert r.max() > 100.0  # leaves the sensors' range and comes back
    assert r[-1] < 10.0


def test_bad_arguments_raise_parameter_errors():
    with pytest.raises(ParameterError, match="unknown scenario 'nope'"):
        Simulation("nope")
    with pytest.raises(ParameterError, match="unknown drone"):
        Simulation("default", drone="f16")
    with pytest.raises(ParameterError, match="has no drone"):
        Simulation("no_drone", drone="mavic2")
    for bad in (0.0, -1.0, float("nan"), float("inf"), 1e7, "20"):
        with pytest.raises(ParameterError, match="duration"):
            Simulation("default", duration=bad)
    with pytest.raises(ParameterError, match="seed"):
        Simulation("default", seed=-1)


def test_drone_override_and_drone_mask_classes():
    seq = simulate("hover", seed=0, duration=0.3, drone="m300")
    assert seq.drone_model == "m300"
    for i in seq.labels:
        np.testing.assert_array_equal(seq.labels[i], seq.classes[i] == CLASS_DRONE)
