"""ROS 1 and ROS 2 bags through rosbags (no ROS install needed).

Reading: ``.bag`` files (ROS 1), ROS 2 bag folders (``metadata.yaml`` + sqlite3 or mcap)
and bare ``.db3``/``.mcap`` files. Lidar topics may carry ``sensor_msgs/PointCloud2``
(any field layout) or Livox ``CustomMsg`` (livox_ros_driver / livox_ros_driver2, parsed
from the raw bytes); ground truth comes from ``geometry_msgs/PointStamped``,
``PoseStamped``, ``PoseWithCovarianceStamped`` or ``nav_msgs/Odometry``.

Writing: ROS 2 bags (sqlite3 or mcap) or ROS 1 bags with livox_ros_driver2-layout
PointCloud2 (or CustomMsg) per sensor and PointStamped ground truth; header stamps are
the frame stamps.

rosbags is imported inside the functions, so importing this module is cheap.
"""

from __future__ import annotations

import dataclasses
import functools
import heapq
import os
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from clusterfilter_ros.core.frame import AVIA, MID360, Frame, Sequence, TimedPositions
from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io.atomic import atomic_output_dir, atomic_output_path
from clusterfilter_ros.io.livox import (
    CUSTOM_MSG_DEFINITION,
    CUSTOM_POINT_DEFINITION,
    decode_custom_msg,
    encode_custom_msg,
    is_custom_msg_type,
)
from clusterfilter_ros.io.pointcloud2 import (
    MAX_ROS1_SEC,
    MAX_ROS2_SEC,
    decode_pointcloud2,
    frame_to_pointcloud2,
    seconds_to_stamp,
    stamp_to_seconds,
)

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
GROUND_TRUTH_TYPES = (
    "geometry_msgs/msg/PointStamped",
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "nav_msgs/msg/Odometry",
)
DEFAULT_GROUND_TRUTH_TOPIC = "/uav/ground_truth"
DEFAULT_TOPICS: dict[str, str] = {AVIA: "/livox/avia", MID360: "/livox/mid360"}
#: Frames may arrive this much (s) out of header-stamp order and still be re-ordered
#: by :func:`iter_bag_frames`.
REORDER_WINDOW_S = 1.0


@dataclass(frozen=True)
class TopicSummary:
    """One topic of a bag: message type and number of messages."""

    topic: str
    msgtype: str
    count: int


@dataclass(frozen=True)
class BagSummary:
    """What a bag holds (from its index; no message is decoded)."""

    path: Path
    ros_version: int
    storage: str  # "rosbag1", "sqlite3" or "mcap"
    topics: dict[str, TopicSummary]
    start: float
    end: float

    def describe_topics(self) -> str:
        return ", ".join(f"{t.topic} ({t.msgtype})" for t in self.topics.values()) or "none"


def is_lidar_type(msgtype: str) -> bool:
    """True for PointCloud2 and the Livox CustomMsg types."""
    return msgtype == POINTCLOUD2 or is_custom_msg_type(msgtype)


def sensor_for_topic(topic: str) -> str | None:
    """Guess the sensor of a lidar topic from its name (``avia`` / ``mid360``/``360``)."""
    name = topic.lower()
    if "avia" in name:
        return AVIA
    if "mid360" in name or "mid_360" in name or "360" in name:
        return MID360
    return None


def _livox_types() -> dict[str, Any]:
    from rosbags.typesys import get_types_from_msg

    types: dict[str, Any] = {}
    for pkg in ("livox_ros_driver", "livox_ros_driver2"):
        types.update(get_types_from_msg(CUSTOM_POINT_DEFINITION, f"{pkg}/msg/CustomPoint"))
        types.update(get_types_from_msg(CUSTOM_MSG_DEFINITION, f"{pkg}/msg/CustomMsg"))
    return types


@functools.lru_cache(maxsize=2)
def typestore_for(ros_version: int) -> Any:
    """The rosbags typestore (ROS 1 Noetic or ROS 2 Jazzy) with the Livox types added."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros_version == 1 else Stores.ROS2_JAZZY)
    store.register(_livox_types())
    return store


def _bag_errors() -> tuple[type[BaseException], ...]:
    """Exceptions raised by rosbags' readers on damaged files.

    Besides its own ReaderError, rosbags lets low-level errors through on corrupt data
    (struct, sqlite3, zstd/lz4, seek overflows, ...), so everything derived from
    :class:`Exception` raised *inside rosbags' reading code* is treated as a damaged bag;
    the original is chained (``--debug`` shows it).
    """
    return (Exception,)


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def bag_ros_version(path: str | os.PathLike[str]) -> int:
    """1 for a ``.bag`` file, 2 for a ROS 2 bag folder or ``.db3``/``.mcap`` file."""
    p = Path(path)
    if p.is_file() and p.suffix.lower() == ".bag":
        return 1
    if p.is_dir() or p.suffix.lower() in (".db3", ".mcap"):
        return 2
    raise InputError(f"{p}: not a bag (expected a .bag file, a ROS 2 bag folder, .db3 or .mcap)")


def _permission_denied(exc: BaseException) -> bool:
    """True if ``exc`` or an exception it was raised from is a PermissionError (rosbags
    wraps the OS error in its own)."""
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        if isinstance(current, PermissionError):
            return True
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return False


class _OpenBag:
    """A rosbags reader opened with errors turned into :class:`InputError`."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise InputError(f"{self.path}: no such bag")
        self.ros_version = bag_ros_version(self.path)
        self.errors = _bag_errors()
        try:
            if self.ros_version == 1:
                from rosbags.rosbag1 import Reader as Ros1Reader

                self.reader: Any = Ros1Reader(self.path)
            else:
                from rosbags.rosbag2 import Reader as Ros2Reader

                self.reader = Ros2Reader(self._ros2_storage_path())
            self.reader.open()
        except self.errors as exc:
            if _permission_denied(exc):
                raise InputError(f"{self.path}: cannot read bag (permission denied)") from exc
            raise InputError(
                f"{self.path}: cannot read bag, truncated or corrupt? ({_one_line(exc)})"
            ) from exc

    def _ros2_storage_path(self) -> Path:
        """The bag folder, or its only storage file when ``metadata.yaml`` is missing
        (e.g. a recording that was killed before rosbag2 wrote it)."""
        p = self.path
        if not p.is_dir() or (p / "metadata.yaml").is_file():
            return p
        files = sorted(p.glob("*.db3")) + sorted(p.glob("*.mcap"))
        if len(files) == 1:
            return files[0]
        if not files:
            raise InputError(f"{p}: no metadata.yaml and no .db3/.mcap file (not a ROS 2 bag)")
        raise InputError(
            f"{p}: no metadata.yaml and {len(files)} storage files; pass one of them, "
            f"e.g. {files[0]}"
        )

    def close(self) -> None:
        try:
            self.reader.close()
        except self.errors:
            pass

    def __enter__(self) -> _OpenBag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def storage(self) -> str:
        if self.ros_version == 1:
            return "rosbag1"
        p = self.path
        if p.is_dir():
            files = list(p.glob("*.mcap"))
            return "mcap" if files else "sqlite3"
        return "mcap" if p.suffix.lower() == ".mcap" else "sqlite3"

    def summary(self) -> BagSummary:
        topics: dict[str, TopicSummary] = {}
        for conn in self.reader.connections:
            old = topics.get(conn.topic)
            count = int(getattr(conn, "msgcount", 0) or 0) + (old.count if old else 0)
            topics[conn.topic] = TopicSummary(conn.topic, conn.msgtype, count)
        start, end = self.reader.start_time, self.reader.end_time
        if not self.reader.message_count:
            start = end = 0
        return BagSummary(
            self.path, self.ros_version, self.storage, topics, start * 1e-9, end * 1e-9
        )

    def messages(self, connections: list[Any]) -> Iterator[tuple[Any, int, bytes]]:
        if not connections:
            return
        it = self.reader.messages(connections=connections)
        while True:
            try:
                item = next(it)
            except StopIteration:
                return
            except self.errors as exc:
                raise InputError(
                    f"{self.path}: bag is truncated or corrupt ({_one_line(exc)})"
                ) from exc
            yield item

    def deserialize(self, raw: bytes, msgtype: str, what: str) -> Any:
        store = typestore_for(self.ros_version)
        try:
            if self.ros_version == 1:
                return store.deserialize_ros1(raw, msgtype)
            return store.deserialize_cdr(raw, msgtype)
        except self.errors as exc:
            raise InputError(f"{what}: cannot decode {msgtype} ({_one_line(exc)})") from exc


def bag_summary(path: str | os.PathLike[str]) -> BagSummary:
    """Topics, types, message counts and time span of a bag (nothing decoded)."""
    with _OpenBag(path) as bag:
        return bag.summary()


def _resolve_lidar_topics(
    bag: _OpenBag,
    topics: Mapping[str, str] | None,
    sensors: Iterable[str] | None,
) -> dict[str, str]:
    """Topic -> sensor for the lidar topics to read (validated against the bag)."""
    summary = bag.summary()
    have = summary.topics
    if topics:
        mapping = dict(topics)
        for topic in mapping:
            if topic not in have:
                raise InputError(
                    f"{bag.path}: no topic {topic}; the bag has: {summary.describe_topics()}"
                )
            if not is_lidar_type(have[topic].msgtype):
                raise InputError(
                    f"{bag.path}: topic {topic} is {have[topic].msgtype}, "
                    "not PointCloud2 or Livox CustomMsg"
                )
    else:
        mapping = {}
        unknown = []
        for topic, info in have.items():
            if not is_lidar_type(info.msgtype):
                continue
            sensor = sensor_for_topic(topic)
            if sensor is None:
                unknown.append(topic)
            else:
                mapping[topic] = sensor
        if unknown:
            raise InputError(
                f"{bag.path}: cannot tell which sensor lidar topic(s) {', '.join(unknown)} "
                f"belong to; map them, e.g. --topic {unknown[0]}=avia "
                f"(topics={{'{unknown[0]}': 'avia'}})"
            )
        if not mapping:
            raise InputError(
                f"{bag.path}: no PointCloud2 or Livox CustomMsg topic; "
                f"the bag has: {summary.describe_topics()}"
            )
    if sensors is not None:
        wanted = {sensors} if isinstance(sensors, str) else set(sensors)
        mapping = {t: s for t, s in mapping.items() if s in wanted}
        if not mapping:
            raise InputError(
                f"{bag.path}: no lidar topic for sensor(s) {', '.join(sorted(wanted))}"
            )
    return mapping


def _decode_lidar(bag: _OpenBag, conn: Any, timestamp_ns: int, raw: bytes, sensor: str) -> Frame:
    what = f"{bag.path} {conn.topic} message at {timestamp_ns * 1e-9:.6f}"
    if is_custom_msg_type(conn.msgtype):
        frame = decode_custom_msg(raw, sensor, bag.ros_version, what).frame
    else:
        msg = bag.deserialize(raw, conn.msgtype, what)
        try:
            frame = decode_pointcloud2(msg, sensor).frame
        except InputError as exc:
            raise type(exc)(f"{what}: {exc}") from exc
    if frame.stamp == 0.0:  # header never filled in: fall back to the record time
        frame = dataclasses.replace(frame, stamp=timestamp_ns * 1e-9)
    return frame


def _position_of(msg: Any, msgtype: str) -> tuple[float, float, float]:
    if msgtype.endswith("PointStamped"):
        p = msg.point
    elif msgtype.endswith("PoseStamped"):
        p = msg.pose.position
    else:  # PoseWithCovarianceStamped, Odometry
        p = msg.pose.pose.position
    return float(p.x), float(p.y), float(p.z)


def _iter_frames(
    bag: _OpenBag, mapping: Mapping[str, str], reorder_window: float
) -> Iterator[Frame]:
    connections = [c for c in bag.reader.connections if c.topic in mapping]
    pending: list[tuple[float, str, int, Frame]] = []
    serial = 0
    latest = -np.inf
    for conn, timestamp_ns, raw in bag.messages(connections):
        frame = _decode_lidar(bag, conn, timestamp_ns, raw, mapping[conn.topic])
        heapq.heappush(pending, (frame.stamp, frame.sensor, serial, frame))
        serial += 1
        latest = max(latest, frame.stamp)
        while pending and pending[0][0] < latest - reorder_window:
            yield heapq.heappop(pending)[3]
    while pending:
        yield heapq.heappop(pending)[3]


def count_bag_frames(
    path: str | os.PathLike[str],
    topics: Mapping[str, str] | None = None,
    sensors: Iterable[str] | None = None,
) -> int:
    """Number of lidar messages :func:`iter_bag_frames` would decode (from the index)."""
    with _OpenBag(path) as bag:
        mapping = _resolve_lidar_topics(bag, topics, sensors)
        summary = bag.summary()
    return sum(summary.topics[t].count for t in mapping)


def iter_bag_frames(
    path: str | os.PathLike[str],
    topics: Mapping[str, str] | None = None,
    sensors: Iterable[str] | None = None,
    reorder_window: float = REORDER_WINDOW_S,
) -> Iterator[Frame]:
    """Lidar frames of a bag in header-stamp order, decoded one message at a time.

    Args:
        path: ``.bag`` file, ROS 2 bag folder, or ``.db3``/``.mcap`` file.
        topics: lidar topic -> sensor name. Default: every PointCloud2/CustomMsg topic,
            its sensor guessed from the name (``avia``, ``mid360``/``360``); an
            unguessable name is an :class:`InputError` asking for the mapping.
        sensors: keep only these sensors.
        reorder_window: frames arriving up to this many seconds out of stamp order are
            put back in order (a small buffer, not the whole bag).
    """
    bag = _OpenBag(path)
    try:
        mapping = _resolve_lidar_topics(bag, topics, sensors)
    except BaseException:
        bag.close()
        raise

    def generate() -> Iterator[Frame]:
        with bag:
            yield from _iter_frames(bag, mapping, reorder_window)

    return generate()


def read_bag_ground_truth(
    path: str | os.PathLike[str], topic: str = DEFAULT_GROUND_TRUTH_TOPIC
) -> TimedPositions:
    """Positions from a PointStamped/PoseStamped/... topic (header stamps, else record times)."""
    with _OpenBag(path) as bag:
        gt = _read_ground_truth(bag, topic, required=True)
    assert gt is not None
    return gt


def _read_ground_truth(bag: _OpenBag, topic: str, required: bool) -> TimedPositions | None:
    summary = bag.summary()
    info = summary.topics.get(topic)
    if info is None:
        if required:
            raise InputError(
                f"{bag.path}: no ground-truth topic {topic}; "
                f"the bag has: {summary.describe_topics()}"
            )
        return None
    if info.msgtype not in GROUND_TRUTH_TYPES:
        raise InputError(
            f"{bag.path}: ground-truth topic {topic} is {info.msgtype}; expected one of "
            + ", ".join(t.rsplit("/", 1)[-1] for t in GROUND_TRUTH_TYPES)
        )
    connections = [c for c in bag.reader.connections if c.topic == topic]
    stamps, xyz = [], []
    for conn, timestamp_ns, raw in bag.messages(connections):
        msg = bag.deserialize(raw, conn.msgtype, f"{bag.path} {topic}")
        stamp = stamp_to_seconds(msg.header.stamp)
        stamps.append(stamp if stamp != 0.0 else timestamp_ns * 1e-9)
        xyz.append(_position_of(msg, conn.msgtype))
    xyz_arr = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    stamps_arr = np.asarray(stamps, dtype=np.float64)
    finite = np.isfinite(xyz_arr).all(axis=1)
    return TimedPositions(stamps_arr[finite], xyz_arr[finite])


def read_bag(
    path: str | os.PathLike[str],
    topics: Mapping[str, str] | None = None,
    ground_truth_topic: str | None = None,
    sensors: Iterable[str] | None = None,
) -> Sequence:
    """A whole bag as a :class:`Sequence` (frames sorted by stamp, then sensor).

    ``ground_truth_topic`` defaults to :data:`DEFAULT_GROUND_TRUTH_TOPIC`, read if the bag
    has it; a topic given explicitly must exist. See :func:`iter_bag_frames` for the rest.
    """
    p = Path(path)
    with _OpenBag(p) as bag:
        mapping = _resolve_lidar_topics(bag, topics, sensors)
        frames = list(_iter_frames(bag, mapping, REORDER_WINDOW_S))
        gt_topic = ground_truth_topic or DEFAULT_GROUND_TRUTH_TOPIC
        ground_truth = _read_ground_truth(bag, gt_topic, required=ground_truth_topic is not None)
    frames.sort(key=lambda f: (f.stamp, f.sensor))
    name = p.name[: -len(p.suffix)] if p.is_file() else p.name
    return Sequence(name=name, frames=frames, ground_truth=ground_truth)


# ----------------------------------------------------------------------------- writing


class _MessageBuilder:
    """Serialises frames and positions for one ROS version with the rosbags typestore."""

    def __init__(self, ros_version: int, frame_id: str, layout: str, lidar_msg: str) -> None:
        self.ros_version = ros_version
        self.store = typestore_for(ros_version)
        self.frame_id = frame_id
        self.layout = layout
        self.lidar_msg = lidar_msg
        self.seq = 0
        types = self.store.types
        self.Time = types["builtin_interfaces/msg/Time"]
        self.Header = types["std_msgs/msg/Header"]
        self.PointCloud2 = types[POINTCLOUD2]
        self.PointField = types["sensor_msgs/msg/PointField"]
        self.PointStamped = types["geometry_msgs/msg/PointStamped"]
        self.Point = types["geometry_msgs/msg/Point"]

    @property
    def lidar_type(self) -> str:
        return POINTCLOUD2 if self.lidar_msg == "PointCloud2" else "livox_ros_driver2/msg/CustomMsg"

    def header(self, stamp: float) -> Any:
        sec, nanosec = seconds_to_stamp(
            stamp, MAX_ROS1_SEC if self.ros_version == 1 else MAX_ROS2_SEC
        )
        kwargs: dict[str, Any] = {
            "stamp": self.Time(sec=sec, nanosec=nanosec),
            "frame_id": self.frame_id,
        }
        if self.ros_version == 1:
            kwargs["seq"] = self.seq
            self.seq += 1
        return self.Header(**kwargs)

    def serialize(self, msg: Any, msgtype: str) -> bytes:
        if self.ros_version == 1:
            return bytes(self.store.serialize_ros1(msg, msgtype))
        return bytes(self.store.serialize_cdr(msg, msgtype))

    def lidar(self, frame: Frame) -> bytes:
        if self.lidar_msg == "CustomMsg":
            self.seq += 1
            return encode_custom_msg(
                frame, self.ros_version, frame_id=self.frame_id, seq=self.seq - 1
            )
        msg = frame_to_pointcloud2(
            frame, self.PointCloud2, self.PointField, self.header(frame.stamp), self.layout
        )
        return self.serialize(msg, POINTCLOUD2)

    def point(self, stamp: float, xyz: np.ndarray) -> bytes:
        x, y, z = (float(v) for v in xyz)
        msg = self.PointStamped(header=self.header(stamp), point=self.Point(x=x, y=y, z=z))
        return self.serialize(msg, "geometry_msgs/msg/PointStamped")


def _messages(
    frames: Iterable[Frame],
    ground_truth: TimedPositions | None,
    topics: Mapping[str, str],
    gt_topic: str | None,
) -> Iterator[tuple[float, str, Frame | np.ndarray]]:
    """(stamp, topic, frame or GT position) for every message, merged in time order.

    ``frames`` must be time-ordered (as every reader here yields them); ground truth
    positions are merged in between without holding the frames in memory.
    """

    def lidar() -> Iterator[tuple[float, int, str, Frame | np.ndarray]]:
        for frame in frames:
            topic = topics.get(frame.sensor)
            if topic is None:
                raise InputError(
                    f"no bag topic for sensor {frame.sensor!r}; give topics={{sensor: topic}}"
                )
            yield frame.stamp, 1, topic, frame

    streams = [lidar()]
    if gt_topic and ground_truth is not None and len(ground_truth):
        gt = ground_truth
        streams.append((float(t), 0, gt_topic, gt.xyz[i]) for i, t in enumerate(gt.stamps))
    for stamp, _, topic, payload in heapq.merge(*streams, key=lambda r: (r[0], r[1])):
        yield stamp, topic, payload


def write_bag(
    seq: Sequence,
    path: str | os.PathLike[str],
    fmt: str = "rosbag2",
    storage: str = "sqlite3",
    topics: Mapping[str, str] | None = None,
    ground_truth_topic: str | None = DEFAULT_GROUND_TRUTH_TOPIC,
    frame_id: str = "livox_frame",
    layout: str = "livox",
    lidar_msg: str = "PointCloud2",
    overwrite: bool = False,
    progress: Any = None,
) -> Path:
    """Write ``seq`` as a bag and return its path.

    Args:
        fmt: ``"rosbag2"`` (a folder) or ``"rosbag1"`` (a ``.bag`` file).
        storage: ROS 2 only: ``"sqlite3"`` or ``"mcap"``.
        topics: sensor -> topic (default :data:`DEFAULT_TOPICS`).
        ground_truth_topic: topic for PointStamped ground truth (None: not written).
        frame_id: header frame_id of every message.
        layout: PointCloud2 field layout (``livox``, ``xyz``, ``xyzi``).
        lidar_msg: ``"PointCloud2"`` or ``"CustomMsg"`` (livox_ros_driver2).
        overwrite: replace an existing output.
        progress: optional callable taking the number of lidar frames just written.

    The bag is written under a temporary name and moved into place when complete.
    """
    frames = sorted(seq.frames, key=lambda f: (f.stamp, f.sensor))
    return write_bag_frames(
        frames,
        path,
        ground_truth=seq.ground_truth,
        fmt=fmt,
        storage=storage,
        topics=topics,
        ground_truth_topic=ground_truth_topic,
        frame_id=frame_id,
        layout=layout,
        lidar_msg=lidar_msg,
        overwrite=overwrite,
        progress=progress,
    )


def write_bag_frames(
    frames: Iterable[Frame],
    path: str | os.PathLike[str],
    ground_truth: TimedPositions | None = None,
    fmt: str = "rosbag2",
    storage: str = "sqlite3",
    topics: Mapping[str, str] | None = None,
    ground_truth_topic: str | None = DEFAULT_GROUND_TRUTH_TOPIC,
    frame_id: str = "livox_frame",
    layout: str = "livox",
    lidar_msg: str = "PointCloud2",
    overwrite: bool = False,
    progress: Any = None,
) -> Path:
    """Like :func:`write_bag` for a time-ordered stream of frames (constant memory)."""
    if fmt not in ("rosbag2", "rosbag1"):
        raise InputError(f"unknown bag format {fmt!r}; choose rosbag2 or rosbag1")
    if storage not in ("sqlite3", "mcap"):
        raise InputError(f"unknown ROS 2 bag storage {storage!r}; choose sqlite3 or mcap")
    if lidar_msg not in ("PointCloud2", "CustomMsg"):
        raise InputError(f"unknown lidar message {lidar_msg!r}; choose PointCloud2 or CustomMsg")
    topic_of = dict(DEFAULT_TOPICS if topics is None else topics)
    for sensor, topic in topic_of.items():
        if not isinstance(topic, str) or not topic.strip():
            raise InputError(f"the {sensor} topic name is empty")
    if len(set(topic_of.values())) < len(topic_of):
        # Both lidars on one topic could not be told apart when the bag is read.
        raise InputError(f"two lidars share one topic: {topic_of}")
    if ground_truth_topic is not None and not ground_truth_topic.strip():
        raise InputError("the ground-truth topic name is empty")
    if ground_truth_topic and ground_truth_topic in topic_of.values():
        raise InputError(f"ground-truth topic {ground_truth_topic} is also a lidar topic")
    messages = _messages(frames, ground_truth, topic_of, ground_truth_topic)
    builder = _MessageBuilder(1 if fmt == "rosbag1" else 2, frame_id, layout, lidar_msg)
    target = Path(path)
    if fmt == "rosbag1":
        from rosbags.rosbag1 import Writer as Ros1Writer

        if target.suffix.lower() != ".bag":
            # Readers (ours, rosbag, ros2 bag) recognise a ROS 1 bag by its extension.
            raise InputError(f"output {target}: a ROS 1 bag's name must end in .bag")
        if target.exists() and not overwrite:
            raise InputError(f"output {target} already exists (choose another path or remove it)")
        with atomic_output_path(target, suffix=".bag") as tmp:
            tmp.unlink()
            with Ros1Writer(tmp) as writer:
                _write_messages(writer, builder, messages, progress)
        return target
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with atomic_output_dir(target, overwrite=overwrite) as tmp:
        inner = tmp / target.name  # rosbags names the storage file after the folder
        with Writer(inner, version=Writer.VERSION_LATEST, storage_plugin=plugin) as writer:
            _write_messages(writer, builder, messages, progress)
        for item in inner.iterdir():
            os.rename(item, tmp / item.name)
        inner.rmdir()
    return target


def _write_messages(
    writer: Any,
    builder: _MessageBuilder,
    messages: Iterable[tuple[float, str, Frame | np.ndarray]],
    progress: Any,
) -> None:
    """Serialise and write every message, adding each topic's connection on first use."""
    connections: dict[str, Any] = {}
    for stamp, topic, payload in messages:
        is_frame = isinstance(payload, Frame)
        if topic not in connections:
            msgtype = builder.lidar_type if is_frame else "geometry_msgs/msg/PointStamped"
            connections[topic] = writer.add_connection(topic, msgtype, typestore=builder.store)
        data = builder.lidar(payload) if is_frame else builder.point(stamp, payload)
        sec, nanosec = seconds_to_stamp(stamp)
        writer.write(connections[topic], sec * 1_000_000_000 + nanosec, data)
        if progress is not None and is_frame:
            progress(1)
