"""Per-group reductions and orderings over point arrays."""

from __future__ import annotations

import numpy as np

#: numpy sorts integers of at most 16 bits with a radix sort when asked for a stable sort.
_RADIX_LIMIT = 1 << 16


def stable_order(ids: np.ndarray) -> np.ndarray:
    """``np.argsort(ids, kind="stable")`` for integer ``ids``, in linear time when they lie
    in 0..65535 (group ids usually do): numpy radix-sorts 16-bit integers."""
    ids = np.asarray(ids).reshape(-1)
    if ids.size and ids.dtype.kind in "iu":
        lo, hi = int(ids.min()), int(ids.max())
        if lo >= 0 and hi < _RADIX_LIMIT:
            return np.argsort(ids.astype(np.uint16), kind="stable")
    return np.argsort(ids, kind="stable")


def lex_order(minor: np.ndarray, major: np.ndarray) -> np.ndarray:
    """``np.lexsort((minor, major))`` (by integer ``major``, then ``minor``, then position):
    a stable sort by ``minor`` followed by :func:`stable_order` of ``major``."""
    order = np.argsort(np.asarray(minor).reshape(-1), kind="stable")
    return order[stable_order(np.asarray(major).reshape(-1)[order])]


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
        order = stable_order(ids)
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
