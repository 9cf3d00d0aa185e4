"""The per-frame input filter (core/preprocess.py)."""

from __future__ import annotations

import numpy as np

from clusterfilter_ros.core.frame import AVIA, MID360, Frame
from clusterfilter_ros.core.params import detector_params
from clusterfilter_ros.core.preprocess import (
    frame_points,
    points_at,
    usable_and_below_floor,
    usable_mask,
)


def test_usable_mask_drops_bad_padding_far_and_low_rows():
    params = detector_params({"max_range": 500.0, "mid360_min_z": 1.0})
    big = np.float32(3.0e38)
    xyz = np.array(
        [
            [10.0, 5.0, 3.0],  # kept
            [np.nan, 1.0, 3.0],  # NaN
            [np.inf, 1.0, 3.0],  # infinite
            [1.0, -np.inf, 3.0],
            [0.0, 0.0, 0.0],  # padding
            [-0.0, 0.0, -0.0],
            [big, 0.0, 0.0],  # finite but far beyond max_range (no float32 overflow)
            [0.0, 400.0, 300.0],  # 500.0 m exactly: kept
            [0.0, 400.0, 300.5],  # just beyond
            [1e-30, 0.0, 0.0],  # tiny but not padding (kept by the range test, low z)
            [5.0, 5.0, 0.5],  # below mid360_min_z
        ],
        dtype=np.float32,
    )
    expect_avia = [True, False, False, False, False, False, False, True, False, True, True]
    expect_mid = [True, False, False, False, False, False, False, True, False, False, False]
    assert usable_mask(Frame(1.0, AVIA, xyz), params).tolist() == expect_avia
    assert usable_mask(Frame(1.0, MID360, xyz), params).tolist() == expect_mid
    assert usable_mask(Frame(1.0, AVIA, xyz.astype(np.float64)), params).tolist() == expect_avia
    assert not usable_mask(Frame(float("nan"), AVIA, xyz), params).any()
    # Below the floor: exactly the rows dropped for their height alone (the tiny one and
    # the low one), for the Mid360 only.
    usable, floor = usable_and_below_floor(Frame(1.0, MID360, xyz), params)
    assert floor.tolist() == [a and not m for a, m in zip(expect_avia, expect_mid, strict=True)]
    assert usable.tolist() == expect_mid
    assert not usable_and_below_floor(Frame(1.0, AVIA, xyz), params)[1].any()
    assert not usable_and_below_floor(Frame(float("nan"), MID360, xyz), params)[1].any()


def test_frame_points_applies_point_times_and_rejects_wild_offsets():
    params = detector_params()
    xyz = np.array([[10.0, 0.0, 5.0], [11.0, 0.0, 5.0], [12.0, 0.0, 5.0]], np.float32)
    offsets = np.array([0.05, np.nan, 7.0])
    pts, t = frame_points(Frame(100.0, AVIA, xyz, point_time=offsets), params)
    assert pts.dtype == np.float32 and pts.shape == (3, 3)
    assert np.allclose(t, [100.05, 100.0, 100.0])


def test_points_at_gives_the_marked_rows_with_their_times():
    xyz = np.array([[10.0, 0.0, -1.0], [11.0, 0.0, 5.0], [12.0, 0.0, -2.0]], np.float32)
    frame = Frame(100.0, MID360, xyz, point_time=np.array([0.01, 0.02, 0.03]))
    pts, t = points_at(frame, usable_and_below_floor(frame, detector_params())[1])
    assert pts.tolist() == [[10.0, 0.0, -1.0], [12.0, 0.0, -2.0]]
    assert np.allclose(t, [100.01, 100.03]) and t.dtype == np.float64
