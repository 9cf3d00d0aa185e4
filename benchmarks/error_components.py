"""Where the position error comes from: lag along the flight path, or scatter.

For every (scenario, seed) this runs both modes with the prism offset as
``target_offset`` (as ``detector_accuracy.py`` does) and splits each estimate's error
against the simulator's dense truth (body centre + prism offset, interpolated at the
estimate's stamp) into the component along the drone's true velocity and the rest.
Only estimates within 2 m of the truth (hits) while the drone moves faster than 0.5
m/s enter the split, so a wrong object does not swamp it.

A causal estimator that trails the drone shows a negative mean along-track error
proportional to the speed (``lag`` column: mean along-track error / speed, in
seconds); one that only scatters more shows a larger standard deviation with no such
mean.

    .venv/bin/python benchmarks/error_components.py --scenarios avia_only --seeds 900 901

``--by-age`` also splits the streaming hits by how old the drone's newest return was
when the frame was estimated (its own scan included: returns up to ``frame_period``
after the stamp): the streaming position past the newest return is an extrapolation,
and where the drone is seen in bursts (the Avia's scan pattern revisits a small target
every few frames) its error grows with that age, which smoothing over both sides spares
the offline mode.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from clusterfilter_ros.core.offline import detect_offline
from clusterfilter_ros.core.streaming import run_streaming

sys.path.insert(0, str(Path(__file__).resolve().parent))
from detector_accuracy import SIM_CACHE, estimates_to_positions, load_sim, sim_params  # noqa: E402

MIN_SPEED = 0.5  # m/s: slower estimates have no meaningful along-track direction
HIT_RADIUS = 2.0  # m, as the evaluator's detection radius
#: Upper edges (s) of the return-age bins of ``--by-age``; the last bin is open.
AGE_EDGES = (0.0, 0.1, 0.2, 0.3, 0.5)


def error_components(
    stamps: np.ndarray, xyz: np.ndarray, truth_stamps: np.ndarray, truth_xyz: np.ndarray
) -> dict[str, float]:
    """Along-track mean / sd, cross-track RMS and lag of estimates against a dense truth."""
    nan = float("nan")
    out = {"n": int(stamps.size), "hits": 0, "rmse": nan, "moving": 0}
    out.update(along_mean=nan, along_sd=nan, cross_rms=nan, lag=nan)
    if stamps.size == 0:
        return out
    truth = np.stack([np.interp(stamps, truth_stamps, truth_xyz[:, k]) for k in range(3)], 1)
    velocity = np.gradient(truth_xyz, truth_stamps, axis=0)
    vel = np.stack([np.interp(stamps, truth_stamps, velocity[:, k]) for k in range(3)], 1)
    err = xyz - truth
    dist = np.linalg.norm(err, axis=1)
    hit = dist < HIT_RADIUS
    speed = np.linalg.norm(vel, axis=1)
    moving = hit & (speed > MIN_SPEED)
    out["hits"] = int(hit.sum())
    if hit.any():
        out["rmse"] = float(np.sqrt(np.mean(dist[hit] ** 2)))
    out["moving"] = int(moving.sum())
    if moving.any():
        unit = vel[moving] / speed[moving, None]
        along = np.sum(err[moving] * unit, axis=1)
        cross = err[moving] - along[:, None] * unit
        out["along_mean"] = float(along.mean())
        out["along_sd"] = float(along.std())
        out["cross_rms"] = float(np.sqrt(np.mean(np.sum(cross**2, axis=1))))
        out["lag"] = float(np.mean(along / speed[moving]))
    return out


def return_ages(stamps: np.ndarray, return_times: np.ndarray, horizon: float) -> np.ndarray:
    """(N,) age (s) of the newest of ``return_times`` at or before ``stamp + horizon``
    for each stamp, measured from the stamp (negative: a return scanned after the
    stamp); inf where there is none."""
    rt = np.sort(np.asarray(return_times, dtype=np.float64))
    stamps = np.asarray(stamps, dtype=np.float64)
    i = np.searchsorted(rt, stamps + horizon, side="right") - 1
    ages = np.full(stamps.size, np.inf)
    ok = i >= 0
    ages[ok] = stamps[ok] - rt[i[ok]]
    return ages


def error_by_age(
    stamps: np.ndarray,
    xyz: np.ndarray,
    truth_stamps: np.ndarray,
    truth_xyz: np.ndarray,
    ages: np.ndarray,
    edges: tuple[float, ...] = AGE_EDGES,
) -> list[dict[str, float]]:
    """Per age bin (``edges`` are upper bounds, then one open bin): the number of hits
    (estimates within 2 m of the truth) and their RMSE."""
    out = []
    if stamps.size == 0:
        dist = np.empty(0)
    else:
        truth = np.stack([np.interp(stamps, truth_stamps, truth_xyz[:, k]) for k in range(3)], 1)
        dist = np.linalg.norm(xyz - truth, axis=1)
    hit = dist < HIT_RADIUS
    bounds = [-np.inf, *edges, np.inf]
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        m = hit & (ages > lo) & (ages <= hi)
        rmse = float(np.sqrt(np.mean(dist[m] ** 2))) if m.any() else float("nan")
        out.append({"lo": lo, "hi": hi, "hits": int(m.sum()), "rmse": rmse})
    return out


def drone_return_times(sim) -> np.ndarray:
    """Stamps of the recording's labelled drone returns (per-point times where known)."""
    parts = [np.empty(0)]
    for i, frame in enumerate(sim.sequence.frames):
        label = np.asarray(sim.labels[i], dtype=bool)
        if not label.any():
            continue
        if frame.point_time is not None:
            parts.append(frame.stamp + np.asarray(frame.point_time, dtype=np.float64)[label])
        else:
            parts.append(np.full(int(label.sum()), frame.stamp))
    return np.concatenate(parts)


def _age_label(lo: float, hi: float) -> str:
    if np.isinf(lo):
        return f"<={hi:g}"
    if np.isinf(hi):
        return f">{lo:g}"
    return f"{lo:g}-{hi:g}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=["avia_only"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--cache", type=Path, default=SIM_CACHE)
    parser.add_argument(
        "--by-age",
        action="store_true",
        help="also split the streaming hits by the age of the newest drone return",
    )
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    header = "scenario seed mode: n hits rmse | moving along_mean along_sd cross_rms lag"
    print(header)
    for scenario in args.scenarios:
        for seed in args.seeds:
            sim = load_sim(scenario, seed, args.cache)
            if len(sim.drone_truth) == 0:
                print(f"{scenario} s{seed}: no drone, skipped")
                continue
            params = sim_params(sim)
            frames = sim.sequence.frames
            truth_xyz = sim.drone_truth.xyz + np.asarray(sim.prism_offset, dtype=float)
            for mode in ("offline", "stream"):
                if mode == "offline":
                    pred = detect_offline(frames, params).estimates
                else:
                    pred = estimates_to_positions(run_streaming(frames, params))
                c = error_components(pred.stamps, pred.xyz, sim.drone_truth.stamps, truth_xyz)
                print(
                    f"{scenario} s{seed} {mode}: {c['n']} {c['hits']} {c['rmse']:.3f} | "
                    f"{c['moving']} {c['along_mean']:+.3f} {c['along_sd']:.3f} "
                    f"{c['cross_rms']:.3f} {c['lag']:+.3f} s"
                )
                if args.by_age and mode == "stream":
                    ages = return_ages(pred.stamps, drone_return_times(sim), params.frame_period)
                    bins = error_by_age(
                        pred.stamps, pred.xyz, sim.drone_truth.stamps, truth_xyz, ages
                    )
                    print(
                        "    newest return age s: "
                        + "  ".join(
                            f"{_age_label(b['lo'], b['hi'])}: {b['hits']} {b['rmse']:.3f}"
                            for b in bins
                        )
                    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
