"""Track linking: fragments of one sparse moving object become one cluster."""

from __future__ import annotations

import numpy as np
import pytest

from clusterfilter_ros.core.clustering import relabel_compact
from clusterfilter_ros.core.linking import (
    chains_formed,
    extend_track,
    fill_track,
    link_fragments,
)
from clusterfilter_ros.core.offline import global_clusters
from clusterfilter_ros.core.params import detector_params
from clusterfilter_ros.core.scoring import group_median, score_clusters


def _fragments(rng, starts, length=0.4, speed=(8.0, 0.0, 0.0), origin=(0.0, 0.0, 20.0)):
    """A constant-velocity object seen in bursts: one cluster label per burst."""
    xyz, t, lab = [], [], []
    for i, s in enumerate(starts):
        for f in np.arange(s, s + length, 0.1):
            p = np.asarray(origin) + f * np.asarray(speed)
            xyz.append(p + rng.normal(0, 0.1, (4, 3)))
            t.append(np.full(4, f))
            lab.append(np.full(4, i))
    return np.concatenate(xyz), np.concatenate(t), np.concatenate(lab).astype(np.int64)


def test_bursts_of_one_moving_object_are_linked_into_one_cluster():
    rng = np.random.default_rng(0)
    xyz, t, lab = _fragments(rng, [0.0, 1.2, 2.3, 3.9])
    out, k = link_fragments(lab, xyz, t, detector_params())
    assert k == 1
    assert (out == 0).all()


def test_gap_longer_than_link_max_gap_is_not_bridged():
    rng = np.random.default_rng(1)
    xyz, t, lab = _fragments(rng, [0.0, 4.0])
    out, k = link_fragments(lab, xyz, t, detector_params({"link_max_gap": 2.0}))
    assert k == 2
    off, k_off = link_fragments(lab, xyz, t, detector_params({"link_max_gap": 0.0}))
    assert k_off == 2 and np.array_equal(off, lab)


def test_fragment_off_the_predicted_path_is_not_linked():
    rng = np.random.default_rng(2)
    xyz, t, lab = _fragments(rng, [0.0])
    # A second object 1 s later, 15 m to the side of where the first was heading.
    other, t2, _ = _fragments(rng, [1.0], origin=(0.0, 15.0, 20.0))
    out, k = link_fragments(
        np.concatenate([lab, np.ones(t2.size, np.int64)]),
        np.concatenate([xyz, other]),
        np.concatenate([t, t2]),
        detector_params(),
    )
    assert k == 2


def test_single_returns_without_velocity_do_not_chain():
    # Sparse returns of a static structure, one per frame, each its own fragment,
    # separated by more than a frame: no velocity on either side, no link.
    rng = np.random.default_rng(3)
    t = np.arange(6) * 0.5
    xyz = np.array([50.0, 10.0, 15.0]) + rng.normal(0, 1.0, (6, 3))
    lab = np.arange(6, dtype=np.int64)
    _, k = link_fragments(lab, xyz, t, detector_params())
    assert k == 6


def test_large_or_low_clusters_take_no_part():
    rng = np.random.default_rng(4)
    xyz, t, lab = _fragments(rng, [0.0, 1.0], origin=(0.0, 0.0, 0.5))  # below min_centroid_z
    _, k = link_fragments(lab, xyz, t, detector_params())
    assert k == 2


def test_large_and_low_clusters_beside_the_fragments_change_no_link():
    # Fragments interleaved in time and in the arrays with a large cluster (over
    # max_cluster_points) and a low one: the same links as without them, and those
    # two keep labels of their own.
    rng = np.random.default_rng(5)
    xyz, t, lab = _fragments(rng, [0.0, 1.2, 2.3])
    params = detector_params({"max_cluster_points": 60})
    alone, k_alone = link_fragments(lab, xyz, t, params)
    assert k_alone == 1
    wall = np.array([30.0, 5.0, 10.0]) + rng.normal(0, 2.0, (80, 3))
    low, t_low, _ = _fragments(rng, [0.5, 1.6], origin=(5.0, 5.0, 0.5))
    all_xyz = np.concatenate([wall, xyz, low])
    all_t = np.concatenate([rng.uniform(0.0, 3.0, 80), t, t_low])
    all_lab = np.concatenate([np.full(80, 3), lab, np.full(t_low.size, 4)])
    mixed = rng.permutation(all_t.size)
    out, k = link_fragments(all_lab[mixed], all_xyz[mixed], all_t[mixed], params)
    back = np.empty_like(out)
    back[mixed] = out
    assert k == k_alone + 2
    fragments = back[80 : 80 + t.size]
    assert np.array_equal(fragments == fragments[0], alone == alone[0])
    assert len({back[0], back[-1], *fragments}) == 2 + len(set(alone))


def test_extend_track_takes_points_on_the_path_only():
    rng = np.random.default_rng(5)
    xyz, t, _ = _fragments(rng, [0.0], length=1.0)
    member = np.ones(t.size, bool)
    # Isolated returns ahead on the path (1.3 s, 1.6 s) and one far off it.
    ahead_t = np.array([1.3, 1.6, 1.6])
    ahead = np.array([[8.0 * 1.3, 0.0, 20.0], [8.0 * 1.6, 0.0, 20.0], [8.0 * 1.6, 12.0, 20.0]])
    all_xyz = np.concatenate([xyz, ahead])
    all_t = np.concatenate([t, ahead_t])
    member = np.concatenate([member, np.zeros(3, bool)])
    pool = ~member
    out = extend_track(member, all_xyz, all_t, pool, detector_params())
    assert out[-3] and out[-2]
    assert not out[-1]


def test_extend_track_without_grow_end_grows_the_start_only():
    rng = np.random.default_rng(5)
    xyz, t, _ = _fragments(rng, [1.0], length=1.0)
    # Lone returns on the path 0.4 s before the track's first and after its last.
    extra_t = np.array([0.6, 2.3])
    extra = np.array([[8.0 * 0.6, 0.0, 20.0], [8.0 * 2.3, 0.0, 20.0]])
    all_xyz, all_t = np.concatenate([xyz, extra]), np.concatenate([t, extra_t])
    member = np.arange(all_t.size) < t.size
    both = extend_track(member, all_xyz, all_t, ~member, detector_params())
    assert both[-2] and both[-1]
    start = extend_track(member, all_xyz, all_t, ~member, detector_params(), grow_end=False)
    assert start[-2] and not start[-1]
    assert start[: t.size].all()


def test_fill_track_takes_returns_inside_its_gaps_on_its_path_only():
    # A drone hovering at (5, 5, 15), kept by the clusterer at 0-2 s and 5.5-7 s; single
    # returns at 3 s and 4.2 s (inside a 3.5 s gap), one 6 m off, one after the track.
    rng = np.random.default_rng(8)
    kept_t = np.concatenate([np.arange(0.0, 2.0, 0.3), np.arange(5.5, 7.0, 0.3)])
    kept = np.array([5.0, 5.0, 15.0]) + rng.normal(0, 0.1, (kept_t.size, 3))
    extra_t = np.array([3.0, 4.2, 3.6, 8.0])
    extra = np.array([[5.2, 4.9, 15.1], [4.8, 5.1, 14.9], [11.0, 5.0, 15.0], [5.0, 5.0, 15.0]])
    xyz = np.concatenate([kept, extra])
    t = np.concatenate([kept_t, extra_t])
    member = np.arange(t.size) < kept_t.size
    out = fill_track(member, xyz, t, ~member, detector_params())
    assert out[: kept_t.size].all()
    assert out[-4] and out[-3]  # on the path, inside the gap
    assert not out[-2]  # 6 m off the path
    assert not out[-1]  # after the track's end: extend_track's business, not this
    # Points outside the pool are never taken.
    pool = ~member
    pool[-4] = False
    assert not fill_track(member, xyz, t, pool, detector_params())[-4]


def test_fill_track_follows_a_moving_track():
    # 8 m/s along x with a 1.5 s hole; returns in the hole on the line join, one 4 m
    # to the side does not.
    t = np.concatenate([np.arange(0.0, 2.0, 0.1), np.arange(3.5, 5.0, 0.1)])
    xyz = np.stack([8.0 * t, np.zeros_like(t), np.full_like(t, 20.0)], axis=1)
    hole_t = np.array([2.5, 3.0, 2.8])
    hole = np.array([[20.0, 0.3, 20.0], [24.0, -0.2, 20.0], [22.4, 4.0, 20.0]])
    member = np.concatenate([np.ones(t.size, bool), np.zeros(3, bool)])
    out = fill_track(
        member, np.concatenate([xyz, hole]), np.concatenate([t, hole_t]), ~member, detector_params()
    )
    assert out[-3] and out[-2] and not out[-1]


def test_group_median():
    g = np.array([0, 0, 0, 1, 1, 2])
    v = np.array([5.0, 1.0, 3.0, 2.0, 4.0, 7.0])
    assert np.allclose(group_median(g, v, 4), [3.0, 3.0, 7.0, 0.0])


def test_weaving_track_loses_confidence_to_acceleration():
    # Same straight flight, one with a 1.5 m, 1.2 s-period weave (a bird), dense points.
    t = np.repeat(np.arange(0.0, 6.0, 0.1), 5)
    base = np.stack([6.0 * t, np.zeros_like(t), np.full_like(t, 20.0)], axis=1)
    weave = base.copy()
    weave[:, 1] += 1.5 * np.sin(2 * np.pi * t / 1.2)
    rng = np.random.default_rng(6)
    xyz = np.concatenate([base, weave + [0.0, 40.0, 0.0]]) + rng.normal(0, 0.05, (2 * t.size, 3))
    tt = np.concatenate([t, t])
    labels = np.repeat([0, 1], t.size)
    params = detector_params({"max_residual": 100.0, "max_excess": 100.0})
    scores = score_clusters(labels, xyz, tt, params, n_clusters=2)
    assert scores.acceleration[0] < params.smooth_accel
    assert scores.acceleration[1] > params.max_accel
    assert scores.confidence[0] > 0.5
    assert scores.confidence[1] == 0.0


def test_block_size_does_not_change_the_links(monkeypatch):
    import clusterfilter_ros.core.linking as linking

    rng = np.random.default_rng(7)
    parts = [_fragments(rng, [0.0, 1.0, 2.2], origin=(0.0, 5.0 * i, 20.0)) for i in range(6)]
    xyz = np.concatenate([p[0] for p in parts])
    t = np.concatenate([p[1] for p in parts])
    lab = np.concatenate([p[2] + 3 * i for i, p in enumerate(parts)])
    ref, k_ref = link_fragments(lab, xyz, t, detector_params())
    monkeypatch.setattr(linking, "_BLOCK", 2)
    monkeypatch.setattr(linking, "_BLOCK_CELLS", 3)
    small, k_small = link_fragments(lab, xyz, t, detector_params())
    assert k_ref == k_small == 6
    assert np.array_equal(ref, small)


def test_group_quantile_matches_numpy():
    rng = np.random.default_rng(8)
    g = rng.integers(0, 5, 200)
    v = rng.normal(size=200)
    from clusterfilter_ros.core.scoring import group_quantile

    for q in (0.1, 0.5, 0.9):
        got = group_quantile(g, v, 6, q)
        for c in range(5):
            assert got[c] == pytest.approx(np.quantile(v[g == c], q))
        assert got[5] == 0.0


def test_a_few_stray_returns_do_not_stop_a_hovering_cluster_from_counting_as_hovering():
    rng = np.random.default_rng(9)
    t = np.repeat(np.arange(0.0, 10.0, 0.2), 2)
    xyz = np.array([5.0, 5.0, 15.0]) + rng.normal(0, 0.15, (t.size, 3))
    # Four returns of something passing 4 m away join the cluster.
    stray_t = np.array([3.0, 3.1, 3.2, 3.3])
    stray = np.array([[9.0, 5.0, 15.0]] * 4)
    all_xyz = np.concatenate([xyz, stray])
    all_t = np.concatenate([t, stray_t])
    labels = np.zeros(all_t.size, np.int64)
    scores = score_clusters(labels, all_xyz, all_t, detector_params(), n_clusters=1)
    assert scores.extent[0] > detector_params().hover_max_extent
    # Scored as hovering (a still cluster gets nothing from the motion factors); the
    # stray returns still cost it some smoothness.
    assert scores.coherence[0] < detector_params().coherence_floor
    assert scores.confidence[0] > 0.3


def test_sparse_cluster_is_measured_with_longer_windows():
    from clusterfilter_ros.core.scoring import multiscale_residual, track_residual

    # Three returns per 2 s window over 8 s: no 2 s window has the six points a quadratic
    # fit needs, the longer windows do.
    t = np.arange(0.0, 8.0, 0.66)
    lab = np.zeros(t.size, np.int64)
    rng = np.random.default_rng(10)
    base = np.stack([5.0 * t, np.zeros_like(t), np.full_like(t, 20.0)], axis=1)
    smooth = base + rng.normal(0, 0.05, base.shape)
    erratic = base.copy()
    erratic[:, 1] += rng.normal(0, 1.0, t.size)
    _, has = track_residual(lab, erratic, t, 1, 2.0, 0.0, evidence=True)
    assert not has[0]
    r_smooth = multiscale_residual(lab, smooth, t, 1, 2.0, 0.0)[0]
    r_erratic = multiscale_residual(lab, erratic, t, 1, 2.0, 0.0)[0]
    assert 0.0 < r_smooth < 0.15
    assert r_erratic > 2.0 * r_smooth + 0.1


def test_more_evidence_ranks_first_at_equal_confidence():
    from clusterfilter_ros.core.scoring import select_clusters

    rng = np.random.default_rng(11)
    long_xyz, long_t, _ = _fragments(rng, [0.0], length=6.0)
    short_xyz, short_t, _ = _fragments(rng, [2.0], length=1.0, origin=(0.0, 40.0, 20.0))
    xyz = np.concatenate([long_xyz, short_xyz])
    t = np.concatenate([long_t, short_t])
    labels = np.concatenate([np.zeros(long_t.size, np.int64), np.ones(short_t.size, np.int64)])
    params = detector_params({"min_track_seconds": 0.0})
    scores = score_clusters(labels, xyz, t, params, n_clusters=2)
    scores.confidence[:] = 1.0  # equal confidence: evidence decides
    order = np.argsort(-scores.rank_score("normalized"))
    assert order[0] == 0
    assert select_clusters(scores, params)[0] == 0


def test_track_growth_does_not_take_a_scored_and_rejected_cluster():
    from clusterfilter_ros.core.offline import extend_selected

    rng = np.random.default_rng(12)
    track_xyz, track_t, _ = _fragments(rng, [0.0], length=1.0)
    # Right where the track is heading: a big cluster that was scored and rejected, and
    # one lone return (noise).
    big_t = np.repeat(np.arange(1.1, 1.9, 0.1), 4)
    big = np.stack([8.0 * big_t, np.zeros_like(big_t), np.full_like(big_t, 20.0)], axis=1)
    lone_t = np.array([1.05])
    lone = np.array([[8.0 * 1.05, 0.0, 20.0]])
    xyz = np.concatenate([track_xyz, big, lone])
    t = np.concatenate([track_t, big_t, lone_t])
    labels = np.concatenate([np.zeros(track_t.size, np.int64), np.ones(big_t.size, np.int64), [-1]])
    params = detector_params()
    scores = score_clusters(labels, xyz, t, params, n_clusters=2)
    scores.confidence[1] = 0.0  # rejected
    out = extend_selected(labels, xyz, t, scores, [0], params)
    assert out[-1] == 0  # the lone return joins
    assert (out[track_t.size : -1] == 1).all()  # the rejected cluster does not


def test_a_hovering_track_takes_back_its_returns_from_a_passing_birds_cluster():
    from clusterfilter_ros.core.offline import extend_selected

    rng = np.random.default_rng(13)
    hover = np.array([5.0, 10.0, 15.0])
    drone_t = np.arange(0.0, 12.0, 0.3)
    drone = hover + rng.normal(0.0, 0.05, (drone_t.size, 3))
    # From 4 s to 8 s a bird flying past took the drone's returns into its cluster.
    passing = (drone_t > 4.0) & (drone_t < 8.0)
    bird_t = np.repeat(np.arange(4.0, 8.0, 0.1), 2)
    bird = hover + np.column_stack(
        [2.5 * (bird_t - 6.0), np.full_like(bird_t, 1.5), np.zeros_like(bird_t)]
    )
    xyz = np.concatenate([drone, bird])
    t = np.concatenate([drone_t, bird_t])
    labels = np.concatenate([np.where(passing, 1, 0), np.ones(bird_t.size, np.int64)])
    params = detector_params()
    scores = score_clusters(labels, xyz, t, params, n_clusters=2)
    assert scores.n_points[1] >= params.min_cluster_points  # scored, not too small
    out = extend_selected(labels, xyz, t, scores, [0], params)
    assert (out[: drone_t.size] == 0).all()  # the drone's returns are back in its track
    far = np.linalg.norm(bird - hover, axis=1) > 3.0
    assert (out[drone_t.size :][far] == 1).all()  # the bird away from it is not
    # Points in exclude (split pieces, trimmed points) are never taken.
    ends = extend_selected(labels, xyz, t, scores, [0], params, exclude=labels == 1)
    assert (ends[: drone_t.size][passing] == 1).all()


def test_extend_track_crosses_gaps_up_to_extend_max_gap():
    rng = np.random.default_rng(8)
    xyz, t, _ = _fragments(rng, [0.0], length=1.0)  # last frame at 0.9 s
    lone_t = np.array([2.2])  # 1.3 s later, where the track was heading
    all_xyz = np.concatenate([xyz, [[8.0 * 2.2, 0.0, 20.0]]])
    all_t = np.concatenate([t, lone_t])
    member = np.concatenate([np.ones(t.size, bool), [False]])
    grown = extend_track(member, all_xyz, all_t, ~member, detector_params())
    assert grown[-1]
    short = detector_params({"extend_max_gap": 1.0})
    assert not extend_track(member, all_xyz, all_t, ~member, short)[-1]
    off = detector_params({"extend_max_gap": 0.0})
    assert np.array_equal(extend_track(member, all_xyz, all_t, ~member, off), member)


def test_later_linking_rounds_join_chains_by_their_own_end_states():
    # A 1 s track, then single-frame returns 0.4 s and 0.9 s after it: the first joins
    # the track in round one; the second is one frame after a one-frame fragment (no
    # velocity on either side) and joins only once the chain's end state is used.
    rng = np.random.default_rng(9)
    xyz, t, lab = _fragments(rng, [0.0, 1.3, 1.8], length=1.0)
    single = (lab == 0) | (t == 1.3) | (t == 1.8)
    xyz, t, lab = xyz[single], t[single], lab[single]
    one, k1 = global_clusters(xyz, t, detector_params({"link_passes": 1}))
    assert k1 == 2
    out, k = global_clusters(xyz, t, detector_params())
    assert k == 1 and (out == 0).all()
    # Streaming keeps to one round unless told otherwise.
    _, k_stream = global_clusters(xyz, t, detector_params(), passes=1)
    assert k_stream == 2


def test_frame_samples_follow_the_gaps_between_returns_not_a_time_grid():
    from clusterfilter_ros.core.linking import frame_samples

    # Cluster 0: one sweep per frame, the two lidars 5 ms apart, each sweep's returns
    # spread over 20 ms. Cluster 1: a run of returns every 20 ms for 0.35 s.
    sweeps = np.concatenate([f + np.array([0.0, 0.01, 0.02, 0.025]) for f in (0.0, 0.1, 0.3)])
    run = np.arange(0.0, 0.35, 0.02) + 1.0
    t = np.concatenate([sweeps, run])
    lab = np.concatenate([np.zeros(sweeps.size, int), np.ones(run.size, int)])
    xyz = np.column_stack([t * 5.0, np.zeros_like(t), np.full_like(t, 20.0)])
    cid, ts, _, n, _ = frame_samples(lab, xyz, t, 2, 0.1)
    assert cid.tolist() == [0, 0, 0, 1, 1, 1, 1]
    assert n.tolist() == [4, 4, 4, 5, 5, 5, 3]
    assert np.all(np.diff(ts[:3]) > 0) and np.all(np.diff(ts[3:]) > 0)
    # The same returns with the rest of the cloud starting elsewhere in time (another
    # point 0.0437 s earlier) give the same samples: nothing depends on a grid's start.
    extra_t = np.concatenate([[t.min() - 0.0437], t])
    extra_lab = np.concatenate([[2], lab])
    extra_xyz = np.vstack([[[50.0, 50.0, 0.0]], xyz])
    cid2, ts2, _, n2, _ = frame_samples(extra_lab, extra_xyz, extra_t, 3, 0.1)
    keep = cid2 < 2
    assert cid2[keep].tolist() == cid.tolist() and n2[keep].tolist() == n.tolist()
    assert np.allclose(ts2[keep], ts)


def test_chains_formed_marks_the_clusters_that_joined_several():
    before = np.array([0, 0, 1, 2, 3, -1, 4])
    after = np.array([0, 0, 0, 1, 2, -1, 2])
    assert chains_formed(before, after, 3).tolist() == [True, False, True]


def test_later_rounds_over_new_chains_only_link_as_rounds_over_every_pair():
    # Many objects, each broken into bursts, some bursts single frames: rounds 2+ that
    # look only at pairs with a chain formed in the round before give the same labels as
    # rounds over every pair.
    rng = np.random.default_rng(4)
    parts = []
    for i in range(12):
        speed = rng.uniform(-9, 9, 3) * np.array([1.0, 1.0, 0.2])
        origin = rng.uniform(-60, 60, 3) + np.array([0.0, 0.0, 80.0])
        # Two single frames, a 1 s burst, single frames 0.4-0.6 s apart, another burst.
        # As in the test above, a single frame joins only once the fragment next to it
        # is part of a chain with a velocity: after the burst (a chain before a single
        # frame) and before it (a single frame before a chain).
        first = rng.uniform(1.5, 3.0)
        singles = np.concatenate(
            [[first - 1.0, first - 0.5], first + 1.0 + np.cumsum(rng.uniform(0.4, 0.6, 4))]
        )
        bursts = [first, singles[-1] + 0.5]
        starts = np.sort(np.concatenate([singles, bursts]))
        xyz, t, lab = _fragments(rng, starts, length=1.0, speed=speed, origin=origin)
        burst_labels = np.searchsorted(starts, bursts)
        keep = np.isin(lab, burst_labels) | np.isin(np.round(t, 6), np.round(singles, 6))
        parts.append((xyz[keep], t[keep], lab[keep] + 10 * i))
    xyz = np.concatenate([p[0] for p in parts])
    t = np.concatenate([p[1] for p in parts])
    labels, k = relabel_compact(np.concatenate([p[2] for p in parts]))
    params = detector_params()
    every, k_every, rounds = labels, k, 0
    while True:
        nxt, k_next = link_fragments(every, xyz, t, params)
        if k_next == k_every:
            break
        every, k_every, rounds = nxt, k_next, rounds + 1
    assert rounds >= 2  # the case needs later rounds
    new_only, k_new = global_clusters(xyz, t, params.copy(link_passes=20))
    # Same partition of the points (label numbers may differ).
    pairs = np.unique(np.stack([every, new_only]), axis=1)
    assert k_new == k_every and pairs.shape[1] == k_every + (every < 0).any()


def _with_lone_return(offset) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An object at 8 m/s, 20 m up: a sparse piece (one return every 0.3 s, 0-1.5 s), a
    dense one (four returns a frame, 1.9-2.9 s), and one more return in the sparse
    piece's cluster at 1.8 s, ``offset`` m from the object's path."""
    rng = np.random.default_rng(3)
    sparse = np.arange(0.0, 1.6, 0.3)
    dense = np.repeat(np.arange(1.9, 3.0, 0.1), 4)
    t = np.concatenate([sparse, dense, [1.8]])
    xyz = np.column_stack([8.0 * t, np.zeros_like(t), np.full_like(t, 20.0)])
    xyz += rng.normal(0.0, 0.1, xyz.shape)
    xyz[-1] += np.asarray(offset, float)
    lab = np.concatenate([np.zeros(sparse.size), np.ones(dense.size), [0]]).astype(np.int64)
    return xyz, t, lab


def test_a_lone_return_off_the_path_at_a_fragments_end_does_not_stop_the_link():
    # Another object's return the clusterer joined to the end of the sparse piece, 4 m
    # off its path: the piece's end state followed it, and the dense piece did not link
    # (flyover seeds 1503, 1901, 1904: the drone's approach was left unreported).
    params = detector_params()
    xyz, t, lab = _with_lone_return((0.0, 4.0, 0.0))
    assert link_fragments(lab, xyz, t, params)[1] == 1
    # The same return on the path is the piece's end, and the pieces link as well.
    xyz, t, lab = _with_lone_return((0.0, 0.2, 0.0))
    assert link_fragments(lab, xyz, t, params)[1] == 1


def test_fragments_of_one_or_two_samples_have_no_stray_ends():
    # The last cluster a single return (its neighbouring sample indices past the end).
    xyz, t, lab = _with_lone_return((0.0, 4.0, 0.0))
    xyz = np.vstack([xyz, [[50.0, 50.0, 20.0]]])
    t, lab = np.append(t, 1.0), np.append(lab, 2)
    out, k = link_fragments(lab, xyz, t, detector_params())
    assert k == 2 and np.count_nonzero(out == out[-1]) == 1


def test_leaving_out_a_stray_end_does_not_widen_the_reach():
    # Simulated fast_pass seed 1604 (t, x, y, z): three returns of a crown 50 m away, the
    # last off the line of the first two, then the drone's first returns 1.3 s later.
    # Without its last return the crown's piece ends 1.7 s before the drone's starts;
    # the reach for 1.7 s joined them, the reach for the 1.3 s between the returns
    # does not.
    rows = np.array(
        [
            [2.991, -47.57, 21.31, 7.55],
            [3.109, -48.03, 21.0, 5.03],
            [3.545, -49.51, 19.62, 2.14],
            [4.805, -33.42, 14.24, 7.35],
            [4.964, -31.83, 13.78, 7.1],
            [5.24, -29.32, 12.63, 6.71],
            [5.95, -23.16, 10.63, 5.88],
        ]
    )
    lab = np.array([0, 0, 0, 1, 1, 1, 1])
    assert link_fragments(lab, rows[:, 1:], rows[:, 0], detector_params())[1] == 2


def _sparse_pass(z: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A drone passing at 10 m/s whose selected track starts with a lone return 1.1 s
    before the rest (as in fast_pass seed 3); two earlier returns on its path and one
    5 m off it are left as noise. Returns xyz, t and the track's member mask."""
    vel = np.array([10.0, -3.0, -1.0])
    start = np.array([-40.0, 17.0, z])
    track_t = np.concatenate([[3.9], np.arange(5.0, 8.0, 0.3)])
    noise_t = np.array([3.1, 2.7, 3.1])
    t = np.concatenate([track_t, noise_t])
    xyz = start + (t - 3.9)[:, None] * vel
    xyz[-1] += [0.0, 5.0, 0.0]
    member = np.arange(t.size) < track_t.size
    return xyz, t, member


def test_extend_track_lone_first_return_takes_its_velocity_from_the_next_sample():
    xyz, t, member = _sparse_pass(z=9.0)
    grown = extend_track(member, xyz, t, ~member, detector_params())
    assert grown[-3] and grown[-2]  # on the path, 0.8 s and 1.2 s before the lone return
    assert not grown[-1]  # 5 m off it


def test_extend_track_lone_return_near_the_ground_borrows_no_velocity():
    # Below min_centroid_z (a landing drone's track may have taken a person's returns
    # there) a lone end sample keeps to the old rule: no velocity, one frame of reach.
    xyz, t, member = _sparse_pass(z=0.5)
    grown = extend_track(member, xyz, t, ~member, detector_params())
    assert np.array_equal(grown, member)


def test_extend_track_ignores_a_stray_last_return_of_the_track():
    # A sparse track (one return every 0.3 s at 8 m/s, as fast_pass seed 1903 40 m out)
    # whose last member is a return of something else 8 m behind it, joined by the
    # clusterer. The drone's next returns, 0.6 s and 1.1 s after its own last one, lie
    # where the track was heading and are grown into; the stray stays a member.
    track_t = np.arange(0.0, 1.6, 0.3)
    track = np.column_stack([8.0 * track_t, np.zeros_like(track_t), np.full_like(track_t, 20.0)])
    stray = [[7.2, 2.0, 20.0]]
    ahead_t = np.array([2.1, 2.6])
    ahead = np.column_stack([8.0 * ahead_t, np.zeros(2), np.full(2, 20.0)])
    xyz = np.concatenate([track, stray, ahead])
    t = np.concatenate([track_t, [1.8], ahead_t])
    member = np.arange(t.size) < track_t.size + 1
    grown = extend_track(member, xyz, t, ~member, detector_params())
    assert grown[-2] and grown[-1]
    assert grown[track_t.size]


def test_an_end_state_over_two_frames_0_1_s_apart_reaches_back_for_its_velocity():
    # Flyover seed 1902, 110 m out: a track at 11.7 m/s whose last two frames, 0.09 s
    # apart, are 0.35 m off its path in opposite directions (the drone's spread of
    # returns). Fitted over those two alone its end velocity is 8 m/s off, and the
    # drone's next frame, 1.35 s later and on the path, lay beyond the reach.
    def on_path(times):
        times = np.asarray(times, dtype=float)
        return np.column_stack([np.zeros_like(times), 11.7 * times, np.full_like(times, 90.0)])

    a_t = np.array([35.0, 35.4, 35.9, 37.04, 37.13])
    a_xyz = on_path(a_t) + [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0.25, -0.25, 0], [-0.25, 0.25, 0]]
    b_t = np.array([38.48])
    t = np.concatenate([np.repeat(a_t, 3), np.repeat(b_t, 5)])
    xyz = np.concatenate([np.repeat(a_xyz, 3, axis=0), np.repeat(on_path(b_t), 5, axis=0)])
    lab = np.concatenate([np.zeros(15, np.int64), np.ones(5, np.int64)])
    out, k = link_fragments(lab, xyz, t, detector_params())
    assert k == 1


def test_extend_track_bridges_no_gap_into_returns_below_the_floor():
    # Take-off seed 2201 of the twenty-first fresh set: a drone landing 7 m from the rig
    # (one sample a frame, descending at 2.4 m/s), then, 1.37 s after its last return
    # and 5 m away, a person walking past below the Mid360's height. Both are returns
    # below the floor that growth may take; the person's must not continue the track.
    land_t = np.arange(32.0, 33.45, 0.1)
    land = np.column_stack(
        [np.full_like(land_t, 6.0), -3.5 + 0.85 * (land_t - 33.0), 0.05 - 2.4 * (land_t - 33.0)]
    )
    touch_t = np.array([33.5])  # the drone's last return, 0.09 s after the track's end
    touch = np.array([[6.0, -3.07, -1.0]])
    walk_t = np.arange(34.78, 36.0, 0.1)
    walk = np.column_stack(
        [np.full_like(walk_t, 10.3), -0.64 - 1.8 * (walk_t - 34.78), np.full_like(walk_t, -0.8)]
    )
    xyz = np.concatenate([land, touch, walk])
    t = np.concatenate([land_t, touch_t, walk_t])
    member = np.arange(t.size) < land_t.size
    below = ~member & (xyz[:, 2] <= 0.0)
    params = detector_params()
    grown = extend_track(member, xyz, t, ~member, params, short_gap=below)
    assert grown[land_t.size]  # the drone's own last return, one frame on
    assert not grown[land_t.size + 1 :].any()
    # Without the limit the person's returns are within the reach (5.2 m after 1.37 s).
    assert extend_track(member, xyz, t, ~member, params)[land_t.size + 1 :].any()


def _braking_into_a_hover(
    first_return: tuple[float, float], delay: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Take-off seed 2303 of the twenty-second fresh set: a track at 7.6 m/s along x whose
    last return is at x = 26 m (9.95 s), and the returns of a hover 1.15-4.55 s later at
    ``first_return`` (along x, across in y). The drone braked harder than link_max_accel:
    the hover lies 5.1 m short of where the track was heading, beyond the reach of 4.1 m.
    Returns (xyz, t) of the track (2 returns a frame) followed by the hover's 10,
    ``delay`` s later still."""
    rng = np.random.default_rng(3)
    track_t = np.repeat(np.arange(8.0, 9.96, 0.15), 2)
    track = np.column_stack(
        [26.0 + 7.6 * (track_t - 9.95), np.zeros_like(track_t), np.full_like(track_t, 14.0)]
    )
    hover_t = np.linspace(11.1, 14.5, 10) + delay
    x, y = first_return
    hover = np.column_stack([np.full(10, 26.0 + x), np.full(10, y), np.full(10, 14.0)])
    hover += rng.normal(0.0, 0.05, hover.shape)
    return np.concatenate([track, hover]), np.concatenate([track_t, hover_t])


def test_extend_track_follows_a_drone_braking_into_a_hover():
    xyz, t = _braking_into_a_hover((3.67, 0.0))
    member = t < 10.0
    grown = extend_track(member, xyz, t, ~member, detector_params())
    assert grown[~member].all()
    # Braking no harder than link_max_accel, the hover is out of reach.
    gentle = detector_params({"extend_max_brake": 4.0})
    assert not extend_track(member, xyz, t, ~member, gentle)[~member].any()


def test_extend_track_finds_a_hover_seconds_after_a_braking_end():
    # Take-off 5604 of the fifty-fifth set: the hover's first return came 1.51 s after
    # the track's last, beyond extend_max_gap (1.5 s). Deviation 124: a moving end grows
    # up to extend_hover_gap (3 s) by returns where braking would have stopped it, when
    # another return confirms the spot; here the first comes 1.75 s on.
    xyz, t = _braking_into_a_hover((3.67, 0.0), delay=0.6)
    member = t < 10.0
    assert extend_track(member, xyz, t, ~member, detector_params())[~member].all()
    off = detector_params({"extend_brake_hover": False})
    assert not extend_track(member, xyz, t, ~member, off)[~member].any()
    # A lone return there (a tree's, noise), nothing else at that spot: not taken.
    lone = np.flatnonzero(~member)[0]
    keep = member.copy()
    keep[lone] = True
    grown = extend_track(member[keep], xyz[keep], t[keep], ~member[keep], detector_params())
    assert not grown[~member[keep]].any()


@pytest.mark.parametrize(
    "first_return",
    [(1.5, 0.0), (3.67, 2.5)],  # a stop needing 19 m/s^2; 2.5 m off the way
    ids=["harder-than-extend_max_brake", "off-the-way"],
)
def test_extend_track_takes_no_stop_it_could_not_have_made(first_return):
    xyz, t = _braking_into_a_hover(first_return)
    member = t < 10.0
    assert not extend_track(member, xyz, t, ~member, detector_params())[~member].any()


def test_extend_track_reaches_back_to_the_hover_a_drone_sped_away_from():
    # The same flight backwards in time: a hover, then a track leaving it at 7.6 m/s.
    # Growing from the track's first return back in time is the mirror image.
    xyz, t = _braking_into_a_hover((3.67, 0.0))
    t = 20.0 - t
    member = t > 10.0
    grown = extend_track(member, xyz, t, ~member, detector_params())
    assert grown[~member].all()
    gentle = detector_params({"extend_max_brake": 4.0})
    assert not extend_track(member, xyz, t, ~member, gentle)[~member].any()


def test_extend_track_reaches_back_through_a_hover_more_than_link_max_gap_before():
    # Default 6604 of the sixty-fifth set: a drone hovered 15 m out, seen in lone
    # returns, then climbed away; its track began 2.3 s after the hover's last return.
    # Growing back, the braking rule takes that return where the drone had stopped, but
    # alone (its neighbour inward beyond link_max_gap) it spans no velocity. Deviation
    # 138: it is an end at rest, and the hover's earlier returns join as a hover's do.
    xyz, t = _braking_into_a_hover((3.67, 0.0), delay=1.0)
    t = 20.0 - t
    member = t > 10.0
    hover = ~member
    assert t[member].min() - t[hover].max() > detector_params().link_max_gap
    assert extend_track(member, xyz, t, hover, detector_params())[hover].all()
    off = detector_params({"extend_stop_hover": False})
    assert np.count_nonzero(extend_track(member, xyz, t, hover, off)[hover]) == 1


def _hover_with_a_pause(earlier: list[tuple[float, float]]) -> tuple[np.ndarray, np.ndarray]:
    """Take-off seed 2301 of the twenty-second fresh set: a drone hovering 35 m out, its
    returns once or twice a second, with a pause of 2.35 s (12.92 -> 15.27 s) longer than
    extend_max_gap. The track is the hover after the pause; ``earlier`` are (time, offset
    along x in m) or (time, x, y, z offsets) of returns before it. Returns (xyz, t), the
    track's first."""
    rng = np.random.default_rng(4)
    here = np.array([22.4, 22.2, 14.7])
    track_t = np.array([15.27, 15.76, 16.33, 16.88, 17.4, 17.9])
    track = here + rng.normal(0.0, 0.1, (track_t.size, 3))
    early_t = np.array([e[0] for e in earlier])
    early = here + np.array([[*e[1:], 0.0, 0.0][:3] for e in earlier]).reshape(-1, 3)
    return np.concatenate([track, early]), np.concatenate([track_t, early_t])


def test_extend_track_takes_a_hovering_drones_returns_across_a_longer_pause():
    xyz, t = _hover_with_a_pause([(11.38, 0.0), (11.87, 0.1), (12.37, -0.1), (12.92, 0.0)])
    member = t > 15.0
    grown = extend_track(member, xyz, t, ~member, detector_params())
    assert grown.all()
    off = detector_params({"extend_hover_gap": 0.0})
    assert not extend_track(member, xyz, t, ~member, off)[~member].any()


def test_a_hovering_end_gives_back_a_scattered_stay_taken_across_its_pause():
    # `default` 6003 of the fifty-ninth set: a track's start grew back across a 1.7 s
    # pause into a tree crown's returns, one a second spread 0.7 m (these five, about
    # their mean), and the track was reported on the crown for 6 s. Deviation 131:
    # returns taken from a long pause on that stay in place must scatter as a hovering
    # drone's do (hover_max_scatter).
    crown = [
        (13.57, 0.76, -0.38, 0.42),
        (13.08, 0.56, 0.22, -0.58),
        (11.99, 0.46, 0.02, -0.08),
        (10.67, -0.74, 0.12, 0.02),
        (8.82, -1.04, 0.02, 0.22),
    ]
    xyz, t = _hover_with_a_pause(crown)
    member = t > 15.0
    on = detector_params()
    off = detector_params({"extend_stay_scatter": False})
    assert extend_track(member, xyz, t, ~member, off)[~member].all()
    assert not extend_track(member, xyz, t, ~member, on)[~member].any()
    # The drone's own returns at the spot (0.1 m apart) are kept.
    xyz, t = _hover_with_a_pause([(11.38, 0.0), (11.87, 0.1), (12.37, -0.1), (12.92, 0.0)])
    member = t > 15.0
    assert extend_track(member, xyz, t, ~member, on)[~member].all()


@pytest.mark.parametrize(
    "earlier",
    [[(12.92, 3.0)], [(11.9, 0.0)]],  # beyond track_gate; beyond extend_hover_gap
    ids=["off-the-spot", "too-long-before"],
)
def test_extend_track_hover_pause_takes_only_returns_on_the_spot_within_the_gap(earlier):
    xyz, t = _hover_with_a_pause(earlier)
    member = t > 15.0
    assert not extend_track(member, xyz, t, ~member, detector_params())[~member].any()


@pytest.mark.parametrize(("offset", "taken"), [(3.0, False), (1.5, True)])
def test_a_hovering_end_takes_a_return_past_max_gap_only_on_the_spot(offset, taken):
    # Hover 4801 of the forty-seventh set: a bird's lone return 3.0 m from a drone
    # hovering 30 m out, 1.15 s before the drone's first return. Within the pause
    # extend_max_gap allows (1.5 s) the linking reach was 4.1 m. But a return taken more
    # than max_gap (1 s) back becomes a segment of its own, reported where it lies. So a
    # hovering end now takes it only within track_gate (2 m), as across a longer pause.
    xyz, t = _hover_with_a_pause([(15.27 - 1.15, offset)])
    member = t > 15.0
    assert extend_track(member, xyz, t, ~member, detector_params())[~member].all() == taken


def _pass_with_a_lone_return(direction: np.ndarray, lone_behind: float = 7.7):
    """A drone passing at 11 m/s along ``direction`` from 25 m out along a fixed line
    of sight, two returns a frame for 1 s, then one return 2.7 s after the last frame,
    ``lone_behind`` m short of where the track was heading (it slowed down): fast_pass
    seed 2501 leaving the rig. Returns (xyz, t, member)."""
    rng = np.random.default_rng(11)
    sight = np.array([0.8, -0.55, 0.25])
    sight /= np.linalg.norm(sight)
    direction = direction / np.linalg.norm(direction)
    frames = np.repeat(np.arange(11) * 0.1, 2)
    track = 25.0 * sight + frames[:, None] * 11.0 * direction
    track += rng.normal(0.0, 0.1, track.shape)
    lone_t = frames[-1] + 2.7
    lone = 25.0 * sight + (lone_t * 11.0 - lone_behind) * direction
    xyz = np.concatenate([track, lone[None]])
    t = np.concatenate([frames, [lone_t]])
    return xyz, t, t <= frames[-1]


def test_extend_track_follows_a_pass_leaving_the_lidars_across_a_longer_gap():
    sight = np.array([0.8, -0.55, 0.25])
    xyz, t, member = _pass_with_a_lone_return(sight)
    assert extend_track(member, xyz, t, ~member, detector_params())[~member].all()
    off = detector_params({"extend_far_gap": 0.0})
    assert not extend_track(member, xyz, t, ~member, off)[~member].any()
    # Backwards in time: the same pass arriving, its first return 2.7 s before the rest.
    xyz_in, t_in = xyz.copy(), -t
    assert extend_track(member, xyz_in, t_in, ~member, detector_params())[~member].all()


def test_extend_track_takes_no_longer_gap_for_a_pass_across_the_line_of_sight():
    # Moving across the line of sight, the track's returns do not thin out with range:
    # a gap of 2.7 s is not bridged.
    across = np.cross(np.array([0.8, -0.55, 0.25]), [0.0, 0.0, 1.0])
    xyz, t, member = _pass_with_a_lone_return(across)
    assert not extend_track(member, xyz, t, ~member, detector_params())[~member].any()


def test_extend_track_takes_no_longer_gap_into_a_spot_that_returns_again():
    # The same lone return, but the spot also returned 5 s later (a tree crown far out,
    # hit too seldom to be static): not taken across the longer gap.
    sight = np.array([0.8, -0.55, 0.25])
    xyz, t, member = _pass_with_a_lone_return(sight)
    again = xyz[-1] + np.array([0.5, 0.3, -0.4])
    xyz2 = np.concatenate([xyz, again[None]])
    t2 = np.concatenate([t, [t[-1] + 5.0]])
    member2 = np.concatenate([member, [False]])
    grown = extend_track(member2, xyz2, t2, ~member2, detector_params())
    assert not grown[~member2].any()


def test_extend_track_takes_no_longer_gap_close_in():
    # A lone return 2.7 s after a track leaving at 3.6 m/s, 26 m out: that close, a drone
    # returns every frame or two, and the gap is not its range.
    sight = np.array([0.8, -0.55, 0.25])
    sight /= np.linalg.norm(sight)
    frames = np.repeat(np.arange(11) * 0.1, 2)
    track = 20.0 * sight + frames[:, None] * 3.6 * sight
    lone_t = frames[-1] + 2.7
    xyz = np.concatenate([track, (20.0 + 3.6 * lone_t) * sight[None]])
    t = np.concatenate([frames, [lone_t]])
    member = t <= frames[-1]
    assert not extend_track(member, xyz, t, ~member, detector_params())[~member].any()


def _leg(rng, t0, t1, start, velocity, label):
    """A straight leg seen every frame from t0 to t1: 4 returns per frame."""
    xyz, t = [], []
    for f in np.arange(t0, t1 + 1e-9, 0.1):
        p = np.asarray(start) + (f - t0) * np.asarray(velocity)
        xyz.append(p + rng.normal(0, 0.05, (4, 3)))
        t.append(np.full(4, f))
    xyz, t = np.concatenate(xyz), np.concatenate(t)
    return xyz, t, np.full(t.size, label, dtype=np.int64)


def test_a_leg_heading_where_another_object_appears_is_not_linked_to_it():
    # fast_pass seed 3604 of the thirty-fifth set: a bird leg at 14 m/s ended 1.2 s
    # before the drone's track began about where the leg was heading (within the
    # linking reach), the drone flying across it at 5 m/s (deviation 88).
    rng = np.random.default_rng(3)
    bird = _leg(rng, 0.0, 1.3, (12.9, -20.5, 13.9), (-9.2, 10.9, -2.3), 0)
    start = np.asarray((12.9, -20.5, 13.9)) + 2.5 * np.asarray((-9.2, 10.9, -2.3))
    drone = _leg(rng, 2.5, 5.0, start + (1.0, 1.0, 0.0), (5.0, -2.0, -1.0), 1)
    xyz, t, lab = (np.concatenate(parts) for parts in zip(bird, drone, strict=True))
    _, k_off = link_fragments(lab, xyz, t, detector_params({"link_max_dv": 0.0}))
    assert k_off == 1  # position alone: linked
    _, k = link_fragments(lab, xyz, t, detector_params())
    assert k == 2
    # A drone's own turn: the same gap, its velocity turned by 30 degrees.
    turn = np.radians(30.0)
    v2 = (8.0 * np.cos(turn), 8.0 * np.sin(turn), 0.0)
    first = _leg(rng, 0.0, 1.0, (0.0, 0.0, 20.0), (8.0, 0.0, 0.0), 0)
    second = _leg(
        rng, 2.2, 3.2, (8.0 * 1.6 + 8.0 * 0.6 * np.cos(turn), 8.0 * 0.6 * np.sin(turn), 20.0), v2, 1
    )
    xyz, t, lab = (np.concatenate(parts) for parts in zip(first, second, strict=True))
    _, k = link_fragments(lab, xyz, t, detector_params())
    assert k == 1


def test_a_fast_bird_does_not_take_over_a_slow_drone_hidden_for_a_second():
    # `default` seed 5701 of the fifty-sixth set: the drone (2.4 m/s) went behind cover,
    # and 1 s later a bird at 14 m/s began 2.4 m from where the drone was heading. Their
    # velocities differ by 13.5 m/s: within 10 + link_max_accel x gap, not within 8
    # (deviation 126).
    rng = np.random.default_rng(5)
    drone = _leg(rng, 0.0, 2.0, (18.0, 0.0, 11.0), (-2.0, 1.5, 0.0), 0)
    bird = _leg(rng, 2.98, 3.38, (10.9, 2.4, 11.3), (-11.5, -7.0, 4.5), 1)
    xyz, t, lab = (np.concatenate(parts) for parts in zip(drone, bird, strict=True))
    _, k_old = link_fragments(lab, xyz, t, detector_params({"link_max_dv": 10.0}))
    assert k_old == 1
    _, k = link_fragments(lab, xyz, t, detector_params())
    assert k == 2


def test_streaming_links_with_its_own_velocity_test(monkeypatch):
    # Deviation 88 is offline only by default: the live history links by position alone.
    from clusterfilter_ros.core import streaming
    from clusterfilter_ros.core.frame import AVIA, Frame

    seen = []
    original = streaming.global_clusters

    def spy(xyz, t, params, **kwargs):
        seen.append(params.link_max_dv)
        return original(xyz, t, params, **kwargs)

    monkeypatch.setattr(streaming, "global_clusters", spy)
    rng = np.random.default_rng(4)
    xyz, t, _ = _leg(rng, 0.0, 2.0, (0.0, 0.0, 20.0), (8.0, 0.0, 0.0), 0)
    for dv in (0.0, 7.0):
        params = detector_params().copy(warmup=0.0, stream_link_max_dv=dv)
        assert params.link_max_dv == 8.0
        detector = streaming.StreamingDetector(params)
        for stamp in np.unique(t):
            detector.push(Frame(float(stamp), AVIA, xyz[t == stamp].astype(np.float32)))
    assert set(seen) == {0.0, 7.0}


def test_a_leg_does_not_link_to_an_object_at_rest_it_could_not_have_left():
    # no_drone seed 5901 of the fifty-eighth set: returns from a crown's edge, scattered
    # in place (fitted speed 1.6 m/s), and 1.75 s later a bird's leg at 9 m/s whose
    # start, carried back by its own velocity, came within the reach of the crown's
    # last returns. From rest, the bird would have covered only half of that
    # (deviation 128).
    rng = np.random.default_rng(6)
    crown = _leg(rng, 3.6, 4.0, (-35.9, -38.7, 6.6), (0.3, 0.0, -1.6), 0)
    end = np.asarray((-35.9, -38.7, 6.6)) + 0.4 * np.asarray((0.3, 0.0, -1.6))
    v_bird = np.asarray((5.0, 6.8, 2.5))
    start = end + 1.75 * v_bird + (3.0, 0.0, 0.0)
    bird = _leg(rng, 5.75, 6.35, start, v_bird, 1)
    xyz, t, lab = (np.concatenate(parts) for parts in zip(crown, bird, strict=True))
    _, k_off = link_fragments(lab, xyz, t, detector_params({"link_rest_speed": 0.0}))
    assert k_off == 1  # the nearer single-velocity carry alone: linked
    _, k = link_fragments(lab, xyz, t, detector_params())
    assert k == 2


@pytest.mark.parametrize("arriving", [False, True])
def test_a_drone_leaving_or_reaching_a_hover_is_still_linked(arriving):
    # From rest to 4 m/s at 3 m/s^2 over a 1.3 s gap without returns (or the reverse):
    # the mean of the two velocities carries one end onto the other.
    rng = np.random.default_rng(7)
    spot = np.asarray((10.0, 5.0, 15.0))
    v = np.asarray((4.0, 0.0, 0.0))
    gap = 4.0 / 3.0
    if arriving:
        leg = _leg(rng, 0.0, 1.0, spot - (1.0 + gap / 2) * v, v, 0)
        hover = _leg(rng, 1.0 + gap, 4.0, spot, (0.0, 0.0, 0.0), 1)
        parts = zip(leg, hover, strict=True)
    else:
        hover = _leg(rng, 0.0, 2.0, spot, (0.0, 0.0, 0.0), 0)
        leg = _leg(rng, 2.0 + gap, 3.5, spot + 0.5 * gap * v, v, 1)
        parts = zip(hover, leg, strict=True)
    xyz, t, lab = (np.concatenate(p) for p in parts)
    _, k = link_fragments(lab, xyz, t, detector_params())
    assert k == 1
