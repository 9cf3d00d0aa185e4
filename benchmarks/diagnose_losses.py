"""Where the offline detector loses the drone, stage by stage, on simulated runs.

The simulator labels every drone return, so each stage of :func:`detect_offline` can be
replayed with that label carried along: usable points, denoise, static suppression,
clustering, candidate gates, selection. For every ground-truth sample at which the
drone was observable (a return within +-0.5 s) and no estimate lay within 2 m, the
first stage that left no drone point within +-0.5 s (or the reason the drone's cluster
was not reported) is counted.

    .venv/bin/python benchmarks/diagnose_losses.py --scenarios flyover --seeds 0 1 2

Prints, per run, the drone points surviving each stage and the miss reasons; with
``--clusters`` also the features of every cluster holding drone points.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from clusterfilter_ros.core.background import static_mask_offline
from clusterfilter_ros.core.clustering import density_mask
from clusterfilter_ros.core.evaluation import observable_mask
from clusterfilter_ros.core.offline import detect_offline, extend_selected, global_clusters
from clusterfilter_ros.core.params import detector_params, parse_assignments
from clusterfilter_ros.core.preprocess import frame_points, usable_mask
from clusterfilter_ros.core.scoring import score_clusters, select_clusters
from clusterfilter_ros.sim.raycast import CLASS_NAMES

sys.path.insert(0, str(Path(__file__).resolve().parent))
from detector_accuracy import drone_hit_stamps, load_sim  # noqa: E402

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
    if params.static_suppression:
        idx = np.nonzero(keep)[0]
        static = static_mask_offline(xyz[idx], t[idx], params)
        keep[idx[static]] = False
    stages["static"] = int((drone & keep).sum())
    kx, kt, kd, kc = xyz[keep], t[keep], drone[keep], cls[keep]
    labels, k = global_clusters(kx, kt, params)
    stages["clustered"] = int((kd & (labels >= 0)).sum())
    scores = score_clusters(labels, kx, kt, params, n_clusters=k)
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


def miss_reasons(sim, tr, result, params) -> Counter:
    gt = sim.sequence.ground_truth
    reasons: Counter = Counter()
    if gt is None or len(gt) == 0:
        return reasons
    obs = observable_mask(gt.stamps, drone_hit_stamps(sim), window=1.0)
    est = result.estimates
    hit = np.zeros(len(gt), bool)
    if len(est):
        j = np.clip(np.searchsorted(est.stamps, gt.stamps), 1, len(est) - 1)
        for jj in (j - 1, j):
            close = np.abs(est.stamps[jj] - gt.stamps) <= 0.3
            d = np.linalg.norm(est.xyz[jj] - gt.xyz, axis=1)
            hit |= close & (d <= 2.0)
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="+", default=["default", "flyover", "hover"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/clusterfilter_sim_cache"))
    ap.add_argument("--clusters", action="store_true", help="print drone clusters' features")
    ap.add_argument("--duration", type=float, help="simulate this many seconds (default: all)")
    args = ap.parse_args(argv)
    values = parse_assignments(args.param)
    total: Counter = Counter()
    for scenario in args.scenarios:
        for seed in args.seeds:
            sim = load_sim(scenario, seed, args.cache, args.duration)
            offset = [float(v) for v in sim.prism_offset]
            params = detector_params({**values, "target_offset": offset})
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
