"""The loss diagnostic replays the offline stages and accounts for every missed sample."""

from __future__ import annotations

import re


def test_every_observable_sample_is_hit_or_has_a_reason(tmp_path, capsys, benchmark_module):
    diagnose = benchmark_module("diagnose_losses")
    assert (
        diagnose.main(
            [
                "--scenarios",
                "default",
                "--seeds",
                "0",
                "--duration",
                "8",
                "--cache",
                str(tmp_path),
                "--clusters",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    total = re.search(r"TOTAL observable (\d+), hit (\d+)", out)
    assert total, out
    observable, hit = int(total.group(1)), int(total.group(2))
    assert observable > 0
    reasons = [int(m.group(1)) for m in re.finditer(r"^\s+(\d+)\s+[\d.]+%", out, re.M)]
    assert hit + sum(reasons) == observable, out
    stages = re.search(r"drone points raw=(\d+) usable=(\d+) denoise=(\d+) static=(\d+)", out)
    raw, usable, denoised, kept = (int(g) for g in stages.groups())
    assert raw >= usable >= denoised >= kept


def test_stream_mode_accounts_for_every_observable_sample(tmp_path, capsys, benchmark_module):
    diagnose = benchmark_module("diagnose_losses")
    argv = ["--mode", "stream", "--scenarios", "default", "--seeds", "0", "--duration", "8"]
    assert diagnose.main(argv + ["--cache", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    total = re.search(r"TOTAL observable (\d+), hit (\d+)", out)
    assert total, out
    observable, hit = int(total.group(1)), int(total.group(2))
    assert observable > 0
    reasons = re.findall(r"^\s+(\d+)\s+[\d.]+% (.+)$", out, re.M)
    assert hit + sum(int(n) for n, _ in reasons) == observable, out
    # The first seconds are the warm-up: nothing can be reported there.
    assert any(name.startswith("before any cluster was scored") for _, name in reasons), out
    # The scoring hook is removed afterwards.
    from clusterfilter_ros.core import scoring, streaming

    assert streaming.score_clusters is scoring.score_clusters


def test_stream_phases_split_the_same_misses(tmp_path, capsys, benchmark_module):
    diagnose = benchmark_module("diagnose_losses")
    argv = ["--mode", "stream", "--scenarios", "default", "--seeds", "0", "--duration", "8"]
    argv += ["--cache", str(tmp_path)]
    assert diagnose.main(argv) == 0
    plain = re.findall(r"^\s+(\d+)\s+[\d.]+% (.+)$", capsys.readouterr().out, re.M)
    assert diagnose.main(argv + ["--phase"]) == 0
    split = re.findall(r"^\s+(\d+)\s+[\d.]+% (.+)$", capsys.readouterr().out, re.M)
    by_cause = {}
    for n, name in split:
        prefix, _, cause = name.partition("] ")
        assert prefix in ("[acquiring", "[after the first hit"), name
        if cause.startswith("before any cluster was scored"):
            assert prefix == "[acquiring", name  # the warm-up comes before any hit
        by_cause[cause] = by_cause.get(cause, 0) + int(n)
    assert by_cause == {name: int(n) for n, name in plain}
