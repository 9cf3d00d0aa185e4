"""Helpers shared by the benchmark scripts: machine description, timing, JSON output.

Every benchmark script in this folder is runnable on its own
(``python benchmarks/bench_X.py [--quick] [--json OUT.json]``) and returns a result
dictionary of this shape, which ``run_all.py`` collects, renders and plots::

    {
      "benchmark": "core",
      "command": "python benchmarks/bench_core.py",
      "machine": {...machine_info()...},
      "tables": [{"id": ..., "title": ..., "columns": [...], "rows": [[...], ...]}],
      "series": {...raw numbers for plots...},
      "targets": [{"name": ..., "target": ..., "measured": ..., "passed": bool|None}],
      "profiles": {"name": "cProfile text"},
      "seconds": wall time of the whole script,
    }
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import platform
import pstats
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

BENCH_DIR = Path(__file__).resolve().parent
REPO_DIR = BENCH_DIR.parent


def cpu_model() -> str:
    """The CPU model name from /proc/cpuinfo (or platform.processor() elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine_info() -> dict[str, Any]:
    """Cores, CPU model, memory, Python and package versions, git commit."""
    import psutil

    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=REPO_DIR,
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = ""
    import scipy
    import sklearn

    return {
        "cores": os.cpu_count(),
        "cpu_model": cpu_model(),
        "memory_gb": round(psutil.virtual_memory().total / 2**30, 1),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "sklearn": sklearn.__version__,
        "platform": platform.platform(),
        "git_commit": commit,
        "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
    }


def machine_label(info: dict[str, Any] | None = None) -> str:
    """Short machine description for a table row, e.g. ``2 cores, AMD EPYC``."""
    info = info or machine_info()
    return f"{info['cores']} cores, {info['cpu_model']}"


def percentiles(values: Any, qs: tuple[float, ...] = (50, 95, 99)) -> dict[str, float]:
    """``{"p50": ..., "p95": ..., "p99": ...}`` of ``values`` (NaN when empty)."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.size == 0:
        return {f"p{q:g}": float("nan") for q in qs}
    return {f"p{q:g}": float(np.percentile(arr, q)) for q in qs}


def profile_call(fn: Callable[[], Any], top: int = 15) -> tuple[Any, str]:
    """Run ``fn`` under cProfile; return its result and the top functions by cumulative time."""
    profiler = cProfile.Profile()
    result = profiler.runcall(fn)
    buffer = io.StringIO()
    stats = pstats.Stats(profiler, stream=buffer)
    stats.strip_dirs().sort_stats("cumulative").print_stats(top)
    text = buffer.getvalue()
    # Keep the table part: from the column header on.
    start = text.find("   ncalls")
    return result, text[start:].rstrip() if start >= 0 else text.rstrip()


def fmt(value: Any, digits: int = 3) -> str:
    """Format a number for a Markdown table (3 significant digits, thousands kept)."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return f"{int(value):,}"
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if not np.isfinite(v):
            return "-"
        if v == 0:
            return "0"
        if abs(v) >= 1000:
            return f"{v:,.0f}"
        return f"{v:.{digits}g}"
    return str(value)


def target_row(
    name: str, target: str, measured: float | str | None, passed: bool | None, unit: str = ""
) -> dict[str, Any]:
    """One target check for BENCHMARKS.md (``passed`` None = not measured)."""
    return {
        "name": name,
        "target": target,
        "measured": measured,
        "unit": unit,
        "passed": passed,
    }


def bench_main(
    name: str,
    run: Callable[[argparse.Namespace], dict[str, Any]],
    add_arguments: Callable[[argparse.ArgumentParser], None] | None = None,
    description: str = "",
) -> None:
    """Command-line entry shared by the benchmark scripts (``--quick``, ``--json``)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--quick", action="store_true", help="tiny sizes (CI smoke run)")
    parser.add_argument("--json", type=Path, help="write the result dictionary here")
    if add_arguments:
        add_arguments(parser)
    args = parser.parse_args()
    tic = time.perf_counter()
    result = run(args)
    result.setdefault("benchmark", name)
    result.setdefault("machine", machine_info())
    result["quick"] = bool(args.quick)
    if args.quick:
        # Quick runs use tiny sizes: their figures are smoke tests, not target checks.
        for target in result.get("targets", []):
            target["passed"] = None
    result["seconds"] = time.perf_counter() - tic
    for table in result.get("tables", []):
        print_table(table)
    for target in result.get("targets", []):
        status = {True: "PASS", False: "MISS", None: "n/a"}[target["passed"]]
        print(f"target {target['name']}: {target['target']} -> {fmt(target['measured'])} {status}")
    print(f"[{name}] done in {result['seconds']:.1f} s")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=1, default=_json_default))


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj)}")


def markdown_table(table: dict[str, Any]) -> str:
    """A Markdown table from ``{"columns": [...], "rows": [[...]]}``."""
    cols = table["columns"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for row in table["rows"]:
        lines.append("| " + " | ".join(fmt(v) for v in row) + " |")
    return "\n".join(lines)


def print_table(table: dict[str, Any]) -> None:
    print(f"\n## {table.get('title', table.get('id', ''))}")
    print(markdown_table(table))


def sys_executable() -> str:
    """The interpreter running the benchmarks (the project's venv when launched from it)."""
    return sys.executable
