"""Streaming detection: causal, bounded memory, one estimate per pushed frame.

State (all bounded whatever the stream length):

- **Global accumulator**: a voxel grid (``voxel_size`` voxels) held as sorted int64 keys
  with a hit count and last-seen time per voxel. Counts decay with time constant
  ``global_window`` and voxels unseen for ``global_window`` seconds are dropped; the grid
  is capped at ``max_accumulator_voxels`` (weakest voxels dropped first). Static
  structure piles up counts (high global density); a moving drone leaves ~1 hit/voxel.
- **Local history**: the raw filtered points of the last ``local_history`` seconds
  (capped at ``max_local_points``), from which the local windows and the drone points
  come.
- **Track**: per-frame mean positions of the selected cluster's points.

Every ``recluster_period`` seconds of stream time the pending frames are merged into the
grid, the grid is clustered (voxel connected components on ``cluster_voxel`` voxels,
weighted by the counts), each cluster is scored from its local-history points (same
scoring code as offline, global density from the grid) and the best candidate becomes
the track. Between re-clusterings, new points within ``track_gate`` metres of the
predicted position extend the track. The estimate for a frame is a weighted straight-line
fit over the track's last ``track_window`` seconds, evaluated at the frame stamp.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from clusterfilter_ros.core import voxel
from clusterfilter_ros.core.clustering import relabel_compact, voxel_clusters
from clusterfilter_ros.core.estimate import Estimate
from clusterfilter_ros.core.frame import Frame
from clusterfilter_ros.core.params import ParamSet, detector_params
from clusterfilter_ros.core.preprocess import frame_points
from clusterfilter_ros.core.scoring import score_clusters, select_clusters

#: Parameters whose change invalidates the accumulated state (voxel keys, filtering).
_STRUCTURAL = {
    "voxel_size",
    "denoise_voxel",
    "denoise_sensors",
    "mid360_min_z",
    "max_range",
    "frame_period",
}


@dataclass
class _Chunk:
    """Filtered points of one frame in the local history."""

    stamp: float
    xyz: np.ndarray  # (N, 3) float32
    t: np.ndarray  # (N,) float64
    keys: np.ndarray  # (N,) int64 voxel_size keys


@dataclass
class _TrackSample:
    t: float
    position: np.ndarray  # (3,) float64 mean of the frame's drone points
    points: np.ndarray  # (n, 3) float32 the drone points themselves


class StreamingDetector:
    """Push frames one at a time; get an :class:`Estimate` (or None) for each."""

    def __init__(self, params: ParamSet | None = None) -> None:
        self.params = detector_params() if params is None else params.copy()
        self.frames_pushed = 0
        self.frames_rejected = 0
        self.reset()

    # ------------------------------------------------------------------ public API
    def reset(self) -> None:
        """Forget everything seen so far (counters of pushed/rejected frames are kept)."""
        self._grid_keys = np.empty(0, np.int64)
        self._grid_counts = np.empty(0, np.float64)
        self._grid_last = np.empty(0, np.float64)
        self._grid_time = math.nan
        self._pending: list[tuple[np.ndarray, float]] = []
        self._chunks: deque[_Chunk] = deque()
        self._chunk_points = 0
        self._denoise_recent: dict[str, deque[tuple[float, np.ndarray]]] = {}
        self._track: deque[_TrackSample] = deque()
        self._selected_conf = 0.0
        self._selected_clusters = 0
        self._now = -math.inf
        self._origin = math.nan
        self._last_recluster = -math.inf
        self._last_recluster_ms = 0.0
        self._recluster_ms_total = 0.0
        self._reclusters = 0
        self._last_push_ms = 0.0
        self._clusters = 0

    def update_params(self, values: Mapping[str, Any]) -> None:
        """Validate and apply new values; the state is reset only if a voxel or filter
        parameter changed (raises :class:`~clusterfilter_ros.errors.ParameterError`)."""
        new = self.params.copy(**dict(values))
        old = self.params.as_dict()
        changed = {k for k, v in new.as_dict().items() if old[k] != v}
        self.params = new
        if changed & _STRUCTURAL:
            self.reset()

    def push(self, frame: Frame) -> Estimate | None:
        """Add one frame; return the drone position at ``frame.stamp`` or None."""
        start = time.perf_counter()
        self.frames_pushed += 1
        stamp = float(frame.stamp)
        if not math.isfinite(stamp) or stamp < self._now - self.params.local_history:
            self.frames_rejected += 1
            self._last_push_ms = (time.perf_counter() - start) * 1e3
            return None
        if math.isnan(self._origin):
            self._origin = stamp
        xyz, t = frame_points(frame, self.params)
        if frame.sensor in self.params.denoise_sensors:
            keep = self._denoise(frame.sensor, stamp, xyz)
            xyz, t = xyz[keep], t[keep]
        keys = voxel.voxel_keys(xyz, self.params.voxel_size)
        self._now = max(self._now, stamp)
        self._chunks.append(_Chunk(stamp, xyz, t, keys))
        self._chunk_points += xyz.shape[0]
        self._pending.append((keys, stamp))
        self._evict_chunks()
        if self._now - self._last_recluster >= self.params.recluster_period:
            self._recluster()
        elif xyz.shape[0] and self._track:
            self._extend_track(stamp, xyz, t)
        estimate = self._estimate(stamp)
        self._last_push_ms = (time.perf_counter() - start) * 1e3
        return estimate

    def drone_points(self) -> np.ndarray:
        """(M, 3) float32 points of the selected cluster within the last track_window s."""
        if not self._track:
            return np.empty((0, 3), np.float32)
        lo = self._now - self.params.track_window
        parts = [s.points for s in self._track if s.t >= lo]
        return np.concatenate(parts).astype(np.float32) if parts else np.empty((0, 3), np.float32)

    def stats(self) -> dict[str, float]:
        """Sizes and timings of the state, for monitoring and benchmarks."""
        grid_bytes = self._grid_keys.nbytes + self._grid_counts.nbytes + self._grid_last.nbytes
        local_bytes = sum(c.xyz.nbytes + c.t.nbytes + c.keys.nbytes for c in self._chunks)
        pending_bytes = sum(k.nbytes for k, _ in self._pending)
        return {
            "accumulator_voxels": float(self._grid_keys.size),
            "accumulator_bytes": float(grid_bytes),
            "local_points": float(self._chunk_points),
            "local_bytes": float(local_bytes + pending_bytes),
            "state_bytes": float(grid_bytes + local_bytes + pending_bytes),
            "track_samples": float(len(self._track)),
            "clusters": float(self._clusters),
            "selected_confidence": float(self._selected_conf),
            "last_recluster_ms": self._last_recluster_ms,
            "mean_recluster_ms": self._recluster_ms_total / max(self._reclusters, 1),
            "reclusters": float(self._reclusters),
            "last_push_ms": self._last_push_ms,
            "frames_pushed": float(self.frames_pushed),
            "frames_rejected": float(self.frames_rejected),
        }

    # ------------------------------------------------------------------ internals
    def _denoise(self, sensor: str, stamp: float, xyz: np.ndarray) -> np.ndarray:
        """Keep points whose neighbourhood over the recent frames of this sensor is dense."""
        p = self.params
        recent = self._denoise_recent.setdefault(sensor, deque())
        keys = voxel.voxel_keys(xyz, p.denoise_voxel)
        recent.append((stamp, keys))
        while recent and recent[0][0] < self._now - p.denoise_window:
            recent.popleft()
        if xyz.shape[0] == 0:
            return np.zeros(0, bool)
        all_keys = np.concatenate([k for _, k in recent])
        uk, counts = np.unique(all_keys, return_counts=True)
        density = voxel.neighbourhood_sums(uk, counts)
        return density[np.searchsorted(uk, keys)] >= p.denoise_min_points

    def _evict_chunks(self) -> None:
        lo = self._now - self.params.local_history
        cap = self.params.max_local_points
        while self._chunks and (self._chunks[0].stamp < lo or self._chunk_points > cap):
            self._chunk_points -= self._chunks.popleft().xyz.shape[0]
        lo_track = self._now - self.params.local_history
        while self._track and self._track[0].t < lo_track:
            self._track.popleft()

    def _merge_pending(self) -> None:
        p = self.params
        now = self._now
        if not math.isnan(self._grid_time) and self._grid_counts.size:
            self._grid_counts *= math.exp(-max(now - self._grid_time, 0.0) / p.global_window)
        self._grid_time = now
        if self._pending:
            new_keys = np.concatenate([k for k, _ in self._pending])
            self._pending.clear()
            uk, cnt = np.unique(new_keys, return_counts=True)
            idx = voxel.lookup(self._grid_keys, uk)
            found = idx >= 0
            self._grid_counts[idx[found]] += cnt[found]
            self._grid_last[idx[found]] = now
            fresh = ~found
            if fresh.any():
                pos = np.searchsorted(self._grid_keys, uk[fresh])
                self._grid_keys = np.insert(self._grid_keys, pos, uk[fresh])
                self._grid_counts = np.insert(self._grid_counts, pos, cnt[fresh].astype(float))
                self._grid_last = np.insert(self._grid_last, pos, now)
        keep = self._grid_last >= now - p.global_window
        if self._grid_keys.size - int(keep.sum()) > 0:
            self._grid_keys = self._grid_keys[keep]
            self._grid_counts = self._grid_counts[keep]
            self._grid_last = self._grid_last[keep]
        excess = self._grid_keys.size - p.max_accumulator_voxels
        if excess > 0:
            drop = np.argpartition(self._grid_counts, excess)[:excess]
            keep = np.ones(self._grid_keys.size, bool)
            keep[drop] = False
            self._grid_keys = self._grid_keys[keep]
            self._grid_counts = self._grid_counts[keep]
            self._grid_last = self._grid_last[keep]

    def _recluster(self) -> None:
        start = time.perf_counter()
        p = self.params
        self._last_recluster = self._now
        self._merge_pending()
        self._track.clear()
        self._selected_conf = 0.0
        self._clusters = 0
        if self._grid_keys.size and self._chunks:
            centres = (voxel.unpack(self._grid_keys) + 0.5) * p.voxel_size
            coarse = voxel.voxel_keys(centres, p.cluster_voxel)
            uc, inv = np.unique(coarse, return_inverse=True)
            inv = inv.reshape(-1)
            weights = np.bincount(inv, weights=self._grid_counts, minlength=uc.size)
            grid_labels, k = relabel_compact(voxel_clusters(uc, weights, p.min_samples)[inv])
            self._clusters = k
            if k:
                g_pts = np.bincount(
                    grid_labels[grid_labels >= 0],
                    weights=self._grid_counts[grid_labels >= 0],
                    minlength=k,
                )
                g_vox = np.bincount(grid_labels[grid_labels >= 0], minlength=k).astype(float)
                xyz = np.concatenate([c.xyz for c in self._chunks])
                t = np.concatenate([c.t for c in self._chunks])
                keys = np.concatenate([c.keys for c in self._chunks])
                gi = voxel.lookup(self._grid_keys, keys)
                labels = np.where(gi >= 0, grid_labels[gi], -1)
                scores = score_clusters(
                    labels,
                    xyz,
                    t,
                    p,
                    n_clusters=k,
                    global_points=g_pts,
                    global_voxels=g_vox,
                    t0=self._origin,
                )
                chosen = select_clusters(scores, p)
                if chosen:
                    best = chosen[0]
                    self._selected_conf = float(scores.confidence[best])
                    self._rebuild_track(labels == best, xyz, t)
        ms = (time.perf_counter() - start) * 1e3
        self._last_recluster_ms = ms
        self._recluster_ms_total += ms
        self._reclusters += 1

    def _rebuild_track(self, mask: np.ndarray, xyz: np.ndarray, t: np.ndarray) -> None:
        pts, tt = xyz[mask], t[mask]
        if tt.size == 0:
            return
        half = self.params.frame_period / 2
        bins = np.floor((tt - self._origin) / half + 1e-6).astype(np.int64)
        order = np.argsort(bins, kind="stable")
        bins, pts, tt = bins[order], pts[order], tt[order]
        cuts = np.nonzero(np.diff(bins))[0] + 1
        for idx in np.split(np.arange(bins.size), cuts):
            group = pts[idx]
            self._track.append(
                _TrackSample(float(tt[idx].mean()), group.mean(axis=0, dtype=np.float64), group)
            )

    def _fit(self, stamp: float) -> tuple[np.ndarray, int] | None:
        """Position at ``stamp`` from the track's last track_window seconds."""
        p = self.params
        samples = [s for s in self._track if stamp - p.track_window <= s.t <= stamp]
        if not samples or stamp - samples[-1].t > p.max_extrapolation:
            return None
        ts = np.array([s.t for s in samples])
        ps = np.array([s.position for s in samples])
        ws = np.array([float(s.points.shape[0]) for s in samples])
        n = int(ws.sum())
        mean = np.average(ps, axis=0, weights=ws)
        if ts.size >= 3 and ts[-1] - ts[0] >= 2 * p.frame_period:
            tc = float(np.average(ts, weights=ws))
            dt = ts - tc
            slope = (ws[:, None] * dt[:, None] * (ps - mean)).sum(axis=0) / float(
                np.sum(ws * dt * dt)
            )
            return mean + slope * (stamp - tc), n
        return mean, n

    def _extend_track(self, stamp: float, xyz: np.ndarray, t: np.ndarray) -> None:
        fit = self._fit(stamp)
        if fit is None:
            return
        predicted, _ = fit
        d2 = np.sum((xyz.astype(np.float64) - predicted) ** 2, axis=1)
        near = d2 <= self.params.track_gate**2
        if near.any():
            group = xyz[near]
            self._track.append(
                _TrackSample(float(t[near].mean()), group.mean(axis=0, dtype=np.float64), group)
            )

    def _estimate(self, stamp: float) -> Estimate | None:
        p = self.params
        if not self._track or self._selected_conf < p.min_confidence:
            return None
        fit = self._fit(stamp)
        if fit is None:
            return None
        position, n = fit
        if n < p.min_points:
            return None
        offset = np.asarray(p.target_offset, dtype=np.float64)
        return Estimate(stamp, position + offset, self._selected_conf, n)


def run_streaming(frames: Iterable[Frame], params: ParamSet | None = None) -> list[Estimate]:
    """Push every frame through one :class:`StreamingDetector`; the estimates in order."""
    detector = StreamingDetector(params)
    out = []
    for frame in frames:
        est = detector.push(frame)
        if est is not None:
            out.append(est)
    return out
