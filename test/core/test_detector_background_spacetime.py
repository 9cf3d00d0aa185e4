"""Persistence map (static suppression), space-time clustering and motion coherence."""

from __future__ import annotations

import numpy as np
import pytest

from clusterfilter_ros.core import voxel
from clusterfilter_ros.core.background import BackgroundGrid, persistent_mask, static_offline
from clusterfilter_ros.core.clustering import spacetime_cluster_points, voxel_clusters
from clusterfilter_ros.core.params import detector_params
from clusterfilter_ros.core.scoring import motion_coherence


def wall_and_track(seconds: int = 10, seed: int = 0):
    rng = np.random.default_rng(seed)
    xyz, t, moving = [], [], []
    for i in range(seconds * 10):
        stamp = i * 0.1
        wall = np.column_stack([np.full(50, 30.0), rng.uniform(-3, 3, 50), rng.uniform(5, 8, 50)])
        drone = np.array([[-20 + 0.5 * i, 0.0, 15.0]])  # 5 m/s
        xyz += [wall, drone]
        t += [np.full(50, stamp), [stamp]]
        moving += [np.zeros(50, bool), [True]]
    return np.vstack(xyz), np.concatenate(t), np.concatenate(moving)


def test_offline_persistence_masks_the_wall_not_the_drone():
    xyz, t, moving = wall_and_track()
    static, _ = static_offline(xyz, t, detector_params())
    assert static[~moving].mean() > 0.99
    assert not static[moving].any()
    # Persistence alone gives the same answer here (no drifting or compact group).
    assert (persistent_mask(xyz, t, detector_params()) == static).all()
    assert persistent_mask(np.empty((0, 3)), np.empty(0), detector_params()).size == 0


def test_background_grid_learns_and_forgets():
    params = detector_params(
        {"global_window": 5.0, "static_bin": 1.0, "static_min_bins": 3, "hover_detection": False}
    )
    grid = BackgroundGrid(params)
    wall_key = voxel.voxel_keys(np.array([[30.0, 0.0, 5.0]]), params.static_voxel)
    for second in range(4):
        grid.update(wall_key, np.array([second + 0.5]), now=second + 0.9)
    assert voxel.lookup(grid.static_keys(), wall_key)[0] >= 0
    once = voxel.voxel_keys(np.array([[0.0, 0.0, 20.0]]), params.static_voxel)
    grid.update(once, np.array([4.5]), now=4.9)
    assert voxel.lookup(grid.static_keys(), once)[0] < 0
    grid.update(np.empty(0, np.int64), np.empty(0), now=20.0)  # nothing for 15 s
    assert grid.keys.size == 0


def test_spacetime_clusters_split_in_time_and_follow_motion():
    rng = np.random.default_rng(1)
    # The same place visited twice, 5 s apart: two clusters (space-only would merge them).
    a = rng.normal([0, 0, 20], 0.2, (20, 3))
    b = rng.normal([0, 0, 20], 0.2, (20, 3))
    t = np.concatenate([np.linspace(0, 0.5, 20), np.linspace(5, 5.5, 20)])
    labels = spacetime_cluster_points(np.vstack([a, b]), t, 2.0, 0.5, 3)
    assert labels.min() >= 0 and len(set(labels[:20])) == 1 and len(set(labels[20:])) == 1
    assert labels[0] != labels[-1]
    # A track at 4 m/s sampled every 0.2 s stays one cluster.
    tt = np.arange(0, 6, 0.2)
    track = np.column_stack([4 * tt, np.zeros_like(tt), np.full_like(tt, 20.0)])
    labels = spacetime_cluster_points(track, tt, 2.0, 0.5, 3)
    assert (labels >= 0).all() and len(set(labels.tolist())) == 1


def test_motion_coherence_moving_vs_static():
    rng = np.random.default_rng(2)
    t = np.repeat(np.arange(0, 5, 0.1), 3)
    moving = np.column_stack([3 * t, np.zeros_like(t), np.full_like(t, 20)]) + rng.normal(
        0, 0.1, (t.size, 3)
    )
    static = rng.uniform([0, 0, 10], [4, 4, 14], (t.size, 3))
    lab = np.concatenate([np.zeros(t.size, int), np.ones(t.size, int)])
    coh = motion_coherence(lab, np.vstack([moving, static]), np.concatenate([t, t]), 2, 1.0)
    assert coh[0] > 0.7 and coh[1] < 0.3  # straight 3 m/s track, 1 s windows: ~0.8
    # A cluster seen in one window only carries no motion evidence.
    one = motion_coherence(np.zeros(5, int), rng.normal(size=(5, 3)), np.zeros(5), 1, 1.0)
    assert one[0] == 0.0


def test_motion_coherence_per_window_is_not_swamped_by_a_burst():
    # Deviation 144 (take-off 7101 of the seventieth set): a pass over the rig at 7 m/s
    # leaves 320 of its returns in the one second it is closest, a dozen in each other.
    rng = np.random.default_rng(3)
    t = np.concatenate([np.linspace(0, 2, 24, endpoint=False), np.linspace(2, 3, 320)])
    t = np.concatenate([t, np.linspace(3, 4, 12)])
    moving = np.column_stack([7 * t, np.zeros_like(t), np.full_like(t, 8.0)])
    moving += rng.normal(0, 0.1, moving.shape)
    lab = np.zeros(t.size, int)
    by_returns = motion_coherence(lab, moving, t, 1, 1.0)[0]
    by_window = motion_coherence(lab, moving, t, 1, 1.0, per_window=True)[0]
    assert by_returns < 0.5 < 0.7 < by_window
    # Something that stays put looks static either way, burst or not.
    static = rng.uniform([0, 0, 10], [4, 4, 14], (t.size, 3))
    assert motion_coherence(lab, static, t, 1, 1.0, per_window=True)[0] < 0.3


def test_compact_static_group_is_kept_for_hover_detection():
    from clusterfilter_ros.core.background import compact_static_keys

    params = detector_params()
    wall = voxel.voxel_keys(
        np.array([[30.0, y, z] for y in np.arange(-10, 10, 1.5) for z in np.arange(2, 12, 1.5)]),
        params.static_voxel,
    )
    drone = voxel.voxel_keys(np.array([[0.0, 0.0, 20.0], [0.8, 0.0, 20.0]]), params.static_voxel)
    keys = np.unique(np.concatenate([wall, drone]))
    kept = compact_static_keys(keys, params)
    assert set(kept.tolist()) == set(np.unique(drone).tolist())


def test_drone_hovering_near_a_wall_is_not_merged_with_it():
    # Voxel-centre positions (static_voxel 1.5 m): a wall in the plane y = 18.75 up to
    # z = 6.75 and a drone 3 m out from it and 3 m above its top, two voxels away on
    # each axis (not touching). Grouping on a 3 m grid merged the two (hover seed 3).
    from clusterfilter_ros.core.background import compact_static_keys

    params = detector_params()
    sv = params.static_voxel
    wall = voxel.voxel_keys(
        np.array(
            [
                [x, 18.75, z]
                for x in np.arange(-30.75, -14.0, sv)
                for z in (0.75, 2.25, 3.75, 5.25, 6.75)
            ]
        ),
        sv,
    )
    drone = voxel.voxel_keys(np.array([[-20.25, 15.75, 9.75], [-21.75, 15.75, 9.75]]), sv)
    keys = np.unique(np.concatenate([wall, drone]))
    kept = compact_static_keys(keys, params)
    assert set(kept.tolist()) == set(np.unique(drone).tolist())
    # Touching the wall (one voxel out from its face), the drone is part of it.
    touching = voxel.voxel_keys(np.array([[-20.25, 17.25, 6.75]]), sv)
    keys = np.unique(np.concatenate([wall, touching]))
    assert compact_static_keys(keys, params).size == 0


def test_hovering_object_detected_offline_only_with_hover_detection():
    from clusterfilter_ros.core.frame import MID360, Frame
    from clusterfilter_ros.core.offline import detect_offline

    rng = np.random.default_rng(4)
    frames = []
    for i in range(150):
        wall = np.column_stack([np.full(60, 30.0), rng.uniform(-5, 5, 60), rng.uniform(3, 9, 60)])
        parts = [wall]
        if i % 2 == 0:  # one return every other frame, drifting 0.3 m around a point
            parts.append(np.array([[5.0, 5.0, 18.0]]) + rng.normal(0, 0.15, (1, 3)))
        frames.append(Frame(i * 0.1, MID360, np.vstack(parts).astype(np.float32)))
    found = detect_offline(frames)
    assert len(found.estimates) > 100
    assert np.allclose(np.median(found.estimates.xyz, axis=0), [5, 5, 18], atol=0.3)
    missed = detect_offline(frames, detector_params({"hover_detection": False}))
    assert len(missed.estimates) == 0


def _wall_and_slow_drone(seconds: int = 20, seed: int = 1):
    """A wall hit every frame and a drone drifting at 0.3 m/s, 2 returns per frame."""
    rng = np.random.default_rng(seed)
    xyz, t, drone = [], [], []
    for i in range(seconds * 10):
        stamp = i * 0.1
        wall = np.column_stack([np.full(40, 30.0), rng.uniform(-3, 3, 40), rng.uniform(5, 8, 40)])
        body = np.array([[-3.0 + 0.03 * i, 4.0, 25.0]]) + rng.normal(0, 0.1, (2, 3))
        xyz += [wall, body]
        t += [np.full(40, stamp), np.full(2, stamp)]
        drone += [np.zeros(40, bool), np.ones(2, bool)]
    return np.vstack(xyz), np.concatenate(t), np.concatenate(drone)


def test_a_slowly_drifting_drone_is_not_static_structure():
    xyz, t, drone = _wall_and_slow_drone()
    params = detector_params()
    # Each 1.5 m voxel of its 6 m path holds the drone for ~5 s: persistent, and too
    # long a group for the compact-group exception.
    static, _ = static_offline(xyz, t, params.copy(static_drift_span=0.0))
    assert static[drone].mean() > 0.8
    static, keys = static_offline(xyz, t, params)
    assert not static[drone].any()
    assert static[~drone].mean() > 0.99
    assert keys.size > 0


def _grid_static(xyz, t, params, until: float) -> tuple[np.ndarray, np.ndarray]:
    """The keys of each point and the grid's static keys, the points pushed 0.1 s at a
    time up to stream time ``until``."""
    grid = BackgroundGrid(params)
    keys = voxel.voxel_keys(xyz, params.static_voxel)
    for stamp in np.arange(0.0, until, 0.1):
        now = (t >= stamp - 1e-9) & (t < stamp + 0.1 - 1e-9)
        grid.update(keys[now], t[now], now=stamp)
    return keys, grid.static_keys()


def test_streaming_map_releases_a_slowly_drifting_drone():
    xyz, t, drone = _wall_and_slow_drone()
    params = detector_params()
    # After 20 s: the wall was hit from the map's first bin, so its span is unknown
    # and long; each voxel of the drone's path was hit for about 5 s.
    keys, static = _grid_static(xyz, t, params, 20.0)
    assert voxel.lookup(static, keys[~drone]).min() >= 0
    assert (voxel.lookup(static, keys[drone & (t > 15)]) < 0).all()
    _, without = _grid_static(xyz, t, params.copy(stream_static_drift=False), 20.0)
    assert (voxel.lookup(without, keys[drone & (t > 15)]) >= 0).mean() > 0.8


def test_streaming_map_keeps_structure_at_start_up():
    xyz, t, drone = _wall_and_slow_drone()
    params = detector_params()
    # Six seconds in, every voxel was first hit at most 6 s ago, the wall's in the
    # map's first bin: the wall stays static (its span is not known to be short).
    keys, static = _grid_static(xyz, t, params, 6.0)
    wall = ~drone & (t < 6.0)
    assert (voxel.lookup(static, keys[wall]) >= 0).all()


def test_streaming_map_keeps_structure_that_came_into_view():
    xyz, t, drone = _wall_and_slow_drone()
    params = detector_params()
    # The wall is first hit 3 s after the map began: at 10 s each of its voxels was hit
    # over 7 s, but the map had watched them for only 3 s before, too little to tell a
    # drone that arrived there from structure that was there all along.
    later = ~drone & (t >= 3.0) | drone
    keys, static = _grid_static(xyz[later], t[later], params, 10.0)
    wall = ~drone[later]
    assert (voxel.lookup(static, keys[wall]) >= 0).all()


def test_streaming_map_keeps_structure_a_paused_lidar_sees_again():
    xyz, t, drone = _wall_and_slow_drone(seconds=32)
    params = detector_params()
    # The lidar that sees the wall paused from 2 s to 25 s: at 31 s each wall voxel was
    # hit over the last 6 s only, and the map, which heard nothing from that lidar for
    # 23 s, took it for empty before.
    seen = ~drone & ((t < 2.0) | (t >= 25.0))
    grid = BackgroundGrid(params)
    keys = voxel.voxel_keys(xyz[seen], params.static_voxel)
    for stamp in np.arange(0.0, 31.0, 0.1):
        now = (t[seen] >= stamp - 1e-9) & (t[seen] < stamp + 0.1 - 1e-9)
        grid.update(keys[now], t[seen][now], now=stamp)
    wall = t[seen] >= 25.0
    released = voxel.lookup(grid.static_keys(), keys[wall]) < 0
    assert released.all()
    # Told that the lidar came back at 25 s, the map watched those voxels for 6 s only.
    assert (voxel.lookup(grid.static_keys(watched_since=25.0), keys[wall]) >= 0).all()


def test_streaming_detector_watches_afresh_after_a_lidar_pause():
    from clusterfilter_ros.core.frame import AVIA, MID360, Frame
    from clusterfilter_ros.core.streaming import StreamingDetector

    detector = StreamingDetector(detector_params())
    empty = np.empty((0, 3), np.float32)
    for stamp in np.arange(0.0, 10.0, 0.1):
        detector.push(Frame(float(stamp), AVIA, empty))
        if stamp < 4.0 or stamp >= 7.0:  # the Mid360 pauses 3 s
            detector.push(Frame(float(stamp) + 0.05, MID360, empty))
    assert detector._watched_since == pytest.approx(7.05)
    # Frames under ever new sensor names keep the state bounded.
    for i in range(100):
        detector.push(Frame(10.0 + 0.01 * i, f"lidar{i}", empty))
    assert len(detector._sensor_last) <= 8


def test_drifting_static_keys_needs_short_spans():
    from clusterfilter_ros.core.background import drifting_static_keys

    params = detector_params()
    keys = voxel.voxel_keys(np.array([[x, 0.0, 20.0] for x in (0.0, 1.5, 3.0, 4.5)]), 1.5)
    order = np.argsort(keys)
    keys = keys[order]
    first = np.array([0, 4, 8, 12])[order]
    # Hit 3-5 s each, one after the other: a path.
    kept = drifting_static_keys(keys, first, first + 4, params)
    assert set(kept.tolist()) == set(keys.tolist())
    # Hit over the whole 20 s recording each: structure.
    whole = np.zeros(4, np.int64)
    assert drifting_static_keys(keys, whole, whole + 19, params).size == 0
    # Fewer than three voxels: left to the compact-group exception.
    assert drifting_static_keys(keys[:2], first[:2], first[:2] + 4, params).size == 0


def test_a_drone_hovering_beside_structure_is_released_from_it():
    from clusterfilter_ros.core.background import drifting_static_keys

    params = detector_params()
    # A crown: eight voxels hit over the whole 20 s; a drone hovering beside it for 5 s
    # fills three voxels, the first of which touches the crown's corner diagonally.
    crown = [[x, y, 6.0] for x in (0.0, 1.5) for y in (0.0, 1.5, 3.0, 4.5)]
    drone = [[3.0, 6.0, 7.5], [4.5, 6.0, 7.5], [4.5, 7.5, 7.5]]
    keys = voxel.voxel_keys(np.array(crown + drone), 1.5)
    first = np.array([0] * 8 + [7, 7, 8])
    last = np.array([19] * 8 + [12, 12, 12])
    order = np.argsort(keys)
    keys, first, last = keys[order], first[order], last[order]
    kept = drifting_static_keys(keys, first, last, params)
    assert set(kept.tolist()) == set(voxel.voxel_keys(np.array(drone), 1.5).tolist())
    # Crown and drone are one group of touching voxels, whose median span is the crown's
    # (deviation 46 alone kept nothing).
    assert np.unique(voxel_clusters(keys, np.ones(keys.size), 0.0)).size == 1
    # Two short-span voxels beside the crown are too few to be a drone.
    two = ~np.isin(keys, voxel.voxel_keys(np.array(drone[2:]), 1.5))
    assert drifting_static_keys(keys[two], first[two], last[two], params).size == 0
