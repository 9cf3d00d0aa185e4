"""Trajectory from time-ordered drone points (paper 3.4).

Drone points are first averaged per time bin (half a frame period), giving one sample
per frame weighted by its number of points. The samples are split into segments where
consecutive samples are more than ``max_gap`` seconds apart. Each segment with at least
five samples gets a cubic smoothing B-spline per axis
(:func:`scipy.interpolate.make_smoothing_spline`, smoothing chosen by generalised
cross-validation); shorter segments get a weighted straight line (or a constant).
With ``context_gap`` set (offline: the longer of ``link_max_gap`` and
``extend_far_gap``, the longest gaps growth and linking cross, as all samples belong to
one linked track), a short segment's line is fitted through its neighbours' nearest
``context_window`` seconds as well, when they are at most ``context_gap`` away: one or
two returns after a gap then move on with the track's velocity instead of standing still.
That line judges strays (:func:`fit_trajectory`); the line returned keeps its velocity
but passes through the segment's own samples, so a lone return on a curving path is not
replaced by the chord between its neighbours.
Positions are defined only inside a segment's span widened by ``max_extrapolation``
seconds at each end (linear continuation there); elsewhere the answer is NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.interpolate import make_smoothing_spline

from clusterfilter_ros.core.voxel import unique_ints


def time_samples(
    t: np.ndarray, xyz: np.ndarray, bin_seconds: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Average points per time bin: (times (S,), positions (S, 3), point counts (S,))."""
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    return _bin_means(t, xyz, bin_seconds)


def _bin_means(
    t: np.ndarray, values: np.ndarray, bin_seconds: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`time_samples` for any number of columns: (mean times (S,), mean ``values``
    per bin (S, C), counts (S,)), ``t`` (N,) and ``values`` (N, C) float64."""
    if t.size == 0:
        return np.empty(0), np.empty((0, values.shape[1])), np.empty(0)
    b = np.floor((t - t.min()) / bin_seconds).astype(np.int64)
    ub, inv, counts = unique_ints(b, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    tm = np.bincount(inv, weights=t) / counts
    means = np.stack(
        [np.bincount(inv, weights=values[:, a]) / counts for a in range(values.shape[1])],
        axis=1,
    )
    return tm, means, counts.astype(np.float64)


def weighted_line(
    t: np.ndarray, xyz: np.ndarray, w: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float]:
    """Weighted least-squares straight line through samples (t (S,), xyz (S, 3), weights
    (S,)): (velocity (3,), weighted mean position (3,), weighted mean time); the position
    at time ``x`` is ``mean + (x - tc) * velocity``. Zero velocity if all ``t`` are equal."""
    # The arithmetic of np.average (same order, same results) without its other checks.
    total = w.sum()
    if not total > 0:
        raise ValueError("weighted_line: the weights must sum to more than zero")
    tc = float((t * w).sum() / total)
    dt = t - tc
    mean = (xyz * w[:, None]).sum(axis=0) / total
    denom = float(np.sum(w * dt * dt))
    if denom <= 0:
        return np.zeros(3), mean, tc
    slope = (w[:, None] * dt[:, None] * (xyz - mean)).sum(axis=0) / denom
    return slope, mean, tc


def weighted_quadratic(dt: np.ndarray, xyz: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted least-squares quadratic through samples (time offsets dt (S,), xyz (S, 3),
    weights (S,)): (3, 3) coefficients, the position at offset ``x`` being
    ``c[0] + c[1] * x + c[2] * x * x`` (so the acceleration is ``2 * c[2]``)."""
    sw = np.sqrt(w)[:, None]
    design = np.stack([np.ones_like(dt), dt, dt * dt], axis=1) * sw
    return np.linalg.lstsq(design, xyz * sw, rcond=None)[0]


def chord_strays(
    ts: np.ndarray,
    ps: np.ndarray,
    distance: float,
    accel: float,
    max_span: float,
    lone_gap: float = 0.0,
) -> np.ndarray:
    """(S,) bool: the samples (times ``ts`` ascending, positions ``ps`` (S, 3)) that lie
    farther than ``distance`` plus ``accel`` x dt1 x dt2 / 2 (the most an object
    accelerating that hard strays from the chord) from the straight line between the
    samples on either side of them, those at most ``max_span`` seconds apart: a lone
    return of something else a track took between two of the drone's; of neighbouring
    samples only the one that strays most. The first and last samples are never strays
    here; ``distance`` <= 0 finds none. ``lone_gap`` (s): only samples at least this far
    in time from both neighbours are judged."""
    out = np.zeros(ts.size, dtype=bool)
    if ts.size < 3 or distance <= 0:
        return out
    t0, t1, t2 = ts[:-2], ts[1:-1], ts[2:]
    span = t2 - t0
    ok = (span > 0) & (span <= max_span)
    frac = np.where(span > 0, (t1 - t0) / np.where(span > 0, span, 1.0), 0.5)
    between = ps[:-2] + frac[:, None] * (ps[2:] - ps[:-2])
    off = np.linalg.norm(ps[1:-1] - between, axis=1)
    allow = distance + 0.5 * accel * (t1 - t0) * (t2 - t1)
    # A stray moves the chords its neighbours are judged by, too: only the sample that
    # strays most among its neighbours is taken for one.
    excess = np.zeros(ts.size)
    excess[1:-1] = np.where(ok, off / allow, 0.0)
    out[1:-1] = (excess[1:-1] > 1.0) & (excess[1:-1] >= excess[:-2]) & (excess[1:-1] >= excess[2:])
    if lone_gap > 0:
        out[1:-1] &= (t1 - t0 >= lone_gap) & (t2 - t1 >= lone_gap)
    return out


@dataclass
class _Segment:
    t_start: float
    t_end: float
    kind: str  # "spline", "line" or "constant"
    model: object
    confidence: float
    n_samples: int
    # A context line's own samples: (weighted mean position, weighted mean time).
    own: tuple[np.ndarray, float] | None = None

    def anchored(self) -> _Segment:
        """A context line moved to pass through its own samples' mean, keeping the
        velocity of its context; any other segment unchanged."""
        if self.own is None:
            return self
        slope = self.model[0]
        return replace(self, model=(slope, *self.own), own=None)

    def value(self, t: np.ndarray) -> np.ndarray:
        if self.kind == "constant":
            return np.repeat(np.asarray(self.model)[None, :], t.size, axis=0)
        if self.kind == "line":
            slope, intercept, tc = self.model
            return intercept[None, :] + (t - tc)[:, None] * slope[None, :]
        splines = self.model
        tc = np.clip(t, self.t_start, self.t_end)
        out = np.stack([s(tc) for s in splines], axis=1)
        outside = t != tc
        if outside.any():
            deriv = np.stack([s.derivative()(tc[outside]) for s in splines], axis=1)
            out[outside] += (t[outside] - tc[outside])[:, None] * deriv
        return out


@dataclass
class Trajectory:
    """Piecewise smooth drone trajectory; evaluable only where the evidence supports it."""

    segments: list[_Segment] = field(default_factory=list)
    max_extrapolation: float = 0.3
    sample_times: np.ndarray = field(default_factory=lambda: np.empty(0))
    sample_counts: np.ndarray = field(default_factory=lambda: np.empty(0))

    @property
    def span(self) -> tuple[float, float]:
        if not self.segments:
            return (float("nan"), float("nan"))
        return (self.segments[0].t_start, self.segments[-1].t_end)

    def segment_index(self, stamps: np.ndarray) -> np.ndarray:
        """Index of the segment supporting each stamp, -1 where none does. Where segments
        overlap (two selected clusters at once), one whose own span holds the stamp goes
        before one that only extrapolates to it, and of those alike the longer one, then
        the earlier one: a flight's track outlasts a bird's leg (deviation 120)."""
        stamps = np.asarray(stamps, dtype=np.float64).reshape(-1)
        out = np.full(stamps.size, -1, dtype=np.int64)
        if not self.segments:
            return out
        m = self.max_extrapolation
        spans = np.array([seg.t_end - seg.t_start for seg in self.segments])
        # Holding the stamp counts 2; the span adds less than 1 (equal spans: the first).
        length = spans / (float(spans.max()) + 1.0)
        best = np.full(stamps.size, -np.inf)
        for i, seg in enumerate(self.segments):
            near = (stamps >= seg.t_start - m) & (stamps <= seg.t_end + m)
            within = (stamps >= seg.t_start) & (stamps <= seg.t_end)
            rank = np.where(within, 2.0, 0.0) + length[i]
            take = near & (rank > best)
            out[take] = i
            best[take] = rank[take]
        return out

    def __call__(self, stamps: np.ndarray) -> np.ndarray:
        """(M, 3) positions at ``stamps``; NaN rows where unsupported."""
        stamps = np.asarray(stamps, dtype=np.float64).reshape(-1)
        out = np.full((stamps.size, 3), np.nan)
        seg_idx = self.segment_index(stamps)
        for i, seg in enumerate(self.segments):
            sel = seg_idx == i
            if sel.any():
                out[sel] = seg.value(stamps[sel])
        return out

    def confidence(self, stamps: np.ndarray) -> np.ndarray:
        """Confidence of the segment supporting each stamp (0 where none)."""
        seg_idx = self.segment_index(stamps)
        conf = np.array([s.confidence for s in self.segments] + [0.0])
        return conf[seg_idx]

    def support(self, stamps: np.ndarray, window: float) -> np.ndarray:
        """Drone points within +-window/2 of each stamp."""
        stamps = np.asarray(stamps, dtype=np.float64).reshape(-1)
        if self.sample_times.size == 0:
            return np.zeros(stamps.size, dtype=np.int64)
        csum = np.concatenate([[0.0], np.cumsum(self.sample_counts)])
        lo = np.searchsorted(self.sample_times, stamps - window / 2, side="left")
        hi = np.searchsorted(self.sample_times, stamps + window / 2, side="right")
        return (csum[hi] - csum[lo]).astype(np.int64)


#: Stray-return refits of :func:`fit_trajectory` (each re-judges every point).
STRAY_REFITS = 3


def fit_trajectory(
    t: np.ndarray,
    xyz: np.ndarray,
    *,
    max_gap: float,
    max_extrapolation: float,
    bin_seconds: float = 0.05,
    confidence: np.ndarray | None = None,
    context_gap: float = 0.0,
    context_window: float = 1.0,
    stray_distance: float = 0.0,
    stray_speed: float = 0.0,
    stray_accel: float = math.inf,
    stray_window: float = 1.0,
    stray_span: float = 0.0,
    stray_chord_span: float = 0.0,
    stray_chord_lone: float = 0.0,
) -> Trajectory | None:
    """Fit a :class:`Trajectory` to drone points (t (N,), xyz (N, 3)); None if no points.

    ``confidence`` (N,) optional per-point confidence; a segment's confidence is the
    point-weighted mean over its points. ``context_gap`` (s, 0 = off) and
    ``context_window`` (s): a segment of fewer than five samples is a straight line
    through its own samples and those of the neighbouring segments' nearest
    ``context_window`` seconds, for neighbours at most ``context_gap`` away (see the
    module docstring); its span stays its own. Strays are judged against that line; the
    returned line has its velocity and goes through the segment's own mean position.

    ``stray_distance`` (m, 0 = off): points farther than this from the fitted track
    (another object's returns the clusterer joined to the drone's) are left out and the
    track fitted again, up to :data:`STRAY_REFITS` times, each time judging every point
    against the latest fit, so a drone return that a stray pulled the first fit away from
    comes back. Nothing is left out when more than half the points would be.
    ``stray_speed`` (m/s, 0 = off, with ``stray_distance``), ``stray_accel`` (m/s^2)
    and ``stray_window`` (s): a fitted curve follows a stray sample at a segment's end
    (nothing beyond it holds the curve back), so the first and last samples of each
    segment are also dropped, one by one, while they lie farther than
    ``stray_distance`` + ``stray_speed`` x dt from their neighbour, or farther than
    ``stray_distance`` + ``stray_accel`` x dt^2 / 2 from where the neighbouring
    ``stray_window`` seconds of samples were heading; and so is a segment of fewer than
    five samples that neither neighbouring segment could have reached that way.
    ``stray_span`` (s, 0 = off): samples spanning less than this give no heading (two
    returns 0.06 s apart give their scatter): the nearest further in join them until
    they span it.
    ``stray_chord_span`` (s, 0 = off, with ``stray_distance``): samples that
    :func:`chord_strays` finds between neighbours at most this far apart (with
    ``stray_accel``), at least ``stray_chord_lone`` seconds from both, are left out of a
    last fit, after the refits: a spline passes through a lone stray between two of the
    track's samples, so the distance to the fit never finds it. (Where another object's
    samples alternate with the drone's, the chords run between the other object's and
    throw out the drone's: only lone samples are judged.)
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    good = np.isfinite(t) & np.isfinite(xyz).all(axis=1)
    t, xyz = t[good], xyz[good]
    if t.size == 0:
        return None
    conf_pts = np.ones(t.size) if confidence is None else np.asarray(confidence)[good]
    reach = None
    if stray_distance > 0 and stray_speed > 0:
        reach = (stray_distance, stray_speed, stray_accel, stray_window, stray_span)
    chord = None
    if stray_chord_span > 0:
        chord = (stray_distance, stray_accel, stray_chord_span, stray_chord_lone)
    fit_args = (max_gap, max_extrapolation, bin_seconds, context_gap, context_window, reach)
    traj = _fit(t, xyz, conf_pts, *fit_args)
    kept = np.ones(t.size, dtype=bool)
    if stray_distance > 0:
        for _ in range(STRAY_REFITS):
            off = np.linalg.norm(traj(t) - xyz, axis=1)
            keep = ~(off > stray_distance)  # NaN (no estimate there): kept
            if np.array_equal(keep, kept) or keep.sum() * 2 < t.size:
                break
            kept = keep
            traj = _fit(t[kept], xyz[kept], conf_pts[kept], *fit_args)
    if chord is not None:
        # Last, once the returns far from the fit are out: where another object's
        # returns alternate with the drone's, the chords would run between the
        # other object's samples and throw out the drone's.
        ts, ps, _ = _bin_means(t[kept], xyz[kept], bin_seconds)
        if chord_strays(ts, ps, *chord).any():
            traj = _fit(t[kept], xyz[kept], conf_pts[kept], *fit_args, chord)
    # Strays are judged against the context lines as fitted (a lone return off its
    # neighbours' line is left out); what is kept is then estimated through its own
    # position: on a curving pass the line through the neighbours' denser windows misses
    # a lone drone return between them by a metre or more.
    traj.segments = [seg.anchored() for seg in traj.segments]
    return traj


def _fit(
    t: np.ndarray,
    xyz: np.ndarray,
    conf_pts: np.ndarray,
    max_gap: float,
    max_extrapolation: float,
    bin_seconds: float,
    context_gap: float,
    context_window: float,
    reach: tuple[float, float, float, float, float] | None,
    chord: tuple[float, float, float, float] | None = None,
) -> Trajectory:
    """:func:`fit_trajectory` without the stray refits, on finite points."""
    order = np.argsort(t, kind="stable")
    t, xyz, conf_pts = t[order], xyz[order], conf_pts[order]
    # One binning for the positions and the per-point confidences.
    ts, means, ws = _bin_means(
        t.astype(np.float64), np.column_stack([xyz, conf_pts]).astype(np.float64), bin_seconds
    )
    ps, cs = means[:, :3], means[:, 3]
    if chord is not None:
        keep = ~chord_strays(ts, ps, *chord)
        ts, ps, cs, ws = ts[keep], ps[keep], cs[keep], ws[keep]
    breaks = np.nonzero(np.diff(ts) > max_gap)[0] + 1
    groups = np.split(np.arange(ts.size), breaks)
    if reach is not None:
        groups = _reachable_groups(ts, ps, ws, groups, reach)
        used = np.concatenate(groups)  # the support counts only the samples fitted
        ts_used, ws_used = ts[used], ws[used]
    else:
        ts_used, ws_used = ts, ws
    segments = []
    # A mean of equal confidences can round below them (0.6 -> 0.5999999999999999), and
    # a piece given exactly min_confidence would then not be reported: clip to the inputs.
    lowest, highest = float(conf_pts.min()), float(conf_pts.max())
    for g, idx in enumerate(groups):
        st, sp, sw, sc = ts[idx], ps[idx], ws[idx], cs[idx]
        conf = min(max(float(np.average(sc, weights=sw)), lowest), highest)
        if context_gap > 0 and st.size < 5:
            # A short piece of a longer track: its line also goes through the nearest
            # context_window of the neighbouring pieces (same object, within context_gap),
            # so that one or two returns after a gap move on with the track's velocity.
            extra = []
            if g > 0 and st[0] - ts[groups[g - 1][-1]] <= context_gap:
                prev = groups[g - 1]
                extra.append(prev[ts[prev] >= ts[prev[-1]] - context_window])
            if g + 1 < len(groups) and ts[groups[g + 1][0]] - st[-1] <= context_gap:
                nxt = groups[g + 1]
                extra.append(nxt[ts[nxt] <= ts[nxt[0]] + context_window])
            if extra:
                ctx = np.concatenate([idx, *extra])
                model = weighted_line(ts[ctx], ps[ctx], ws[ctx])
                own = (np.average(sp, axis=0, weights=sw), float(np.average(st, weights=sw)))
                segments.append(_Segment(st[0], st[-1], "line", model, conf, st.size, own))
                continue
        if st.size >= 5 and st[-1] - st[0] > 0:
            splines = []
            for a in range(3):
                try:
                    splines.append(make_smoothing_spline(st, sp[:, a], w=sw / sw.mean()))
                except (ValueError, np.linalg.LinAlgError):
                    splines = []
                    break
            if splines:
                segments.append(_Segment(st[0], st[-1], "spline", splines, conf, st.size))
                continue
        if st.size >= 2 and st[-1] - st[0] > 0:
            segments.append(
                _Segment(st[0], st[-1], "line", weighted_line(st, sp, sw), conf, st.size)
            )
        else:
            mean = np.average(sp, axis=0, weights=sw)
            segments.append(_Segment(st[0], st[-1], "constant", mean, conf, st.size))
    return Trajectory(segments, max_extrapolation, ts_used, ws_used)


def _unreachable(
    ts: np.ndarray,
    ps: np.ndarray,
    ws: np.ndarray,
    i: int,
    side: np.ndarray,
    reach: tuple[float, float, float, float, float],
) -> bool:
    """Whether no object could have got to sample ``i`` from the samples ``side`` (on one
    side of it, the nearest last): farther than ``base + speed * dt`` from the nearest,
    or farther than ``base + accel * dt^2 / 2`` from where the ``window`` seconds of
    them next to it were heading (a straight line through them, over at least ``span``
    seconds of them where there are)."""
    base, speed, accel, window, span = reach
    j = side[-1]
    gap = abs(ts[i] - ts[j])
    if np.linalg.norm(ps[i] - ps[j]) > base + speed * gap:
        return True
    near = side[np.abs(ts[side] - ts[j]) <= window]
    if span > 0 and near.size < side.size and np.ptp(ts[near]) < span:
        # Over less than `span` the heading is the scatter of a frame or two (fast_pass
        # 5604 of the fifty-fifth set: two returns 0.06 s apart threw out the pass's
        # lone return 1 s on, deviation 123). The nearest ones further in join them.
        apart = np.abs(ts[side] - ts[j])
        order = np.argsort(apart, kind="stable")
        near = side[order[: int(np.searchsorted(apart[order], span)) + 1]]
    if near.size < 2 or np.ptp(ts[near]) <= 0:
        return False
    velocity, mean, tc = weighted_line(ts[near], ps[near], ws[near])
    heading = mean + (ts[i] - tc) * velocity
    return bool(np.linalg.norm(ps[i] - heading) > base + 0.5 * accel * gap * gap)


def _reachable_groups(
    ts: np.ndarray,
    ps: np.ndarray,
    ws: np.ndarray,
    groups: list[np.ndarray],
    reach: tuple[float, float, float, float, float],
) -> list[np.ndarray]:
    """Segments (sample indices) with their unreachable end samples trimmed, one by one,
    and without the short ones (fewer than five samples) that no neighbouring segment
    could have reached: another object's returns after the drone's, say."""
    trimmed = []
    for idx in groups:
        lo, hi = 0, idx.size - 1
        while hi > lo and _unreachable(ts, ps, ws, idx[hi], idx[lo:hi], reach):
            hi -= 1
        while hi > lo and _unreachable(ts, ps, ws, idx[lo], idx[lo + 1 : hi + 1][::-1], reach):
            lo += 1
        trimmed.append(idx[lo : hi + 1])
    kept = []
    for g, idx in enumerate(trimmed):
        if idx.size < 5 and len(trimmed) > 1:
            verdicts = []
            if g > 0:
                verdicts.append(_unreachable(ts, ps, ws, idx[0], trimmed[g - 1], reach))
            if g + 1 < len(trimmed):
                verdicts.append(_unreachable(ts, ps, ws, idx[-1], trimmed[g + 1][::-1], reach))
            if all(verdicts):
                continue
        kept.append(idx)
    return kept or trimmed  # short pieces that all disagree: nothing to prefer


def merge_trajectories(parts: list[Trajectory], max_extrapolation: float) -> Trajectory | None:
    """One :class:`Trajectory` holding the segments of several (e.g. one per cluster),
    so that no segment ever spans two different objects."""
    parts = [p for p in parts if p is not None and p.segments]
    if not parts:
        return None
    segments = sorted((s for p in parts for s in p.segments), key=lambda s: s.t_start)
    times = np.concatenate([p.sample_times for p in parts])
    counts = np.concatenate([p.sample_counts for p in parts])
    order = np.argsort(times, kind="stable")
    return Trajectory(segments, max_extrapolation, times[order], counts[order])
