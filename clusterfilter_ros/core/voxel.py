"""Vectorised voxel-grid primitives: packed int64 voxel keys and their neighbourhoods.

A voxel key packs the integer voxel indices (ix, iy, iz), each offset by 2**20 into 21
bits, into one int64, so that a neighbour at (dx, dy, dz) has key ``key + offset_key``
and sorted key arrays can be searched with :func:`numpy.searchsorted`.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Iterable

import numpy as np

_BITS = 21
_OFFSET = 1 << (_BITS - 1)
_MASK = (1 << _BITS) - 1
#: Voxel indices are clipped to this range so that neighbour keys never overflow a field.
_LIMIT = _OFFSET - 2

#: The 13 "forward" neighbour offsets of the 26-neighbourhood (each pair counted once).
HALF_OFFSETS = np.array(
    [
        (dx, dy, dz)
        for dx in (-1, 0, 1)
        for dy in (-1, 0, 1)
        for dz in (-1, 0, 1)
        if (dx, dy, dz) > (0, 0, 0)
    ],
    dtype=np.int64,
)


def voxel_indices(xyz: np.ndarray, size: float) -> np.ndarray:
    """(N, 3) int64 voxel indices of points for voxels of edge ``size`` metres."""
    return _floor_indices(xyz, size, _LIMIT)


def _floor_indices(xyz: np.ndarray, size: float, limit: int) -> np.ndarray:
    """floor(xyz / size) in float64, clipped to +-limit, as int64; one float64 buffer
    (fresh temporaries of a frame's size cost page faults on every call)."""
    scaled = np.divide(np.asarray(xyz), float(size), dtype=np.float64)
    np.floor(scaled, out=scaled)
    np.clip(scaled, -limit, limit, out=scaled)
    return scaled.astype(np.int64)


def pack(idx: np.ndarray) -> np.ndarray:
    """Pack (N, 3) int64 voxel indices into (N,) int64 keys."""
    idx = np.asarray(idx, dtype=np.int64).reshape(-1, 3) + _OFFSET
    return (idx[:, 0] << (2 * _BITS)) | (idx[:, 1] << _BITS) | idx[:, 2]


def unpack(keys: np.ndarray) -> np.ndarray:
    """Inverse of :func:`pack`: (N,) keys to (N, 3) int64 voxel indices."""
    keys = np.asarray(keys, dtype=np.int64)
    out = np.empty((keys.shape[0], 3), dtype=np.int64)
    out[:, 0] = (keys >> (2 * _BITS)) & _MASK
    out[:, 1] = (keys >> _BITS) & _MASK
    out[:, 2] = keys & _MASK
    return out - _OFFSET


def voxel_keys(xyz: np.ndarray, size: float) -> np.ndarray:
    """(N,) int64 keys of the voxels of edge ``size`` containing each point."""
    return pack(voxel_indices(xyz, size))


def offset_key(offset: np.ndarray) -> int:
    """Key difference between a voxel and its neighbour at integer ``offset``."""
    dx, dy, dz = (int(v) for v in offset)
    return (dx << (2 * _BITS)) + (dy << _BITS) + dz


#: Key offsets of a voxel and its 26 neighbours (itself included).
NEIGHBOURHOOD = np.array(
    [offset_key((dx, dy, dz)) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)],
    dtype=np.int64,
)


# --- space-time keys: 15 bits per spatial axis, 18 bits of time bins -------------------
_S_BITS = 15
_S_OFFSET = 1 << (_S_BITS - 1)
_T_BITS = 18
_T_OFFSET = 1 << (_T_BITS - 1)

#: The 40 "forward" offsets of the 80-neighbourhood in (x, y, z, t) voxels.
HALF_OFFSETS_4D = np.array(
    [
        (dx, dy, dz, dt)
        for dx in (-1, 0, 1)
        for dy in (-1, 0, 1)
        for dz in (-1, 0, 1)
        for dt in (-1, 0, 1)
        if (dx, dy, dz, dt) > (0, 0, 0, 0)
    ],
    dtype=np.int64,
)


def spacetime_keys(xyz: np.ndarray, t: np.ndarray, size: float, time_bin: float) -> np.ndarray:
    """(N,) int64 keys of (x, y, z, t) voxels: edge ``size`` m, ``time_bin`` s.

    Time is taken relative to the earliest stamp, so any recording up to 2**17 bins
    long (36 h at 0.5 s) fits; spatial indices are clipped to +-2**14 voxels.
    """
    idx = _floor_indices(xyz, size, _S_OFFSET - 2)
    t = np.asarray(t, dtype=np.float64)
    rel = np.floor((t - (t.min() if t.size else 0.0)) / float(time_bin))
    it = np.clip(rel, 0, (1 << _T_BITS) - 2).astype(np.int64)
    idx = idx + _S_OFFSET
    return (
        (idx[:, 0] << (2 * _S_BITS + _T_BITS))
        | (idx[:, 1] << (_S_BITS + _T_BITS))
        | (idx[:, 2] << _T_BITS)
        | (it + 1)
    )


def spacetime_offset_key(offset: np.ndarray) -> int:
    dx, dy, dz, dt = (int(v) for v in offset)
    return (dx << (2 * _S_BITS + _T_BITS)) + (dy << (_S_BITS + _T_BITS)) + (dz << _T_BITS) + dt


def neighbour_pairs(
    sorted_keys: np.ndarray, offset_keys: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """All adjacent pairs (i, j) of a sorted unique key array, each pair once.

    ``offset_keys``: key differences of the forward half-neighbourhood (default: the
    13 of the 3D 26-neighbourhood).
    """
    n = sorted_keys.shape[0]
    firsts, seconds = [], []
    if n == 0:
        empty = np.empty(0, dtype=np.int64)
        return empty, empty
    if offset_keys is None:
        offset_keys = [offset_key(off) for off in HALF_OFFSETS]
    for off in offset_keys:
        target = sorted_keys + int(off)
        pos = np.searchsorted(sorted_keys, target)
        pos_c = np.minimum(pos, n - 1)
        hit = sorted_keys[pos_c] == target
        if hit.any():
            firsts.append(np.nonzero(hit)[0])
            seconds.append(pos_c[hit])
    if not firsts:
        empty = np.empty(0, dtype=np.int64)
        return empty, empty
    return np.concatenate(firsts), np.concatenate(seconds)


def neighbourhood_sums(
    sorted_keys: np.ndarray,
    weights: np.ndarray,
    pairs: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Sum of ``weights`` over each voxel's neighbourhood (itself included; default 3x3x3)."""
    first, second = neighbour_pairs(sorted_keys) if pairs is None else pairs
    w = np.asarray(weights, dtype=np.float64)
    total = w.copy()
    if first.size:
        total += np.bincount(first, weights=w[second], minlength=w.size)
        total += np.bincount(second, weights=w[first], minlength=w.size)
    return total


#: Bit widths of the fields of a :func:`pack` key and of a :func:`spacetime_keys` key,
#: most significant first (for :func:`unique_ints`).
VOXEL_FIELDS = (_BITS, _BITS, _BITS)
SPACETIME_FIELDS = (_S_BITS, _S_BITS, _S_BITS, _T_BITS)

#: A dense table replaces the sort while it has at most _DENSE_CELLS_PER_VALUE cells per
#: value (plus a floor); over packed fields, whose split costs a fixed ~0.2 ms, only from
#: _DENSE_FIELDS_MIN_VALUES values on and up to _DENSE_FIELDS_CELLS_PER_VALUE cells per
#: value. Measured on frames of 4k-24k points: scanning a table cell costs about 0.2 ns,
#: sorting a value 60-90 ns. The tables are kept per thread and reused (fresh tables of a
#: frame's size cost page faults on every call), at most _DENSE_MAX_CELLS cells: 4 MB of
#: flags and 16 MB of ranks.
_DENSE_CELLS_PER_VALUE = 48
_DENSE_MIN_CELLS = 1 << 12
_DENSE_FIELDS_MIN_VALUES = 1 << 13
#: Above this many values the keys are a whole scene's (offline): a few far returns make
#: its box too large for a table (a 20 s scene spans 9M cells of 2 m), so no attempt.
_DENSE_FIELDS_MAX_VALUES = 1 << 18
_DENSE_FIELDS_CELLS_PER_VALUE = 256
_DENSE_MAX_CELLS = 1 << 22
_TABLES = threading.local()


def _table_unique(code: np.ndarray, cells: int, ranks: bool) -> tuple[np.ndarray, np.ndarray]:
    """(the distinct values of ``code`` (0..cells-1) in ascending order, each entry's rank
    among them as intp, or an empty array unless ``ranks``), from this thread's tables."""
    seen = getattr(_TABLES, "seen", None)
    # "dirty": a call interrupted (Ctrl-C, MemoryError) between marking and clearing left
    # flags set; the next call then starts from a fresh table instead of trusting it.
    if seen is None or seen.size < cells or getattr(_TABLES, "dirty", False):
        old = 0 if seen is None else seen.size
        size = min(max(cells, 2 * old if old < cells else old), _DENSE_MAX_CELLS)
        _TABLES.seen = seen = np.zeros(size, dtype=bool)
        _TABLES.rank = np.empty(size, dtype=np.int32)  # only cells in use are read
    _TABLES.dirty = True
    seen[code] = True
    present = np.flatnonzero(seen[:cells])
    seen[code] = False  # all False again for the next call
    _TABLES.dirty = False
    if not ranks:
        return present, np.empty(0, dtype=np.intp)
    rank = _TABLES.rank
    rank[present] = np.arange(present.size, dtype=np.int32)
    return present, rank[code].astype(np.intp)


def unique_ints(
    values: np.ndarray,
    *,
    return_inverse: bool = False,
    return_counts: bool = False,
    fields: tuple[int, ...] | None = None,
) -> np.ndarray | tuple[np.ndarray, ...]:
    """:func:`numpy.unique` of a 1-D integer array, with the same results (sorted unique
    values, then the inverse and the counts if asked), in linear time when it can.

    Sorting dominates the per-frame cost of the streaming detector. When the values span
    a range not much larger than their number, a table over that range replaces the
    sort. Packed keys (voxel or space-time keys) span a huge numeric range but few
    distinct values per field: ``fields`` gives the bit widths of non-negative packed
    fields, most significant first (:data:`VOXEL_FIELDS`, :data:`SPACETIME_FIELDS`), and
    the table is laid over the fields' own ranges, whose lexicographic order is the
    keys' order. Otherwise (or for empty input) it is :func:`numpy.unique`.
    """
    values = np.asarray(values)
    n = values.shape[0] if values.ndim == 1 else 0
    code, cells, decode = (None, 0, None) if n == 0 else _dense_code(values, n, fields)
    if code is None:
        return np.unique(values, return_inverse=return_inverse, return_counts=return_counts)
    present, inverse = _table_unique(code, cells, return_inverse or return_counts)
    out: list[np.ndarray] = [decode(present).astype(values.dtype, copy=False)]
    if return_inverse:
        out.append(inverse)
    if return_counts:
        out.append(np.bincount(inverse, minlength=present.size))
    return out[0] if len(out) == 1 else tuple(out)


def unique_voxel_keys(
    xyz: np.ndarray, size: float, *, return_counts: bool = False
) -> tuple[np.ndarray, ...]:
    """``voxel_keys(xyz, size)`` and their :func:`unique_ints`: (keys (N,), sorted unique
    keys, inverse (N,)[, counts]). The table is laid over the voxel indices directly,
    without packing every point's key and splitting it again (a frame's hot path)."""
    idx = voxel_indices(xyz, size)
    n = idx.shape[0]
    limit = min(_DENSE_FIELDS_CELLS_PER_VALUE * n, _DENSE_MAX_CELLS)
    if _DENSE_FIELDS_MIN_VALUES <= n <= _DENSE_FIELDS_MAX_VALUES:
        radix = _radix_code((np.ascontiguousarray(idx[:, a]) for a in range(3)), limit)
        if radix is not None:
            code, cells, los, spans = radix
            present, inverse = _table_unique(code, cells, True)
            uk = pack(np.stack(_radix_digits(present, los, spans), axis=1))
            out = (uk[inverse], uk, inverse)
            if return_counts:
                out += (np.bincount(inverse, minlength=present.size),)
            return out
    keys = pack(idx)
    return (keys, *unique_ints(keys, return_inverse=True, return_counts=return_counts))


def _dense_code(values: np.ndarray, n: int, fields: tuple[int, ...] | None):
    """(codes in 0..cells-1 ordered like ``values``, cells, codes -> values), or
    (None, 0, None) when no table small enough exists or ``values`` are not integers."""
    if values.dtype.kind not in "iu":
        return None, 0, None
    v = values.astype(np.int64, copy=False)
    lo, hi = int(v.min()), int(v.max())
    if hi - lo < min(_DENSE_CELLS_PER_VALUE * n + _DENSE_MIN_CELLS, _DENSE_MAX_CELLS):
        base = lo
        return v - base, hi - lo + 1, lambda c: c + base
    if fields is None or lo < 0 or not _DENSE_FIELDS_MIN_VALUES <= n <= _DENSE_FIELDS_MAX_VALUES:
        return None, 0, None
    limit = min(_DENSE_FIELDS_CELLS_PER_VALUE * n, _DENSE_MAX_CELLS)
    shifts = [int(x) for x in np.cumsum((0,) + tuple(fields[::-1]))[:-1][::-1]]
    parts = ((v >> shift) & ((1 << int(w)) - 1) for w, shift in zip(fields, shifts, strict=True))
    radix = _radix_code(parts, limit)
    if radix is None:
        return None, 0, None
    code, cells, los, spans = radix

    def decode(c: np.ndarray) -> np.ndarray:
        key = np.zeros(c.shape, dtype=np.int64)
        for digit, shift in zip(_radix_digits(c, los, spans), shifts, strict=True):
            key |= digit << shift
        return key

    return code, cells, decode


def _radix_code(
    parts: Iterable[np.ndarray], limit: int
) -> tuple[np.ndarray, int, list[int], list[int]] | None:
    """Integer columns (the first most significant) as one mixed-radix code over their
    own ranges, ordered as the columns are lexicographically: (code, cells, lows, spans),
    or None when that box has ``limit`` cells or more. ``parts`` may be a generator: no
    column is made after the one that overflows the box."""
    cols: list[np.ndarray] = []
    los, spans, cells = [], [], 1
    for f in parts:
        cols.append(f)
        lo = int(f.min())
        los.append(lo)
        spans.append(int(f.max()) - lo + 1)
        cells *= spans[-1]
        if cells >= limit:
            return None
    code = cols[0] - los[0]
    for f, lo, span in zip(cols[1:], los[1:], spans[1:], strict=True):
        code = code * span + (f - lo)
    return code, cells, los, spans


def _radix_digits(code: np.ndarray, los: list[int], spans: list[int]) -> list[np.ndarray]:
    """Inverse of :func:`_radix_code`: the columns of ``code``, the first most significant."""
    digits = []
    for lo, span in zip(los[::-1], spans[::-1], strict=True):
        code, digit = np.divmod(code, span)
        digits.append(digit + lo)
    return digits[::-1]


def lookup(sorted_keys: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """Index of each query key in ``sorted_keys``, or -1 where absent."""
    n = sorted_keys.shape[0]
    queries = np.asarray(queries, dtype=np.int64)
    if n == 0:
        return np.full(queries.shape, -1, dtype=np.int64)
    pos = np.minimum(np.searchsorted(sorted_keys, queries), n - 1)
    return np.where(sorted_keys[pos] == queries, pos, -1)


#: Up to this many queries, the neighbourhood counts are looked up all at once.
_FEW_QUERIES = 512

#: Key differences of a voxel's 3x3x3 neighbourhood, itself first.
_NEIGHBOURHOOD_KEYS = np.array(
    [0] + [s * offset_key(off) for off in HALF_OFFSETS for s in (1, -1)], dtype=np.int64
)


class SlidingVoxelCounts:
    """Point counts per voxel over a sliding window of frames, updated incrementally.

    Holds one sorted array of (key, count) for the whole window plus each frame's own
    unique keys and counts, so adding or evicting a frame is a merge of sorted runs
    (O(window voxels)) instead of re-sorting every point of the window, and the 3x3x3
    neighbourhood count is looked up only for the voxels being asked about.
    """

    def __init__(self) -> None:
        self._frames: deque[tuple[float, np.ndarray, np.ndarray]] = deque()
        self.keys = np.empty(0, np.int64)
        self.counts = np.empty(0, np.int64)

    def __len__(self) -> int:
        return len(self._frames)

    def add(self, stamp: float, keys: np.ndarray) -> None:
        """Add one frame's (unsorted, repeated) voxel keys."""
        uk, cnt = unique_ints(
            np.asarray(keys, dtype=np.int64), return_counts=True, fields=VOXEL_FIELDS
        )
        self.add_unique(stamp, uk, cnt)

    def add_unique(self, stamp: float, uk: np.ndarray, cnt: np.ndarray) -> None:
        """Add one frame given as its sorted unique voxel keys and their point counts."""
        self._frames.append((float(stamp), uk, cnt))
        if uk.size == 0:
            return
        merged = np.concatenate([self.keys, uk])
        weights = np.concatenate([self.counts, cnt])
        order = np.argsort(merged, kind="stable")  # two sorted runs: a linear merge
        merged, weights = merged[order], weights[order]
        starts = np.flatnonzero(np.r_[True, merged[1:] != merged[:-1]])
        self.keys = merged[starts]
        self.counts = np.add.reduceat(weights, starts)

    def evict_before(self, stamp: float) -> None:
        """Drop the frames stamped before ``stamp``."""
        removed = False
        while self._frames and self._frames[0][0] < stamp:
            _, uk, cnt = self._frames.popleft()
            if uk.size:
                self.counts[np.searchsorted(self.keys, uk)] -= cnt  # keys unique per frame
                removed = True
        if removed:
            keep = self.counts > 0
            self.keys, self.counts = self.keys[keep], self.counts[keep]

    def neighbourhood_at_least(self, queries: np.ndarray, n: int) -> np.ndarray:
        """(Q,) bool: the 3x3x3 neighbourhood of each query key holds >= ``n`` points.

        Equal to ``neighbourhood_counts(queries) >= n``, but a query stops being looked
        up once it has ``n`` (a dense voxel needs no neighbours: full frames are mostly
        that).
        """
        queries = np.asarray(queries, dtype=np.int64)
        total = np.zeros(queries.shape, np.int64)
        if self.keys.size == 0 or queries.size == 0:
            return total >= n
        if queries.size <= _FEW_QUERIES:
            # A few queries (a real Avia frame holds tens of returns): one lookup of all
            # 27 neighbours each costs less than 27 lookups that rarely stop early.
            return self.neighbourhood_counts(queries) >= n
        open_ = np.arange(queries.size)
        for off in _NEIGHBOURHOOD_KEYS:
            idx = lookup(self.keys, queries[open_] + off)
            total[open_] += np.where(idx >= 0, self.counts[np.maximum(idx, 0)], 0)
            open_ = open_[total[open_] < n]
            if open_.size == 0:
                break
        return total >= n

    def neighbourhood_counts(self, queries: np.ndarray) -> np.ndarray:
        """Points in the 3x3x3 voxel neighbourhood of each query key (itself included)."""
        queries = np.asarray(queries, dtype=np.int64)
        if self.keys.size == 0 or queries.size == 0:
            return np.zeros(queries.shape, np.int64)
        around = queries.reshape(-1, 1) + _NEIGHBOURHOOD_KEYS[None, :]  # one lookup for all
        idx = lookup(self.keys, around.ravel()).reshape(around.shape)
        found = np.where(idx >= 0, self.counts[np.maximum(idx, 0)], 0)
        return found.sum(axis=1).reshape(queries.shape)
