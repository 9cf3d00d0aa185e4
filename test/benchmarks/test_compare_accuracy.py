"""Two accuracy runs of the same seeds compared run by run."""

from __future__ import annotations

import json

import pytest


def _row(scenario, seed, mode, det, fa, rmse):
    return {
        "scenario": scenario,
        "seed": seed,
        "mode": mode,
        "observable_detection_rate": det,
        "false_alarm_fraction": fa,
        "rmse": rmse,
    }


BEFORE = [
    _row("fast_pass", 3, "offline", 0.900, 0.0, 0.27),
    _row("fast_pass", 4, "offline", 0.917, 0.0, 0.13),
    _row("birds", 5, "offline", 0.425, 0.0, 0.12),
    _row("takeoff_landing", 1603, "offline", 0.978, 0.04, 0.94),
    _row("no_drone", 0, "offline", None, 0.0, None),
    _row("no_drone", 0, "stream", None, 0.0, None),
]
AFTER = [
    _row("fast_pass", 3, "offline", 0.976, 0.0, 0.32),  # gain
    _row("fast_pass", 4, "offline", 0.917, 0.0, 0.15),  # RMSE only
    _row("birds", 5, "offline", 0.425, 0.101, 13.2),  # loss: another object reported
    _row("takeoff_landing", 1603, "offline", 0.990, 0.19, 1.82),  # mixed
    _row("no_drone", 0, "offline", None, 0.0, None),  # identical
    _row("no_drone", 1, "offline", None, 0.0, None),  # only after
]


def test_each_run_is_classified(benchmark_module):
    cmp = benchmark_module("compare_accuracy")
    before = {(r["scenario"], r["seed"], r["mode"]): r for r in BEFORE}
    after = {(r["scenario"], r["seed"], r["mode"]): r for r in AFTER}
    changes, only_before, only_after = cmp.compare(before, after)
    kinds = {c.key: c.kind for c in changes}
    assert kinds == {
        ("birds", 5, "offline"): "loss",
        ("fast_pass", 3, "offline"): "gain",
        ("fast_pass", 4, "offline"): "rmse",
        ("no_drone", 0, "offline"): "identical",
        ("takeoff_landing", 1603, "offline"): "mixed",
    }
    assert only_before == [("no_drone", 0, "stream")]
    assert only_after == [("no_drone", 1, "offline")]
    # An RMSE change within the tolerance is no change.
    assert cmp.classify(BEFORE[1], AFTER[1], rmse_tol=0.05) == "identical"


def test_main_prints_changed_runs_and_per_scenario_counts(benchmark_module, tmp_path, capsys):
    cmp = benchmark_module("compare_accuracy")
    (tmp_path / "a.json").write_text(json.dumps(BEFORE))
    (tmp_path / "b.json").write_text(json.dumps(AFTER).replace("null", "NaN", 1))
    assert cmp.main([str(tmp_path / "a.json"), str(tmp_path / "b.json")]) == 0
    out = capsys.readouterr().out
    assert "fast_pass s3" in out and "gain: detection 90.0 -> 97.6 %" in out
    assert "only before: 1 runs (stream no_drone s0)" in out
    assert "all: 5 runs, 1 identical, 1 gains, 1 losses, 1 mixed, 1 RMSE only" in out
    fast = next(line for line in out.splitlines() if line.startswith("offline  fast_pass"))
    assert fast.split()[2:8] == ["2", "0", "1", "0", "0", "1"]


def test_unreadable_input_is_a_clear_error(benchmark_module, tmp_path):
    cmp = benchmark_module("compare_accuracy")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(SystemExit, match="cannot read"):
        cmp.load_runs(bad)
    bad.write_text(json.dumps({"rows": []}))
    with pytest.raises(SystemExit, match="not a detector_accuracy.py --json file"):
        cmp.load_runs(bad)
    bad.write_text(json.dumps([{"seed": 1}]))
    with pytest.raises(SystemExit, match="a row without"):
        cmp.load_runs(bad)
    with pytest.raises(SystemExit, match="cannot read"):
        cmp.load_runs(tmp_path / "missing.json")
