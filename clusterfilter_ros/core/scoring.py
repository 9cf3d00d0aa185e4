"""Per-cluster global/local features and scores (paper 3.2 local windows, 3.3 scoring).

For every global cluster k:
- global density rho_g = points / occupied voxels (voxel_size voxels; the voxel volume
  cancels in every ratio below, so densities are in points per voxel);
- for each local window length w in ``frames`` (w * frame_period seconds, consecutive
  non-overlapping windows starting at ``t0``): the cluster's points inside the window
  (never re-clustered), their local density rho_l and the relative density
  R = rho_l / rho_g; the voxel IoU between the voxel sets of consecutive windows;
- the paper's score ``sum exp(R) + iou_weight * sum log(1 / max(IoU, iou_floor))``;
- the normalized score, used as the cluster's confidence in both scoring modes (in
  [0, 1]): ``(mean min(R, 1) + iou_weight * mean log(1/IoU) / log(1/iou_floor)) /
  (1 + iou_weight)``, times a ramp of the motion coherence (0 at ``coherence_floor``, 1
  at ``min_coherence``; see :func:`motion_coherence`), times ``min(1, apparent_speed /
  min_speed)`` (bounding-box size over time span: sparse static remnants crawl, a
  flying drone does not), times ``min(1, support_frames / min_support_frames)``, times a
  smoothness ramp (1 up to ``smooth_residual``, 0 at ``max_residual``) of the RMS residual
  of a quadratic fit of position against time per ``residual_window`` (see
  :func:`track_residual`): drones fly smooth, acceleration-limited paths, birds and
  swaying branches do not; and times a ramp (1 up to ``smooth_excess``, 0 at
  ``max_excess``) of the excess residual sqrt(residual^2 - spread^2), spread being the
  RMS scatter of a cluster's points within one frame (:func:`frame_spread`); and times a
  ramp (1 up to ``smooth_accel``, 0 at ``max_accel``) of the acceleration fitted per
  ``accel_window``: a drone's sustained acceleration is bounded, a bird's wing-driven
  weaving is not (simulation, 1 s windows: drones median 2.5 m/s^2, 90% below 5.2;
  birds median 12, 90% above 5.5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from clusterfilter_ros.core import voxel
from clusterfilter_ros.core.grouping import group_bounds, lex_order
from clusterfilter_ros.core.params import ParamSet


@dataclass
class ClusterScores:
    """Features and scores of K global clusters (every attribute is a length-K array).

    ``residual``, ``excess_residual`` and ``acceleration`` are measured only for
    candidates whose score is not already 0 without them; they are 0 elsewhere."""

    n_points: np.ndarray
    n_voxels: np.ndarray
    volume: np.ndarray
    centroid: np.ndarray
    extent: np.ndarray
    t_first: np.ndarray
    t_last: np.ndarray
    support_frames: np.ndarray
    n_windows: np.ndarray
    n_pairs: np.ndarray
    mean_relative_density: np.ndarray
    mean_iou: np.ndarray
    local_extent: np.ndarray
    coherence: np.ndarray
    apparent_speed: np.ndarray
    residual: np.ndarray
    excess_residual: np.ndarray
    acceleration: np.ndarray
    paper_score: np.ndarray
    normalized_score: np.ndarray
    confidence: np.ndarray
    candidate: np.ndarray

    def __len__(self) -> int:
        return int(self.n_points.shape[0])

    def rank_score(self, scoring: str) -> np.ndarray:
        """The score clusters are ranked by in the given scoring mode.

        Normalized scoring ranks by confidence times log(1 + frames with points): of two
        confident tracks, the one with more evidence wins (a few sparse returns can look
        as smooth as a drone; they cannot look as long-lived).
        """
        if scoring == "paper":
            return self.paper_score
        return self.confidence * np.log1p(self.support_frames)

    def rows(self) -> list[dict[str, float]]:
        """One dict per cluster, for debugging, tables and JSON."""
        out = []
        for k in range(len(self)):
            row: dict[str, float] = {"cluster": k}
            for f in fields(self):
                v = getattr(self, f.name)[k]
                if f.name == "centroid":
                    row.update({"cx": float(v[0]), "cy": float(v[1]), "cz": float(v[2])})
                else:
                    row[f.name] = float(v)
            out.append(row)
        return out


def select_and_append(
    scores: ClusterScores, keep: np.ndarray, more: ClusterScores | None = None
) -> ClusterScores:
    """The clusters ``keep`` of ``scores`` (in that order), followed by those of ``more``
    (if given)."""

    def column(name: str) -> np.ndarray:
        kept = getattr(scores, name)[keep]
        return kept if more is None else np.concatenate([kept, getattr(more, name)])

    return ClusterScores(**{f.name: column(f.name) for f in fields(ClusterScores)})


def _empty(k: int) -> ClusterScores:
    z = np.zeros(k)
    return ClusterScores(
        n_points=z.copy(),
        n_voxels=z.copy(),
        volume=z.copy(),
        centroid=np.zeros((k, 3)),
        extent=z.copy(),
        t_first=z.copy(),
        t_last=z.copy(),
        support_frames=z.copy(),
        n_windows=z.copy(),
        n_pairs=z.copy(),
        mean_relative_density=z.copy(),
        mean_iou=z.copy(),
        local_extent=z.copy(),
        coherence=z.copy(),
        apparent_speed=z.copy(),
        residual=z.copy(),
        excess_residual=z.copy(),
        acceleration=z.copy(),
        paper_score=z.copy(),
        normalized_score=z.copy(),
        confidence=z.copy(),
        candidate=np.zeros(k, dtype=bool),
    )


_SUMS = (
    "sum_exp_r",
    "sum_r_capped",
    "n_windows",
    "sum_log_inv_iou",
    "sum_iou",
    "n_pairs",
    "sum_extent",
)


def local_window_features(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    fine_ids: np.ndarray,
    global_density: np.ndarray,
    window_seconds: float,
    t0: float,
    iou_floor: float,
) -> dict[str, np.ndarray]:
    """Sums over one window length's local windows, per cluster (length-K arrays).

    Returns ``sum_exp_r``, ``sum_r_capped`` (sum of min(R, 1)), ``n_windows``,
    ``sum_log_inv_iou``, ``sum_iou``, ``n_pairs`` and ``sum_extent`` (sum over windows of
    the largest bounding-box side of the window's points). ``labels`` must be 0..K-1;
    ``fine_ids`` number the points' ``voxel_size`` voxels 0..V-1.
    """
    k = global_density.shape[0]
    out = {name: np.zeros(k) for name in _SUMS}
    if labels.size == 0:
        return out
    win = np.floor((t - t0) / window_seconds + 1e-6).astype(np.int64)
    win -= win.min()
    n_win = int(win.max()) + 1
    fid = fine_ids
    n_fine = int(fid.max()) + 1
    # (cluster, window) point counts and voxel counts.
    cw = labels * n_win + win
    cw_u, cw_inv, cw_points = voxel.unique_ints(cw, return_inverse=True, return_counts=True)
    cw_inv = cw_inv.reshape(-1)
    ((lo, hi),) = group_bounds(cw_inv, cw_u.size, xyz)
    triple = (labels * n_fine + fid.reshape(-1)) * n_win + win
    triple_u = voxel.unique_ints(triple)
    t_cw = (triple_u // (n_win * n_fine)) * n_win + triple_u % n_win
    t_cw_idx = np.searchsorted(cw_u, t_cw)
    cw_voxels = np.bincount(t_cw_idx, minlength=cw_u.size).astype(np.float64)
    cw_cluster = cw_u // n_win
    rel = (cw_points / cw_voxels) / global_density[cw_cluster]
    out["sum_exp_r"] = np.bincount(cw_cluster, weights=np.exp(np.minimum(rel, 50.0)), minlength=k)
    out["sum_r_capped"] = np.bincount(cw_cluster, weights=np.minimum(rel, 1.0), minlength=k)
    out["n_windows"] = np.bincount(cw_cluster, minlength=k).astype(np.float64)
    out["sum_extent"] = np.bincount(cw_cluster, weights=(hi - lo).max(axis=1), minlength=k)
    # Intersections: the same (cluster, voxel) in windows j and j + 1 (triples are
    # sorted by cluster, voxel, window, so such entries are adjacent).
    same_voxel = (triple_u[1:] // n_win) == (triple_u[:-1] // n_win)
    next_window = (triple_u[1:] % n_win) == (triple_u[:-1] % n_win) + 1
    inter_at = t_cw_idx[:-1][same_voxel & next_window]
    inter = np.bincount(inter_at, minlength=cw_u.size).astype(np.float64)
    # Pairs: (cluster, j) and (cluster, j + 1) both present (cw_u sorted => adjacent).
    pair = cw_u[1:] == cw_u[:-1] + 1
    pair &= (cw_u[1:] // n_win) == (cw_u[:-1] // n_win)
    first = np.nonzero(pair)[0]
    union = cw_voxels[first] + cw_voxels[first + 1] - inter[first]
    iou = inter[first] / union
    pc = cw_cluster[first]
    out["sum_log_inv_iou"] = np.bincount(
        pc, weights=np.log(1.0 / np.maximum(iou, iou_floor)), minlength=k
    )
    out["sum_iou"] = np.bincount(pc, weights=iou, minlength=k)
    out["n_pairs"] = np.bincount(pc, minlength=k).astype(np.float64)
    return out


def structure_contact(
    lab: np.ndarray,
    pts: np.ndarray,
    k: int,
    which: np.ndarray,
    structure_keys: np.ndarray,
    voxel_size: float,
) -> np.ndarray:
    """(k,) share of the points of each cluster flagged in ``which`` whose voxel of edge
    ``voxel_size`` is, or touches (26 neighbours), a voxel in the sorted
    ``structure_keys``; 0 for the clusters not flagged."""
    out = np.zeros(k)
    sel = which[lab]
    if not sel.any():
        return out
    keys, inverse = voxel.unique_ints(
        voxel.voxel_keys(pts[sel], voxel_size), return_inverse=True, fields=voxel.VOXEL_FIELDS
    )
    around = keys[:, None] + voxel.NEIGHBOURHOOD[None, :]
    touching = (voxel.lookup(structure_keys, around.ravel()) >= 0).reshape(around.shape)
    per_point = touching.any(axis=1)[inverse.reshape(-1)]
    cl = lab[sel]
    counts = np.bincount(cl, minlength=k)
    hits = np.bincount(cl, weights=per_point, minlength=k)
    flagged = counts > 0
    out[flagged] = hits[flagged] / counts[flagged]
    return out


def score_clusters(
    labels: np.ndarray,
    xyz: np.ndarray,
    t: np.ndarray,
    params: ParamSet,
    *,
    n_clusters: int,
    global_points: np.ndarray | None = None,
    global_voxels: np.ndarray | None = None,
    t0: float | None = None,
    min_track_seconds: float | None = None,
    structure_keys: np.ndarray | None = None,
    coherence_origin: float | None = None,
    tight_hover: tuple[int, float] | None = None,
) -> ClusterScores:
    """Features, gates and scores of clusters ``0..n_clusters-1``.

    Local windows start at ``t0`` (default: the earliest labelled stamp); the motion
    coherence windows at ``coherence_origin`` (default: the earliest labelled stamp,
    even when ``t0`` is given; aligning them to a streaming ``t0`` was measured and not
    taken, docs/detector.md deviation 34). Scores are per cluster: scoring a subset of
    the clusters alone gives the same values when both origins are given.

    ``structure_keys``: sorted ``static_voxel`` keys of the suppressed static structure;
    a cluster is taken for a hovering drone only if at most ``hover_max_contact`` of its
    points lie in or next to one of them (a swaying crown's edge, not a drone in the
    open).

    ``min_track_seconds`` (default ``params.min_track_seconds``, the offline value)
    scales the confidence of clusters seen for less than that many seconds; streaming
    passes ``params.stream_min_track_seconds``.

    ``tight_hover`` = (frames, extent): a hovering cluster whose returns stay within
    ``extent`` (10th-90th percentile per axis) needs only ``frames`` frames in place, and
    as many points, to be a candidate with full support (streaming passes
    ``stream_hover_min_frames`` and ``stream_hover_max_extent``); None: off.

    ``labels``/``xyz``/``t`` are the points the local windows are drawn from (label -1
    ignored). ``global_points``/``global_voxels`` give each cluster's global point count
    and occupied voxel count when the global cloud is not these points (streaming: the
    voxel accumulator); by default both come from the points themselves.
    """
    k = int(n_clusters)
    res = _empty(k)
    if k == 0:
        return res
    labels = np.asarray(labels, dtype=np.int64)
    keep = labels >= 0
    lab = labels[keep]
    pts = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)[keep]
    tt = np.asarray(t, dtype=np.float64)[keep]
    vs = float(params.voxel_size)
    # Each point's voxel_size voxel, numbered 0..V-1 (once for every window length).
    fid = voxel.unique_voxel_keys(pts, vs)[2].reshape(-1)
    counts = np.bincount(lab, minlength=k).astype(np.float64)
    if global_points is None or global_voxels is None:
        g_vox = np.zeros(k)
        if lab.size:
            n_fine = int(fid.max()) + 1
            pair_u = voxel.unique_ints(lab * n_fine + fid.reshape(-1))
            g_vox = np.bincount(pair_u // n_fine, minlength=k).astype(np.float64)
        g_pts = counts.copy()
    else:
        g_pts = np.asarray(global_points, dtype=np.float64)
        g_vox = np.asarray(global_voxels, dtype=np.float64)
    res.n_points = g_pts
    res.n_voxels = g_vox
    res.volume = g_vox * vs**3
    global_density = np.where(g_vox > 0, g_pts / np.maximum(g_vox, 1.0), 1.0)
    global_density = np.where(global_density > 0, global_density, 1.0)
    if lab.size:
        for axis in range(3):
            res.centroid[:, axis] = np.bincount(
                lab, weights=pts[:, axis], minlength=k
            ) / np.maximum(counts, 1.0)
        (lo, hi), (tf, tl) = group_bounds(lab, k, pts, tt)
        res.extent = np.where(counts > 0, (hi - lo).max(axis=1), 0.0)
        res.t_first = np.where(counts > 0, tf, np.nan)
        res.t_last = np.where(counts > 0, tl, np.nan)
        origin = float(tt.min()) if t0 is None else float(t0)
        fp = float(params.frame_period)
        frame_bin = np.floor((tt - origin) / fp + 1e-6).astype(np.int64)
        frames = bin_means(lab, frame_bin, pts)
        res.support_frames = np.bincount(frames[0], minlength=k).astype(np.float64)
        sums = {n: np.zeros(k) for n in _SUMS}
        for i, w in enumerate(sorted(params.frames)):
            part = local_window_features(
                lab, pts, tt, fid, global_density, float(w) * fp, origin, float(params.iou_floor)
            )
            if i == 0:  # extent over the shortest windows
                res.local_extent = part["sum_extent"] / np.maximum(part["n_windows"], 1.0)
            for name in sums:
                sums[name] += part[name]
        res.n_windows = sums["n_windows"]
        res.n_pairs = sums["n_pairs"]
        nw = np.maximum(sums["n_windows"], 1.0)
        npairs = np.maximum(sums["n_pairs"], 1.0)
        res.mean_relative_density = sums["sum_r_capped"] / nw
        res.mean_iou = np.where(sums["n_pairs"] > 0, sums["sum_iou"] / npairs, 1.0)
        lam = float(params.iou_weight)
        res.paper_score = sums["sum_exp_r"] + lam * sums["sum_log_inv_iou"]
        iou_term = np.where(
            sums["n_pairs"] > 0,
            sums["sum_log_inv_iou"] / npairs / np.log(1.0 / float(params.iou_floor)),
            0.0,
        )
        res.coherence = motion_coherence(
            lab,
            pts,
            tt,
            k,
            float(params.coherence_window),
            coherence_origin,
            per_window=bool(params.coherence_per_window),
        )
        lo = min(float(params.coherence_floor), float(params.min_coherence) - 1e-6)
        coherent = np.clip((res.coherence - lo) / (float(params.min_coherence) - lo), 0.0, 1.0)
        span = np.maximum(res.t_last - res.t_first, fp)
        res.apparent_speed = np.where(counts > 0, res.extent / span, 0.0)
        if params.min_speed > 0:
            moving = np.clip(res.apparent_speed / float(params.min_speed), 0.0, 1.0)
        else:  # min_speed 0: every cluster counts as moving (0 / 0 would be NaN)
            moving = np.ones(k)
        if params.min_travel > 0:
            moving = np.maximum(moving, np.clip(res.extent / float(params.min_travel), 0.0, 1.0))
        motion = coherent * moving
        hovering = np.zeros(k, dtype=bool)
        tight = np.zeros(k, dtype=bool)
        tight_frames, tight_extent = tight_hover if tight_hover is not None else (0, 0.0)
        if params.hover_detection:
            # A compact object seen in many frames over some seconds: a hovering drone
            # (static structure has been suppressed, except compact isolated groups; see
            # background.py). A dense flock passing close to the rig fills the frames
            # in 1.5 s, hence the time span too.
            # Extent between the 10th and 90th percentiles per axis: a few returns of a
            # bird passing by must not stretch a hovering drone's cluster past the limit.
            quantiles = [group_quantiles(lab, pts[:, a], k, (0.9, 0.1, 0.5)) for a in range(3)]
            core_extent = np.max([q[0] - q[1] for q in quantiles], axis=0)
            median_position = np.stack([q[2] for q in quantiles], axis=1)
            # Counted in frames, not returns: a bird crossing over the rig can leave most of
            # its returns in the few frames in which the Avia's pattern caught it, within
            # a metre or two, and one return in each of its other frames (deviation 62).
            frames_in_place, span_in_place = frames_near(
                frames, tt, median_position, 0.5 * float(params.hover_max_extent), k
            )
            in_place = (core_extent <= params.hover_max_extent) & (
                span_in_place >= float(params.hover_min_seconds)
            )
            if params.hover_max_scatter > 0 and in_place.any():
                # A drone's returns lie on its body wherever it drifts or brakes to; a
                # far crown's few returns scatter over the crown (deviation 106).
                near = in_place[lab]
                scatter = local_scatter(lab[near], pts[near], tt[near], k)
                in_place &= scatter <= float(params.hover_max_scatter)
            hovering = in_place & (frames_in_place >= params.hover_min_frames)
            if tight_frames and tight_frames < params.hover_min_frames:
                # A small drone hovering far away fills fewer frames in the same time;
                # what stays that tight is a drone's body, not a pole or an edge.
                tight = (
                    in_place
                    & ~hovering
                    & (core_extent <= tight_extent)
                    & (frames_in_place >= tight_frames)
                )
                hovering |= tight
            if structure_keys is not None and structure_keys.size and hovering.any():
                contact = structure_contact(
                    lab, pts, k, hovering, structure_keys, float(params.static_voxel)
                )
                hovering &= contact <= float(params.hover_max_contact)
                tight &= hovering
        res.normalized_score = motion * (res.mean_relative_density + lam * iou_term) / (1.0 + lam)
        if params.hover_detection:
            # Staying in place is what lowers R and raises IoU, so a hovering candidate
            # is scored by its compactness and support alone.
            res.normalized_score = np.where(hovering, 1.0, res.normalized_score)
        # Smoothness and acceleration only for clusters that pass the gates and still have
        # a score (both only scale it down): the others cannot be selected, and the walls,
        # crowns and incoherent clutter among them hold most of the points. The rest keep
        # residual and acceleration 0.
        res.candidate = _gates(res, counts, params)
        if tight.any():
            res.candidate |= tight & _gates(res, counts, params, min_points=tight_frames)
        gated = (res.candidate & (res.normalized_score > 0))[lab]
        if hovering.any():
            # A hovering candidate is judged on the returns of what stays: one farther than
            # half of hover_max_extent from its median position on some axis (a stray
            # return, a bird passing) would make the stay look erratic.
            member = hovering[lab]
            off = np.abs(pts[member] - median_position[lab[member]]).max(axis=1)
            gated[np.flatnonzero(member)[off > 0.5 * float(params.hover_max_extent)]] = False
        g_lab, g_pts, g_t = lab[gated], pts[gated], tt[gated]
        res.residual = multiscale_residual(
            g_lab, g_pts, g_t, k, float(params.residual_window), origin
        )
        res.acceleration = multiscale_residual(
            g_lab,
            g_pts,
            g_t,
            k,
            float(params.accel_window),
            origin,
            acceleration=True,
            phases=int(params.accel_phases),
        )
        # The part of the residual not explained by the object's own spread in one frame
        # (body size, range noise, motion within the frame): a sparse bird's few points
        # per frame are tight but wander from any smooth path between frames.
        spread = frame_spread(lab, pts, frame_bin, k, frames)
        res.excess_residual = np.sqrt(np.maximum(res.residual**2 - spread**2, 0.0))
        r_lo = float(params.smooth_residual)
        r_hi = max(float(params.max_residual), r_lo + 1e-6)
        e_lo = float(params.smooth_excess)
        e_hi = max(float(params.max_excess), e_lo + 1e-6)
        # The raw residual ramp applies to hovering candidates: there it bounds the size of
        # what stays in place (a swaying tree crown scatters 0.7-0.9 m, a drone's body
        # less). A moving drone close to the rig spreads its returns over its body just
        # as much, and is judged by the excess over that spread alone.
        raw = np.clip((r_hi - res.residual) / (r_hi - r_lo), 0.0, 1.0)
        res.normalized_score = (
            res.normalized_score
            * np.where(hovering, raw, 1.0)
            * np.clip((e_hi - res.excess_residual) / (e_hi - e_lo), 0.0, 1.0)
        )
        a_lo = float(params.smooth_accel)
        a_hi = max(float(params.max_accel), a_lo + 1e-6)
        res.normalized_score *= np.clip((a_hi - res.acceleration) / (a_hi - a_lo), 0.0, 1.0)
        need = np.full(k, float(params.min_support_frames))
        need[tight] = min(tight_frames, params.min_support_frames)
        support = np.minimum(1.0, res.support_frames / need)
        confirm = float(
            params.min_track_seconds if min_track_seconds is None else min_track_seconds
        )
        if confirm > 0:
            # Track confirmation: a track seen for less than `confirm` seconds is scaled
            # down in proportion (a bird's straight leg lasts seconds, a flight longer).
            duration = np.where(counts > 0, res.t_last - res.t_first, 0.0)
            support = support * np.clip(duration / confirm, 0.0, 1.0)
        res.confidence = np.clip(res.normalized_score * support, 0.0, 1.0)
    # Without labelled points every cluster keeps the candidate flag False of _empty().
    return res


def _gates(
    res: ClusterScores, counts: np.ndarray, params: ParamSet, min_points: int | None = None
) -> np.ndarray:
    """(K,) bool: the candidate gates (size, height, volume, extent; local extent in
    normalized scoring), from the features computed before any scoring; ``min_points``
    in place of ``params.min_cluster_points``."""
    least = params.min_cluster_points if min_points is None else min_points
    ok = (
        (res.n_points >= least)
        & (res.n_points <= params.max_cluster_points)
        & (res.centroid[:, 2] >= params.min_centroid_z)
        & (res.volume >= params.min_volume - 1e-9)
        & (res.extent <= params.max_extent)
        & (counts > 0)
    )
    if params.scoring != "paper":
        ok &= res.local_extent <= params.max_local_extent
    return ok


def motion_coherence(
    lab: np.ndarray,
    pts: np.ndarray,
    t: np.ndarray,
    k: int,
    window: float,
    origin: float | None = None,
    per_window: bool = False,
) -> np.ndarray:
    """1 - (mean distance to the window centroid) / (mean distance to the cluster centroid).

    Windows are ``window`` seconds long, counted from ``origin`` (default: the earliest
    stamp in ``t``). A moving object's points are close to the
    centroid of their own time window and far from the overall centroid (coherence near
    1); a static object's windows all sample the same place (near 0). Clusters seen in
    a single window get 0: no evidence of motion.

    With ``per_window`` (deviation 144) every window counts once: the cluster centroid
    is the mean of its window centroids, and the distances are averaged per window
    before the windows are averaged. A drone passing over the rig leaves most of its
    returns in the one second it is closest; weighted by returns, that second's spread
    (the drone's own motion in it) is compared with distances to a centroid sitting in
    it, and the pass looked static (coherence 0.42).
    """
    out = np.zeros(k)
    if lab.size == 0:
        return out
    win = np.floor((t - (t.min() if origin is None else origin)) / window).astype(np.int64)
    win -= win.min()
    cw_owner, cw_inv, cw_n, cw_c = bin_means(lab, win, pts)
    # The cluster centroid: the mean of its returns, or of its window centroids.
    ids, values = (cw_owner, cw_c) if per_window else (lab, pts)
    counts = np.bincount(ids, minlength=k).astype(np.float64)
    centroid = (
        np.stack([np.bincount(ids, weights=values[:, a], minlength=k) for a in range(3)], axis=1)
        / np.maximum(counts, 1.0)[:, None]
    )
    # Only windows with >= 2 points say anything about scatter within a window.
    multi = cw_n[cw_inv] >= 2
    local = np.linalg.norm(pts - cw_c[cw_inv], axis=1)
    overall = np.linalg.norm(pts - centroid[lab], axis=1)
    if per_window:
        # Each point weighs 1 / (points in its window): every window counts once.
        w = 1.0 / cw_n[cw_inv]
        local, overall = local * w, overall * w
    local_sum = np.bincount(lab[multi], weights=local[multi], minlength=k)
    overall_sum = np.bincount(lab[multi], weights=overall[multi], minlength=k)
    multi_windows = np.bincount(cw_owner[cw_n >= 2], minlength=k)
    coh = 1.0 - local_sum / np.maximum(overall_sum, 1e-9)
    out[:] = np.where(multi_windows >= 2, np.clip(coh, 0.0, 1.0), 0.0)
    return out


def bin_means(
    lab: np.ndarray, bins: np.ndarray, pts: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The (cluster, bin) pairs holding points, for per-point cluster ids and
    non-negative bin numbers (frames, time windows): (cluster id of each pair (P,),
    pair index of each point (N,), points per pair (P,), mean position per pair (P, 3))."""
    nb = int(bins.max()) + 1
    u, inv = voxel.unique_ints(lab * nb + bins, return_inverse=True)
    inv = inv.reshape(-1)
    n = np.bincount(inv).astype(np.float64)
    mean = np.stack([np.bincount(inv, weights=pts[:, a]) for a in range(3)], axis=1) / n[:, None]
    return u // nb, inv, n, mean


def frames_near(
    frames: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    t: np.ndarray,
    position: np.ndarray,
    reach: float,
    k: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Per cluster: (number of frame bins, seconds between the first and the last of
    them) whose mean position lies within ``reach`` of ``position[cluster]`` on every
    axis. ``frames``: :func:`bin_means` of the points' clusters and frame bins; ``t``:
    the points' stamps (a bin's time is its returns' mean stamp)."""
    owner, inv, n, mean = frames
    near = np.abs(mean - position[owner]).max(axis=1) <= reach
    owner = owner[near]
    stamp = (np.bincount(inv, weights=t) / n)[near]
    count = np.bincount(owner, minlength=k)
    ((first, last),) = group_bounds(owner, k, stamp)
    return count, np.where(count > 0, last - first, 0.0)


def frame_spread(
    lab: np.ndarray,
    pts: np.ndarray,
    frame_bin: np.ndarray,
    k: int,
    frames: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Per cluster: RMS distance (m) of points to the mean of their frame bin, over all
    of the cluster's points.

    A point alone in its frame bin counts with distance 0: its scatter within the frame
    cannot be seen, so none of its distance from a fitted path is put down to it. (Averaged
    over the points of frames with at least 2 points only, as before deviation 61, the
    sparse returns of a far wall, most alone in their frame and a few pairs metres apart,
    had a "spread" as large as their residual.) 0 for clusters with no such pair.
    ``frames``: :func:`bin_means` of ``lab``, ``frame_bin`` and ``pts`` when the caller
    has it already."""
    if lab.size == 0:
        return np.zeros(k)
    _, inv, _, c = bin_means(lab, frame_bin, pts) if frames is None else frames
    d2 = np.einsum("na,na->n", pts - c[inv], pts - c[inv])
    cnt = np.bincount(lab, minlength=k)
    return np.sqrt(np.bincount(lab, weights=d2, minlength=k) / np.maximum(cnt, 1))


#: Fewest points for a residual window to count (a quadratic in 3 axes has 9 unknowns).
RESIDUAL_MIN_POINTS = 6
#: Points farther from a window's quadratic fit than this many times the window's median
#: distance (at least RESIDUAL_MEDIAN_FLOOR m) do not count in its residual (deviation 32).
RESIDUAL_OUTLIER_FACTOR = 10.0
RESIDUAL_MEDIAN_FLOOR = 0.05


def track_residual(
    lab: np.ndarray,
    pts: np.ndarray,
    t: np.ndarray,
    k: int,
    window: float,
    t0: float,
    evidence: bool = False,
    acceleration: bool = False,
    min_span: float | None = None,
    phases: int = 1,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Per cluster: RMS 3D residual (m) of a quadratic fit of position against time.

    Time is cut into ``window``-second windows from ``t0``; in each (cluster, window)
    with at least :data:`RESIDUAL_MIN_POINTS` points spanning at least half the window,
    x, y and z are fitted by least squares as quadratics of time, and the RMS distance of
    the points to the fit is taken (squares summed over n - 3 degrees of freedom, so few
    points do not look smooth by overfitting), leaving out points farther from the fit
    than :data:`RESIDUAL_OUTLIER_FACTOR` times the window's median distance (a stray
    return joined to the track). The result is the point-weighted mean over a
    cluster's windows, 0 for clusters without such a window (no evidence either way).
    An acceleration-limited drone leaves only its body size and range noise (simulation:
    0.07-0.39 m); an erratic bird or a swaying branch leaves much more.

    ``acceleration``: instead, the median over a cluster's windows of the fitted
    acceleration's magnitude (twice the quadratic coefficient, refitted without the
    points left out of the residual), with the windows laid at
    ``phases`` offsets ``window / phases`` apart (all of them pooled). Where a window edge
    falls is arbitrary, and a sparse track's few frames can fit a large acceleration in one
    window and a small one in the window shifted by a fraction of a second; the pooled
    median is that of a sliding window, in effect.
    """
    out = np.zeros(k)
    none = np.zeros(k, dtype=bool)
    if lab.size == 0:
        return (out, none) if evidence else out
    n_phase = max(1, int(phases)) if acceleration else 1
    # Sorted by cluster, then time: each window grid's windows are then runs of points.
    order = lex_order(t, lab)
    lab, pts, t = lab[order], pts[order], t[order]
    origins = [t0 - i * window / n_phase for i in range(n_phase)]
    cluster, values, counts = _window_fits(
        lab, pts, t, k, window, origins, acceleration, min_span, t0
    )
    if cluster.size == 0:
        return (out, none) if evidence else out
    weight = np.bincount(cluster, weights=counts, minlength=k)
    if acceleration:
        # Median over windows: one short, sparse window's fit is easily far off.
        result = group_median(cluster, values, k)
    else:
        total = np.bincount(cluster, weights=values * counts, minlength=k)
        result = np.where(weight > 0, total / np.maximum(weight, 1.0), 0.0)
    return (result, weight > 0) if evidence else result


def _window_fits(
    lab: np.ndarray,
    pts: np.ndarray,
    t: np.ndarray,
    k: int,
    window: float,
    origins: list[float],
    acceleration: bool,
    min_span: float | None,
    instant_origin: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The (cluster, window) quadratic fits of :func:`track_residual`, for one window grid
    per entry of ``origins`` (all grids in one vectorised pass, the points repeated once
    per grid): (cluster id, residual or acceleration, point count) per window with enough
    evidence, grid by grid. The points must be sorted by cluster, then time.
    Distinct instants are counted on a 0.05 s grid from ``instant_origin`` (the same for
    every window grid and every subset of clusters), or from the first point if that is
    absurdly far."""
    empty = (np.empty(0, np.int64), np.empty(0), np.empty(0))
    t_min = float(t.min())
    rel = t - t_min
    span = float(rel.max()) / window
    fractions = []
    for t0 in origins:
        offset = (t_min - t0) / window if math.isfinite(t_min - t0) else 0.0
        if not (math.isfinite(span) and span < 1e9 and 0.0 <= offset < 1e9):
            offset = 0.0  # stamps far from t0: windows aligned to the first point instead
            if not (math.isfinite(span) and span < 1e9):
                return empty  # absurd time spans: no evidence
        fractions.append(offset % 1.0)
    n_grid = len(fractions)
    if n_grid > 1:
        # Grid g's copy of cluster c is cluster g * k + c: still sorted by cluster, time.
        lab = (np.arange(n_grid)[:, None] * k + lab[None, :]).reshape(-1)
        pts = np.tile(pts, (n_grid, 1))
        rel = np.tile(rel, n_grid)
    fraction = np.repeat(np.asarray(fractions), lab.size // n_grid)
    win = np.floor(rel / window + fraction + 1e-9).astype(np.int64)
    n_win = int(win.max()) + 1
    key = lab * n_win + win  # non-decreasing: sorted by cluster, then time
    first = np.empty(key.size, dtype=bool)
    first[0] = True
    np.not_equal(key[1:], key[:-1], out=first[1:])
    starts = np.flatnonzero(first)
    inv = np.cumsum(first) - 1
    cw_u = key[starts]
    m = cw_u.size
    n = np.diff(np.append(starts, key.size)).astype(np.float64)
    centre = np.bincount(inv, weights=rel, minlength=m) / n
    s = rel - centre[inv]  # time relative to the window's mean time (conditioning)
    powers = np.stack([np.ones_like(s), s, s * s], axis=1)  # (N, 3)
    gram, rhs = _normal_equations(inv, powers, pts, m)
    t_lo = rel[starts]
    t_hi = rel[np.append(starts[1:], key.size) - 1]
    span_needed = 0.5 * window if min_span is None else float(min_span)
    # Three distinct instants at least (0.05 s apart): points from two frames only fit a
    # line exactly, and their quadratic term is unbounded.
    lead = t_min - instant_origin if math.isfinite(t_min - instant_origin) else -1.0
    tick = np.floor((rel + lead) / 0.05) if 0.0 <= lead < 1e6 else np.floor(rel / 0.05)
    tick = tick.astype(np.int64)
    # Distinct instants per window: the ticks are non-decreasing within a window.
    new_instant = first.copy()
    new_instant[1:] |= tick[1:] != tick[:-1]
    n_instants = np.bincount(inv[new_instant], minlength=m)
    ok = (n >= RESIDUAL_MIN_POINTS) & (t_hi - t_lo >= span_needed) & (n_instants >= 3)
    if not ok.any():
        return empty
    gram[~ok] = np.eye(3)
    rhs[~ok] = 0.0
    # Tiny ridge: windows whose points share few distinct times are near-singular.
    coef = np.linalg.solve(gram + 1e-9 * np.eye(3), rhs)  # (m, 3 powers, 3 axes)
    fitted = np.einsum("np,npa->na", powers, coef[inv])
    sq = np.einsum("na,na->n", pts - fitted, pts - fitted)
    # One stray return metres away (noise the clusterer joined to the track) would
    # dominate the RMS of a window of a hundred returns: points farther from the fit
    # than RESIDUAL_OUTLIER_FACTOR times the window's median distance are left out.
    median = group_median(inv, np.sqrt(sq), m)
    limit = RESIDUAL_OUTLIER_FACTOR * np.maximum(median, RESIDUAL_MEDIAN_FLOOR)
    keep = sq <= limit[inv] ** 2
    n_keep = np.bincount(inv[keep], minlength=m).astype(np.float64)
    if acceleration:
        # The acceleration is refitted without them (deviation 52): a few noise returns
        # metres off a drone's path bend a window's quadratic as much as a turn does. A
        # window left with too few points keeps its first fit.
        refit = ok & (n_keep < n) & (n_keep >= RESIDUAL_MIN_POINTS)
        if refit.any():
            again = np.flatnonzero(refit[inv] & keep)  # kept points of those windows only
            gram, rhs = _normal_equations(inv[again], powers[again], pts[again], m)
            gram[~refit] = np.eye(3)
            rhs[~refit] = 0.0
            coef[refit] = np.linalg.solve(gram + 1e-9 * np.eye(3), rhs)[refit]
        per_window = 2.0 * np.linalg.norm(coef[:, 2, :], axis=1)
    else:
        # Unbiased: the fit spends 3 degrees of freedom per axis.
        per_window = np.sqrt(
            np.bincount(inv[keep], weights=sq[keep], minlength=m) / np.maximum(n_keep - 3.0, 1.0)
        )
    return ((cw_u // n_win) % k)[ok], per_window[ok], n[ok]


def _normal_equations(
    inv: np.ndarray, powers: np.ndarray, pts: np.ndarray, m: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per window (``inv`` 0..m-1): the (m, 3, 3) Gram matrix of the time ``powers`` and
    the (m, 3 powers, 3 axes) right-hand sides of a least-squares quadratic fit of
    ``pts`` (zeros for a window without points)."""
    gram = np.empty((m, 3, 3))
    rhs = np.empty((m, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            gram[:, i, j] = gram[:, j, i] = np.bincount(
                inv, weights=powers[:, i] * powers[:, j], minlength=m
            )
        for a in range(3):
            rhs[:, i, a] = np.bincount(inv, weights=powers[:, i] * pts[:, a], minlength=m)
    return gram, rhs


def group_median(groups: np.ndarray, values: np.ndarray, k: int) -> np.ndarray:
    """(K,) median of ``values`` per group id 0..K-1 (0 for empty groups)."""
    return group_quantile(groups, values, k, 0.5)


def group_quantile(groups: np.ndarray, values: np.ndarray, k: int, q: float) -> np.ndarray:
    """(K,) ``q`` quantile (linear interpolation) of ``values`` per group id 0..K-1 (0 for
    empty groups)."""
    return group_quantiles(groups, values, k, (q,))[0]


def _sorted_groups(
    minor: np.ndarray, groups: np.ndarray, k: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The order that sorts by group id, then by ``minor``; the sorted ids; each group's
    member count and its first position in that order."""
    order = lex_order(minor, groups)
    g = groups[order]
    counts = np.bincount(g, minlength=k)
    return order, g, counts, np.concatenate([[0], np.cumsum(counts)[:-1]])


#: Returns (nearest in time, each return among them) whose median position
#: :func:`local_scatter` measures a return's distance from.
SCATTER_NEIGHBOURS = 7


def local_scatter(
    groups: np.ndarray, xyz: np.ndarray, t: np.ndarray, k: int, neighbours: int = SCATTER_NEIGHBOURS
) -> np.ndarray:
    """(K,) per group 0..k-1: the median distance of its returns from the per-axis median
    of the ``neighbours`` returns nearest in time (the window centred on each return,
    shifted inward at the group's ends; a group with fewer returns uses them all).

    Where an object is at a moment is what its neighbours in time agree on, so a drone
    that drifts or brakes scatters only over its body, while returns spread over a
    still object (a far tree crown seen a return at a time) scatter over all of it.
    Groups without members get 0.
    """
    out = np.zeros(k)
    groups = np.asarray(groups, dtype=np.int64)
    if groups.size == 0:
        return out
    order, g, counts, start = _sorted_groups(t, groups, k)
    p = np.asarray(xyz, dtype=np.float64)[order]
    width = np.minimum(counts, int(neighbours))[g]
    first, n = start[g], counts[g]
    pos = np.arange(g.size)
    lo = np.clip(pos - width // 2, first, first + n - width)
    # Windows of one width at a time (at most `neighbours` widths), no loop over points.
    dist = np.empty(g.size)
    for w in np.unique(width):
        rows = np.flatnonzero(width == w)
        window = p[lo[rows, None] + np.arange(w)]
        dist[rows] = np.linalg.norm(p[rows] - np.median(window, axis=1), axis=1)
    return group_quantile(g, dist, k, 0.5)


def group_quantiles(
    groups: np.ndarray, values: np.ndarray, k: int, qs: tuple[float, ...]
) -> np.ndarray:
    """(len(qs), K) quantiles of ``values`` per group id, from one sort (see
    :func:`group_quantile`)."""
    out = np.zeros((len(qs), k))
    if groups.size == 0:
        return out
    order, g, counts, start = _sorted_groups(values, groups, k)
    v = np.asarray(values, dtype=np.float64)[order]
    has = counts > 0
    last = start[has] + counts[has] - 1
    for row, q in zip(out, qs, strict=True):
        pos = start[has] + q * (counts[has] - 1)
        lo = np.floor(pos).astype(np.int64)
        hi = np.minimum(lo + 1, last)
        frac = pos - lo
        row[has] = v[lo] * (1.0 - frac) + v[hi] * frac
    return out


#: Window lengths (multiples of ``residual_window``) tried in turn for sparse clusters.
RESIDUAL_SCALES = (1, 2, 4)


def multiscale_residual(
    lab: np.ndarray,
    pts: np.ndarray,
    t: np.ndarray,
    k: int,
    window: float,
    t0: float,
    acceleration: bool = False,
    phases: int = 1,
) -> np.ndarray:
    """:func:`track_residual` at ``window``; clusters too sparse for any window there are
    measured with windows 2x and then 4x as long (a sparse track's few returns per
    window say nothing alone; a quadratic over a longer span still bounds its wander);
    the points of a window must span half the base ``window`` at every scale.
    0 for clusters without evidence at any scale. ``acceleration``: see
    :func:`track_residual`."""
    out = np.zeros(k)
    todo = np.ones(k, dtype=bool)
    for scale in RESIDUAL_SCALES:
        sel = todo[lab]
        if not sel.any():
            break
        r, has = track_residual(
            lab[sel],
            pts[sel],
            t[sel],
            k,
            scale * window,
            t0,
            True,
            acceleration,
            0.5 * window,
            phases,
        )
        take = todo & has
        out[take] = r[take]
        todo &= ~has
    return out


def select_clusters(scores: ClusterScores, params: ParamSet) -> list[int]:
    """Clusters reported as the drone, best first.

    The best-ranked candidate (gates passed, confidence >= ``min_confidence``) is taken;
    with 'normalized' scoring, further qualifying candidates whose time spans do not
    overlap the ones already taken follow (a track broken into pieces). The paper's
    mode keeps its single best cluster.
    """
    ok = scores.candidate & (scores.confidence >= params.min_confidence)
    if not ok.any():
        return []
    rank = scores.rank_score(params.scoring)
    order = [int(i) for i in np.argsort(-rank, kind="stable") if ok[i]]
    if params.scoring == "paper":
        return order[:1]
    chosen: list[int] = []
    for i in order:
        if all(
            scores.t_last[i] < scores.t_first[j] or scores.t_first[i] > scores.t_last[j]
            for j in chosen
        ):
            chosen.append(i)
    return chosen
