"""Compare two accuracy runs of the same seeds, run by run (a change against the code
before it).

    git worktree add /tmp/before <old commit>
    PYTHONPATH=/tmp/before .venv/bin/python benchmarks/detector_accuracy.py \
        --seeds 0 1 2 3 4 5 --modes offline --json before.json
    .venv/bin/python benchmarks/detector_accuracy.py \
        --seeds 0 1 2 3 4 5 --modes offline --json after.json
    .venv/bin/python benchmarks/compare_accuracy.py before.json after.json

A run is identical when its detection of the observable time, false-alarm time and RMSE
are all equal (to ``--rmse-tol`` for the RMSE). Otherwise it is a gain (detection up or
false alarms down, neither the other way), a loss (the reverse), mixed (both), or an
RMSE change alone. Prints each changed run, then per mode and scenario the counts and
the means before and after.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

Key = tuple[str, int, str]  # scenario, seed, mode

DETECTION = "observable_detection_rate"
FALSE_ALARMS = "false_alarm_fraction"
RMSE = "rmse"


@dataclass(frozen=True)
class RunChange:
    """One run in both files: its figures before and after, and what kind of change."""

    key: Key
    before: dict
    after: dict
    kind: str  # "identical", "gain", "loss", "mixed" or "rmse"


def _num(value) -> float | None:
    """A metric as a float; None for a missing or NaN one (drone-free runs have no RMSE)."""
    if value is None:
        return None
    value = float(value)
    return None if math.isnan(value) else value


def load_runs(path: Path) -> dict[Key, dict]:
    """The rows of a ``detector_accuracy.py --json`` file by (scenario, seed, mode)."""
    try:
        rows = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise SystemExit(f"compare_accuracy: cannot read {path}: {exc}") from exc
    if not isinstance(rows, list):
        raise SystemExit(f"compare_accuracy: {path} is not a detector_accuracy.py --json file")
    runs = {}
    for row in rows:
        try:
            runs[(str(row["scenario"]), int(row["seed"]), str(row["mode"]))] = row
        except (KeyError, TypeError, ValueError) as exc:
            raise SystemExit(f"compare_accuracy: {path}: a row without {exc}") from exc
    return runs


def classify(before: dict, after: dict, rmse_tol: float = 0.0) -> str:
    """What changed between two results of one run (see the module docstring)."""
    det_a, det_b = _num(before.get(DETECTION)), _num(after.get(DETECTION))
    fa_a, fa_b = _num(before.get(FALSE_ALARMS)) or 0.0, _num(after.get(FALSE_ALARMS)) or 0.0
    better = (det_a is not None and det_b is not None and det_b > det_a) or fa_b < fa_a
    worse = (det_a is not None and det_b is not None and det_b < det_a) or fa_b > fa_a
    if better and worse:
        return "mixed"
    if better:
        return "gain"
    if worse:
        return "loss"
    rmse_a, rmse_b = _num(before.get(RMSE)), _num(after.get(RMSE))
    if (rmse_a is None) != (rmse_b is None):
        return "rmse"
    if rmse_a is not None and abs(rmse_b - rmse_a) > rmse_tol:
        return "rmse"
    return "identical"


def compare(
    before: dict[Key, dict], after: dict[Key, dict], rmse_tol: float = 0.0
) -> tuple[list[RunChange], list[Key], list[Key]]:
    """(every run in both, sorted; keys only before; keys only after)."""
    common = sorted(before.keys() & after.keys())
    changes = [
        RunChange(k, before[k], after[k], classify(before[k], after[k], rmse_tol)) for k in common
    ]
    return changes, sorted(before.keys() - after.keys()), sorted(after.keys() - before.keys())


def _pct(value) -> str:
    value = _num(value)
    return "-" if value is None else f"{100.0 * value:.1f}"


def _m(value) -> str:
    value = _num(value)
    return "-" if value is None else f"{value:.3f}"


def _mean(rows: Iterable[dict], name: str) -> float | None:
    values = [v for v in (_num(r.get(name)) for r in rows) if v is not None]
    return sum(values) / len(values) if values else None


def report(changes: list[RunChange]) -> list[str]:
    """The lines printed: each changed run, then one line per mode and scenario."""
    lines = []
    for c in changes:
        if c.kind == "identical":
            continue
        scenario, seed, mode = c.key
        lines.append(
            f"{mode:>8} {scenario:>16} s{seed:<5} {c.kind:>6}:"
            f" detection {_pct(c.before.get(DETECTION))} -> {_pct(c.after.get(DETECTION))} %,"
            f" false alarms {_pct(c.before.get(FALSE_ALARMS))}"
            f" -> {_pct(c.after.get(FALSE_ALARMS))} %,"
            f" RMSE {_m(c.before.get(RMSE))} -> {_m(c.after.get(RMSE))} m"
        )
    groups: dict[tuple[str, str], list[RunChange]] = {}
    for c in changes:
        groups.setdefault((c.key[2], c.key[0]), []).append(c)
    if lines:
        lines.append("")
    lines.append(
        "mode     scenario          runs identical gain loss mixed rmse"
        "  detection % before -> after  false alarms % before -> after"
    )
    for (mode, scenario), group in sorted(groups.items()):
        kinds = [c.kind for c in group]
        counts = " ".join(
            f"{kinds.count(k):>{w}}"
            for k, w in (("identical", 9), ("gain", 4), ("loss", 4), ("mixed", 5), ("rmse", 4))
        )
        before = [c.before for c in group]
        after = [c.after for c in group]
        lines.append(
            f"{mode:<8} {scenario:<16} {len(group):>5} {counts}"
            f"  {_pct(_mean(before, DETECTION)):>8} -> {_pct(_mean(after, DETECTION)):<8}"
            f"        {_pct(_mean(before, FALSE_ALARMS)):>6} -> {_pct(_mean(after, FALSE_ALARMS))}"
        )
    total = [c.kind for c in changes]
    lines.append(
        f"all: {len(changes)} runs, {total.count('identical')} identical,"
        f" {total.count('gain')} gains, {total.count('loss')} losses,"
        f" {total.count('mixed')} mixed, {total.count('rmse')} RMSE only"
    )
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path, help="detector_accuracy.py --json of the old code")
    ap.add_argument("after", type=Path, help="the same seeds with the new code")
    ap.add_argument(
        "--rmse-tol", type=float, default=0.0, help="RMSE changes up to this (m) count as equal"
    )
    args = ap.parse_args(argv)
    changes, only_before, only_after = compare(
        load_runs(args.before), load_runs(args.after), args.rmse_tol
    )
    for name, keys in (("before", only_before), ("after", only_after)):
        if keys:
            shown = ", ".join(f"{m} {s} s{d}" for s, d, m in keys[:5])
            more = f" and {len(keys) - 5} more" if len(keys) > 5 else ""
            print(f"only {name}: {len(keys)} runs ({shown}{more})")
    if not changes:
        print("no run is in both files")
        return 1
    print("\n".join(report(changes)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
