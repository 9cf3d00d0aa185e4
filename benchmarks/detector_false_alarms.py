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


def main(argv=None) -> int:
    from clusterfilter_ros.sim.raycast import CLASS_NAMES

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
            frames = sim.sequence.frames
            stamps = np.array([f.stamp for f in frames])
            truth = sim.drone_truth
            for mode in args.modes:
                _, pred, _ = run_case(sim, mode, {})
                counts: collections.Counter = collections.Counter()
                for t, p in zip(pred.stamps, pred.xyz, strict=True):
                    if len(truth):
                        at = [np.interp(t, truth.stamps, truth.xyz[:, a]) for a in range(3)]
                        if np.linalg.norm(p - np.asarray(at) - sim.prism_offset) < HIT_RADIUS:
                            continue
                    votes = np.zeros(len(CLASS_NAMES) + 1)
                    for i in np.nonzero(np.abs(stamps - t) <= 0.3)[0]:
                        near = np.linalg.norm(frames[i].xyz - (p - sim.prism_offset), axis=1) < 3
                        cls = sim.classes[i][near].astype(int)
                        votes[: len(CLASS_NAMES)] += np.bincount(cls, minlength=len(CLASS_NAMES))
                    name = CLASS_NAMES.get(int(votes.argmax()), "?") if votes.any() else "none"
                    counts[name] += 1
                total.update(counts)
                print(f"{scenario} seed {seed} {mode}: {dict(counts)}")
    n = sum(total.values())
    shares = {k: f"{100 * v / n:.1f}%" for k, v in total.most_common()} if n else {}
    print(f"all {n} reports: {shares}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
