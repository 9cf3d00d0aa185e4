"""What the detector reports where there is no drone, by simulator class.

For each report the simulator's labelled points within 3 m of it (prism offset removed)
in frames within +-0.3 s are counted by class; the report is attributed to the majority
class, or ``none`` when no point is that close. In scenarios with a drone only the
reports farther than 2 m from its ground truth count (another object reported, or the
drone's estimate that far off: ``drone`` then).

    .venv/bin/python benchmarks/detector_false_alarms.py --seeds 100 101 102
    .venv/bin/python benchmarks/detector_false_alarms.py --scenarios birds hover \
        --seeds 1700 1701 --modes offline stream delayed
"""

from __future__ import annotations

import argparse
import collections
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from detector_accuracy import SIM_CACHE, load_sim, run_case  # noqa: E402

HIT_RADIUS = 2.0  # m: the evaluator's detection radius
NEAR = 3.0  # m: labelled returns this close to a report vote for its class
WINDOW = 0.3  # s: from frames this close in time


def attribute(sim, pred) -> collections.Counter:
    """Reports (``TimedPositions`` with the prism offset added) counted by the class of
    the labelled returns near them; in a recording with a drone only those at least
    ``HIT_RADIUS`` from its ground truth."""
    from clusterfilter_ros.sim.raycast import CLASS_NAMES

    frames = sim.sequence.frames
    stamps = np.array([f.stamp for f in frames])
    offset = np.asarray(sim.prism_offset, dtype=np.float64)
    truth = sim.drone_truth
    counts: collections.Counter = collections.Counter()
    for t, p in zip(pred.stamps, pred.xyz, strict=True):
        if len(truth):
            at = np.array([np.interp(t, truth.stamps, truth.xyz[:, a]) for a in range(3)])
            if np.linalg.norm(p - at - offset) < HIT_RADIUS:
                continue
        votes = np.zeros(len(CLASS_NAMES))
        for i in np.flatnonzero(np.abs(stamps - t) <= WINDOW):
            near = np.linalg.norm(frames[i].xyz - (p - offset), axis=1) < NEAR
            cls = np.asarray(sim.classes[i])[near].astype(int)
            votes += np.bincount(cls, minlength=len(CLASS_NAMES))[: len(CLASS_NAMES)]
        counts[CLASS_NAMES.get(int(votes.argmax()), "?") if votes.any() else "none"] += 1
    return counts


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="+", default=["no_drone", "no_drone_birds"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[100, 101, 102])
    modes = ["offline", "stream", "delayed"]
    ap.add_argument("--modes", nargs="+", default=modes[:2], choices=modes)
    ap.add_argument("--cache", type=Path, default=SIM_CACHE)
    args = ap.parse_args(argv)
    total: collections.Counter = collections.Counter()
    for scenario in args.scenarios:
        for seed in args.seeds:
            sim = load_sim(scenario, seed, args.cache)
            for mode in args.modes:
                _, pred, _ = run_case(sim, mode, {})
                counts = attribute(sim, pred)
                total.update(counts)
                print(f"{scenario} seed {seed} {mode}: {dict(counts)}")
    n = sum(total.values())
    shares = {k: f"{100 * v / n:.1f}%" for k, v in total.most_common()} if n else {}
    print(f"all {n} reports: {shares}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
