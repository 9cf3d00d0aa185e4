"""Live, delayed (``report_lag``) and offline estimates of one simulated run, over time.

Top: the drone's distance from the rig (ground truth) with each mode's estimates;
bottom: each mode's 3D error against the ground truth on the same time axis, over the
times the drone is observable (shaded) and the streaming warm-up (grey). Where a mode
has no estimate its line is missing, so the live output's late start and its gaps show
at a glance.

    .venv/bin/python benchmarks/plot_report_lag.py --scenario flyover --seed 100 \
        --lag 3 -o docs/report_lag.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from clusterfilter_ros.core.evaluation import observable_mask

sys.path.insert(0, str(Path(__file__).resolve().parent))
from detector_accuracy import (  # noqa: E402
    SIM_CACHE,
    drone_hit_stamps,
    load_sim,
    run_case,
    sim_params,
)


def _with_gaps(stamps: np.ndarray, values: np.ndarray, max_gap: float) -> tuple:
    """Insert NaN where consecutive stamps are more than ``max_gap`` apart (a plotted
    line then breaks there)."""
    if stamps.size == 0:
        return stamps, values
    cut = np.flatnonzero(np.diff(stamps) > max_gap) + 1
    return np.insert(stamps, cut, np.nan), np.insert(values, cut, np.nan)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--seed", type=int, default=101)
    ap.add_argument("--lag", type=float, default=3.0, help="report_lag (s)")
    ap.add_argument("--cache", type=Path, default=SIM_CACHE)
    ap.add_argument("--duration", type=float, help="simulate this many seconds (default: all)")
    ap.add_argument("-o", "--output", type=Path, default=Path("report_lag.png"))
    args = ap.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sim = load_sim(args.scenario, args.seed, args.cache, args.duration)
    gt = sim.sequence.ground_truth
    t0 = sim.sequence.frames[0].stamp
    # Offline underneath (wide, light), then the late output, then the live one on top:
    # (label, benchmark mode, colour, line width).
    runs = [
        ("offline", "offline", "#b0b0b0", 4.0),
        (f"{args.lag:g} s late (/uav/pose_delayed)", "delayed", "#1a9641", 2.0),
        ("live (/uav/pose)", "stream", "#1f5fbf", 1.0),
    ]
    fig, (ax_range, ax_err) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True)
    ax_range.plot(
        gt.stamps - t0, np.linalg.norm(gt.xyz, axis=1), color="#d7191c", lw=1.0, label="truth"
    )
    obs = observable_mask(gt.stamps, drone_hit_stamps(sim), window=1.0)
    ax_err.fill_between(
        gt.stamps - t0, 0, 1, where=obs, color="#fde0dd", step="mid", label="drone observable"
    )
    for name, mode, colour, width in runs:
        res, pred, _ = run_case(sim, mode, {}, report_lag=args.lag)
        label = f"{name}: {100 * res['observable_detection_rate']:.1f}% of the observable time" + (
            f", RMSE {res['rmse']:.2f} m" if res["rmse"] is not None else ""
        )
        t, r = _with_gaps(pred.stamps - t0, np.linalg.norm(pred.xyz, axis=1), 0.3)
        ax_range.plot(t, r, color=colour, lw=width, label=label)
        truth = np.stack([np.interp(pred.stamps, gt.stamps, gt.xyz[:, k]) for k in range(3)], 1)
        t, e = _with_gaps(pred.stamps - t0, np.linalg.norm(pred.xyz - truth, axis=1), 0.3)
        ax_err.plot(t, e, color=colour, lw=width)
        print(label)
    ax_range.set_ylabel("distance from the rig (m)")
    ax_range.legend(loc="best", fontsize=8)
    ax_range.set_title(
        f"{args.scenario} seed {args.seed}: live, {args.lag:g} s late and offline estimates"
    )
    ax_err.set_ylabel("3D error (m)")
    ax_err.set_xlabel("time since the first frame (s)")
    ax_err.set_ylim(0, 1.0)
    ax_err.axvspan(0, sim_params(sim).warmup, color="#e0e0e0", label="streaming warm-up")
    ax_err.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    args.output.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.output, dpi=110)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
