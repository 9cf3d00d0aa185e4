"""Accuracy of estimated positions against ground truth.

Matching rule: each ground-truth sample at time g gets the prediction interpolated
linearly between the last prediction at or before g and the first at or after g, when
both lie within ``max_gap`` seconds of g (an exact stamp match uses that row);
otherwise the sample has no prediction. Over the ground-truth samples:

- coverage: fraction with a prediction;
- detection rate: fraction with a prediction within ``hit_radius`` metres;
- observable detection rate: the same over the samples flagged observable (e.g. the
  drone gave at least one lidar return in the surrounding second);
- mean / RMSE / median / p95 of the 3D error and the MSE (m^2) over matched samples;
- acquisition: the observable samples fall into appearances (runs separated by more
  than ``reacquire_gap`` seconds without one); per appearance, the delay from its first
  sample to its first hit, and the tracked detection rate, the detection rate over the
  samples from that first hit on. A causal detector needs time to confirm a new
  object; these separate that time from the losses of an established track.

On drone-free data, :func:`false_alarm_seconds` measures how long anything was reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from clusterfilter_ros.core.frame import TimedPositions


@dataclass
class EvaluationResult:
    """Metrics of one prediction against one ground truth (NaN where undefined)."""

    n_gt: int
    n_pred: int
    n_matched: int
    coverage: float
    detection_rate: float
    n_observable: int
    observable_detection_rate: float
    mean_error: float
    rmse: float
    median_error: float
    p95_error: float
    mse: float
    false_alarm_seconds: float
    false_alarm_fraction: float
    duration: float
    n_appearances: int = 0
    n_acquired: int = 0
    mean_acquisition_delay: float = float("nan")
    max_acquisition_delay: float = float("nan")
    tracked_detection_rate: float = float("nan")
    errors: np.ndarray = field(default_factory=lambda: np.empty(0), repr=False)
    matched_xyz: np.ndarray = field(default_factory=lambda: np.empty((0, 3)), repr=False)

    def as_dict(self) -> dict[str, float]:
        """The scalar metrics (JSON-friendly; NaN becomes None)."""
        out: dict[str, float] = {}
        for name in (
            "n_gt",
            "n_pred",
            "n_matched",
            "coverage",
            "detection_rate",
            "n_observable",
            "observable_detection_rate",
            "mean_error",
            "rmse",
            "median_error",
            "p95_error",
            "mse",
            "false_alarm_seconds",
            "false_alarm_fraction",
            "duration",
            "n_appearances",
            "n_acquired",
            "mean_acquisition_delay",
            "max_acquisition_delay",
            "tracked_detection_rate",
        ):
            v = getattr(self, name)
            out[name] = None if isinstance(v, float) and math.isnan(v) else v
        return out


def interpolate_predictions(
    pred: TimedPositions, stamps: np.ndarray, max_gap: float = 0.3
) -> np.ndarray:
    """(M, 3) predictions at ``stamps`` by the matching rule; NaN rows where none."""
    stamps = np.asarray(stamps, dtype=np.float64).reshape(-1)
    out = np.full((stamps.size, 3), np.nan)
    n = len(pred)
    if n == 0 or stamps.size == 0:
        return out
    ps, px = pred.stamps, pred.xyz
    right = np.searchsorted(ps, stamps, side="left")  # first pred >= g
    left = np.searchsorted(ps, stamps, side="right") - 1  # last pred <= g
    ok = (left >= 0) & (right < n)
    lc = np.clip(left, 0, n - 1)
    rc = np.clip(right, 0, n - 1)
    ok &= (stamps - ps[lc] <= max_gap) & (ps[rc] - stamps <= max_gap)
    span = ps[rc] - ps[lc]
    frac = np.where(span > 0, (stamps - ps[lc]) / np.where(span > 0, span, 1.0), 0.0)
    with np.errstate(over="ignore", invalid="ignore"):
        interp = px[lc] + frac[:, None] * (px[rc] - px[lc])
        bad = ~np.isfinite(interp)
        if bad.any():
            # Positions so large (~1e308 m) that their difference overflows: the other
            # form of the same interpolation stays finite.
            f = frac[:, None]
            interp = np.where(bad, px[lc] * (1.0 - f) + px[rc] * f, interp)
    out[ok] = interp[ok]
    return out


def false_alarm_seconds(pred: TimedPositions, max_gap: float = 0.3) -> float:
    """Seconds during which something was reported: each prediction covers the time to
    the next one, at most ``max_gap`` (and ``max_gap`` for the last)."""
    if len(pred) == 0:
        return 0.0
    gaps = np.diff(pred.stamps)
    return float(np.minimum(gaps, max_gap).sum() + max_gap)


def evaluate(
    pred: TimedPositions,
    gt: TimedPositions,
    max_gap: float = 0.3,
    hit_radius: float = 2.0,
    observable: np.ndarray | None = None,
    duration: float | None = None,
    reacquire_gap: float = 2.0,
) -> EvaluationResult:
    """Compare predictions with ground truth; see the module docstring.

    ``observable``: optional (len(gt),) bool mask of GT samples at which the drone was
    observable. ``duration``: length (s) of the recording, for the false-alarm fraction
    (default: the GT span, or the prediction span if there is no GT).
    ``reacquire_gap``: seconds without an observable sample after which the drone's
    next observable sample starts a new appearance (acquisition metrics).
    """
    # Absurd but finite positions (~1e308 m) give infinite errors, reported as such,
    # without numpy's overflow warnings.
    with np.errstate(over="ignore", invalid="ignore"):
        return _evaluate(pred, gt, max_gap, hit_radius, observable, duration, reacquire_gap)


def _evaluate(
    pred: TimedPositions,
    gt: TimedPositions,
    max_gap: float,
    hit_radius: float,
    observable: np.ndarray | None,
    duration: float | None,
    reacquire_gap: float,
) -> EvaluationResult:
    n_gt = len(gt)
    matched = interpolate_predictions(pred, gt.stamps, max_gap)
    has = np.isfinite(matched).all(axis=1)
    err = np.full(n_gt, np.nan)
    err[has] = np.linalg.norm(matched[has] - gt.xyz[has], axis=1)
    hit = has & (err <= hit_radius)
    e = err[has]
    nan = float("nan")
    if observable is not None:
        obs = np.asarray(observable, dtype=bool).reshape(-1)
        if obs.size != n_gt:
            raise ValueError(f"observable mask has {obs.size} values for {n_gt} GT samples")
    else:
        obs = np.ones(n_gt, dtype=bool)
    if duration is None:
        ref = gt.stamps if n_gt else pred.stamps
        duration = float(ref[-1] - ref[0]) if ref.size > 1 else 0.0
    # False alarms: predictions not near any GT-supported answer (all of them when no GT).
    if n_gt:
        at_pred = _gt_at(gt, pred.stamps, max_gap)
        wrong = ~np.isfinite(at_pred).all(axis=1)
        wrong |= np.linalg.norm(np.nan_to_num(at_pred) - pred.xyz, axis=1) > hit_radius
        fa_pred = TimedPositions(pred.stamps[wrong], pred.xyz[wrong])
    else:
        fa_pred = pred
    fa = false_alarm_seconds(fa_pred, max_gap) if len(fa_pred) else 0.0
    if duration > 0:
        fa = min(fa, float(duration))
    acq = acquisition(gt.stamps[obs], hit[obs], reacquire_gap)
    return EvaluationResult(
        n_gt=n_gt,
        n_pred=len(pred),
        n_matched=int(has.sum()),
        coverage=float(has.mean()) if n_gt else nan,
        detection_rate=float(hit.mean()) if n_gt else nan,
        n_observable=int(obs.sum()),
        observable_detection_rate=float(hit[obs].mean()) if obs.any() else nan,
        mean_error=float(e.mean()) if e.size else nan,
        rmse=float(np.sqrt(np.mean(e**2))) if e.size else nan,
        median_error=float(np.median(e)) if e.size else nan,
        p95_error=float(np.percentile(e, 95)) if e.size else nan,
        mse=float(np.mean(e**2)) if e.size else nan,
        false_alarm_seconds=fa,
        false_alarm_fraction=fa / duration if duration > 0 else nan,
        duration=float(duration),
        n_appearances=acq.n_appearances,
        n_acquired=acq.n_acquired,
        mean_acquisition_delay=float(acq.delays.mean()) if acq.delays.size else nan,
        max_acquisition_delay=float(acq.delays.max()) if acq.delays.size else nan,
        tracked_detection_rate=acq.tracked_rate,
        errors=err,
        matched_xyz=matched,
    )


@dataclass
class Acquisition:
    """How soon each appearance of the drone was detected, and how well it was kept."""

    n_appearances: int
    n_acquired: int
    delays: np.ndarray  # seconds from each acquired appearance's start to its first hit
    tracked_rate: float  # hits / samples from each appearance's first hit on (NaN: none)


def acquisition(stamps: np.ndarray, hit: np.ndarray, reacquire_gap: float = 2.0) -> Acquisition:
    """Acquisition metrics over time-sorted samples (``stamps``) and whether each was
    detected (``hit``). Samples more than ``reacquire_gap`` s apart start a new
    appearance; an appearance without a hit counts as not acquired."""
    stamps = np.asarray(stamps, dtype=np.float64).reshape(-1)
    hit = np.asarray(hit, dtype=bool).reshape(-1)
    if stamps.size == 0:
        return Acquisition(0, 0, np.empty(0), float("nan"))
    new = np.ones(stamps.size, dtype=bool)
    new[1:] = np.diff(stamps) > reacquire_gap
    segment = np.cumsum(new) - 1
    starts = np.flatnonzero(new)
    # Hits so far within the sample's own appearance (the sample itself included).
    hits_so_far = np.cumsum(hit)
    before = np.concatenate([[0], hits_so_far])[starts]
    tracked = hits_so_far - before[segment] > 0
    first_hit = np.full(starts.size, -1)
    hit_idx = np.flatnonzero(hit)
    # The first hit of each appearance: the earliest hit index in that segment.
    seg_of_hit = segment[hit_idx]
    uniq, pos = np.unique(seg_of_hit, return_index=True)
    first_hit[uniq] = hit_idx[pos]
    acquired = first_hit >= 0
    delays = stamps[first_hit[acquired]] - stamps[starts[acquired]]
    rate = float(hit[tracked].mean()) if tracked.any() else float("nan")
    return Acquisition(int(starts.size), int(acquired.sum()), delays, rate)


def _gt_at(gt: TimedPositions, stamps: np.ndarray, max_gap: float) -> np.ndarray:
    """Ground truth at prediction stamps by the same matching rule; a stamp at most
    ``max_gap`` before the first (after the last) GT sample gets that sample, so that a
    prediction made just before the ground truth starts is not counted as wrong."""
    stamps = np.asarray(stamps, dtype=np.float64).reshape(-1)
    out = interpolate_predictions(gt, stamps, max_gap)
    if len(gt):
        first, last = gt.stamps[0], gt.stamps[-1]
        before = (stamps < first) & (first - stamps <= max_gap)
        after = (stamps > last) & (stamps - last <= max_gap)
        out[before] = gt.xyz[0]
        out[after] = gt.xyz[-1]
    return out


def observable_mask(
    gt_stamps: np.ndarray, hit_stamps: np.ndarray, window: float = 1.0, min_hits: int = 1
) -> np.ndarray:
    """GT samples with at least ``min_hits`` drone lidar returns within +-window/2 s.

    ``hit_stamps``: one entry per drone return (or per frame, repeated per return).
    """
    gt_stamps = np.asarray(gt_stamps, dtype=np.float64).reshape(-1)
    hs = np.sort(np.asarray(hit_stamps, dtype=np.float64).reshape(-1))
    lo = np.searchsorted(hs, gt_stamps - window / 2, side="left")
    hi = np.searchsorted(hs, gt_stamps + window / 2, side="right")
    return (hi - lo) >= min_hits
