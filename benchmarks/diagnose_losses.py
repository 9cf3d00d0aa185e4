"""Where the offline detector loses the drone, stage by stage, on simulated runs.

The simulator labels every drone return, so each stage of :func:`detect_offline` can be
replayed with that label carried along: usable points, denoise, static suppression,
clustering, candidate gates, selection. For every ground-truth sample at which the
drone was observable (a return within +-0.5 s) and no estimate lay within 2 m, the
first stage that left no drone point within +-0.5 s (or the reason the drone's cluster
was not reported) is counted. The replay is simplified (no splitting, and its growth
takes no returns the filters removed, as ``extend_denoised`` / ``extend_below_floor``
let :func:`detect_offline` do): its stage counts are approximate, the hits are
:func:`detect_offline`'s own, so a "denoise" or "filtered" miss is one that growth did
not recover either.

    .venv/bin/python benchmarks/diagnose_losses.py --scenarios flyover --seeds 0 1 2

Prints, per run, the drone points surviving each stage and the miss reasons; with
``--clusters`` also the features of every cluster holding drone points.

``--mode stream`` pushes the frames through a :class:`StreamingDetector` instead and
records, at every re-clustering, the cluster holding most of the history's points of the
last ``track_window`` within 1.5 m of the drone's true position (the streaming history
carries no labels). A missed sample is
put down to the state at the last frame before it: no cluster scored yet, no drone
return in the history, the returns left as noise, a failed gate, too low a confidence
(with the factors below their thresholds), or a confirmed track that reported nothing
or reported something else. A selected track whose newest sample is too old to report
from (older than ``max_gap`` and ``max_extrapolation``) counts as no track: its cluster
can stay in the history, and selected, for seconds after the drone has moved on.

    .venv/bin/python benchmarks/diagnose_losses.py --mode stream --seeds 0 1 2 3 4 5 \
        --scenarios default takeoff_landing flyover fast_pass hover avia_only

``--phase`` (stream) prefixes each cause with "[acquiring]" (before the run's first hit:
the drone not yet reported) or "[after the first hit]" (a reported drone lost, or a new
appearance of it to acquire again).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from clusterfilter_ros.core import streaming
from clusterfilter_ros.core.background import static_offline
from clusterfilter_ros.core.clustering import density_mask
from clusterfilter_ros.core.evaluation import interpolate_predictions, observable_mask
from clusterfilter_ros.core.frame import TimedPositions
from clusterfilter_ros.core.offline import detect_offline, extend_selected, global_clusters
from clusterfilter_ros.core.params import parse_assignments
from clusterfilter_ros.core.preprocess import frame_points, usable_mask
from clusterfilter_ros.core.scoring import score_clusters, select_clusters
from clusterfilter_ros.sim.raycast import CLASS_NAMES

sys.path.insert(0, str(Path(__file__).resolve().parent))
from detector_accuracy import SIM_CACHE, drone_hit_stamps, load_sim, sim_params  # noqa: E402

#: Confidence factors reported for an unselected drone cluster (see scoring.py).
FEATURES = (
    "n_points",
    "support_frames",
    "extent",
    "local_extent",
    "coherence",
    "apparent_speed",
    "residual",
    "excess_residual",
    "acceleration",
    "normalized_score",
    "confidence",
)


def trace(sim, params):
    """Replay the offline stages with drone labels; returns a dict of per-point arrays."""
    xyzs, ts, drones, noisy, classes = [], [], [], [], []
    raw = 0
    denoise = set(params.denoise_sensors)
    for i, frame in enumerate(sim.sequence.frames):
        label = np.asarray(sim.labels[i], dtype=bool)
        raw += int(label.sum())
        keep = usable_mask(frame, params)
        xyz, t = frame_points(frame, params)
        xyzs.append(xyz)
        ts.append(t)
        drones.append(label[keep])
        classes.append(np.asarray(sim.classes[i])[keep])
        noisy.append(np.full(t.size, frame.sensor in denoise))
    xyz, t = np.concatenate(xyzs), np.concatenate(ts)
    drone, noisy = np.concatenate(drones), np.concatenate(noisy)
    cls = np.concatenate(classes)
    stages = {"raw": raw, "usable": int(drone.sum())}
    keep = np.ones(t.size, bool)
    if noisy.any():
        keep[noisy] = density_mask(xyz[noisy], params.denoise_voxel, params.denoise_min_points)
    after_denoise = keep.copy()
    stages["denoise"] = int((drone & keep).sum())
    structure = None
    if params.static_suppression:
        idx = np.nonzero(keep)[0]
        static, structure = static_offline(xyz[idx], t[idx], params)
        keep[idx[static]] = False
    stages["static"] = int((drone & keep).sum())
    kx, kt, kd, kc = xyz[keep], t[keep], drone[keep], cls[keep]
    labels, k = global_clusters(kx, kt, params)
    stages["clustered"] = int((kd & (labels >= 0)).sum())
    scores = score_clusters(labels, kx, kt, params, n_clusters=k, structure_keys=structure)
    selected = select_clusters(scores, params)
    cand = scores.candidate
    stages["candidate"] = int((kd & (labels >= 0) & cand[np.maximum(labels, 0)]).sum())
    if params.link_max_gap > 0:
        labels = extend_selected(labels, kx, kt, scores, selected, params)
    stages["selected"] = int((kd & np.isin(labels, selected)).sum())
    return {
        "stages": stages,
        "t_all": t,
        "drone_all": drone,
        "after_denoise": after_denoise,
        "kept": keep,
        "xyz": kx,
        "t": kt,
        "drone": kd,
        "classes": kc,
        "labels": labels,
        "scores": scores,
        "selected": selected,
    }


def gate_failures(scores, c: int, params) -> list[str]:
    out = []
    if scores.n_points[c] < params.min_cluster_points:
        out.append("min_cluster_points")
    if scores.n_points[c] > params.max_cluster_points:
        out.append("max_cluster_points")
    if scores.centroid[c, 2] < params.min_centroid_z:
        out.append("min_centroid_z")
    if scores.extent[c] > params.max_extent:
        out.append("max_extent")
    if params.scoring != "paper" and scores.local_extent[c] > params.max_local_extent:
        out.append("max_local_extent")
    return out


def hit_mask(gt, est_stamps: np.ndarray, est_xyz: np.ndarray) -> np.ndarray:
    """(G,) bool: the evaluator's rule (``clusterfilter evaluate``): the estimate
    interpolated between the two nearest rows, both within 0.3 s, is within 2 m."""
    order = np.argsort(est_stamps, kind="stable")
    pred = TimedPositions(
        np.asarray(est_stamps, dtype=np.float64)[order],
        np.asarray(est_xyz, dtype=np.float64).reshape(-1, 3)[order],
    )
    at = interpolate_predictions(pred, gt.stamps, 0.3)
    with np.errstate(invalid="ignore"):
        return np.linalg.norm(at - gt.xyz, axis=1) <= 2.0


def miss_reasons(sim, tr, result, params) -> Counter:
    gt = sim.sequence.ground_truth
    reasons: Counter = Counter()
    if gt is None or len(gt) == 0:
        return reasons
    obs = observable_mask(gt.stamps, drone_hit_stamps(sim), window=1.0)
    est = result.estimates
    hit = hit_mask(gt, est.stamps, est.xyz)
    for g in np.nonzero(obs & ~hit)[0]:
        s = gt.stamps[g]
        near_all = np.abs(tr["t_all"] - s) <= 0.5
        d_all = tr["drone_all"] & near_all
        if not d_all.any():
            reasons["filtered (usable)"] += 1
            continue
        if not (d_all & tr["after_denoise"]).any():
            reasons["denoise"] += 1
            continue
        if not (d_all & tr["kept"]).any():
            reasons["static suppression"] += 1
            continue
        near = tr["drone"] & (np.abs(tr["t"] - s) <= 0.5)
        lab = tr["labels"][near]
        if (lab < 0).all():
            reasons["clustering noise"] += 1
            continue
        c = int(np.bincount(lab[lab >= 0]).argmax())
        sc = tr["scores"]
        if c not in tr["selected"]:
            gates = gate_failures(sc, c, params)
            if gates:
                reasons["gate " + "+".join(gates)] += 1
            elif sc.confidence[c] < params.min_confidence:
                reasons["low confidence"] += 1
            else:
                reasons["time overlap with a better cluster"] += 1
            continue
        if len(est) and (np.abs(est.stamps - s) <= 0.3).any():
            reasons["estimate > 2 m off"] += 1
        else:
            reasons["selected, no estimate (gap/support)"] += 1
    reasons["_observable"] = int(obs.sum())
    reasons["_hit"] = int((obs & hit).sum())
    return reasons


def low_confidence_factors(scores, c: int, params) -> str:
    """The confidence factors of cluster ``c`` below their full-credit thresholds."""
    below = {
        "coherence": scores.coherence[c] < params.min_coherence,
        "speed": scores.apparent_speed[c] < params.min_speed,
        "support": scores.support_frames[c] < params.min_support_frames,
        "excess residual": scores.excess_residual[c] > params.smooth_excess,
        "acceleration": scores.acceleration[c] > params.smooth_accel,
    }
    return ",".join(k for k, v in below.items() if v) or "density/IoU"


@contextlib.contextmanager
def _recording_scores(record):
    """Make each streaming re-clustering call ``record(labels, xyz, t, params, scores)``
    once, with the labels and scores it selects from: those of the first scoring call,
    or, when merged clusters were split, the split's (its pieces are scored on their
    own, and the hysteresis re-scores with other parameters; neither is recorded)."""
    original_score = streaming.score_clusters
    original_split = streaming.split_and_score

    def scored(labels, xyz, t, params, **kwargs):
        scores = original_score(labels, xyz, t, params, **kwargs)
        record(labels, xyz, t, params, scores)
        return scores

    def split(labels, xyz, t, scores, params, *args, **kwargs):
        out = original_split(labels, xyz, t, scores, params, *args, **kwargs)
        if out[3].any():
            record(out[0], xyz, t, params, out[2], replace=True)
        return out

    streaming.score_clusters = scored
    streaming.split_and_score = split
    try:
        yield
    finally:
        streaming.score_clusters = original_score
        streaming.split_and_score = original_split


def stream_miss_reasons(sim, params, phase: bool = False) -> Counter:
    """Streaming: the cause of every observable ground-truth sample without a hit; with
    ``phase``, each cause prefixed by whether the sample came before the run's first hit
    ("acquiring": the drone not yet reported) or after it ("after the first hit": a
    reported drone lost, or a new appearance of it)."""
    gt = sim.sequence.ground_truth
    reasons: Counter = Counter()
    if gt is None or len(gt) == 0:
        return reasons
    truth = sim.drone_truth
    offset = np.asarray(params.target_offset, dtype=np.float64)

    def true_position(t: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(t, truth.stamps, truth.xyz[:, a]) for a in range(3)], 1)

    detector = streaming.StreamingDetector(params)
    log: list[tuple[float, str]] = []

    def record(labels, xyz, t, p, scores, replace: bool = False) -> None:
        again = bool(log) and log[-1][0] == detector._now
        if again and not replace:
            return
        recent = t >= detector._now - p.track_window
        near = recent & (np.linalg.norm(xyz - true_position(t), axis=1) < 1.5)
        lab = labels[near & (labels >= 0)]
        if not near.any():
            cause = "no recent drone return in the history (filtered or suppressed)"
        elif lab.size == 0:
            cause = "the drone's returns left as noise"
        else:
            c = int(np.bincount(lab).argmax())
            gates = gate_failures(scores, c, p)
            if gates:
                cause = "gate " + "+".join(gates)
            elif scores.confidence[c] < p.min_confidence:
                cause = "low confidence: " + low_confidence_factors(scores, c, p)
            else:
                cause = "a confident drone cluster, another one tracked"
        if again:
            log[-1] = (detector._now, cause)
        else:
            log.append((detector._now, cause))

    limit = max(params.max_extrapolation, params.max_gap)
    frames = sim.sequence.frames
    stamps, states, est_t, est_xyz = [], [], [], []
    with _recording_scores(record):
        for frame in frames:
            est = detector.push(frame)
            stamps.append(frame.stamp)
            if est is not None:
                est_t.append(est.stamp)
                est_xyz.append(est.position - offset)
                states.append("reported")
            elif detector._track and detector._selected_conf >= params.min_confidence:
                pred = detector._predict(frame.stamp)
                if pred is None:
                    states.append("a confirmed track without a sample yet")
                else:
                    on = np.linalg.norm(pred[0] - true_position(np.array([frame.stamp]))[0]) < 2
                    where = "on the drone" if on else "off the drone"
                    if pred[2] <= limit:
                        states.append(
                            f"a confirmed track not reported: newest sample <= {limit:g} s"
                            f" old, {where}"
                        )
                    else:
                        # Too old to report from ever again: the drone's cluster is what
                        # decides whether it is found.
                        states.append("")
            else:
                states.append("")
    hit = hit_mask(gt, np.asarray(est_t), np.asarray(est_xyz, dtype=np.float64))
    obs = observable_mask(gt.stamps, drone_hit_stamps(sim), window=1.0)
    stamps = np.asarray(stamps)
    log_t = np.array([t for t, _ in log])
    hits = gt.stamps[obs & hit]
    first_hit = float(hits.min()) if hits.size else np.inf
    for g in np.nonzero(obs & ~hit)[0]:
        s = gt.stamps[g]
        i = int(np.searchsorted(stamps, s, side="right")) - 1
        state = states[i] if i >= 0 else ""
        if state == "reported":
            cause = "another object reported, or the estimate > 2 m off"
        elif state:
            cause = state
        else:
            k = int(np.searchsorted(log_t, s, side="right")) - 1
            cause = log[k][1] if k >= 0 else "before any cluster was scored (run start)"
        if phase:
            cause = ("[acquiring] " if s < first_hit else "[after the first hit] ") + cause
        reasons[cause] += 1
    reasons["_observable"] = int(obs.sum())
    reasons["_hit"] = int((obs & hit).sum())
    return reasons


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="+", default=["default", "flyover", "hover"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--cache", type=Path, default=SIM_CACHE)
    ap.add_argument("--clusters", action="store_true", help="print drone clusters' features")
    ap.add_argument("--duration", type=float, help="simulate this many seconds (default: all)")
    ap.add_argument("--mode", choices=("offline", "stream"), default="offline")
    ap.add_argument(
        "--phase",
        action="store_true",
        help="stream: split the misses into those before the run's first hit and after",
    )
    args = ap.parse_args(argv)
    values = parse_assignments(args.param)
    total: Counter = Counter()
    for scenario in args.scenarios:
        for seed in args.seeds:
            sim = load_sim(scenario, seed, args.cache, args.duration)
            params = sim_params(sim, values)
            if args.mode == "stream":
                reasons = stream_miss_reasons(sim, params, args.phase)
                total.update(reasons)
                obs, hit = reasons.pop("_observable", 0), reasons.pop("_hit", 0)
                print(f"{scenario} s{seed} (stream): observable GT {obs}, hit {hit}")
                for k, v in reasons.most_common():
                    print(f"    {v:5d} {k}")
                continue
            tr = trace(sim, params)
            result = detect_offline(sim.sequence.frames, params)
            reasons = miss_reasons(sim, tr, result, params)
            total.update(reasons)
            st = " ".join(f"{k}={v}" for k, v in tr["stages"].items())
            print(f"{scenario} s{seed}: drone points {st}")
            obs, hit = reasons.pop("_observable", 0), reasons.pop("_hit", 0)
            print(f"  observable GT {obs}, hit {hit}; misses: {dict(reasons.most_common())}")
            if args.clusters:
                sc, lab, kd = tr["scores"], tr["labels"], tr["drone"]
                shown = np.union1d(lab[kd & (lab >= 0)], np.asarray(tr["selected"], int))
                for c in shown:
                    nd = int((kd & (lab == c)).sum())
                    feats = " ".join(f"{f}={getattr(sc, f)[c]:.2f}" for f in FEATURES)
                    t0, t1 = sc.t_first[c], sc.t_last[c]
                    cc = np.bincount(tr["classes"][lab == c].astype(np.int64), minlength=8)
                    feats += " classes=" + ",".join(
                        f"{CLASS_NAMES.get(i, i)}:{n}" for i, n in enumerate(cc) if n
                    )
                    print(
                        f"  cluster {c} drone {nd}/{int(sc.n_points[c])} t=[{t0:.1f},{t1:.1f}]"
                        f" sel={c in tr['selected']} gates={gate_failures(sc, c, params)} {feats}"
                    )
    obs, hit = total.pop("_observable", 0), total.pop("_hit", 0)
    print(f"TOTAL observable {obs}, hit {hit} ({hit / max(obs, 1):.1%}); misses:")
    for k, v in total.most_common():
        print(f"  {v:6d} {v / max(obs, 1):6.1%} {k}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
