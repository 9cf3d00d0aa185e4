"""The detector node under bad input, in-process (one rclpy context, loopback DDS).

Each kind of fault is published on the lidar topics of a running node; the node must
reject (malformed) or repair (big-endian, NaN/Inf, padding, empty) every message, count
it in ``/diagnostics``, keep going and keep detecting. Stamp faults (duplicates, out of
order, jumps back), a silent lidar, a 2-million-point cloud and invalid parameter
updates are covered too. Log throttling is checked in ``test_node_garbage_process.py``
(the node's log is only visible from outside the process).
"""

from __future__ import annotations

import array
import math

import numpy as np
import pytest

pytest.importorskip("rclpy")

from clusterfilter_ros.core.frame import AVIA, MID360, Frame  # noqa: E402
from clusterfilter_ros.core.params import detector_params  # noqa: E402
from clusterfilter_ros.core.streaming import run_streaming  # noqa: E402
from clusterfilter_ros.io.pointcloud2 import (  # noqa: E402
    CloudMessage,
    FieldSpec,
    Header,
    Stamp,
    make_pointcloud2,
    pointcloud2_to_frame,
    seconds_to_stamp,
    structured_to_cloud_message,
)

pytestmark = pytest.mark.ros


def ros_cloud(msg: CloudMessage):
    """An rclpy PointCloud2 with exactly the (possibly inconsistent) fields of ``msg``."""
    from sensor_msgs.msg import PointCloud2, PointField

    out = PointCloud2()
    out.header.stamp.sec = int(msg.header.stamp.sec)
    out.header.stamp.nanosec = int(msg.header.stamp.nanosec)
    out.header.frame_id = msg.header.frame_id
    out.height, out.width = int(msg.height), int(msg.width)
    out.fields = [
        PointField(name=f.name, offset=f.offset, datatype=f.datatype, count=f.count)
        for f in msg.fields
    ]
    out.is_bigendian = bool(msg.is_bigendian)
    out.point_step, out.row_step = int(msg.point_step), int(msg.row_step)
    out.data = array.array("B", bytes(msg.data))
    out.is_dense = bool(msg.is_dense)
    return out


def xyz_cloud(xyz: np.ndarray, stamp: float, big_endian: bool = False, **layout) -> CloudMessage:
    """A cloud of float32 x, y, z (optionally big-endian, padded, organised)."""
    order = ">" if big_endian else "<"
    dtype = np.dtype(
        {
            "names": ["x", "y", "z"],
            "formats": [order + "f4"] * 3,
            "offsets": [0, 4, 8],
            "itemsize": layout.pop("point_step", 12),
        }
    )
    points = np.zeros(len(xyz), dtype=dtype)
    for i, axis in enumerate("xyz"):
        points[axis] = xyz[:, i]
    return structured_to_cloud_message(points, stamp=stamp, **layout)


def _raw(stamp: float, fields, point_step, width, data, height=1, row_step=None, big=False):
    sec, nanosec = seconds_to_stamp(stamp)
    return CloudMessage(
        header=Header(Stamp(sec, nanosec), "avia"),
        height=height,
        width=width,
        fields=[FieldSpec(*f) for f in fields],
        is_bigendian=big,
        point_step=point_step,
        row_step=width * point_step if row_step is None else row_step,
        data=data,
    )


XYZ = [("x", 0, 7), ("y", 4, 7), ("z", 8, 7)]
#: (name, message) pairs the node must reject as malformed.
MALFORMED = [
    ("no x/y/z fields", _raw(10.0, [("a", 0, 7), ("b", 4, 7), ("c", 8, 7)], 12, 4, bytes(48))),
    ("no z field", _raw(10.1, XYZ[:2], 12, 4, bytes(48))),
    ("no fields at all", _raw(10.2, [], 12, 4, bytes(48))),
    ("data shorter than width*point_step", _raw(10.3, XYZ, 12, 100, bytes(60))),
    ("data longer than height*row_step", _raw(10.4, XYZ, 12, 4, bytes(100))),
    ("row_step < width*point_step", _raw(10.5, XYZ, 12, 4, bytes(48), row_step=40)),
    ("row_step inconsistent with data", _raw(10.6, XYZ, 12, 4, bytes(96), height=2, row_step=60)),
    ("point_step 0", _raw(10.7, XYZ, 0, 4, bytes(48))),
    ("field beyond point_step", _raw(10.8, XYZ + [("i", 12, 7)], 12, 4, bytes(48))),
    ("unknown datatype 9", _raw(10.9, [("x", 0, 9), ("y", 4, 7), ("z", 8, 7)], 12, 4, bytes(48))),
    ("duplicate field x", _raw(11.0, XYZ + [("x", 0, 7)], 12, 4, bytes(48))),
    ("x with count 3", _raw(11.1, [("x", 0, 7, 3), ("y", 4, 7), ("z", 8, 7)], 12, 4, bytes(48))),
    ("width 2**32-1 with 48 bytes", _raw(11.2, XYZ, 12, 2**32 - 1, bytes(48), row_step=2**32 - 1)),
]


def _statuses(node) -> dict:
    """``{short status name: (level, message, {key: value})}`` of one diagnostics message."""
    out = {}
    for s in node.diagnostics().status:
        out[s.name.split(": ")[-1]] = (s.level, s.message, {kv.key: kv.value for kv in s.values})
    return out


def _spy_on_push(node) -> list[Frame]:
    """Record every frame the node's worker pushes into its StreamingDetector."""
    pushed: list[Frame] = []
    detector = node._detector
    original = detector.push

    def push(frame: Frame):
        pushed.append(frame)
        return original(frame)

    detector.push = push
    return pushed


def _publish(rig, sensor: str, msgs, wait_for, expect_received: int) -> None:
    assert rig.replayer.wait_for_subscribers(10.0, settle=0.3)
    for msg in msgs:
        rig.replayer.publishers[sensor].publish(
            ros_cloud(msg) if isinstance(msg, CloudMessage) else msg
        )
    assert wait_for(lambda: rig.detector.counters()["received"][sensor] >= expect_received, 20.0), (
        rig.detector.counters()
    )
    assert rig.detector.wait_until_idle(20.0)


def test_malformed_clouds_are_rejected_counted_and_survived(make_rig, small_sequence, wait_for):
    from diagnostic_msgs.msg import DiagnosticStatus

    rig = make_rig(qos_depth=1000, max_queue=1000, sync_timeout=1.0, stale_timeout=30.0)
    _publish(rig, AVIA, [m for _, m in MALFORMED], wait_for, len(MALFORMED))
    counters = rig.detector.counters()
    assert counters["rejected"][AVIA] == len(MALFORMED), counters
    assert counters["processed"] == 0 and counters["errors"] == 0
    status = _statuses(rig.detector)
    level, message, values = status["avia input"]
    assert level == DiagnosticStatus.ERROR and "rejected" in message
    assert values["rejected_malformed"] == str(len(MALFORMED))
    assert status["detector"][0] == DiagnosticStatus.ERROR  # "input rejected"
    # The node still works: the clean sequence afterwards gives the streaming core's poses.
    frames = small_sequence.frames
    rig.replayer.play(frames, rate=0.0)
    assert wait_for(
        lambda: sum(rig.detector.counters()["received"].values()) >= len(MALFORMED) + len(frames),
        30.0,
    )
    assert rig.detector.wait_until_idle(30.0)
    wire = [pointcloud2_to_frame(make_pointcloud2(f, f.sensor), f.sensor) for f in frames]
    expected = run_streaming(wire, detector_params())
    assert wait_for(lambda: len(rig.recorder) >= len(expected), 10.0)
    assert len(rig.recorder) == len(expected) > 0
    status = _statuses(rig.detector)
    assert status["avia input"][2]["rejected_malformed"] == str(len(MALFORMED))
    assert status["avia input"][0] == DiagnosticStatus.OK  # this period: all accepted
    # The last pose's confidence and support, which a PoseStamped cannot carry.
    values = status["detector"][2]
    assert float(values["last_estimate_stamp"]) == expected[-1].stamp
    assert float(values["last_estimate_confidence"]) == pytest.approx(
        expected[-1].confidence, abs=1e-3
    )
    assert int(values["last_estimate_points"]) == expected[-1].n_points


def test_repairable_clouds_are_decoded_exactly(make_rig, wait_for):
    """Big-endian, NaN/Inf coordinates, padded points, padded rows, organised clouds,
    float64 fields, empty and all-NaN clouds are all accepted; the detector gets exactly
    the finite points and the dropped ones are counted."""
    rng = np.random.default_rng(1)
    rig = make_rig(qos_depth=1000, sync_timeout=0.0, stale_timeout=30.0)
    pushed = _spy_on_push(rig.detector)
    xyz = rng.normal(0, 20, (60, 3)).astype(np.float32)
    with_bad = xyz.copy()
    with_bad[::7, 0] = np.nan
    with_bad[3::11, 2] = np.inf
    with_bad[5, 1] = -np.inf
    n_bad = int((~np.isfinite(with_bad).all(axis=1)).sum())
    f64 = np.zeros(60, dtype=[("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("intensity", ">f4")])
    for i, a in enumerate("xyz"):
        f64[a] = xyz[:, i]
    cases = [
        ("little-endian", xyz_cloud(xyz, 20.0), xyz),
        ("big-endian", xyz_cloud(xyz, 20.1, big_endian=True), xyz),
        ("NaN/Inf coordinates", xyz_cloud(with_bad, 20.2), with_bad[np.isfinite(with_bad).all(1)]),
        (
            "big-endian NaN/Inf",
            xyz_cloud(with_bad, 20.3, True),
            with_bad[np.isfinite(with_bad).all(1)],
        ),
        ("padded points", xyz_cloud(xyz, 20.4, point_step=32), xyz),
        ("organised 3 rows + row padding", xyz_cloud(xyz, 20.5, height=3, row_padding=5), xyz),
        ("big-endian float64 + intensity", structured_to_cloud_message(f64, stamp=20.6), xyz),
        ("empty cloud", xyz_cloud(xyz[:0], 20.7), xyz[:0]),
        ("all points NaN", xyz_cloud(np.full((10, 3), np.nan, np.float32), 20.8), xyz[:0]),
    ]
    _publish(rig, AVIA, [c[1] for c in cases], wait_for, len(cases))
    counters = rig.detector.counters()
    assert counters["rejected"][AVIA] == 0 and counters["processed"] == len(cases), counters
    assert len(pushed) == len(cases)
    for (name, _, expected), frame in zip(cases, pushed, strict=True):
        np.testing.assert_array_equal(frame.xyz, expected, err_msg=name)
    values = _statuses(rig.detector)["avia input"][2]
    assert values["nonfinite_points_dropped"] == str(2 * n_bad + 10)


def test_stamp_faults_dropped_or_reset_and_counted(make_rig, small_sequence, wait_for):
    """Duplicates and small steps back are dropped (dropped_late); a jump back by more
    than backwards_tolerance resets the detector (resets); the detector only ever sees
    increasing stamps within a generation and detects again after the reset."""
    rng = np.random.default_rng(2)

    def cloud(stamp):
        return xyz_cloud(rng.normal(0, 20, (50, 3)).astype(np.float32), stamp)

    rig = make_rig(qos_depth=1000, max_queue=1000, sync_timeout=0.5, stale_timeout=30.0)
    pushed = _spy_on_push(rig.detector)
    stamps = [50.0, 50.1, 50.1, 50.2, 50.15, 50.3, 50.3, 50.05, 50.4]  # dups, out of order
    _publish(rig, AVIA, [cloud(t) for t in stamps], wait_for, len(stamps))
    counters = rig.detector.counters()
    assert [f.stamp for f in pushed] == pytest.approx([50.0, 50.1, 50.2, 50.3, 50.4])
    assert counters["dropped_late"] == 4 and counters["resets"] == 0, counters
    values = _statuses(rig.detector)["detector"][2]
    assert values["dropped_late"] == "4"
    # The clock jumps back 40 s (a restarted driver): reset, then the drone is found again.
    frames = small_sequence.frames  # stamps 100 .. 108 s
    shifted = [Frame(f.stamp - 90.0, f.sensor, f.xyz) for f in frames]  # 10 .. 18 s
    rig.replayer.play(shifted, rate=0.0)
    assert wait_for(lambda: rig.detector.counters()["processed"] >= 5 + len(frames), 30.0)
    assert rig.detector.wait_until_idle(30.0)
    counters = rig.detector.counters()
    assert counters["resets"] == 1 and _statuses(rig.detector)["detector"][2]["resets"] == "1"
    wire = [pointcloud2_to_frame(make_pointcloud2(f, f.sensor), f.sensor) for f in shifted]
    expected = run_streaming(wire, detector_params())
    assert wait_for(lambda: len(rig.recorder) >= len(expected), 10.0)
    got = rig.recorder.positions()
    np.testing.assert_array_equal(got.xyz, [e.position for e in expected])


def test_silent_lidar_warn_then_stale_and_detection_continues(make_rig, small_sequence, wait_for):
    """The Mid360 stops half-way: the node keeps detecting from the Avia alone (frames
    released after sync_timeout), /diagnostics says WARN naming the Mid360; when the Avia
    stops too it says STALE."""
    from diagnostic_msgs.msg import DiagnosticStatus

    rig = make_rig(qos_depth=1000, max_queue=1000, sync_timeout=0.1, stale_timeout=0.5)
    frames = small_sequence.frames
    cut = frames[len(frames) // 2].stamp
    assert rig.replayer.wait_for_subscribers(10.0, ["/uav/pose"], settle=0.3)
    rig.replayer.play([f for f in frames if f.stamp < cut], rate=0.0)
    n_first = sum(f.stamp < cut for f in frames)
    assert wait_for(lambda: rig.detector.counters()["processed"] >= n_first - 2, 20.0)
    avia_rest = [f for f in frames if f.stamp >= cut and f.sensor == AVIA]
    levels = []
    rig.replayer.play(
        avia_rest, rate=2.0, on_frame=lambda f: levels.append(_statuses(rig.detector)["detector"])
    )
    assert rig.detector.wait_until_idle(10.0)
    warn = [m for lvl, m, _ in levels if lvl == DiagnosticStatus.WARN and MID360 in m]
    assert warn, levels[-3:]  # the Mid360 reported silent while the Avia carried on
    poses = rig.recorder.positions()
    late = poses.stamps[poses.stamps > cut + 1.0]
    avia_late = sum(f.stamp > cut + 1.0 for f in avia_rest)
    assert len(late) >= 0.5 * avia_late, (len(late), avia_late)
    gt = small_sequence.ground_truth
    truth = np.column_stack([np.interp(late, gt.stamps, gt.xyz[:, i]) for i in range(3)])
    err = np.linalg.norm(poses.xyz[poses.stamps > cut + 1.0] - truth, axis=1)
    assert np.median(err) < 1.0, np.median(err)
    assert wait_for(lambda: _statuses(rig.detector)["detector"][0] == DiagnosticStatus.STALE, 5.0)
    status = _statuses(rig.detector)
    assert status["avia input"][0] == status["mid360 input"][0] == DiagnosticStatus.STALE


def test_two_million_point_cloud(make_rig, wait_for, capsys):
    """A 2,000,000-point cloud (about 20x a real frame, 24 MB) is decoded and processed;
    the node stays responsive and processes the next clouds."""
    import time

    rng = np.random.default_rng(3)
    rig = make_rig(qos_depth=10, sync_timeout=0.0, stale_timeout=30.0)
    huge = rng.uniform(-100, 100, (2_000_000, 3)).astype(np.float32)
    msg = ros_cloud(xyz_cloud(huge, 30.0))
    started = time.monotonic()
    _publish(rig, MID360, [msg], wait_for, 1)
    seconds = time.monotonic() - started
    small = [
        xyz_cloud(rng.normal(0, 20, (100, 3)).astype(np.float32), 30.1 + 0.1 * i) for i in range(5)
    ]
    _publish(rig, MID360, small, wait_for, 6)
    counters = rig.detector.counters()
    assert counters["processed"] == 6 and counters["errors"] == 0, counters
    values = _statuses(rig.detector)["detector"][2]
    assert float(values["detector_local_points"]) <= detector_params().max_local_points
    with capsys.disabled():
        print(f"\n[node] 2,000,000-point PointCloud2 received and processed in {seconds:.2f} s")


def _plain(value):
    return value if isinstance(value, (str, int, float, bool)) else list(value)


INVALID_UPDATES = [
    ("eps", math.nan),
    ("eps", math.inf),
    ("eps", -1.0),
    ("eps", "wide"),
    ("min_samples", 2.5),
    ("min_samples", -3),
    ("voxel_size", 0.0),
    ("target_offset", [1.0, 2.0]),
    ("target_offset", [1.0, math.nan, 0.0]),
    ("avia_extrinsic", [0.0] * 7),
    ("avia_extrinsic", [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
    ("mid360_extrinsic", [math.inf, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]),
    ("scoring", "magic"),
    ("denoise_sensors", ["sonar"]),
    ("avia_topic", "/elsewhere"),
    ("qos_depth", 5),
    ("stale_timeout", -1.0),
    ("max_queue", 0),
]


def test_invalid_parameter_updates_rejected_and_node_keeps_working(
    make_rig, small_sequence, wait_for
):
    from rclpy.parameter import Parameter

    rig = make_rig(qos_depth=1000, max_queue=1000, sync_timeout=1.0)
    node = rig.detector
    before = {p.name: p.value for p in node.get_parameters([n for n, _ in INVALID_UPDATES])}
    core_before = node._detector.params.as_dict()
    accepted = []
    for name, value in INVALID_UPDATES:
        try:
            result = node.set_parameters([Parameter(name, value=value)])[0]
        except Exception as exc:  # rclpy refuses some before our callback sees them
            result = None
            assert "Parameter" in type(exc).__name__ or isinstance(exc, (TypeError, ValueError))
        if result is not None and result.successful:
            accepted.append((name, value))
    assert accepted == []
    # All or nothing: a valid and an invalid value together change neither.
    both = node.set_parameters_atomically(
        [Parameter("eps", value=1.7), Parameter("min_samples", value=-1)]
    )
    assert not both.successful
    after = {p.name: p.value for p in node.get_parameters([n for n, _ in INVALID_UPDATES])}
    assert {k: _plain(v) for k, v in after.items()} == {k: _plain(v) for k, v in before.items()}
    assert node._detector.params.as_dict() == core_before
    # Still detecting, with the untouched parameters.
    frames = small_sequence.frames
    rig.replayer.play(frames, rate=0.0)
    assert wait_for(lambda: node.counters()["processed"] >= len(frames), 30.0)
    expected = run_streaming(
        [pointcloud2_to_frame(make_pointcloud2(f, f.sensor), f.sensor) for f in frames]
    )
    assert wait_for(lambda: len(rig.recorder) >= len(expected) > 0, 10.0)
