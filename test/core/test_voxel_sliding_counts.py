"""Voxel primitives: indices of points, and SlidingVoxelCounts (the streaming Avia denoise
window), which must equal a recount from scratch."""

import numpy as np
import pytest

from clusterfilter_ros.core import voxel


def brute_neighbourhood(window_keys: np.ndarray, queries: np.ndarray) -> np.ndarray:
    uk, counts = np.unique(window_keys, return_counts=True)
    dens = voxel.neighbourhood_sums(uk, counts)
    idx = voxel.lookup(uk, queries)
    out = np.zeros(queries.shape, np.int64)
    # a query voxel without points of its own: sum its neighbours directly
    for i, q in enumerate(queries):
        if idx[i] >= 0:
            out[i] = int(dens[idx[i]])
        else:
            nbr = [0] + [s * voxel.offset_key(o) for o in voxel.HALF_OFFSETS for s in (1, -1)]
            hits = voxel.lookup(uk, q + np.array(nbr, np.int64))
            out[i] = int(counts[hits[hits >= 0]].sum())
    return out


def test_incremental_window_matches_recount():
    rng = np.random.default_rng(3)
    window = voxel.SlidingVoxelCounts()
    frames = []
    for k in range(40):
        stamp = 0.1 * k
        xyz = rng.normal(0.0, 3.0, size=(rng.integers(0, 300), 3))
        keys = voxel.voxel_keys(xyz, 1.0)
        window.evict_before(stamp - 1.0)
        window.add(stamp, keys)
        frames = [(t, kk) for t, kk in frames if t >= stamp - 1.0] + [(stamp, keys)]
        all_keys = np.concatenate([kk for _, kk in frames])
        uk, counts = np.unique(all_keys, return_counts=True)
        assert np.array_equal(window.keys, uk) and np.array_equal(window.counts, counts)
        queries = np.unique(
            np.concatenate([keys[:20], voxel.voxel_keys(rng.normal(0, 6, (5, 3)), 1.0)])
        )
        assert np.array_equal(
            window.neighbourhood_counts(queries), brute_neighbourhood(all_keys, queries)
        )
    assert len(window) == 11  # stamps 2.9 .. 3.9 (1 s window at 10 Hz)


@pytest.mark.parametrize("n_queries", [300, 5000])  # all at once, and one offset at a time
def test_neighbourhood_at_least_equals_the_count_threshold(n_queries):
    rng = np.random.default_rng(4)
    window = voxel.SlidingVoxelCounts()
    for k in range(10):
        window.add(0.1 * k, voxel.voxel_keys(rng.normal(0.0, 2.0, size=(200, 3)), 1.0))
    queries = np.unique(voxel.voxel_keys(rng.normal(0.0, 8.0, size=(n_queries, 3)), 1.0))
    assert (queries.size > voxel._FEW_QUERIES) == (n_queries > 1000)
    counts = window.neighbourhood_counts(queries)
    for n in (1, 3, 10, 50):
        assert np.array_equal(window.neighbourhood_at_least(queries, n), counts >= n)
    assert not voxel.SlidingVoxelCounts().neighbourhood_at_least(queries, 1).any()


def test_voxel_indices_floor_in_float64_and_clip():
    rng = np.random.default_rng(3)
    xyz = rng.uniform(-50.0, 50.0, (2000, 3)).astype(np.float32)
    xyz[:10] = np.float32(0.5) * rng.integers(-20, 20, (10, 3))  # exactly on voxel edges
    for size in (0.2, 0.5, 1.5):
        expected = np.floor(xyz.astype(np.float64) / size).astype(np.int64)
        np.testing.assert_array_equal(voxel.voxel_indices(xyz, size), expected)
        np.testing.assert_array_equal(voxel.voxel_indices(xyz.tolist(), size), expected)
    far = np.array([[1e30, -1e30, 0.0]])
    assert voxel.voxel_indices(far, 1.0).tolist() == [[voxel._LIMIT, -voxel._LIMIT, 0]]
    assert voxel.voxel_indices(np.empty((0, 3), np.float32), 1.0).shape == (0, 3)
    # Space-time keys of the same cells are equal, of neighbouring cells different.
    keys = voxel.spacetime_keys(
        np.array([[0.1, 0.1, 0.1], [0.4, 0.2, 0.3], [1.1, 0.0, 0.0]]), np.zeros(3), 1.0, 0.5
    )
    assert keys[0] == keys[1] != keys[2]
