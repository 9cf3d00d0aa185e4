"""Figures of detections against ground truth (matplotlib, Agg backend, no display)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from clusterfilter_ros.core.frame import TimedPositions


def plot_evaluation(
    gt: TimedPositions | None,
    pred: TimedPositions,
    out_png: str | os.PathLike[str],
    drone_points: np.ndarray | None = None,
    title: str = "",
    max_gap: float = 0.3,
    late: TimedPositions | None = None,
    late_label: str = "delayed estimate",
) -> Path:
    """Top view (x-y), side view (x-z) and 3D error over time; written to ``out_png``.

    ``drone_points``: optional (M, 3) or (M, 4) ``[t,] x, y, z`` points the detector
    attributed to the drone (drawn green, as in the paper's figure 4). Ground truth is
    red, estimates blue; ``late``: optional second estimates (such as the ``report_lag``
    output), drawn orange as ``late_label``. Returns the written path.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from clusterfilter_ros.core.evaluation import interpolate_predictions
    from clusterfilter_ros.io.atomic import atomic_output_path

    live = "live " if late is not None else ""  # names the estimates apart from ``late``
    fig = plt.figure(figsize=(13, 4.6))
    ax_top = fig.add_subplot(1, 3, 1)
    ax_side = fig.add_subplot(1, 3, 2)
    ax_err = fig.add_subplot(1, 3, 3)
    pts = None
    if drone_points is not None and len(drone_points):
        dp = np.asarray(drone_points, dtype=np.float64)
        pts = dp[:, -3:]
        if pts.shape[0] > 20000:
            pts = pts[np.linspace(0, pts.shape[0] - 1, 20000).astype(int)]
    for ax, (a, b), labels in (
        (ax_top, (0, 1), ("x (m)", "y (m)")),
        (ax_side, (0, 2), ("x (m)", "z (m)")),
    ):
        if pts is not None:
            ax.scatter(pts[:, a], pts[:, b], s=2, c="tab:green", alpha=0.4, label="drone points")
        if gt is not None and len(gt):
            ax.plot(gt.xyz[:, a], gt.xyz[:, b], "-", c="tab:red", lw=1.5, label="ground truth")
        if late is not None and len(late):
            ax.plot(late.xyz[:, a], late.xyz[:, b], ".", c="tab:orange", ms=5, label=late_label)
        if len(pred):
            ax.plot(
                pred.xyz[:, a], pred.xyz[:, b], ".", c="tab:blue", ms=3, label=f"{live}estimate"
            )
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)
    ax_top.set_title("top view")
    ax_side.set_title("side view")
    ax_top.legend(loc="best", fontsize=8)
    t0 = None
    if gt is not None and len(gt):
        t0 = gt.stamps[0]

        def errors(series: TimedPositions) -> np.ndarray:
            matched = interpolate_predictions(series, gt.stamps, max_gap)
            return np.linalg.norm(matched - gt.xyz, axis=1)

        if late is not None and len(late):
            ax_err.plot(
                gt.stamps - t0, errors(late), ".", c="tab:orange", ms=5, label=f"{late_label} error"
            )
        err = errors(pred)
        ax_err.plot(gt.stamps - t0, err, ".", c="tab:blue", ms=3, label=f"{live}3D error")
        missing = ~np.isfinite(err)
        if missing.any():
            ax_err.plot(
                gt.stamps[missing] - t0,
                np.zeros(int(missing.sum())),
                "|",
                c="tab:red",
                ms=8,
                label=f"no {live}estimate",
            )
        ax_err.set_ylabel("3D error (m)")
        ax_err.legend(loc="best", fontsize=8)
    elif len(pred):
        t0 = pred.stamps[0]
        ax_err.plot(pred.stamps - t0, np.ones(len(pred)), "|", c="tab:red", label="reported")
        ax_err.set_ylabel("reports (no ground truth)")
        ax_err.legend(loc="best", fontsize=8)
    ax_err.set_xlabel("time (s)" if t0 is None else f"time since {t0:.2f} (s)")
    ax_err.set_title("error over time")
    ax_err.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    out = Path(out_png)
    with atomic_output_path(out, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return out
