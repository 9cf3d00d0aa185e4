"""Streaming detection: causal, bounded memory, one estimate per pushed frame.

State (all bounded whatever the stream length):

- **Persistence map** (:class:`~clusterfilter_ros.core.background.BackgroundGrid`): per
  ``static_voxel`` voxel, which of the last ``global_window`` seconds (in ``static_bin``
  bins) it was hit in; capped at ``max_accumulator_voxels``. Voxels hit in at least
  ``static_min_bins`` bins are static structure.
- **Local history**: the filtered points of the last ``local_history`` seconds that were
  not in a known static voxel when they arrived (capped at ``max_local_points``), from
  which clusters, local windows and drone points come.
- **Track**: per-frame mean positions of the selected cluster's points.

Every ``recluster_period`` seconds of stream time the pending frames go into the
persistence map, the non-static history points are clustered (voxel connected
components, then track linking), each cluster is scored by the same code as offline and
the best candidate becomes the track; returns the previous track had gathered since are
carried over, and the history after the track's newest sample is caught up. A reported
track whose cluster scores lower is kept while it passes ``keep_confidence``
(hysteresis), and a hovering one whose returns only became too few to cluster is kept
for up to ``hover_coast_seconds``. Between
re-clusterings, new points within ``track_gate`` metres of the predicted position extend
the track, up to ``max_gap`` seconds after its newest sample. The estimate for a frame is
a weighted straight-line fit (a quadratic for a well-sampled moving track, continued along
its tangent past the newest sample) over the track's last ``track_window`` seconds (at
least its last three samples, newer ones weighing more with ``track_recency``) up to the
end of the frame's scan, evaluated at the frame
stamp, and reported while the newest sample is at most ``max_extrapolation`` old
(``max_gap`` for a track slower than ``min_speed``).

With ``report_lag`` > 0 each frame is estimated a second time once the stream has moved
``report_lag`` seconds past it (:meth:`StreamingDetector.delayed`): from the track as it
is then, whose samples reach back to the start of its cluster in the local history and
forward past the frame, so a drone is reported from its first returns rather than from
the re-clustering that confirmed it, and gaps between returns are interpolated, not
extrapolated (fixed-lag smoothing; see :func:`smoothed_position`). Where a later
re-clustering selected a track that no longer reaches a waiting frame (a later piece of
the flight) or the reported track was lost, the samples it had are kept for those frames:
joined to the track that continues them, or else used for the frames up to the newest
one at which the live output reported a position on them.
"""

from __future__ import annotations

import bisect
import dataclasses
import functools
import math
import time
from collections import deque
from collections.abc import Iterable, Iterator, Mapping
from concurrent import futures
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from clusterfilter_ros.core import voxel
from clusterfilter_ros.core.background import BackgroundGrid
from clusterfilter_ros.core.clustering import absorb_colocated_noise
from clusterfilter_ros.core.estimate import Estimate, reported_positions
from clusterfilter_ros.core.frame import MID360, Frame
from clusterfilter_ros.core.linking import extend_track, fill_track
from clusterfilter_ros.core.offline import gap_runs, global_clusters, transient_below_floor
from clusterfilter_ros.core.params import ParamSet, detector_params
from clusterfilter_ros.core.preprocess import frame_points, points_at, usable_and_below_floor
from clusterfilter_ros.core.scoring import (
    ClusterScores,
    score_clusters,
    select_clusters,
    structure_contact,
)
from clusterfilter_ros.core.splitting import kinematic_tracks, split_and_score
from clusterfilter_ros.core.trajectory import chord_strays, weighted_line, weighted_quadratic

#: Frames waiting for their report_lag estimate beyond this are estimated at once (a
#: stream whose stamps stop advancing cannot grow the queue without bound).
_MAX_LAGGED = 10000

#: Earlier pieces of reported tracks kept for report_lag estimates (older ones are
#: dropped first; they are also dropped once no waiting frame can need them).
_MAX_ARCHIVED = 64

#: Parameters whose change invalidates the accumulated state (voxel keys, filtering).
_STRUCTURAL = {
    "static_voxel",
    "static_bin",
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
    static_keys: np.ndarray  # (N,) int64 static_voxel keys


@dataclass
class _HeldFrame:
    """A frame held for the late output (report_backfill), or an estimate held behind
    one so that the output stays in stamp order."""

    stamp: float
    estimate: Estimate | None = None
    decided: bool = False  # the estimate (None: dropped) is final
    new_run: bool = False  # before a new live run (report_hold_new_runs, deviation 107)
    # report_next_run: the live run it waits for begins after this stamp (deviation 110).
    after: float = -math.inf
    # report_next_dropped: the dropped track that reached it; its estimate must agree
    # with where that track was (deviation 133).
    dropped: _TrackPiece | None = None


@dataclass
class _TrackSample:
    t: float
    position: np.ndarray  # (3,) float64 mean of the frame's drone points
    points: np.ndarray  # (n, 3) float32 the drone points themselves


@dataclass(frozen=True)
class _TrackFit:
    """Weighted fits through a track's recent samples (:meth:`StreamingDetector._predict`)."""

    samples: tuple[_TrackSample, ...]
    params: ParamSet  # the parameters they were made with
    points: int  # returns in the samples (the support count, whatever the weights)
    slope: np.ndarray  # (3,) velocity of the straight line (zero over < 2 frame periods)
    mean: np.ndarray  # (3,) weighted mean position
    tc: float  # weighted mean time
    t_newest: float  # time of the newest sample
    # (3, 3) quadratic coefficients about tc, when the track moves at least min_speed,
    # 6 samples span 0.6 s (with track_recency: 4 over 0.4 s, the curvature at least
    # _CURVATURE_SIGMAS standard errors) and the fitted acceleration is at most
    # max_accel; else None.
    quadratic: np.ndarray | None
    # The line's speed is below min_speed and within _STILL_SIGMAS standard errors of
    # zero: as far as its samples tell, the track is not moving (deviation 73).
    still: bool = False
    # The samples span the two frame periods a velocity needs (_track_line): the slope is
    # measured, not unknown (deviation 82).
    measured: bool = True


@dataclass(frozen=True)
class _TrackPiece:
    """A track's samples as arrays, times ascending (report_lag)."""

    ts: np.ndarray  # (S,) float64
    ps: np.ndarray  # (S, 3) float64 positions
    ws: np.ndarray  # (S,) float64 point counts
    confidence: float
    # Newest stamp at which push() reported a position on this track (inf: not known).
    reported_until: float = math.inf
    # report_extend_tail: newest stamp the track's grown tail serves, whether or not
    # push() reported there (-inf: none).
    extends_until: float = -math.inf
    # report_extend_tail: newest sample of the track before its tail (inf: no tail).
    tail_from: float = math.inf


#: Lidars whose newest frame stamp the detector keeps (stream_static_drift); the rig has
#: two.
_MAX_SENSORS = 8

#: The samples, and the seconds they span, a quadratic fit of a track needs (live, and
#: around a late estimate's stamp).
_QUAD_SAMPLES = 6
_QUAD_SPAN = 0.6
#: With ``track_recency``, the same for the live quadratic (deviation 102).
_RECENT_QUAD_SAMPLES = 4
_RECENT_QUAD_SPAN = 0.4
#: ... and its quadratic term must be at least this many standard errors from zero.
_CURVATURE_SIGMAS = 2.0

#: A slow track's fitted speed within this many standard errors of zero is taken for
#: the scatter of its returns (deviation 73).
_STILL_SIGMAS = 3.0


def _speed_standard_error(
    ts: np.ndarray,
    ps: np.ndarray,
    ws: np.ndarray,
    line: tuple[np.ndarray, np.ndarray, float],
) -> float:
    """Standard error (m/s) of the speed of the weighted line ``line`` = (slope, mean,
    tc) of :func:`weighted_line`, ``mean + (t - tc) * slope``, through samples weighted
    by their point counts (each sample the mean of that many returns); inf with fewer
    than three samples or no spread in time."""
    slope, mean, tc = line
    dt = ts - tc
    sxx = float((ws * dt * dt).sum())
    if ts.size < 3 or not sxx > 0.0:
        return math.inf
    residual = ps - mean - dt[:, None] * slope
    variance = (ws[:, None] * residual * residual).sum(axis=0) / (ts.size - 2)
    return math.sqrt(float(variance.sum()) / sxx)


def _curvature_standard_error(
    dt: np.ndarray, ps: np.ndarray, ws: np.ndarray, coef: np.ndarray
) -> float:
    """Standard error of the quadratic term ``coef[2]`` (its norm over the three axes)
    of :func:`weighted_quadratic` ``coef`` through samples at time offsets ``dt`` with
    positions ``ps`` and weights ``ws`` (from the weighted residuals); inf with three
    samples or fewer (no residual left to judge the scatter by)."""
    if dt.size <= 3:
        return math.inf
    design = np.stack([np.ones_like(dt), dt, dt * dt], axis=1)
    residual = ps - design @ coef
    variance = (ws[:, None] * residual * residual).sum(axis=0) / (dt.size - 3)
    inverse = np.linalg.pinv(design.T @ (design * ws[:, None]))
    return math.sqrt(float(variance.sum()) * max(float(inverse[2, 2]), 0.0))


def _spans_velocity(ts: np.ndarray, params: ParamSet) -> bool:
    """Whether samples at times ``ts`` (ascending) span the two frame periods a velocity
    needs: over less, a fitted slope is the scatter of one or two frames' returns."""
    return bool(ts[-1] - ts[0] >= 2 * params.frame_period)


def _track_line(
    ts: np.ndarray, ps: np.ndarray, ws: np.ndarray, params: ParamSet
) -> tuple[np.ndarray, np.ndarray, float]:
    """:func:`weighted_line` through track samples, with no velocity from samples
    spanning less than two frame periods (:func:`_spans_velocity`): (velocity, weighted
    mean position, weighted mean time)."""
    slope, mean, tc = weighted_line(ts, ps, ws)
    if not _spans_velocity(ts, params):
        slope = np.zeros(3)
    return slope, mean, tc


def _facing_lines(
    earlier: _TrackPiece, later: _TrackPiece, params: ParamSet
) -> list[tuple[np.ndarray, np.ndarray, float, bool]]:
    """The straight-line fits (:func:`_track_line`) over ``track_window`` at the facing
    ends of ``earlier`` and ``later``: (velocity, mean position, mean time, whether the
    velocity was measured: samples spanning two frame periods), earlier's first."""
    p = params
    lines = []
    for piece, near in (
        (earlier, earlier.ts >= earlier.ts[-1] - p.track_window),
        (later, later.ts <= later.ts[0] + p.track_window),
    ):
        ts = piece.ts[near]
        slope, mean, tc = _track_line(ts, piece.ps[near], piece.ws[near], p)
        lines.append((slope, mean, tc, _spans_velocity(ts, p)))
    return lines


def _continues(earlier: _TrackPiece, later: _TrackPiece, params: ParamSet) -> bool:
    """Whether ``later`` (starting after ``earlier`` ends) continues the same object: at
    most ``link_max_gap`` after it, and the two straight-line fits over ``track_window``
    at their facing ends meet in the middle of the gap within ``track_gate`` (plus the
    ``link_max_accel`` allowance for the gap)."""
    p = params
    gap = float(later.ts[0] - earlier.ts[-1])
    if not 0.0 <= gap <= p.link_max_gap:
        return False
    middle = earlier.ts[-1] + 0.5 * gap
    return _lines_meet(_facing_lines(earlier, later, p), middle, 0.5 * gap, p)


def _lines_meet(
    lines: list[tuple[np.ndarray, np.ndarray, float, bool]],
    at: float,
    elapsed: float,
    params: ParamSet,
) -> bool:
    """Whether the two lines of :func:`_facing_lines`, carried to time ``at``, lie within
    ``track_gate`` plus half ``link_max_accel`` times ``elapsed`` squared (the way an
    object may have bent off a line over ``elapsed`` seconds) of each other."""
    ends = [mean + slope * (at - tc) for slope, mean, tc, _ in lines]
    reach = params.track_gate + 0.5 * params.link_max_accel * elapsed**2
    return float(np.linalg.norm(ends[0] - ends[1])) <= reach


def _could_continue(earlier: _TrackPiece, later: _TrackPiece, params: ParamSet) -> bool:
    """Whether one object could have left ``earlier`` and begun ``later``, however long
    the gap between them: the lines at their facing ends (:func:`_facing_lines`) meet in
    the middle of the gap within ``track_gate`` plus half ``link_max_accel`` times the
    squared half gap, as in :func:`_continues`; where only one end has a measured
    velocity, its line carried across the whole gap must reach the other end within
    ``track_gate`` plus half ``link_max_accel`` times the squared gap; with none, nothing
    says otherwise (deviation 85)."""
    lines = _facing_lines(earlier, later, params)
    v0, v1 = lines[0][3], lines[1][3]
    gap = float(later.ts[0] - earlier.ts[-1])
    if v0 and v1:
        return _lines_meet(lines, float(earlier.ts[-1]) + 0.5 * gap, 0.5 * gap, params)
    if v0 or v1:
        at = float(later.ts[0]) if v0 else float(earlier.ts[-1])
        return _lines_meet(lines, at, gap, params)
    return True


def _recent_samples(
    samples: Iterable[_TrackSample], last: float, params: ParamSet
) -> list[_TrackSample]:
    """The samples (in time order) a fit ending at ``last`` uses: those of the last
    ``track_window`` up to it or, for a sparse track, the last three within
    ``link_max_gap``, so that a return after a gap is not averaged with the one before
    it."""
    samples = list(samples)
    keep = _recent_mask(np.array([s.t for s in samples]), last, params)
    return [s for s, k in zip(samples, keep, strict=True) if k]


def _recent_mask(times: np.ndarray, last: float, params: ParamSet) -> np.ndarray:
    """(S,) bool: which of the samples at ``times`` (in time order) :func:`_recent_samples`
    keeps."""
    p = params
    recent = (times >= last - p.track_window) & (times <= last)
    if np.count_nonzero(recent) < 3:
        within = np.flatnonzero(
            (times >= last - max(p.track_window, p.link_max_gap)) & (times <= last)
        )
        recent = np.zeros(times.size, dtype=bool)
        recent[within[-3:]] = True
    return recent


def _after(samples: Iterable[_TrackSample], track: Iterable[_TrackSample]) -> list[_TrackSample]:
    """The ``samples`` newer than every sample of ``track`` (all of them if it is empty)."""
    newest = max((s.t for s in track), default=-math.inf)
    return [s for s in samples if s.t > newest]


def _sample_arrays(samples: list[_TrackSample]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times, positions, point counts) of samples sorted by time."""
    return (
        np.array([s.t for s in samples]),
        np.array([s.position for s in samples]),
        np.array([float(s.points.shape[0]) for s in samples]),
    )


@dataclass(frozen=True)
class _HistorySnapshot:
    """What one re-clustering reads: the frames' hits since the last one, copies of the
    history's points and the state it needs, so that it can run while frames keep
    arriving (background mode). Only the re-clustering touches ``grid``."""

    now: float
    origin: float
    grid: BackgroundGrid
    hit_keys: np.ndarray  # (M,) int64 static_voxel keys of the pending hits
    hit_times: np.ndarray  # (M,) float64
    xyz: np.ndarray | None  # (N, 3) float32; None while warming up or with no history
    t: np.ndarray | None  # (N,) float64
    static_keys: np.ndarray | None  # (N,) int64 static_voxel keys of the points
    # report_denoised: the far points the denoise dropped (xyz, t, static_voxel keys)
    dropped: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    expected: tuple[np.ndarray, float] | None  # (position, gate) of the reported track
    # (time, position) of the reported track's newest sample, with ``expected``
    newest: tuple[float, np.ndarray] | None
    params: ParamSet
    # Time of the reported track's oldest sample, with ``expected``.
    track_from: float | None = None
    # (times (S,), positions (S, 3), point counts (S,)) of the reported track's samples,
    # with ``expected`` (stream_track_agree, and stream_split_track's share before the
    # piece).
    track_path: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    # Stamp since which every lidar seen so far has sent frames without a pause
    # (stream_static_drift: the map watched the scene only then).
    watched_since: float = -math.inf
    # report_below_floor: the Mid360's returns at or below mid360_min_z (xyz, t).
    floor: tuple[np.ndarray, np.ndarray] | None = None


@dataclass(frozen=True)
class _LateSamples:
    """Samples beside a track's own that only the late output reads (report_lag), of
    returns the re-clustering grew the chosen track into."""

    # report_extend_head: before the track's first sample.
    head: tuple[_TrackSample, ...] = ()
    # report_extend_tail: after the track's newest sample.
    tail: tuple[_TrackSample, ...] = ()
    # report_fill: inside the track's gaps longer than max_gap, on its path.
    inner: tuple[_TrackSample, ...] = ()

    def around(
        self, track: Iterable[_TrackSample]
    ) -> tuple[list[_TrackSample], list[_TrackSample]]:
        """The samples the late output reads for ``track``: (its own, head and inner
        ones in time order; the tail's beyond the newest of them)."""
        core = sorted((*self.head, *self.inner, *track), key=lambda s: s.t)
        return core, _after(self.tail, core)


@dataclass(frozen=True)
class _TrackChoice:
    """The outcome of a re-clustering: the new static voxels and the track's samples."""

    snapshot: _HistorySnapshot
    static: np.ndarray  # sorted static voxel keys after the pending hits
    samples: list[_TrackSample] | None  # None: no track
    confidence: float
    new_track: bool  # a selected candidate (False: an existing track kept by hysteresis)
    clusters: int
    foreground_points: int  # history points left after static suppression
    elapsed_ms: float
    # No track chosen, and nothing near the reported track's prediction was rejected
    # for what it is (its recent returns were noise, or too few to be a candidate).
    coast: bool = False
    late: _LateSamples = _LateSamples()


class StreamingDetector:
    """Push frames one at a time; get an :class:`Estimate` (or None) for each."""

    def __init__(self, params: ParamSet | None = None, *, background: bool = False) -> None:
        """``background``: run each re-clustering on a worker thread while later frames
        keep being processed (their estimates come from the current track until it
        finishes), instead of inside the ``push`` that triggered it. Its result is applied
        by the first push after it finished, and at the latest by the first frame
        ``recluster_period`` of stream time after the one that started it (that push
        waits for it). Estimates then depend on how fast the machine is; the default
        (False) is deterministic."""
        self.params = detector_params() if params is None else params.copy()
        self.background = background
        self.frames_pushed = 0
        self.frames_rejected = 0
        self._executor: ThreadPoolExecutor | None = None
        # report_lag: stamps of the frames still to be estimated again, and the delayed
        # estimates made but not yet taken by delayed() (the newest _MAX_LAGGED). Both
        # survive reset().
        self._lagged: deque[float] = deque()
        self._ready: deque[Estimate] = deque(maxlen=_MAX_LAGGED)
        # report_backfill: in stamp order, frames released while a new track's live run
        # was still too short to backfill, each decided on its own, and the estimates
        # made after them, held so that the output stays in stamp order.
        self._held: deque[_HeldFrame] = deque()
        self.delayed_dropped = 0
        self.reset()

    # ------------------------------------------------------------------ public API
    def reset(self) -> None:
        """Forget everything seen so far (counters of pushed/rejected frames are kept).
        Frames still waiting for their delayed estimate get it from the state before the
        reset; :meth:`delayed` returns them."""
        self._release_delayed(math.inf)
        self._background = BackgroundGrid(self.params)
        self._static = np.empty(0, np.int64)  # sorted static voxel keys (last re-clustering)
        self._pending: list[tuple[np.ndarray, np.ndarray]] = []
        self._chunks: deque[_Chunk] = deque()
        self._chunk_points = 0
        # report_denoised: the far points the denoise dropped, per frame, as the history.
        self._dropped: deque[_Chunk] = deque()
        self._dropped_points = 0
        # report_below_floor: the Mid360's returns at or below mid360_min_z, per frame.
        self._floor: deque[_Chunk] = deque()
        self._floor_points = 0
        self._denoise_recent: dict[str, voxel.SlidingVoxelCounts] = {}
        self._track: deque[_TrackSample] = deque()
        # The track's grown head and tail and its filled gaps (the late output's only).
        self._late = _LateSamples()
        # The last track fit, per weighting (True: the reported estimate's, by recency).
        self._fit_cache: dict[bool, _TrackFit] = {}
        self._selected_conf = 0.0
        self._chosen_at = -math.inf  # stream time of the last re-clustering choosing a track
        self._now = -math.inf
        self._origin = math.nan
        self._last_recluster = -math.inf
        # The background re-clustering in flight and the main-thread time spent on it.
        self._job: Future[_TrackChoice] | None = None
        self._job_ms = 0.0
        self._last_recluster_ms = 0.0
        self._recluster_ms_total = 0.0
        self._reclusters = 0
        self._last_push_ms = 0.0
        self._clusters = 0
        self._foreground_points = 0
        self._jump_candidate: float | None = None
        self._last_live = -math.inf  # stamp of the newest estimate push() returned
        # stream_static_drift: each lidar's newest frame stamp, and the stamp since which
        # every lidar seen so far has sent frames with no pause longer than static_bin.
        self._sensor_last: dict[str, float] = {}
        self._watched_since = -math.inf
        # report_backfill: frames stamped up to this had fallen due with nothing reported
        # live since them (without report_backfill they would have been dropped).
        self._unreported_until = -math.inf
        # report_lag: earlier pieces of reported tracks, for the frames waiting for their
        # delayed estimate that the current track no longer reaches (oldest first).
        self._archive: deque[_TrackPiece] = deque(maxlen=_MAX_ARCHIVED)
        # report_next_run: (first sample time, newest live report, dropped track or None)
        # of newer returns that report_keep_newer did not keep, and of dropped tracks
        # (report_next_dropped), held live too briefly: a frame they reached waits for the
        # next live run instead of being dropped (deviations 112 and 133).
        self._unkept: deque[tuple[float, float, _TrackPiece | None]] = deque(maxlen=_MAX_ARCHIVED)
        # report_lag: (stamp, position) of push()'s recent estimates, to tell which kept
        # piece the live output reported.
        self._live_reports: deque[tuple[float, np.ndarray]] = deque(maxlen=_MAX_LAGGED)
        # (newest sample time, position there, velocity) of the last reported track.
        self._last_reported: tuple[float, np.ndarray, np.ndarray] | None = None

    def update_params(self, values: Mapping[str, Any]) -> None:
        """Validate and apply new values; the state is reset only if a voxel or filter
        parameter changed (raises :class:`~clusterfilter_ros.errors.ParameterError`)."""
        new = self.params.copy(**dict(values))
        old = self.params.as_dict()
        changed = {k for k, v in new.as_dict().items() if old[k] != v}
        self.params = new
        self._background.params = new
        if changed & _STRUCTURAL:
            self.reset()

    def finish_recluster(self, timeout: float | None = None) -> bool:
        """Wait for a background re-clustering in flight and apply it now; True if one
        was applied. (A no-op without ``background``: re-clusterings finish in ``push``.)
        Raises TimeoutError after ``timeout`` seconds."""
        if self._job is None:
            return False
        self._job.result(timeout)
        return self._collect_recluster()

    def close(self) -> None:
        """Stop the background worker (an unfinished re-clustering is dropped)."""
        self._job = None
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=True)
            self._executor = None

    def push(self, frame: Frame) -> Estimate | None:
        """Add one frame; return the drone position at ``frame.stamp`` or None."""
        start = time.perf_counter()
        self.frames_pushed += 1
        stamp = float(frame.stamp)
        if not math.isfinite(stamp) or stamp < self._now - self.params.local_history:
            self.frames_rejected += 1
            self._last_push_ms = (time.perf_counter() - start) * 1e3
            return None
        if self._now > -math.inf and stamp > self._now + self.params.local_history:
            # A jump forward by more than the history: one glitched stamp, or a clock that
            # really moved. A second frame on the new timeline confirms the jump (the state
            # restarts there); until then the frame is rejected, so a single garbage stamp
            # cannot make every later, correct frame look old.
            jump = self._jump_candidate
            self._jump_candidate = stamp
            if jump is None or abs(stamp - jump) > self.params.local_history:
                self.frames_rejected += 1
                self._last_push_ms = (time.perf_counter() - start) * 1e3
                return None
            self.reset()
        self._jump_candidate = None
        if math.isnan(self._origin):
            self._origin = stamp
        self._watch(frame.sensor, stamp)
        if frame.sensor == MID360 and self._keeps_floor():
            usable, below = usable_and_below_floor(frame, self.params)
            xyz, t = points_at(frame, usable)
            if below.any():
                fxyz, ft = points_at(frame, below)
                self._floor.append(_Chunk(stamp, fxyz, ft, np.empty(0, np.int64)))
                self._floor_points += ft.size
        else:
            xyz, t = frame_points(frame, self.params)
        self._now = max(self._now, stamp)
        dropped = None  # the denoise's dropped returns far enough out to be kept
        if frame.sensor in self.params.denoise_sensors:
            dense = self._denoise(frame.sensor, stamp, xyz)
            keeps = self._keeps_dropped()
            if not dense.all() and (keeps or self.params.track_denoised):
                dropped = self._far_dropped(xyz, t, np.flatnonzero(~dense))
                if keeps:
                    self._keep_dropped(stamp, *dropped)
            keep = np.flatnonzero(dense)
            xyz, t = xyz.take(keep, axis=0), t.take(keep)
        static_keys, uk, inverse = voxel.unique_voxel_keys(xyz, self.params.static_voxel)
        inverse = inverse.reshape(-1)
        self._pending.append(self._distinct_hits(uk, static_keys, t))
        if self.params.static_suppression and self._static.size and xyz.shape[0]:
            # Points in voxels already known static never reach the local history.
            moving = np.flatnonzero((voxel.lookup(self._static, uk) < 0)[inverse])
            xyz, t, static_keys = xyz.take(moving, axis=0), t.take(moving), static_keys.take(moving)
        self._chunks.append(_Chunk(stamp, xyz, t, static_keys))
        self._chunk_points += xyz.shape[0]
        self._evict_chunks()
        due = self._now - self._last_recluster >= self.params.recluster_period
        if due and self._job is not None:
            # A background re-clustering lags the stream by at most recluster_period: when
            # frames come faster than it runs (a fast replay), the stream waits for it.
            futures.wait([self._job])
        # A re-clustering applied here has caught its track up through this frame.
        caught_up = self._collect_recluster()
        if due and self._job is None:
            caught_up = self._recluster() or caught_up
        if dropped is not None and self.params.track_denoised and dropped[1].size:
            # track_denoised: the live track may take them too, as static-free as the rest.
            far_xyz, far_t, far_keys = dropped
            if self.params.static_suppression and self._static.size:
                far_xyz, far_t = _off_static(self._static, far_keys, far_xyz, far_t)
            xyz, t = np.concatenate([xyz, far_xyz]), np.concatenate([t, far_t])
        if not caught_up and xyz.shape[0] and self._track:
            self._extend_track(stamp, xyz, t)
        estimate = self._estimate(stamp)
        if estimate is not None:
            self._last_live = max(self._last_live, stamp)
        lag = self.params.report_lag
        if lag > 0:
            self._lagged.append(stamp)
            if estimate is not None:
                self._live_reports.append((stamp, estimate.position))
        self._release_delayed(self._now - lag)
        self._last_push_ms = (time.perf_counter() - start) * 1e3
        return estimate

    def delayed(self) -> list[Estimate]:
        """The ``report_lag`` estimates made since the last call, oldest frame first:
        after a push, those of the frames the stream has now passed by ``report_lag``
        seconds (stream time, the stamps pushed). Each is the position at its frame's
        stamp from all data up to the newest frame; frames with no drone there give none.
        Empty while ``report_lag`` is 0. Only the newest ``_MAX_LAGGED`` (10,000) are
        kept between calls; older ones are counted in ``delayed_dropped``."""
        ready = list(self._ready)
        self._ready.clear()
        return ready

    def flush(self) -> list[Estimate]:
        """End of a stream: the delayed estimates of every frame still waiting for
        ``report_lag`` to pass, from the data so far, with those not yet taken."""
        self._release_delayed(math.inf)
        return self.delayed()

    def drone_points(self) -> np.ndarray:
        """(M, 3) float32 points of the selected cluster within the last track_window s."""
        if not self._track:
            return np.empty((0, 3), np.float32)
        lo = self._now - self.params.track_window
        parts = [s.points for s in self._track if s.t >= lo]
        return np.concatenate(parts).astype(np.float32) if parts else np.empty((0, 3), np.float32)

    def stats(self) -> dict[str, float]:
        """Sizes and timings of the state, for monitoring and benchmarks."""
        grid_bytes = self._background.nbytes
        local_bytes = sum(c.xyz.nbytes + c.t.nbytes + c.static_keys.nbytes for c in self._chunks)
        local_bytes += sum(c.xyz.nbytes + c.t.nbytes + c.static_keys.nbytes for c in self._dropped)
        local_bytes += sum(c.xyz.nbytes + c.t.nbytes for c in self._floor)
        local_bytes += self._static.nbytes
        pending_bytes = sum(k.nbytes + t.nbytes for k, t in self._pending)
        return {
            "accumulator_voxels": float(self._background.keys.size),
            "accumulator_bytes": float(grid_bytes),
            "local_points": float(self._chunk_points),
            "accumulator_points": float(self._chunk_points),
            "foreground_points": float(self._foreground_points),
            "local_bytes": float(local_bytes + pending_bytes),
            "state_bytes": float(grid_bytes + local_bytes + pending_bytes),
            "track_samples": float(len(self._track)),
            "clusters": float(self._clusters),
            "selected_confidence": float(self._selected_conf),
            "last_recluster_ms": self._last_recluster_ms,
            "mean_recluster_ms": self._recluster_ms_total / max(self._reclusters, 1),
            "reclusters": float(self._reclusters),
            "recluster_in_flight": float(self._job is not None),
            "last_push_ms": self._last_push_ms,
            "frames_pushed": float(self.frames_pushed),
            "frames_rejected": float(self.frames_rejected),
            "delayed_pending": float(len(self._lagged) + len(self._held)),
            "delayed_dropped": float(self.delayed_dropped),
        }

    # ------------------------------------------------------------------ internals
    def _watch(self, sensor: str, stamp: float) -> None:
        """Note a frame of ``sensor`` at ``stamp``: a lidar heard for the first time, or
        again after a pause longer than ``static_bin``, starts the time the persistence
        map has watched the scene afresh (deviation 125: the structure it sees again was
        there all along, not a drone that arrived where nothing was)."""
        last = self._sensor_last.get(sensor)
        if last is None or stamp - last > self.params.static_bin:
            self._watched_since = max(self._watched_since, stamp)
        if last is None and len(self._sensor_last) >= _MAX_SENSORS:
            # Garbage sensor names must not grow the state: forget the stalest (heard
            # again, it counts as new, which only delays releases).
            del self._sensor_last[min(self._sensor_last, key=self._sensor_last.__getitem__)]
        if last is None or stamp > last:
            self._sensor_last[sensor] = stamp

    def _denoise(self, sensor: str, stamp: float, xyz: np.ndarray) -> np.ndarray:
        """Keep points whose neighbourhood over the recent frames of this sensor is dense."""
        p = self.params
        recent = self._denoise_recent.setdefault(sensor, voxel.SlidingVoxelCounts())
        recent.evict_before(self._now - p.denoise_window)
        _, uk, inverse, counts = voxel.unique_voxel_keys(xyz, p.denoise_voxel, return_counts=True)
        recent.add_unique(stamp, uk, counts)
        if xyz.shape[0] == 0:
            return np.zeros(0, bool)
        dense = recent.neighbourhood_at_least(uk, int(p.denoise_min_points))
        return dense[inverse.reshape(-1)]

    def _distinct_hits(
        self, uk: np.ndarray, keys: np.ndarray, t: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """A frame's hits for the persistence map: one (voxel, time) per voxel when the
        whole frame falls in one ``static_bin`` (the map keeps one bit per voxel and
        bin, so repeats change nothing), else every point's."""
        if t.size == 0:
            return keys, t
        width = self.params.static_bin
        first = math.floor(float(t.min()) / width)
        if math.floor(float(t.max()) / width) != first:
            return keys, t
        return uk, np.full(uk.size, (first + 0.5) * width)

    def _keeps_dropped(self) -> bool:
        """Whether the denoise's dropped points are kept (report_denoised: the late
        output's growth or fill may take them)."""
        p = self.params
        return (
            p.report_lag > 0
            and p.report_denoised
            and (p.report_extend_head or p.report_extend_tail or p.report_fill)
        )

    def _keeps_floor(self) -> bool:
        """Whether the Mid360's returns at or below ``mid360_min_z`` are kept
        (report_below_floor: the late output's growth at a track's ends may take them)."""
        p = self.params
        return (
            p.report_lag > 0
            and p.report_below_floor
            and (p.report_extend_head or p.report_extend_tail)
        )

    def _far_dropped(
        self, xyz: np.ndarray, t: np.ndarray, gone: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(xyz, t, static_voxel keys) of the rows ``gone`` (dropped by the denoise) at
        least ``denoised_min_range`` from the origin."""
        xyz, t = xyz.take(gone, axis=0), t.take(gone)
        near = float(self.params.denoised_min_range)
        if near > 0:
            far = np.flatnonzero(np.einsum("ij,ij->i", xyz, xyz) >= near * near)
            xyz, t = xyz.take(far, axis=0), t.take(far)
        return xyz, t, voxel.voxel_keys(xyz, self.params.static_voxel)

    def _keep_dropped(self, stamp: float, xyz: np.ndarray, t: np.ndarray, keys: np.ndarray) -> None:
        """Keep a frame's far points the denoise dropped for the late output's growth."""
        if xyz.shape[0] == 0:
            return
        self._dropped.append(_Chunk(stamp, xyz, t, keys))
        self._dropped_points += xyz.shape[0]

    def _evict_chunks(self) -> None:
        lo = self._now - self.params.local_history
        cap = self.params.max_local_points
        while self._chunks and (self._chunks[0].stamp < lo or self._chunk_points > cap):
            self._chunk_points -= self._chunks.popleft().xyz.shape[0]
        while self._dropped and (self._dropped[0].stamp < lo or self._dropped_points > cap):
            self._dropped_points -= self._dropped.popleft().xyz.shape[0]
        while self._floor and (self._floor[0].stamp < lo or self._floor_points > cap):
            self._floor_points -= self._floor.popleft().xyz.shape[0]
        while self._track and self._track[0].t < lo:
            self._track.popleft()

    def _recluster(self) -> bool:
        """Start a re-clustering: the pending frames enter the persistence map, static
        points leave the history, and the history is clustered and scored, here or on
        the background worker. True if its result was applied before returning."""
        start = time.perf_counter()
        p = self.params
        self._last_recluster = self._now
        if self._pending:
            keys = np.concatenate([k for k, _ in self._pending])
            times = np.concatenate([t for _, t in self._pending])
            self._pending.clear()
        else:
            keys, times = np.empty(0, np.int64), np.empty(0)
        previous = None
        if self._selected_conf >= p.min_confidence and self._track:
            previous = self._fit(self._now)
            self._last_reported = self._track_state()
        xyz = t = static_keys = None
        expected = self._expected_position(previous)
        warming_up = self._now - self._origin < p.warmup
        if self._chunks and self._chunk_points and not warming_up:
            xyz = np.concatenate([c.xyz for c in self._chunks])
            t = np.concatenate([c.t for c in self._chunks])
            static_keys = np.concatenate([c.static_keys for c in self._chunks])
        dropped = None
        if xyz is not None and self._dropped_points:
            dropped = (
                np.concatenate([c.xyz for c in self._dropped]),
                np.concatenate([c.t for c in self._dropped]),
                np.concatenate([c.static_keys for c in self._dropped]),
            )
        floor = None
        if xyz is not None and self._floor_points:
            floor = (
                np.concatenate([c.xyz for c in self._floor]),
                np.concatenate([c.t for c in self._floor]),
            )
        snapshot = _HistorySnapshot(
            now=self._now,
            origin=self._origin,
            grid=self._background,
            hit_keys=keys,
            hit_times=times,
            xyz=xyz,
            t=t,
            static_keys=static_keys,
            dropped=dropped,
            expected=expected,
            newest=None
            if expected is None or self._last_reported is None
            else (self._last_reported[0], self._last_reported[1]),
            params=p,
            track_from=None if expected is None or not self._track else self._track[0].t,
            track_path=None if expected is None or not self._track else _sample_arrays(self._track),
            watched_since=self._watched_since,
            floor=floor,
        )
        self._job_ms = (time.perf_counter() - start) * 1e3
        if self.background:
            if self._executor is None:
                self._executor = ThreadPoolExecutor(1, thread_name_prefix="clusterfilter-recluster")
            self._job = self._executor.submit(_recluster_snapshot, snapshot)
            return False
        self._apply_choice(_recluster_snapshot(snapshot))
        return True

    def _collect_recluster(self) -> bool:
        """Apply the background re-clustering if it has finished; True if it was."""
        job = self._job
        if job is None or not job.done():
            return False
        self._job = None
        self._apply_choice(job.result())  # re-raises the worker's exception, if any
        return True

    def _apply_choice(self, choice: _TrackChoice) -> None:
        """Make the re-clustering's outcome the state: points of voxels that became static
        leave the history, the chosen samples become the track, returns the previous
        track had gathered since are carried over and the history after the new track's
        newest sample is caught up (in background mode also the frames pushed meanwhile)."""
        start = time.perf_counter()
        self._static = choice.static
        if self.params.static_suppression and self._static.size:
            self._drop_static_from_history()
        old_track = list(self._track)
        old_late = self._late
        old_conf = self._selected_conf
        old_velocity = None  # only needed when nothing was chosen (deviation 77)
        if choice.samples is None and old_track and old_conf >= self.params.min_confidence:
            old_velocity = self._track_state()[2]
        self._track.clear()
        self._late = _LateSamples()
        self._selected_conf = 0.0
        self._clusters = choice.clusters
        self._foreground_points = choice.foreground_points
        p = self.params
        if choice.samples is not None:
            self._selected_conf = choice.confidence
            self._track.extend(choice.samples)
            self._late = choice.late
            if choice.confidence >= p.min_confidence:
                self._chosen_at = choice.snapshot.now
            if choice.new_track:
                self._carry_over(old_track)
                self._catch_up()
            else:
                self._catch_up(after=choice.snapshot.now)
        elif old_velocity is not None and self._hover_coasts(choice, old_track, old_velocity):
            # Deviation 77: the re-clustering found nothing against the hovering track,
            # only too little of it to confirm it again.
            self._selected_conf = p.min_confidence
            self._track.extend(old_track)
            self._late = old_late
            self._catch_up()
        if self.params.report_lag > 0 and old_track and old_conf >= self.params.min_confidence:
            core, tail = old_late.around(old_track)
            self._archive_piece([*core, *tail], old_conf, choice.snapshot.now)
        ms = self._job_ms + choice.elapsed_ms + (time.perf_counter() - start) * 1e3
        self._last_recluster_ms = ms
        self._recluster_ms_total += ms
        self._reclusters += 1

    def _hover_coasts(
        self, choice: _TrackChoice, old_track: list[_TrackSample], velocity: np.ndarray
    ) -> bool:
        """Whether the reported track ``old_track`` (fitted ``velocity``), which the
        re-clustering ``choice`` neither selected nor kept, stays the track
        (``hover_coast_seconds``): it is slower than ``min_speed``, its newest sample is
        at most ``max_gap`` old (a track without returns for longer is dropped as
        before: forgotten by the late output, not kept as lost), a re-clustering chose
        it at most ``hover_coast_seconds`` ago, and what lay near its prediction was
        noise or too few points to be a candidate, not a cluster rejected for its shape
        or motion."""
        p = self.params
        now = choice.snapshot.now
        return (
            p.hover_coast_seconds > 0
            and choice.coast
            and float(np.linalg.norm(velocity)) < p.min_speed
            and now - max(s.t for s in old_track) <= p.max_gap
            and now - self._chosen_at <= p.hover_coast_seconds
        )

    def _archive_piece(self, old_track: list[_TrackSample], confidence: float, now: float) -> None:
        """After the re-clustering of stream time ``now`` replaced the reported track
        ``old_track``: keep its samples older than the new track's first one for the frames
        still waiting for their delayed estimate (report_lag), which the new track may no
        longer reach. A track dropped (no confident track after it) is kept if it was
        lost: its newest return more than ``reacquire_window`` old, so that nothing was
        left to re-acquire. One dropped sooner was rejected by the re-clustering: it is
        forgotten, and the pieces kept before it with it, unless push() had reported it
        over at least ``report_backfill_min_run`` (:meth:`_reported_span`; deviation 93:
        what the live output held for seconds is not taken back from the late output by a
        later re-clustering). With a new track that ends before ``old_track`` did, its
        newer samples are judged the same way (:meth:`_archive_newer`)."""
        p = self.params
        current = bool(self._track) and self._selected_conf >= p.min_confidence
        samples = (*self._late.head, *self._track) if current else ()
        first = min((s.t for s in samples), default=math.inf)
        kept = sorted((s for s in old_track if s.t < first), key=lambda s: s.t)
        piece = _TrackPiece(*_sample_arrays(kept), confidence) if kept else None
        # With no current track, ``piece`` holds all of ``old_track``: rejected unless lost.
        if not current and (piece is None or not self._survives_drop(piece, now)):
            self._archive.clear()
            if piece is not None and p.report_next_dropped:
                # Deviation 133: the frames it reached wait for the next live run, as a
                # replaced track's unkept newer returns do (deviation 112), for an
                # estimate where it was.
                self._remember_unkept(piece, dropped=True)
            return
        if piece is not None:
            until = self._reported_until(piece)
            self._archive.append(dataclasses.replace(piece, reported_until=until))
        if current and p.report_keep_newer:
            self._archive_newer(old_track, confidence, now, max(s.t for s in samples))
        self._prune_archive()

    def _archive_newer(
        self, old_track: list[_TrackSample], confidence: float, now: float, last: float
    ) -> None:
        """report_keep_newer (deviation 105): the replaced track's samples newer than the
        new track's newest one ``last`` (the re-clustering chose a cluster that ended
        sooner) are kept as a dropped track's would be: if lost (the newest more than
        ``reacquire_window`` old) or if push() reported them over at least
        ``report_backfill_min_run``."""
        newer = [s for s in old_track if s.t > last]
        if not newer:
            return
        piece = _TrackPiece(*_sample_arrays(newer), confidence)
        until = self._reported_until(piece)
        if self._survives_drop(piece, now):
            self._archive.append(dataclasses.replace(piece, reported_until=until))
        else:
            self._remember_unkept(piece, until)

    def _remember_unkept(
        self, piece: _TrackPiece, until: float | None = None, dropped: bool = False
    ) -> None:
        """report_next_run: the span from ``piece``'s first sample to its newest live
        report (``until``; computed if None), if push() reported it at all. A frame in it
        that no kept track reaches when due waits for the live run after that report
        (deviation 112); for a ``dropped`` track, to be estimated where the piece was
        (deviation 133)."""
        until = self._reported_until(piece) if until is None else until
        if until > -math.inf:
            self._unkept.append((float(piece.ts[0]), until, piece if dropped else None))

    def _survives_drop(self, piece: _TrackPiece, now: float) -> bool:
        """Whether a reported track's samples ``piece``, no longer the track after the
        re-clustering of stream time ``now``, stay for the late output: lost (the newest
        more than ``reacquire_window`` old, nothing left to re-acquire) or reported by
        push() over at least ``report_backfill_min_run`` (deviation 93)."""
        p = self.params
        lost = now - float(piece.ts[-1]) > p.reacquire_window
        return lost or self._reported_span(piece) >= p.report_backfill_min_run

    def _reported_stamps(self, piece: _TrackPiece, newest_first: bool) -> Iterator[float]:
        """The stamps at which push() reported a position within ``track_gate`` of the
        piece's own (:func:`smoothed_position`) there: newest first, stopping at the first
        report before the piece's reach, or all of them in push order."""
        p = self.params
        lo, hi = piece.ts[0] - p.max_extrapolation, piece.ts[-1] + p.max_extrapolation
        reports = reversed(self._live_reports) if newest_first else iter(self._live_reports)
        for stamp, position in reports:
            if newest_first and stamp < lo:
                return
            if not lo <= stamp <= hi:
                continue
            # Judged as the live output fits a track: past returns without a velocity of
            # their own after a pause, it holds them still, where the late output follows
            # the chord across the pause (deviation 122); the same track either way.
            own = smoothed_position(piece.ts, piece.ps, piece.ws, stamp, p, chord_ends=False)
            if own is None:
                continue
            if float(np.linalg.norm(reported_positions(own, p)[0] - position)) <= p.track_gate:
                yield stamp

    def _reported_span(self, piece: _TrackPiece) -> float:
        """Seconds from the first to the last of the piece's :meth:`_reported_stamps`;
        -inf if there is none."""
        hits = list(self._reported_stamps(piece, newest_first=False))
        return max(hits) - min(hits) if hits else -math.inf

    def _reported_until(self, piece: _TrackPiece) -> float:
        """The newest stamp at which push() reported a position within ``track_gate`` of
        the piece's own (:func:`smoothed_position`) there, or -inf."""
        return next(self._reported_stamps(piece, newest_first=True), -math.inf)

    def _prune_archive(self) -> None:
        """Forget the archived pieces no frame still waiting (stamped at most
        ``report_lag`` before the newest) can take samples from."""
        p = self.params
        reach = max(p.track_window, p.link_max_gap) + max(p.max_gap, p.max_extrapolation)
        horizon = self._now - p.report_lag - p.report_backfill - reach
        while self._archive and self._archive[0].ts[-1] < horizon:
            self._archive.popleft()
        while self._unkept and self._unkept[0][1] < horizon:
            self._unkept.popleft()
        # A kept piece spans at most local_history.
        while self._live_reports and self._live_reports[0][0] < horizon - p.local_history:
            self._live_reports.popleft()

    def _expected_position(
        self, previous: tuple[np.ndarray, int] | None
    ) -> tuple[np.ndarray, float] | None:
        """(position, gate) where the reported track should be now: its fit while it
        is fresh, else, for ``reacquire_window`` seconds after its newest sample, that
        sample's position moved on at the track's velocity, with a gate widened by
        half ``link_max_accel`` times the squared time since; None otherwise."""
        p = self.params
        if previous is not None:
            return previous[0], p.track_gate
        if self._last_reported is None:
            return None
        t_last, position, velocity = self._last_reported
        dt = self._now - t_last
        if p.reacquire_window <= 0 or not 0.0 <= dt <= p.reacquire_window:
            return None
        return position + velocity * dt, p.track_gate + 0.5 * p.link_max_accel * dt * dt

    def _track_state(self) -> tuple[float, np.ndarray, np.ndarray]:
        """(newest sample time, fitted position there, velocity) of the track."""
        last = max(s.t for s in self._track)
        pred = self._predict(last)
        assert pred is not None  # the track has a sample at ``last``
        return last, pred[0], pred[3]

    def _carry_over(self, old_track: list[_TrackSample]) -> None:
        """Re-append samples the previous track had gathered between re-clusterings (gated
        returns the clusterer may now call noise) beyond the rebuilt track's newest one,
        each while it stays within ``track_gate`` of the rebuilt track's prediction. With
        ``stream_carry_gap`` (deviation 152), where the rebuilt track ends more than
        ``max_extrapolation`` before such a sample (no prediction), the sample is kept
        if it follows at most ``stream_carry_gap`` after the rebuilt track's newest
        sample and lies where the track's own motion reaches (:func:`_on_own_path`)."""
        if not self._track:
            return
        p = self.params
        gate2 = p.track_gate**2
        for sample in old_track:
            if sample.t <= self._track[-1].t:
                continue
            fit = self._fit(sample.t)
            if fit is None:
                if not (
                    sample.t - self._track[-1].t <= p.stream_carry_gap
                    and _on_own_path(self._track, sample, p)
                ):
                    break
            elif float(np.sum((sample.position - fit[0]) ** 2)) > gate2:
                break
            self._track.append(sample)

    def _catch_up(self, after: float = -math.inf) -> None:
        """Extend the rebuilt track through the history frames after its newest sample
        (and after ``after``), as :meth:`_extend_track` would have done had they arrived
        after this re-clustering (a sparse drone's newest return is often a cluster of
        its own)."""
        if not self._track:
            return
        for chunk in self._chunks:
            if chunk.stamp > max(self._track[-1].t, after) and chunk.xyz.shape[0]:
                self._extend_track(chunk.stamp, chunk.xyz, chunk.t)

    def _drop_static_from_history(self) -> None:
        """Remove points of voxels that have become static from the local history."""
        if not self._chunk_points:
            return
        # One lookup over the whole history (a chunk per frame: thousands at high rates),
        # then only the chunks that hold static points are rebuilt.
        sizes = np.fromiter((c.t.shape[0] for c in self._chunks), np.int64, len(self._chunks))
        keys = np.concatenate([c.static_keys for c in self._chunks])
        static = voxel.lookup(self._static, keys) >= 0
        if not static.any():
            return
        chunk_of = np.repeat(np.arange(sizes.size), sizes)
        ends = np.cumsum(sizes)
        for i in np.unique(chunk_of[static]):
            c = self._chunks[i]
            moving = ~static[ends[i] - sizes[i] : ends[i]]
            self._chunk_points -= int(sizes[i] - np.count_nonzero(moving))
            self._chunks[i] = _Chunk(c.stamp, c.xyz[moving], c.t[moving], c.static_keys[moving])

    def _fit(self, stamp: float, reporting: bool = False) -> tuple[np.ndarray, int] | None:
        """Position at ``stamp`` from the track's last track_window seconds of samples
        (ending at its newest sample); ``reporting``: for the estimate push() returns,
        newer samples weighing more (``track_recency``). The newest sample may be at most
        ``max_extrapolation`` old, or ``max_gap`` for a track slower than ``min_speed``
        (a hovering drone seen once a second is where it was); past its newest sample,
        a track whose samples show no motion stays where it was then (deviation 73).

        ``stamp`` is a frame's stamp, the start of its scan: the frame's own returns,
        scanned over the next ``frame_period``, are part of its estimate (deviation 56).
        """
        pred = self._predict(
            stamp, until=stamp + self.params.frame_period, hold_still=True, recent=reporting
        )
        if pred is None:
            return None
        position, n, age, velocity, measured = pred
        speed = float(np.linalg.norm(velocity))
        p = self.params
        # A velocity measured as slow, not one unknown: the first returns after a pause
        # longer than link_max_gap, all in one frame or two, tell nothing of the motion,
        # and a pass 110 m out held where they were was 10 m off within a second
        # (deviation 82).
        slow = measured and speed < p.min_speed
        limit = max(p.max_extrapolation, p.max_gap) if slow else p.max_extrapolation
        return (position, n) if age <= limit else None

    def _predict(
        self,
        stamp: float,
        until: float | None = None,
        hold_still: bool = False,
        recent: bool = False,
    ) -> tuple[np.ndarray, int, float, np.ndarray, bool] | None:
        """(position, points, age of the newest sample, velocity, whether the samples span
        the two frame periods a velocity needs) at ``stamp`` from a weighted
        fit over the samples up to ``until`` (default ``stamp``): the last track_window
        seconds of them (at least the last three), or None without such a sample. The
        age is negative when the newest sample is after ``stamp``. The fit is a straight
        line or, for a track at least ``min_speed`` fast, a quadratic when at least 6
        samples span 0.6 s (with ``track_recency``: 4 over 0.4 s, and its curvature at
        least two standard errors), the newest is at most ``max_extrapolation`` old and
        the fitted acceleration is at most ``max_accel``; past its newest sample the
        quadratic is continued along its tangent there (deviation 56). With
        ``hold_still``, a line whose samples show no motion (:attr:`_TrackFit.still`) is
        not continued past the newest sample: the position is the line's there
        (deviation 73)."""
        p = self.params
        cutoff = stamp if until is None else until
        newest = [s.t for s in self._track if s.t <= cutoff]
        if not newest:
            return None
        last = max(newest)
        fit = self._track_fit(_recent_samples(self._track, last, p), recent)
        age = stamp - last
        if fit.quadratic is not None and age <= p.max_extrapolation:
            # A well-sampled, fresh, moving track: a quadratic follows a turn or a change
            # of speed without the straight line's lag, unless its acceleration is
            # implausible. Beyond the newest sample it goes on along its tangent: the
            # curvature of a second of noisy samples is not extrapolated.
            coef = fit.quadratic
            x = stamp - fit.tc
            x_last = min(x, fit.t_newest - fit.tc)
            at_last = coef[0] + coef[1] * x_last + coef[2] * x_last * x_last
            tangent = coef[1] + 2.0 * coef[2] * x_last
            return at_last + tangent * (x - x_last), fit.points, age, fit.slope, True
        at = last if hold_still and fit.still and age > 0.0 else stamp
        return fit.mean + fit.slope * (at - fit.tc), fit.points, age, fit.slope, fit.measured

    def _track_fit(self, samples: list[_TrackSample], recent: bool = False) -> _TrackFit:
        """The fits :meth:`_predict` reads, through these samples, weighted by recency
        (``track_recency``) if ``recent``; the last one of each weighting is reused
        while the samples are the same (between a track's returns, every frame and every
        history frame a re-clustering catches up through asks for it again)."""
        p = self.params
        recent = recent and p.track_recency > 0
        cached = self._fit_cache.get(recent)
        if (
            cached is not None
            and cached.params is p
            and len(cached.samples) == len(samples)
            and all(a is b for a, b in zip(cached.samples, samples, strict=True))
        ):
            return cached
        ts, ps, counts = _sample_arrays(samples)
        ws = counts
        quad_samples, quad_span = _QUAD_SAMPLES, _QUAD_SPAN
        if recent:
            # Newer samples weigh more: a line over the whole window lags a drone that
            # starts, stops or turns, by what it did early in the window (deviation 102).
            # Only the reported estimate: which returns join the track is decided on
            # equal weights (a weaving bird followed more closely stayed a track longer).
            ws = counts * np.exp((ts - ts[-1]) / p.track_recency)
            quad_samples, quad_span = _RECENT_QUAD_SAMPLES, _RECENT_QUAD_SPAN
        slope, mean, tc = _track_line(ts, ps, ws, p)
        quadratic = None
        speed = float(np.linalg.norm(slope))
        if speed >= p.min_speed and ts.size >= quad_samples and ts[-1] - ts[0] >= quad_span:
            coef = weighted_quadratic(ts - tc, ps, ws)
            plausible = 2.0 * float(np.linalg.norm(coef[2])) <= p.max_accel
            if plausible and recent:
                # Fewer samples, weighted to the newest: the curve must stand out of the
                # samples' scatter, or a far pass's noisy returns bend the estimate.
                se = _curvature_standard_error(ts - tc, ps, ws, coef)
                plausible = float(np.linalg.norm(coef[2])) >= _CURVATURE_SIGMAS * se
            if plausible:
                quadratic = coef
        still = speed < p.min_speed and (
            speed == 0.0
            or speed < _STILL_SIGMAS * _speed_standard_error(ts, ps, ws, (slope, mean, tc))
        )
        measured = _spans_velocity(ts, p)
        fit = _TrackFit(
            tuple(samples),
            p,
            int(counts.sum()),
            slope,
            mean,
            tc,
            float(ts[-1]),
            quadratic,
            still,
            measured,
        )
        self._fit_cache[recent] = fit
        return fit

    def _extend_track(self, stamp: float, xyz: np.ndarray, t: np.ndarray) -> None:
        """Append the frame's points within ``track_gate`` of the track's predicted
        position; for a track at least ``min_speed`` fast, only those chained within
        ``track_join_link`` to the one nearest it (:func:`_nearest_group`, deviation 116).
        Association outlives reporting: a return up to ``max_gap`` after the track's
        newest one continues it, although nothing was reported in between."""
        p = self.params
        pred = self._predict(stamp)
        if pred is None:
            return
        predicted, _, age, velocity, _ = pred
        limit = max(p.max_extrapolation, p.max_gap)
        moving = float(np.linalg.norm(velocity)) >= p.min_speed
        if not moving:
            # A hovering drone seen once every second or two is still where it was.
            limit = max(limit, p.reacquire_window)
        if age > limit:
            return
        gate = p.track_gate
        d2 = np.sum((xyz.astype(np.float64) - predicted) ** 2, axis=1)
        near = np.flatnonzero(d2 <= gate**2)
        if near.size:
            if moving:
                near = near[_nearest_group(xyz[near], d2[near], p.track_join_link)]
            group = xyz[near]
            self._track.append(
                _TrackSample(float(t[near].mean()), group.mean(axis=0, dtype=np.float64), group)
            )

    def _release_delayed(self, until: float) -> None:
        """Make the delayed estimates of the waiting frames stamped at or before ``until``
        (and of the oldest ones beyond ``_MAX_LAGGED`` waiting frames), from the samples
        on both sides of each (:func:`smoothed_position`) of the reported tracks
        (:meth:`_delayed_tracks`): the first that supports one. Only where push() has
        returned an estimate since the frame's stamp: an object confirmed only after its
        returns had stopped (so never reported by push) is not reported late either.

        With ``report_backfill`` a frame push() has reported nothing since when it falls
        due waits up to that much longer for a confirmation. Such a frame (backfilled) is
        estimated once the live run holding the first live estimate after it has lasted
        ``report_backfill_min_run``, and not at all if the run ends sooner or the wait
        exceeds ``report_backfill`` (:meth:`_resolve_held`); the estimates made meanwhile
        are held back so that the output stays in stamp order. With
        ``report_hold_new_runs`` so is a frame due after the first estimate of a new
        live run when that run has lasted less than the frame is before it (at most
        ``report_backfill_min_run``; :meth:`_before_new_run`, deviation 107).

        With ``report_extend_tail`` a frame past the current track's cluster that its
        grown tail serves (:attr:`_TrackPiece.extends_until`) is estimated when due,
        whether or not push() reported anything since (deviation 99).

        With ``report_bridge`` a frame whose live run after it was too short is still
        estimated when the live output reported one track on both sides of it within
        ``link_max_gap``, the earlier report in a run that was not (deviation 101)."""
        p = self.params
        lagged = self._lagged
        wait_until = until - p.report_backfill
        tracks: list[_TrackPiece] | None = None  # built once for all frames released here
        while lagged and (lagged[0] <= until or len(lagged) > _MAX_LAGGED):
            stamp = lagged[0]
            on_tail = False  # past a track's cluster, on its grown tail (deviation 99)
            if self._late.tail and p.report_extend_tail:
                if tracks is None:
                    tracks = self._delayed_tracks()
                on_tail = any(tr.tail_from < stamp <= tr.extends_until for tr in tracks)
            waiting = self._last_live < stamp and stamp > wait_until and len(lagged) <= _MAX_LAGGED
            if waiting and not on_tail:
                # Nothing reported live since this frame, nor since the later ones due:
                # they wait for a confirmation.
                self._unreported_until = max(self._unreported_until, until)
                break
            lagged.popleft()
            bridged = False  # deviation 101: only from a track reported on both sides
            if not on_tail:  # a tail frame is estimated whatever the live output did
                if self._last_live < stamp:
                    continue
                if stamp <= self._unreported_until:
                    self._held.append(_HeldFrame(stamp))  # backfilled: resolved below
                    continue
                if self._before_new_run(stamp):
                    self._held.append(_HeldFrame(stamp, new_run=True))  # deviation 107
                    continue
                shortest = p.report_lag_min_run
                if shortest > 0 and self._live_run_seconds(stamp) < shortest:
                    if not p.report_bridge:
                        continue
                    bridged = True
            if tracks is None:
                tracks = self._delayed_tracks()
            estimate = self._tracks_estimate(stamp, tracks, bridged=bridged)
            if estimate is not None:
                self._emit_in_order(estimate)
            elif not on_tail and p.report_next_run:
                # Deviation 112: returns not kept reached this frame; it waits for the
                # live run after the one that reported them, as a frame whose run ended
                # too soon does.
                spans = [(u, piece) for t0, u, piece in self._unkept if t0 <= stamp <= u]
                if spans:
                    reported, dropped = max(spans, key=lambda span: span[0])
                    run = self._live_run(reported)
                    if run is not None:
                        held = _HeldFrame(stamp, after=_after_run(run), dropped=dropped)
                        self._held.append(held)
        self._resolve_held(until)

    def _resolve_held(self, until: float) -> None:
        """Decide each undecided held frame, on its own, and emit the held frames in
        order up to the first still undecided. A backfilled frame is estimated once its
        live run (:meth:`_live_run`; for a frame before a new run, with pauses up to
        ``link_max_gap``) has lasted :meth:`_run_needed`, dropped if the run ended
        sooner or the frame is more than ``report_backfill`` past due. A run that ended
        sooner still has its frames estimated, within that wait, from a track holding
        ``report_backfill_min_points`` returns (deviation 98). A frame is decided when
        its own run allows, from the tracks at that moment, whether or not the frames
        before it are (deviation 110). ``until`` inf (flush, reset): every frame is
        decided, a run still going taken as ended there."""
        held = self._held
        tracks: list[_TrackPiece] | None = None
        forced = len(held) - _MAX_LAGGED  # the oldest beyond _MAX_LAGGED: decided now
        for index, frame in enumerate(held):
            if frame.decided:
                continue
            tracks = self._decide_held(frame, until, index < forced, tracks)
        while held and held[0].decided:
            estimate = held.popleft().estimate
            if estimate is not None:
                self._emit(estimate)

    def _decide_held(
        self,
        frame: _HeldFrame,
        until: float,
        forced: bool,
        tracks: list[_TrackPiece] | None,
    ) -> list[_TrackPiece] | None:
        """Decide ``frame`` (of :meth:`_resolve_held`) if its live run allows; returns
        the delayed tracks, built here if needed (``tracks`` None: not yet)."""
        p = self.params
        final = math.isinf(until)
        stamp = frame.stamp
        past_due = not final and stamp <= until - p.report_backfill
        waited = past_due or forced
        while True:
            waits_next = frame.after > stamp  # deviation 110: for a run after a short one
            run = self._live_run(max(stamp, frame.after), p.link_max_gap if frame.new_run else None)
            if run is None and waits_next and not waited and not final:
                return tracks  # no live run since the short one yet
            lasted = run is not None and run[1] - run[0] >= self._run_needed(stamp, run)
            going = run is not None and run[2] and not final
            if not lasted and going and not waited:
                return tracks
            # Deviation 98: a run cut short still backfills from a well-observed track.
            short = run is not None and not going and not waited
            if lasted or (short and p.report_backfill_min_points > 0):
                if tracks is None:
                    tracks = self._delayed_tracks()
                least = 0 if lasted else p.report_backfill_min_points
                # After a short run, only from a track of the run waited for, or one
                # such a track could continue (deviation 110).
                since = run[0] if waits_next and run is not None else -math.inf
                frame.estimate = self._tracks_estimate(stamp, tracks, least, since)
                if frame.dropped is not None and not self._agrees(frame.estimate, frame.dropped):
                    frame.estimate = None
            if frame.estimate is None and short and not lasted and p.report_next_run:
                # Deviation 110: the run ended too soon; wait for the next one.
                assert run is not None
                frame.after = _after_run(run)
                continue
            frame.decided = True
            return tracks

    def _tracks_estimate(
        self,
        stamp: float,
        tracks: list[_TrackPiece],
        min_returns: int = 0,
        reported_since: float = -math.inf,
        bridged: bool = False,
    ) -> Estimate | None:
        """The delayed estimate at ``stamp`` from the first of ``tracks`` (of
        :meth:`_delayed_tracks`) that reaches it and supports one; only from a track
        holding at least ``min_returns`` returns, reported live at or after
        ``reported_since`` or continued by such a track (:meth:`_continued_in`), and with
        ``bridged`` only from one the live output reported on both sides of ``stamp``
        (:meth:`_bridges`)."""
        for track in tracks:
            if stamp > max(track.reported_until, track.extends_until):
                continue
            if track.reported_until < reported_since and not self._continued_in(
                track, tracks, reported_since
            ):
                continue
            if min_returns and track.ws.sum() < min_returns:
                continue
            if bridged and not self._bridges(stamp, track):
                continue
            estimate = self._delayed_estimate(stamp, track)
            if estimate is not None:
                return estimate
        return None

    def _continued_in(self, track: _TrackPiece, tracks: list[_TrackPiece], since: float) -> bool:
        """Whether one of ``tracks`` the live output reported at or after ``since``
        begins after ``track`` ends and could continue it (:func:`_could_continue`): a
        short live run's object is taken as confirmed by the next run only if that run
        could be the same object (deviation 110)."""
        return any(
            later.reported_until >= since
            and later.ts[0] > track.ts[-1]
            and _could_continue(track, later, self.params)
            for later in tracks
        )

    def _agrees(self, estimate: Estimate | None, piece: _TrackPiece) -> bool:
        """Deviation 133: whether ``estimate`` lies within ``track_gate`` of where the
        dropped track ``piece`` was at its stamp (:func:`smoothed_position`; not where
        the piece gives no position) and of push()'s own estimates within half a frame
        period of that stamp, if there were any: the late output confirms the object the
        live output reported there, not another one a later track holds."""
        if estimate is None:
            return False
        p = self.params
        position = smoothed_position(piece.ts, piece.ps, piece.ws, estimate.stamp, p)
        if position is None:
            return False
        where = [reported_positions(position, p)[0]]
        reports = self._live_reports
        half = 0.5 * float(p.frame_period)
        i = bisect.bisect_left(reports, estimate.stamp - half, key=lambda r: r[0])
        while i < len(reports) and reports[i][0] <= estimate.stamp + half:
            where.append(reports[i][1])
            i += 1
        gaps = np.linalg.norm(np.asarray(where) - estimate.position, axis=1)
        return bool((gaps <= p.track_gate).all())

    def _bridges(self, stamp: float, track: _TrackPiece) -> bool:
        """report_bridge: whether push() reported positions on ``track``
        (:meth:`_reported_stamps`) before and after ``stamp`` at most ``link_max_gap``
        apart, the earlier within a live run that lasted ``report_lag_min_run`` or is
        still going (deviation 101)."""
        p = self.params
        hits = np.fromiter(self._reported_stamps(track, newest_first=False), float)
        before, after = hits[hits < stamp], hits[hits > stamp]
        if not before.size or not after.size or after[0] - before[-1] > p.link_max_gap:
            return False
        run = self._live_run(float(before[-1]))
        return run is not None and (run[2] or run[1] - run[0] >= p.report_lag_min_run)

    def _emit_in_order(self, estimate: Estimate) -> None:
        """Emit ``estimate``, or hold it behind the held frames before it."""
        if self._held:
            self._held.append(_HeldFrame(estimate.stamp, estimate, decided=True))
        else:
            self._emit(estimate)

    def _emit(self, estimate: Estimate) -> None:
        self.delayed_dropped += len(self._ready) == self._ready.maxlen
        self._ready.append(estimate)

    def _live_run(self, stamp: float, gap: float | None = None) -> tuple[float, float, bool] | None:
        """(first, last stamp, still going) of the live output's run of estimates (each
        within ``gap``, default ``max_gap``, of the one before) that holds its first
        estimate at or after ``stamp``; still going: its newest estimate is the newest,
        at most ``gap`` old. None if there is no estimate at or after ``stamp``."""
        reports = self._live_reports
        gap = self.params.max_gap if gap is None else gap
        if not reports or reports[-1][0] < stamp:
            return None
        # Walk back from the newest estimate, run by run, to the earliest run ending at or
        # after ``stamp``.
        newest = reports[-1][0]
        end = start = newest
        found = (start, end)  # the earliest run ending at or after stamp so far
        for t, _ in reversed(reports):
            if start - t <= gap:
                start = t
                continue
            found = (start, end)
            if t < stamp:
                break
            end = start = t
        else:
            found = (start, end)
        run_start, run_end = found
        return run_start, run_end, run_end == newest and self._now - newest <= gap

    def _before_new_run(self, stamp: float) -> bool:
        """report_hold_new_runs (deviation 107): whether the frame at ``stamp``, with no
        live estimate within ``link_max_gap`` before it, comes before the first estimate
        of a live run (pauses up to ``link_max_gap`` inside it) that has lasted less than
        :meth:`_run_needed` so far: a bird leg the live output takes up for a moment
        must not be reported over the seconds before."""
        p = self.params
        if not p.report_hold_new_runs or p.report_backfill <= 0 or p.report_backfill_min_run <= 0:
            return False
        # The cheap test first: most frames due have a live estimate just before them.
        reports = self._live_reports
        i = bisect.bisect_left(reports, stamp, key=lambda r: r[0])
        if i > 0 and stamp - reports[i - 1][0] <= p.link_max_gap:
            return False
        run = self._live_run(stamp, p.link_max_gap)
        return run is not None and run[0] > stamp and run[1] - run[0] < self._run_needed(stamp, run)

    def _run_needed(self, stamp: float, run: tuple[float, float, bool]) -> float:
        """How long the live run ``run`` (of :meth:`_live_run`) after the frame at
        ``stamp`` must last before the frame is estimated from the history before the
        run: as long as the frame is before it, at most ``report_backfill_min_run``
        (deviation 107; a backfilled frame, more than ``report_lag`` before it, that
        long)."""
        return min(self.params.report_backfill_min_run, run[0] - stamp)

    def _live_run_seconds(self, stamp: float) -> float:
        """How long the live run of :meth:`_live_run` lasted; inf while it is still
        going, 0 if there is no estimate at or after ``stamp``."""
        run = self._live_run(stamp)
        if run is None:
            return 0.0
        return math.inf if run[2] else run[1] - run[0]

    def _delayed_tracks(self) -> list[_TrackPiece]:
        """The tracks delayed estimates come from, in order of preference: the current
        track while it is confident, then the kept pieces newest first (a track cut off
        by a later re-clustering, or lost); each preceded by the older
        pieces it continues (:func:`_continues`), without its lone stray samples
        (:func:`_stray_samples`) and then without samples of another object before it
        (:meth:`_without_unreported_head`: a stray would bend the line the gap next to it
        is judged by); once here for all the frames released together. A track, kept
        piece or current one (deviation 95), serves only frames up to the newest stamp at
        which the live output reported a position on it. Kept pieces newer than the
        current track (deviation 105) come first, the current track joined to them where
        it continues into them."""
        p = self.params
        self._prune_archive()
        pieces = list(self._archive)
        if self._track and self._selected_conf >= p.min_confidence:
            core, tail = self._late.around(self._track)
            current = _TrackPiece(*_sample_arrays([*core, *tail]), self._selected_conf)
            # Like a kept piece, only up to where the live output reported it: a track just
            # chosen that push() has not reported (yet) must not take the frames that the
            # live output reported on the track before it (deviation 95).
            reported = self._reported_stamps(current, newest_first=True)
            until = next(reported, -math.inf)
            # Past its cluster along its grown tail, once the live output reported it to
            # within max_gap of the cluster's end, over at least report_lag_min_run
            # (deviation 99).
            extends = -math.inf
            if tail and until >= core[-1].t - p.max_gap:
                since = until - p.report_lag_min_run
                if any(stamp <= since for stamp in reported):
                    extends = tail[-1].t + p.max_extrapolation
            current = dataclasses.replace(
                current, reported_until=until, extends_until=extends, tail_from=core[-1].t
            )
            if p.report_keep_newer:
                # Kept pieces newer than the current track (deviation 105) come after it,
                # as their own chains, which the current one may continue. Newer: reaching
                # past its newest sample. A piece that begins at or before it (a grown tail
                # can take the very return the piece begins with) is no older: among the
                # older pieces it was dropped, as one the current track reaches back over.
                newer = [pc for pc in pieces if pc.ts[-1] > current.ts[-1]]
                pieces = [pc for pc in pieces if pc.ts[-1] <= current.ts[-1]]
                pieces += [current, *newer]
            else:
                pieces.append(current)
        chains: list[_TrackPiece] = []
        while pieces:
            chain = pieces.pop()
            while pieces:
                older = pieces[-1].ts < chain.ts[0]
                if not older.any():
                    pieces.pop()  # the newer track reaches back over the whole piece
                    continue
                piece = pieces[-1]
                head = _TrackPiece(piece.ts[older], piece.ps[older], piece.ws[older], 0.0)
                if not _continues(head, chain, p):
                    break
                pieces.pop()
                chain = dataclasses.replace(
                    chain,
                    ts=np.concatenate([head.ts, chain.ts]),
                    ps=np.concatenate([head.ps, chain.ps]),
                    ws=np.concatenate([head.ws, chain.ws]),
                    reported_until=max(chain.reported_until, piece.reported_until),
                )
            chains.append(self._without_unreported_head(_without_strays(chain, p)))
        return chains

    def _without_unreported_head(self, chain: _TrackPiece) -> _TrackPiece:
        """``chain`` without its samples before the newest gap longer than
        ``report_head_gap`` across which the object could not have gone on
        (:func:`_could_continue`) and before which the live output never reported it
        (:meth:`_reported_until`): a re-clustering's linking can join another object's
        earlier returns to the drone's cluster, and the late output then reported them
        (deviation 85; since deviation 91 also at gaps shorter than ``max_gap``: a bird's
        returns 0.9 s before the drone's first, in the cluster confirmed later); then,
        with ``report_head_path``, without its samples before its first live report that
        lie off the path the later ones trace back (:func:`_off_path_before`, deviation
        103)."""
        p = self.params
        for k in np.flatnonzero(np.diff(chain.ts) > p.report_head_gap)[::-1] + 1:
            earlier = _TrackPiece(chain.ts[:k], chain.ps[:k], chain.ws[:k], 0.0)
            later = _TrackPiece(chain.ts[k:], chain.ps[k:], chain.ws[k:], 0.0)
            if _could_continue(earlier, later, p) or self._reported_until(earlier) > -math.inf:
                continue
            chain = dataclasses.replace(chain, ts=later.ts, ps=later.ps, ws=later.ws)
            break
        if not p.report_head_path:
            return chain
        # Before its first live report, the samples off the path the later ones trace
        # back: a cluster that began with another object's returns where they met the
        # drone's path (deviation 103).
        first = next(self._reported_stamps(chain, newest_first=False), None)
        start = 0 if first is None else int(np.searchsorted(chain.ts, first))
        if start <= 0 or start >= chain.ts.size:
            return chain
        keep = ~_off_path_before(chain.ts, chain.ps, chain.ws, start, p)
        if keep.all():
            return chain
        return dataclasses.replace(chain, ts=chain.ts[keep], ps=chain.ps[keep], ws=chain.ws[keep])

    def _delayed_estimate(self, stamp: float, piece: _TrackPiece) -> Estimate | None:
        """The delayed estimate at ``stamp`` from one track's samples, or None where they
        do not support one."""
        p = self.params
        ts, ps, ws = piece.ts, piece.ps, piece.ws
        position = smoothed_position(ts, ps, ws, stamp, p)
        if position is None:
            return None
        n = int(ws[np.abs(ts - stamp) <= p.track_window].sum())
        if n < p.min_points:
            return None
        return Estimate(stamp, reported_positions(position, p)[0], piece.confidence, n)

    def _estimate(self, stamp: float) -> Estimate | None:
        p = self.params
        if not self._track or self._selected_conf < p.min_confidence:
            return None
        if stamp - self._origin < p.warmup:
            return None
        fit = self._fit(stamp, reporting=True)
        if fit is None:
            return None
        position, n = fit
        if n < p.min_points:
            return None
        return Estimate(stamp, reported_positions(position, p)[0], self._selected_conf, n)


def _off_static(
    static: np.ndarray, keys: np.ndarray, *arrays: np.ndarray
) -> tuple[np.ndarray, ...]:
    """The rows of ``arrays`` whose ``static_voxel`` ``keys`` are not in the sorted
    ``static`` keys (the arrays themselves when none is)."""
    rows = np.flatnonzero(voxel.lookup(static, keys) < 0)
    if rows.size == keys.size:
        return arrays
    return tuple(a.take(rows, axis=0) for a in arrays)


def _recluster_snapshot(snap: _HistorySnapshot) -> _TrackChoice:
    """One re-clustering (reads only the snapshot and updates only its persistence map, so
    it may run on another thread): the pending hits enter the map, the history without
    its static points is clustered and scored, and the track is the best selected
    candidate that was seen last or, failing that, the reported track's cluster if
    hysteresis keeps it."""
    start = time.perf_counter()
    p = snap.params
    snap.grid.update(snap.hit_keys, snap.hit_times, snap.now)
    static = snap.grid.static_keys(watched_since=snap.watched_since)
    xyz, t = snap.xyz, snap.t
    if xyz is not None and snap.static_keys is not None and p.static_suppression and static.size:
        xyz, t = _off_static(static, snap.static_keys, xyz, t)
    structure = static if p.static_suppression else None
    dropped = snap.dropped
    if dropped is not None and structure is not None and structure.size:
        dropped = _off_static(structure, dropped[2], *dropped)

    pool = None  # report_extend_head: the points a chosen track may grow back into

    def choice(
        mask: np.ndarray | None, confidence: float, new: bool, k: int, coast: bool = False
    ) -> _TrackChoice:
        reported = snap.track_path if p.stream_track_agree else None
        if mask is not None and p.stream_segment_contact:
            mask = _off_structure_segments(mask, xyz, t, structure, p, snap.track_path)
        samples = None if mask is None else _track_samples(mask, xyz, t, p, reported)
        head: tuple[_TrackSample, ...] = ()
        tail: tuple[_TrackSample, ...] = ()
        inner: tuple[_TrackSample, ...] = ()
        if samples and pool is not None:
            grow = (mask, pool, xyz, t)
            if dropped is not None and dropped[1].size:
                # report_denoised: the denoise's dropped points are growth-only.
                grow = _with_growth_only(grow, dropped[0], dropped[1])
            fill = grow  # the fill reads the returns above the floor only
            short = None
            if snap.floor is not None:
                # report_below_floor: growth-only, and only across max_extrapolation.
                ends = np.array([samples[0].position, samples[-1].position])
                fxyz, ft = transient_below_floor(*snap.floor, ends, p)
                if ft.size:
                    short = np.arange(grow[3].size + ft.size) >= grow[3].size
                    grow = _with_growth_only(grow, fxyz, ft)
            head, tail = _grown_ends(*grow, samples, p, short)
            gmask, gpool, gxyz, gt = fill
            tail = _short_of_structure(tail, structure, p)
            if p.report_fill:
                fpool = gpool
                if p.report_fill_clustered:
                    # Any cluster's returns within track_gate of the chord, as offline
                    # fills a track: a bird crossing a sparse hover took the hover's
                    # returns of the next seconds into its cluster (deviation 129).
                    fpool = np.ones(gpool.shape, dtype=bool)
                inner = _filled_gaps(gmask, fpool, gxyz, gt, p)
        ms = (time.perf_counter() - start) * 1e3
        n = 0 if t is None else int(t.size)
        return _TrackChoice(
            snap,
            static,
            samples,
            confidence,
            new,
            k,
            n,
            ms,
            coast,
            late=_LateSamples(head, tail, inner),
        )

    if xyz is None or t is None or t.size == 0:
        return choice(None, 0.0, False, 0)
    # Clusters are scored with streaming's own smallest candidate size and acceleration
    # ramp (deviation 150).
    ps = p.copy(min_cluster_points=p.stream_min_cluster_points, smooth_accel=p.stream_smooth_accel)
    linking = p.copy(link_max_dv=p.stream_link_max_dv)
    labels, k = global_clusters(xyz, t, linking, passes=p.stream_link_passes)
    tight_hover = None  # deviation 96, on while it asks fewer frames than hover_min_frames
    if p.hover_detection and p.stream_hover_min_frames < p.hover_min_frames:
        tight_hover = (p.stream_hover_min_frames, p.stream_hover_max_extent)
        if k:
            # A tight hover's lone returns, left as noise, count towards its frames.
            extent = float(p.stream_hover_max_extent)
            labels = absorb_colocated_noise(labels, xyz, extent, extent / 2)
    if not k:
        return choice(None, 0.0, False, k, coast=True)
    # Windows aligned to the stream's first stamp (deterministic), unless the stream's
    # clock jumped so far that the offsets would not fit an int64.
    t0 = snap.origin if 0 <= t.min() - snap.origin < 1e9 else None
    first = float(t[labels >= 0].min())
    scorer = functools.partial(
        score_clusters,
        t0=t0 if t0 is not None else first,
        coherence_origin=first,
        min_track_seconds=p.stream_min_track_seconds,
        structure_keys=structure,
        tight_hover=tight_hover,
    )
    scores = scorer(labels, xyz, t, ps, n_clusters=k)
    if p.split_merged:
        tracked = None
        if (
            p.split_contact_tracked
            and p.split_contact_apart
            and snap.expected is not None
            and snap.track_from is not None
            and snap.now - snap.track_from >= p.min_track_seconds
        ):
            c = _track_cluster(*snap.expected, labels, xyz, t, snap.now - p.track_window)
            tracked = None if c is None else np.array([c])
        labels, k, scores, _ = split_and_score(
            labels,
            xyz,
            t,
            scores,
            ps,
            scorer,
            structure,
            p.stream_split_min_extent,
            excess_residual=p.stream_split_excess_residual,
            excess_min_points=3 * ps.min_cluster_points,
            apart=p.split_apart,
            contact_apart=p.split_contact_apart,
            tracked=tracked,
        )
    if p.report_lag > 0 and (p.report_extend_head or p.report_extend_tail or p.report_fill):
        # Noise and clusters too small to be judged alone, as offline grows into.
        pool = (labels < 0) | (scores.n_points < ps.min_cluster_points)[np.maximum(labels, 0)]
    chosen = select_clusters(scores, ps)
    if chosen:
        # The selected cluster that was seen last is the one being tracked.
        best = max(chosen[:3], key=lambda c: scores.t_last[c])
        # The cluster holding the reported track's recent points near its prediction.
        reported = None
        if snap.expected is not None and (p.reacquire_join or p.stream_keep_reported):
            reported = _track_cluster(*snap.expected, labels, xyz, t, snap.now - p.track_window)
        if p.reacquire_join and snap.expected is not None and snap.newest is not None:
            # The selected cluster (the reported track's earlier returns) ended before a
            # fragment near where the track would be now began.
            c = reported
            if c is None and p.reacquire_newest:
                # Deviation 140: a sparse track's newest returns (an Avia's bursts 95 m
                # up) lie behind where it would be now, outside track_gate.
                c = _newest_cluster(snap, labels, xyz, t, p)
            if c is not None and c != best and scores.t_first[c] > scores.t_last[best]:
                joined = _joined_track(best, c, labels, xyz, t, k, scorer, ps, structure)
                if joined is not None:
                    return choice(joined[0], max(joined[1], float(p.min_confidence)), True, k)
            if p.reacquire_compete:
                # Another object ranks first; the reported track, joined across its gap,
                # competes with it as a candidate of its own.
                kept = _competing_track(
                    best, snap, labels, xyz, t, k, scores, scorer, ps, structure
                )
                if kept is not None:
                    return choice(kept[0], kept[1], True, k)
        if p.stream_keep_reported and _kept_over(reported, best, snap.now, scores, p):
            # Deviation 139: another object's cluster ranks first while the reported
            # track's own cluster, a hover's the drone is leaving, still passes the
            # hysteresis.
            return choice(labels == reported, float(p.min_confidence), False, k)
        return choice(labels == best, float(scores.confidence[best]), True, k)
    if p.keep_confidence >= p.min_confidence or snap.expected is None:
        return choice(None, 0.0, False, k)
    # Hysteresis: the cluster holding the reported track's recent points continues it
    # if it passes the gates with keep_confidence (reported at min_confidence: the track
    # was confirmed, its evidence is weaker now).
    predicted, gate = snap.expected
    c = _track_cluster(predicted, gate, labels, xyz, t, snap.now - p.track_window)
    if c is None:
        return choice(None, 0.0, False, k, coast=True)
    if _passes_keep(scores, c, p):
        return choice(labels == c, float(p.min_confidence), False, k)
    if p.split_merged and p.stream_split_track:
        # The reported track's cluster fails: another object may have joined it.
        mask = _split_track(c, labels, xyz, t, snap, scorer, ps)
        if mask is not None:
            return choice(mask, float(p.min_confidence), False, k)
    if p.hover_detection and p.hover_keep_frames < p.hover_min_frames:
        # A hovering drone 10-20 m away leaves about as many frames in the history as
        # hover_min_frames asks: once reported, fewer suffice.
        mask = _hovering_track(c, predicted, labels, xyz, t, k, scorer, ps)
        if mask is not None:
            return choice(mask, float(p.min_confidence), False, k)
    if p.reacquire_join:
        # The cluster holding the track's newest returns.
        o = _newest_cluster(snap, labels, xyz, t, p)
        if o is not None and o != c:
            joined = _joined_track(o, c, labels, xyz, t, k, scorer, ps, structure)
            if joined is not None:
                return choice(joined[0], float(p.min_confidence), False, k)
    sparse = scores.n_points[c] < ps.min_cluster_points
    return choice(None, 0.0, False, k, coast=bool(sparse))


#: Samples a rebuilt track must share with the reported one for deviation 115 to judge
#: it by the reported track (it continues that track).
_SHARED_SAMPLES = 3


def _track_samples(
    mask: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    params: ParamSet,
    reported: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> list[_TrackSample]:
    """A track from the points in ``mask``: one sample per half frame period (of a half
    frame whose returns span more than ``track_join_link``, its largest group,
    :func:`_main_group`, deviation 116), skipping a sample that no object could have
    reached from the sample kept before it (deviation 39), and, within
    ``track_window`` of the newest return, one off the path of the samples kept before
    it (:func:`_on_own_path`, deviation 60). With ``reported`` (the reported track's
    sample times and positions, stream_track_agree), when the new samples hold some of
    the reported track's own, one that lies more than ``track_gate`` from where the
    reported track was at its time (between two of its samples at most
    ``link_max_gap`` apart) is another object's (deviation 115)."""
    pts, tt = xyz[mask], t[mask]
    if tt.size == 0:
        return []
    half = params.frame_period / 2
    bins = np.floor((tt - tt.min()) / half + 1e-6).astype(np.int64)
    order = np.argsort(bins, kind="stable")
    bins, pts, tt = bins[order], pts[order], tt[order]
    cuts = np.nonzero(np.diff(bins))[0] + 1
    newest = float(tt.max())
    groups = np.split(np.arange(bins.size), cuts)
    link = params.track_join_link
    if link > 0.0:
        # A bin's returns spread wider than a drone are not all the drone's: its mean
        # lay between the drone and a noise return 10 m off, and the drone's next
        # samples then failed the path check (deviation 116).
        starts = np.r_[0, cuts]
        spread = np.maximum.reduceat(pts, starts, axis=0) - np.minimum.reduceat(pts, starts, axis=0)
        for i in np.flatnonzero(np.linalg.norm(spread, axis=1) > link):
            near = pts[groups[i - 1]].mean(axis=0, dtype=np.float64) if i > 0 else None
            groups[i] = groups[i][_main_group(pts[groups[i]], link, near)]
    times = np.array([tt[idx].mean() for idx in groups])
    means = np.array([pts[idx].mean(axis=0, dtype=np.float64) for idx in groups])
    conflict = _off_reported(times, means, reported, params)
    samples: list[_TrackSample] = []
    for i, idx in enumerate(groups):
        if conflict[i]:
            continue
        sample = _TrackSample(float(times[i]), means[i], pts[idx])
        if samples:
            # A sample farther from the one kept before than track_gate plus
            # link_max_speed allows is another object the linking joined to the cluster
            # (a bird's returns at its end would become the track's newest).
            last = samples[-1]
            reach = params.track_gate + params.link_max_speed * (sample.t - last.t)
            if float(np.sum((sample.position - last.position) ** 2)) > reach * reach:
                continue
            if sample.t >= newest - params.track_window and not _on_own_path(
                samples, sample, params
            ):
                continue
        samples.append(sample)
    return samples


def _linked_components(points: np.ndarray, link: float) -> np.ndarray:
    """(N,) component label of each of a few ``points``: chained by steps of at most
    ``link`` (single linkage)."""
    pts = points.astype(np.float64)
    adjacent = np.sum((pts[:, None, :] - pts[None, :, :]) ** 2, axis=2) <= link * link
    return connected_components(csr_matrix(adjacent), directed=False)[1]


def _nearest_group(points: np.ndarray, d2: np.ndarray, link: float) -> np.ndarray:
    """Indices of ``points`` chained to the one with the smallest ``d2`` (squared distance
    to a predicted position) by steps of at most ``link``; all of them when ``link`` is
    0 or they span no more than it (deviation 116)."""
    n = points.shape[0]
    if n == 1 or link <= 0.0 or float(np.linalg.norm(np.ptp(points, axis=0))) <= link:
        return np.arange(n)
    labels = _linked_components(points, link)
    return np.flatnonzero(labels == labels[int(np.argmin(d2))])


def _main_group(points: np.ndarray, link: float, near: np.ndarray | None) -> np.ndarray:
    """Indices of the largest group of ``points`` chained by steps of at most ``link``
    (> 0); of equal ones, the one whose mean is nearest ``near`` (if given); deviation
    116. :func:`_track_samples` calls it only for half frames wider than ``link``."""
    labels = _linked_components(points, link)
    ids, sizes = np.unique(labels, return_counts=True)
    best = ids[sizes == sizes.max()]
    if best.size > 1 and near is not None:
        pts = points.astype(np.float64)
        d = [float(np.sum((pts[labels == k].mean(axis=0) - near) ** 2)) for k in best]
        best = best[[int(np.argmin(d))]]
    return np.flatnonzero(labels == best[0])


def _off_reported(
    times: np.ndarray,
    means: np.ndarray,
    reported: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
    params: ParamSet,
) -> np.ndarray:
    """(S,) bool: the samples (``times``, ``means``) that contradict the reported track
    (deviation 115, :func:`_track_samples`): if at least :data:`_SHARED_SAMPLES` of them
    are the reported track's own (same time and place), those more than ``track_gate``
    from where it was, linearly between two of its samples at most ``link_max_gap``
    apart, and, with ``stream_carry_gap`` (deviation 152), those within ``link_max_gap``
    after its newest sample that its own straight-line motion does not reach
    (:func:`_reaches`: ``track_gate`` plus ``link_max_accel`` x dt^2 / 2). All False
    otherwise: another object chosen is not judged by the old track."""
    out = np.zeros(times.size, dtype=bool)
    if reported is None or times.size == 0 or reported[0].size < 2:
        return out
    order = np.argsort(reported[0], kind="stable")  # in time order already, as a rule
    rt, rp = reported[0][order], reported[1][order]
    # Shared: a sample within 1 ms and 1 cm of one of the reported track's.
    j = np.clip(np.searchsorted(rt, times), 1, rt.size - 1)
    near = np.where(np.abs(rt[j - 1] - times) <= np.abs(rt[j] - times), j - 1, j)
    same = (np.abs(rt[near] - times) < 1e-3) & (np.linalg.norm(rp[near] - means, axis=1) < 0.01)
    if np.count_nonzero(same) < _SHARED_SAMPLES:
        return out
    # Where the reported track was: between its samples j - 1 and j.
    inside = (times > rt[0]) & (times < rt[-1])
    gap = rt[j] - rt[j - 1]
    bracketed = inside & (gap <= params.link_max_gap) & (gap > 0)
    w = np.where(bracketed, (times - rt[j - 1]) / np.where(gap > 0, gap, 1.0), 0.0)
    where = rp[j - 1] + w[:, None] * (rp[j] - rp[j - 1])
    off = np.linalg.norm(means - where, axis=1) > params.track_gate
    out = bracketed & off & ~same
    if params.stream_carry_gap > 0:
        # Deviation 152: within link_max_gap after its newest sample, where the reported
        # track's own motion does not reach.
        after = np.flatnonzero((times > rt[-1]) & (times - rt[-1] <= params.link_max_gap))
        recent = _recent_mask(rt, float(rt[-1]), params)
        ts, ps, ws = rt[recent], rp[recent], reported[2][order][recent]
        for i in after:
            out[i] = not _motion_reaches(ts, ps, ws, float(times[i]), means[i], params)
    return out


def _after_run(run: tuple[float, float, bool]) -> float:
    """The stamp from which the live run after ``run`` (of
    :meth:`StreamingDetector._live_run`) is looked for: just past its last estimate."""
    return math.nextafter(run[1], math.inf)


def _with_growth_only(
    arrays: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    xyz: np.ndarray,
    t: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(mask, pool, xyz, t) with the returns ``xyz``, ``t`` appended as growth-only
    points: in the pool, not of the track."""
    mask, pool, pxyz, pt = arrays
    return (
        np.concatenate([mask, np.zeros(t.size, bool)]),
        np.concatenate([pool, np.ones(t.size, bool)]),
        np.concatenate([pxyz, xyz]),
        np.concatenate([pt, t]),
    )


def _grown_ends(
    mask: np.ndarray,
    pool: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    samples: list[_TrackSample],
    params: ParamSet,
    short_gap: np.ndarray | None = None,
) -> tuple[tuple[_TrackSample, ...], tuple[_TrackSample, ...]]:
    """(head, tail): the samples the track of ``samples``, rebuilt from the cluster of
    ``mask``, grows into before its first sample (report_extend_head) and after its
    newest (report_extend_tail), :func:`_grown`. Each end grows from the track's own
    samples, not from the cluster's end: the cluster's returns beyond them are those the
    rebuilt track left out (deviations 39, 60 and 115), and grown from there the tail
    followed a bird that crossed the drone's path (deviation 117). Those returns may
    still be taken, as the pool's are, where the track was heading (the drone's own,
    left out behind a sample another object's returns had moved). ``short_gap``: pool
    points that join only within ``max_extrapolation`` of the end (the returns below the
    floor)."""
    half = params.frame_period / 2
    head: tuple[_TrackSample, ...] = ()
    tail: tuple[_TrackSample, ...] = ()
    if params.report_extend_head:
        own = mask & (t >= samples[0].t - half)
        head = _grown(own, pool | (mask & ~own), xyz, t, samples[0].t, params, False, short_gap)
    if params.report_extend_tail:
        own = mask & (t <= samples[-1].t + half)
        tail = _grown(own, pool | (mask & ~own), xyz, t, samples[-1].t, params, True, short_gap)
    return head, tail


def _grown(
    mask: np.ndarray,
    pool: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    edge: float,
    params: ParamSet,
    forward: bool,
    short_gap: np.ndarray | None = None,
) -> tuple[_TrackSample, ...]:
    """report_extend_tail (``forward``) / report_extend_head: the samples beyond ``edge``
    (the track's newest sample, after it; else its first, before it) of the points in
    ``pool`` the track of ``mask`` grows into at that end (:func:`extend_track`, one end
    only)."""
    if not mask.any():
        # The track's samples lie off its points' stamps (a stamp so large that the
        # frame-sample bins round it away): nothing to grow from.
        return ()
    span = max(params.link_fit_window, params.link_max_gap)
    # Only what the growth reads: the pool beyond the track's end and the track's
    # seconds there, whose line the growth starts from.
    if forward:
        end = float(t[mask].max())
        grow, own = pool & (t > end), mask & (t >= end - span)
    else:
        end = float(t[mask].min())
        grow, own = pool & (t < end), mask & (t <= end + span)
    if not grow.any():
        return ()
    # Toward a far lone return (extend_far_gap), the tail only (report_extend_far,
    # deviation 122); the growth then also reads every other return, as offline's does,
    # to tell whether something returned from that spot a second before or after it.
    # Not the head: on fast passes such a return was often something else's near the
    # line, and the late output reported a second of it (fast_pass, 212 runs the growth
    # changed: other objects 1.34% -> 0.27% of the time without it, detection 92.7% ->
    # 92.2%).
    far = forward and params.report_extend_far
    sub = slice(None) if far else np.flatnonzero(grow | own)
    grown = extend_track(
        own[sub],
        xyz[sub],
        t[sub],
        grow[sub],
        # Braking into a hover beyond extend_max_gap only with report_extend_brake.
        params.copy(
            extend_brake_hover=params.extend_brake_hover and params.report_extend_brake,
            **({} if far else {"extend_far_gap": 0.0}),
        ),
        short_gap=None if short_gap is None else short_gap[sub],
        grow_end=forward,
        grow_start=not forward,
    )
    new = grown & ~own[sub]
    if not new.any():
        return ()
    samples = _track_samples(new, xyz[sub], t[sub], params)
    return tuple(s for s in samples if (s.t > edge if forward else s.t < edge))


def _off_structure_segments(
    mask: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    structure: np.ndarray | None,
    params: ParamSet,
    path: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """stream_segment_contact (deviation 143): ``mask`` without its segments (its returns
    cut where they are more than ``max_gap`` apart) of which more than
    ``hover_max_contact`` lie in or next to a voxel of the sorted static ``structure``
    keys (:func:`structure_contact`), unless that is all of them: a swaying crown's
    edge the clusterer linked to a drone's cluster after the drone's returns stopped.
    With ``stream_segment_own`` and ``path`` (the reported track's sample times and
    positions), a segment whose centre lies within ``hover_max_extent`` of one of the
    track's samples is kept: a hover's own voxels turn static (deviation 146)."""
    limit = float(params.hover_max_contact)
    if limit >= 1.0 or structure is None or structure.size == 0 or not mask.any():
        return mask
    idx = np.flatnonzero(mask)
    runs = gap_runs(t[idx], params.max_gap)
    if len(runs) < 2:
        return mask
    k = len(runs)
    idx = idx[np.concatenate(runs)]
    sizes = np.array([run.size for run in runs])
    segment = np.repeat(np.arange(k), sizes)
    pts = xyz[idx].astype(np.float64)
    share = structure_contact(segment, pts, k, np.ones(k, bool), structure, params.static_voxel)
    touching = share > limit
    if touching.any() and path is not None and path[1].size and params.stream_segment_own:
        # A hover's own voxels turn static: a segment where the reported track has been
        # is the track's, whatever it touches (deviation 146). The rule keeps what the
        # track had not reached out of it; it does not take back what it reported.
        centre = np.add.reduceat(pts, np.r_[0, np.cumsum(sizes)[:-1]], axis=0) / sizes[:, None]
        d = np.linalg.norm(centre[:, None, :] - path[1][None, :, :], axis=2).min(axis=1)
        touching &= d > float(params.hover_max_extent)
    if not touching.any() or touching.all():
        return mask
    out = mask.copy()
    out[idx[touching[segment]]] = False
    return out


def _short_of_structure(
    samples: tuple[_TrackSample, ...], structure: np.ndarray | None, params: ParamSet
) -> tuple[_TrackSample, ...]:
    """report_grow_max_contact: the grown tail ``samples`` (time order, after the track's
    newest sample) before the first one with more than that share of its returns in or
    next to a voxel of the sorted static ``structure`` keys (:func:`structure_contact`):
    a swaying crown's edge the growth went on into after the drone left."""
    limit = float(params.report_grow_max_contact)
    if not samples or limit >= 1.0 or structure is None or structure.size == 0:
        return samples
    sizes = [s.points.shape[0] for s in samples]
    pts = np.concatenate([s.points for s in samples]).astype(np.float64)
    which = np.repeat(np.arange(len(samples)), sizes)
    share = structure_contact(
        which, pts, len(samples), np.ones(len(samples), bool), structure, params.static_voxel
    )
    touching = np.flatnonzero(share > limit)
    return samples[: touching[0]] if touching.size else samples


def _filled_gaps(
    mask: np.ndarray, pool: np.ndarray, xyz: np.ndarray, t: np.ndarray, params: ParamSet
) -> tuple[_TrackSample, ...]:
    """report_fill: the samples of the points in ``pool`` that fill the track of ``mask``
    inside (:func:`~.linking.fill_track`, as offline fills a selected track, within at
    most ``track_gate`` of the chord), only those in a gap between the track's returns
    longer than ``max_gap``, where the late output's estimate from its own samples stops
    (a far pass's single returns between the frames the clustering kept; deviation 100).
    Over 729 runs, filling every gap changed as much and no more (39 runs with only the
    RMSE changed instead of 21, and a bird's track filled and reported in one), and the
    linking reach alone (3.5 m at a 2 s gap) took a circling bird's returns into the
    drone's track where the cap keeps them out (`birds`: other objects 3.92% against
    3.83% of the time)."""
    own = np.unique(t[mask])
    if own.size < 2 or float(np.diff(own).max()) <= params.max_gap:
        return ()
    filled = fill_track(mask, xyz, t, pool, params, max_reach=params.track_gate) & ~mask
    idx = np.flatnonzero(filled)
    if idx.size == 0:
        return ()
    after = np.clip(np.searchsorted(own, t[idx]), 1, own.size - 1)
    filled[idx[own[after] - own[after - 1] <= params.max_gap]] = False
    if not filled.any():
        return ()
    return tuple(_track_samples(filled, xyz, t, params))


def _on_own_path(kept: list[_TrackSample], sample: _TrackSample, params: ParamSet) -> bool:
    """Whether ``sample`` lies where the kept samples' own straight-line motion (over the
    last ``track_window`` of them, at least the last three within ``link_max_gap``)
    puts it, within ``track_gate`` plus ``link_max_accel`` x dt^2 / 2 for the time dt since
    the newest of them (deviation 60). True while their motion is unknown (spanning less
    than two frame periods)."""
    ts, ps, ws = _sample_arrays(_recent_samples(kept, kept[-1].t, params))
    return _motion_reaches(ts, ps, ws, sample.t, sample.position, params)


def _motion_reaches(
    ts: np.ndarray,
    ps: np.ndarray,
    ws: np.ndarray,
    t: float,
    position: np.ndarray,
    params: ParamSet,
) -> bool:
    """Whether ``position`` at ``t`` lies where the straight-line motion of a track's
    recent samples (``ts`` in time order, ``ps``, weights ``ws``) reaches from the newest
    of them (:func:`_reaches`); True while their motion is unknown (spanning less than
    two frame periods)."""
    if not _spans_velocity(ts, params):
        return True
    return _reaches(ts, ps, ws, float(ts[-1]), t, position, params)


def _reaches(
    ts: np.ndarray,
    ps: np.ndarray,
    ws: np.ndarray,
    since: float,
    t: float,
    position: np.ndarray,
    params: ParamSet,
) -> bool:
    """Whether the straight line through track samples (:func:`_track_line`), carried to
    ``t``, passes within ``track_gate`` plus ``link_max_accel`` x (t - since)^2 / 2 of
    ``position``: an object on that path at ``since`` could be there at ``t``."""
    p = params
    slope, mean, tc = _track_line(ts, ps, ws, p)
    dt = t - since
    reach = p.track_gate + 0.5 * p.link_max_accel * dt * dt
    return float(np.linalg.norm(mean + slope * (t - tc) - position)) <= reach


def _off_path_before(
    ts: np.ndarray, ps: np.ndarray, ws: np.ndarray, start: int, params: ParamSet
) -> np.ndarray:
    """(S,) bool: the track samples (times ``ts`` ascending) before index ``start`` that
    lie off the path the samples after them trace back in time. Walking back from
    ``start``, each sample is judged by the straight line through the kept samples after
    it (the first ``track_window`` of them, at least the first three within
    ``link_max_gap``, as :func:`_recent_samples` takes the last ones) and kept if an
    object on that line could have been there (:func:`_reaches`), while the line spans
    less than two frame periods, or when the next sample (kept or not) comes more than
    ``max_gap`` after it: deviation 60's own-path test, backward (deviation 103)."""
    p = params
    off = np.zeros(ts.size, dtype=bool)
    span = max(p.track_window, p.link_max_gap)
    kept = list(range(ts.size - 1, start - 1, -1))  # newest first: kept[-1] is the earliest
    for i in range(start - 1, -1, -1):
        if ts[i + 1] - ts[i] > p.max_gap:
            # Across a gap in the returns longer than max_gap a line carried back says
            # little: a drone 70 m up that turned in the 1.7 s before its next return
            # was 9 m off it.
            kept.append(i)
            continue
        earliest = float(ts[kept[-1]])
        recent = []
        for k in reversed(kept):
            if ts[k] > earliest + p.track_window:
                break
            recent.append(k)
        if len(recent) < 3:
            recent = [k for k in reversed(kept[-3:]) if ts[k] <= earliest + span]
        idx = np.asarray(recent)
        if _spans_velocity(ts[idx], p) and not _reaches(
            ts[idx], ps[idx], ws[idx], earliest, float(ts[i]), ps[i], p
        ):
            off[i] = True
            continue
        kept.append(i)
    return off


def _track_cluster(
    predicted: np.ndarray,
    gate: float,
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    since: float,
    until: float = math.inf,
) -> int | None:
    """The cluster holding most of the points from ``since`` (to ``until``) within
    ``gate`` of ``predicted``, or None."""
    recent = (t >= since) & (t <= until) & (labels >= 0)
    near = recent & (np.sum((xyz.astype(np.float64) - predicted) ** 2, axis=1) <= gate**2)
    if not near.any():
        return None
    return int(np.bincount(labels[near]).argmax())


def _sample_cluster(
    sample_t: float,
    position: np.ndarray,
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    params: ParamSet,
) -> int | None:
    """The cluster of ``labels`` holding a track sample's returns (those of the
    ``track_window`` up to ``sample_t`` within ``track_gate`` of ``position``), or None."""
    window = params.track_window
    return _track_cluster(position, params.track_gate, labels, xyz, t, sample_t - window, sample_t)


def _newest_cluster(
    snap: _HistorySnapshot,
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    params: ParamSet,
) -> int | None:
    """The cluster of ``labels`` holding the reported track's newest returns
    (:func:`_sample_cluster` of its newest sample), or None (also without a reported
    track)."""
    if snap.newest is None:
        return None
    t_last, position = snap.newest
    return _sample_cluster(t_last, position, labels, xyz, t, params)


def _split_track(
    c: int,
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    snap: _HistorySnapshot,
    scorer: Any,
    params: ParamSet,
) -> np.ndarray | None:
    """Points of the kinematic track (:func:`~.splitting.kinematic_tracks`) of cluster
    ``c`` that continues the reported track (``snap``): it holds most of the cluster's
    returns of the last ``track_window`` near the track's expected position, and most of
    those near its newest sample in the ``track_window`` before that, begins within
    ``track_window`` of its oldest sample or with at most :data:`_SPLIT_OLDER_SHARE` of
    the track's samples before it (:func:`_few_before`), and alone is a candidate with
    ``keep_confidence``. For a reported drone's cluster that another object joined,
    too narrow and smooth for the split of merged clusters (deviation 111); else None."""
    if snap.expected is None or snap.newest is None or snap.track_from is None:
        return None
    member = np.flatnonzero(labels == c)
    xm, tm = xyz[member], t[member]
    pieces = kinematic_tracks(xm, tm, params)
    n = int(pieces.max()) + 1 if pieces.size else 0
    if n < 2:
        return None
    predicted, gate = snap.expected
    window = params.track_window
    piece = _track_cluster(predicted, gate, pieces, xm, tm, snap.now - window)
    if piece is None:
        return None
    # The piece must be the track's continuation, not another object that came near where
    # it was heading: it holds the track's newest returns and reaches back to its oldest
    # (or to the cluster's first, if the history holds less).
    if _newest_cluster(snap, pieces, xm, tm, params) != piece:
        return None
    begins = float(tm[pieces == piece].min())
    if begins > max(snap.track_from, tm.min()) + window and not _few_before(snap, begins - window):
        return None
    scores = scorer(pieces, xm, tm, params, n_clusters=n)
    if not _passes_keep(scores, piece, params):
        return None
    mask = np.zeros(labels.size, dtype=bool)
    mask[member[pieces == piece]] = True
    return mask


#: Largest share of the reported track's samples that may lie before the start of the
#: piece continuing it (:func:`_split_track`, deviation 119).
_SPLIT_OLDER_SHARE = 0.2


def _few_before(snap: _HistorySnapshot, before: float) -> bool:
    """Whether at most :data:`_SPLIT_OLDER_SHARE` of the reported track's samples
    (``snap.track_path``) are older than ``before``: a bird's few returns at the start of
    the drone's cluster, not the drone's own older part."""
    if snap.track_path is None:
        return False
    times = snap.track_path[0]
    return bool(times.size) and np.count_nonzero(times < before) <= _SPLIT_OLDER_SHARE * times.size


def _hovering_track(
    c: int,
    predicted: np.ndarray,
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    k: int,
    scorer: Any,
    scoring: ParamSet,
) -> np.ndarray | None:
    """Hysteresis for a hovering track, tried when cluster ``c`` (the one holding the
    track's recent points) did not keep it as scored: ``c`` without its points farther
    than ``track_gate`` from ``predicted`` (a bird passing a hovering drone leaves returns
    metres away in its cluster for the whole history, and their residual would fail it),
    re-scored with ``hover_keep_frames`` frames instead of ``hover_min_frames``. Only a
    cluster that still counts as hovering gains by this; a moving track's cluster cut down
    to its last metres fails the gates. ``scoring``: the parameters the re-clustering
    scored with. The mask of the points that continue the track, or None."""
    far = labels == c
    far[far] = (
        np.sum((xyz[far].astype(np.float64) - predicted) ** 2, axis=1) > scoring.track_gate**2
    )
    if far.any():
        labels = labels.copy()
        labels[far] = -1
    relaxed = scorer(
        labels,
        xyz,
        t,
        params=scoring.copy(hover_min_frames=scoring.hover_keep_frames),
        n_clusters=k,
    )
    if _passes_keep(relaxed, c, scoring):
        return labels == c
    return None


def _joined_track(
    o: int,
    c: int,
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    k: int,
    scorer: Any,
    scoring: ParamSet,
    structure: np.ndarray | None = None,
) -> tuple[np.ndarray, float, float] | None:
    """Hysteresis across a gap (``reacquire_join``): a drone's first returns after a gap
    longer than the clusterer's linking form a cluster of their own (``c``, near where
    the reported track would be now), too small and too short to pass the gates, while
    the track's earlier returns sit in another (``o``). The two are scored as one cluster:
    its acceleration and residual judge whether the fragment continues the track's path.
    (mask of the joined cluster, its confidence, its rank score) if it is a candidate
    with at least ``keep_confidence``, else None. The scoring's windows do not span the
    gap, so the fragment must also start where the track was heading: the straight-line
    fit over the track's last ``track_window`` seconds, carried to the fragment's first
    return, within ``track_gate`` plus ``link_max_accel`` x gap^2 / 2 of the fragment's
    first ``frame_period``, and (with the sorted ``structure`` keys of suppressed static
    voxels) have at most ``hover_max_contact`` of its returns in or next to them: the
    swaying edge of a tree crown beside where a drone turned away is no continuation of
    its track (deviation 81)."""
    p = scoring
    track, fragment = labels == o, labels == c
    t_end, t_start = float(t[track].max()), float(t[fragment].min())
    gap = t_start - t_end
    if not 0.0 < gap <= p.reacquire_window:
        return None
    end = np.flatnonzero(track & (t >= t_end - p.track_window))
    end = end[np.argsort(t[end], kind="stable")]
    start = fragment & (t <= t_start + p.frame_period)
    first = xyz[start].astype(np.float64).mean(axis=0)
    ends = (t[end], xyz[end].astype(np.float64), np.ones(end.size))
    if not _reaches(*ends, t_end, t_start, first, p):
        return None
    if structure is not None and structure.size and p.hover_max_contact < 1.0:
        which = np.zeros(k, dtype=bool)
        which[c] = True
        contact = structure_contact(
            labels[fragment], xyz[fragment], k, which, structure, p.static_voxel
        )
        if contact[c] > p.hover_max_contact:
            return None
    joined = labels.copy()
    joined[labels == c] = o
    rescored = scorer(joined, xyz, t, params=scoring, n_clusters=k)
    if _passes_keep(rescored, o, scoring):
        return (
            joined == o,
            float(rescored.confidence[o]),
            float(rescored.rank_score(scoring.scoring)[o]),
        )
    return None


def _passes_keep(scores: ClusterScores, c: int, scoring: ParamSet) -> bool:
    """Whether cluster ``c`` passes the hysteresis: a candidate with at least
    ``keep_confidence``."""
    return bool(scores.candidate[c] and scores.confidence[c] >= scoring.keep_confidence)


def _kept_over(
    reported: int | None, best: int, now: float, scores: ClusterScores, scoring: ParamSet
) -> bool:
    """``stream_keep_reported``: whether the reported track's cluster ``reported`` (the
    one holding its recent points near its prediction, None if there is none) stays the
    track although ``best``, another cluster, ranks first: it is slower than
    ``min_speed`` (a hover's), still has returns within ``max_gap`` of ``now`` and
    passes the hysteresis (:func:`_passes_keep`)."""
    return (
        reported is not None
        and reported != best
        and now - float(scores.t_last[reported]) <= scoring.max_gap
        and _passes_keep(scores, reported, scoring)
        and bool(scores.apparent_speed[reported] < scoring.min_speed)
    )


def _competing_track(
    best: int,
    snap: _HistorySnapshot,
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    k: int,
    scores: ClusterScores,
    scorer: Any,
    scoring: ParamSet,
    structure: np.ndarray | None,
) -> tuple[np.ndarray, float] | None:
    """``reacquire_compete``: ``best`` (another object) ranks first, while the reported
    track's newest returns lie in a fragment ``c`` that began after a gap. The cluster
    holding the track's samples from before ``c`` began is joined with ``c``
    (:func:`_joined_track`); the joined cluster is (mask, confidence) if it passes
    ``min_confidence`` and ranks above ``best``, else None."""
    if snap.track_path is None:
        return None
    p = scoring
    c = _newest_cluster(snap, labels, xyz, t, p)
    if c is None or c == best:
        return None
    times, positions, _ = snap.track_path
    before = np.flatnonzero(times < scores.t_first[c])
    if not before.size:
        return None
    i = before[-1]
    o = _sample_cluster(float(times[i]), positions[i], labels, xyz, t, p)
    if o is None or o in (best, c):
        return None
    joined = _joined_track(o, c, labels, xyz, t, k, scorer, p, structure)
    if joined is None or joined[1] < p.min_confidence:
        return None
    if joined[2] <= float(scores.rank_score(p.scoring)[best]):
        return None
    return joined[0], joined[1]


def _stray_samples(ts: np.ndarray, ps: np.ndarray, params: ParamSet) -> np.ndarray:
    """(S,) bool: the samples (times ``ts`` ascending, positions ``ps``) that
    :func:`~.trajectory.chord_strays` leaves out, with ``stray_distance``,
    ``link_max_accel`` and ``link_max_gap`` (deviation 83)."""
    return chord_strays(ts, ps, params.stray_distance, params.link_max_accel, params.link_max_gap)


def _without_strays(piece: _TrackPiece, params: ParamSet) -> _TrackPiece:
    """``piece`` without its :func:`_stray_samples` (deviation 83)."""
    keep = ~_stray_samples(piece.ts, piece.ps, params)
    if keep.all():
        return piece
    return dataclasses.replace(piece, ts=piece.ts[keep], ps=piece.ps[keep], ws=piece.ws[keep])


def smoothed_position(
    ts: np.ndarray,
    ps: np.ndarray,
    ws: np.ndarray,
    stamp: float,
    params: ParamSet,
    chord_ends: bool = True,
) -> np.ndarray | None:
    """Position at ``stamp`` from track samples (times ``ts`` ascending, positions ``ps``
    (S, 3), point counts ``ws``) on both sides of it, or None where the samples do not
    support one.

    Supported: within ``max_gap`` seconds between two samples, or up to
    ``max_extrapolation`` seconds before the first or after the last sample on that side
    of a longer gap. The fit uses the samples within ``track_window`` seconds of ``stamp``
    (at least the four nearest within ``link_max_gap``, so that a sparse track is not read
    as standing still): a weighted quadratic where ``stamp`` lies among at least 6 samples
    spanning 0.6 s and the fitted acceleration is at most ``max_accel``, else a weighted
    straight line (no velocity over less than two frame periods; beside a gap of at most
    ``link_max_gap``, such samples take the velocity of the chord across the gap). With
    ``report_extend_far``, gaps up to ``extend_far_gap`` count too, and before the first
    or after the last sample beside such a gap the fit is from that side, as inside it
    (unless ``chord_ends`` is False)."""
    p = params
    n = ts.size
    if n == 0 or not ts[0] - p.max_extrapolation <= stamp <= ts[-1] + p.max_extrapolation:
        return None
    k = int(np.searchsorted(ts, stamp))
    across = None  # the velocity of the chord across a gap, where one side may need it
    chord_gap = float(p.link_max_gap)
    if p.report_extend_far:
        # A far lone return the tail grew into is up to extend_far_gap beyond the rest.
        chord_gap = max(chord_gap, float(p.extend_far_gap))
    if 0 < k < n and ts[k] - ts[k - 1] > p.max_gap:
        # Inside a gap too long to bridge: only near one of its ends, from that side.
        gap = float(ts[k] - ts[k - 1])
        if gap <= chord_gap:
            across = (ps[k] - ps[k - 1]) / gap
        if stamp - ts[k - 1] <= p.max_extrapolation:
            ts, ps, ws = ts[:k], ps[:k], ws[:k]
        elif ts[k] - stamp <= p.max_extrapolation:
            ts, ps, ws = ts[k:], ps[k:], ws[k:]
        else:
            return None
    elif chord_ends and p.report_extend_far and n >= 2 and (k == 0 or k == n):
        # Before the first sample or after the last, beside the track's first or last
        # gap too long to bridge: from that side, as inside one (deviation 122; held
        # still, a pass's lone last return gave estimates 2-4 m off within
        # max_extrapolation of it).
        long = np.flatnonzero(np.diff(ts) > p.max_gap)
        if long.size:
            j = int(long[-1] if k == n else long[0]) + 1
            gap = float(ts[j] - ts[j - 1])
            if gap <= chord_gap:
                across = (ps[j] - ps[j - 1]) / gap
                if k == n:
                    ts, ps, ws = ts[j:], ps[j:], ws[j:]
                else:
                    ts, ps, ws = ts[:j], ps[:j], ws[:j]
    dist = np.abs(ts - stamp)
    near = dist <= p.track_window
    if np.count_nonzero(near) < 4:
        near = np.zeros(ts.size, dtype=bool)
        near[np.argsort(dist, kind="stable")[:4]] = True
        near &= dist <= max(p.track_window, p.link_max_gap)
        if not near.any():  # only with max_extrapolation beyond both of those
            return None
    tt, pp, ww = ts[near], ps[near], ws[near]
    if tt.size >= _QUAD_SAMPLES and tt[-1] - tt[0] >= _QUAD_SPAN and tt[0] <= stamp <= tt[-1]:
        tc = float(np.average(tt, weights=ww))
        coef = weighted_quadratic(tt - tc, pp, ww)
        if 2.0 * float(np.linalg.norm(coef[2])) <= p.max_accel:
            x = stamp - tc
            return coef[0] + coef[1] * x + coef[2] * x * x
    slope, mean, tc = _track_line(tt, pp, ww, p)
    if across is not None and not _spans_velocity(tt, p):
        # The first returns after a pause, all within a frame or two, have no velocity of
        # their own, and held still a pass 110 m out was 2-5 m off (deviation 84).
        slope = across
    return mean + slope * (stamp - tc)


def run_streaming(frames: Iterable[Frame], params: ParamSet | None = None) -> list[Estimate]:
    """Push every frame through one :class:`StreamingDetector`; the estimates in order:
    each frame's own, or with ``report_lag`` > 0 the delayed ones (the last frames'
    flushed at the end)."""
    detector = StreamingDetector(params)
    lagged = detector.params.report_lag > 0
    out = []
    for frame in frames:
        est = detector.push(frame)
        if lagged:
            out.extend(detector.delayed())
        elif est is not None:
            out.append(est)
    if lagged:
        out.extend(detector.flush())
    return out
