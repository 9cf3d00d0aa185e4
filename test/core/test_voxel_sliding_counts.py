"""SlidingVoxelCounts (the streaming Avia denoise window) equals a recount from scratch."""

import numpy as np

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


def test_neighbourhood_at_least_equals_the_count_threshold():
    rng = np.random.default_rng(4)
    window = voxel.SlidingVoxelCounts()
    for k in range(10):
        window.add(0.1 * k, voxel.voxel_keys(rng.normal(0.0, 2.0, size=(200, 3)), 1.0))
    queries = np.unique(voxel.voxel_keys(rng.normal(0.0, 4.0, size=(300, 3)), 1.0))
    counts = window.neighbourhood_counts(queries)
    for n in (1, 3, 10, 50):
        assert np.array_equal(window.neighbourhood_at_least(queries, n), counts >= n)
    assert not voxel.SlidingVoxelCounts().neighbourhood_at_least(queries, 1).any()
