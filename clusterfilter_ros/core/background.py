"""Static-structure suppression: the relative-density idea applied per voxel.

The paper separates static structure from a moving drone by comparing a cluster's
density accumulated over the whole sequence with its density in short windows. With a
non-repetitive Livox scan at tens of metres, though, a static surface is sampled so
sparsely that its points rarely share a 0.2 m voxel, and that cluster-level ratio stops
telling a far wall from a drone. Persistence is the robust form of the same idea: a
voxel of edge ``static_voxel`` that receives returns in at least ``static_min_bins``
distinct time bins of ``static_bin`` seconds is static (walls, roofs, trees, poles); a
moving drone occupies any one voxel for a bin or two. Points in static voxels (optionally
dilated by ``static_dilation`` voxels) are removed before clustering.

Offline, bins are counted over the whole sequence, and a group of static voxels each hit
over a few seconds only is released (:func:`drifting_static_keys`); streaming, over the last
``global_window`` seconds with a 64-bit hit mask per voxel (:class:`BackgroundGrid`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from clusterfilter_ros.core import voxel
from clusterfilter_ros.core.grouping import group_bounds, lex_order
from clusterfilter_ros.core.params import ParamSet

_MAX_BINS = 64


def _popcount(x: np.ndarray) -> np.ndarray:
    if hasattr(np, "bitwise_count"):
        return np.bitwise_count(x).astype(np.int64)
    as_bytes = np.ascontiguousarray(x, dtype=np.uint64).view(np.uint8).reshape(-1, 8)
    return np.unpackbits(as_bytes, axis=1).sum(axis=1).astype(np.int64)


def _lowest_bit(x: np.ndarray) -> np.ndarray:
    """(N,) int64: index of the lowest set bit of each nonzero uint64 in ``x``."""
    x = np.asarray(x, dtype=np.uint64)
    low = x & (~x + np.uint64(1))  # isolate the lowest set bit
    return _highest_bit(low)


def _highest_bit(x: np.ndarray) -> np.ndarray:
    """(N,) int64: index of the highest set bit of each nonzero uint64 in ``x``."""
    x = np.asarray(x, dtype=np.uint64)
    out = np.zeros(x.shape, dtype=np.int64)
    for shift in (32, 16, 8, 4, 2, 1):
        s = np.uint64(shift)
        big = (x >> s) != 0
        out += np.where(big, shift, 0)
        x = np.where(big, x >> s, x)
    return out


def _dilate(static_keys: np.ndarray, dilation: int) -> np.ndarray:
    """Sorted keys of the static voxels plus their 26 neighbours (dilation 1)."""
    if dilation <= 0 or static_keys.size == 0:
        return static_keys
    return voxel.unique_ints(
        (static_keys[:, None] + voxel.NEIGHBOURHOOD[None, :]).ravel(), fields=voxel.VOXEL_FIELDS
    )


def compact_static_keys(static_keys: np.ndarray, params: ParamSet) -> np.ndarray:
    """The static voxels that form small isolated groups (a hovering drone, not a building).

    Static voxels are grouped by connected components of touching voxels (26
    neighbours); groups whose bounding box is at most ``hover_max_extent`` metres are
    returned (sorted keys). Grouping on a grid twice as coarse, as this once did, merged
    a drone hovering 3-6 m from a wall with the wall (deviation 22 in docs/detector.md).
    """
    if static_keys.size == 0:
        return static_keys
    from clusterfilter_ros.core.clustering import voxel_clusters

    centres = (voxel.unpack(static_keys) + 0.5) * params.static_voxel
    comp = voxel_clusters(static_keys, np.ones(static_keys.size), 0.0)
    k = int(comp.max()) + 1
    half = params.static_voxel / 2
    (lo, _), (_, hi) = group_bounds(comp, k, centres - half, centres + half)
    small = (hi - lo).max(axis=1) <= params.hover_max_extent + 1e-9
    return static_keys[small[comp]]


def drifting_static_keys(
    static_keys: np.ndarray, first_bin: np.ndarray, last_bin: np.ndarray, params: ParamSet
) -> np.ndarray:
    """The static voxels a slowly moving object left behind (a drone drifting, or slowing
    into a hover and out of it, overhead, or hovering beside structure).

    At 1.5 m voxels and 1 s bins, a drone moving at under about 0.5 m/s fills each voxel
    it crosses for three or more bins and so counts as static; when the voxels it filled
    span more than ``hover_max_extent`` the compact-group exception does not keep them.
    Structure is hit over the whole recording, such an object for a few seconds per
    voxel. With a voxel's hit span its last minus first bin, in seconds, two kinds of
    voxels are returned (sorted keys):

    - the groups of touching static voxels (as in :func:`compact_static_keys`) of at
      least three voxels whose median span is at most ``static_drift_span``
      (deviation 46 in docs/detector.md);
    - the groups of at least three touching static voxels *each* of span at most
      ``static_drift_span``, wherever they lie: a drone hovering a metre or two from a
      tree touches the crown's group through one sparse voxel at its edge, and the
      group's median span is then the crown's (deviation 86).

    ``first_bin`` and ``last_bin`` are per key, in ``static_bin`` units.
    """
    if static_keys.size < 3 or params.static_drift_span <= 0:
        return static_keys[:0]
    span = (np.asarray(last_bin) - np.asarray(first_bin)) * params.static_bin
    short = span <= params.static_drift_span
    limit = params.static_drift_span
    drifting = _drifting_groups(static_keys, span, limit)
    if np.count_nonzero(short) >= 3:
        drifting[short] |= _drifting_groups(static_keys[short], span[short], limit)
    return static_keys[drifting]


def _drifting_groups(static_keys: np.ndarray, span: np.ndarray, limit: float) -> np.ndarray:
    """(V,) bool: the voxels in groups of at least three touching voxels whose (lower)
    median ``span`` is at most ``limit``. Given only voxels of span <= ``limit``, every
    group of three or more."""
    from clusterfilter_ros.core.clustering import voxel_clusters

    comp = voxel_clusters(static_keys, np.ones(static_keys.size), 0.0)
    k = int(comp.max()) + 1
    n = np.bincount(comp, minlength=k)
    order = lex_order(span, comp)
    starts = np.searchsorted(comp[order], np.arange(k))
    median_span = span[order[starts + (n - 1) // 2]]  # the lower median
    return ((n >= 3) & (median_span <= limit))[comp]


def suppressed_keys(persistent: np.ndarray, params: ParamSet) -> np.ndarray:
    """Sorted keys of the voxels to suppress, from the sorted keys of the persistent ones:
    without the small isolated groups (a hovering drone; with ``hover_detection``), then
    dilated by ``static_dilation`` voxels. Offline and streaming share this step."""
    if params.hover_detection:
        persistent = np.setdiff1d(persistent, compact_static_keys(persistent, params))
    return _dilate(persistent, params.static_dilation)


class _Occupancy(NamedTuple):
    keys: np.ndarray  # (N,) voxel key per point
    ukeys: np.ndarray  # (V,) sorted unique keys
    inverse: np.ndarray  # (N,) index into ukeys per point
    pair_voxel: np.ndarray  # (P,) voxel index of each distinct (voxel, bin) pair, sorted
    pair_bin: np.ndarray  # (P,) its time bin
    bins_per_voxel: np.ndarray  # (V,) distinct bins per voxel


def _occupancy(xyz: np.ndarray, t: np.ndarray, params: ParamSet) -> _Occupancy:
    """Which ``static_bin`` time bins (counted from the first point) hit each
    ``static_voxel`` voxel; ``xyz`` must not be empty."""
    keys, ukeys, kinv = voxel.unique_voxel_keys(xyz, params.static_voxel)
    t = np.asarray(t, dtype=np.float64)
    bins = np.floor((t - t.min()) / params.static_bin).astype(np.int64)
    kinv = kinv.reshape(-1)
    n_bins = int(bins.max()) + 1
    pairs = voxel.unique_ints(kinv * n_bins + bins)
    pair_voxel, pair_bin = np.divmod(pairs, n_bins)
    bins_per_voxel = np.bincount(pair_voxel, minlength=ukeys.size)
    return _Occupancy(keys, ukeys, kinv, pair_voxel, pair_bin, bins_per_voxel)


def persistent_mask(xyz: np.ndarray, t: np.ndarray, params: ParamSet) -> np.ndarray:
    """(N,) bool: the points in ``static_voxel`` voxels hit in at least
    ``static_min_bins`` distinct time bins of these points (persistence alone: no
    released groups, no dilation)."""
    xyz = np.asarray(xyz).reshape(-1, 3)
    if xyz.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    occ = _occupancy(xyz, t, params)
    return (occ.bins_per_voxel >= params.static_min_bins)[occ.inverse]


def static_offline(
    xyz: np.ndarray, t: np.ndarray, params: ParamSet
) -> tuple[np.ndarray, np.ndarray]:
    """(mask of the points in voxels occupied in at least ``static_min_bins`` time bins of
    the whole sequence, sorted keys of the voxels to suppress): those voxels without the
    groups :func:`drifting_static_keys` returns, then :func:`suppressed_keys`."""
    xyz = np.asarray(xyz).reshape(-1, 3)
    if xyz.shape[0] == 0:
        return np.zeros(0, dtype=bool), np.empty(0, np.int64)
    occ = _occupancy(xyz, t, params)
    persistent = occ.bins_per_voxel >= params.static_min_bins
    persistent_keys = occ.ukeys[persistent]
    if params.static_drift_span > 0 and persistent_keys.size >= 3:
        # pairs are sorted by voxel then bin: a voxel's first and last pairs hold its extremes
        first = np.searchsorted(occ.pair_voxel, np.flatnonzero(persistent))
        last = first + occ.bins_per_voxel[persistent] - 1
        drifting = drifting_static_keys(
            persistent_keys, occ.pair_bin[first], occ.pair_bin[last], params
        )
        persistent_keys = np.setdiff1d(persistent_keys, drifting, assume_unique=True)
    static_keys = suppressed_keys(persistent_keys, params)
    return voxel.lookup(static_keys, occ.keys) >= 0, static_keys


class BackgroundGrid:
    """Streaming persistence map: per voxel, a bit per ``static_bin`` seconds it was hit.

    Memory: three arrays over the voxels hit within the last ``global_window`` seconds
    (at most :data:`_MAX_BINS` bins), capped at ``max_accumulator_voxels``.
    """

    def __init__(self, params: ParamSet) -> None:
        self.params = params
        self.keys = np.empty(0, np.int64)
        self.masks = np.empty(0, np.uint64)
        self.bin = None  # bin index that bit 0 stands for
        self.first = None  # bin index of the first update (bits older than it are unknown)

    def window_bins(self) -> int:
        return max(1, min(_MAX_BINS, math.ceil(self.params.global_window / self.params.static_bin)))

    def update(self, keys: np.ndarray, t: np.ndarray, now: float) -> None:
        """Record hits (static_voxel keys with their times) and age the map to ``now``."""
        p = self.params
        now_bin = math.floor(now / p.static_bin)  # a float stays finite for any stamp
        if self.bin is None:
            self.bin = now_bin
            self.first = now_bin
        shift = now_bin - self.bin
        if shift > 0:
            if shift >= _MAX_BINS:
                self.masks[:] = 0
            else:
                self.masks <<= np.uint64(int(shift))
            self.bin = now_bin
        window = self.window_bins()
        if keys.size:
            age = float(now_bin) - np.floor(np.asarray(t, dtype=np.float64) / p.static_bin)
            ok = (age >= 0) & (age < window)
            keys = keys[ok]
            bits = np.left_shift(np.uint64(1), age[ok].astype(np.uint64))
            order = np.argsort(keys, kind="stable")
            keys, bits = keys[order], bits[order]
            uk, start = np.unique(keys, return_index=True)
            hit = np.bitwise_or.reduceat(bits, start) if keys.size else bits
            idx = voxel.lookup(self.keys, uk)
            found = idx >= 0
            self.masks[idx[found]] |= hit[found]
            fresh = ~found
            if fresh.any():
                pos = np.searchsorted(self.keys, uk[fresh])
                self.keys = np.insert(self.keys, pos, uk[fresh])
                self.masks = np.insert(self.masks, pos, hit[fresh])
        limit = np.uint64((1 << window) - 1) if window < 64 else np.uint64(0xFFFFFFFFFFFFFFFF)
        self.masks &= limit
        alive = self.masks != 0
        if not alive.all():
            self.keys, self.masks = self.keys[alive], self.masks[alive]
        excess = self.keys.size - p.max_accumulator_voxels
        if excess > 0:
            counts = _popcount(self.masks)
            drop = np.argpartition(counts, excess)[:excess]
            keep = np.ones(self.keys.size, bool)
            keep[drop] = False
            self.keys, self.masks = self.keys[keep], self.masks[keep]

    def static_keys(self, watched_since: float = -math.inf) -> np.ndarray:
        """Sorted keys of the voxels currently considered static (dilated as configured);
        with ``stream_static_drift``, without the groups a slowly moving object left
        (:meth:`drifting_keys`; ``watched_since``: see there)."""
        persistent = _popcount(self.masks) >= self.params.static_min_bins
        keys = self.keys[persistent]
        if self.params.stream_static_drift and self.params.static_drift_span > 0:
            drifting = self.drifting_keys(keys, self.masks[persistent], watched_since)
            if drifting.size:
                keys = np.setdiff1d(keys, drifting, assume_unique=True)
        return suppressed_keys(keys, self.params)

    def drifting_keys(
        self, keys: np.ndarray, masks: np.ndarray, watched_since: float = -math.inf
    ) -> np.ndarray:
        """Of the persistent ``keys`` (hit ``masks``), those :func:`drifting_static_keys`
        releases, each voxel's span read from its oldest and newest hit bin in the window
        (deviation 125). Offline, structure is told by being hit over the whole
        recording; the map holds only ``global_window`` seconds, and at start-up less.
        So a voxel's span counts only if the map watched it unhit for at least
        ``static_drift_span`` seconds before its first hit (a drone arrives where
        nothing was); any other voxel's span is unknown and counts as long. The map
        watches from its first update, or from ``watched_since`` (stream time) if later:
        a lidar that paused saw nothing meanwhile."""
        if keys.size < 3 or self.bin is None or self.first is None:
            return keys[:0]
        start = self.first
        if math.isfinite(watched_since):
            start = max(start, math.floor(watched_since / self.params.static_bin))
        oldest = min(self.window_bins() - 1, self.bin - start)  # in bins, back from now
        p = self.params
        if oldest * p.static_bin < p.static_drift_span:
            # Watched for less than static_drift_span: no span can be known yet (at
            # start-up and after a lidar's pause), so skip the grouping.
            return keys[:0]
        newest_age = _lowest_bit(masks)
        oldest_age = _highest_bit(masks)
        unknown = (oldest - oldest_age) * p.static_bin < p.static_drift_span
        # Ages count back from now: first bin = now - oldest age, last = now - newest age.
        first_bin = np.where(unknown, -np.inf, -oldest_age.astype(np.float64))
        return drifting_static_keys(keys, first_bin, -newest_age.astype(np.float64), p)

    @property
    def nbytes(self) -> int:
        return int(self.keys.nbytes + self.masks.nbytes)
