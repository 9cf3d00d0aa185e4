"""Simulated input for the benchmarks: cached sequences, looped and rate-compressed streams.

- :func:`simulated` runs the project's simulator once per (scenario, seed, duration) and
  caches the result as a pickle under ``~/.cache/clusterfilter_bench`` (keyed by the
  simulator's source code, so a changed simulator regenerates), so the benchmark
  scripts of one suite run do not pay the generation cost several times.
- :func:`stream` loops a pre-generated sequence for as long as wanted, with stamps
  shifted by whole loops, and compresses time by a rate multiple ``k`` (stamps and
  per-point times divided by ``k``), so the detector sees ``k`` times more frames per
  second of stream time.
- :func:`full_row_frames` turns a sequence into the worst case for throughput: every
  row of the lidar's MMAUD frame is a real return (20,064 Mid360 and 24,000 Avia points
  per frame, instead of the ~4k and 0-178 real points of a real recording).
"""

from __future__ import annotations

import hashlib
import os
import pickle
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from clusterfilter_ros.core.frame import AVIA, MID360, Frame

#: Rows per frame in the MMAUD challenge files (REFERENCE section 2).
MID360_ROWS = 20_064
AVIA_ROWS = 24_000
FULL_ROWS = {MID360: MID360_ROWS, AVIA: AVIA_ROWS}

CACHE_DIR = Path(os.environ.get("CLUSTERFILTER_BENCH_CACHE", Path.home() / ".cache"))
CACHE_DIR = CACHE_DIR / "clusterfilter_bench"


def sim_fingerprint() -> str:
    """Hash of the simulator's source files (cache key part)."""
    import clusterfilter_ros.sim as sim_pkg

    digest = hashlib.sha1()
    for path in sorted(Path(sim_pkg.__file__).parent.glob("*.py")):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def simulated(scenario: str, seed: int, duration: float) -> Any:
    """The simulator's ``SimulatedSequence`` for these arguments (cached on disk)."""
    from clusterfilter_ros.sim.scenarios import simulate

    key = f"{scenario}-{seed}-{duration:g}-{sim_fingerprint()}"
    path = CACHE_DIR / f"{key}.pkl"
    if path.exists():
        try:
            with path.open("rb") as fh:
                return pickle.load(fh)
        except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ImportError):
            path.unlink(missing_ok=True)
    result = simulate(scenario, seed=seed, duration=duration)
    CACHE_DIR.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    with tmp.open("wb") as fh:
        pickle.dump(result, fh, protocol=pickle.HIGHEST_PROTOCOL)
    tmp.replace(path)
    return result


def sequence_span(frames: list[Frame]) -> tuple[float, float]:
    """(first stamp, loop length) of a time-ordered frame list; the loop length adds one
    frame period so that looped copies do not overlap."""
    stamps = np.array([f.stamp for f in frames])
    sensors = np.array([f.sensor for f in frames])
    gaps = [np.diff(np.sort(stamps[sensors == s])) for s in np.unique(sensors)]
    gaps_all = np.concatenate(gaps) if gaps else np.empty(0)
    period = float(np.median(gaps_all)) if gaps_all.size else 0.1
    return float(stamps.min()), float(stamps.max() - stamps.min()) + period


def stream(
    frames: list[Frame], rate: float = 1.0, stream_seconds: float | None = None
) -> Iterator[Frame]:
    """Frames of ``frames`` looped and time-compressed by ``rate``.

    Yields frames until ``stream_seconds`` of (compressed) stream time have passed
    (default: one pass over the input). Stamps: ``t0 + (stamp + loop * length - t0) / rate``.
    """
    frames = sorted(frames, key=lambda f: f.stamp)
    if not frames:
        return
    t0, length = sequence_span(frames)
    limit = stream_seconds if stream_seconds is not None else length / rate
    loop = 0
    while True:
        for f in frames:
            new_stamp = t0 + (f.stamp + loop * length - t0) / rate
            if new_stamp - t0 >= limit:
                return
            pt = None if f.point_time is None else f.point_time / rate
            yield Frame(new_stamp, f.sensor, f.xyz, f.intensity, pt)
        loop += 1


def full_row_frames(frames: list[Frame], seed: int = 0, min_z: float = 3.5) -> list[Frame]:
    """Each frame filled up to its MMAUD row count with real-looking returns.

    Mid360 frames are topped up with jittered (3 cm) copies of the frame's own returns
    (denser walls, ground and trees: the same scene seen with every ray returning);
    Avia frames with jittered copies of their own points and of the above-ground
    (z > ``min_z``) returns of the nearest Mid360 frame (structure overhead: canopies,
    walls, as if the Avia saw them). This is a throughput stress case, not a realistic
    recording.
    """
    rng = np.random.default_rng(seed)
    frames = sorted(frames, key=lambda f: f.stamp)
    mid = [f for f in frames if f.sensor == MID360]
    mid_stamps = np.array([f.stamp for f in mid]) if mid else np.empty(0)
    out: list[Frame] = []
    for f in frames:
        rows = FULL_ROWS.get(f.sensor)
        if rows is None or len(f) >= rows:
            out.append(f)
            continue
        source = f.xyz
        if f.sensor == AVIA and mid:
            j = int(np.clip(np.searchsorted(mid_stamps, f.stamp), 0, len(mid) - 1))
            m = mid[j].xyz
            source = np.concatenate([f.xyz, m[m[:, 2] > min_z]])
        if len(source) == 0:
            out.append(f)
            continue
        extra = rows - len(f)
        pick = rng.integers(0, len(source), extra)
        filler = source[pick] + rng.normal(0.0, 0.03, (extra, 3)).astype(np.float32)
        xyz = np.concatenate([f.xyz, filler.astype(np.float32)])
        pt = None
        if f.point_time is not None:
            pt = np.concatenate([f.point_time, rng.uniform(0, 0.1, extra)])
        intensity = None
        if f.intensity is not None:
            intensity = np.concatenate([f.intensity, np.full(extra, 10.0, np.float32)])
        out.append(Frame(f.stamp, f.sensor, xyz, intensity, pt))
    return out


def frame_counts(frames: list[Frame]) -> dict[str, float]:
    """Mean points per frame for each sensor."""
    out: dict[str, float] = {}
    for sensor in sorted({f.sensor for f in frames}):
        n = [len(f) for f in frames if f.sensor == sensor]
        out[sensor] = float(np.mean(n)) if n else 0.0
    return out
