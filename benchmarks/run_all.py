"""Run the whole benchmark suite, collect JSON results, rewrite BENCHMARKS.md, save plots.

Usage::

    python benchmarks/run_all.py                 # full suite (< 15 min on 2 cores)
    python benchmarks/run_all.py --quick --out /tmp/bench   # CI smoke run (< 2 min)
    python benchmarks/run_all.py --only core,memory          # a subset

Each benchmark runs in its own process (``python benchmarks/bench_X.py --json F``), so
memory figures are clean and one crash does not hide the other results. The results are
merged into ``OUT/results.json``, plots are written as PNG into ``OUT`` and the tables in
the Markdown document are rewritten between ``<!-- table:ID -->`` and
``<!-- /table:ID -->`` markers (tables without a marker are appended to the
``<!-- table:* -->`` block). A full run rewrites ``BENCHMARKS.md`` at the repository
root; ``--quick`` writes its document to ``OUT/BENCHMARKS.md`` and never touches the
committed one. ``--quick`` fails (exit 1) only when a benchmark crashes, never on timing.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from benchlib import (  # noqa: E402
    BENCH_DIR,
    REPO_DIR,
    fmt,
    machine_info,
    machine_label,
    markdown_table,
)

#: Benchmarks in run order: (name, script, extra arguments, seconds allowed in a full
#: run, seconds allowed in a quick run, part of the default suite). Scripts written by
#: other parts of the project are run when present. Entries outside the default suite
#: run only with ``--long`` or ``--only NAME``; their last results are kept in
#: results.json and rendered with the rest.
SUITE: list[tuple[str, str, tuple[str, ...], int, int, bool]] = [
    ("core", "bench_core.py", (), 480, 90, True),
    ("side_by_side", "bench_side_by_side.py", (), 300, 90, True),
    # A scenario where the streaming detector reports the drone, so poses (and with them
    # latencies) exist for a good share of the frames.
    ("node", "bench_node.py", ("--scenario", "avia_only", "--seed", "100"), 180, 90, True),
    # The full hour; the budget stops it (and the table says so) if the detector ever
    # gets too slow for the suite's 15 minutes.
    ("memory", "bench_memory.py", ("--minutes", "60", "--budget", "360"), 480, 90, True),
    ("detector", "bench_detector.py", (), 240, 90, True),
    ("simulate", "bench_simulate.py", (), 120, 60, True),
    ("io", "bench_io.py", (), 120, 60, True),
]

DOC_PATH = REPO_DIR / "BENCHMARKS.md"
DEFAULT_OUT = BENCH_DIR / "results"


def run_benchmark(
    name: str, script: str, extra: tuple[str, ...], out: Path, quick: bool, timeout: int
) -> dict[str, Any]:
    """Run one benchmark script in a child process; return its result (or the failure)."""
    path = BENCH_DIR / script
    json_path = out / f"{name}.json"
    if json_path.exists():
        json_path.unlink()
    cmd = [sys.executable, str(path), *extra]
    if quick:
        cmd.append("--quick")
    accepts_json = "--json" in path.read_text()
    if accepts_json:
        cmd += ["--json", str(json_path)]
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO_DIR), env.get("PYTHONPATH", "")) if p)
    print(f"[run_all] {name}: {' '.join(cmd[1:])}", flush=True)
    tic = time.perf_counter()
    try:
        proc = subprocess.run(
            cmd, cwd=REPO_DIR, env=env, capture_output=True, text=True, timeout=timeout
        )
        returncode, stdout, stderr = proc.returncode, proc.stdout, proc.stderr
    except subprocess.TimeoutExpired as exc:
        returncode = -1
        stdout = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        stderr = f"timed out after {timeout} s"
    seconds = time.perf_counter() - tic
    (out / f"{name}.log").write_text(stdout + "\n--- stderr ---\n" + stderr)
    result: dict[str, Any] = {}
    if returncode == 0 and accepts_json and json_path.exists():
        result = json.loads(json_path.read_text())
    result.update(
        {
            "benchmark": name,
            "script": script,
            "returncode": returncode,
            "wall_seconds": seconds,
            "command": result.get("command")
            or " ".join(
                ["python", f"benchmarks/{script}", *extra] + (["--quick"] if quick else [])
            ),
        }
    )
    if returncode != 0:
        result["error"] = (stderr or stdout)[-3000:]
        print(f"[run_all] {name} FAILED ({returncode}) after {seconds:.0f} s", flush=True)
        print(result["error"], flush=True)
    elif not accepts_json:
        result["stdout"] = stdout[-6000:]
    print(f"[run_all] {name}: {seconds:.1f} s", flush=True)
    return result


# --------------------------------------------------------------------------- rendering


def render_table(table: dict[str, Any], command: str, machine: str) -> str:
    """A table with the command and machine appended to every row."""
    columns = list(table["columns"]) + ["command", "machine"]
    rows = [list(r) + [f"`{table.get('command', command)}`", machine] for r in table["rows"]]
    title = table.get("title", "")
    text = markdown_table({"columns": columns, "rows": rows})
    note = table.get("note")
    return (f"**{title}**\n\n" if title else "") + text + (f"\n\n{note}" if note else "")


def render_targets(results: list[dict[str, Any]], machine: str) -> dict[str, Any]:
    """All targets of all benchmarks as one table."""
    rows = []
    for res in results:
        for t in res.get("targets", []):
            if t["passed"] is not None:
                status = "PASS" if t["passed"] else "MISS"
            elif t["measured"] is None:
                status = "not measured"
            elif res.get("quick"):
                status = "quick run, not checked"
            else:
                status = "reported"
            measured = t["measured"]
            measured_text = fmt(measured) + (f" {t['unit']}" if t.get("unit") else "")
            rows.append([t["name"], t["target"], measured_text, status, f"`{res['command']}`"])
    return {
        "id": "targets",
        "title": "Targets (issue 6) against measured values",
        "columns": ["target", "wanted", "measured", "status", "command"],
        "rows": rows,
    }


def render_document(results: list[dict[str, Any]], doc_text: str, info: dict[str, Any]) -> str:
    """Rewrite every ``<!-- table:ID -->`` block of ``doc_text`` from ``results``."""
    machine = machine_label(info)
    blocks: dict[str, str] = {}
    targets = render_targets(results, machine)
    blocks["targets"] = markdown_table(targets)
    for res in results:
        command = res.get("command", "")
        for table in res.get("tables", []):
            blocks[table["id"]] = render_table(table, command, machine)
        for pname, ptext in res.get("profiles", {}).items():
            blocks[f"profile_{pname}"] = f"```\n{ptext}\n```"
        if "stdout" in res:
            blocks[f"stdout_{res['benchmark']}"] = (
                f"`{command}` on {machine}:\n\n```\n{res['stdout'].strip()}\n```"
            )
        if res.get("returncode", 0) != 0:
            blocks[f"error_{res['benchmark']}"] = (
                f"`{command}` FAILED:\n\n```\n{res.get('error', '').strip()[-1500:]}\n```"
            )
    blocks["machine"] = (
        f"{info['cores']} cores, {info['cpu_model']}, {info['memory_gb']} GB RAM; "
        f"Python {info['python']}, numpy {info['numpy']}, scipy {info['scipy']}, "
        f"scikit-learn {info['sklearn']}; {info['platform']}; commit {info['git_commit']}; "
        f"run {info['date']}; whole suite {sum(r.get('wall_seconds', 0) for r in results):.0f} s"
    )
    used: set[str] = set()

    def replace(match: re.Match[str]) -> str:
        key = match.group(1)
        if key == "*":
            return match.group(0)
        used.add(key)
        body = blocks.get(key, "_not produced by this run_")
        return f"<!-- table:{key} -->\n{body}\n<!-- /table:{key} -->"

    pattern = re.compile(r"<!-- table:([\w*]+) -->.*?<!-- /table:\1 -->", re.S)
    text = pattern.sub(replace, doc_text)
    rest = [f"{blocks[k]}\n" for k in blocks if k not in used]
    catch_all = re.compile(r"<!-- table:\* -->.*?<!-- /table:\* -->", re.S)
    rest_text = "<!-- table:* -->\n" + "\n".join(rest) + "<!-- /table:* -->"
    if catch_all.search(text):
        text = catch_all.sub(lambda _m: rest_text, text)
    else:
        text = text.rstrip() + "\n\n## Other results\n\n" + rest_text + "\n"
    return text


# --------------------------------------------------------------------------- plots


def save_plots(results: list[dict[str, Any]], out: Path) -> list[Path]:
    """PNG plots of the series the benchmarks returned."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by_name = {r["benchmark"]: r.get("series", {}) for r in results}
    saved: list[Path] = []

    def save(fig: Any, name: str) -> None:
        path = out / name
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        saved.append(path)

    core = by_name.get("core", {})
    scaling = core.get("recluster_scaling")
    if scaling:
        fig, ax = plt.subplots(figsize=(6.5, 4.2))
        for label, pts in scaling.items():
            xs = [p[0] for p in pts if p[1] is not None]
            ys = [p[1] for p in pts if p[1] is not None]
            if xs:
                ax.loglog(xs, ys, "o-", label=label)
        ax.axhline(0.1, color="grey", ls=":", lw=1, label="0.1 s")
        ax.set_xlabel("points in the accumulator")
        ax.set_ylabel("clustering time (s)")
        ax.set_title("Re-clustering time against accumulator size")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        save(fig, "recluster_scaling.png")

    rates = core.get("streaming_rates")
    if rates:
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
        for key, style, name in (
            ("streaming_rates", "-", "simulated"),
            ("streaming_rates_full", "--", "full rows"),
        ):
            runs = core.get(key) or []
            if not runs:
                continue
            mult = [r["rate"] for r in runs]
            ax1.semilogx(mult, [r["p50_ms"] for r in runs], "o" + style, label=f"{name} p50")
            ax1.semilogx(mult, [r["mean_ms"] for r in runs], "^" + style, label=f"{name} mean")
            ax2.loglog(mult, [r["load"] for r in runs], "o" + style, label=name)
        ax1.set_xlabel("input rate (x real time)")
        ax1.set_ylabel("push() time per frame (ms)")
        ax1.grid(True, which="both", alpha=0.3)
        ax1.legend(fontsize=8)
        ax2.axhline(1.0, color="red", ls="--", lw=1, label="falls behind")
        ax2.set_xlabel("input rate (x real time)")
        ax2.set_ylabel("processing s per stream s")
        ax2.grid(True, which="both", alpha=0.3)
        ax2.legend()
        fig.suptitle("Streaming detector, both lidars")
        save(fig, "streaming_rates.png")

    for key, png in (("memory", "memory_rss.png"),):
        memory = by_name.get(key, {})
        if not memory.get("rss_mb"):
            continue
        fig, ax = plt.subplots(figsize=(6.5, 4))
        ax.plot(memory["minute"], memory["rss_mb"], "-", lw=1.2, label="process RSS")
        if memory.get("state_mb"):
            ax.plot(memory["minute"], memory["state_mb"], "-", lw=1.0, label="detector state")
        ax.axhline(500, color="red", ls="--", lw=1, label="target 500 MB")
        ax.set_xlabel("stream time (min)")
        ax.set_ylabel("MB")
        ax.set_ylim(bottom=0)
        ax.grid(True, alpha=0.3)
        ax.legend()
        ax.set_title("Streaming detector memory, full-rate simulated stream")
        save(fig, png)

    node = by_name.get("node", {})
    if node.get("latency_ms"):
        fig, ax = plt.subplots(figsize=(6.5, 4))
        import numpy as np

        lat = np.sort(np.asarray(node["latency_ms"]))
        ax.plot(lat, np.arange(1, len(lat) + 1) / len(lat))
        ax.axvline(50, color="red", ls="--", lw=1, label="target p99 50 ms")
        ax.set_xlabel("publication to /uav/pose (ms)")
        ax.set_ylabel("fraction of frames")
        ax.grid(True, alpha=0.3)
        ax.legend()
        ax.set_title("Node end-to-end latency (CDF)")
        save(fig, "node_latency.png")

    sbs = by_name.get("side_by_side", {})
    if sbs.get("runs"):
        runs = sbs["runs"]
        labels = [r["scenario"] for r in runs]
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
        import numpy as np

        x = np.arange(len(labels))
        ax1.bar(x - 0.2, [r["reference_s"] for r in runs], 0.4, label="reference (sklearn)")
        ax1.bar(x + 0.2, [r["product_s"] for r in runs], 0.4, label="product offline")
        ax1.set_yscale("log")
        ax1.set_xticks(x, labels, rotation=30, ha="right", fontsize=8)
        ax1.set_ylabel("wall time (s)")
        ax1.legend()
        for offset, key, name in (
            (-0.27, "reference_observable_detection", "reference (paper score)"),
            (0.0, "mean_observable_detection", "reference (mean score)"),
            (0.27, "product_observable_detection", "product"),
        ):
            values = [r.get(key) for r in runs]
            ax2.bar(x + offset, [v if v is not None else 0.0 for v in values], 0.27, label=name)
        ax2.set_xticks(x, labels, rotation=30, ha="right", fontsize=8)
        ax2.set_ylabel("detection rate (observable GT samples)")
        ax2.set_ylim(0, 1.05)
        ax2.legend(fontsize=8)
        fig.suptitle("Reference implementation vs product, same sequences")
        save(fig, "side_by_side.png")
    return saved


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="tiny sizes, for CI (< 2 min)")
    parser.add_argument("--out", type=Path, default=None, help="results folder")
    parser.add_argument("--only", default="", help="comma-separated benchmark names")
    parser.add_argument("--doc", type=Path, default=None, help="Markdown file to rewrite")
    parser.add_argument(
        "--long", action="store_true", help="also the benchmarks outside the default suite"
    )
    args = parser.parse_args(argv)
    out = (args.out or DEFAULT_OUT).resolve()
    out.mkdir(parents=True, exist_ok=True)
    doc_path = args.doc or (out / "BENCHMARKS.md" if args.quick else DOC_PATH)
    wanted = {n.strip() for n in args.only.split(",") if n.strip()}
    unknown = wanted - {entry[0] for entry in SUITE}
    if unknown:
        parser.error(f"unknown benchmark(s): {', '.join(sorted(unknown))}")

    info = machine_info()
    tic = time.perf_counter()
    results: list[dict[str, Any]] = []
    for name, script, extra, full_timeout, quick_timeout, default in SUITE:
        if wanted and name not in wanted:
            continue
        if not wanted and not default and not (args.long and not args.quick):
            continue
        if not (BENCH_DIR / script).exists():
            print(f"[run_all] {name}: {script} not present, skipped", flush=True)
            continue
        timeout = quick_timeout if args.quick else full_timeout
        results.append(run_benchmark(name, script, extra, out, args.quick, timeout))

    merged_path = out / "results.json"
    previous: dict[str, Any] = {}
    if merged_path.exists():
        # A partial run keeps the other benchmarks' last results; a full run keeps only
        # those of benchmarks outside the default suite.
        defaults = {entry[0] for entry in SUITE if entry[5]}
        old = json.loads(merged_path.read_text())
        if bool(old.get("quick")) == args.quick:
            previous = {
                r["benchmark"]: r
                for r in old["results"]
                if wanted or r["benchmark"] not in defaults
            }
    previous.update({r["benchmark"]: r for r in results})
    merged = [previous[entry[0]] for entry in SUITE if entry[0] in previous]
    merged_path.write_text(
        json.dumps({"machine": info, "quick": args.quick, "results": merged}, indent=1, default=str)
    )
    plots = save_plots(merged, out)
    template = doc_path if doc_path.exists() else DOC_PATH
    doc_text = template.read_text() if template.exists() else "# Benchmarks\n"
    doc_path.write_text(render_document(merged, doc_text, info))
    total = time.perf_counter() - tic
    failed = [r["benchmark"] for r in results if r.get("returncode", 0) != 0]
    print(f"[run_all] {len(results)} benchmarks in {total:.0f} s; results {merged_path}")
    print(f"[run_all] plots: {', '.join(p.name for p in plots) or 'none'}; doc: {doc_path}")
    if failed:
        print(f"[run_all] FAILED: {', '.join(failed)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
