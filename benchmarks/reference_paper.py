"""A straightforward reference implementation of the cluster-filter paper (the baseline).

This is what a first, literal reading of the paper's sections 3.1-3.4 gives, written with
scikit-learn DBSCAN on *all* accumulated points, the way the authors' offline code works.
It lives in ``benchmarks/`` only: the benchmarks run it on the same simulated sequences
as the product, in the same process, to report a speed ratio and an accuracy comparison.
It is deliberately plain numpy (no tricks), but not deliberately slow.

Pipeline (defaults are the authors' published ones, see REFERENCE section 1):

1. Avia denoise (3.1): superimpose every Avia point of the sequence and run
   ``DBSCAN(eps=2.0, min_samples=10)``; points labelled noise are dropped.
2. Mid360 ground cut: keep points with ``z > 3.5`` m.
3. Global clusterer (3.2): ``DBSCAN(eps=2.0, min_samples=10)`` on every remaining point
   of both lidars over the whole sequence. scikit-learn's DBSCAN materialises every
   point's eps-neighbourhood, so its memory grows with points x neighbours: on a
   simulated 20 s sequence (~300k points above 3.5 m, ~20,000 neighbours within 2 m on
   average) that is ~6e9 indices, ~48 GB, more than the machine has. The reference
   therefore estimates the neighbourhood size first (KD-tree counts on a sample) and,
   when exact DBSCAN would need more than ``max_dbscan_gb``, runs the same DBSCAN on
   ``fallback_voxel`` (0.15 m) voxel centroids weighted by their point counts
   (``sample_weight``; REFERENCE section 5), every point taking its voxel's label. The
   fallback is *faster* than the literal method, so speed ratios against it are lower
   bounds. ``ReferenceResult.dbscan_mode`` says which one ran.
4. Candidate gates: a global cluster is a candidate if it has 100..10,000 points, its
   centroid is at ``z >= 6`` m and its occupied 0.2 m voxels cover at least 0.3 m^3.
5. Local clusterer (3.2): a "frame" is one lidar period (0.1 s) of both lidars; for
   window lengths ``frames`` in (2, 5, 10), the windows starting at every frame take the
   global cluster's points in that time span (no re-clustering). Density = points /
   occupied voxel volume; relative density ``R = rho_local / rho_global``; IoU of the
   occupied 0.2 m voxel sets of consecutive windows.
6. Score (3.3): ``Score = sum exp(R) + lambda * sum log(1/IoU)`` summed over every
   non-empty window (and consecutive non-empty pair) of every window length; IoU is
   clipped to ``[iou_floor, 1]`` so a disjoint pair scores a finite ``log(1/iou_floor)``.
   The best-scoring candidate is the drone.
7. Trajectory (3.4): the selected points, ordered by time, are grouped per frame
   (centroid, weight = point count); a cubic smoothing spline per axis
   (``scipy.interpolate.make_smoothing_spline``, smoothing chosen by generalised
   cross-validation) through them is evaluated at the requested
   stamps inside the time span the points cover and within ``max_gap`` (1 s) of a frame
   with selected points (no estimate elsewhere).

Choices the paper leaves open are written down here: the frame = 0.1 s slot of both
lidars; per-point times (``Frame.point_time``) are used when the frames carry them;
lambda = 1. ``score_mode="sum"`` (default) ranks by the paper's sums; ``"mean"`` by the
same terms averaged over windows. Both rankings come out of one run
(``ReferenceResult.estimates``), since they share everything up to the scores.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import make_smoothing_spline
from sklearn.cluster import DBSCAN

from clusterfilter_ros.core.frame import AVIA, MID360, Frame, TimedPositions


@dataclass(frozen=True)
class ReferenceParams:
    """Parameters of the reference implementation (the authors' defaults)."""

    avia_eps: float = 2.0
    avia_min_samples: int = 10
    mid360_min_z: float = 3.5
    eps: float = 2.0
    min_samples: int = 10
    min_cluster_points: int = 100
    max_cluster_points: int = 10_000
    min_centroid_z: float = 6.0
    min_occupied_volume: float = 0.3
    voxel_size: float = 0.2
    window_lengths: tuple[int, ...] = (2, 5, 10)
    score_lambda: float = 1.0
    iou_floor: float = 1e-3
    frame_period: float = 0.1
    score_mode: str = "sum"
    max_gap: float = 1.0
    target_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    max_dbscan_gb: float = 4.0
    fallback_voxel: float = 0.15


@dataclass
class ReferenceResult:
    """What the reference run produced.

    Attributes:
        estimate: positions at the requested stamps where the spline covers them, for the
            cluster ranked best by ``params.score_mode``.
        drone_xyz: (K, 3) points of the selected cluster.
        drone_time: (K,) times of those points (s).
        n_points_clustered: size of the global cloud given to DBSCAN.
        n_candidates: global clusters that passed the gates.
        dbscan_mode: ``exact`` (DBSCAN on every point) or ``voxel-weighted`` (fallback).
        estimates: the estimate for each score mode (``sum``, ``mean``).
        scores: score of each candidate (same order as the candidates).
        timings: wall seconds per stage.
    """

    estimate: TimedPositions
    drone_xyz: np.ndarray
    drone_time: np.ndarray
    n_points_clustered: int
    n_candidates: int
    scores: list[float] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    dbscan_mode: str = "exact"
    estimates: dict[str, TimedPositions] = field(default_factory=dict)


def _frame_points(frames: list[Frame]) -> tuple[np.ndarray, np.ndarray]:
    """Stack frames into (N,3) xyz and (N,) absolute point times."""
    if not frames:
        return np.empty((0, 3), np.float64), np.empty(0, np.float64)
    xyz = np.concatenate([f.xyz for f in frames]).astype(np.float64)
    times = np.concatenate(
        [f.stamp + (f.point_time if f.point_time is not None else np.zeros(len(f))) for f in frames]
    )
    return xyz, times


def _point_voxel_keys(xyz: np.ndarray, voxel_size: float) -> np.ndarray:
    """One int64 key per point: its voxel's integer indices packed into 21 bits each."""
    ijk = np.floor(xyz / voxel_size).astype(np.int64) + (1 << 20)
    return (ijk[:, 0] << 42) | (ijk[:, 1] << 21) | ijk[:, 2]


def _voxel_keys(xyz: np.ndarray, voxel_size: float) -> np.ndarray:
    """Unique occupied voxel keys (one int64 per voxel) of a point set."""
    return np.unique(_point_voxel_keys(xyz, voxel_size))


def estimated_dbscan_gb(xyz: np.ndarray, eps: float, sample: int = 1000) -> float:
    """Memory (GB) scikit-learn DBSCAN would need for the neighbourhoods of ``xyz``.

    Counts neighbours within ``eps`` of a random sample of points with a KD-tree and
    scales to all points (8 bytes per neighbour index, plus 50% for the arrays around).
    """
    from sklearn.neighbors import KDTree

    if len(xyz) <= sample:
        return 0.0
    rng = np.random.default_rng(0)
    tree = KDTree(xyz)
    counts = tree.query_radius(
        xyz[rng.choice(len(xyz), sample, replace=False)], eps, count_only=True
    )
    return float(counts.mean()) * len(xyz) * 8 * 1.5 / 2**30


def dbscan_labels(
    xyz: np.ndarray, eps: float, min_samples: int, params: ReferenceParams
) -> tuple[np.ndarray, str, float]:
    """DBSCAN labels of every point (-1 noise), the mode used (see module docstring) and
    the seconds spent on the memory check (not part of the method: callers that time the
    reference subtract it)."""
    import time

    if len(xyz) == 0:
        return np.empty(0, np.int64), "exact", 0.0
    tic = time.perf_counter()
    need_gb = estimated_dbscan_gb(xyz, eps)
    check_s = time.perf_counter() - tic
    if need_gb <= params.max_dbscan_gb:
        return DBSCAN(eps=eps, min_samples=min_samples).fit_predict(xyz), "exact", check_s
    keys = _point_voxel_keys(xyz, params.fallback_voxel)
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    centroids = np.zeros((len(counts), 3))
    np.add.at(centroids, inverse, xyz)
    centroids /= counts[:, None]
    labels = DBSCAN(eps=eps, min_samples=min_samples).fit_predict(centroids, sample_weight=counts)
    return labels[inverse], "voxel-weighted", check_s


def denoise_avia(xyz: np.ndarray, params: ReferenceParams) -> np.ndarray:
    """Boolean mask of superimposed Avia points that DBSCAN does not call noise."""
    if len(xyz) == 0:
        return np.zeros(0, dtype=bool)
    labels, _mode, _check = dbscan_labels(xyz, params.avia_eps, params.avia_min_samples, params)
    return labels >= 0


def score_cluster(
    xyz: np.ndarray, frame_index: np.ndarray, n_frames: int, params: ReferenceParams
) -> tuple[float, float]:
    """Score of one global cluster: the paper's sums, and the same terms averaged.

    Returns ``(sum exp(R) + lambda * sum log(1/IoU), mean exp(R) + lambda * mean
    log(1/IoU))`` over the non-empty windows (and consecutive non-empty pairs) of every
    window length. The sums are the paper's formula; the means are the one change that
    stops long-lived background clusters from winning just by being present in more
    windows.
    """
    voxel_volume = params.voxel_size**3
    global_density = len(xyz) / (len(_voxel_keys(xyz, params.voxel_size)) * voxel_volume)
    order = np.argsort(frame_index, kind="stable")
    xyz, frame_index = xyz[order], frame_index[order]
    score_density = 0.0
    score_iou = 0.0
    n_windows = 0
    n_pairs = 0
    for length in params.window_lengths:
        previous_keys: np.ndarray | None = None
        for start in range(0, max(n_frames - length, 0) + 1):
            lo, hi = np.searchsorted(frame_index, [start, start + length])
            if hi <= lo:
                previous_keys = None
                continue
            keys = _voxel_keys(xyz[lo:hi], params.voxel_size)
            local_density = (hi - lo) / (len(keys) * voxel_volume)
            score_density += float(np.exp(local_density / global_density))
            n_windows += 1
            if previous_keys is not None:
                inter = len(np.intersect1d(previous_keys, keys, assume_unique=True))
                union = len(previous_keys) + len(keys) - inter
                iou = min(max(inter / union, params.iou_floor), 1.0)
                score_iou += float(np.log(1.0 / iou))
                n_pairs += 1
            previous_keys = keys
    total = score_density + params.score_lambda * score_iou
    mean = score_density / max(n_windows, 1) + params.score_lambda * score_iou / max(n_pairs, 1)
    return total, mean


def fit_trajectory(
    xyz: np.ndarray,
    times: np.ndarray,
    frame_index: np.ndarray,
    stamps: np.ndarray,
    params: ReferenceParams,
) -> TimedPositions:
    """Cubic smoothing B-spline through per-frame centroids, evaluated at ``stamps``."""
    stamps = np.asarray(stamps, dtype=np.float64)
    empty = TimedPositions(np.empty(0), np.empty((0, 3)))
    if len(xyz) == 0 or len(stamps) == 0:
        return empty
    uniq, inverse, counts = np.unique(frame_index, return_inverse=True, return_counts=True)
    centroid = np.zeros((len(uniq), 3))
    np.add.at(centroid, inverse, xyz)
    centroid /= counts[:, None]
    t = np.bincount(inverse, weights=times) / counts
    order = np.argsort(t)
    t, centroid, counts = t[order], centroid[order], counts[order]
    # Inside the span of the points and within max_gap of a frame that has points.
    nearest = np.clip(np.searchsorted(t, stamps), 1, len(t) - 1) if len(t) > 1 else None
    if nearest is None:
        near = np.abs(stamps - t[0]) <= params.max_gap
    else:
        gap = np.minimum(np.abs(stamps - t[nearest - 1]), np.abs(stamps - t[nearest]))
        near = gap <= params.max_gap
    inside = (stamps >= t[0]) & (stamps <= t[-1]) & near
    if not inside.any():
        return empty
    query = stamps[inside]
    if len(t) < 5:
        out = np.stack([np.interp(query, t, centroid[:, a]) for a in range(3)], axis=1)
    else:
        out = np.stack(
            [make_smoothing_spline(t, centroid[:, a], w=counts)(query) for a in range(3)],
            axis=1,
        )
    return TimedPositions(query, out + np.asarray(params.target_offset, dtype=np.float64))


def reference_detect(
    frames: list[Frame],
    stamps: np.ndarray | None = None,
    params: ReferenceParams | None = None,
) -> ReferenceResult:
    """Run the reference pipeline on a whole sequence.

    ``stamps`` are the times to estimate at (default: every frame stamp). Returns the
    estimates, the selected drone points and per-stage timings.
    """
    import time

    params = params or ReferenceParams()
    timings: dict[str, float] = {}
    frames = sorted(frames, key=lambda f: f.stamp)
    if stamps is None:
        stamps = np.unique([f.stamp for f in frames])
    empty = ReferenceResult(
        TimedPositions(np.empty(0), np.empty((0, 3))), np.empty((0, 3)), np.empty(0), 0, 0
    )
    if not frames:
        return empty
    t0 = frames[0].stamp

    tic = time.perf_counter()
    avia_xyz, avia_t = _frame_points([f for f in frames if f.sensor == AVIA])
    keep = denoise_avia(avia_xyz, params)
    avia_xyz, avia_t = avia_xyz[keep], avia_t[keep]
    timings["avia_denoise"] = time.perf_counter() - tic

    tic = time.perf_counter()
    mid_xyz, mid_t = _frame_points([f for f in frames if f.sensor == MID360])
    above = mid_xyz[:, 2] > params.mid360_min_z
    mid_xyz, mid_t = mid_xyz[above], mid_t[above]
    other = [f for f in frames if f.sensor not in (AVIA, MID360)]
    other_xyz, other_t = _frame_points(other)
    xyz = np.concatenate([avia_xyz, mid_xyz, other_xyz])
    times = np.concatenate([avia_t, mid_t, other_t])
    frame_stamp_index = np.floor((times - t0) / params.frame_period).astype(np.int64)
    frame_stamp_index = np.maximum(frame_stamp_index, 0)
    n_frames = int(frame_stamp_index.max()) + 1 if len(times) else 0
    timings["merge"] = time.perf_counter() - tic

    tic = time.perf_counter()
    if len(xyz) == 0:
        return empty
    labels, mode, check_s = dbscan_labels(xyz, params.eps, params.min_samples, params)
    timings["memory_check"] = check_s
    timings["global_dbscan"] = time.perf_counter() - tic - check_s

    tic = time.perf_counter()
    order = np.argsort(labels, kind="stable")
    sorted_labels = labels[order]
    cluster_ids, starts, sizes = np.unique(sorted_labels, return_index=True, return_counts=True)
    candidates: list[np.ndarray] = []
    min_voxels = params.min_occupied_volume / params.voxel_size**3
    for cid, start, size in zip(cluster_ids, starts, sizes, strict=True):
        if cid < 0 or not params.min_cluster_points <= size <= params.max_cluster_points:
            continue
        members = order[start : start + size]
        if xyz[members, 2].mean() < params.min_centroid_z:
            continue
        if len(_voxel_keys(xyz[members], params.voxel_size)) < min_voxels - 1e-9:
            continue
        candidates.append(members)
    timings["gates"] = time.perf_counter() - tic

    tic = time.perf_counter()
    both = [score_cluster(xyz[m], frame_stamp_index[m], n_frames, params) for m in candidates]
    timings["local_scoring"] = time.perf_counter() - tic

    tic = time.perf_counter()
    empty_estimate = TimedPositions(np.empty(0), np.empty((0, 3)))
    if not candidates:
        timings["spline"] = 0.0
        return ReferenceResult(
            empty_estimate,
            np.empty((0, 3)),
            np.empty(0),
            len(xyz),
            0,
            [],
            timings,
            mode,
            {"sum": empty_estimate, "mean": empty_estimate},
        )
    estimates: dict[str, TimedPositions] = {}
    chosen: dict[str, np.ndarray] = {}
    for column, name in enumerate(("sum", "mean")):
        best = candidates[int(np.argmax([b[column] for b in both]))]
        chosen[name] = best
        estimates[name] = fit_trajectory(
            xyz[best], times[best], frame_stamp_index[best], np.asarray(stamps), params
        )
    timings["spline"] = time.perf_counter() - tic
    best = chosen[params.score_mode]
    scores = [b[0 if params.score_mode == "sum" else 1] for b in both]
    return ReferenceResult(
        estimates[params.score_mode],
        xyz[best],
        times[best],
        len(xyz),
        len(candidates),
        scores,
        timings,
        mode,
        estimates,
    )


__all__ = ["ReferenceParams", "ReferenceResult", "reference_detect", "score_cluster"]
