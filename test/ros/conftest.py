"""Helpers for the ROS tests: a small synthetic two-lidar sequence and an in-process rig."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from clusterfilter_ros.core.frame import AVIA, MID360, Frame, Sequence, TimedPositions


def synthetic_sequence(duration: float = 8.0, seed: int = 0) -> Sequence:
    """Static clutter (ground, a wall, a tree) and a drone crossing the sky.

    Both lidars run at 10 Hz; the Mid360's stamps are 50 ms after the Avia's, and every
    fifth Mid360 frame shares the Avia's stamp (to exercise the tie rule). The drone is a
    0.35 m blob of ~25 points per lidar frame moving at 3 m/s, 20 m up.
    """
    rng = np.random.default_rng(seed)
    wall = np.column_stack(
        [np.full(3000, 15.0), rng.uniform(-10, 10, 3000), rng.uniform(0, 12, 3000)]
    )
    tree = rng.normal([-8.0, 6.0, 7.0], [0.8, 0.8, 2.0], (1500, 3))
    ground = np.column_stack(
        [rng.uniform(-30, 30, 2000), rng.uniform(-30, 30, 2000), rng.normal(0, 0.05, 2000)]
    )
    static = np.concatenate([wall, tree, ground])

    def drone_at(t: float) -> np.ndarray:
        return np.array([-10.0 + 3.0 * t, 2.0 + 0.5 * t, 20.0 + 0.2 * np.sin(t)])

    frames = []
    for k in range(int(duration * 10)):
        t_avia = 100.0 + 0.1 * k
        t_mid = t_avia + (0.0 if k % 5 == 0 else 0.05)
        for sensor, t in ((AVIA, t_avia), (MID360, t_mid)):
            blob = drone_at(t - 100.0) + rng.normal(0, 0.12, (25, 3))
            if sensor == MID360:
                pick = rng.choice(static.shape[0], 2500, replace=False)
                pts = np.concatenate([static[pick] + rng.normal(0, 0.02, (2500, 3)), blob])
            else:
                noise = rng.uniform([-60, -60, 30], [60, 60, 300], (5, 3))
                pts = np.concatenate([blob, noise])
            frames.append(Frame(stamp=t, sensor=sensor, xyz=pts.astype(np.float32)))
    frames.sort(key=lambda f: (f.stamp, f.sensor))
    gt_t = np.arange(0.0, duration, 0.07)
    gt = TimedPositions(gt_t + 100.0, np.array([drone_at(t) for t in gt_t]))
    return Sequence("synthetic", frames, gt)


@pytest.fixture(scope="session")
def small_sequence() -> Sequence:
    return synthetic_sequence()


def poll(condition, timeout: float, step: float = 0.02) -> bool:
    """Poll ``condition()`` until true or ``timeout`` s pass."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(step)
    return bool(condition())


@pytest.fixture(name="wait_for")
def wait_for_fixture():
    """``wait_for(condition, timeout)``: poll until ``condition()`` is true."""
    return poll


class Rig:
    """A detector node plus a client node (replayer, recorder, diagnostics) in one context,
    spun by one executor in a background thread.

    The detector re-clusters inside the frame that triggers it (``recluster_in_background``
    false, unlike the node's default) unless the overrides say otherwise, so that its poses
    can be compared with :func:`run_streaming`'s exactly."""

    def __init__(self, context, overrides: dict | None = None) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from nav_msgs.msg import Path as PathMsg
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.parameter import Parameter

        from clusterfilter_ros.ros.node import OUTPUT_QOS, DetectorNode
        from clusterfilter_ros.ros.record import RECORD_QOS, PoseRecorder
        from clusterfilter_ros.ros.replay import Replayer

        values = {"recluster_in_background": False, **(overrides or {})}
        params = [Parameter(k, value=v) for k, v in values.items()]
        self.detector = DetectorNode(context=context, parameter_overrides=params)
        self.client = rclpy.create_node("test_client", context=context)
        self.replayer = Replayer(self.client)
        self.recorder = PoseRecorder(self.client, points_topic="/uav/points")
        self.paths: list[PathMsg] = []
        # As deep a queue as the pose recorder's: with the node's own depth of 10, a client
        # spun late on a loaded machine lost paths the detector had published.
        self.client.create_subscription(PathMsg, "/uav/path", self.paths.append, RECORD_QOS)
        self.diagnostics: list[DiagnosticArray] = []
        self.client.create_subscription(
            DiagnosticArray, "/diagnostics", self.diagnostics.append, OUTPUT_QOS
        )
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.detector)
        self.executor.add_node(self.client)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()
        # Best-effort clouds published before the detector's readers match go nowhere.
        assert self.replayer.wait_for_subscribers(20.0, ["/uav/pose"], settle=0.2)

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:  # context shut down under us at teardown
            pass

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=2.0)
        self._thread.join(timeout=5.0)
        self.detector.destroy_node()
        self.client.destroy_node()


@pytest.fixture
def make_rig(rclpy_context):
    rigs = []

    def factory(**overrides) -> Rig:
        rig = Rig(rclpy_context, overrides)
        rigs.append(rig)
        return rig

    yield factory
    for rig in rigs:
        rig.close()
