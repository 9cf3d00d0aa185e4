"""Offline detection: the paper's whole-sequence method (sections 3.1-3.4).

1. Filter every frame (:func:`~clusterfilter_ros.core.preprocess.frame_points`) and
   superimpose all of them into the global cloud.
2. Denoise the points of ``denoise_sensors`` by density over the whole sequence, and
   (``static_suppression``) drop points in persistently occupied voxels, except the
   groups a hovering or slowly drifting drone leaves.
3. Cluster the global cloud (voxel connected components, or DBSCAN) and link the
   fragments of one sparse moving object into one cluster (:mod:`~.linking`).
4. Score every cluster from its local windows; split a flying cluster too wide to be one
   object into kinematic tracks (:mod:`~.splitting`), and one that hovered, then flew,
   into the stay and the flight, and score those; gate; select the drone cluster(s),
   overlap in time judged on their trajectories' spans (:func:`tracked_spans`), a
   qualifying one that overlaps a selected one trimmed to the rest
   (:func:`select_trimmed`), and only pieces one flight could join
   (:func:`reachable_pieces`); grow each selected track at its ends by the noise
   points and small clusters it was heading for, and fill it inside with those on its
   path; the growth may also take returns the filters removed: the denoise
   (``extend_denoised``) and the Mid360 floor (``extend_below_floor``), see
   :func:`growth_only_points`.
5. Fit the trajectory through the selected points and evaluate it at the frame stamps
   (or given timestamps) inside the supported span.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from clusterfilter_ros.core import voxel
from clusterfilter_ros.core.background import persistent_mask, static_offline
from clusterfilter_ros.core.clustering import (
    absorb_colocated_noise,
    dbscan_points,
    density_mask,
    merge_colocated_compact,
    relabel_compact,
    spacetime_cluster_points,
    voxel_cluster_points,
)
from clusterfilter_ros.core.estimate import reported_positions
from clusterfilter_ros.core.frame import Frame, TimedPositions
from clusterfilter_ros.core.linking import (
    chains_formed,
    end_state,
    extend_track,
    fill_track,
    frame_sample_ids,
    frame_samples,
    link_fragments,
    linking_reach,
    stay_scatter,
)
from clusterfilter_ros.core.params import ParamSet, detector_params
from clusterfilter_ros.core.preprocess import points_at, usable_and_below_floor
from clusterfilter_ros.core.scoring import ClusterScores, score_clusters, select_clusters
from clusterfilter_ros.core.splitting import (
    Scorer,
    kinematic_tracks,
    score_pieces,
    split_and_score,
    split_long,
    split_still,
)
from clusterfilter_ros.core.trajectory import (
    Trajectory,
    fit_trajectory,
    merge_trajectories,
    weighted_line,
)


@dataclass
class OfflineResult:
    """What :func:`detect_offline` found.

    Attributes:
        estimates: positions (target_offset applied) with extra columns ``confidence``
            and ``points`` (drone points within ``track_window``), only where a drone
            is believed present.
        drone_points: (M, 4) float64 rows ``t, x, y, z`` of the selected clusters' points.
        trajectory: the fitted :class:`~clusterfilter_ros.core.trajectory.Trajectory`
            (without target_offset), or None when no drone was found.
        clusters: one dict per global cluster (features, scores, gates, ``selected``).
        scores: the raw :class:`~clusterfilter_ros.core.scoring.ClusterScores`.
        selected: indices of the selected clusters, best first.
    """

    estimates: TimedPositions
    drone_points: np.ndarray
    trajectory: Trajectory | None
    clusters: list[dict[str, float]] = field(default_factory=list)
    scores: ClusterScores | None = None
    selected: list[int] = field(default_factory=list)


class GlobalCloud(NamedTuple):
    """The superimposed, filtered frames of a sequence (:func:`global_cloud`)."""

    xyz: np.ndarray  # (N, 3) float32
    t: np.ndarray  # (N,) float64 per-point time
    noisy: np.ndarray  # (N,) bool: from a sensor in denoise_sensors
    stamps: np.ndarray  # sorted unique finite frame stamps
    floor_xyz: np.ndarray  # (F, 3) float32: Mid360 returns at or below mid360_min_z
    floor_t: np.ndarray  # (F,) float64


def _grows_below_floor(params: ParamSet) -> bool:
    return bool(params.extend_below_floor) and _grows(params)


def _grows(params: ParamSet) -> bool:
    return params.link_max_gap > 0 and params.extend_max_gap > 0


def global_cloud(frames: Iterable[Frame], params: ParamSet) -> GlobalCloud:
    """Superimpose filtered frames. The Mid360 returns dropped for lying at or below
    ``mid360_min_z`` are kept apart (``floor_*``) when ``extend_below_floor`` can use
    them, else those arrays are empty."""
    xyzs, ts, flags, stamps, floor_xyzs, floor_ts = [], [], [], [], [], []
    denoise = set(params.denoise_sensors)
    keep_floor = _grows_below_floor(params)
    for frame in frames:
        stamps.append(frame.stamp)
        usable, floor = usable_and_below_floor(frame, params)
        xyz, t = points_at(frame, usable)
        if keep_floor and floor.any():
            fxyz, ft = points_at(frame, floor)
            floor_xyzs.append(fxyz)
            floor_ts.append(ft)
        xyzs.append(xyz)
        ts.append(t)
        flags.append(np.full(t.size, frame.sensor in denoise))
    stamp_arr = np.asarray(stamps, dtype=np.float64)
    return GlobalCloud(
        _stack(xyzs, np.empty((0, 3), np.float32)),
        _stack(ts, np.empty(0)),
        _stack(flags, np.empty(0, bool)),
        np.unique(stamp_arr[np.isfinite(stamp_arr)]),
        _stack(floor_xyzs, np.empty((0, 3), np.float32)),
        _stack(floor_ts, np.empty(0)),
    )


def _stack(parts: list[np.ndarray], empty: np.ndarray) -> np.ndarray:
    return np.concatenate(parts) if parts else empty


def cluster_labels(xyz: np.ndarray, t: np.ndarray, params: ParamSet) -> np.ndarray:
    """Global cluster label per point (-1 noise) with the configured clusterer."""
    if params.clustering == "dbscan":
        return dbscan_points(xyz, params.eps, params.min_samples)
    if params.cluster_time > 0:
        return spacetime_cluster_points(
            xyz, t, params.cluster_voxel, params.cluster_time, params.min_samples
        )
    return voxel_cluster_points(xyz, params.cluster_voxel, params.min_samples)


def global_clusters(
    xyz: np.ndarray, t: np.ndarray, params: ParamSet, passes: int | None = None
) -> tuple[np.ndarray, int]:
    """Compact cluster labels (0..K-1, -1 noise) and K: clustering, the merge of a hovering
    drone's co-located pieces (``hover_detection``), then track linking (``link_max_gap``)
    in up to ``passes`` rounds (default ``link_passes``), until a round links nothing."""
    labels, k = relabel_compact(cluster_labels(xyz, t, params))
    if params.hover_detection:
        labels, k = merge_colocated_compact(labels, xyz, params.hover_max_extent)
    if params.link_max_gap > 0:
        active = None  # the first round considers every pair, later ones new chains only
        for _ in range(int(params.link_passes if passes is None else passes)):
            before, k_before = labels, k
            labels, k = link_fragments(labels, xyz, t, params, active)
            if k == k_before:
                break
            active = chains_formed(before, labels, k)
    return labels, k


def cluster_trajectory(
    t: np.ndarray, xyz: np.ndarray, confidence: float, params: ParamSet
) -> Trajectory | None:
    """The trajectory of one cluster's returns (see :func:`~.trajectory.fit_trajectory`)."""
    return fit_trajectory(
        t,
        xyz,
        max_gap=params.max_gap,
        max_extrapolation=params.max_extrapolation,
        bin_seconds=params.frame_period / 2,
        confidence=np.full(t.size, confidence),
        context_gap=max(float(params.link_max_gap), float(params.extend_far_gap)),
        context_window=float(params.link_fit_window),
        stray_distance=float(params.stray_distance),
        stray_speed=float(params.link_max_speed),
        stray_accel=float(params.link_max_accel),
        stray_window=float(params.link_fit_window),
        stray_span=2.0 * float(params.frame_period),
        stray_chord_span=float(params.link_max_gap) if params.stray_chord else 0.0,
        stray_chord_lone=2.0 * float(params.frame_period),
    )


def tracked_spans(
    labels: np.ndarray, xyz: np.ndarray, t: np.ndarray, scores: ClusterScores, params: ParamSet
) -> ClusterScores:
    """``scores`` with the time span of each qualifying candidate (gates passed,
    ``min_confidence``) replaced by that of its trajectory, which leaves out the returns
    no object on the track could have made (``stray_distance``; deviations 42, 44). A
    drone's track that picked up a few returns of something else after the drone left
    it seemed to last seconds longer, and the next piece of the drone's track, which had
    started meanwhile, overlapped it and was never selected. These spans decide only
    which pieces overlap, in :func:`~.scoring.select_clusters` and
    :func:`select_trimmed`."""
    qualifies = np.flatnonzero(scores.candidate & (scores.confidence >= params.min_confidence))
    if qualifies.size == 0 or params.scoring == "paper":
        return scores
    first, last = scores.t_first.copy(), scores.t_last.copy()
    # Only spans that overlap another qualifying one matter.
    lo, hi = first[qualifies], last[qualifies]
    overlaps = (lo[:, None] <= hi[None, :]) & (lo[None, :] <= hi[:, None])
    for c in qualifies[overlaps.sum(axis=1) > 1]:
        member = labels == c
        traj = cluster_trajectory(t[member], xyz[member], float(scores.confidence[c]), params)
        if traj is not None and traj.segments:
            first[c], last[c] = traj.span
    return dataclasses.replace(scores, t_first=first, t_last=last)


def select_trimmed(
    labels: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    selected: list[int],
    params: ParamSet,
    was_split: np.ndarray | None = None,
    xyz: np.ndarray | None = None,
) -> tuple[np.ndarray, list[int], np.ndarray]:
    """Selected clusters plus the qualifying candidates that :func:`select_clusters` left
    out for overlapping a selected one in time, each trimmed to its points outside the
    time spans already taken, if those still hold ``min_cluster_points`` points over at
    least ``min_track_seconds`` (the confirmation a whole track needs), or over
    ``split_rest_seconds`` for a piece of a split cluster (``was_split`` marks their
    points), which qualified as a whole. A cluster takes the time where it has returns
    (within its span in ``scores``), not the gaps of more than ``link_max_gap`` between
    them: a hovering drone's cluster joins co-located pieces seconds apart, and the
    piece of the drone split from a bird that passed it in such a gap fills the gap
    (deviation 64).

    Where a bird flies past the drone, the kinematic split (deviation 34) can end one
    drone track and start the next in the middle of the other: the later, better track
    is selected and the earlier one, seconds of drone before the swap, was dropped; or
    the earlier one is selected, goes on along the bird, and the drone's next piece is
    left with a rest of 2-4 s (deviation 79).
    With ``xyz`` (the points' positions), a candidate seen at the same moments as a
    cluster of ``selected`` and never within :data:`APART_OBJECTS` of it
    (:func:`_elsewhere`) is another object flying at the same time, and is not added
    (deviation 121): a bird's leg 40 m from the drone's pass, which began before it.
    With ``apart_segments`` that is judged per segment of the candidate, and only what
    is elsewhere is left out, trimmed (:func:`_apart_from`, deviation 141).
    With ``end_overlap_support`` a candidate that outnumbers the end of a selected track
    in its own time takes that time (:func:`_outnumbered_end`, deviation 145).
    Returns (labels with the trimmed points set to -1, selected clusters best first,
    mask of the trimmed points).
    """
    labels = np.asarray(labels, dtype=np.int64)
    trimmed = np.zeros(labels.size, dtype=bool)
    if not selected or params.scoring == "paper":
        return labels, list(selected), trimmed
    qualifies = scores.candidate & (scores.confidence >= params.min_confidence)
    rank = scores.rank_score(params.scoring)
    labels = labels.copy()
    chosen = list(selected)
    gap = float(params.link_max_gap)

    # The points of the tracks selected whole. Candidates are judged against these (the
    # rests added here rank lower); the loop below relabels only candidates' points, so
    # these stay as they are (but for the ends that end_overlap_support hands over).
    whole = [np.flatnonzero(labels == j) for j in selected]

    def whole_spans(c: int, points: np.ndarray) -> list[tuple[float, float]]:
        tc = t[points]
        return occupied_spans(tc[(tc >= scores.t_first[c]) & (tc <= scores.t_last[c])], gap)

    spans_of = {c: whole_spans(c, points) for c, points in zip(selected, whole, strict=True)}
    order = np.argsort(-rank, kind="stable")
    for c in order[qualifies[order]]:
        c = int(c)
        if c in chosen:
            continue
        member = np.nonzero(labels == c)[0]
        apart = _apart_from(member, whole, xyz, t, params)
        if apart.all():
            continue
        elsewhere, member = member[apart], member[~apart]
        # Deviation 145: what is left of the selected tracks whose ends this candidate
        # outnumbers, handed over only if the candidate is then taken.
        kept = {}
        if params.end_overlap_support and member.size:
            for j, s in enumerate(selected):
                end = _outnumbered_end(whole[j], t, scores, s, c, member)
                if end is not None:
                    kept[j] = whole[j][~end]
        spans_now = dict(spans_of)
        for j, points in kept.items():
            spans_now[selected[j]] = whole_spans(selected[j], points)
        covered = np.zeros(member.size, dtype=bool)
        for first, last in (span for spans in spans_now.values() for span in spans):
            covered |= (t[member] >= first) & (t[member] <= last)
        rest = member[~covered]
        need = params.min_track_seconds
        if was_split is not None and was_split[member].all():
            need = min(need, params.split_rest_seconds)  # deviation 79
        if rest.size < params.min_cluster_points or np.ptp(t[rest]) < need:
            continue
        for j, points in kept.items():
            end = np.setdiff1d(whole[j], points, assume_unique=True)
            labels[end] = -1
            trimmed[end] = True
            whole[j] = points
        spans_of = spans_now
        labels[member[covered]] = -1
        trimmed[member[covered]] = True
        labels[elsewhere] = -1
        trimmed[elsewhere] = True
        chosen.append(c)
        spans_of[c] = occupied_spans(t[rest], gap)
    return labels, chosen, trimmed


#: A candidate takes over the end of a selected track it overlaps (``end_overlap_support``)
#: when it holds at least this many times the track's returns in that time.
OUTNUMBER = 3.0


def _outnumbered_end(
    own: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    track: int,
    candidate: int,
    member: np.ndarray,
) -> np.ndarray | None:
    """``end_overlap_support`` (deviation 145): mask over ``own`` (the points of the
    selected ``track``) of its returns within the time span of ``candidate`` (its
    points ``member``), when they are one end
    of the track (none of its returns after the candidate's last, or none before its
    first, but not both), the candidate is at least as confident and holds at least
    :data:`OUTNUMBER` times as many returns in that span: one drone at a time, and the
    track's end there is something else the clusterer joined to it (a bird that flew on
    beside the drone as the drone's own returns formed the candidate). None otherwise."""
    tt = t[member]
    lo, hi = float(tt.min()), float(tt.max())
    if own.size == 0 or scores.confidence[candidate] < scores.confidence[track]:
        return None
    ts = t[own]
    inside = (ts >= lo) & (ts <= hi)
    n_in = int(np.count_nonzero(inside))
    tail, head = not (ts > hi).any(), not (ts < lo).any()
    if n_in == 0 or tail == head or member.size < OUTNUMBER * n_in:
        return None
    return inside


#: Two tracks seen at the same moments, never closer than this (m), are two objects
#: (deviation 121; birds circling the drone come within a few metres of it).
APART_OBJECTS = 10.0
#: Moments (frame samples of one track with one of the other within two frame periods)
#: that make two tracks simultaneous for :func:`_elsewhere`.
APART_MIN_MOMENTS = 3


def without_end_objects(
    labels: np.ndarray, xyz: np.ndarray, t: np.ndarray, tracks: list[int], params: ParamSet
) -> np.ndarray:
    """``end_objects`` (deviation 142): labels with another object's returns at a selected
    track's ends set to noise. Each of ``tracks`` is split into kinematic tracks (as a
    merged cluster is); one with fewer than ``min_cluster_points`` returns lying wholly
    after the largest one's last return (or wholly before its first), whose first (last)
    return lies beyond the linking reach (:func:`~.linking.linking_reach`) of where that
    end was heading (:func:`~.linking.end_state`), is another object the clusterer
    joined to the track where the two met: a bird passing the drone as it left. As
    noise, growth takes back only what lies where the track was heading."""
    out = labels
    for c in tracks:
        member = np.flatnonzero(labels == c)
        if member.size < 2:
            continue
        tm, pm = t[member], xyz[member].astype(np.float64)
        which = kinematic_tracks(pm, tm, params)
        counts = np.bincount(which)
        main = which == int(np.argmax(counts))
        for forward in (True, False):
            edge, position, velocity = end_state(tm[main], pm[main], params, forward)
            for k in np.flatnonzero(counts < params.min_cluster_points):
                mine = which == k
                beyond = tm[mine] > edge if forward else tm[mine] < edge
                if not beyond.all():
                    continue
                i = int(np.argmin(tm[mine]) if forward else np.argmax(tm[mine]))
                dt = float(tm[mine][i]) - edge
                heading = position if velocity is None else position + velocity * dt
                far = np.linalg.norm(pm[mine][i] - heading) > linking_reach(dt, params)
                if far:
                    if out is labels:
                        out = labels.copy()
                    out[member[mine]] = -1
    return out


def _apart_from(
    member: np.ndarray,
    tracks: list[np.ndarray],
    xyz: np.ndarray | None,
    t: np.ndarray,
    params: ParamSet,
) -> np.ndarray:
    """Mask of the candidate's points ``member`` that are another object flying at the
    same time as one of ``tracks`` (:func:`_elsewhere`; none without ``xyz``). With
    ``apart_segments`` each segment of the candidate (its returns cut where they are
    more than ``max_gap`` apart, as the trajectory cuts them) is judged alone, else the
    whole candidate: a bird's returns 2 s before the drone's began the cluster of the
    drone's second half (deviation 141). When some segments are apart and some not, the
    rest is split into kinematic tracks and those with fewer than ``min_cluster_points``
    returns are apart too: the same bird's last returns, in the drone's segment."""
    apart = np.zeros(member.size, dtype=bool)
    if xyz is None or not tracks or member.size == 0:
        return apart
    pieces = [np.arange(member.size)]
    if params.apart_segments:
        pieces = gap_runs(t[member], params.max_gap)
    for piece in pieces:
        if any(_elsewhere(member[piece], track, xyz, t, params) for track in tracks):
            apart[piece] = True
    if apart.any() and not apart.all():
        # The candidate held another object: the rest is split into kinematic tracks, as
        # a merged cluster is, and those too small to be a candidate are left out too
        # (the bird's last returns before the drone's, in the segment the drone's began).
        rest = np.flatnonzero(~apart)
        tracks_of = kinematic_tracks(xyz[member[rest]], t[member[rest]], params)
        small = np.bincount(tracks_of)[tracks_of] < params.min_cluster_points
        apart[rest[small]] = True
    return apart


def _elsewhere(
    first: np.ndarray, second: np.ndarray, xyz: np.ndarray, t: np.ndarray, params: ParamSet
) -> bool:
    """Whether the points ``first`` and ``second`` (indices into ``xyz``, ``t``) are two
    objects seen at the same time: at least :data:`APART_MIN_MOMENTS` of the frame
    samples of ``first`` have one of ``second`` within two frame periods, and every such
    pair lies more than :data:`APART_OBJECTS` apart."""
    if first.size == 0 or second.size == 0:
        return False
    fp = float(params.frame_period)
    idx = np.concatenate([first, second])
    which = np.repeat([0, 1], [first.size, second.size])
    cid, ts, ps, _, _ = frame_samples(which, xyz[idx], t[idx], 2, fp)
    ta, pa = ts[cid == 0], ps[cid == 0]
    tb, pb = ts[cid == 1], ps[cid == 1]
    # The nearest sample of the second in time to each of the first's (both sorted).
    k = np.searchsorted(tb, ta)
    before, after = np.clip(k - 1, 0, tb.size - 1), np.clip(k, 0, tb.size - 1)
    near = np.where(np.abs(tb[before] - ta) <= np.abs(tb[after] - ta), before, after)
    moments = np.abs(tb[near] - ta) <= 2.0 * fp
    if np.count_nonzero(moments) < APART_MIN_MOMENTS:
        return False
    return bool(np.linalg.norm(pa[moments] - pb[near[moments]], axis=1).min() > APART_OBJECTS)


def gap_runs(t: np.ndarray, max_gap: float) -> list[np.ndarray]:
    """Indices into the stamps ``t``, in time order (stable), one array per run with no
    gap over ``max_gap`` between consecutive stamps (the segments a trajectory is cut
    into); [] for no stamps."""
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if t.size == 0:
        return []
    order = np.argsort(t, kind="stable")
    return np.split(order, np.flatnonzero(np.diff(t[order]) > max_gap) + 1)


def occupied_spans(t: np.ndarray, max_gap: float) -> list[tuple[float, float]]:
    """(first, last) stamp of each run of the stamps ``t`` with no gap over ``max_gap``."""
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    return [(float(t[run[0]]), float(t[run[-1]])) for run in gap_runs(t, max_gap)]


#: Seconds at each end of a selected cluster averaged for its end positions...
END_WINDOW = 0.25
#: ...and the fewest returns averaged there (one stray return must not be an end).
END_POINTS = 5
#: Seconds at each end of a selected cluster whose returns give its end velocities.
VELOCITY_WINDOW = 1.0


class _PieceEnds(NamedTuple):
    cluster: int
    first: float  # first and last stamps of the piece
    last: float
    t_first: float  # mean stamp and position of the returns averaged at each end
    p_first: np.ndarray
    t_last: float
    p_last: np.ndarray
    v_first: np.ndarray  # velocity over the first and last VELOCITY_WINDOW (NaN: unknown)
    v_last: np.ndarray


def _velocity(t: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """Least-squares velocity of sorted returns; NaN when they are fewer than
    :data:`END_POINTS` or span less than a third of :data:`VELOCITY_WINDOW`."""
    if t.size < END_POINTS or t[-1] - t[0] < VELOCITY_WINDOW / 3:
        return np.full(3, np.nan)
    return weighted_line(t, xyz, np.ones(t.size))[0]


def _piece_ends(cluster: int, t: np.ndarray, xyz: np.ndarray) -> _PieceEnds:
    """The piece's ends: at each, the returns within :data:`END_WINDOW` s of its first
    (last) stamp, or its :data:`END_POINTS` earliest (latest) if that is more, and the
    velocity of those within :data:`VELOCITY_WINDOW` s."""
    order = np.argsort(t, kind="stable")
    t, xyz = t[order], xyz[order]
    n_first = max(int(np.searchsorted(t, t[0] + END_WINDOW, side="right")), END_POINTS)
    n_last = max(t.size - int(np.searchsorted(t, t[-1] - END_WINDOW, side="left")), END_POINTS)
    head, tail = slice(0, n_first), slice(max(t.size - n_last, 0), t.size)
    v_head = slice(0, int(np.searchsorted(t, t[0] + VELOCITY_WINDOW, side="right")))
    v_tail = slice(int(np.searchsorted(t, t[-1] - VELOCITY_WINDOW, side="left")), t.size)
    return _PieceEnds(
        cluster,
        float(t[0]),
        float(t[-1]),
        float(t[head].mean()),
        xyz[head].mean(axis=0),
        float(t[tail].mean()),
        xyz[tail].mean(axis=0),
        _velocity(t[v_head], xyz[v_head]),
        _velocity(t[v_tail], xyz[v_tail]),
    )


def _joinable(before: _PieceEnds, after: _PieceEnds, params: ParamSet) -> bool:
    """Whether one flight can go from ``before``'s end to ``after``'s start: within
    ``link_gate`` + ``link_max_speed`` x gap, and, where both end velocities are known,
    changing velocity at no more than ``link_max_accel``. The velocities stand about half
    a :data:`VELOCITY_WINDOW` inside each piece, and lines fitted to a second of sparse
    returns are uncertain: the time allowed for the change is the gap plus two
    windows."""
    gap = max(after.t_first - before.t_last, 0.0)
    if (
        np.linalg.norm(after.p_first - before.p_last)
        > params.link_gate + params.link_max_speed * gap
    ):
        return False
    dv = float(np.linalg.norm(after.v_first - before.v_last))
    return not dv > params.link_max_accel * (gap + 2 * VELOCITY_WINDOW)  # NaN: unknown, kept


def _selected_ends(
    labels: np.ndarray, xyz: np.ndarray, t: np.ndarray, selected: list[int]
) -> list[_PieceEnds]:
    """The ends (:func:`_piece_ends`) of each of the ``selected`` clusters that has points,
    in the order given."""
    out = []
    for c in selected:
        member = labels == c
        if member.any():
            out.append(_piece_ends(c, t[member], xyz[member]))
    return out


def reachable_pieces(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    selected: list[int],
    params: ParamSet,
    exempt: frozenset[int] = frozenset(),
) -> list[int]:
    """``selected`` (best first) without the clusters that cannot be pieces of one track
    with the better ones: each cluster's first and last positions (means over
    :data:`END_WINDOW` s, at least :data:`END_POINTS` returns) must be within
    ``link_gate`` + ``link_max_speed`` x gap of the end of the nearest better piece
    before it and of the start of the nearest one after it, the gap measured between
    the mean stamps of the returns averaged, and the velocity change between them must
    be one ``link_max_accel`` allows (:func:`_joinable`). A bird leg taken while the
    drone was out of view, just before the drone's track starts 80 m higher, or one
    arriving at 11 m/s where the drone's track starts 4 m away going the other way, is
    not part of the drone's track.

    ``exempt`` clusters (the trimmed ones of :func:`select_trimmed`) are kept and do not
    serve as neighbours: they meet another piece where a bird swapped tracks with the
    drone, and the returns at that meeting are the bird's as often as the drone's."""
    kept: list[_PieceEnds] = []
    for c in selected:
        if c in exempt:
            continue
        member = labels == c
        if not member.any():
            continue
        ends = _piece_ends(c, t[member], xyz[member])
        ok = True
        before = [k for k in kept if k.last <= ends.first]
        after = [k for k in kept if k.first >= ends.last]
        if before:
            ok &= _joinable(max(before, key=lambda k: k.last), ends, params)
        if after:
            ok &= _joinable(ends, min(after, key=lambda k: k.first), params)
        if ok:
            kept.append(ends)
    taken = {k.cluster for k in kept} | set(exempt)
    return [c for c in selected if c in taken]


def continuing_pieces(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    selected: list[int],
    was_split: np.ndarray,
    params: ParamSet,
) -> list[int]:
    """Pieces of split clusters that continue a selected piece although they fall short
    of ``min_confidence`` (deviation 80): a candidate with at least ``keep_confidence``,
    made only of split points (``was_split``), overlapping no selected piece in time,
    that starts at most ``extend_max_gap`` after the end of the selected piece before it
    (or ends at most that long before the start of the one after it; the gap a track's
    growth crosses) where one flight could go on (:func:`_joinable`). Where the
    kinematic split cut the drone's track at a bird's crossing, the drone's next piece,
    seconds long and alone, is often just below ``min_confidence``; streaming keeps such
    a continuation by its hysteresis (``keep_confidence``). Only the selected pieces
    are neighbours (no chains of weak pieces); the weak ones are taken best first, each
    in time no piece holds yet. Returns the pieces to add, after the selected ones."""
    weak = (
        scores.candidate
        & (scores.confidence >= params.keep_confidence)
        & (scores.confidence < params.min_confidence)
    )
    if not selected or not weak.any():
        return []
    neighbours = _selected_ends(labels, xyz, t, selected)
    taken = list(neighbours)  # and the weak pieces added
    gap = float(params.extend_max_gap)
    added: list[int] = []
    rank = scores.rank_score(params.scoring)
    for c in np.flatnonzero(weak)[np.argsort(-rank[weak], kind="stable")]:
        member = labels == c
        if c in selected or not member.any() or not was_split[member].all():
            continue
        ends = _piece_ends(int(c), t[member], xyz[member])
        if any(ends.first <= k.last and k.first <= ends.last for k in taken):
            continue
        before = [k for k in neighbours if k.last < ends.first]
        after = [k for k in neighbours if k.first > ends.last]
        prev = max(before, key=lambda k: k.last) if before else None
        nxt = min(after, key=lambda k: k.first) if after else None
        if (
            prev is not None and ends.first - prev.last <= gap and _joinable(prev, ends, params)
        ) or (nxt is not None and nxt.first - ends.last <= gap and _joinable(ends, nxt, params)):
            taken.append(ends)
            added.append(int(c))
    return added


def _carries_on(before: _PieceEnds, after: _PieceEnds, params: ParamSet) -> bool:
    """Whether ``after`` starts where ``before`` was heading: :func:`_joinable`, and each
    known facing velocity (``before``'s forward, ``after``'s backward) carries one end to
    within the linking reach (:func:`~clusterfilter_ros.core.linking.linking_reach`) of
    the other across the gap: not only a piece one flight could reach at up to
    ``link_max_speed``, but one on the way the track was going."""
    if not _joinable(before, after, params):
        return False
    dt = after.t_first - before.t_last
    reach = float(linking_reach(np.asarray(dt), params))
    for miss in (
        after.p_first - (before.p_last + before.v_last * dt),
        before.p_last - (after.p_first - after.v_first * dt),
    ):
        if float(np.linalg.norm(miss)) > reach:  # NaN velocity: unknown, kept
            return False
    return True


def _split_pool(
    labels: np.ndarray,
    scores: ClusterScores,
    selected: list[int],
    was_split: np.ndarray,
    params: ParamSet,
) -> np.ndarray:
    """(K,) bool: the clusters :func:`bridging_pieces` and :func:`end_pieces` may chain:
    made only of split points (``was_split``), unselected, with at least
    :data:`END_POINTS` returns, flying (centroid above ``min_centroid_z``) and within
    ``max_local_extent``."""
    pool = (
        (scores.n_points >= END_POINTS)
        & (scores.centroid[:, 2] >= params.min_centroid_z)
        & (scores.local_extent <= params.max_local_extent)
    )
    pool[selected] = False
    inside = labels >= 0
    pool[np.unique(labels[inside & ~was_split])] = False
    return pool


def _moving_ends(
    labels: np.ndarray, xyz: np.ndarray, t: np.ndarray, clusters: np.ndarray
) -> list[_PieceEnds]:
    """The ends of ``clusters`` with a velocity at both ends: a piece of one or two
    frames has no velocity to show it went the track's way, and distance alone reaches
    a bird's returns 7 m off."""
    out = []
    for c in clusters:
        member = labels == c
        ends = _piece_ends(int(c), t[member], xyz[member])
        if np.isfinite(ends.v_first).all() and np.isfinite(ends.v_last).all():
            out.append(ends)
    return out


def _chains(
    origin: _PieceEnds,
    nodes: list[_PieceEnds],
    scores: ClusterScores,
    params: ParamSet,
    reach: float,
    backward: bool = False,
) -> list[tuple[_PieceEnds, int, list[int]]]:
    """Each node that a chain of pieces reaches from ``origin`` (later in time, or
    earlier with ``backward``), each step at most ``reach`` seconds long and on the way
    each end was going (:func:`_carries_on`), with the returns and pieces of the best
    such chain (most returns)."""
    order = sorted(nodes, key=lambda e: e.last if backward else e.first, reverse=backward)
    path = [origin, *order]
    best: list[tuple[int, list[int]] | None] = [(0, [])] + [None] * len(order)
    for j in range(1, len(path)):
        for i in range(j):
            found = best[i]
            if found is None:
                continue
            early, late = (path[j], path[i]) if backward else (path[i], path[j])
            if not (
                early.last < late.first <= early.last + reach and _carries_on(early, late, params)
            ):
                continue
            points = found[0] + int(scores.n_points[path[j].cluster])
            if best[j] is None or points > best[j][0]:
                best[j] = (points, found[1] + [path[j].cluster])
    return [(path[j], *best[j]) for j in range(1, len(path)) if best[j] is not None]


def bridging_pieces(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    selected: list[int],
    was_split: np.ndarray,
    params: ParamSet,
) -> list[int]:
    """bridge_split_pieces (deviation 134): the pieces of split clusters that carry one
    flight across the gap between two consecutive selected pieces. Between them (in
    time), the unselected pieces made only of split points (``was_split``), flying
    (centroid above ``min_centroid_z``), within ``max_local_extent``, with a velocity
    at both ends (at least :data:`END_POINTS` returns over a third of
    :data:`VELOCITY_WINDOW`), are chained: each step from one piece's end to the next
    one's start at most ``link_max_gap`` long and on the way each end was going
    (:func:`_carries_on`), from the earlier selected piece to the later one. Of the chains
    that reach it, the one with the most returns is taken. Where a bird's returns made
    the split cut a drone's sparse track, the pieces between two selected ones are
    often below ``min_cluster_points`` or ``min_confidence`` each; joined end to end
    to both neighbours, they are that track. Returns the pieces to add."""
    if not params.bridge_split_pieces or len(selected) < 2:
        return []
    pieces = sorted(_selected_ends(labels, xyz, t, selected), key=lambda e: e.first)
    pool = _split_pool(labels, scores, selected, was_split, params)
    reach = float(params.link_max_gap)
    added: list[int] = []
    for before, after in zip(pieces[:-1], pieces[1:], strict=True):
        between = np.flatnonzero(
            pool & (scores.t_first > before.last) & (scores.t_last < after.first)
        )
        if between.size == 0 or after.first - before.last <= 0:
            continue
        nodes = _moving_ends(labels, xyz, t, between)
        chains = [
            (points, pieces_)
            for last, points, pieces_ in _chains(before, nodes, scores, params, reach)
            if last.last < after.first <= last.last + reach and _carries_on(last, after, params)
        ]
        if chains:
            added += max(chains, key=lambda chain: chain[0])[1]
    return added


def end_pieces(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    selected: list[int],
    was_split: np.ndarray,
    params: ParamSet,
) -> list[int]:
    """bridge_end_gap (deviation 147): :func:`bridging_pieces` beyond the track's ends.
    The pieces of split clusters (the same pool) after the last selected piece that
    chain on from its end, and those before the first that chain into its start, each
    step at most ``bridge_end_gap`` s long; at each end the chain with the most returns
    is taken. A drone's returns after a half-second gap were in another cluster when the
    linker ran (a bird's beside them, or a bird's four returns seconds earlier at the
    same spot), and the split or the cut freed them too late to be linked; alone they
    are too brief or too sparse to be selected. With steps as long as ``link_max_gap``,
    birds' legs 1.3-1.9 s from a track's end joined it; with 1.0 s a drone's piece
    1.08 s on was lost (deviation 151 made it 1.3 s). Returns the pieces to add."""
    gap = float(params.bridge_end_gap)
    if gap <= 0 or not selected:
        return []
    pieces = _selected_ends(labels, xyz, t, selected)
    if not pieces:
        return []
    pool = _split_pool(labels, scores, selected, was_split, params)
    first = min(pieces, key=lambda e: e.first)
    last = max(pieces, key=lambda e: e.last)
    added: list[int] = []
    for origin, backward, side in (
        (last, False, scores.t_first > last.last),
        (first, True, scores.t_last < first.first),
    ):
        nodes = _moving_ends(labels, xyz, t, np.flatnonzero(pool & side))
        chains = _chains(origin, nodes, scores, params, gap, backward)
        if chains:
            added += max(chains, key=lambda chain: chain[1])[2]
    return added


def _heads_to(origin: np.ndarray, velocity: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(M,) bool: whether ``velocity`` at ``origin`` points at each of ``targets`` (M, 3)
    within 60 degrees (all False for an unknown or zero velocity)."""
    speed = float(np.linalg.norm(velocity))
    if not speed > 0:  # NaN velocity: unknown
        return np.zeros(len(targets), dtype=bool)
    way = np.asarray(targets, dtype=np.float64).reshape(-1, 3) - origin
    return way @ velocity >= 0.5 * speed * np.linalg.norm(way, axis=1)


def lead_in_piece(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    selected: list[int],
    params: ParamSet,
) -> list[int]:
    """lead_in_gap (deviation 114): the piece of a drone's arrival that ended up to
    ``lead_in_gap`` s before the first selected piece began, seen too briefly or too
    sparsely to be selected alone, where the drone then stopped out of view and went on
    from near where it was last seen: a flying cluster (``min_centroid_z``) of at least
    half ``min_cluster_points`` returns and ``keep_confidence``, moving (``min_speed``)
    coherently (above ``coherence_floor``), within ``max_local_extent``, whose last
    returns lie within ``lead_in_reach`` of the selected piece's first ones and head
    towards them (the velocity over its last second within 60 degrees of that
    direction), with the piece's start within the linking reach
    (:func:`~clusterfilter_ros.core.linking.linking_reach`) of where that velocity
    led. The latest such cluster, or none; no chains."""
    gap, reach = float(params.lead_in_gap), float(params.lead_in_reach)
    if gap <= 0 or not selected:
        return []
    first = min(selected, key=lambda c: scores.t_first[c])
    member = labels == first
    if not member.any():
        return []
    track = _piece_ends(first, t[member], xyz[member])
    ok = (
        (scores.n_points >= 0.5 * params.min_cluster_points)
        & (scores.confidence >= params.keep_confidence)
        & (scores.centroid[:, 2] >= params.min_centroid_z)
        & (scores.apparent_speed >= params.min_speed)
        & (scores.coherence > params.coherence_floor)
        & (scores.local_extent <= params.max_local_extent)
        & (scores.t_last < track.first)
        & (scores.t_last >= track.first - gap)
    )
    ok[selected] = False
    for c in np.flatnonzero(ok)[np.argsort(-scores.t_last[ok], kind="stable")]:
        member = labels == c
        ends = _piece_ends(int(c), t[member], xyz[member])
        way = track.p_first - ends.p_last
        distance = float(np.linalg.norm(way))
        speed = float(np.linalg.norm(ends.v_last))
        if not (distance <= reach and speed > 0):  # NaN velocity: unknown, not taken
            continue
        if not _heads_to(ends.p_last, ends.v_last, track.p_first)[0]:
            continue
        # Where it was heading, the track's start within the linking reach: an arrival
        # at 11 m/s cannot have stopped 4 m further on in 3.5 s (link_max_accel).
        dt = track.t_first - ends.t_last
        miss = float(np.linalg.norm(way - ends.v_last * dt))
        if miss <= float(linking_reach(np.asarray(dt), params)):
            return [int(c)]
    return []


def _unscored(labels: np.ndarray, scores: ClusterScores, params: ParamSet) -> np.ndarray:
    """(N,) bool: the returns too few to be scored, noise and clusters below
    ``min_cluster_points``; what growth and the stays between pieces may take."""
    small = scores.n_points < params.min_cluster_points
    return (labels < 0) | small[np.maximum(labels, 0)]


def stop_between_pieces(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    selected: list[int],
    params: ParamSet,
    exclude: np.ndarray | None = None,
) -> np.ndarray:
    """stop_bridge_gap (deviation 132): labels with the stay of a drone that stopped
    between two selected pieces, seen there in lone returns, labelled as the earlier
    piece. Between consecutive pieces (by time) more than ``extend_max_gap`` and at most
    ``stop_bridge_gap`` apart, the returns too few to be scored (noise and clusters
    below ``min_cluster_points``, not in ``exclude``) in the gap, above
    ``min_centroid_z``, where the earlier piece's end was heading and the later piece's
    start came from (its velocity, each within 60 degrees of the way to the return), no
    farther from either than ``link_gate`` plus its speed times the time between, are
    candidates. The candidate with the most frames of candidates within
    ``stream_hover_max_extent`` of it, with those candidates, is the stay if they span
    at least three frames within a box that size and scatter no more than
    ``hover_max_scatter`` (:func:`~.scoring.local_scatter`). A drone flying on to a
    spot 32 m out, staying there 2 s, then flying on, is seen neither on the way nor
    enough to be a cluster there; growth does not cross the seconds before and after
    the stay."""
    limit = float(params.stop_bridge_gap)
    if limit <= 0 or len(selected) < 2:
        return labels
    pool = _unscored(labels, scores, params) & ~np.isin(labels, selected)
    if exclude is not None:
        pool &= ~exclude
    pieces = sorted(_selected_ends(labels, xyz, t, selected), key=lambda e: e.first)
    extent = float(params.stream_hover_max_extent)
    fp = float(params.frame_period)
    out = labels.copy()
    for before, after in zip(pieces[:-1], pieces[1:], strict=True):
        if not params.extend_max_gap < after.first - before.last <= limit:
            continue
        idx = np.flatnonzero(pool & (t > before.last) & (t < after.first))
        pts = xyz[idx].astype(np.float64)
        heading = pts[:, 2] >= params.min_centroid_z
        gate = float(params.link_gate)
        # Where the earlier piece was heading and the later one came from, no farther
        # than each flew by then at its speed.
        for origin, velocity, dt in (
            (before.p_last, before.v_last, t[idx] - before.t_last),
            (after.p_first, -after.v_first, after.t_first - t[idx]),
        ):
            heading &= _heads_to(origin, velocity, pts)
            heading &= np.linalg.norm(pts - origin, axis=1) <= gate + np.linalg.norm(velocity) * dt
        idx, pts = idx[heading], pts[heading]
        if idx.size < 3:
            continue
        # Per candidate, the frames of the candidates within `extent` of it (itself too).
        pairs = cKDTree(pts).query_pairs(extent, output_type="ndarray")
        a = np.concatenate([np.arange(idx.size), pairs[:, 0], pairs[:, 1]])
        b = np.concatenate([np.arange(idx.size), pairs[:, 1], pairs[:, 0]])
        frames = frame_sample_ids(np.zeros(idx.size, np.int64), t[idx], fp)
        seen = np.unique(np.column_stack([a, frames[b]]), axis=0)
        best = int(np.argmax(np.bincount(seen[:, 0], minlength=idx.size)))
        stay = idx[np.unique(np.r_[best, b[a == best]])]
        scatter = stay_scatter(xyz[stay], t[stay], extent, fp)
        if scatter is None:
            continue
        if params.hover_max_scatter > 0 and scatter > params.hover_max_scatter:
            continue
        out[stay] = before.cluster
        pool[stay] = False
    return out


def extend_selected(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    selected: list[int],
    params: ParamSet,
    exclude: np.ndarray | None = None,
    near_floor: np.ndarray | None = None,
    start_only: frozenset[int] = frozenset(),
) -> np.ndarray:
    """Labels with each selected track grown at its ends (:func:`~.linking.extend_track`;
    the ``start_only`` ones backwards only)
    and filled inside (:func:`~.linking.fill_track`) by noise points and clusters too
    small to be scored (< ``min_cluster_points``), and inside also by the points of other
    scored clusters within ``track_gate`` of its path; never by the points in
    ``exclude``. The points in ``near_floor`` (the Mid360 returns below ``mid360_min_z``
    of :func:`growth_only_points`) join a track's end only across gaps of at most
    ``max_extrapolation``: a drone landing near the rig is seen every frame, and after
    it has landed a person walking past must not continue its track."""
    # Only what is too small to be judged on its own: a cluster that was scored and
    # rejected (an erratic bird, say) must not extend a track.
    pool = _unscored(labels, scores, params)
    # Inside the track's span, returns close to its path join it whatever cluster they
    # were put in: a bird passing a hovering drone takes the drone's returns into its own
    # cluster for seconds (deviation 54).
    scored = ~pool & ~np.isin(labels, selected)
    if exclude is not None:
        pool &= ~exclude
        scored &= ~exclude
    out = labels.copy()
    for c in selected:
        member = out == c
        grown = extend_track(
            member,
            xyz,
            t,
            pool,
            params,
            short_gap=near_floor,
            grow_end=c not in start_only,
            heading=_on_fit(member, xyz, t, float(scores.confidence[c]), params),
        )
        member = fill_track(grown, xyz, t, pool, params)
        member = fill_track(member, xyz, t, scored, params, max_reach=params.track_gate)
        pool &= ~member
        scored &= ~member
        out[member] = c
    return out


#: grow_from_fit: seconds at each end of a track that its own trajectory fit judges.
ENDS_FIT_SPAN = 4.0


def _on_fit(
    member: np.ndarray, xyz: np.ndarray, t: np.ndarray, confidence: float, params: ParamSet
) -> np.ndarray | None:
    """grow_from_fit (deviation 137): (N,) bool, the ``member`` returns that define the
    track's ends for growth: at each end (its first and last :data:`ENDS_FIT_SPAN`
    seconds, or all of a track no longer than twice that), those within
    ``stray_distance`` of the end's own trajectory fit (:func:`cluster_trajectory`);
    the returns between the two ends, and those of an end without a fit, all count.
    None with the switch off, ``stray_distance`` 0 or no members. Another object's
    returns at the head or tail of a track's cluster are off the fit."""
    if not params.grow_from_fit or params.stray_distance <= 0 or not member.any():
        return None
    idx = np.flatnonzero(member)
    out = member.copy()
    tm = t[idx]
    # Only the ends are judged: the first and last ENDS_FIT_SPAN seconds, each fitted
    # on its own (a smoothing spline's cross-validation over a whole long track costs
    # as much as the rest of the detection).
    window = ENDS_FIT_SPAN
    lo, hi = float(tm.min()), float(tm.max())
    if hi - lo <= 2 * window:
        parts = [np.ones(tm.size, dtype=bool)]
    else:
        parts = [tm <= lo + window, tm >= hi - window]
    for part in parts:
        sel = idx[part]
        traj = cluster_trajectory(t[sel], xyz[sel], confidence, params)
        if traj is None:
            continue
        off = np.linalg.norm(traj(t[sel]) - xyz[sel], axis=1)
        out[sel[~(off <= float(params.stray_distance))]] = False  # NaN (no fit there): off
    return out


def growth_only_points(
    cloud: GlobalCloud,
    denoised: np.ndarray,
    structure: np.ndarray | None,
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    selected: list[int],
    params: ParamSet,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(xyz (M, 3) float32, t (M,), below the floor (M,) bool): points kept out of
    clustering and scoring that a selected track may still grow into
    (:func:`extend_selected`).

    - ``extend_denoised``: the points of ``cloud`` the denoise removed (``denoised``
      marks them), except those in the suppressed static voxels ``structure``. A drone
      far away leaves one Avia return a second or less, too sparse for the density
      count, but where its track was heading.
    - ``extend_below_floor``: the Mid360 returns at or below ``mid360_min_z`` within one
      growth step (the linking reach for ``extend_max_gap``) of a selected track's first
      or last point, except those in voxels hit in ``static_min_bins`` or more time bins
      (:func:`~.background.persistent_mask`): the ground, walls and parked things stay
      out, a drone taking off or landing below the Mid360's height does not.

    ``labels``, ``xyz`` and ``t`` are the clustered points (after the filters). Returns
    also (M,) bool: which of the points are those below the floor.
    """
    parts_xyz, parts_t, parts_floor = [], [], []
    if params.extend_denoised and denoised.any():
        dxyz, dt = cloud.xyz[denoised], cloud.t[denoised]
        if structure is not None and structure.size:
            off = voxel.lookup(structure, voxel.voxel_keys(dxyz, params.static_voxel)) < 0
            dxyz, dt = dxyz[off], dt[off]
        parts_xyz.append(dxyz)
        parts_t.append(dt)
        parts_floor.append(np.zeros(dt.size, dtype=bool))
    if _grows_below_floor(params) and cloud.floor_t.size and selected:
        ends = _track_ends(labels, xyz, t, selected)
        fxyz, ft = transient_below_floor(cloud.floor_xyz, cloud.floor_t, ends, params)
        parts_xyz.append(fxyz)
        parts_t.append(ft)
        parts_floor.append(np.ones(ft.size, dtype=bool))
    return (
        _stack(parts_xyz, np.empty((0, 3), np.float32)),
        _stack(parts_t, np.empty(0)),
        _stack(parts_floor, np.empty(0, dtype=bool)),
    )


def transient_below_floor(
    floor_xyz: np.ndarray, floor_t: np.ndarray, ends: np.ndarray, params: ParamSet
) -> tuple[np.ndarray, np.ndarray]:
    """(xyz, t) of the Mid360 returns at or below ``mid360_min_z`` (``floor_xyz``,
    ``floor_t``) within one growth step (the linking reach for ``extend_max_gap``) of
    any of the track ``ends`` (K, 3), except those in voxels hit in ``static_min_bins``
    or more time bins of these returns (:func:`~.background.persistent_mask`): the
    ground, walls and parked things stay out, a drone taking off or landing does not.
    Offline's ``extend_below_floor`` and the late output's ``report_below_floor``."""
    radius = float(linking_reach(params.extend_max_gap, params))
    fz = np.ascontiguousarray(floor_xyz[:, 2])
    near = np.zeros(fz.size, dtype=bool)
    for end in ends:
        # Most track ends are far above the floor: a height test first (cheap), the
        # distance only for the points that pass it.
        rows = np.flatnonzero(np.abs(fz - end[2]) <= radius)
        d = floor_xyz[rows] - end
        near[rows[np.einsum("ij,ij->i", d, d) <= radius * radius]] = True
    fxyz, ft = floor_xyz[near], floor_t[near]
    transient = ~persistent_mask(fxyz, ft, params)
    return fxyz[transient], ft[transient]


def _track_ends(
    labels: np.ndarray, xyz: np.ndarray, t: np.ndarray, selected: list[int]
) -> np.ndarray:
    """(2 * len(selected), 3) float32: each selected cluster's first and last point."""
    ends = []
    for c in selected:
        m = np.flatnonzero(labels == c)
        if m.size:
            ends += [xyz[m[np.argmin(t[m])]], xyz[m[np.argmax(t[m])]]]
    return np.asarray(ends, dtype=np.float32).reshape(-1, 3)


def split_offline(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    params: ParamSet,
    score: Scorer,
    apart: float = 0.0,
    among: np.ndarray | None = None,
) -> tuple[np.ndarray, int, ClusterScores, np.ndarray]:
    """:func:`~.splitting.split_and_score` as offline splits: whatever the cluster's
    contact with suppressed structure, a narrow cluster below ``min_confidence`` above
    ``split_excess_residual`` too, with two trackers; ``apart`` and ``among`` passed on."""
    return split_and_score(
        labels,
        xyz,
        t,
        scores,
        params,
        score,
        None,
        excess_residual=params.split_excess_residual,
        two_trackers=True,
        apart=apart,
        among=among,
    )


def cut_unconfident(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    scores: ClusterScores,
    params: ParamSet,
    score: Scorer,
) -> tuple[np.ndarray, ClusterScores, np.ndarray | None]:
    """Unconfident clusters cut in time, each piece scored alone (``score`` with a
    fixed window origin): a hover then a flight (split_still), then a long pass in
    pieces (split_long; deviation 90). With split_cut_pieces, a piece of a hover then a
    flight is then split into kinematic tracks as a merged cluster is (deviation 113):
    a bird that joined the drone's track for a second leaves the whole smooth enough not
    to be split, but makes its piece rough. Returns (labels, scores, mask of the points
    of a cut cluster; None when neither cut is enabled)."""
    cut_any = None
    still = np.zeros(labels.size, dtype=bool)  # the points of split_still's cuts
    for enabled, cut_in_time in (
        (params.split_still, split_still),
        (params.split_long > 0, split_long),
    ):
        if not enabled:
            continue
        cut_labels, k, cut = cut_in_time(labels, xyz, t, scores, params)
        scores = score_pieces(labels, cut_labels, k, cut, xyz, t, scores, params, score)
        labels = cut_labels
        cut_any = cut if cut_any is None else cut_any | cut
        if cut_in_time is split_still:
            still = cut
    if params.split_merged and params.split_cut_pieces and still.any():
        # Not split_long's pieces: a long bird cluster cut into 4 s pieces then split
        # gave a bird's smooth leg (no_drone_birds 3302: false alarms 39% -> 74%).
        among = np.unique(labels[still & (labels >= 0)])
        labels, _, scores, again = split_offline(labels, xyz, t, scores, params, score, among=among)
        assert cut_any is not None
        cut_any |= again
    return labels, scores, cut_any


def detect_offline(
    frames: Iterable[Frame],
    params: ParamSet | None = None,
    timestamps: np.ndarray | None = None,
) -> OfflineResult:
    """Detect the drone over a whole sequence; see the module docstring."""
    params = detector_params() if params is None else params
    cloud = global_cloud(frames, params)
    noisy, stamps = cloud.noisy, cloud.stamps
    keep = np.ones(cloud.t.size, dtype=bool)
    if noisy.any():
        keep[noisy] = density_mask(
            cloud.xyz[noisy], params.denoise_voxel, params.denoise_min_points
        )
    xyz, t = cloud.xyz[keep], cloud.t[keep]
    structure = None
    if params.static_suppression and t.size:
        static, structure = static_offline(xyz, t, params)
        xyz, t = xyz[~static], t[~static]
    labels, k = global_clusters(xyz, t, params)
    tight_hover = None
    if params.offline_tight_hover and params.hover_detection:
        if params.stream_hover_min_frames < params.hover_min_frames:
            tight_hover = (params.stream_hover_min_frames, params.stream_hover_max_extent)
            if k:
                # A far hover's lone returns count towards its frames (deviation 97),
                # each with the piece at its spot that was there then.
                extent = float(params.stream_hover_max_extent)
                labels = absorb_colocated_noise(
                    labels, xyz, extent, extent / 2, t=t, max_gap=params.link_max_gap
                )
    # Fixed window origins: the pieces of a split cluster are scored alone.
    labelled = labels >= 0
    origin = float(t[labelled].min()) if labelled.any() else None
    score = functools.partial(
        score_clusters,
        t0=origin,
        coherence_origin=origin,
        structure_keys=structure,
        tight_hover=tight_hover,
    )
    scores = score(labels, xyz, t, params, n_clusters=k)
    was_split = None
    if params.split_merged:
        # Split whatever the cluster's contact with suppressed structure (deviation 78):
        # birds circling a drone for seconds make voxels static around both, and the
        # merged cluster, barely coherent, was left whole as a remnant of structure.
        # Streaming keeps the contact test (it let a bird piece be reported live).
        labels, k, scores, was_split = split_offline(
            labels, xyz, t, scores, params, score, apart=params.split_apart
        )
    labels, scores, cut = cut_unconfident(labels, xyz, t, scores, params, score)
    if cut is not None:
        was_split = cut if was_split is None else was_split | cut
    spans = tracked_spans(labels, xyz, t, scores, params)
    whole = select_clusters(spans, params)
    labels, selected, trimmed = select_trimmed(labels, t, spans, whole, params, was_split, xyz=xyz)
    if params.end_objects:
        labels = without_end_objects(labels, xyz, t, whole, params)
    selected = reachable_pieces(
        labels, xyz, t, selected, params, frozenset(selected) - frozenset(whole)
    )
    if was_split is not None:
        selected += continuing_pieces(labels, xyz, t, scores, selected, was_split, params)
        selected += bridging_pieces(labels, xyz, t, scores, selected, was_split, params)
        selected += end_pieces(labels, xyz, t, scores, selected, was_split, params)
    lead_in = lead_in_piece(labels, xyz, t, scores, selected, params)
    selected += lead_in
    rows = scores.rows()
    for row in rows:
        row["selected"] = float(int(row["cluster"]) in selected)
    empty = TimedPositions(
        np.empty(0), np.empty((0, 3)), {"confidence": np.empty(0), "points": np.empty(0, int)}
    )
    if not selected:
        return OfflineResult(empty, np.empty((0, 4)), None, rows, scores, selected)
    if params.link_max_gap > 0:
        # The pieces of a split cluster were scored: none of them re-enters a track as
        # growth (a bird's piece beside the drone's would).
        # Nor do the points trimmed off a selected cluster.
        exclude = trimmed if was_split is None else was_split | trimmed
        near_floor = None
        if _grows(params):
            gxyz, gt, gfloor = growth_only_points(
                cloud, ~keep, structure, labels, xyz, t, selected, params
            )
            if gt.size:
                near_floor = np.concatenate([np.zeros(t.size, dtype=bool), gfloor])
                xyz, t = np.concatenate([xyz, gxyz]), np.concatenate([t, gt])
                labels = np.concatenate([labels, np.full(gt.size, -1, labels.dtype)])
                exclude = np.concatenate([exclude, np.zeros(gt.size, dtype=bool)])
        # The lead-in grows backwards only: past its end the drone went out of view, and
        # growth there took another object's returns (`default` 4703).
        labels = extend_selected(
            labels, xyz, t, scores, selected, params, exclude, near_floor, frozenset(lead_in)
        )
        labels = stop_between_pieces(labels, xyz, t, scores, selected, params, exclude)
    drone = np.isin(labels, selected)
    # One trajectory per selected cluster: a segment never bridges two objects.
    traj = merge_trajectories(
        [
            cluster_trajectory(
                t[labels == c],
                xyz[labels == c],
                # A continuing piece is reported as the track it continues (deviation 80).
                max(float(scores.confidence[c]), float(params.min_confidence)),
                params,
            )
            for c in selected
        ],
        params.max_extrapolation,
    )
    drone_points = np.column_stack([t[drone], xyz[drone].astype(np.float64)])
    drone_points = drone_points[np.argsort(drone_points[:, 0], kind="stable")]
    if traj is None:
        return OfflineResult(empty, drone_points, None, rows, scores, selected)
    query = stamps if timestamps is None else np.asarray(timestamps, dtype=np.float64).reshape(-1)
    query = query[np.isfinite(query)]
    pos = traj(query)
    conf = traj.confidence(query)
    support = traj.support(query, params.track_window)
    ok = np.isfinite(pos).all(axis=1) & (conf >= params.min_confidence)
    ok &= support >= params.min_points
    estimates = TimedPositions(
        query[ok],
        reported_positions(pos[ok], params),
        {"confidence": conf[ok], "points": support[ok]},
    )
    return OfflineResult(estimates, drone_points, traj, rows, scores, selected)
