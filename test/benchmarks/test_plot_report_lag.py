"""The report_lag plot runs end to end on a short simulated recording."""

from __future__ import annotations


def test_plot_of_live_late_and_offline_estimates(benchmark_module, tmp_path, capsys):
    plot = benchmark_module("plot_report_lag")
    out = tmp_path / "lag.png"
    argv = ["--scenario", "avia_only", "--seed", "0", "--duration", "8", "--lag", "2"]
    assert plot.main([*argv, "--cache", str(tmp_path / "cache"), "-o", str(out)]) == 0
    assert out.stat().st_size > 10_000
    printed = capsys.readouterr().out
    rates = {}
    for line in printed.splitlines():
        if "% of the observable time" in line:
            name, rest = line.split(": ", 1)
            rates[name] = float(rest.split("%")[0])
    assert set(rates) == {"offline", "2 s late (/uav/pose_delayed)", "live (/uav/pose)"}
    # Over 8 s the live output loses its 3 s warm-up; the late one gets 2 s of it back.
    assert rates["live (/uav/pose)"] < rates["2 s late (/uav/pose_delayed)"] <= 100.0
