"""The accuracy script's plumbing: parallel runs keep the serial order; per-run lines."""

from __future__ import annotations

import json

FIELDS = ("observable_detection_rate", "detection_rate", "coverage", "rmse", "p95_error")


def _row(scenario, seed, mode, det, fa, rmse):
    row = {"scenario": scenario, "seed": seed, "mode": mode, "seconds": 0.1}
    row.update({k: None for k in FIELDS})
    row.update(
        observable_detection_rate=det,
        false_alarm_fraction=fa,
        rmse=rmse,
        mean_acquisition_delay=None,
        tracked_detection_rate=None,
    )
    return row


def _fake_run_seed(scenario, seed, modes, values, cache, plot_dir=None, report_lag=3.0):
    drone = not scenario.startswith("no_drone")
    return [
        _row(
            scenario,
            seed,
            mode,
            0.5 + seed / 100 if drone else None,
            0.01 * seed,
            0.2 if drone else None,
        )
        for mode in modes
    ]


def test_jobs_keep_the_serial_order(benchmark_module, monkeypatch, tmp_path, capsys):
    acc = benchmark_module("detector_accuracy")
    monkeypatch.setattr(acc, "run_seed", _fake_run_seed)
    argv = [
        "--scenarios",
        "hover",
        "no_drone",
        "--seeds",
        "3",
        "1",
        "2",
        "--modes",
        "offline",
        "stream",
    ]
    acc.main([*argv, "--json", str(tmp_path / "serial.json")])
    acc.main([*argv, "--jobs", "2", "--json", str(tmp_path / "jobs.json")])
    serial = json.loads((tmp_path / "serial.json").read_text())
    jobs = json.loads((tmp_path / "jobs.json").read_text())
    assert jobs == serial
    assert [(r["scenario"], r["seed"], r["mode"]) for r in serial[:4]] == [
        ("hover", 3, "offline"),
        ("hover", 3, "stream"),
        ("hover", 1, "offline"),
        ("hover", 1, "stream"),
    ]
    capsys.readouterr()


def test_per_run_lines(benchmark_module, capsys):
    acc = benchmark_module("detector_accuracy")
    rows = [
        _row("hover", 7, "offline", 0.981, 0.0, 0.114),
        _row("hover", 7, "delayed", 0.9, 0.02, 0.3),
        _row("no_drone", 7, "offline", None, 0.246, None),
    ]
    acc.print_per_run(rows, markdown=True)
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "| scenario | seed | offline | delayed |"
    assert out[2] == "| hover | 7 | 98.1% / other 0.0% / 0.11 m | 90.0% / other 2.0% / 0.30 m |"
    # A drone-free run has only its false-alarm time; a mode it lacks stays empty.
    assert out[3] == "| no_drone | 7 | other 24.6% |  |"
