"""A picture of a simulated sequence: top and side views plus a drone-visibility timeline.

:class:`PreviewCollector` gathers a bounded sample of the points while frames stream
past (every moving-object point, a thinned share of the scene), so an hour-long run
can still be drawn. :func:`draw_preview` writes the PNG with matplotlib's Agg backend.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from clusterfilter_ros.core.frame import AVIA, MID360, TimedPositions
from clusterfilter_ros.sim.raycast import (
    CLASS_BIRD,
    CLASS_CAR,
    CLASS_DRONE,
    CLASS_GROUND,
    CLASS_NOISE,
    CLASS_PERSON,
    CLASS_STRUCTURE,
    CLASS_VEGETATION,
)

_STYLE = {  # class: (legend name, colour, marker size)
    CLASS_GROUND: ("ground", "#b0b0b0", 0.3),
    CLASS_STRUCTURE: ("buildings, cars, posts", "#6d6d6d", 0.3),
    CLASS_VEGETATION: ("trees", "#4f9a4f", 0.3),
    CLASS_PERSON: ("people", "#e08a1e", 2.0),
    CLASS_CAR: ("moving car", "#8a5a00", 2.0),
    CLASS_BIRD: ("birds", "#1f6fd0", 4.0),
    CLASS_NOISE: ("Avia sky noise", "#c040c0", 3.0),
    CLASS_DRONE: ("drone returns", "#e01010", 9.0),
}


@dataclass
class PreviewCollector:
    """Keeps up to ``max_static`` scene points (thinned evenly) and every moving-object point."""

    max_static: int = 150_000
    expected_frames: int = 200
    seed: int = 0
    xyz: list[np.ndarray] = field(default_factory=list)
    classes: list[np.ndarray] = field(default_factory=list)
    drone_hits: dict[str, list[tuple[float, int]]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng(self.seed)

    def add(self, xyz: np.ndarray, classes: np.ndarray, sensor: str, stamp: float) -> None:
        static = (
            (classes == CLASS_GROUND) | (classes == CLASS_STRUCTURE) | (classes == CLASS_VEGETATION)
        )
        share = self.max_static / max(1, self.expected_frames) / max(1, int(static.sum()))
        keep = ~static | (self._rng.random(len(classes)) < share)
        self.xyz.append(np.asarray(xyz, dtype=np.float32)[keep])
        self.classes.append(np.asarray(classes)[keep])
        self.drone_hits.setdefault(sensor, []).append((stamp, int((classes == CLASS_DRONE).sum())))


def draw_preview(
    path: str | os.PathLike[str],
    collector: PreviewCollector,
    drone_truth: TimedPositions,
    ground_truth: TimedPositions | None,
    sensor_positions: dict[str, np.ndarray],
    title: str,
) -> None:
    """Write a PNG: top view (x-y), side view (x-z) and drone hits per second over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    xyz = np.concatenate(collector.xyz) if collector.xyz else np.zeros((0, 3), np.float32)
    cls = np.concatenate(collector.classes) if collector.classes else np.zeros(0, np.int8)
    fig = plt.figure(figsize=(15, 10), dpi=110)
    grid = fig.add_gridspec(2, 2, height_ratios=[2.2, 1.0], width_ratios=[1.0, 1.25])
    ax_top = fig.add_subplot(grid[0, 0])
    ax_side = fig.add_subplot(grid[0, 1])
    ax_time = fig.add_subplot(grid[1, :])
    handles: list = []
    for code in (
        CLASS_GROUND,
        CLASS_STRUCTURE,
        CLASS_VEGETATION,
        CLASS_PERSON,
        CLASS_CAR,
        CLASS_BIRD,
        CLASS_NOISE,
        CLASS_DRONE,
    ):
        name, colour, size = _STYLE[code]
        sel = cls == code
        if not sel.any():
            continue
        pts = xyz[sel]
        ax_top.scatter(pts[:, 0], pts[:, 1], s=size, c=colour, lw=0, rasterized=True)
        ax_side.scatter(pts[:, 0], pts[:, 2], s=size, c=colour, lw=0, rasterized=True)
        handles.append(
            Line2D(
                [], [], ls="", marker="o", ms=5, color=colour, label=f"{name} ({int(sel.sum())})"
            )
        )
    if len(drone_truth):
        d = drone_truth.xyz
        for ax, j in ((ax_top, 1), (ax_side, 2)):
            ax.plot(d[:, 0], d[:, j], "-", color="#900000", lw=1.2)
            ax.plot(d[0, 0], d[0, j], "o", color="#900000", ms=5)
            ax.plot(d[-1, 0], d[-1, j], "x", color="#900000", ms=6)
        handles.append(Line2D([], [], color="#900000", lw=1.2, label="drone path (o start, x end)"))
    if ground_truth is not None and len(ground_truth):
        g = ground_truth.xyz
        ax_side.plot(g[:, 0], g[:, 2], ".", color="#ffb000", ms=1.5)
        handles.append(
            Line2D([], [], ls="", marker=".", color="#ffb000", label="prism (ground truth)")
        )
    for pos in sensor_positions.values():
        for ax, j in ((ax_top, 1), (ax_side, 2)):
            ax.plot(pos[0], pos[j], "s", color="black", ms=6, mec="white")
    handles.append(Line2D([], [], ls="", marker="s", color="black", label="rig (Mid360, Avia)"))
    # Keep the scene readable: far sky noise and long flights beyond it are clipped.
    extent = np.abs(xyz[cls != CLASS_NOISE, :2]).max() if len(xyz) else 50.0
    if len(drone_truth):
        extent = max(extent, np.abs(drone_truth.xyz[:, :2]).max())
    extent = min(extent + 5.0, 200.0)
    ax_top.set_xlim(-extent, extent)
    ax_top.set_ylim(-extent, extent)
    z_top = 45.0 if not len(drone_truth) else max(45.0, drone_truth.xyz[:, 2].max() + 10.0)
    ax_side.set_xlim(-extent, extent)
    ax_side.set_ylim(-5.0, min(z_top, 200.0))
    ax_top.set_title("top view")
    ax_top.set_xlabel("x (m)")
    ax_top.set_ylabel("y (m)")
    ax_top.set_aspect("equal", adjustable="box")
    ax_top.legend(handles=handles, loc="upper left", fontsize=7, framealpha=0.85)
    ax_side.set_title("side view (looking along +y)")
    ax_side.set_xlabel("x (m)")
    ax_side.set_ylabel("z (m)")

    for ax in (ax_top, ax_side):
        ax.grid(True, lw=0.3, alpha=0.5)
    t0 = None
    for sensor, colour in ((MID360, "#d04040"), (AVIA, "#4040d0")):
        rows = collector.drone_hits.get(sensor)
        if not rows:
            continue
        stamps = np.array([r[0] for r in rows])
        hits = np.array([r[1] for r in rows])
        t0 = stamps[0] if t0 is None else t0
        sec = np.floor(stamps - t0).astype(int)
        per_sec = np.bincount(sec, weights=hits)
        ax_time.step(np.arange(len(per_sec)), per_sec, where="post", color=colour, label=sensor)
    if len(drone_truth):
        ax_range = ax_time.twinx()
        t_rel = drone_truth.stamps - (t0 if t0 is not None else drone_truth.stamps[0])
        ax_range.plot(t_rel, np.linalg.norm(drone_truth.xyz, axis=1), color="gray", lw=1)
        ax_range.set_ylabel("drone range (m, grey)")
    ax_time.set_xlabel("time (s)")
    ax_time.set_ylabel("drone returns per second")
    ax_time.set_title("drone visibility")
    ax_time.legend(loc="upper left", fontsize=8)
    ax_time.grid(True, lw=0.3, alpha=0.5)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(os.fspath(path))
    plt.close(fig)
