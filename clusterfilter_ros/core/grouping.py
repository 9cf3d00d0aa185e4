"""Per-group reductions over point arrays."""

from __future__ import annotations

import numpy as np


def group_bounds(
    ids: np.ndarray, k: int, *values: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per group 0..k-1, the minimum and maximum of each of ``values`` ((N,) or (N, D)
    arrays, one row per id): a list of (lo, hi) pairs of float64 arrays of shape (k,) or
    (k, D), +inf / -inf for groups without members.

    One stable sort of ``ids`` serves every array, and the extremes are taken over
    contiguous runs (``reduceat``): several times faster than ``np.minimum.at`` /
    ``np.maximum.at`` per array, with the same (exact) results.
    """
    ids = np.asarray(ids, dtype=np.int64).reshape(-1)
    out = []
    order = starts = first = None
    if ids.size:
        order = np.argsort(ids, kind="stable")
        sorted_ids = ids[order]
        starts = np.flatnonzero(np.r_[True, sorted_ids[1:] != sorted_ids[:-1]])
        first = sorted_ids[starts]
    for v in values:
        v = np.asarray(v)
        lo = np.full((k, *v.shape[1:]), np.inf)
        hi = np.full((k, *v.shape[1:]), -np.inf)
        if order is not None:
            run = v[order]
            lo[first] = np.minimum.reduceat(run, starts, axis=0)
            hi[first] = np.maximum.reduceat(run, starts, axis=0)
        out.append((lo, hi))
    return out
