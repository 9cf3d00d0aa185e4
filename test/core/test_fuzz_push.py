"""Property-based fuzzing of :meth:`StreamingDetector.push`: no Frame makes it raise.

Random streams mix ordinary frames with empty frames, NaN/Inf/huge coordinates,
degenerate clouds (every point at one spot), NaN/Inf per-point times and intensities,
duplicate, out-of-order, backwards-jumping, NaN/Inf and huge stamps, unknown sensor
names and a small moving blob (so that the clustering, scoring and track paths run on
the same garbage). Every push must return None or a finite :class:`Estimate` for the
frame's stamp, without raising or emitting numpy RuntimeWarnings, and the state must
stay within its caps; with ``report_lag`` (and no warm-up, so that garbage reaches the
estimates at all) every late estimate is finite and for a frame that was pushed. A
separate test pushes a 2-million-point frame.

Example counts and the 2M-point timing are printed to the terminal (also without -s).
"""

from __future__ import annotations

import math
import os
import time
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from clusterfilter_ros.core.estimate import Estimate
from clusterfilter_ros.core.frame import AVIA, MID360, Frame
from clusterfilter_ros.core.params import detector_params
from clusterfilter_ros.core.streaming import StreamingDetector

EXAMPLES = int(os.environ.get("CLUSTERFILTER_FUZZ_EXAMPLES", "200"))
SPECIAL = [math.nan, math.inf, -math.inf, 3.4e38, -3.4e38, 1e-45, 0.0, 1e7]
STAMP_KINDS = ["next", "next", "next", "same", "back-small", "back-big", "forward-big", "special"]
_seen = {"streams": 0, "frames": 0, "estimates": 0, "rejected": 0, "late": 0}


@st.composite
def frame_streams(draw: st.DrawFn) -> tuple[list[Frame], dict]:
    """A short stream of frames, most of them broken in some way."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    stamp = draw(st.sampled_from([0.0, 1000.0, 1.7e9, -5.0]))
    frames = []
    for i in range(draw(st.integers(1, 25))):
        kind = draw(st.sampled_from(STAMP_KINDS))
        if kind == "next":
            stamp += 0.1
        elif kind == "back-small":
            stamp -= draw(st.sampled_from([0.01, 0.3, 1.0]))
        elif kind == "back-big":
            stamp -= draw(st.sampled_from([10.0, 1e6]))
        elif kind == "forward-big":
            stamp += draw(st.sampled_from([100.0, 1e9]))
        frame_stamp = (
            draw(st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300]))
            if kind == "special"
            else stamp
        )
        n = draw(st.sampled_from([0, 0, 1, 3, 50, 300]))
        shape = draw(st.sampled_from(["random", "random", "blob", "degenerate"]))
        if shape == "blob":  # a small drone-like blob moving at 2 m/s, 20 m up
            centre = np.array([2.0 * 0.1 * i, 5.0, 20.0])
            xyz = centre + rng.normal(0, 0.1, (n, 3))
        elif shape == "degenerate":
            xyz = np.tile(rng.normal(0, 30, 3), (n, 1))
        else:
            xyz = rng.normal(0, 40, (n, 3))
        xyz = xyz.astype(np.float32)
        if n:
            for _ in range(draw(st.integers(0, 3))):
                xyz[draw(st.integers(0, n - 1)), draw(st.integers(0, 2))] = draw(
                    st.sampled_from(SPECIAL)
                )
        intensity = point_time = None
        if draw(st.booleans()):
            intensity = rng.uniform(0, 255, n)
            if n and draw(st.booleans()):
                intensity[0] = draw(st.sampled_from(SPECIAL))
        if draw(st.booleans()):
            point_time = rng.uniform(0, 0.1, n)
            if n and draw(st.booleans()):
                point_time[rng.integers(0, n)] = draw(st.sampled_from(SPECIAL + [-1e9, 1e18]))
        sensor = draw(st.sampled_from([AVIA, MID360, MID360, "", "unknown"]))
        frames.append(Frame(frame_stamp, sensor, xyz, intensity, point_time))
    overrides = draw(
        st.sampled_from(
            [
                {},
                {"recluster_period": 0.0},  # cluster + score after every frame
                {"recluster_period": 0.0, "min_support_frames": 1, "min_confidence": 0.0},
                {"denoise_sensors": ["avia", "mid360"], "recluster_period": 0.2},
                {
                    "recluster_period": 0.0,
                    "min_support_frames": 1,
                    "min_confidence": 0.0,
                    "report_lag": 0.3,
                    "warmup": 0.0,
                },  # late estimates from the same garbage
            ]
        )
    )
    return frames, overrides


def _huge_stamp_then_nothing() -> tuple[list[Frame], dict]:
    """Found by this test: a blob at stamp -1e300, then 2 s of empty frames from 0.1 s.
    The track's sample time rounded off its returns' stamp, and the late output's growth
    of its head had no returns to start from (a ValueError before the guard in
    ``streaming._grown``)."""
    rng = np.random.default_rng(0)
    blob = (np.array([0.0, 5.0, 20.0]) + rng.normal(0, 0.1, (50, 3))).astype(np.float32)
    empty = np.empty((0, 3), np.float32)
    frames = [Frame(-1e300, AVIA, blob)] + [Frame(0.1 * i, AVIA, empty) for i in range(1, 20)]
    overrides = {
        "recluster_period": 0.0,
        "min_support_frames": 1,
        "min_confidence": 0.0,
        "report_lag": 0.3,
        "warmup": 0.0,
    }
    return frames, overrides


@example(stream=_huge_stamp_then_nothing())
@settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(stream=frame_streams())
def _property_push_never_raises(stream: tuple[list[Frame], dict]) -> None:
    frames, overrides = stream
    params = detector_params(overrides)
    det = StreamingDetector(params)
    late = []
    _seen["streams"] += 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning per frame would flood a node's log
        for frame in frames:
            estimate = det.push(frame)
            _seen["frames"] += 1
            if estimate is not None:
                _seen["estimates"] += 1
                assert isinstance(estimate, Estimate)
                assert estimate.stamp == frame.stamp
                assert np.isfinite(estimate.position).all() and estimate.position.shape == (3,)
                assert 0.0 <= estimate.confidence <= 1.0 and estimate.n_points >= 1
            late.extend(det.delayed())
        late.extend(det.flush())
        stats = det.stats()
        points = det.drone_points()
    _seen["rejected"] += int(stats["frames_rejected"])
    assert stats["frames_pushed"] == len(frames)
    assert stats["local_points"] <= params.max_local_points
    assert stats["accumulator_voxels"] <= params.max_accumulator_voxels
    assert points.ndim == 2 and points.shape[1] == 3 and np.isfinite(points).all()
    # Late estimates: finite, each for a frame that was pushed, none left waiting.
    pushed = {f.stamp for f in frames}
    assert stats["delayed_pending"] == 0
    for estimate in late:
        assert estimate.stamp in pushed and np.isfinite(estimate.position).all()
        assert 0.0 <= estimate.confidence <= 1.0 and estimate.n_points >= 1
    _seen["late"] += len(late)


def test_push_never_raises_on_any_frame(capsys: pytest.CaptureFixture[str]) -> None:
    before = dict(_seen)
    _property_push_never_raises()
    got = {k: v - before[k] for k, v in _seen.items()}
    with capsys.disabled():
        print(
            f"\n[fuzz] StreamingDetector.push: {got['streams']} random streams, "
            f"{got['frames']} frames pushed, {got['rejected']} rejected by the detector, "
            f"{got['estimates']} estimates and {got['late']} late ones (all finite)"
        )
    assert got["streams"] >= min(EXAMPLES, 100) and got["frames"] > got["streams"]


def test_two_million_point_frame(capsys: pytest.CaptureFixture[str]) -> None:
    """A 2-million-point frame (20x a real Mid360 frame) is processed, not choked on, and
    the local history cap holds; the detector keeps working on ordinary frames after it."""
    rng = np.random.default_rng(3)
    params = detector_params({"recluster_period": 0.0})
    det = StreamingDetector(params)
    small = [Frame(100.0 + 0.1 * i, MID360, rng.normal(0, 20, (2000, 3))) for i in range(5)]
    for frame in small:
        det.push(frame)
    huge_xyz = rng.uniform(-100, 100, (2_000_000, 3)).astype(np.float32)
    huge_xyz[::1000] = np.nan
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        det.push(Frame(100.5, MID360, huge_xyz))
    seconds = time.perf_counter() - start
    stats = det.stats()
    assert stats["local_points"] <= params.max_local_points
    for i in range(5):
        det.push(Frame(100.6 + 0.1 * i, MID360, rng.normal(0, 20, (2000, 3))))
    after = det.stats()
    assert after["frames_pushed"] == 11 and after["frames_rejected"] == 0
    assert after["local_points"] <= params.max_local_points
    with capsys.disabled():
        print(
            f"\n[fuzz] 2,000,000-point frame pushed in {seconds:.2f} s; local history "
            f"{int(stats['local_points'])} points (cap {params.max_local_points}), "
            f"accumulator {int(stats['accumulator_voxels'])} voxels"
        )
