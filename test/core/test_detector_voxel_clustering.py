"""Voxel keys, neighbourhoods, the voxel clusterer against DBSCAN, and the denoise."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

from clusterfilter_ros.core import voxel
from clusterfilter_ros.core.clustering import (
    absorb_colocated_noise,
    dbscan_points,
    density_mask,
    relabel_compact,
    voxel_cluster_points,
    voxel_clusters,
)


def test_pack_unpack_roundtrip_and_negative_indices():
    idx = np.array([[0, 0, 0], [-5, 3, 7], [1000, -1000, 12], [-1, -1, -1]])
    assert np.array_equal(voxel.unpack(voxel.pack(idx)), idx)
    keys = voxel.voxel_keys(np.array([[-0.1, 0.1, 0.0], [0.25, -0.25, 0.45]]), 0.2)
    assert np.array_equal(voxel.unpack(keys), [[-1, 0, 0], [1, -2, 2]])


def test_neighbour_pairs_of_a_full_block():
    idx = np.array([(x, y, z) for x in range(3) for y in range(3) for z in range(3)])
    keys = np.sort(voxel.pack(idx))
    first, second = voxel.neighbour_pairs(keys)
    # 26-adjacency edges in a 3x3x3 grid: 3*(2*3*3) face + 6*(2*2*3) edge + 4*(2*2*2) corner.
    assert first.size == 54 + 72 + 32
    sums = voxel.neighbourhood_sums(keys, np.ones(keys.size))
    centre = np.searchsorted(keys, voxel.pack(np.array([[1, 1, 1]]))[0])
    assert sums[centre] == 27
    assert sums.min() == 8  # a corner sees itself and 7 neighbours


def test_lookup_finds_present_and_flags_absent():
    keys = np.array([3, 7, 11], dtype=np.int64)
    assert voxel.lookup(keys, np.array([7, 8, 3, 12])).tolist() == [1, -1, 0, -1]
    assert voxel.lookup(np.empty(0, np.int64), np.array([1])).tolist() == [-1]


def test_voxel_clusters_core_and_border():
    # A line of 5 voxels with 4 points each, plus one lonely voxel far away.
    idx = np.array([[i, 0, 0] for i in range(5)] + [[50, 50, 50]])
    keys = voxel.pack(idx)
    order = np.argsort(keys)
    weights = np.array([4, 4, 4, 4, 4, 1], dtype=float)[order]
    labels = voxel_clusters(keys[order], weights, min_samples=10)
    by_index = np.empty(6, dtype=np.int64)
    by_index[order] = labels
    # Ends see 8 points (not core) but touch a core voxel: border members of one cluster.
    assert len(set(by_index[:5].tolist())) == 1 and by_index[0] >= 0
    assert by_index[5] == -1


def blobs(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    parts = [
        rng.normal([0, 0, 10], 0.4, (300, 3)),
        rng.normal([12, 0, 10], 0.4, (200, 3)),
        rng.normal([0, 15, 20], 0.6, (400, 3)),
        rng.uniform(-60, 60, (60, 3)),
    ]
    return np.vstack(parts)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_voxel_clusterer_agrees_with_dbscan_on_small_clouds(seed):
    xyz = blobs(seed)
    lv = voxel_cluster_points(xyz, cluster_voxel=1.0, min_samples=10)
    ld = dbscan_points(xyz, eps=2.0, min_samples=10)
    assert len(set(lv[lv >= 0].tolist())) == 3
    assert len(set(ld[ld >= 0].tolist())) == 3
    assert adjusted_rand_score(lv, ld) > 0.95


def test_clusterers_on_empty_input():
    assert voxel_cluster_points(np.empty((0, 3)), 1.0, 10).shape == (0,)
    assert dbscan_points(np.empty((0, 3)), 2.0, 10).shape == (0,)
    assert density_mask(np.empty((0, 3)), 2.0, 3).shape == (0,)


def test_density_mask_drops_isolated_noise_keeps_consistent_track():
    rng = np.random.default_rng(3)
    track = np.column_stack([np.linspace(0, 20, 60), np.zeros(60), np.full(60, 30.0)])
    noise = rng.uniform(-300, 300, (200, 3))
    keep = density_mask(np.vstack([track, noise]), 2.0, 3)
    assert keep[:60].all()
    assert keep[60:].mean() < 0.05


def test_relabel_compact():
    labels, k = relabel_compact(np.array([5, -1, 5, 9, 2]))
    assert k == 3 and labels.tolist() == [1, -1, 1, 2, 0]


def test_merge_colocated_compact_joins_pieces_at_one_spot_only():
    from clusterfilter_ros.core.clustering import merge_colocated_compact

    rng = np.random.default_rng(5)
    hover_a = rng.normal([0, 0, 20], 0.2, (6, 3))  # two pieces of a hover, same spot
    hover_b = rng.normal([0, 0, 20], 0.2, (6, 3))
    far = rng.normal([30, 0, 20], 0.2, (6, 3))  # compact, elsewhere
    wide = np.column_stack([np.linspace(-20, -5, 6), np.zeros(6), np.full(6, 20.0)])
    xyz = np.vstack([hover_a, hover_b, far, wide])
    labels = np.repeat([0, 1, 2, 3], 6)
    merged, k = merge_colocated_compact(labels, xyz, 3.0)
    assert k == 3
    assert len(set(merged[:12].tolist())) == 1
    assert len({merged[0], merged[12], merged[18]}) == 3


def _unique_cases():
    rng = np.random.default_rng(11)
    near = rng.normal(0.0, 20.0, (10_000, 3))  # a frame's worth of points: a dense table
    far = rng.normal(0.0, 2_000.0, (10_000, 3))  # too spread out for one: numpy's sort
    t = rng.uniform(0.0, 10.0, 10_000)
    return [
        ("labels", rng.integers(0, 400, 5000), None, True),
        ("negative int32", rng.integers(-50, 50, 3000).astype(np.int32), None, True),
        ("voxel keys", voxel.voxel_keys(near, 1.5), voxel.VOXEL_FIELDS, True),
        (
            "space-time keys",
            voxel.spacetime_keys(0.4 * near, t, 2.0, 0.5),
            voxel.SPACETIME_FIELDS,
            True,
        ),
        ("spread voxel keys", voxel.voxel_keys(far, 0.2), voxel.VOXEL_FIELDS, False),
        ("few voxel keys", voxel.voxel_keys(near[:50], 1.5), voxel.VOXEL_FIELDS, False),
        ("wide ints", rng.integers(0, 1 << 40, 2000), None, False),
        ("one", np.array([7]), None, True),
    ]


def test_noise_joins_a_compact_cluster_at_its_spot_only():
    # Cluster 0: a hovering drone's burst of returns within 0.3 m; cluster 1: a bird's
    # leg 8 m long. Noise: two lone returns of the drone 0.1 m from its cluster, one
    # 0.5 m away, one on the bird's path, and an empty label set.
    rng = np.random.default_rng(1)
    drone = np.array([20.0, 5.0, 10.0]) + rng.uniform(-0.15, 0.15, (6, 3))
    bird = np.column_stack([np.linspace(0, 8, 10), np.full(10, 30.0), np.full(10, 12.0)])
    lone = np.array([[20.1, 5.0, 10.0], [20.0, 5.1, 9.95], [20.0, 5.0, 10.65], [4.0, 30.0, 12.1]])
    xyz = np.vstack([drone, bird, lone])
    labels = np.r_[np.zeros(6, int), np.ones(10, int), np.full(4, -1)]
    out = absorb_colocated_noise(labels, xyz, max_extent=0.6, radius=0.3)
    assert out[:16].tolist() == labels[:16].tolist()  # members keep their labels
    assert out[16:].tolist() == [0, 0, -1, -1]
    assert absorb_colocated_noise(labels[:16], xyz[:16], 0.6, 0.3).tolist() == labels[:16].tolist()
    nothing = np.full(3, -1)
    assert absorb_colocated_noise(nothing, xyz[:3], 0.6, 0.3).tolist() == [-1, -1, -1]
    empty = absorb_colocated_noise(np.empty(0, int), np.empty((0, 3)), 0.6, 0.3)
    assert empty.size == 0


def test_with_stamps_noise_joins_the_compact_cluster_there_at_its_time():
    # Deviation 130: a hover split in two by a passing bird leaves two compact clusters at
    # one spot, 0 over 0-3 s and 1 over 8-12 s. A lone return at 9.5 s lies nearest to
    # one of cluster 0's returns but joins cluster 1; one at 5.5 s, more than max_gap from
    # both spans, stays noise; one at 3.5 s joins cluster 0.
    spot = np.array([20.0, 5.0, 10.0])
    first = spot + np.array([[0.05, 0.0, 0.0], [0.1, 0.0, 0.0], [0.15, 0.0, 0.0]])
    second = spot + np.array([[-0.15, 0.0, 0.0], [-0.1, 0.0, 0.0], [-0.05, 0.0, 0.0]])
    lone = spot + np.array([[0.08, 0.0, 0.01], [0.0, 0.0, 0.0], [0.12, 0.0, 0.01]])
    xyz = np.vstack([first, second, lone])
    t = np.array([0.0, 1.5, 3.0, 8.0, 10.0, 12.0, 9.5, 5.5, 3.5])
    labels = np.r_[np.zeros(3, int), np.ones(3, int), np.full(3, -1)]
    out = absorb_colocated_noise(labels, xyz, 0.6, 0.3, t=t, max_gap=2.0)
    assert out.tolist() == [0, 0, 0, 1, 1, 1, 1, -1, 0]
    # Without stamps each joins the cluster of its nearest return.
    assert absorb_colocated_noise(labels, xyz, 0.6, 0.3)[6:].tolist() == [0, 0, 0]


@pytest.mark.parametrize("case", _unique_cases(), ids=lambda c: c[0])
def test_unique_ints_equals_numpy_unique(case):
    _, values, fields, dense = case
    # The case exercises the path it is named for.
    assert (voxel._dense_code(values, values.size, fields)[0] is not None) is dense
    for inverse in (False, True):
        for counts in (False, True):
            want = np.unique(values, return_inverse=inverse, return_counts=counts)
            got = voxel.unique_ints(
                values, return_inverse=inverse, return_counts=counts, fields=fields
            )
            want, got = (want, got) if inverse or counts else ((want,), (got,))
            assert len(got) == len(want)
            for g, w in zip(got, want, strict=True):
                assert g.dtype == w.dtype
                assert np.array_equal(g.reshape(-1), w.reshape(-1))


def test_unique_ints_of_nothing():
    uk, inv, cnt = voxel.unique_ints(
        np.empty(0, np.int64), return_inverse=True, return_counts=True, fields=voxel.VOXEL_FIELDS
    )
    assert uk.size == inv.size == cnt.size == 0


@pytest.mark.parametrize("spread, n", [(20.0, 10_000), (2_000.0, 10_000), (20.0, 300), (1.0, 0)])
def test_unique_voxel_keys_equal_voxel_keys_and_numpy_unique(spread, n):
    xyz = np.random.default_rng(5).normal(0.0, spread, (n, 3)).astype(np.float32)
    keys, uk, inverse, counts = voxel.unique_voxel_keys(xyz, 1.5, return_counts=True)
    want_keys = voxel.voxel_keys(xyz, 1.5)
    want = np.unique(want_keys, return_inverse=True, return_counts=True)
    assert np.array_equal(keys, want_keys)
    for got, ref in zip((uk, inverse, counts), want, strict=True):
        assert got.dtype == ref.dtype and np.array_equal(got.reshape(-1), ref.reshape(-1))
    assert len(voxel.unique_voxel_keys(xyz, 1.5)) == 3


def test_unique_ints_tables_are_reused_cleanly_across_calls_and_threads():
    from concurrent.futures import ThreadPoolExecutor

    rng = np.random.default_rng(8)
    inputs = [rng.integers(0, high, size) for high, size in ((50_000, 9_000), (40, 500))] * 3

    def check(values):
        got = voxel.unique_ints(values, return_inverse=True, return_counts=True)
        want = np.unique(values, return_inverse=True, return_counts=True)
        return all(np.array_equal(g, w) for g, w in zip(got, want, strict=True))

    assert all(check(v) for v in inputs)  # a big table, then a small one, and again
    with ThreadPoolExecutor(4) as pool:
        assert all(pool.map(check, inputs * 4))


def test_unique_ints_recovers_from_a_call_interrupted_mid_table():
    values = np.random.default_rng(9).integers(0, 3000, 2000)
    voxel.unique_ints(values)  # the thread's tables exist
    voxel._TABLES.seen[:50] = True  # flags left set, as by a Ctrl-C between mark and clear
    voxel._TABLES.dirty = True
    assert np.array_equal(voxel.unique_ints(values), np.unique(values))
    assert not voxel._TABLES.dirty and not voxel._TABLES.seen.any()
