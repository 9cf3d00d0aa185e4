"""How the clusters offline selects move, by what they are: the drone's against birds'.

For every cluster the offline detector selects, the simulator's labels of its returns
give its majority class, and its frame-mean positions give kinematic measures beyond
the scorer's own: how fast the acceleration fitted in sliding windows changes (it turns
over where a path weaves over seconds; a wobble much shorter than the window averages
out there and shows in the smoothness residual instead; on a sparse leg it is also the
fits' own scatter), and the vertical acceleration. Prints one row per selected cluster
and percentiles per class; the figures in docs/detector.md ("How the acceleration
changes") came from this.

    .venv/bin/python benchmarks/selection_kinematics.py --seeds 5300 5301 5302
    .venv/bin/python benchmarks/selection_kinematics.py --scenarios no_drone_birds \
        --seeds 2701 3302 --window 3
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from detector_accuracy import DEFAULT_SCENARIOS, SIM_CACHE, load_sim, sim_params  # noqa: E402

#: Seconds between the centres of consecutive sliding windows.
STEP = 0.25
#: Frame-mean samples a window needs, spanning at least half of it.
MIN_SAMPLES = 6


def window_accelerations(
    t: np.ndarray, xyz: np.ndarray, window: float, frame_period: float = 0.1
) -> tuple[np.ndarray, np.ndarray]:
    """(centres (W,), accelerations (W, 3)): quadratic fits of the frame-mean positions
    in windows of ``window`` s slid by :data:`STEP`, those with at least
    :data:`MIN_SAMPLES` samples spanning half the window."""
    t = np.asarray(t, dtype=np.float64)
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if t.size == 0:
        return np.empty(0), np.empty((0, 3))
    frame = np.floor((t - t.min()) / frame_period).astype(np.int64)
    _, inv = np.unique(frame, return_inverse=True)
    n = np.bincount(inv).astype(np.float64)
    tm = np.bincount(inv, weights=t) / n
    pm = np.stack([np.bincount(inv, weights=xyz[:, a]) for a in range(3)], axis=1) / n[:, None]
    centres, acc = [], []
    for c in np.arange(tm[0] + window / 2, tm[-1] - window / 2 + 1e-9, STEP):
        sel = np.abs(tm - c) <= window / 2
        if sel.sum() < MIN_SAMPLES or np.ptp(tm[sel]) < window / 2:
            continue
        x = tm[sel] - c
        design = np.stack([np.ones_like(x), x, x * x], axis=1)
        coef, *_ = np.linalg.lstsq(design, pm[sel], rcond=None)
        centres.append(c)
        acc.append(2.0 * coef[2])
    return np.asarray(centres), np.asarray(acc).reshape(-1, 3)


def kinematics(t: np.ndarray, xyz: np.ndarray, window: float) -> dict[str, float]:
    """Median change of the fitted acceleration between windows half a window apart, per
    second (m/s^3), and median vertical acceleration (m/s^2); NaN without enough
    windows."""
    centres, acc = window_accelerations(t, xyz, window)
    lag = window / 2
    changes = []
    for i, c in enumerate(centres):
        j = np.flatnonzero(np.abs(centres - (c + lag)) < 1e-6)
        if j.size:
            changes.append(float(np.linalg.norm(acc[j[0]] - acc[i])) / lag)
    return {
        "accel_change": float(np.median(changes)) if changes else float("nan"),
        "vertical_accel": float(np.median(np.abs(acc[:, 2]))) if len(acc) else float("nan"),
    }


@contextlib.contextmanager
def _captured_selection(record: dict) -> Iterator[None]:
    """Record the labels, points and scores the offline selection reads
    (``offline.tracked_spans``' arguments) while detect_offline runs."""
    from clusterfilter_ros.core import offline

    original = offline.tracked_spans

    def tracked(labels, xyz, t, scores, params):
        record.update(labels=labels, xyz=xyz, t=t, scores=scores)
        return original(labels, xyz, t, scores, params)

    offline.tracked_spans = tracked
    try:
        yield
    finally:
        offline.tracked_spans = original


def selections(sim, window: float) -> list[dict]:
    """One row per cluster offline selects in ``sim``: class shares of its returns,
    confidence, duration, returns and :func:`kinematics`."""
    from scipy.spatial import cKDTree

    from clusterfilter_ros.core.offline import detect_offline
    from clusterfilter_ros.sim.raycast import CLASS_NAMES

    record: dict = {}
    with _captured_selection(record):
        result = detect_offline(sim.sequence.frames, sim_params(sim, {}))
    if not result.selected or "labels" not in record:
        return []
    frames = sim.sequence.frames
    points = np.concatenate([f.xyz for f in frames])
    classes = np.concatenate([np.asarray(sim.classes[i]) for i in range(len(frames))])
    tree = cKDTree(points)
    scores = record["scores"]
    rows = []
    for c in result.selected:
        member = record["labels"] == c
        if not member.any():
            continue
        xyz = np.asarray(record["xyz"][member], dtype=np.float64)
        t = np.asarray(record["t"][member], dtype=np.float64)
        _, nearest = tree.query(xyz)
        names = np.array([CLASS_NAMES.get(int(k), str(k)) for k in classes[nearest]])
        kinds, counts = np.unique(names, return_counts=True)
        rows.append(
            {
                "scenario": sim.scenario,
                "seed": int(sim.seed),
                "class": str(kinds[np.argmax(counts)]),
                "share": float(counts.max() / counts.sum()),
                "confidence": float(scores.confidence[c]),
                "seconds": float(t.max() - t.min()),
                "returns": int(member.sum()),
                "fitted_accel": float(scores.acceleration[c]),
                **kinematics(t, xyz, window),
            }
        )
    return rows


def summary(rows: list[dict]) -> str:
    """Percentiles (10, 50, 90, 99, max) of each measure per majority class."""
    lines = ["| class | selections | measure | p10 | p50 | p90 | p99 | max |", "|---" * 8 + "|"]
    for kind in sorted({r["class"] for r in rows}):
        group = [r for r in rows if r["class"] == kind]
        for key in ("fitted_accel", "accel_change", "vertical_accel"):
            v = np.array([r[key] for r in group], dtype=np.float64)
            v = v[np.isfinite(v)]
            if not v.size:
                continue
            q = np.percentile(v, [10, 50, 90, 99])
            cells = " | ".join(f"{x:.2f}" for x in (*q, v.max()))
            lines.append(f"| {kind} | {v.size} | {key} | {cells} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenarios", nargs="+", default=list(DEFAULT_SCENARIOS))
    ap.add_argument("--seeds", nargs="+", type=int, default=[100, 101, 102])
    ap.add_argument("--window", type=float, default=3.0, help="sliding window (s)")
    ap.add_argument("--cache", type=Path, default=SIM_CACHE)
    ap.add_argument("--json", type=Path, help="write the rows here")
    args = ap.parse_args(argv)
    rows: list[dict] = []
    for seed in args.seeds:
        for scenario in args.scenarios:
            sim = load_sim(scenario, seed, args.cache)
            for r in selections(sim, args.window):
                rows.append(r)
                print(
                    f"{r['scenario']:>16} s{r['seed']:<5} {r['class']:>9} ({r['share']:.2f})"
                    f" conf {r['confidence']:.2f} {r['seconds']:5.1f} s {r['returns']:4d} ret"
                    f"  accel {r['fitted_accel']:.2f}  change {r['accel_change']:.2f}"
                    f"  vertical {r['vertical_accel']:.2f}",
                    flush=True,
                )
    print(summary(rows))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
