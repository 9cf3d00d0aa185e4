"""The benchmark suite's quick mode runs end to end (crashes fail; timings never do)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_run_all_quick(tmp_path: Path, ros_env: dict[str, str]) -> None:
    out = tmp_path / "bench"
    proc = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "run_all.py"), "--quick", "--out", str(out)],
        cwd=REPO,
        env=ros_env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-4000:]
    merged = json.loads((out / "results.json").read_text())
    names = {r["benchmark"] for r in merged["results"]}
    assert {"core", "side_by_side", "memory", "node"} <= names
    assert all(r["returncode"] == 0 for r in merged["results"])
    doc = (out / "BENCHMARKS.md").read_text()
    assert "| points | voxel clusterer ms" in doc
    assert "2 cores" in doc or "cores," in doc
    assert (out / "recluster_scaling.png").stat().st_size > 1000
    assert (out / "memory_rss.png").stat().st_size > 1000
