"""Link the fragments of one moving object into one cluster (track linking).

A small drone far from the lidars gives a few returns per frame and frames without any,
and at 5-15 m/s it leaves the clusterer's neighbourhood between two returns; one flight
then becomes dozens of clusters of 3-30 points, each too small and too short to be
scored. Linking joins cluster B to cluster A when B starts shortly after A ends, where A
was heading:

- each cluster's *end state* (position and velocity at its last stamp) and *start state*
  come from a weighted straight-line fit over its first / last ``link_fit_window``
  seconds of per-frame mean positions, reaching further inward (within
  ``link_max_gap``) to a sample at least three frame periods from the end when none
  there is (:func:`_end_windows`); a fragment spanning less than two frames has no
  velocity, only a position;
- a pair (A, B) is a candidate when the gap ``dt = t_first(B) - t_last(A)`` is between
  ``-frame_period`` and ``link_max_gap`` and the distance between B's start and A's
  end carried forward by A's velocity (or A's end and B's start carried back by B's
  velocity, whichever is smaller) is within ``link_gate + link_max_accel * dt^2 / 2``
  (never more than ``link_gate + link_max_speed * dt``); two fragments without a velocity
  link only across one frame period, by the distance between A's end and B's start;
  where both ends have a velocity, they may differ by at most
  ``link_max_dv + link_max_accel * dt`` (a bird leg heading where the drone's track
  begins is another object, however well its line meets the track), and where one of
  them is at most ``link_rest_speed`` fast (at rest), A's end carried by the mean of
  the two velocities must lie within the reach too (starting or stopping at constant
  acceleration);
- a fragment's first or last sample that is a single return lying beyond the linking
  reach of where the fragment's next ``link_fit_window`` of samples inward was heading
  (another object's return the clusterer joined to it) does not define that end; the
  reach is then still that of the gap between the two fragments' returns;
- candidates are taken greedily, best first (distance relative to the reach plus gap
  relative to ``link_max_gap``, so that the next fragment in time is not skipped), each
  cluster getting at most one successor and one predecessor, so a chain is one object's
  track and never a tree of several objects.

Only clusters that could be a small flying object take part: at most
``max_cluster_points`` points, centroid above ``min_centroid_z``, and a mean extent per
frame no larger than ``max_local_extent``. Walls, ground clutter and people are left
alone, so a drone track can never be joined to them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from clusterfilter_ros.core import voxel
from clusterfilter_ros.core.grouping import group_bounds, lex_order
from clusterfilter_ros.core.params import ParamSet
from clusterfilter_ros.core.scoring import local_scatter

#: Candidate pairs are formed in blocks of at most this many clusters and about this
#: many (cluster, candidate) cells, which bounds the memory whatever the scene.
_BLOCK = 512
_BLOCK_CELLS = 1 << 18
#: An end state's line needs samples at least this many frame periods apart: over 0.1 s
#: a drone's 0.3-0.5 m spread of returns is a velocity error of several m/s.
MIN_BASELINE_FRAMES = 3


def linking_reach(gap: np.ndarray, params: ParamSet, gate: float | None = None) -> np.ndarray:
    """Distance (m) a fragment may be from where the previous one was heading after
    ``gap`` seconds: ``gate + link_max_accel * gap^2 / 2``, at most
    ``gate + link_max_speed * gap`` (``gate`` default ``link_gate``)."""
    gap = np.abs(np.asarray(gap, dtype=np.float64))
    base = params.link_gate if gate is None else gate
    return np.minimum(
        base + 0.5 * params.link_max_accel * gap * gap,
        base + params.link_max_speed * gap,
    )


def frame_sample_ids(labels: np.ndarray, t: np.ndarray, frame_period: float) -> np.ndarray:
    """(N,) frame-sample index per point, 0..S-1, sorted by cluster, then time.

    A cluster's returns form one frame sample while each follows the previous one within
    half a ``frame_period`` (one sweep over the object, both lidars at about the same
    moment); a run longer than ``frame_period`` is cut every ``frame_period`` from its
    first return. The samples depend on the gaps between returns only, not on where a
    fixed time grid happens to start.
    """
    labels = np.asarray(labels, dtype=np.int64).reshape(-1)
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if t.size == 0:
        return np.empty(0, dtype=np.int64)
    order = lex_order(t, labels)
    lab_s, t_s = labels[order], t[order]
    new = np.ones(t_s.size, dtype=bool)
    new[1:] = (lab_s[1:] != lab_s[:-1]) | (np.diff(t_s) > frame_period / 2)
    run_start = np.maximum.accumulate(np.where(new, np.arange(t_s.size), 0))
    within = np.floor((t_s - t_s[run_start]) / frame_period + 1e-6).astype(np.int64)
    key_s = (np.cumsum(new) - 1) * (int(within.max()) + 1) + within
    # key_s never decreases along the sorted points, so numbering its changes gives the
    # same ids as np.unique(key, return_inverse=True) without a second sort.
    step = np.ones(key_s.size, dtype=bool)
    np.not_equal(key_s[1:], key_s[:-1], out=step[1:])
    ids = np.empty(key_s.size, dtype=np.int64)
    ids[order] = np.cumsum(step) - 1
    return ids


def frame_samples(
    labels: np.ndarray, xyz: np.ndarray, t: np.ndarray, k: int, frame_period: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per (cluster, frame) mean: cluster id, time, position, point count, bbox side.

    Samples are those of :func:`frame_sample_ids`: they follow the gaps between returns,
    so adding or removing unrelated points elsewhere in the cloud cannot move a
    fragment's returns from one sample to two. Samples come sorted by cluster, then time.
    """
    inv = frame_sample_ids(labels, t, frame_period)
    n = np.bincount(inv)
    cid = np.empty(n.size, dtype=np.int64)
    cid[inv] = labels
    n = n.astype(np.float64)
    ts = np.bincount(inv, weights=t) / n
    ps = np.stack([np.bincount(inv, weights=xyz[:, a]) for a in range(3)], axis=1) / n[:, None]
    ((lo, hi),) = group_bounds(inv, n.size, xyz)
    return cid, ts, ps, n, (hi - lo).max(axis=1)


def _line_fits(
    cid: np.ndarray, ts: np.ndarray, ps: np.ndarray, w: np.ndarray, sel: np.ndarray, k: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Weighted line fit per cluster over the selected samples.

    Returns (mean time (K,), mean position (K, 3), velocity (K, 3), has velocity (K,)).
    """
    c, tt, pp, ww = cid[sel], ts[sel], ps[sel], w[sel]
    sw = np.bincount(c, weights=ww, minlength=k)
    safe = np.maximum(sw, 1e-12)
    tm = np.bincount(c, weights=ww * tt, minlength=k) / safe
    pm = np.stack([np.bincount(c, weights=ww * pp[:, a], minlength=k) for a in range(3)], 1)
    pm /= safe[:, None]
    dt = tt - tm[c]
    stt = np.bincount(c, weights=ww * dt * dt, minlength=k)
    stp = np.stack(
        [np.bincount(c, weights=ww * dt * (pp[:, a] - pm[c, a]), minlength=k) for a in range(3)],
        axis=1,
    )
    n_samples = np.bincount(c, minlength=k)
    ((t_lo, t_hi),) = group_bounds(c, k, tt)
    has_v = (n_samples >= 2) & (t_hi - t_lo > 0) & (stt > 0)
    vel = np.where(has_v[:, None], stp / np.maximum(stt, 1e-12)[:, None], 0.0)
    return tm, pm, vel, has_v


def _end_windows(
    cid: np.ndarray,
    ts: np.ndarray,
    t_first: np.ndarray,
    t_last: np.ndarray,
    k: int,
    params: ParamSet,
    widen: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(S,) bool each over the frame samples: those a cluster's end state and start state
    are fitted over. Normally its last / first ``link_fit_window`` seconds of samples.
    Where no sample there lies at least :data:`MIN_BASELINE_FRAMES` frame periods from
    the end (two frames 0.1 s apart: a velocity that is mostly noise; or the end sample
    alone: none), the window reaches inward to the nearest such sample, if it is within
    ``link_max_gap`` of the end. ``widen`` (K,) bool: the clusters allowed that (default
    all)."""
    win = float(params.link_fit_window)
    base = MIN_BASELINE_FRAMES * float(params.frame_period)
    gap = float(params.link_max_gap)
    allowed = np.ones(k, dtype=bool) if widen is None else np.asarray(widen, dtype=bool)
    far_e = ts <= t_last[cid] - base
    far_s = ts >= t_first[cid] + base
    ((_, ref_e),) = group_bounds(cid[far_e], k, ts[far_e])  # latest sample base before end
    ((ref_s, _),) = group_bounds(cid[far_s], k, ts[far_s])  # earliest base after start
    from_e = np.where(
        allowed & (ref_e < t_last - win) & (ref_e >= t_last - gap), ref_e, t_last - win
    )
    to_s = np.where(
        allowed & (ref_s > t_first + win) & (ref_s <= t_first + gap), ref_s, t_first + win
    )
    return ts >= from_e[cid], ts <= to_s[cid]


def _stray_ends(
    cid: np.ndarray, ts: np.ndarray, ps: np.ndarray, w: np.ndarray, k: int, params: ParamSet
) -> np.ndarray:
    """(S,) bool over the frame samples (sorted by cluster, then time): each cluster's
    first or last sample when it is a single return farther than the linking reach from
    where the cluster's next ``link_fit_window`` of samples inward was heading (line fit
    with a velocity, over at least two other samples)."""
    stray = np.zeros(ts.size, dtype=bool)
    if ts.size == 0:
        return stray
    n = np.bincount(cid, minlength=k)
    first = np.concatenate([[0], np.cumsum(n)[:-1]])
    last = first + n - 1
    win = float(params.link_fit_window)
    idx = np.arange(ts.size)
    for edge, inner, sign in ((last, last - 1, 1.0), (first, first + 1, -1.0)):
        # Indices clipped for clusters with fewer than three samples, which are not judged.
        edge, inner = np.clip(edge, 0, ts.size - 1), np.clip(inner, 0, ts.size - 1)
        judged = (n >= 3) & (w[edge] == 1)
        if not judged.any():
            continue
        e, i = edge[cid], inner[cid]
        sel = judged[cid] & (idx != e) & (sign * (ts[i] - ts) <= win)
        tm, pm, vel, has_v = _line_fits(cid, ts, ps, w, sel, k)
        c = np.flatnonzero(judged & has_v)
        gap = np.abs(ts[edge[c]] - ts[inner[c]])
        heading = pm[c] + vel[c] * (ts[edge[c]] - tm[c])[:, None]
        off = np.linalg.norm(ps[edge[c]] - heading, axis=1)
        stray[edge[c[off > linking_reach(gap, params)]]] = True
    return stray


class _Ends(NamedTuple):
    """Per cluster: first / last stamp, start / end position and velocity (with whether
    the velocity is known, and its norm)."""

    t_first: np.ndarray
    t_last: np.ndarray
    start_pos: np.ndarray
    end_pos: np.ndarray
    v_s: np.ndarray
    v_e: np.ndarray
    has_s: np.ndarray
    has_e: np.ndarray
    speed_s: np.ndarray
    speed_e: np.ndarray
    first_seen: np.ndarray  # first / last stamp with the stray ends kept
    last_seen: np.ndarray


def _linkable(
    aa: np.ndarray, b: np.ndarray, ends: _Ends, params: ParamSet
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The candidate pairs (a, b) that may link, and their costs."""
    t_first, t_last, start_pos, end_pos, v_s, v_e, has_s, has_e, speed_s, speed_e = ends[:10]
    first_seen, last_seen = ends.first_seen, ends.last_seen  # with stray ends kept
    fp = float(params.frame_period)
    gap = float(params.link_max_gap)
    dt = t_first[b] - t_last[aa]
    adt = np.abs(dt)
    known_a, known_b = has_e[aa], has_s[b]
    any_v = known_a | known_b
    # A stray end left out moves the end back in time, not the object: the reach is at
    # most that of the gap between the fragments' returns (fast_pass seed 1604: a crown's
    # three returns otherwise joined the drone's track 1.7 s later).
    reach = np.minimum(
        linking_reach(adt, params),
        linking_reach(first_seen[b] - last_seen[aa], params),
    )
    plain = np.linalg.norm(start_pos[b] - end_pos[aa], axis=-1)
    # Two fragments without a velocity link only across one frame period: chains
    # of single sparse returns (far structure, noise) would otherwise form. And
    # carried by a velocity v over dt, an end gets at most |v| dt closer to a start:
    # pairs farther apart than that plus the reach cannot link (most of a scene).
    speed = np.maximum(np.where(known_a, speed_e[aa], 0.0), np.where(known_b, speed_s[b], 0.0))
    near = (any_v | (adt <= fp + 1e-6)) & (plain - speed * adt <= reach + 1e-6)
    aa, b, dt, adt, known_a, known_b, any_v, reach, plain = (
        x[near] for x in (aa, b, dt, adt, known_a, known_b, any_v, reach, plain)
    )
    fwd = np.linalg.norm(end_pos[aa] + v_e[aa] * dt[:, None] - start_pos[b], axis=-1)
    back = np.linalg.norm(start_pos[b] - v_s[b] * dt[:, None] - end_pos[aa], axis=-1)
    dist = np.where(known_a, fwd, np.inf)
    dist = np.minimum(dist, np.where(known_b, back, np.inf))
    dist = np.where(any_v, dist, plain)
    ok = dist <= reach
    if params.link_rest_speed > 0:
        # One end at rest: the object started (or stopped) during the gap, and at
        # constant acceleration covered the mean of the two velocities times the gap.
        # The nearer single-velocity carry alone let a bird's leg, carried back at its
        # full speed, join a crown's returns it never left from (deviation 128).
        slowest = np.minimum(speed_e[aa], speed_s[b])
        r = np.flatnonzero(known_a & known_b & (slowest <= float(params.link_rest_speed)))
        if r.size:
            ra, rb = aa[r], b[r]
            mean_v = 0.5 * (v_e[ra] + v_s[rb])
            mid = np.linalg.norm(end_pos[ra] + mean_v * dt[r, None] - start_pos[rb], axis=-1)
            ok[r] &= mid <= reach[r]
    if params.link_max_dv > 0:
        # Both ends moving: the object cannot have changed its velocity by more than it
        # could accelerate over the gap, give or take the fits' error (deviation 88).
        dv = np.linalg.norm(v_s[b] - v_e[aa], axis=-1)
        turn = float(params.link_max_dv) + float(params.link_max_accel) * adt
        ok &= ~(known_a & known_b) | (dv <= turn)
    # Distance relative to the reach, plus the gap relative to link_max_gap: the next
    # fragment in time comes first (by distance alone, the reach growing with the gap
    # would let A skip over B to C, leaving B alone).
    return aa[ok], b[ok], dist[ok] / reach[ok] + adt[ok] / gap


def chains_formed(before: np.ndarray, after: np.ndarray, k_after: int) -> np.ndarray:
    """(K_after,) bool: the clusters of ``after`` that joined several of ``before``."""
    keep = before >= 0
    width = int(before.max()) + 1
    pairs = voxel.unique_ints(after[keep] * width + before[keep])
    return np.bincount(pairs // width, minlength=k_after) > 1


def link_fragments(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    params: ParamSet,
    active: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """Relabel so that linked fragments share one label; returns (labels, K).

    ``labels`` must be compact (0..K-1, -1 noise). With ``link_max_gap`` 0 the labels
    are returned unchanged. ``active`` (K,) bool: only pairs with at least one active
    cluster are considered. After a round, the clusters that took part in no link can
    only link to a chain formed in it (:func:`chains_formed`): a pair of them that could
    link had both ends free when the greedy pass reached it, and would have been taken.
    """
    labels = np.asarray(labels, dtype=np.int64)
    k = int(labels.max()) + 1 if labels.size else 0
    gap = float(params.link_max_gap)
    if k < 2 or gap <= 0:
        return labels, k
    keep = labels >= 0
    lab = labels[keep]
    pts = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)[keep]
    tt = np.asarray(t, dtype=np.float64)[keep]
    fp = float(params.frame_period)
    counts = np.bincount(lab, minlength=k)
    cz = np.bincount(lab, weights=pts[:, 2], minlength=k) / np.maximum(counts, 1)
    candidate = (counts > 0) & (counts <= params.max_cluster_points) & (cz >= params.min_centroid_z)
    if np.count_nonzero(candidate) < 2:
        return labels, k
    # Only candidates' frame samples are needed (every step below is per cluster, so the
    # others' points change nothing): large or low clusters, often most of the points, are
    # left out before the sort.
    sub = np.flatnonzero(candidate[lab])
    cid, ts, ps, w, side = frame_samples(lab[sub], pts[sub], tt[sub], k, fp)
    n_frames = np.bincount(cid, minlength=k)
    mean_side = np.bincount(cid, weights=side, minlength=k) / np.maximum(n_frames, 1)
    eligible = candidate & (mean_side <= params.max_local_extent)
    if np.count_nonzero(eligible) < 2:
        return labels, k
    # A lone return at either end that the rest of the fragment did not head for (another
    # object's, joined by the clusterer) does not define that end (deviation 65).
    ((first_seen, last_seen),) = group_bounds(cid, k, ts)
    t_first, t_last = first_seen, last_seen
    stray = _stray_ends(cid, ts, ps, w, k, params)
    if stray.any():
        cid, ts, ps, w = cid[~stray], ts[~stray], ps[~stray], w[~stray]
        ((t_first, t_last),) = group_bounds(cid, k, ts)
    end_sel, start_sel = _end_windows(cid, ts, t_first, t_last, k, params)
    tm_e, pm_e, v_e, has_e = _line_fits(cid, ts, ps, w, end_sel, k)
    tm_s, pm_s, v_s, has_s = _line_fits(cid, ts, ps, w, start_sel, k)
    with np.errstate(invalid="ignore"):  # NaN for the non-candidates (no samples): unread
        end_pos = pm_e + v_e * (t_last - tm_e)[:, None]
        start_pos = pm_s + v_s * (t_first - tm_s)[:, None]
    speed_e = np.linalg.norm(v_e, axis=1)
    speed_s = np.linalg.norm(v_s, axis=1)
    ends = _Ends(
        t_first,
        t_last,
        start_pos,
        end_pos,
        v_s,
        v_e,
        has_s,
        has_e,
        speed_s,
        speed_e,
        first_seen,
        last_seen,
    )
    idx = np.nonzero(eligible)[0]
    if active is None:
        row_sets = [(idx, idx)]
    else:
        is_active = np.asarray(active, dtype=bool)[idx]
        # Active rows with every column, then the other rows with active columns only.
        row_sets = [(idx[is_active], idx), (idx[~is_active], idx[is_active])]
    pairs_a, pairs_b, pairs_cost = [], [], []
    for rows_idx, cols_idx in row_sets:
        if rows_idx.size == 0 or cols_idx.size == 0:
            continue
        order = cols_idx[np.argsort(t_first[cols_idx], kind="stable")]
        starts = t_first[order]
        # Successor candidates of a: clusters starting in [t_last(a) - fp, t_last(a) + gap].
        first_all = np.searchsorted(starts, t_last[rows_idx] - fp, side="left")
        last_all = np.searchsorted(starts, t_last[rows_idx] + gap, side="right")
        lo = 0
        while lo < rows_idx.size:
            # Blocks of rows x candidate columns bounded to about _BLOCK_CELLS entries.
            width = int((last_all[lo : lo + _BLOCK] - first_all[lo : lo + _BLOCK]).max())
            rows = max(1, min(_BLOCK, _BLOCK_CELLS // max(width, 1)))
            a = rows_idx[lo : lo + rows]
            first, last = first_all[lo : lo + rows], last_all[lo : lo + rows]
            lo += rows
            width = int((last - first).max())
            if width <= 0:
                continue
            j = first[:, None] + np.arange(width)[None, :]
            valid = j < last[:, None]
            b = order[np.minimum(j, order.size - 1)]
            aa = np.broadcast_to(a[:, None], b.shape)
            valid &= b != aa
            valid &= t_first[b] > t_first[aa]  # B must start after A started
            aa, b = aa[valid], b[valid]
            found = _linkable(aa, b, ends, params)
            pairs_a.append(found[0])
            pairs_b.append(found[1])
            pairs_cost.append(found[2])
    if not pairs_a:
        return labels, k
    pa, pb, cost = (np.concatenate(x) for x in (pairs_a, pairs_b, pairs_cost))
    if pa.size == 0:
        return labels, k
    succ = np.full(k, -1, dtype=np.int64)
    pred = np.full(k, -1, dtype=np.int64)
    for i in np.argsort(cost, kind="stable"):
        a, b = int(pa[i]), int(pb[i])
        if succ[a] < 0 and pred[b] < 0:
            succ[a] = b
            pred[b] = a
    # Each chain takes the label of its head (a cluster without predecessor).
    root = np.where(pred >= 0, pred, np.arange(k))
    while True:  # pointer jumping: log2(longest chain) rounds
        new = root[root]
        if np.array_equal(new, root):
            break
        root = new
    _, compact = voxel.unique_ints(root, return_inverse=True)
    out = labels.copy()
    out[keep] = compact.reshape(-1)[lab]
    return out, int(compact.max()) + 1


def end_state(
    t: np.ndarray, xyz: np.ndarray, params: ParamSet, forward: bool
) -> tuple[float, np.ndarray, np.ndarray | None]:
    """(time, position, velocity or None) at the last (``forward``) or first point.

    The line is fitted over the frame samples of :func:`_end_windows`: a sparse track's
    end in the sky still has a velocity, from the next sample inward. Not when the end
    sample lies below ``min_centroid_z``: near the ground, where a landing drone's track
    may have taken a person's returns, only the samples within ``link_fit_window``."""
    edge = float(t.max() if forward else t.min())
    span = max(float(params.link_fit_window), float(params.link_max_gap))
    sel = np.abs(t - edge) <= span
    zeros = np.zeros(int(np.count_nonzero(sel)), dtype=np.int64)
    cid, ts, ps, w, _ = frame_samples(zeros, xyz[sel], t[sel], 1, float(params.frame_period))
    ((t_first, t_last),) = group_bounds(cid, 1, ts)
    at_edge = int(np.argmax(ts) if forward else np.argmin(ts))
    in_sky = np.array([ps[at_edge, 2] >= params.min_centroid_z])
    end_sel, start_sel = _end_windows(cid, ts, t_first, t_last, 1, params, widen=in_sky)
    tm, pm, vel, has_v = _line_fits(cid, ts, ps, w, end_sel if forward else start_sel, 1)
    pos = pm[0] + vel[0] * (edge - tm[0])
    return edge, pos, (vel[0] if has_v[0] else None)


def extend_track(
    member: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    pool: np.ndarray,
    params: ParamSet,
    short_gap: np.ndarray | None = None,
    grow_end: bool = True,
    grow_start: bool = True,
    heading: np.ndarray | None = None,
) -> np.ndarray:
    """Grow a selected track at both ends with points of ``pool`` where it was heading.

    ``member`` (N,) bool marks the track's points, ``pool`` (N,) bool the points it may
    take (noise and clusters too small to be scored alone). Step by step, the pool points
    of the next frame beyond the track's end within the linking reach of its end state
    (:func:`link_fragments`) join it and the end state is refitted; the same backwards
    from its start. The next frame may be up to ``extend_max_gap`` (at most
    ``link_max_gap``) beyond the end: a fast pass far away leaves returns 1-1.5 s apart.
    An end whose samples within ``link_fit_window`` span less than three frame periods
    (one sample alone, or two frames 0.1 s apart) takes its velocity over the nearest
    sample further inward (:func:`end_state`; not near the ground). A point within
    ``link_gate`` of where the track would be had it braked along its way harder than
    ``link_max_accel``, up to ``extend_max_brake`` (:func:`_braking_offsets`), joins it
    too: a drone stopping into a hover (backwards in time: speeding away from one). An
    end slower than ``min_speed`` (hovering) also takes, across gaps longer than that up
    to ``extend_hover_gap``, the returns within ``track_gate`` of where it was heading;
    across gaps longer than ``max_gap`` it takes only those (deviation 109).
    An end leaving the lidars (:func:`_leaving`: a pass whose returns thin out with
    range) takes, across gaps up to ``extend_far_gap``, a lone return near its line
    farther out (:func:`_near_line`) at a spot that returned nothing else a second
    before or after (:func:`_returned_near`). With ``extend_brake_hover``, an end still
    moving takes, across gaps up to ``extend_hover_gap``, a return where braking would
    have stopped it (:func:`_braking_offsets`) that another pool return confirms there
    within ``max_gap``: a drone braking into a hover, then seen in lone returns. With
    ``extend_stop_hover``, such a return that spans no velocity of its own is an end
    at rest, and growth goes on from it as from a hovering end (deviation 138).
    With ``extend_stay_scatter``, the returns taken in one direction from the first
    step across more than the usual gap by a slow or braking end on are given back if
    they stay in place and scatter more than a drone's body (:func:`_scattered_stay`).
    ``short_gap`` (N,) bool: pool points that join only within ``max_extrapolation`` of
    the end. ``grow_end`` False: grow the start only; ``grow_start`` False: the end
    only. ``heading`` (N,) bool: the members that define the ends (where and when the
    track was heading), if any of them does; default all but a lone stray end. Returns
    the new member mask.
    """
    member = np.asarray(member, dtype=bool).copy()
    pool = np.asarray(pool, dtype=bool) & ~member
    gap = min(float(params.link_max_gap), float(params.extend_max_gap))
    if gap <= 0 or not member.any() or not pool.any():
        return member
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(t, dtype=np.float64)
    fp = float(params.frame_period)
    pool_idx = np.nonzero(pool)[0]
    pool_idx = pool_idx[np.argsort(t[pool_idx], kind="stable")]
    pool_t = t[pool_idx]
    pool_xyz = xyz[pool_idx]
    # A lone stray return at either end of the track (another object's, joined by the
    # clusterer) stays a member but does not define where the track was heading.
    inner = member & ~_stray_end_points(member, xyz, t, params)
    if heading is not None and (inner & heading).any():
        inner &= heading
    hover_gap = float(params.extend_hover_gap)
    far_gap = float(params.extend_far_gap)
    viewpoint = np.asarray(params.viewpoint, dtype=np.float64)
    for forward in [f for f, grow in ((True, grow_end), (False, grow_start)) if grow]:
        taken = np.zeros(pool_idx.size, dtype=bool)
        slow = False
        stopped = False  # the last step took a return where a braking end stopped
        stay = np.zeros(pool_idx.size, dtype=bool)  # taken since the first long pause
        paused = False
        while True:
            m = np.nonzero(inner)[0]
            edge, pos, vel = end_state(t[m], xyz[m], params, forward)
            if vel is None and (slow or stopped) and hover_gap > gap:
                # A lone return taken across a hover's pause, or where a braking end
                # came to a stop (extend_stop_hover): hovering there.
                vel = np.zeros(3)
            slow = vel is not None and float(np.linalg.norm(vel)) < params.min_speed
            end_range = float(np.linalg.norm(pos - viewpoint))
            leaving = far_gap > gap and _leaving(pos - viewpoint, vel, forward)
            # A moving end braking into a hover (extend_brake_hover, deviation 124).
            braking = (
                params.extend_brake_hover
                and not slow
                and vel is not None
                and hover_gap > gap
                and float(params.extend_max_brake) > float(params.link_max_accel)
            )
            if slow:
                span = max(gap, hover_gap)
            elif leaving:
                span = max(gap, far_gap, hover_gap if braking else 0.0)
            else:
                span = max(gap, hover_gap) if braking else gap
            if forward:
                lo = np.searchsorted(pool_t, edge, side="right")
                hi = np.searchsorted(pool_t, edge + span, side="right")
            else:
                lo = np.searchsorted(pool_t, edge - span, side="left")
                hi = np.searchsorted(pool_t, edge, side="left")
            cand = np.arange(lo, hi)
            cand = cand[~taken[cand]]
            if short_gap is not None:
                far = np.abs(pool_t[cand] - edge) > params.max_extrapolation
                cand = cand[~(far & short_gap[pool_idx[cand]])]
            if cand.size == 0:
                break
            dt = pool_t[cand] - edge
            adt = np.abs(dt)
            if vel is None:
                pred = np.broadcast_to(pos, (cand.size, 3))
                reach = np.where(adt <= fp + 1e-6, params.link_gate, -1.0)
            else:
                pred = pos + dt[:, None] * vel
                reach = linking_reach(adt, params)
                if slow:
                    # A hovering end: beyond the usual gap (a hover's pause), where it was.
                    # Past max_gap within it, at most that far: a return taken there becomes
                    # a segment of its own, reported where it lies; within the full linking
                    # reach it was a passing bird's (deviation 109, hover 4801, 47th set).
                    gate = params.track_gate
                    capped = np.where(adt > params.max_gap, np.minimum(reach, gate), reach)
                    reach = np.where(adt > gap, gate, capped)
            pts = pool_xyz[cand]
            ok = np.linalg.norm(pts - pred, axis=1) <= reach
            if vel is not None:
                brake_ok = _braking_offsets(pts, pos, vel, dt, params) <= params.link_gate
                ok |= brake_ok
            beyond = adt > gap
            far_ok = np.zeros(cand.size, dtype=bool)
            if leaving and beyond.any():  # a lone return far out, near its line
                far_ok = beyond & (adt <= far_gap) & ok
                far_ok &= _near_line(pts, pos, vel, dt, end_range, viewpoint, params)
                # At a spot nothing else returned from a second before or after: a tree
                # crown or a wall far out returns now and then at the same spot (too
                # seldom to be static), a drone passing through does not.
                for i in np.nonzero(far_ok)[0]:
                    far_ok[i] = not _returned_near(
                        pts[i], pool_t[cand[i]], xyz, t, 2.0 * params.link_gate, 1.0
                    )
            if leaving or braking:
                # Beyond the usual gap only what these rules take: a lone far return on
                # a leaving pass's line, or one where a braking end stopped that returned
                # again there (a tree's or noise return alone does not: fast_pass 2504,
                # `birds` 3201).
                stop_ok = beyond & brake_ok if braking else np.zeros(cand.size, dtype=bool)
                # A drone stopped there returns again there: another pool return in
                # another frame at most max_gap away.
                for i in np.nonzero(stop_ok)[0]:
                    stop_ok[i] = _returned_near(
                        pts[i],
                        pool_t[cand[i]],
                        pool_xyz,
                        pool_t,
                        params.link_gate,
                        fp / 2,
                        params.max_gap,
                    )
                ok = np.where(beyond, far_ok | stop_ok, ok)
            if not ok.any():
                break
            # The nearest frame in time among the reachable points joins the track.
            near_t = adt[ok].min()
            join = cand[ok & (adt <= near_t + fp / 2)]
            paused = paused or (near_t > gap and (slow or braking))
            stopped = bool(params.extend_stop_hover) and near_t > gap and braking
            stay[join] = paused
            taken[join] = True
            member[pool_idx[join]] = True
            inner[pool_idx[join]] = True
        if params.extend_stay_scatter and _scattered_stay(pool_xyz[stay], pool_t[stay], params):
            member[pool_idx[stay]] = False
            inner[pool_idx[stay]] = False
    return member


def stay_scatter(
    xyz: np.ndarray, t: np.ndarray, max_extent: float, frame_period: float
) -> float | None:
    """The scatter (:func:`~.scoring.local_scatter`) of returns that stay in place: at
    least three frame samples (:func:`frame_sample_ids`) within a bounding box of
    ``max_extent``; None for returns that are no such stay."""
    if t.size < 3 or float(np.ptp(xyz, axis=0).max()) > max_extent:
        return None
    group = np.zeros(t.size, dtype=np.int64)
    if int(frame_sample_ids(group, t, frame_period).max()) < 2:
        return None
    return float(local_scatter(group, xyz, t, 1)[0])


def _scattered_stay(xyz: np.ndarray, t: np.ndarray, params: ParamSet) -> bool:
    """Whether returns a growing end took after a hover's pause (deviation 131) are a
    stay in place (:func:`stay_scatter` within ``hover_max_extent``) that scatters more
    than ``hover_max_scatter``: a tree crown seen a return at a time, not a hovering
    drone, whose returns lie on its body."""
    limit = float(params.hover_max_scatter)
    if limit <= 0:
        return False
    scatter = stay_scatter(xyz, t, params.hover_max_extent, params.frame_period)
    return scatter is not None and scatter > limit


#: Slowest end (m/s) that grows across gaps up to ``extend_far_gap`` while leaving.
_LEAVING_MIN_SPEED = 3.0
#: Nearest (m from ``viewpoint``) a return taken across such a gap may be: closer in, a
#: drone gives returns every frame or two, and a gap of seconds is not its range.
_LEAVING_MIN_RANGE = 40.0


def _leaving(offset: np.ndarray, vel: np.ndarray | None, forward: bool) -> bool:
    """Whether a track end at ``offset`` from the viewpoint, with velocity ``vel``, moves
    away from the lidars in the direction of growth (forward in time: receding;
    backward: it came from farther out) at least ``_LEAVING_MIN_SPEED``, mostly along
    the line of sight (radial speed at least half its speed): a pass whose returns
    thin out with range, seconds apart at 50-80 m."""
    if vel is None:
        return False
    speed = float(np.linalg.norm(vel))
    distance = float(np.linalg.norm(offset))
    if speed < _LEAVING_MIN_SPEED or distance <= 0.0:
        return False
    radial = float(vel @ offset) / distance
    return (radial if forward else -radial) >= 0.5 * speed


def _near_line(
    pts: np.ndarray,
    pos: np.ndarray,
    vel: np.ndarray,
    dt: np.ndarray,
    end_range: float,
    viewpoint: np.ndarray,
    params: ParamSet,
) -> np.ndarray:
    """(M,) bool: points ``dt`` s from a leaving track's end (``pos``, velocity ``vel``,
    ``end_range`` from ``viewpoint``) that lie farther out than the end, within the
    linking reach along its line and within ``link_gate`` plus a quarter of the
    acceleration allowance across it: at 10 m/s and 50-80 m out, a pass holds its
    course better than its speed, and a looser gate takes vegetation and structure
    returns at the same range (fast_pass, 270 tuning runs)."""
    unit = vel / float(np.linalg.norm(vel))
    off = pts - (pos + dt[:, None] * vel)
    along = off @ unit
    across = np.linalg.norm(off - along[:, None] * unit, axis=1)
    reach = linking_reach(dt, params)
    lateral = params.link_gate + 0.125 * params.link_max_accel * dt * dt
    distance = np.linalg.norm(pts - viewpoint, axis=1)
    far = (distance > end_range) & (distance >= _LEAVING_MIN_RANGE)
    return far & (np.abs(along) <= reach) & (across <= lateral)


def _returned_near(
    point: np.ndarray,
    stamp: float,
    xyz: np.ndarray,
    t: np.ndarray,
    radius: float,
    min_dt: float,
    max_dt: float = np.inf,
) -> bool:
    """Whether any of the returns ``xyz``, ``t`` lies within ``radius`` of ``point``,
    more than ``min_dt`` and at most ``max_dt`` seconds from ``stamp``."""
    dt = np.abs(t - stamp)
    near = (dt > min_dt) & (dt <= max_dt)
    return bool((near & (np.linalg.norm(xyz - point, axis=1) <= radius)).any())


def _braking_offsets(
    pts: np.ndarray, pos: np.ndarray, vel: np.ndarray, dt: np.ndarray, params: ParamSet
) -> np.ndarray:
    """(M,) distance (m) of each point from where the track would be ``dt`` seconds from
    its end (``pos``, velocity ``vel``) had it braked along its way at a deceleration
    between ``link_max_accel`` (whose reach covers the gentler ones) and
    ``extend_max_brake``, coming to a stop at most; inf where ``extend_max_brake`` is
    not above ``link_max_accel`` or the track is not moving."""
    brake, gentle = float(params.extend_max_brake), float(params.link_max_accel)
    speed = float(np.linalg.norm(vel))
    if brake <= gentle or speed <= 0:
        return np.full(len(pts), np.inf)
    unit = vel / speed
    adt = np.abs(dt)

    def covered(a: float) -> np.ndarray:  # distance along the way after adt, braking at a
        tau = np.minimum(adt, speed / a) if a > 0 else adt
        return speed * tau - 0.5 * a * tau * tau

    sign = np.sign(dt)
    along = sign * ((pts - pos) @ unit)  # along the way, in the direction of growth
    d = np.clip(along, covered(brake), covered(gentle))
    nearest = pos + (sign * d)[:, None] * unit
    return np.linalg.norm(pts - nearest, axis=1)


def _stray_end_points(
    member: np.ndarray, xyz: np.ndarray, t: np.ndarray, params: ParamSet
) -> np.ndarray:
    """(N,) bool: the member points of the track's first or last frame sample when that
    is a stray end (:func:`_stray_ends`)."""
    m = np.nonzero(member)[0]
    ids = frame_sample_ids(np.zeros(m.size, np.int64), t[m], float(params.frame_period))
    cid, ts, ps, w, _ = frame_samples(
        np.zeros(m.size, np.int64), xyz[m], t[m], 1, float(params.frame_period)
    )
    stray = np.zeros(member.size, dtype=bool)
    stray[m] = _stray_ends(cid, ts, ps, w, 1, params)[ids]
    return stray


def fill_track(
    member: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    pool: np.ndarray,
    params: ParamSet,
    max_reach: float | None = None,
) -> np.ndarray:
    """Fill the gaps inside a selected track with points of ``pool`` lying on its path.

    :func:`extend_track` grows a track at its two ends only. Inside it, a drone seen
    once a second (hovering, or far away) leaves returns the clusterer calls noise
    between the ones it kept, and gaps of several seconds without a kept one. A pool
    point between two consecutive per-frame samples of the track joins it when it lies
    within the linking reach of the position interpolated linearly at its stamp: the
    reach for half the gap (a path bending at ``link_max_accel`` leaves the chord by at
    most that much at the middle), at most the reach for half of ``link_max_gap`` and at
    most ``max_reach`` when given. Returns the new member mask.
    """
    member = np.asarray(member, dtype=bool).copy()
    pool = np.asarray(pool, dtype=bool) & ~member
    m = np.nonzero(member)[0]
    if m.size < 2 or not pool.any() or params.link_max_gap <= 0:
        return member
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(t, dtype=np.float64)
    _, ts, ps, _, _ = frame_samples(
        np.zeros(m.size, np.int64), xyz[m], t[m], 1, float(params.frame_period)
    )
    idx = np.nonzero(pool & (t > ts[0]) & (t < ts[-1]))[0]
    if idx.size == 0:
        return member
    j = np.clip(np.searchsorted(ts, t[idx], side="right"), 1, ts.size - 1)
    gap = ts[j] - ts[j - 1]
    w = np.clip((t[idx] - ts[j - 1]) / np.maximum(gap, 1e-9), 0.0, 1.0)[:, None]
    pred = ps[j - 1] + w * (ps[j] - ps[j - 1])
    reach = linking_reach(np.minimum(gap, params.link_max_gap) / 2, params)
    if max_reach is not None:
        reach = np.minimum(reach, max_reach)
    member[idx[np.linalg.norm(xyz[idx] - pred, axis=1) <= reach]] = True
    return member
