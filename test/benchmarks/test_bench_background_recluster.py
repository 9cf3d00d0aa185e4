"""The paced comparison of re-clustering in push and in the background runs end to end."""

from __future__ import annotations


def test_both_modes_are_paced_timed_and_scored(benchmark_module, tmp_path, capsys):
    bench = benchmark_module("bench_background_recluster")
    sim = bench.load_sim("default", 0, tmp_path, 5.0)
    latency, estimates, stats = bench.paced_run(sim, background=True, rate=10.0)
    assert latency.shape == (len(sim.sequence.frames),)
    assert stats["reclusters"] >= 8  # 5 s of stream, one every 0.5 s
    assert stats["recluster_in_flight"] in (0.0, 1.0)
    assert all(e.stamp >= sim.sequence.frames[0].stamp + 3.0 for e in estimates)  # warm-up

    assert (
        bench.main(
            [
                "--scenario",
                "default",
                "--seeds",
                "0",
                "--duration",
                "5",
                "--rate",
                "10",
                "--cache",
                str(tmp_path),
            ]
        )
        == 0
    )
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| default")]
    assert [r.split(" | ")[1] for r in rows] == ["in push", "background"]
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert int(cells[2]) == len(sim.sequence.frames)
        assert 0.0 <= float(cells[7]) <= 100.0
