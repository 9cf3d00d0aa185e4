"""``plots.plot_evaluation``: the figure holds what the caption says."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from clusterfilter_ros.core.frame import TimedPositions
from clusterfilter_ros.plots import plot_evaluation


def _track(stamps, offset=0.0):
    stamps = np.asarray(stamps, dtype=np.float64)
    xyz = np.stack([stamps, 2.0 * stamps, np.full_like(stamps, 20.0)], axis=1) + offset
    return TimedPositions(stamps, xyz)


def _figure_of(monkeypatch, **kwargs):
    figures = []
    real_close = plt.close
    monkeypatch.setattr(plt, "close", lambda fig=None: (figures.append(fig), real_close(fig)))
    path = plot_evaluation(**kwargs)
    assert path.stat().st_size > 10_000
    return figures[-1]


def test_late_estimates_are_drawn_with_their_own_error(tmp_path, monkeypatch):
    gt = _track(np.arange(100) / 10)
    live = _track(np.arange(50, 100) / 10, offset=0.3)
    late = _track(np.arange(20, 100) / 10, offset=0.1)
    fig = _figure_of(
        monkeypatch,
        gt=gt,
        pred=live,
        out_png=tmp_path / "plot.png",
        late=late,
        late_label="3 s late",
    )
    top, _, err_ax = fig.axes
    assert {"ground truth", "live estimate", "3 s late"} <= {ln.get_label() for ln in top.lines}
    lines = {ln.get_label(): ln for ln in err_ax.lines}
    late_err = np.asarray(lines["3 s late error"].get_ydata())
    # Finite from 2 s on (the late output's first estimate), 0.1 * sqrt(3) m off.
    finite = np.isfinite(late_err)
    assert finite.sum() == 80
    np.testing.assert_allclose(late_err[finite], 0.1 * np.sqrt(3.0), atol=1e-9)
    live_err = np.asarray(lines["live 3D error"].get_ydata())
    assert np.isfinite(live_err).sum() == 50


def test_without_late_estimates_only_the_estimate_is_drawn(tmp_path, monkeypatch):
    gt = _track(np.arange(0.0, 5.0, 0.1))
    fig = _figure_of(monkeypatch, gt=gt, pred=_track(gt.stamps), out_png=tmp_path / "p.png")
    labels = {ln.get_label() for ax in fig.axes for ln in ax.lines}
    assert "estimate" in labels and not [lb for lb in labels if "late" in lb or "live" in lb]
