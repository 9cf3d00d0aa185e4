"""Split a cluster that joined several flying objects into kinematic tracks.

Birds flying around a drone a few metres away touch its returns in the clusterer's 2 m
space-time voxels, and the drone and the birds become one cluster that is too wide
(``max_local_extent``) or too erratic to be a drone. Such a cluster is taken apart the
way a tracker would:

1. its returns are grouped into frame samples (:func:`~.linking.frame_sample_ids`), and
   within each sample into *return groups*: connected components of ``split_blob``
   voxels, one object's returns in one sweep;
2. the groups are tracked through the samples in time order. Each live track predicts its
   position at the sample's time by a straight-line fit over its last
   ``link_fit_window`` s of groups; a group within ``split_gate + link_max_accel dt^2 / 2``
   (at most ``split_gate + link_max_speed dt``) of a prediction may continue that track,
   and the pairing of tracks and groups that minimises the distances relative to these
   reaches is taken (Hungarian assignment), so two objects side by side each keep their
   own track. A track without a velocity (one group in its last ``link_fit_window``)
   reaches ``split_gate + min(link_max_speed dt, 2 link_gate)`` around its newest group.
   A track not continued for more than ``link_max_gap`` ends; a group no track takes
   starts a new one;
3. every track becomes a cluster of its own and is scored like any other.

Which track keeps the drone among birds within a metre of it depends on the assignment;
offline (:func:`split_and_score` with ``two_trackers``) each cluster is also split with a
matching cascade (tracks with a velocity choose first) and keeps the split whose best
reportable piece ranks higher.

A confident cluster is split too when two of its tracks are seen apart in several
sweeps (:func:`two_objects`): a bird that crossed the drone's path and flew on.

Only flying clusters are split (centroid above ``min_centroid_z``), and, when the static
structure is known, only those with at most :data:`MAX_CONTACT` of their points in or
next to its voxels: what suppression leaves of walls and crowns is often wide, and
splitting it costs time and finds nothing. A cluster that moves (motion coherence at
least :data:`MOVING_COHERENCE`) is split whatever its contact: birds circling over one
spot for a while fill voxels often enough to be suppressed as structure, and the rest of
their returns, and a drone's merged with them, then lie next to "structure" of their own.

The loop runs over frame samples of the few clusters that are split, never over points.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.optimize import linear_sum_assignment

from clusterfilter_ros.core import voxel
from clusterfilter_ros.core.clustering import relabel_compact, voxel_clusters
from clusterfilter_ros.core.grouping import group_bounds, lex_order
from clusterfilter_ros.core.linking import frame_sample_ids, linking_reach
from clusterfilter_ros.core.params import ParamSet
from clusterfilter_ros.core.scoring import ClusterScores, select_and_append, structure_contact

_SAME_SAMPLE_OFFSETS = np.array(
    [voxel.spacetime_offset_key((dx, dy, dz, 0)) for dx, dy, dz in voxel.HALF_OFFSETS],
    dtype=np.int64,
)
_UNREACHABLE = 1e6
#: Largest share of a cluster's points in or next to static structure for it to be split.
MAX_CONTACT = 0.1
#: Motion coherence from which a cluster is split whatever its contact with structure.
#: Remnants of walls and crowns mostly measure 0-0.1 (a few 0.3-0.46 in the streaming
#: history); a drone merged with birds circling it 0.55-0.65 (docs/detector.md, dev. 57).
MOVING_COHERENCE = 0.4
#: A cluster left whole for its contact with structure is tested for :func:`two_objects`
#: (``split_and_score``'s ``contact_apart``) from this motion coherence (the remnants of
#: walls that test as two objects measured 0.02-0.14, a drone merged with a walking
#: person 0.21-0.38) ...
APART_COHERENCE = 0.2
#: ... and this share of its returns below ``min_centroid_z``: an object on the ground
#: (a person) joined to one in the air. Without it, drones among birds (no returns near
#: the ground) were split this way too, and a flock split into single birds had one
#: reported (deviation 148).
GROUND_SHARE = 0.1
#: Seconds per centroid in :func:`still_run`: several sweeps of a sparse drone's returns.
STILL_STEP = 0.5
#: :func:`two_objects`: the kinematic tracks compared hold at least this many returns
#: (a stray return or two of sky noise starts a track of its own) ...
APART_TRACK_POINTS = 8
#: ... and lie apart in at least this many frame samples (docs/detector.md, dev. 87).
APART_SAMPLES = 3


def return_groups(
    xyz: np.ndarray, t: np.ndarray, frame_period: float, blob: float
) -> tuple[np.ndarray, np.ndarray]:
    """(group id per point 0..G-1, frame sample of each group (G,)).

    A group is a connected component (26-neighbourhood) of ``blob`` voxels holding
    returns of one frame sample.
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if t.size == 0:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)
    sample = frame_sample_ids(np.zeros(t.size, dtype=np.int64), t, frame_period)
    keys = voxel.spacetime_keys(xyz, sample.astype(np.float64), blob, 1.0)
    ukeys, inverse = voxel.unique_ints(keys, return_inverse=True, fields=voxel.SPACETIME_FIELDS)
    inverse = inverse.reshape(-1)
    comp = voxel_clusters(ukeys, np.ones(ukeys.size), 1.0, _SAME_SAMPLE_OFFSETS)
    groups, n_groups = relabel_compact(comp[inverse])
    group_sample = np.empty(n_groups, dtype=np.int64)
    group_sample[groups] = sample
    return groups, group_sample


def _predictions(
    track: np.ndarray,
    g_t: np.ndarray,
    g_p: np.ndarray,
    live: np.ndarray,
    last_t: np.ndarray,
    last_p: np.ndarray,
    now: float,
    params: ParamSet,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted position at ``now`` (L, 3), reach (L,) and whether it has a velocity
    (L,) bool, of each live track.

    ``track``, ``g_t``, ``g_p``: track, time and position of the groups seen recently;
    ``live``: the live tracks' ids; ``last_t`` / ``last_p``: every track's newest group.
    """
    slot = np.full(last_t.size, -1, dtype=np.int64)
    slot[live] = np.arange(live.size)
    mine = track >= 0
    mine[mine] = slot[track[mine]] >= 0
    mine[mine] = g_t[mine] >= last_t[track[mine]] - params.link_fit_window
    c, tt, pp = slot[track[mine]], g_t[mine], g_p[mine]
    n = np.bincount(c, minlength=live.size).astype(np.float64)
    safe = np.maximum(n, 1.0)
    tm = np.bincount(c, weights=tt, minlength=live.size) / safe
    pm = np.stack([np.bincount(c, weights=pp[:, a], minlength=live.size) for a in range(3)], 1)
    pm /= safe[:, None]
    dt = tt - tm[c]
    stt = np.bincount(c, weights=dt * dt, minlength=live.size)
    stp = np.stack(
        [np.bincount(c, weights=dt * (pp[:, a] - pm[c, a]), minlength=live.size) for a in range(3)],
        axis=1,
    )
    moving = (n >= 2) & (stt > 1e-12)
    velocity = stp / np.where(moving, stt, 1.0)[:, None]
    centre = np.where(moving[:, None], pm + velocity * (now - tm)[:, None], last_p[live])
    gap = now - last_t[live]
    gate = params.split_gate
    reach = np.where(
        moving,
        linking_reach(gap, params, gate),
        gate + np.minimum(params.link_max_speed * gap, 2.0 * params.link_gate),
    )
    return centre, reach, moving


def kinematic_tracks(
    xyz: np.ndarray, t: np.ndarray, params: ParamSet, cascade: bool = False
) -> np.ndarray:
    """(N,) track label per point, 0..K-1; see the module docstring. With ``cascade``,
    the tracks with a velocity are assigned their groups first and those without one
    take what is left (a matching cascade)."""
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if t.size == 0:
        return np.empty(0, dtype=np.int64)
    groups, group_sample = return_groups(xyz, t, params.frame_period, params.split_blob)
    n = np.bincount(groups).astype(np.float64)
    g_t = np.bincount(groups, weights=t) / n
    # Groups in processing order: by frame sample, then time.
    order = lex_order(g_t, group_sample)
    g_t = g_t[order]
    g_p = np.stack([np.bincount(groups, weights=xyz[:, a]) for a in range(3)], axis=1)
    g_p = (g_p / n[:, None])[order]
    bounds = np.flatnonzero(np.diff(group_sample[order])) + 1
    starts = np.concatenate([[0], bounds])
    ends = np.concatenate([bounds, [order.size]])
    sample_t = np.add.reduceat(g_t, starts) / (ends - starts)
    # Groups before this are too old to shape any live track's prediction.
    lookback = params.link_max_gap + params.link_fit_window + params.frame_period
    first = starts[np.searchsorted(sample_t, sample_t - lookback)]
    track = np.full(order.size, -1, dtype=np.int64)
    last_t = np.empty(order.size)
    last_p = np.empty((order.size, 3))
    n_tracks = 0
    for a, b, now, lo in zip(starts, ends, sample_t, first, strict=True):
        age = now - last_t[:n_tracks]
        live = np.flatnonzero((age > 0) & (age <= params.link_max_gap))
        if live.size:
            centre, reach, moving = _predictions(
                track[lo:a],
                g_t[lo:a],
                g_p[lo:a],
                live,
                last_t[:n_tracks],
                last_p[:n_tracks],
                now,
                params,
            )
            dist = np.linalg.norm(g_p[a:b][None, :, :] - centre[:, None, :], axis=2)
            cost = np.where(dist <= reach[:, None], dist / reach[:, None], _UNREACHABLE)
            stages = (moving, ~moving) if cascade else (np.ones(live.size, dtype=bool),)
            for stage in stages:
                free = np.flatnonzero(track[a:b] < 0)
                if not stage.any() or free.size == 0:
                    continue
                sub = cost[np.ix_(np.flatnonzero(stage), free)]
                rows, cols = linear_sum_assignment(sub)
                taken = sub[rows, cols] < _UNREACHABLE
                rows = live[np.flatnonzero(stage)[rows[taken]]]
                cols = free[cols[taken]] + a
                track[cols] = rows
                last_t[rows] = g_t[cols]
                last_p[rows] = g_p[cols]
        new = a + np.flatnonzero(track[a:b] < 0)
        track[new] = np.arange(n_tracks, n_tracks + new.size)
        last_t[n_tracks : n_tracks + new.size] = g_t[new]
        last_p[n_tracks : n_tracks + new.size] = g_p[new]
        n_tracks += new.size
    track_of_group = np.empty(order.size, dtype=np.int64)
    track_of_group[order] = track
    return track_of_group[groups]


def two_objects(xyz: np.ndarray, t: np.ndarray, distance: float, params: ParamSet) -> bool:
    """Whether one cluster's returns are two objects: in at least :data:`APART_SAMPLES`
    frame samples, return groups of its kinematic tracks of at least
    :data:`APART_TRACK_POINTS` returns lie more than ``distance`` metres apart (the
    diagonal of the box around the sample's group centroids).

    A bird crossing a drone's path a few metres away can join the drone's cluster without
    widening it or making it irregular: the two share few sweeps, and then the returns of
    one object each. A drone's own track cut by its gaps gives pieces that follow one
    another, not pieces seen apart in one sweep.
    """
    tracks = kinematic_tracks(xyz, t, params)
    big = np.bincount(tracks)[tracks] >= APART_TRACK_POINTS
    if np.unique(tracks[big]).size < 2:
        return False
    groups, group_sample = return_groups(xyz[big], t[big], params.frame_period, params.split_blob)
    n_groups = int(groups.max()) + 1
    size = np.bincount(groups, minlength=n_groups).astype(np.float64)
    centre = (
        np.stack(
            [np.bincount(groups, weights=xyz[big][:, a], minlength=n_groups) for a in range(3)], 1
        )
        / size[:, None]
    )
    ((lo, hi),) = group_bounds(group_sample, int(group_sample.max()) + 1, centre)
    return int(np.count_nonzero(np.linalg.norm(hi - lo, axis=1) > distance)) >= APART_SAMPLES


def crossed_clusters(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    params: ParamSet,
    distance: float,
    skip: np.ndarray,
) -> np.ndarray:
    """Indices of the confident clusters (flying as in :func:`merged_clusters`, at least
    ``min_confidence``, not in ``skip``) that are :func:`two_objects` at ``distance``."""
    confident = _flying(scores, params) & (scores.confidence >= params.min_confidence)
    crossed = []
    for c in np.setdiff1d(np.flatnonzero(confident), skip):
        member = labels == c
        if two_objects(xyz[member], t[member], distance, params):
            crossed.append(c)
    return np.asarray(crossed, dtype=np.int64)


def merged_clusters(
    scores: ClusterScores,
    params: ParamSet,
    min_extent: float | None = None,
    excess_residual: float = 0.0,
    excess_min_points: int = 0,
    high: np.ndarray | None = None,
) -> np.ndarray:
    """Indices of the clusters to split: flying (:func:`_flying`; ``high``: each
    cluster's returns at least ``min_centroid_z`` high), with at least twice
    ``min_cluster_points`` and at most ``max_cluster_points`` points, and either wider
    than ``max_local_extent`` in their local windows (no drone as a whole) or wider
    than ``min_extent`` (default ``split_min_extent``; streaming passes
    ``stream_split_min_extent``) and below ``min_confidence`` (birds 2-3 m from the
    drone make a cluster narrow enough to pass the extent gate, which then fails on its
    smoothness), or, with ``excess_residual`` > 0, below ``min_confidence`` with a
    larger excess residual, however narrow (a bird's returns joined to a drone's track,
    offline's ``split_excess_residual``, deviation 74; streaming's
    ``stream_split_excess_residual`` only for clusters of at least
    ``excess_min_points`` points, deviation 92)."""
    if min_extent is None:
        min_extent = params.split_min_extent
    wide = scores.local_extent > params.max_local_extent
    wide |= (scores.local_extent > min_extent) & (scores.confidence < params.min_confidence)
    if excess_residual > 0:
        wide |= (
            (scores.excess_residual > excess_residual)
            & (scores.confidence < params.min_confidence)
            & (scores.n_points >= excess_min_points)
        )
    return np.nonzero(wide & _flying(scores, params, high))[0]


def _flying(scores: ClusterScores, params: ParamSet, high: np.ndarray | None = None) -> np.ndarray:
    """(K,) bool: clusters that may be split: centroid at least ``min_centroid_z`` high
    or, with ``split_low_flying`` and ``high`` (each cluster's returns at least that
    high), at least twice ``min_cluster_points`` such returns (deviation 118); at least
    twice ``min_cluster_points`` and at most ``max_cluster_points`` points."""
    flying = scores.centroid[:, 2] >= params.min_centroid_z
    if high is not None and params.split_low_flying:
        flying |= high[: flying.size] >= 2 * params.min_cluster_points
    return (
        flying
        & (scores.n_points >= 2 * params.min_cluster_points)
        & (scores.n_points <= params.max_cluster_points)
    )


def _high_points(labels: np.ndarray, xyz: np.ndarray, k: int, params: ParamSet) -> np.ndarray:
    """(K,) each cluster's returns at least ``min_centroid_z`` high."""
    high = (labels >= 0) & (xyz[:, 2] >= params.min_centroid_z)
    return np.bincount(labels[high], minlength=k)


def split_merged(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    params: ParamSet,
    structure_keys: np.ndarray | None = None,
    min_extent: float | None = None,
    excess_residual: float = 0.0,
    excess_min_points: int = 0,
    cascade: bool = False,
    also: np.ndarray | None = None,
    among: np.ndarray | None = None,
    apart: float = 0.0,
    tracked: np.ndarray | None = None,
) -> tuple[np.ndarray, int, np.ndarray]:
    """Labels with each of :func:`merged_clusters` (``min_extent``, ``excess_residual``
    and ``excess_min_points`` passed on), and each cluster in ``also``, replaced by its
    kinematic tracks (``cascade``: :func:`kinematic_tracks`'s); with ``among``, only
    the clusters in it are split.

    With ``structure_keys`` (sorted ``static_voxel`` keys of suppressed structure), a
    cluster with more than ``MAX_CONTACT`` of its points in or next to those voxels is
    left whole unless its motion coherence is at least ``MOVING_COHERENCE``, or, with
    ``apart`` > 0, it has at least ``GROUND_SHARE`` of its returns below
    ``min_centroid_z``, a coherence of at least ``APART_COHERENCE`` and is
    :func:`two_objects` at that distance: what static suppression left of a wall or a
    tree, not objects in the air. The clusters in ``tracked`` (the one holding the
    reported track, deviation 149) are tested without the share near the ground.
    Returns (compact labels, K, (N,) bool mask of the points that were in a split
    cluster).
    """
    labels = np.asarray(labels, dtype=np.int64)
    k = int(labels.max()) + 1 if labels.size else 0
    high = _high_points(labels, xyz, k, params)
    split = merged_clusters(scores, params, min_extent, excess_residual, excess_min_points, high)
    if also is not None and len(also):
        split = np.union1d(split, np.asarray(also, dtype=split.dtype))
    if among is not None:
        split = np.intersect1d(split, np.asarray(among, dtype=split.dtype))
    if split.size and structure_keys is not None and structure_keys.size:
        which = np.zeros(k, dtype=bool)
        which[split] = True
        member = labels >= 0
        contact = structure_contact(
            labels[member], xyz[member], k, which, structure_keys, float(params.static_voxel)
        )
        moving = scores.coherence[split] >= MOVING_COHERENCE
        free = (contact[split] <= MAX_CONTACT) | moving
        test = ~free & (scores.coherence[split] >= APART_COHERENCE)
        if apart > 0 and test.any():
            # Deviation 148: a drone that passed a walking person beside a tree joined the
            # person's cluster; the remnants of walls and crowns are one object each.
            counts = np.bincount(labels[member], minlength=k)
            low = np.bincount(labels[member & (xyz[:, 2] < params.min_centroid_z)], minlength=k)
            grounded = low[split] >= GROUND_SHARE * np.maximum(counts[split], 1)
            if tracked is not None and len(tracked):
                # Deviation 149: the cluster holding the reported track's recent returns.
                grounded |= np.isin(split, tracked)
            test &= grounded
            for i in np.flatnonzero(test):
                one = labels == split[i]
                free[i] = two_objects(xyz[one], t[one], apart, params)
        split = split[free]
    if split.size == 0:
        return labels, k, np.zeros(labels.size, dtype=bool)
    out = labels.copy()
    next_label = k
    for c in split:
        member = np.nonzero(labels == c)[0]
        tracks = kinematic_tracks(xyz[member], t[member], params, cascade)
        out[member] = tracks + next_label
        next_label += int(tracks.max()) + 1
    labels_out, k_out = relabel_compact(out)
    return labels_out, k_out, np.isin(labels, split)


#: ``score(labels, xyz, t, params, n_clusters=K)``: scores of clusters 0..K-1.
Scorer = Callable[..., ClusterScores]


def split_and_score(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    params: ParamSet,
    score: Scorer,
    structure_keys: np.ndarray | None = None,
    min_extent: float | None = None,
    excess_residual: float = 0.0,
    excess_min_points: int = 0,
    two_trackers: bool = False,
    apart: float = 0.0,
    among: np.ndarray | None = None,
    contact_apart: bool = False,
    tracked: np.ndarray | None = None,
) -> tuple[np.ndarray, int, ClusterScores, np.ndarray]:
    """:func:`split_merged`, then the scores of the new labels; with ``apart`` > 0,
    the confident clusters of :func:`crossed_clusters` are split too, and with
    ``contact_apart`` so are those left whole for their contact with structure that hold
    an object on the ground and are :func:`two_objects` at ``apart`` (:func:`split_merged`;
    for the clusters in ``tracked``, whatever lies near the ground); with ``among``,
    only clusters in it are split.

    Scores are per cluster, so only the pieces are scored (``score`` must use a fixed
    window origin, ``t0``); the clusters left whole keep theirs. With ``two_trackers``
    each cluster is split twice, with and without the matching cascade of
    :func:`kinematic_tracks`, and keeps the split whose best reportable piece ranks
    higher (:func:`_reportable_rank`). Returns (labels, K, scores, mask of the points
    that were in a split cluster).
    """
    args = (
        labels,
        xyz,
        t,
        scores,
        params,
        structure_keys,
        min_extent,
        excess_residual,
        excess_min_points,
    )
    also = None
    if apart > 0:
        k = int(labels.max()) + 1 if labels.size else 0
        high = _high_points(np.asarray(labels, dtype=np.int64), xyz, k, params)
        merged = merged_clusters(
            scores, params, min_extent, excess_residual, excess_min_points, high
        )
        also = crossed_clusters(labels, xyz, t, scores, params, apart, merged)
    near = apart if contact_apart else 0.0
    out, k, was_split = split_merged(*args, also=also, among=among, apart=near, tracked=tracked)
    pieces = score_pieces(labels, out, k, was_split, xyz, t, scores, params, score)
    if not two_trackers or not was_split.any():
        return out, k, pieces, was_split
    alt, k_alt, _ = split_merged(
        *args, cascade=True, also=also, among=among, apart=near, tracked=tracked
    )
    alt_pieces = score_pieces(labels, alt, k_alt, was_split, xyz, t, scores, params, score)
    rank, alt_rank = _reportable_rank(pieces, params), _reportable_rank(alt_pieces, params)
    better = []
    for c in np.unique(labels[was_split]):
        member = labels == c
        if _best_of(alt_rank, alt[member]) > _best_of(rank, out[member]):
            better.append(c)
    if not better:
        return out, k, pieces, was_split
    take = np.isin(labels, better)
    mixed, k_mixed = relabel_compact(np.where(take, alt + k, out))
    # Pieces are scored alone, so the mixed split's scores are rows of the two already
    # made: compacting keeps the order by value, the labels of ``out`` before ``alt``'s.
    from_out = np.unique(out[~take & (out >= 0)])
    from_alt = np.unique(alt[take])
    mixed_scores = select_and_append(pieces, from_out, select_and_append(alt_pieces, from_alt))
    return mixed, k_mixed, mixed_scores, was_split


def _reportable_rank(scores: ClusterScores, params: ParamSet) -> np.ndarray:
    """(K,) the selection rank (:meth:`ClusterScores.rank_score`) of each cluster that
    would be reported (a candidate at ``min_confidence`` or more), 0 for the others."""
    ok = scores.candidate & (scores.confidence >= params.min_confidence)
    return np.where(ok, scores.rank_score(params.scoring), 0.0)


def _best_of(rank: np.ndarray, piece_labels: np.ndarray) -> float:
    """The highest ``rank`` among these pieces (labels < 0 ignored); 0 without one."""
    pieces = piece_labels[piece_labels >= 0]
    return float(rank[pieces].max()) if pieces.size else 0.0


def score_pieces(
    labels: np.ndarray,
    out: np.ndarray,
    k: int,
    was_split: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    params: ParamSet,
    score: Scorer,
) -> ClusterScores:
    """Scores of ``out`` (K compact labels): the clusters of ``labels`` left whole keep
    theirs (they come first, in order), the pieces of the split ones (``was_split``
    points) are scored alone."""
    if not was_split.any():
        return scores
    # relabel_compact keeps the order: the clusters left whole come first, then pieces.
    kept = np.setdiff1d(np.arange(len(scores)), np.unique(labels[was_split]))
    pieces = score(
        out[was_split] - kept.size,
        xyz[was_split],
        t[was_split],
        params,
        n_clusters=k - kept.size,
    )
    return select_and_append(scores, kept, pieces)


def still_run(t: np.ndarray, xyz: np.ndarray, params: ParamSet) -> tuple[float, float] | None:
    """(first, last) stamp of the longest stretch of at least ``hover_min_seconds`` over
    which one object's returns stayed in a box of ``hover_max_extent`` (half-second
    centroids, no gap longer than ``link_max_gap``), or None."""
    b = np.floor((t - t.min()) / STILL_STEP).astype(np.int64)
    ub, inv = voxel.unique_ints(b, return_inverse=True)
    inv = inv.reshape(-1)
    n = np.bincount(inv).astype(np.float64)
    cen = np.stack([np.bincount(inv, xyz[:, a]) / n for a in range(3)], axis=1)
    ((lo_t, hi_t),) = group_bounds(inv, ub.size, t)
    best, best_len = None, float(params.hover_min_seconds)
    for i in range(ub.size):
        box = np.maximum.accumulate(cen[i:], axis=0) - np.minimum.accumulate(cen[i:], axis=0)
        ok = (box.max(axis=1) <= params.hover_max_extent) & np.r_[
            True, np.diff(ub[i:]) * STILL_STEP <= params.link_max_gap
        ]
        j = i + (int(np.argmin(ok)) if not ok.all() else ok.size) - 1
        length = hi_t[j] - lo_t[i]
        if length >= best_len:
            best, best_len = (float(lo_t[i]), float(hi_t[j])), length
    return best


def split_still(
    labels: np.ndarray, xyz: np.ndarray, t: np.ndarray, scores: ClusterScores, params: ParamSet
) -> tuple[np.ndarray, int, np.ndarray]:
    """Labels with each flying candidate below ``min_confidence`` that is wider than
    ``hover_max_extent`` yet stayed in place for ``hover_min_seconds`` (:func:`still_run`)
    cut in time into the part before, the stay, and the part after.

    A drone that hovers, then flies off is one cluster: the stay lowers its relative
    density and raises its IoU, the flight makes it too wide to count as hovering, and
    the whole scores below both. Returns (compact labels, K, mask of the points that
    were in a cut cluster), as :func:`split_merged`.
    """
    labels = np.asarray(labels, dtype=np.int64)
    k = int(labels.max()) + 1 if labels.size else 0
    which = _cuttable_in_time(scores, params, 2 * params.hover_min_seconds)
    out = labels.copy()
    next_label = k
    cut = []
    for c in which:
        member = np.flatnonzero(labels == c)
        run = still_run(t[member], xyz[member].astype(np.float64), params)
        if run is None:
            continue
        part = np.searchsorted(np.asarray(run), t[member], side="right")  # 0, 1 or 2
        part[t[member] == run[1]] = 1  # the stay includes both its ends
        if np.unique(part).size < 2:
            continue
        out[member] = next_label + part
        next_label += 3
        cut.append(c)
    return _cut_labels(labels, out, k, cut)


def split_long(
    labels: np.ndarray, xyz: np.ndarray, t: np.ndarray, scores: ClusterScores, params: ParamSet
) -> tuple[np.ndarray, int, np.ndarray]:
    """Labels with each flying candidate below ``min_confidence`` that lasted at least
    twice ``split_long`` seconds cut in time into equal pieces of about ``split_long``
    seconds. Returns (compact labels, K, mask of the points that were in a cut cluster),
    as :func:`split_merged`."""
    labels = np.asarray(labels, dtype=np.int64)
    k = int(labels.max()) + 1 if labels.size else 0
    piece = float(params.split_long)
    if piece <= 0 or not labels.size:
        return labels, k, np.zeros(labels.size, dtype=bool)
    duration = scores.t_last - scores.t_first
    which = _cuttable_in_time(scores, params, 2 * piece)
    out = labels.copy()
    next_label = k
    cut = []
    for c in which:
        member = np.flatnonzero(labels == c)
        tm = t[member]
        n = int(duration[c] // piece)
        part = np.minimum(((tm - tm.min()) / (duration[c] / n)).astype(np.int64), n - 1)
        out[member] = next_label + part
        next_label += n
        cut.append(c)
    return _cut_labels(labels, out, k, cut)


def _cuttable_in_time(scores: ClusterScores, params: ParamSet, duration: float) -> np.ndarray:
    """Ids of the clusters :func:`split_still` and :func:`split_long` may cut in time:
    candidates below ``min_confidence``, wider than ``hover_max_extent``, at or above
    ``min_centroid_z``, that lasted at least ``duration`` s."""
    return np.flatnonzero(
        scores.candidate
        & (scores.confidence < params.min_confidence)
        & (scores.extent > params.hover_max_extent)
        & (scores.t_last - scores.t_first >= duration)
        & (scores.centroid[:, 2] >= params.min_centroid_z)
    )


def _cut_labels(
    labels: np.ndarray, out: np.ndarray, k: int, cut: list[int]
) -> tuple[np.ndarray, int, np.ndarray]:
    """(compact labels, K, mask of the points of the ``cut`` clusters) after cutting
    ``labels`` (K = ``k``) into ``out``; ``labels`` unchanged if nothing was cut."""
    if not cut:
        return labels, k, np.zeros(labels.size, dtype=bool)
    labels_out, k_out = relabel_compact(out)
    return labels_out, k_out, np.isin(labels, cut)
