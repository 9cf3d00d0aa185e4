"""The ``detector`` node: a thin rclpy wrapper over the streaming detector.

Inputs: two ``sensor_msgs/PointCloud2`` topics (parameters ``avia_topic`` and
``mid360_topic``) with sensor-data QoS (best effort, keep last ``qos_depth``). Each
cloud is decoded by :mod:`clusterfilter_ros.io.pointcloud2`, mapped into the output
frame by its lidar's extrinsic parameter and handed to a :class:`StampMerger`, which
releases frames in header-stamp order (see :mod:`clusterfilter_ros.ros.merge`). A
worker thread pushes them into :class:`~clusterfilter_ros.core.streaming.StreamingDetector`
so the executor keeps receiving (and diagnostics keep flowing) while a frame is being
processed. Time is the header stamp only: a replay at any rate gives the same poses.

Outputs (reliable QoS, depth 10; ``/uav/pose_delayed`` depth 500):

- ``/uav/pose`` ``geometry_msgs/PoseStamped``: stamp = time of the frame the estimate
  is for, ``frame_id`` parameter, identity orientation; nothing when no drone is found;
- ``/uav/pose_delayed`` ``geometry_msgs/PoseStamped``: with ``report_lag`` > 0, each
  frame's position again, ``report_lag`` seconds of stream time later, from the data up
  to then (fixed-lag smoothing; stamp = the frame's); with ``report_backfill`` > 0,
  frames before a new track's confirmation up to ``report_backfill`` seconds later still.
  When input stops, the frames still waiting are estimated after ``report_lag`` seconds
  (at least one) of wall time;
- ``/uav/points`` ``sensor_msgs/PointCloud2``: the points the detector attributes to
  the drone (built only while someone subscribes);
- ``/uav/path`` ``nav_msgs/Path``: the last ``path_length`` poses (built only while
  someone subscribes);
- ``/diagnostics`` ``diagnostic_msgs/DiagnosticArray`` every ``diagnostics_period`` s.

Parameters are declared from the shared :class:`ParamSpec` lists with descriptors and
ranges and can be changed at run time; invalid values are rejected with the reason.
"""

from __future__ import annotations

import collections
import math
import sys
import threading
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path as PathMsg
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import PointCloud2

from clusterfilter_ros.config import all_param_specs
from clusterfilter_ros.core.frame import AVIA, MID360, Frame
from clusterfilter_ros.core.params import DETECTOR_PARAMS, ParamSpec, detector_params
from clusterfilter_ros.core.streaming import StreamingDetector
from clusterfilter_ros.dds import apply_loopback_defaults
from clusterfilter_ros.errors import ClusterfilterError, ParameterError
from clusterfilter_ros.io.pointcloud2 import decode_pointcloud2, make_pointcloud2
from clusterfilter_ros.ros.merge import AddResult, MergedFrame, StampMerger
from clusterfilter_ros.ros.node_params import NODE_NAME
from clusterfilter_ros.ros.signals import shutdown_race, stop_on_signals
from clusterfilter_ros.ros.stamps import seconds_to_time_msg
from clusterfilter_ros.ros.transforms import Extrinsic

POSE_TOPIC = "/uav/pose"
DELAYED_POSE_TOPIC = "/uav/pose_delayed"
POINTS_TOPIC = "/uav/points"
PATH_TOPIC = "/uav/path"
DIAGNOSTICS_TOPIC = "/diagnostics"
SENSORS = (AVIA, MID360)

#: Output QoS: reliable, volatile, keep last 10.
OUTPUT_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

#: ``/uav/pose_delayed``'s QoS: reliable, volatile, keep last 500. It publishes in
#: bursts: the waiting frames at a confirmation (``report_backfill``: up to 20 poses per
#: second of it) and at a flush (``report_lag`` seconds of frames).
DELAYED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=500,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

_PARAMETER_TYPES = {
    "bool": ParameterType.PARAMETER_BOOL,
    "int": ParameterType.PARAMETER_INTEGER,
    "float": ParameterType.PARAMETER_DOUBLE,
    "str": ParameterType.PARAMETER_STRING,
    "float_list": ParameterType.PARAMETER_DOUBLE_ARRAY,
    "str_list": ParameterType.PARAMETER_STRING_ARRAY,
}
_DETECTOR_NAMES = frozenset(s.name for s in DETECTOR_PARAMS)


def parameter_descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """The ROS descriptor of a :class:`ParamSpec`: type, description, range, read-only."""
    descriptor = ParameterDescriptor(
        name=spec.name,
        type=_PARAMETER_TYPES[spec.kind],
        description=spec.description,
        read_only=spec.read_only,
    )
    constraints = []
    if spec.kind == "float" and (spec.minimum is not None or spec.maximum is not None):
        descriptor.floating_point_range = [
            FloatingPointRange(
                from_value=-sys.float_info.max if spec.minimum is None else float(spec.minimum),
                to_value=sys.float_info.max if spec.maximum is None else float(spec.maximum),
                step=0.0,
            )
        ]
    elif spec.kind == "int" and (spec.minimum is not None or spec.maximum is not None):
        descriptor.integer_range = [
            IntegerRange(
                from_value=-(2**63) if spec.minimum is None else int(spec.minimum),
                to_value=2**63 - 1 if spec.maximum is None else int(spec.maximum),
                step=0,
            )
        ]
    elif spec.range_text():
        constraints.append(f"values in {spec.range_text()}")
    if spec.length is not None:
        constraints.append(f"exactly {spec.length} values")
    if constraints:
        descriptor.additional_constraints = "; ".join(constraints)
    return descriptor


def declare_parameters_from_specs(node: Node, specs: Iterable[ParamSpec]) -> dict[str, Any]:
    """Declare every spec on ``node`` (overrides from ``--params-file`` apply) and
    return the values, each validated and coerced by its spec.

    Raises :class:`ParameterError` naming the first invalid value.
    """
    values: dict[str, Any] = {}
    for spec in specs:
        try:
            param = node.declare_parameter(spec.name, spec.default, parameter_descriptor(spec))
        except Exception as exc:  # rclpy's InvalidParameter*Exception: type or range
            raise ParameterError(f"parameter '{spec.name}': {exc}") from None
        values[spec.name] = spec.validate(_plain_value(param.value))
    return values


def _plain_value(value: Any) -> Any:
    """Parameter values as Python scalars/lists (rclpy gives ``array.array`` for arrays)."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return list(value)


@dataclass
class _InputStats:
    """Counters of one lidar input."""

    received: int = 0
    rejected: int = 0
    lost: int = 0
    nonfinite_points: int = 0
    last_receipt: float | None = None  # monotonic
    last_stamp: float | None = None
    received_in_period: int = 0
    rejected_in_period: int = 0


@dataclass
class _PeriodStats:
    """What happened since the last diagnostics message."""

    processing_s: list[float] = field(default_factory=list)
    latency_s: list[float] = field(default_factory=list)
    errors: int = 0
    dropped: int = 0


class DetectorNode(Node):
    """The drone detector as a ROS 2 node (see the module docstring for topics).

    Args:
        node_name: ROS node name.
        **kwargs: passed to :class:`rclpy.node.Node` (``context``,
            ``parameter_overrides``, ...).

    Raises :class:`ParameterError` if a parameter from the overrides is invalid.
    """

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._specs = {s.name: s for s in all_param_specs()}
        try:
            values = declare_parameters_from_specs(self, self._specs.values())
            self._extrinsics = {
                AVIA: Extrinsic.from_list(values["avia_extrinsic"], "avia_extrinsic"),
                MID360: Extrinsic.from_list(values["mid360_extrinsic"], "mid360_extrinsic"),
            }
            self._detector = StreamingDetector(
                detector_params({k: v for k, v in values.items() if k in _DETECTOR_NAMES}),
                background=values["recluster_in_background"],
            )
        except BaseException:
            Node.destroy_node(self)  # nothing of ours to stop yet
            raise
        self._values = dict(values)
        self._warn_if_viewpoint_is_off(values)
        self._detector_lock = threading.Lock()
        self._generation = 0
        self._path: collections.deque[PoseStamped] = collections.deque(maxlen=values["path_length"])
        # Everything below guarded by self._cond's lock.
        self._cond = threading.Condition()
        self._merger = StampMerger(
            SENSORS,
            sync_timeout=values["sync_timeout"],
            max_queue=values["max_queue"],
            backwards_tolerance=values["backwards_tolerance"],
            min_frame_interval=values["min_frame_interval"],
        )
        self._inputs = {s: _InputStats() for s in SENSORS}
        self._period = _PeriodStats()
        self._period_start = time.monotonic()
        self._busy = False
        self._stopping = False
        self._processed = 0
        self._estimates = 0
        self._last_estimate: tuple[float, float, int] | None = None  # stamp, confidence, points
        self._errors = 0
        self._last_error = ""

        self._pose_pub = self.create_publisher(PoseStamped, POSE_TOPIC, OUTPUT_QOS)
        self._delayed_pub = self.create_publisher(PoseStamped, DELAYED_POSE_TOPIC, DELAYED_QOS)
        self._delayed_estimates = 0
        self._last_processed_at = time.monotonic()
        self._points_pub = self.create_publisher(PointCloud2, POINTS_TOPIC, OUTPUT_QOS)
        self._path_pub = self.create_publisher(PathMsg, PATH_TOPIC, OUTPUT_QOS)
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, OUTPUT_QOS)

        input_qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=values["qos_depth"],
            reliability=qos_profile_sensor_data.reliability,
            durability=qos_profile_sensor_data.durability,
        )
        self._subscriptions_by_sensor = {}
        for sensor in SENSORS:
            topic = values[f"{sensor}_topic"]
            self._subscriptions_by_sensor[sensor] = self.create_subscription(
                PointCloud2,
                topic,
                lambda msg, s=sensor: self._on_cloud(msg, s),
                input_qos,
                event_callbacks=SubscriptionEventCallbacks(
                    message_lost=lambda info, s=sensor: self._on_message_lost(info, s)
                ),
            )
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._diag_timer = self.create_timer(
            values["diagnostics_period"], self._publish_diagnostics
        )
        self._worker = threading.Thread(
            target=self._work, name="clusterfilter-detector", daemon=True
        )
        self._worker.start()
        self.get_logger().info(
            f"detecting drones in {values['avia_topic']} (avia) and {values['mid360_topic']} "
            f"(mid360); publishing {POSE_TOPIC}, {POINTS_TOPIC}, {PATH_TOPIC} in frame "
            f"'{values['frame_id']}'"
        )

    # ------------------------------------------------------------------ inputs
    def _on_cloud(self, msg: PointCloud2, sensor: str) -> None:
        now = time.monotonic()
        stats = self._inputs[sensor]
        try:
            decoded = decode_pointcloud2(msg, sensor)
            frame = self._extrinsics[sensor].apply(decoded.frame)
        except Exception as exc:  # malformed input must never stop the node
            with self._cond:
                stats.received += 1
                stats.received_in_period += 1
                stats.rejected += 1
                stats.rejected_in_period += 1
                stats.last_receipt = now
            kind = "malformed" if isinstance(exc, (ClusterfilterError, ValueError)) else "bad"
            self.get_logger().warning(
                f"rejected a {kind} PointCloud2 on {self._values[f'{sensor}_topic']}: {exc}",
                throttle_duration_sec=5.0,
            )
            return
        with self._cond:
            stats.received += 1
            stats.received_in_period += 1
            stats.nonfinite_points += decoded.n_dropped_nonfinite
            stats.last_receipt = now
            previous = stats.last_stamp
            result = self._merger.add(frame, now)
            if result is not AddResult.LATE:
                stats.last_stamp = frame.stamp
            if result is AddResult.RESET:
                for other in self._inputs.values():
                    if other is not stats:
                        other.last_stamp = None
            elif result is AddResult.OVERFLOW:
                self._period.dropped += 1
            elif result is AddResult.LATE:
                self._period.dropped += 1
            self._cond.notify_all()
        if result is AddResult.RESET:
            self.get_logger().warning(
                f"{sensor} stamp went back from {previous:.3f} to {frame.stamp:.3f} s "
                "(looped bag or restarted driver?): resetting the detector"
                if previous is not None
                else f"{sensor} stamp {frame.stamp:.3f} s is before frames already "
                "processed: resetting the detector",
                # Garbage stamps can reset on every message: at most one line a second
                # (the total is in /diagnostics as 'resets').
                throttle_duration_sec=1.0,
            )
        elif result is AddResult.LATE:
            self.get_logger().warning(
                f"dropped a {sensor} frame stamped {frame.stamp:.3f} s: not later than "
                "frames already received or processed",
                throttle_duration_sec=5.0,
            )
        elif result is AddResult.OVERFLOW:
            self.get_logger().warning(
                "detector falling behind: dropped the oldest queued frame "
                f"(max_queue={self._merger.max_queue})",
                throttle_duration_sec=5.0,
            )

    def _on_message_lost(self, info: Any, sensor: str) -> None:
        with self._cond:
            self._inputs[sensor].lost += int(getattr(info, "total_count_change", 1))

    # --------------------------------------------------------------- processing
    def _work(self) -> None:
        while True:
            with self._cond:
                batch: list[MergedFrame] = []
                while not self._stopping:
                    batch = self._merger.pop_ready(time.monotonic())
                    if batch:
                        break
                    deadline = self._merger.next_deadline()
                    timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
                    self._cond.wait(timeout)
                if self._stopping:
                    return
                self._busy = True
            try:
                for item in batch:
                    try:
                        self._process(item)
                    except Exception as exc:  # e.g. publishing while shutting down
                        self._report_error("could not handle a frame", exc)
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()

    def _process(self, item: MergedFrame) -> None:
        started = time.perf_counter()
        points: np.ndarray | None = None
        with self._detector_lock:
            if item.generation != self._generation:
                self._detector.reset()
                self._generation = item.generation
                with self._cond:
                    self._path.clear()
            try:
                estimate = self._detector.push(item.frame)
                delayed = self._detector.delayed()
                if estimate is not None and self._points_pub.get_subscription_count() > 0:
                    points = self._detector.drone_points()
            except Exception as exc:  # a detector failure is reported, never fatal
                self._report_error(
                    f"detector failed on the {item.frame.sensor} frame at {item.frame.stamp:.3f} s",
                    exc,
                    in_period=True,
                )
                return
        processing_s = time.perf_counter() - started
        if estimate is not None and np.all(np.isfinite(estimate.position)):
            self._publish_estimate(estimate, points)
        self._publish_delayed(delayed)
        latency_s = time.monotonic() - item.received_at
        with self._cond:
            self._last_processed_at = time.monotonic()
            self._processed += 1
            self._period.processing_s.append(processing_s)
            self._period.latency_s.append(latency_s)

    def _pose(self, estimate: Any) -> PoseStamped:
        pose = PoseStamped()
        pose.header.stamp = seconds_to_time_msg(estimate.stamp)
        pose.header.frame_id = self._values["frame_id"]
        x, y, z = (float(v) for v in estimate.position)
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = x, y, z
        pose.pose.orientation.w = 1.0
        return pose

    def _publish_delayed(self, estimates: list[Any]) -> None:
        """Publish ``report_lag`` estimates on ``/uav/pose_delayed``."""
        published = 0
        for estimate in estimates:
            if np.all(np.isfinite(estimate.position)):
                self._delayed_pub.publish(self._pose(estimate))
                published += 1
        if published:
            with self._cond:
                self._delayed_estimates += published

    def _flush_delayed_if_idle(self) -> None:
        """The input stopped: estimate the frames still waiting for ``report_lag`` once
        no frame was processed for ``report_lag`` (at least 1) seconds of wall time."""
        with self._detector_lock:
            with self._cond:
                idle = time.monotonic() - self._last_processed_at
                busy = self._busy or len(self._merger) > 0
            if busy or idle < max(float(self._detector.params.report_lag), 1.0):
                return
            try:  # nothing to do (and nothing returned) when no frame is waiting
                estimates = self._detector.flush()
            except Exception as exc:  # reported, never fatal (as in _process)
                self._report_error("detector failed on its delayed estimates", exc)
                return
        self._publish_delayed(estimates)

    def _report_error(self, what: str, exc: Exception, in_period: bool = False) -> None:
        """Count a failure (in the diagnostics period's count too if ``in_period``) and
        log it, at most every 5 s."""
        with self._cond:
            self._errors += 1
            if in_period:
                self._period.errors += 1
            self._last_error = f"{type(exc).__name__}: {exc}"
        self.get_logger().error(f"{what}: {type(exc).__name__}: {exc}", throttle_duration_sec=5.0)

    def _publish_estimate(self, estimate: Any, points: np.ndarray | None) -> None:
        frame_id = self._values["frame_id"]
        pose = self._pose(estimate)
        self._pose_pub.publish(pose)
        with self._cond:
            self._estimates += 1
            self._last_estimate = (
                float(estimate.stamp),
                float(estimate.confidence),
                int(estimate.n_points),
            )
            self._path.append(pose)
            path_poses = list(self._path) if self._path_pub.get_subscription_count() > 0 else None
        if path_poses is not None:
            path = PathMsg()
            path.header = pose.header
            path.poses = path_poses
            self._path_pub.publish(path)
        if points is not None:
            cloud = Frame(stamp=estimate.stamp, sensor="drone", xyz=np.asarray(points))
            self._points_pub.publish(make_pointcloud2(cloud, frame_id, layout="xyz"))

    # ---------------------------------------------------------------- parameters
    def _warn_if_viewpoint_is_off(self, values: Mapping[str, Any]) -> None:
        """``surface_depth`` pushes estimates away from ``viewpoint`` (output frame): warn
        when that is more than 1 m from both lidars' positions given by the extrinsics
        (at start-up and whenever one of them changes)."""
        if float(values["surface_depth"]) <= 0:
            return
        viewpoint = np.asarray(values["viewpoint"], dtype=np.float64)
        lidars = [self._extrinsics[s].translation for s in SENSORS]
        if min(float(np.linalg.norm(viewpoint - t)) for t in lidars) > 1.0:
            where = ", ".join(
                f"{s} {np.round(self._extrinsics[s].translation, 2).tolist()}" for s in SENSORS
            )
            self.get_logger().warning(
                f"surface_depth is {values['surface_depth']} m but viewpoint "
                f"{viewpoint.tolist()} is more than 1 m from the lidars ({where}): estimates "
                "will be moved along the wrong line of sight; set viewpoint to the lidars' "
                "position in the output frame"
            )

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        changes: dict[str, Any] = {}
        try:
            for param in params:
                spec = self._specs.get(param.name)
                if spec is None:
                    continue
                if spec.read_only:
                    raise ParameterError(
                        f"parameter '{spec.name}' is read-only: set it at start-up"
                    )
                changes[spec.name] = spec.validate(_plain_value(param.value))
            self._apply_parameter_changes(changes)
        except ParameterError as exc:
            self.get_logger().warning(f"rejected parameter change: {exc}")
            return SetParametersResult(successful=False, reason=str(exc))
        if changes:
            self.get_logger().info(f"parameters changed: {changes}")
        return SetParametersResult(successful=True)

    def _apply_parameter_changes(self, changes: Mapping[str, Any]) -> None:
        """Apply validated values; all or nothing (raises :class:`ParameterError`)."""
        extrinsics = {
            sensor: Extrinsic.from_list(changes[f"{sensor}_extrinsic"], f"{sensor}_extrinsic")
            for sensor in SENSORS
            if f"{sensor}_extrinsic" in changes
        }
        detector_changes = {k: v for k, v in changes.items() if k in _DETECTOR_NAMES}
        with self._detector_lock:
            if detector_changes:
                self._detector.update_params(detector_changes)
            with self._cond:
                self._extrinsics.update(extrinsics)
                self._values.update(changes)
                if "sync_timeout" in changes:
                    self._merger.sync_timeout = changes["sync_timeout"]
                if "max_queue" in changes:
                    self._merger.max_queue = changes["max_queue"]
                if "backwards_tolerance" in changes:
                    self._merger.backwards_tolerance = changes["backwards_tolerance"]
                if "min_frame_interval" in changes:
                    self._merger.min_frame_interval = changes["min_frame_interval"]
                if "path_length" in changes:
                    self._path = collections.deque(self._path, maxlen=changes["path_length"])
                self._cond.notify_all()
        if changes.keys() & {"surface_depth", "viewpoint", "avia_extrinsic", "mid360_extrinsic"}:
            self._warn_if_viewpoint_is_off(self._values)

    # --------------------------------------------------------------- diagnostics
    def _publish_diagnostics(self) -> None:
        self._flush_delayed_if_idle()
        self._diag_pub.publish(self.diagnostics())

    def diagnostics(self) -> DiagnosticArray:
        """Build the ``/diagnostics`` message for the period since the last call."""
        now = time.monotonic()
        with self._cond:
            elapsed = max(now - self._period_start, 1e-9)
            self._period_start = now
            period, self._period = self._period, _PeriodStats()
            inputs = {s: _InputStats(**vars(st)) for s, st in self._inputs.items()}
            for st in self._inputs.values():
                st.received_in_period = 0
                st.rejected_in_period = 0
            queued = len(self._merger)
            counts = self._merger.counts
            merger_counts = (
                counts.late,
                counts.overflow,
                counts.resets,
                counts.released_by_timeout,
            )
            processed, estimates, errors = self._processed, self._estimates, self._errors
            last_estimate = self._last_estimate
            last_error = self._last_error
            stale_timeout = self._values["stale_timeout"]
        with self._detector_lock:
            detector_stats = dict(self._detector.stats())
        name = self.get_name()
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        silent = []
        input_statuses = []
        for sensor, st in inputs.items():
            status = DiagnosticStatus(name=f"{name}: {sensor} input", hardware_id=sensor)
            age = None if st.last_receipt is None else now - st.last_receipt
            if age is None or age > stale_timeout:
                silent.append(sensor)
                status.level = DiagnosticStatus.WARN
                status.message = "no message yet" if age is None else f"no message for {age:.1f} s"
            elif st.received_in_period and st.rejected_in_period == st.received_in_period:
                status.level = DiagnosticStatus.ERROR
                status.message = "every message rejected as malformed"
            elif st.rejected_in_period:
                status.level = DiagnosticStatus.WARN
                status.message = f"{st.rejected_in_period} malformed messages rejected"
            else:
                status.level = DiagnosticStatus.OK
                status.message = "receiving"
            status.values = _key_values(
                topic=self._values[f"{sensor}_topic"],
                rate_hz=st.received_in_period / elapsed,
                received=st.received,
                rejected_malformed=st.rejected,
                lost_in_transport=st.lost,
                nonfinite_points_dropped=st.nonfinite_points,
                seconds_since_last_message=-1.0 if age is None else age,
                last_stamp=-1.0 if st.last_stamp is None else st.last_stamp,
            )
            input_statuses.append(status)
        if len(silent) == len(SENSORS):
            for status in input_statuses:
                status.level = DiagnosticStatus.STALE
        processing = np.array(period.processing_s) * 1000.0
        latency = np.array(period.latency_s) * 1000.0
        det = DiagnosticStatus(name=f"{name}: detector", hardware_id=name)
        if len(silent) == len(SENSORS):
            det.level, det.message = DiagnosticStatus.STALE, "no input from either lidar"
        elif period.errors:
            det.level = DiagnosticStatus.ERROR
            det.message = f"{period.errors} frames failed: {last_error}"
        elif any(s.level == DiagnosticStatus.ERROR for s in input_statuses):
            det.level, det.message = DiagnosticStatus.ERROR, "input rejected"
        elif silent:
            det.level, det.message = DiagnosticStatus.WARN, f"{', '.join(silent)} silent"
        elif period.dropped or any(s.level != DiagnosticStatus.OK for s in input_statuses):
            det.level = DiagnosticStatus.WARN
            det.message = f"{period.dropped} frames dropped" if period.dropped else "input warnings"
        else:
            det.level, det.message = DiagnosticStatus.OK, "running"
        det.values = _key_values(
            frames_processed=processed,
            estimates_published=estimates,
            processing_ms_mean=float(processing.mean()) if processing.size else 0.0,
            processing_ms_max=float(processing.max()) if processing.size else 0.0,
            latency_ms_mean=float(latency.mean()) if latency.size else 0.0,
            latency_ms_max=float(latency.max()) if latency.size else 0.0,
            frames_queued=queued,
            dropped_late=merger_counts[0],
            dropped_queue_full=merger_counts[1],
            resets=merger_counts[2],
            released_without_other_lidar=merger_counts[3],
            detector_errors=errors,
            last_estimate_stamp=-1.0 if last_estimate is None else last_estimate[0],
            last_estimate_confidence=-1.0 if last_estimate is None else last_estimate[1],
            last_estimate_points=-1 if last_estimate is None else last_estimate[2],
            **{f"detector_{k}": v for k, v in detector_stats.items()},
        )
        array.status = [det, *input_statuses]
        return array

    # ------------------------------------------------------------------- control
    def counters(self) -> dict[str, Any]:
        """Running totals (for tests and tools): received, rejected, processed, ..."""
        with self._cond:
            counts = self._merger.counts
            return {
                "received": {s: st.received for s, st in self._inputs.items()},
                "rejected": {s: st.rejected for s, st in self._inputs.items()},
                "lost": {s: st.lost for s, st in self._inputs.items()},
                "processed": self._processed,
                "estimates": self._estimates,
                "delayed_estimates": self._delayed_estimates,
                "errors": self._errors,
                "queued": len(self._merger),
                "dropped_late": counts.late,
                "dropped_queue_full": counts.overflow,
                "resets": counts.resets,
                "released_by_timeout": counts.released_by_timeout,
            }

    def wait_until_idle(self, timeout: float) -> bool:
        """Block until no frame is queued or being processed; False on timeout."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while len(self._merger) or self._busy:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._cond.wait(min(remaining, 0.05))
            return True

    def destroy_node(self) -> None:
        """Stop the worker thread, then destroy the node."""
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        if self._worker.is_alive() and threading.current_thread() is not self._worker:
            self._worker.join(timeout=30.0)
        if not self._worker.is_alive():
            self._detector.close()  # the background re-clustering thread, if any
        counters = self.counters()
        summary = (
            "stopping: received {received}, processed {processed} frames, published "
            "{estimates} poses; rejected {rejected}, lost in transport {lost}, dropped late "
            "{dropped_late}, dropped queue full {dropped_queue_full}, resets {resets}, "
            "detector errors {errors}".format(**counters)
        )
        if self.context.ok():
            self.get_logger().info(summary)
        else:  # Ctrl-C already shut the context down: /rosout is gone
            print(f"[{self.get_name()}] {summary}", file=sys.stderr, flush=True)
        super().destroy_node()


def _key_values(**values: Any) -> list[KeyValue]:
    out = []
    for key, value in values.items():
        if isinstance(value, float):
            text = f"{value:.3f}" if math.isfinite(value) else str(value)
        else:
            text = str(value)
        out.append(KeyValue(key=key, value=text))
    return out


#: Seconds the spin loop waits for work before it looks at the stop request again.
SPIN_PERIOD = 0.1


def main(args: list[str] | None = None) -> int:
    """Entry point of the ``detector`` executable (``ros2 run clusterfilter_ros detector``).

    ``args`` are ROS command-line arguments (default ``sys.argv``), e.g.
    ``["--ros-args", "--params-file", "detector.yaml"]``. Returns 0 on Ctrl-C, SIGTERM or
    external shutdown, 2 when a parameter is invalid.

    SIGINT and SIGTERM only ask the spin loop to stop (:mod:`~.signals`).
    """
    apply_loopback_defaults()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    executor = None
    with stop_on_signals() as stop:
        try:
            node = DetectorNode()
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            while not stop.is_set() and rclpy.ok():
                executor.spin_once(timeout_sec=SPIN_PERIOD)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except ParameterError as exc:
            print(f"detector: error: {exc}", file=sys.stderr)
            return 2
        except RuntimeError as exc:
            if not shutdown_race(exc):
                raise
        finally:
            if executor is not None:
                executor.shutdown(timeout_sec=1.0)
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
