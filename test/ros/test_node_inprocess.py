"""The detector node in-process: poses, equality with run_streaming, parameters,
diagnostics, looped stamps, malformed clouds (one rclpy context, loopback DDS)."""

from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np
import pytest

pytest.importorskip("rclpy")

from clusterfilter_ros.core.params import detector_params  # noqa: E402
from clusterfilter_ros.core.streaming import run_streaming  # noqa: E402

pytestmark = pytest.mark.ros


def replay_and_wait(rig, frames, expected_frames, wait_for, timeout=60.0, rate=0.0):
    assert rig.replayer.wait_for_subscribers(10.0, ["/uav/pose"], settle=0.3)
    stats = rig.replayer.play(frames, rate=rate)
    assert wait_for(
        lambda: sum(rig.detector.counters()["received"].values()) >= expected_frames, timeout
    ), rig.detector.counters()
    assert rig.detector.wait_until_idle(timeout)
    return stats


def on_the_wire(frames):
    """The frames as the node decodes them: livox PointCloud2 and back (stamps in ns)."""
    from clusterfilter_ros.io.pointcloud2 import make_pointcloud2, pointcloud2_to_frame

    return [pointcloud2_to_frame(make_pointcloud2(f, f.sensor), f.sensor) for f in frames]


def test_node_poses_equal_run_streaming(make_rig, small_sequence, wait_for):
    frames = small_sequence.frames
    expected = run_streaming(on_the_wire(frames), detector_params())
    assert len(expected) > 50
    rig = make_rig(qos_depth=1000, max_queue=1000, sync_timeout=1.0)
    replay_and_wait(rig, frames, len(frames), wait_for)
    counters = rig.detector.counters()
    assert counters["processed"] == len(frames), counters
    # Nothing arrived after a later frame was processed, so the order was stamp order.
    assert counters["dropped_late"] == 0 and counters["dropped_queue_full"] == 0, counters
    assert wait_for(lambda: len(rig.recorder) >= len(expected), 10.0)
    got = rig.recorder.positions()
    assert len(got) == len(expected)
    # Same frames, same order, same core: identical poses.
    np.testing.assert_array_equal(got.xyz, np.array([e.position for e in expected]))
    np.testing.assert_allclose(got.stamps, [e.stamp for e in expected], rtol=0, atol=1e-9)
    # Against the original float stamps (before nanosecond rounding) only rounding differs.
    original = run_streaming(frames, detector_params())
    assert len(original) == len(got)
    np.testing.assert_allclose(got.xyz, [e.position for e in original], rtol=0, atol=1e-9)
    assert rig.recorder.drone_points().shape[0] > 0
    # /uav/path: the last path_length (default 200) poses, in the output frame.
    assert wait_for(lambda: len(rig.paths) == len(expected), 10.0)
    last = rig.paths[-1]
    assert last.header.frame_id == "map" and len(last.poses) == min(200, len(expected))
    assert last.poses[-1].pose.position.x == got.xyz[-1, 0]


def test_node_with_background_reclustering_tracks_like_run_streaming(
    make_rig, small_sequence, wait_for
):
    # The node's default: re-clusterings on a worker thread, applied when they finish
    # (within recluster_period of stream time), so poses can differ from
    # run_streaming's where a re-clustering changed the track.
    frames = small_sequence.frames
    expected = run_streaming(on_the_wire(frames), detector_params())
    rig = make_rig(qos_depth=1000, max_queue=1000, sync_timeout=1.0, recluster_in_background=True)
    replay_and_wait(rig, frames, len(frames), wait_for)
    counters = rig.detector.counters()
    assert counters["processed"] == len(frames) and counters["errors"] == 0, counters
    wait_for(lambda: len(rig.recorder) >= 0.8 * len(expected), 10.0)
    got = rig.recorder.positions()
    print(f"background: {len(got)} poses, run_streaming {len(expected)}")
    # Replayed as fast as possible (rate 0), every re-clustering lags by up to
    # recluster_period (0.5 s) of stream time, so the track is confirmed up to 0.5 s later.
    assert 0.8 * len(expected) <= len(got) <= 1.05 * len(expected)
    assert got.stamps[0] <= expected[0].stamp + 0.5 + 0.05
    by_stamp = {round(e.stamp, 6): e.position for e in expected}
    common = [
        (p, by_stamp[round(s, 6)])
        for s, p in zip(got.stamps, got.xyz, strict=True)
        if round(s, 6) in by_stamp
    ]
    assert len(common) >= 0.8 * len(expected)
    diff = np.array([np.linalg.norm(a - b) for a, b in common])
    print(f"differences at common stamps: median {np.median(diff):.3g} m, max {diff.max():.3g} m")
    assert np.median(diff) < 0.05 and np.mean(diff < 0.5) >= 0.95


@pytest.mark.parametrize("backfill", [0.0, 5.0])
def test_delayed_poses_equal_run_streaming_with_report_lag(
    make_rig, small_sequence, wait_for, backfill
):
    # With report_backfill the frames before the confirmation come in one burst.
    from clusterfilter_ros.ros.node import DELAYED_POSE_TOPIC
    from clusterfilter_ros.ros.record import PoseRecorder

    frames = small_sequence.frames
    values = {"report_lag": 2.0, "report_backfill": backfill}
    expected = run_streaming(on_the_wire(frames), detector_params(values))
    assert len(expected) > 50
    if backfill:  # the burst is there
        plain = {"report_lag": 2.0, "report_backfill": 0.0}
        lagged = run_streaming(on_the_wire(frames), detector_params(plain))
        assert len(expected) > len(lagged) + 10
    rig = make_rig(qos_depth=1000, max_queue=1000, sync_timeout=1.0, **values)
    delayed = PoseRecorder(rig.client, pose_topic=DELAYED_POSE_TOPIC)
    replay_and_wait(rig, frames, len(frames), wait_for)
    # The last report_lag seconds of frames are estimated once the input has been quiet
    # for report_lag seconds of wall time.
    assert wait_for(lambda: len(delayed) >= len(expected), 20.0), (len(delayed), len(expected))
    got = delayed.positions()
    assert len(got) == len(expected)
    np.testing.assert_array_equal(got.xyz, np.array([e.position for e in expected]))
    np.testing.assert_allclose(got.stamps, [e.stamp for e in expected], rtol=0, atol=1e-9)
    assert rig.detector.counters()["delayed_estimates"] == len(expected)
    # The live topic is unchanged by report_lag.
    live = run_streaming(on_the_wire(frames), detector_params())
    assert wait_for(lambda: len(rig.recorder) >= len(live), 10.0)
    np.testing.assert_array_equal(rig.recorder.positions().xyz, [e.position for e in live])


def test_a_failing_delayed_flush_is_counted_not_fatal(make_rig, small_sequence, monkeypatch):
    rig = make_rig(report_lag=2.0)
    node = rig.detector
    with node._cond:  # not idle: the diagnostics timer must not flush meanwhile
        node._last_processed_at = time.monotonic() + 100.0
    with node._detector_lock:
        node._detector.push(small_sequence.frames[0])
    assert node._detector.stats()["delayed_pending"] == 1

    def boom():
        raise RuntimeError("injected")

    monkeypatch.setattr(node._detector, "flush", boom)
    with node._cond:
        node._last_processed_at = time.monotonic() - 10.0  # the input stopped 10 s ago
    node._flush_delayed_if_idle()  # (the timer may have tried too)
    assert node.counters()["errors"] >= 1
    assert node.diagnostics() is not None  # still serving


def test_extrinsic_moves_poses(make_rig, small_sequence, wait_for):
    frames = small_sequence.frames
    shift = [5.0, -3.0, 1.0]
    rig = make_rig(
        qos_depth=1000,
        max_queue=1000,
        sync_timeout=1.0,
        avia_extrinsic=shift + [0.0, 0.0, 0.0, 1.0],
        mid360_extrinsic=shift + [0.0, 0.0, 0.0, 1.0],
        mid360_min_z=1.0,  # the default (0) moved up by 1 m with the shift
    )
    replay_and_wait(rig, frames, len(frames), wait_for)
    shifted = [
        dataclasses.replace(f, xyz=(f.xyz.astype(np.float64) + shift).astype(np.float32))
        for f in frames
    ]
    expected = run_streaming(shifted, detector_params({"mid360_min_z": 1.0}))
    assert wait_for(lambda: len(rig.recorder) >= len(expected), 10.0)
    got = rig.recorder.positions()
    assert len(got) == len(expected) > 0
    np.testing.assert_allclose(got.xyz, [e.position for e in expected], atol=1e-6)


def test_backwards_stamp_resets_state(make_rig, small_sequence, wait_for):
    frames = small_sequence.frames
    rig = make_rig(qos_depth=1000, max_queue=1000, sync_timeout=1.0)
    first = len(run_streaming(on_the_wire(frames), detector_params()))
    assert first > 0
    replay_and_wait(rig, frames, len(frames), wait_for)
    assert wait_for(lambda: len(rig.recorder) >= first, 10.0)
    rig.replayer.play(frames, rate=0.0)  # the bag loops: stamps jump back 8 s
    assert wait_for(
        lambda: sum(rig.detector.counters()["received"].values()) >= 2 * len(frames), 30.0
    )
    assert rig.detector.wait_until_idle(30.0)
    counters = rig.detector.counters()
    assert counters["resets"] == 1
    assert counters["processed"] == 2 * len(frames)
    # After the reset the second pass gives exactly the first pass's poses again.
    assert wait_for(lambda: len(rig.recorder) >= 2 * first, 10.0)
    poses = rig.recorder.positions()
    assert len(poses) == 2 * first
    rows = np.column_stack([poses.stamps, poses.xyz])
    rows = rows[np.lexsort(rows.T[::-1])]  # every (stamp, x, y, z) must appear twice
    np.testing.assert_array_equal(rows[0::2], rows[1::2])


def test_runtime_parameters_validated(make_rig):
    from rclpy.parameter import Parameter

    rig = make_rig()
    node = rig.detector
    ok = node.set_parameters([Parameter("eps", value=1.5), Parameter("frame_id", value="world")])
    assert all(r.successful for r in ok)
    assert node.get_parameter("eps").value == 1.5
    assert node._detector.params.eps == 1.5
    bad = node.set_parameters([Parameter("eps", value=-1.0)])[0]
    assert not bad.successful and "eps" in bad.reason
    assert node.get_parameter("eps").value == 1.5
    zero_q = node.set_parameters([Parameter("avia_extrinsic", value=[0.0] * 7)])[0]
    assert not zero_q.successful and "quaternion" in zero_q.reason
    short = node.set_parameters([Parameter("target_offset", value=[1.0, 2.0])])[0]
    assert not short.successful and "3 values" in short.reason
    topic = node.set_parameters([Parameter("avia_topic", value="/other")])[0]
    assert not topic.successful
    wrong_type = node.set_parameters([Parameter("min_samples", value=2.5)])[0]
    assert not wrong_type.successful


def test_invalid_start_parameter_is_a_parameter_error(rclpy_context):
    from rclpy.parameter import Parameter

    from clusterfilter_ros.errors import ParameterError
    from clusterfilter_ros.ros.node import DetectorNode

    with pytest.raises(ParameterError, match="eps"):
        DetectorNode(context=rclpy_context, parameter_overrides=[Parameter("eps", value=100.0)])
    with pytest.raises(ParameterError, match="mid360_extrinsic"):
        DetectorNode(
            context=rclpy_context,
            parameter_overrides=[Parameter("mid360_extrinsic", value=[0.0] * 7)],
        )


def test_surface_depth_with_a_viewpoint_away_from_the_lidars_warns(rclpy_context, monkeypatch):
    from rclpy.parameter import Parameter

    from clusterfilter_ros.ros.node import DetectorNode

    warnings: list[str] = []

    class Logger:
        def warning(self, msg, *args, **kwargs):
            warnings.append(msg)

        def __getattr__(self, name):
            return lambda *args, **kwargs: None

    monkeypatch.setattr(DetectorNode, "get_logger", lambda self: Logger())
    rig = [50.0, 20.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    for viewpoint, expect in (([0.0, 0.0, 0.0], True), ([50.0, 20.0, 0.5], False)):
        warnings.clear()
        node = DetectorNode(
            context=rclpy_context,
            parameter_overrides=[
                Parameter("surface_depth", value=0.1),
                Parameter("viewpoint", value=viewpoint),
                Parameter("mid360_extrinsic", value=rig),
                Parameter("avia_extrinsic", value=rig),
            ],
        )
        assert any("viewpoint" in w for w in warnings) is expect, warnings
        if not expect:
            # A change at run time is checked too.
            result = node.set_parameters([Parameter("viewpoint", value=[0.0, 0.0, 0.0])])
            assert result[0].successful
            assert any("viewpoint" in w for w in warnings), warnings
        node.destroy_node()


def test_diagnostics_stale_warn_ok_and_malformed(make_rig, small_sequence, wait_for):
    from diagnostic_msgs.msg import DiagnosticStatus
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import PointCloud2, PointField

    rig = make_rig(diagnostics_period=0.2, stale_timeout=0.5, qos_depth=100)

    def detector_status():
        return rig.detector.diagnostics().status[0]

    assert detector_status().level == DiagnosticStatus.STALE  # nothing received yet
    assert wait_for(lambda: len(rig.diagnostics) >= 2, 5.0)
    assert rig.replayer.wait_for_subscribers(10.0, settle=0.3)
    avia_only = [f for f in small_sequence.frames if f.sensor == "avia"][:5]
    rig.replayer.play(avia_only, rate=0.0)
    assert wait_for(lambda: rig.detector.counters()["received"]["avia"] == 5, 10.0)
    status = detector_status()
    assert status.level == DiagnosticStatus.WARN and "mid360" in status.message
    # Wide enough that a busy machine cannot make a lidar look silent during the check.
    assert rig.detector.set_parameters([Parameter("stale_timeout", value=30.0)])[0].successful
    rig.replayer.play(small_sequence.frames[10:20], rate=0.0)
    assert wait_for(lambda: rig.detector.counters()["received"]["mid360"] >= 5, 10.0)
    rig.detector.wait_until_idle(10.0)
    status = detector_status()
    assert status.level == DiagnosticStatus.OK, status
    values = {kv.key: kv.value for kv in status.values}
    assert int(values["frames_processed"]) >= 10
    assert float(values["processing_ms_mean"]) >= 0  # of this period, which may be empty
    assert "detector_accumulator_voxels" in values

    # Some published period saw the frames being processed and timed them.
    def timed_in_a_period() -> bool:
        for array in list(rig.diagnostics):
            for st in array.status:
                kv = {k.key: k.value for k in st.values}
                if float(kv.get("processing_ms_mean", "0")) > 0:
                    return True
        return False

    assert wait_for(timed_in_a_period, 5.0)

    # An empty cloud is a valid frame (nothing seen), not an error.
    from clusterfilter_ros.core.frame import Frame
    from clusterfilter_ros.io.pointcloud2 import make_pointcloud2

    before = rig.detector.counters()["processed"]
    empty = Frame(stamp=200.0, sensor="mid360", xyz=np.empty((0, 3), np.float32))
    rig.replayer.publishers["mid360"].publish(make_pointcloud2(empty, "mid360"))
    assert wait_for(lambda: rig.detector.counters()["processed"] == before + 1, 10.0)
    assert rig.detector.counters()["rejected"]["mid360"] == 0
    # A cloud whose bytes are shorter than width * point_step: rejected, counted, no crash.
    bad = PointCloud2(height=1, width=100, point_step=12, row_step=1200, is_dense=True)
    bad.fields = [
        PointField(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")
    ]
    bad.data = bytes(60)
    bad.header.stamp.sec = 500
    rig.replayer.publishers["avia"].publish(bad)
    assert wait_for(lambda: rig.detector.counters()["rejected"]["avia"] == 1, 10.0)
    statuses = {s.name.split(": ")[-1]: s for s in rig.detector.diagnostics().status}
    assert statuses["avia input"].level in (DiagnosticStatus.WARN, DiagnosticStatus.ERROR)
    assert {kv.key: kv.value for kv in statuses["avia input"].values}["rejected_malformed"] == "1"
    # Silence: both inputs stale after stale_timeout.
    assert rig.detector.set_parameters([Parameter("stale_timeout", value=0.2)])[0].successful
    assert wait_for(lambda: detector_status().level == DiagnosticStatus.STALE, 5.0)


def test_drone_cloud_built_only_when_subscribed(rclpy_context, small_sequence, wait_for):
    import threading

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from clusterfilter_ros.ros.node import DetectorNode
    from clusterfilter_ros.ros.record import PoseRecorder
    from clusterfilter_ros.ros.replay import Replayer

    overrides = {"sync_timeout": 1.0, "qos_depth": 1000, "max_queue": 1000}
    detector = DetectorNode(
        context=rclpy_context,
        parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()],
    )
    client = rclpy.create_node("no_points_client", context=rclpy_context)
    replayer, recorder = Replayer(client), PoseRecorder(client)  # poses only
    calls = []
    original = detector._detector.drone_points
    detector._detector.drone_points = lambda: calls.append(1) or original()
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(detector)
    executor.add_node(client)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    try:
        assert replayer.wait_for_subscribers(20.0, ["/uav/pose"], settle=0.2)
        n = len(small_sequence.frames)
        replayer.play(small_sequence.frames, rate=4.0)
        assert wait_for(lambda: sum(detector.counters()["received"].values()) == n, 30.0)
        assert detector.wait_until_idle(30.0)
        assert detector.counters()["estimates"] > 0 and len(recorder) > 0
        assert calls == []  # nobody listens to /uav/points: the cloud was never made
    finally:
        executor.shutdown(timeout_sec=2.0)
        thread.join(timeout=5.0)
        detector.destroy_node()
        client.destroy_node()


def test_main_stops_on_sigint_and_sigterm_without_a_traceback(capfd):
    import os
    import signal

    from clusterfilter_ros.ros import node as node_module

    before = signal.getsignal(signal.SIGINT)
    for sig in (signal.SIGINT, signal.SIGTERM):
        timer = threading.Timer(1.5, os.kill, (os.getpid(), sig))
        timer.start()
        started = time.monotonic()
        assert node_module.main(["detector"]) == 0
        timer.join()
        assert time.monotonic() - started < 10.0
    assert signal.getsignal(signal.SIGINT) is before  # the caller's handler is back
    err = capfd.readouterr().err
    assert "stopping: received" in err and "Traceback" not in err


def test_main_exits_cleanly_when_a_shutdown_races_the_executor(monkeypatch):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from clusterfilter_ros.ros import node as node_module

    def racing_spin_once(self, timeout_sec=None):
        rclpy.shutdown()  # the context goes down while the wait set is being built
        raise RuntimeError("failed to initialize wait set: the given context is not valid")

    monkeypatch.setattr(SingleThreadedExecutor, "spin_once", racing_spin_once)
    assert node_module.main(["detector"]) == 0

    def broken_spin_once(self, timeout_sec=None):
        raise RuntimeError("a real error")

    monkeypatch.setattr(SingleThreadedExecutor, "spin_once", broken_spin_once)
    with pytest.raises(RuntimeError, match="a real error"):
        node_module.main(["detector"])
    assert not rclpy.ok()  # shut down on the way out all the same
