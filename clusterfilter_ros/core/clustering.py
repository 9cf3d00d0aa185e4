"""Density clustering of accumulated points (paper 3.1 denoise and 3.2 global clusterer).

Two clusterers give the same kind of answer, an (N,) int64 label per point with -1 for
noise:

- :func:`voxel_cluster_points`: points are binned into voxels of edge ``cluster_voxel``;
  a voxel is *core* when its 3x3x3 neighbourhood holds at least ``min_samples`` points
  (DBSCAN's core criterion with the neighbourhood cube in place of the eps ball), core
  voxels that touch (26-neighbourhood) form one cluster, and non-core voxels touching a
  core voxel join its cluster as border voxels. Sorted keys + ``searchsorted`` over the
  13 half-neighbour offsets + ``scipy.sparse.csgraph.connected_components``: about
  linear in the number of occupied voxels.
- :func:`dbscan_points`: scikit-learn DBSCAN (the paper's choice); exact but slow and
  memory-hungry on large accumulations.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from clusterfilter_ros.core import voxel
from clusterfilter_ros.core.grouping import group_bounds


def voxel_clusters(
    sorted_keys: np.ndarray,
    weights: np.ndarray,
    min_samples: float,
    offset_keys: np.ndarray | None = None,
) -> np.ndarray:
    """Cluster label per occupied voxel (sorted unique ``sorted_keys``), -1 for noise.

    ``weights`` are the points per voxel; ``offset_keys`` the forward half-neighbourhood
    (default 3D 26-neighbourhood). Labels are 0..K-1.
    """
    n = sorted_keys.shape[0]
    labels = np.full(n, -1, dtype=np.int64)
    if n == 0:
        return labels
    first, second = voxel.neighbour_pairs(sorted_keys, offset_keys)
    density = voxel.neighbourhood_sums(sorted_keys, weights, (first, second))
    core = density >= float(min_samples)
    if not core.any():
        return labels
    core_idx = np.nonzero(core)[0]
    core_pos = np.full(n, -1, dtype=np.int64)
    core_pos[core_idx] = np.arange(core_idx.size)
    both = core[first] & core[second]
    m = core_idx.size
    graph = coo_matrix(
        (np.ones(int(both.sum()), dtype=np.int8), (core_pos[first[both]], core_pos[second[both]])),
        shape=(m, m),
    ).tocsr()
    _, comp = connected_components(graph, directed=False)
    labels[core_idx] = comp
    # Border voxels: non-core voxels adjacent to a core voxel take that core's label.
    a_core_b_not = core[first] & ~core[second]
    labels[second[a_core_b_not]] = labels[first[a_core_b_not]]
    b_core_a_not = core[second] & ~core[first]
    labels[first[b_core_a_not]] = labels[second[b_core_a_not]]
    return labels


def voxel_cluster_points(
    xyz: np.ndarray, cluster_voxel: float, min_samples: int, weights: np.ndarray | None = None
) -> np.ndarray:
    """(N,) cluster label per point (-1 noise) by voxel connected components."""
    xyz = np.asarray(xyz).reshape(-1, 3)
    if xyz.shape[0] == 0:
        return np.empty(0, dtype=np.int64)
    _, ukeys, inverse = voxel.unique_voxel_keys(xyz, cluster_voxel)
    w = np.ones(xyz.shape[0]) if weights is None else np.asarray(weights, dtype=np.float64)
    per_voxel = np.bincount(inverse.reshape(-1), weights=w, minlength=ukeys.size)
    return voxel_clusters(ukeys, per_voxel, min_samples)[inverse.reshape(-1)]


def spacetime_cluster_points(
    xyz: np.ndarray, t: np.ndarray, cluster_voxel: float, time_bin: float, min_samples: int
) -> np.ndarray:
    """(N,) cluster label per point (-1 noise) by connected components of (x, y, z, t)
    voxels (80-neighbourhood): points link only if close in space AND in time, so a
    sparse drone track does not merge with sparse static remnants it passes at another
    time, and remnants hit once every few seconds do not chain up at all."""
    xyz = np.asarray(xyz).reshape(-1, 3)
    if xyz.shape[0] == 0:
        return np.empty(0, dtype=np.int64)
    keys = voxel.spacetime_keys(xyz, t, cluster_voxel, time_bin)
    ukeys, inverse, counts = voxel.unique_ints(
        keys, return_inverse=True, return_counts=True, fields=voxel.SPACETIME_FIELDS
    )
    offsets = np.array([voxel.spacetime_offset_key(o) for o in voxel.HALF_OFFSETS_4D])
    return voxel_clusters(ukeys, counts, min_samples, offsets)[inverse.reshape(-1)]


def dbscan_points(xyz: np.ndarray, eps: float, min_samples: int) -> np.ndarray:
    """(N,) cluster label per point (-1 noise) from scikit-learn DBSCAN."""
    from sklearn.cluster import DBSCAN

    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if xyz.shape[0] == 0:
        return np.empty(0, dtype=np.int64)
    return DBSCAN(eps=eps, min_samples=min_samples).fit_predict(xyz).astype(np.int64)


def density_mask(xyz: np.ndarray, denoise_voxel: float, min_points: int) -> np.ndarray:
    """(N,) bool: points whose 3x3x3 voxel neighbourhood holds >= ``min_points`` points.

    The paper's Avia denoise (3.1): over superimposed frames, sensor noise is the
    sparsest thing in the cloud, while a drone's returns stay close to each other.
    """
    xyz = np.asarray(xyz).reshape(-1, 3)
    if xyz.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    _, ukeys, inverse, counts = voxel.unique_voxel_keys(xyz, denoise_voxel, return_counts=True)
    density = voxel.neighbourhood_sums(ukeys, counts)
    return density[inverse.reshape(-1)] >= min_points


def relabel_compact(labels: np.ndarray) -> tuple[np.ndarray, int]:
    """Renumber non-negative labels to 0..K-1 (order of first appearance kept by value)."""
    labels = np.asarray(labels, dtype=np.int64)
    valid = labels >= 0
    if not valid.any():
        return labels.copy(), 0
    uniq, inv = voxel.unique_ints(labels[valid], return_inverse=True)
    out = np.full(labels.shape, -1, dtype=np.int64)
    out[valid] = inv.reshape(-1)
    return out, int(uniq.size)


def merge_colocated_compact(
    labels: np.ndarray, xyz: np.ndarray, max_extent: float
) -> tuple[np.ndarray, int]:
    """Merge clusters that are each compact (bounding box <= ``max_extent``) and lie at
    the same place (centroids in touching ``max_extent`` voxels).

    Space-time clustering cuts a hovering drone seen once a second into many short
    clusters at one spot; this joins them again. Returns compact labels and their count.
    """
    labels, k = relabel_compact(labels)
    if k < 2:
        return labels, k
    keep = labels >= 0
    lab = labels[keep]
    pts = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)[keep]
    counts = np.bincount(lab, minlength=k).astype(np.float64)
    centroid = np.stack([np.bincount(lab, weights=pts[:, a], minlength=k) for a in range(3)], 1)
    centroid /= counts[:, None]
    ((lo, hi),) = group_bounds(lab, k, pts)
    compact = np.nonzero((hi - lo).max(axis=1) <= max_extent)[0]
    if compact.size < 2:
        return labels, k
    keys = voxel.voxel_keys(centroid[compact], max_extent)
    uk, inv = voxel.unique_ints(keys, return_inverse=True, fields=voxel.VOXEL_FIELDS)
    group = voxel_clusters(uk, np.ones(uk.size), 0.0)[inv.reshape(-1)]
    n_groups = int(group.max()) + 1
    (g_lo, _), (_, g_hi) = group_bounds(group, n_groups, lo[compact], hi[compact])
    small = (g_hi - g_lo).max(axis=1) <= max_extent  # the union must stay compact too
    target = np.arange(k)
    # Every compact cluster of a small group takes the group's smallest label.
    first = np.full(n_groups, k)
    np.minimum.at(first, group, compact)
    merge = small[group]
    target[compact[merge]] = first[group[merge]]
    out = labels.copy()
    out[keep] = target[lab]
    return relabel_compact(out)


#: Nearest compact-cluster returns :func:`absorb_colocated_noise` weighs per noise point
#: when it checks their clusters' time spans.
_ABSORB_NEIGHBOURS = 8


def absorb_colocated_noise(
    labels: np.ndarray,
    xyz: np.ndarray,
    max_extent: float,
    radius: float,
    t: np.ndarray | None = None,
    max_gap: float | None = None,
) -> np.ndarray:
    """Labels with each noise point within ``radius`` of a point of a compact cluster
    (bounding box <= ``max_extent``) given that cluster's label (the nearest point's).

    Space-time clustering leaves a hovering drone seen once a second partly as noise:
    a return with no neighbour within a time bin is not core; at the same spot as the
    drone's cluster it is the drone's too. Moving objects and extended structure are
    not compact, so their clusters take nothing.

    With stamps ``t`` and ``max_gap``, a noise point joins only a cluster whose time
    span, widened by ``max_gap`` on both sides, holds its stamp (the nearest such
    point's): over a whole sequence a hover split in two by a passing bird leaves two
    compact clusters at one spot, and a lone return between them belongs to the one
    that was there then."""
    labels = np.asarray(labels, dtype=np.int64)
    noise = np.flatnonzero(labels < 0)
    k = int(labels.max()) + 1 if labels.size else 0
    if noise.size == 0 or k == 0:
        return labels
    pts = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    member = np.flatnonzero(labels >= 0)
    ((lo, hi),) = group_bounds(labels[member], k, pts[member])
    compact = (hi - lo).max(axis=1) <= max_extent
    inside = member[compact[labels[member]]]
    if inside.size == 0:
        return labels
    timed = t is not None and max_gap is not None
    n_near = min(_ABSORB_NEIGHBOURS, inside.size) if timed else 1
    dist, nearest = cKDTree(pts[inside]).query(pts[noise], k=n_near, distance_upper_bound=radius)
    dist, nearest = dist.reshape(noise.size, n_near), nearest.reshape(noise.size, n_near)
    ok = np.isfinite(dist)  # sorted by distance; misses are inf
    c = labels[inside[np.where(ok, nearest, 0)]]
    if timed:
        stamps = np.asarray(t, dtype=np.float64).reshape(-1)
        ((first, last),) = group_bounds(labels[member], k, stamps[member])
        ts = stamps[noise][:, None]
        ok &= (first[c] - max_gap <= ts) & (ts <= last[c] + max_gap)
    hit = ok.any(axis=1)
    if not hit.any():
        return labels
    out = labels.copy()
    out[noise[hit]] = c[hit, np.argmax(ok[hit], axis=1)]
    return out
