"""10,000+ randomly malformed clouds into a running ``detector`` process, then a drone.

The detector runs as its own process (``clusterfilter detector``, loopback DDS, the
session's ROS domain from ``ros_env``). This test publishes at least
:data:`N_GARBAGE` clouds drawn from a pool of random faults on both lidar topics
(random bytes and field tables, sizes that do not fit the data, missing x/y/z, unknown
types, NaN/Inf/huge coordinates, big-endian data, empty clouds, random, duplicate,
backwards and far-future stamps), then replays a short simulated sequence with a drone.
The process must still be running, must publish /uav/pose near the drone, must have
counted the garbage in /diagnostics and must have kept its log short (rate-limited
warnings). The counts are printed to the terminal.
"""

from __future__ import annotations

import array
import threading
import time

import numpy as np
import pytest

pytest.importorskip("rclpy")

from clusterfilter_ros.ros import processes  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]

N_GARBAGE = 10_000
#: Most messages published but not yet counted as received by the node (its
#: /diagnostics 'received'): publishing follows the node's pace, so that the best-effort
#: subscription (depth 1000) does not overflow and every cloud reaches the decoder.
IN_FLIGHT = 300


def garbage_pool(rng: np.random.Generator, size: int) -> list:
    """``size`` distinct faulty rclpy PointCloud2 messages (stamps are set when sent)."""
    from sensor_msgs.msg import PointCloud2, PointField

    def field(name, offset, datatype, count=1):
        return PointField(name=name, offset=int(offset), datatype=int(datatype), count=count)

    xyz_fields = [field(a, 4 * i, 7) for i, a in enumerate("xyz")]
    pool = []
    for k in range(size):
        msg = PointCloud2()
        kind = k % 10
        n = int(rng.integers(0, 40))
        if kind == 0:  # random field table, sizes and bytes
            msg.fields = [
                field(
                    rng.choice(["x", "y", "z", "i", ""]),
                    rng.integers(0, 40),
                    rng.integers(0, 11),
                    int(rng.integers(0, 3)),
                )
                for _ in range(int(rng.integers(0, 5)))
            ]
            msg.height, msg.width = int(rng.integers(0, 4)), int(rng.integers(0, 50))
            msg.point_step, msg.row_step = int(rng.integers(0, 40)), int(rng.integers(0, 900))
            msg.data = array.array("B", rng.bytes(int(rng.integers(0, 600))))
        elif kind in (1, 2):  # consistent xyz cloud with one size broken
            msg.fields, msg.height, msg.width, msg.point_step = xyz_fields, 1, n + 1, 12
            msg.row_step = 12 * (n + 1)
            nbytes = msg.row_step + int(rng.choice([-7, -1, 5, 12]))
            if kind == 2:
                msg.row_step -= 1
                nbytes = 12 * (n + 1)
            msg.data = array.array("B", rng.bytes(max(nbytes, 0)))
        elif kind == 3:  # no x/y/z
            msg.fields = [field(a, 4 * i, 7) for i, a in enumerate("abc")]
            msg.height, msg.width, msg.point_step, msg.row_step = 1, n, 12, 12 * n
            msg.data = array.array("B", bytes(12 * n))
        elif kind == 4:  # unknown datatype / field past point_step / duplicate names
            msg.fields = xyz_fields + [field(rng.choice(["x", "t"]), 12, rng.choice([9, 7]))]
            msg.height, msg.width, msg.point_step, msg.row_step = 1, n, 12, 12 * n
            msg.data = array.array("B", bytes(12 * n))
        else:  # decodable: random bytes as coordinates (NaN/Inf/huge), big-endian, empty
            msg.fields = xyz_fields
            msg.is_bigendian = bool(kind % 2)
            n = 0 if kind == 9 else n
            msg.height, msg.width, msg.point_step, msg.row_step = 1, n, 12, 12 * n
            if kind in (5, 6):
                msg.data = array.array("B", rng.bytes(12 * n))
            else:
                xyz = rng.normal(0, 30, (n, 3)).astype(np.float32)
                xyz[::3] = rng.choice([np.nan, np.inf, -np.inf, 3e38], size=xyz[::3].shape)
                msg.data = array.array(
                    "B", xyz.astype(">f4" if msg.is_bigendian else "<f4").tobytes()
                )
        pool.append(msg)
    return pool


def random_stamp(rng: np.random.Generator, k: int) -> tuple[int, int]:
    """Mostly increasing stamps, with duplicates, steps back, zero and far-future ones."""
    choice = rng.random()
    if choice < 0.05:
        return 0, 0
    if choice < 0.10:
        return int(rng.integers(2_000_000_000, 2_100_000_000)), 0
    if choice < 0.25:
        return int(rng.integers(0, 1_000)), int(rng.integers(0, 1_000_000_000))
    return 500 + k // 20, (k % 20) * 50_000_000


class Client:
    """Replayer, pose recorder and /diagnostics listener in the test's own rclpy context."""

    def __init__(self, context) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor

        from clusterfilter_ros.ros.node import OUTPUT_QOS
        from clusterfilter_ros.ros.record import PoseRecorder
        from clusterfilter_ros.ros.replay import Replayer

        self.node = rclpy.create_node("garbage_client", context=context)
        self.replayer = Replayer(self.node)
        self.recorder = PoseRecorder(self.node)
        self.diagnostics: list = []
        self.node.create_subscription(
            DiagnosticArray, "/diagnostics", self.diagnostics.append, OUTPUT_QOS
        )
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:
            pass

    def latest(self) -> dict[str, dict[str, str]]:
        """The last /diagnostics: {short status name: {key: value}} ({} before the first)."""
        if not self.diagnostics:
            return {}
        return {
            s.name.split(": ")[-1]: {kv.key: kv.value for kv in s.values}
            for s in self.diagnostics[-1].status
        }

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=2.0)
        self.thread.join(timeout=5.0)
        self.node.destroy_node()


def _received(client: Client) -> int:
    d = client.latest()
    return sum(int(d.get(f"{s} input", {}).get("received", 0)) for s in ("avia", "mid360"))


def test_garbage_then_drone(tmp_path, ros_env, rclpy_context, small_sequence, capsys):
    rng = np.random.default_rng(7)
    detector = processes.start(
        "detector",
        processes.cli_command(
            "detector",
            "-p",
            "qos_depth=1000",
            "-p",
            "max_queue=1000",
            "-p",
            "diagnostics_period=0.2",
            "-p",
            "sync_timeout=0.5",
        ),
        ros_env,
        tmp_path / "logs",
    )
    client = Client(rclpy_context)
    try:
        assert client.replayer.wait_for_subscribers(60.0, ["/uav/pose"], settle=0.5), (
            detector.log_tail()
        )
        pool = garbage_pool(rng, 500)
        topics = list(client.replayer.publishers.values())
        started = time.monotonic()
        for k in range(N_GARBAGE):
            while k - _received(client) > IN_FLIGHT and time.monotonic() - started < 60:
                time.sleep(0.01)
            msg = pool[int(rng.integers(0, len(pool)))]
            msg.header.stamp.sec, msg.header.stamp.nanosec = random_stamp(rng, k)
            topics[k % 2].publish(msg)
        garbage_seconds = time.monotonic() - started
        # Let the node drain what it received (received count stops growing).
        last, stable_since = -1, time.monotonic()
        while time.monotonic() - stable_since < 1.0 and time.monotonic() - started < 90:
            now_received = _received(client)
            if now_received != last:
                last, stable_since = now_received, time.monotonic()
            time.sleep(0.1)
        assert detector.running(), detector.log_tail()
        after_garbage = client.latest()
        # Then a real sequence with a drone.
        n_poses_before = len(client.recorder)
        client.replayer.play(small_sequence.frames, rate=4.0)
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and len(client.recorder) - n_poses_before < 40:
            time.sleep(0.1)
        time.sleep(1.0)
        assert detector.running(), detector.log_tail()
        final = client.latest()
    finally:
        code = detector.interrupt()
        client.close()
    log = detector.log_path.read_text(errors="replace")
    assert code == 0, log[-2000:]
    assert "Traceback" not in log
    poses = client.recorder.positions()
    on_drone = poses.stamps >= small_sequence.frames[0].stamp
    on_drone &= poses.stamps <= small_sequence.frames[-1].stamp
    stamps, xyz = poses.stamps[on_drone], poses.xyz[on_drone]
    gt = small_sequence.ground_truth
    truth = np.column_stack([np.interp(stamps, gt.stamps, gt.xyz[:, i]) for i in range(3)])
    errors = np.linalg.norm(xyz - truth, axis=1)
    inputs = [after_garbage[f"{s} input"] for s in ("avia", "mid360")]
    received = sum(int(v["received"]) for v in inputs)
    rejected = sum(int(v["rejected_malformed"]) for v in inputs)
    lost = sum(int(v["lost_in_transport"]) for v in inputs)
    nonfinite = sum(int(v["nonfinite_points_dropped"]) for v in inputs)
    det = after_garbage["detector"]
    warnings = sum("WARN" in line or "ERROR" in line for line in log.splitlines())
    with capsys.disabled():
        print(
            f"\n[node garbage] published {N_GARBAGE} faulty clouds in {garbage_seconds:.1f} s; "
            f"node received {received}, rejected {rejected} as malformed, dropped "
            f"{nonfinite} non-finite points, {det['dropped_late']} late frames, "
            f"{det['resets']} resets, {lost} lost in transport; {warnings} warning lines "
            f"logged; afterwards {len(stamps)} poses on the drone sequence, median error "
            f"{np.median(errors) if len(errors) else float('nan'):.2f} m"
        )
    assert received >= 0.95 * N_GARBAGE and rejected >= 0.3 * received
    assert int(det["detector_errors"]) == 0
    assert warnings <= 60, "warnings are not rate-limited"
    assert len(stamps) >= 40, final
    assert np.median(errors) < 0.5
