"""Accuracy of the detector on simulated scenarios, offline and streaming.

For every (scenario, seed) this simulates the recording (cached as .npz-free pickles in
--cache so re-runs are quick), runs ``detect_offline`` and ``run_streaming`` with the
prism offset as ``target_offset``, and evaluates against the total-station ground truth:
detection rate over the time the drone gives at least one lidar return within +-0.5 s
("observable"), RMSE, coverage; on drone-free scenarios the false-alarm fraction.
Mode ``delayed`` is the streaming detector's ``report_lag`` output (``--report-lag``
seconds, default 3): every frame estimated again once the stream has moved that far on.

    .venv/bin/python benchmarks/detector_accuracy.py --seeds 100 101 102 --markdown

Prints one row per (scenario, seed, mode) and a per-scenario summary (means over seeds);
``--per-run`` also each run's figures, ``--jobs N`` runs N recordings at a time (a fresh
six-seed set in all three modes takes about 5 minutes with two on a 2-core machine,
simulation included).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import pickle
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from clusterfilter_ros.core.evaluation import evaluate, observable_mask
from clusterfilter_ros.core.frame import TimedPositions
from clusterfilter_ros.core.offline import detect_offline
from clusterfilter_ros.core.params import detector_params
from clusterfilter_ros.core.streaming import run_streaming

sys.path.insert(0, str(Path(__file__).resolve().parent))
from datasets import sim_fingerprint  # noqa: E402

#: Where the accuracy scripts keep simulated recordings between runs (``--cache``).
SIM_CACHE = Path("/tmp/clusterfilter_sim_cache")

DEFAULT_SCENARIOS = [
    "default",
    "takeoff_landing",
    "flyover",
    "fast_pass",
    "hover",
    "birds",
    "avia_only",
    "no_drone",
    "no_drone_birds",
]


def load_sim(scenario: str, seed: int, cache: Path | None, duration: float | None = None):
    """The simulated recording (from the cache when present).

    The cache key includes a hash of the simulator's source, so a changed simulator
    never has its old recordings scored.
    """
    from clusterfilter_ros.sim.scenarios import simulate

    key = f"{scenario}_s{seed}" + (f"_d{duration:g}" if duration else "")
    key += f"_{sim_fingerprint()}"
    path = cache / f"{key}.pkl" if cache else None
    if path is not None and path.exists():
        with path.open("rb") as fh:
            return pickle.load(fh)
    sim = simulate(scenario, seed, duration)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("wb") as fh:
            pickle.dump(sim, fh, protocol=pickle.HIGHEST_PROTOCOL)
    return sim


def drone_hit_stamps(sim) -> np.ndarray:
    """One stamp per drone lidar return in the recording."""
    frames = sim.sequence.frames
    return np.concatenate(
        [np.full(int(np.count_nonzero(sim.labels[i])), f.stamp) for i, f in enumerate(frames)]
        + [np.empty(0)]
    )


def estimates_to_positions(estimates) -> TimedPositions:
    return TimedPositions(
        np.array([e.stamp for e in estimates], dtype=np.float64),
        np.array([e.position for e in estimates], dtype=np.float64).reshape(-1, 3),
    )


def dedupe(pred: TimedPositions) -> TimedPositions:
    """Keep the last estimate of each stamp (two lidars can share a stamp)."""
    if len(pred) == 0:
        return pred
    _, idx = np.unique(pred.stamps[::-1], return_index=True)
    keep = np.sort(len(pred) - 1 - idx)
    return TimedPositions(pred.stamps[keep], pred.xyz[keep])


def sim_params(sim, values: dict | None = None):
    """Detector parameters ``values`` with the recording's prism offset as
    ``target_offset``, so estimates are compared with the prism's ground truth."""
    return detector_params(
        {**(values or {}), "target_offset": [float(v) for v in sim.prism_offset]}
    )


def evaluate_on_sim(sim, pred: TimedPositions):
    """:func:`evaluate` of predictions against the recording's ground truth, detection
    counted over the time the drone is observable (false alarms without a drone)."""
    frames = sim.sequence.frames
    gt = sim.sequence.ground_truth
    duration = frames[-1].stamp - frames[0].stamp
    if gt is None or len(gt) == 0:
        gt = TimedPositions(np.empty(0), np.empty((0, 3)))
        obs = None
    else:
        obs = observable_mask(gt.stamps, drone_hit_stamps(sim), window=1.0)
    return evaluate(pred, gt, observable=obs, duration=duration)


def run_case(
    sim, mode: str, values: dict, plot: Path | None = None, report_lag: float = 3.0
) -> tuple[dict, TimedPositions, float]:
    """One run: ``mode`` offline, stream or delayed (stream with ``report_lag``)."""
    if mode == "delayed":
        values = {**values, "report_lag": report_lag}
    elif mode not in ("offline", "stream"):
        raise ValueError(f"unknown mode {mode!r}")
    params = sim_params(sim, values)
    frames = sim.sequence.frames
    start = time.perf_counter()
    drone_points = None
    if mode == "offline":
        result = detect_offline(frames, params)
        pred = result.estimates
        drone_points = result.drone_points
    else:
        pred = estimates_to_positions(run_streaming(frames, params))
    seconds = time.perf_counter() - start
    pred = dedupe(TimedPositions(pred.stamps, pred.xyz))
    res = evaluate_on_sim(sim, pred)
    gt = sim.sequence.ground_truth
    if plot is not None:
        from clusterfilter_ros.plots import plot_evaluation

        plot_evaluation(
            gt if gt is not None and len(gt) else None,
            pred,
            plot,
            drone_points=drone_points,
            title=f"{sim.scenario} seed {sim.seed}, {mode}: RMSE {_f(res.as_dict()['rmse'])} m,"
            f" detection {_f(res.as_dict()['observable_detection_rate'])} of observable time",
        )
    return res.as_dict(), pred, seconds


def run_seed(
    scenario: str,
    seed: int,
    modes: list[str],
    values: dict,
    cache: Path | None,
    plot_dir: Path | None = None,
    report_lag: float = 3.0,
) -> list[dict]:
    """The rows of one simulated recording, one per mode (progress on stderr)."""
    sim = load_sim(scenario, seed, cache)
    rows = []
    for mode in modes:
        plot = None
        if plot_dir is not None:
            plot = plot_dir / f"{scenario}_s{seed}_{mode}.png"
        metrics, _, seconds = run_case(sim, mode, values, plot, report_lag)
        row = {"scenario": scenario, "seed": seed, "mode": mode, "seconds": seconds}
        row.update(metrics)
        rows.append(row)
        print(
            f"{scenario:>16} s{seed:<4} {mode:>7}:"
            f" det_obs={_f(row['observable_detection_rate'])}"
            f" det={_f(row['detection_rate'])} cov={_f(row['coverage'])}"
            f" rmse={_f(row['rmse'])} p95={_f(row['p95_error'])}"
            f" fa={_f(row['false_alarm_fraction'])}"
            f" acq={_f(row['mean_acquisition_delay'])}"
            f" tracked={_f(row['tracked_detection_rate'])} t={seconds:.2f}s",
            file=sys.stderr,
            flush=True,
        )
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="+", default=DEFAULT_SCENARIOS)
    ap.add_argument("--seeds", nargs="+", type=int, default=[100, 101, 102])
    ap.add_argument(
        "--modes",
        nargs="+",
        choices=("offline", "stream", "delayed"),
        default=["offline", "stream"],
    )
    ap.add_argument("--report-lag", type=float, default=3.0, help="report_lag (s) of mode delayed")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument(
        "--preset",
        choices=("default", "paper"),
        default="default",
        help="paper: the paper's published settings (PAPER_PRESET) before any --param",
    )
    ap.add_argument("--cache", type=Path, default=SIM_CACHE)
    ap.add_argument("--json", type=Path, help="also write all rows as JSON here")
    ap.add_argument("--markdown", action="store_true", help="print the summary as Markdown")
    ap.add_argument("--plot-dir", type=Path, help="write one evaluation plot per run here")
    ap.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="worker processes, one (scenario, seed) each at a time (run times per row "
        "then share the machine)",
    )
    ap.add_argument(
        "--per-run",
        action="store_true",
        help="also print each run: detection / other objects / RMSE per mode",
    )
    args = ap.parse_args(argv)
    from clusterfilter_ros.core.params import PAPER_PRESET, parse_assignments

    values = dict(PAPER_PRESET) if args.preset == "paper" else {}
    values.update(parse_assignments(args.param))
    cases = [(scenario, seed) for scenario in args.scenarios for seed in args.seeds]
    work = dict(
        modes=args.modes,
        values=values,
        cache=args.cache,
        plot_dir=args.plot_dir,
        report_lag=args.report_lag,
    )
    rows = []
    if args.jobs <= 1 or len(cases) <= 1:
        for scenario, seed in cases:
            rows.extend(run_seed(scenario, seed, **work))
    else:
        # One (scenario, seed) per task: the simulation and its modes stay in one process,
        # and the rows come back in the order of the serial run.
        context = multiprocessing.get_context("fork")
        with ProcessPoolExecutor(min(args.jobs, len(cases)), mp_context=context) as pool:
            futures = [pool.submit(run_seed, scenario, seed, **work) for scenario, seed in cases]
            for future in futures:
                rows.extend(future.result())
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    print_summary(rows, args.markdown)
    if args.per_run:
        print()
        print_per_run(rows, args.markdown)
    return 0


def _f(v) -> str:
    return "  n/a" if v is None else f"{v:.3f}"


def _mean(rows, key):
    vals = [r[key] for r in rows if r[key] is not None]
    return float(np.mean(vals)) if vals else None


def print_summary(rows, markdown: bool) -> None:
    scenarios = list(dict.fromkeys(r["scenario"] for r in rows))
    modes = list(dict.fromkeys(r["mode"] for r in rows))
    header = (
        "| scenario | mode | seeds | detection (observable) | detection (all GT) | coverage "
        "| RMSE m | p95 m | false alarms (% time) | acquisition s | tracked % | run time s |"
    )
    print(header if markdown else header.replace("|", " "))
    if markdown:
        print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for sc in scenarios:
        for mode in modes:
            rs = [r for r in rows if r["scenario"] == sc and r["mode"] == mode]
            if not rs:
                continue
            fa = _mean(rs, "false_alarm_fraction")
            cells = [
                sc,
                mode,
                ",".join(str(r["seed"]) for r in rs),
                _pct(_mean(rs, "observable_detection_rate")),
                _pct(_mean(rs, "detection_rate")),
                _pct(_mean(rs, "coverage")),
                _num(_mean(rs, "rmse")),
                _num(_mean(rs, "p95_error")),
                _pct(fa),
                _num(_mean(rs, "mean_acquisition_delay")),
                _pct(_mean(rs, "tracked_detection_rate")),
                _num(_mean(rs, "seconds")),
            ]
            line = "| " + " | ".join(cells) + " |"
            print(line if markdown else line.replace("|", " "))


def print_per_run(rows, markdown: bool) -> None:
    """One line per (scenario, seed): each mode's detection of the observable time, the
    time another object was reported or the estimate was more than 2 m off (false
    alarms, % of the run), and the RMSE."""
    modes = list(dict.fromkeys(r["mode"] for r in rows))
    runs: dict[tuple[str, int], dict[str, dict]] = {}
    for r in rows:
        runs.setdefault((r["scenario"], r["seed"]), {})[r["mode"]] = r
    header = "| scenario | seed | " + " | ".join(modes) + " |"
    print(header if markdown else header.replace("|", " "))
    if markdown:
        print("|---|---|" + "---|" * len(modes))
    for (scenario, seed), by_mode in runs.items():
        cells = [scenario, str(seed)]
        for mode in modes:
            r = by_mode.get(mode)
            if r is None:
                cells.append("")
                continue
            det = r["observable_detection_rate"]
            cells.append(
                ("" if det is None else f"{_pct(det)}% / ")
                + f"other {_pct(r['false_alarm_fraction'])}%"
                + ("" if r["rmse"] is None else f" / {_num(r['rmse'])} m")
            )
        line = "| " + " | ".join(cells) + " |"
        print(line if markdown else line.replace("|", " "))


def _pct(v) -> str:
    return "-" if v is None else f"{100 * v:.1f}"


def _num(v) -> str:
    return "-" if v is None else f"{v:.2f}"


if __name__ == "__main__":
    sys.exit(main())
