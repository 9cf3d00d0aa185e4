"""ROS 1 / ROS 2 (sqlite3, mcap) bags: round trips, topic mapping, ground truth, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clusterfilter_ros.core.frame import AVIA, MID360, Frame, Sequence, TimedPositions
from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io.bags import (
    bag_summary,
    iter_bag_frames,
    read_bag,
    read_bag_ground_truth,
    typestore_for,
    write_bag,
)
from clusterfilter_ros.io.dataset import detect_input_kind, iter_input_frames, open_input

pytest.importorskip("rosbags")

T0 = 1706255621.600227


def _sequence(n: int = 5) -> Sequence:
    rng = np.random.default_rng(2)
    frames = []
    for i in range(n):
        t = T0 + 0.1 * i
        for sensor, count, dt in ((MID360, 60 + i, 0.0), (AVIA, i * 3, 0.004)):
            frames.append(
                Frame(
                    t + dt,
                    sensor,
                    (rng.normal(size=(count, 3)) * 30).astype(np.float32),
                    intensity=rng.integers(0, 255, count).astype(np.float32),
                    point_time=np.sort(rng.random(count)) * 0.1,
                )
            )
    gt = TimedPositions(T0 + 0.066 * np.arange(7), rng.normal(size=(7, 3)) * 20)
    return Sequence("flight", frames, gt)


def _assert_same(seq: Sequence, back: Sequence, point_time: bool = True) -> None:
    assert [(f.sensor, len(f)) for f in back.frames] == [(f.sensor, len(f)) for f in seq.frames]
    for a, b in zip(seq.frames, back.frames, strict=True):
        assert b.stamp == pytest.approx(a.stamp, abs=1e-6)
        np.testing.assert_array_equal(b.xyz, a.xyz)
        if point_time:
            np.testing.assert_allclose(b.point_time, a.point_time, atol=1e-6)
            np.testing.assert_array_equal(b.intensity, a.intensity)
    assert back.ground_truth is not None
    np.testing.assert_allclose(back.ground_truth.stamps, seq.ground_truth.stamps, atol=1e-6)
    np.testing.assert_array_equal(back.ground_truth.xyz, seq.ground_truth.xyz)


@pytest.mark.parametrize(
    "fmt, storage, lidar_msg",
    [
        ("rosbag2", "sqlite3", "PointCloud2"),
        ("rosbag2", "mcap", "PointCloud2"),
        ("rosbag1", "sqlite3", "PointCloud2"),
        ("rosbag2", "mcap", "CustomMsg"),
        ("rosbag1", "sqlite3", "CustomMsg"),
    ],
)
def test_bag_round_trip(tmp_path: Path, fmt: str, storage: str, lidar_msg: str) -> None:
    seq = _sequence()
    path = tmp_path / ("out.bag" if fmt == "rosbag1" else "out")
    written = write_bag(seq, path, fmt=fmt, storage=storage, lidar_msg=lidar_msg)
    assert written == path and path.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    if fmt == "rosbag2":
        assert (path / "metadata.yaml").is_file()
        assert list(path.glob("out*.mcap" if storage == "mcap" else "out*.db3"))
    summary = bag_summary(path)
    assert summary.topics["/livox/avia"].count == 5
    assert summary.topics["/uav/ground_truth"].msgtype == "geometry_msgs/msg/PointStamped"
    back = read_bag(path)
    _assert_same(seq, back)
    assert back.name == "out"
    assert detect_input_kind(path) == ("rosbag1" if fmt == "rosbag1" else "rosbag2")
    lazy = list(iter_input_frames(path))
    assert [(f.stamp, f.sensor) for f in lazy] == [(f.stamp, f.sensor) for f in back.frames]


def test_bare_storage_files_and_open_input(tmp_path: Path) -> None:
    seq = _sequence(3)
    write_bag(seq, tmp_path / "b", storage="mcap")
    mcap = next((tmp_path / "b").glob("*.mcap"))
    assert detect_input_kind(mcap) == "rosbag2"
    _assert_same(seq, open_input(mcap))
    only_mid = open_input(tmp_path / "b", sensors=[MID360])
    assert {f.sensor for f in only_mid.frames} == {MID360}


def test_custom_topics_and_mapping(tmp_path: Path) -> None:
    seq = _sequence(3)
    topics = {AVIA: "/sensor_a/points", MID360: "/livox/lidar_192_168_1_3"}
    write_bag(seq, tmp_path / "b", topics=topics, ground_truth_topic="/leica/position")
    with pytest.raises(InputError, match="cannot tell which sensor .*/sensor_a/points") as info:
        read_bag(tmp_path / "b")
    assert "\n" not in str(info.value)
    mapping = {"/sensor_a/points": AVIA, "/livox/lidar_192_168_1_3": MID360}
    back = read_bag(tmp_path / "b", topics=mapping, ground_truth_topic="/leica/position")
    _assert_same(seq, back)
    # default GT topic absent: no ground truth, not an error
    assert read_bag(tmp_path / "b", topics=mapping).ground_truth is None
    gt = read_bag_ground_truth(tmp_path / "b", "/leica/position")
    np.testing.assert_array_equal(gt.xyz, seq.ground_truth.xyz)


@pytest.mark.parametrize("fmt", ["rosbag2", "rosbag1"])
@pytest.mark.parametrize(
    ("topics", "gt_topic", "message"),
    [
        ({AVIA: "/x", MID360: "/x"}, None, "two lidars share one topic"),
        ({AVIA: "", MID360: "/m"}, None, "the avia topic name is empty"),
        ({AVIA: "/a", MID360: "/m"}, " ", "the ground-truth topic name is empty"),
        ({AVIA: "/a", MID360: "/m"}, "/a", "is also a lidar topic"),
    ],
)
def test_topics_a_written_bag_could_not_be_read_back_by_are_refused(
    tmp_path: Path, fmt: str, topics, gt_topic, message
) -> None:
    out = tmp_path / ("b.bag" if fmt == "rosbag1" else "b")
    with pytest.raises(InputError, match=message):
        write_bag(_sequence(2), out, fmt=fmt, topics=topics, ground_truth_topic=gt_topic)
    assert not out.exists()


def test_a_ros1_bag_name_must_end_in_bag(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="must end in .bag"):
        write_bag(_sequence(2), tmp_path / "out", fmt="rosbag1")
    assert not (tmp_path / "out").exists()
    write_bag(_sequence(2), tmp_path / "out.BAG", fmt="rosbag1")
    assert detect_input_kind(tmp_path / "out.BAG") == "rosbag1"


@pytest.mark.parametrize("fmt", ["rosbag2", "rosbag1"])
def test_an_unreadable_bag_is_not_called_corrupt(tmp_path: Path, monkeypatch, fmt: str) -> None:
    # Run as root in CI, chmod cannot make a file unreadable: the reader's open fails as
    # rosbags does for a user without read permission (directly, or wrapped in its own).
    from rosbags.rosbag1 import Reader as Ros1Reader
    from rosbags.rosbag2 import Reader as Ros2Reader

    path = tmp_path / ("b.bag" if fmt == "rosbag1" else "b")
    write_bag(_sequence(2), path, fmt=fmt)

    def denied(self) -> None:
        try:
            raise PermissionError(13, "Permission denied", str(path))
        except PermissionError as exc:
            raise RuntimeError("could not open the bag") from exc

    monkeypatch.setattr(Ros1Reader if fmt == "rosbag1" else Ros2Reader, "open", denied)
    with pytest.raises(InputError, match=r"cannot read bag \(permission denied\)"):
        read_bag(path)


def test_unknown_topic_lists_topics(tmp_path: Path) -> None:
    write_bag(_sequence(2), tmp_path / "b")
    with pytest.raises(InputError, match=r"no topic /nope; the bag has: .*/livox/avia") as info:
        read_bag(tmp_path / "b", topics={"/nope": AVIA})
    assert str(tmp_path / "b") in str(info.value)
    with pytest.raises(InputError, match="no ground-truth topic /gt"):
        read_bag(tmp_path / "b", ground_truth_topic="/gt")
    with pytest.raises(InputError, match="not PointCloud2"):
        read_bag(tmp_path / "b", topics={"/uav/ground_truth": AVIA})


def test_pose_stamped_ground_truth(tmp_path: Path) -> None:
    """Ground truth as PoseStamped in a bag written with the raw rosbags API."""
    from rosbags.rosbag2 import Writer

    store = typestore_for(2)
    types = store.types
    path = tmp_path / "pose"
    seq = _sequence(2)
    write_bag(seq, tmp_path / "lidar", ground_truth_topic=None)
    with Writer(path, version=9) as writer:
        conn = writer.add_connection(
            "/uav/ground_truth", "geometry_msgs/msg/PoseStamped", typestore=store
        )
        for i, (t, p) in enumerate(zip(seq.ground_truth.stamps, seq.ground_truth.xyz, strict=True)):
            sec, nsec = int(t), int(round((t - int(t)) * 1e9))
            header = types["std_msgs/msg/Header"](
                stamp=types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id="map"
            )
            pose = types["geometry_msgs/msg/Pose"](
                position=types["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
                orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            )
            msg = types["geometry_msgs/msg/PoseStamped"](header=header, pose=pose)
            writer.write(
                conn, 1000 + i, bytes(store.serialize_cdr(msg, "geometry_msgs/msg/PoseStamped"))
            )
    gt = read_bag_ground_truth(path)
    np.testing.assert_allclose(gt.stamps, seq.ground_truth.stamps, atol=1e-6)
    np.testing.assert_array_equal(gt.xyz, seq.ground_truth.xyz)
    with pytest.raises(InputError, match="no PointCloud2 or Livox CustomMsg topic"):
        read_bag(path)


def test_lazy_reading_is_lazy_and_ordered(tmp_path: Path) -> None:
    seq = _sequence(6)
    write_bag(seq, tmp_path / "b.bag", fmt="rosbag1")
    it = iter_bag_frames(tmp_path / "b.bag", sensors=[AVIA])
    first = next(it)
    assert first.sensor == AVIA and first.stamp == pytest.approx(T0 + 0.004, abs=1e-6)
    rest = list(it)
    assert len(rest) == 5 and all(a.stamp < b.stamp for a, b in zip(rest, rest[1:], strict=False))


def test_existing_output_refused(tmp_path: Path) -> None:
    write_bag(_sequence(1), tmp_path / "b")
    with pytest.raises(InputError, match="already exists"):
        write_bag(_sequence(1), tmp_path / "b")
    write_bag(_sequence(2), tmp_path / "b", overwrite=True)
    assert bag_summary(tmp_path / "b").topics["/livox/mid360"].count == 2
    write_bag(_sequence(1), tmp_path / "c.bag", fmt="rosbag1")
    with pytest.raises(InputError, match="already exists"):
        write_bag(_sequence(1), tmp_path / "c.bag", fmt="rosbag1")


@pytest.mark.parametrize("kind", ["sqlite3", "mcap", "rosbag1"])
def test_truncated_bags_give_one_line_errors(tmp_path: Path, kind: str) -> None:
    seq = _sequence(8)
    if kind == "rosbag1":
        path = write_bag(seq, tmp_path / "t.bag", fmt="rosbag1")
        victim = path
    else:
        path = write_bag(seq, tmp_path / "t", storage=kind)
        victim = next(path.glob("*.mcap" if kind == "mcap" else "*.db3"))
    data = victim.read_bytes()
    victim.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError) as info:
        read_bag(path)
    message = str(info.value)
    assert str(path) in message and "\n" not in message


def test_garbage_and_missing(tmp_path: Path) -> None:
    (tmp_path / "g.bag").write_bytes(b"#ROSBAG V2.0\n" + b"\x00" * 50)
    with pytest.raises(InputError, match="g.bag"):
        read_bag(tmp_path / "g.bag")
    (tmp_path / "g.db3").write_bytes(b"this is not sqlite")
    with pytest.raises(InputError, match="g.db3"):
        open_input(tmp_path / "g.db3")
    with pytest.raises(InputError, match="no such"):
        read_bag(tmp_path / "missing.bag")


def test_ros2_bag_without_metadata_and_damaged_chunks(tmp_path: Path) -> None:
    seq = _sequence(3)
    path = write_bag(seq, tmp_path / "killed", storage="mcap")
    (path / "metadata.yaml").unlink()  # a recorder killed before writing it
    _assert_same(seq, open_input(path))
    path = write_bag(seq, tmp_path / "damaged", storage="mcap")
    victim = next(path.glob("*.mcap"))
    data = bytearray(victim.read_bytes())
    data[len(data) // 2 : len(data) // 2 + 200] = b"\xff" * 200
    victim.write_bytes(bytes(data))
    with pytest.raises(InputError, match="truncated or corrupt") as info:
        read_bag(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_rclpy_reads_the_messages_we_write_into_ros2_bags(tmp_path: Path) -> None:
    """The CDR bytes in our ROS 2 bags deserialise with rclpy into the same points."""
    pytest.importorskip("sensor_msgs.msg")
    from geometry_msgs.msg import PointStamped
    from rclpy.serialization import deserialize_message
    from rosbags.rosbag2 import Reader
    from sensor_msgs.msg import PointCloud2

    from clusterfilter_ros.io.pointcloud2 import decode_pointcloud2

    seq = _sequence(2)
    path = write_bag(seq, tmp_path / "b", storage="mcap")
    lidar, gt = [], []
    with Reader(path) as reader:
        for conn, _, raw in reader.messages():
            if conn.msgtype == "sensor_msgs/msg/PointCloud2":
                lidar.append(decode_pointcloud2(deserialize_message(raw, PointCloud2), "x").frame)
            else:
                gt.append(deserialize_message(raw, PointStamped))
    lidar.sort(key=lambda f: f.stamp)
    assert len(lidar) == len(seq.frames)
    for a, b in zip(seq.frames, lidar, strict=True):
        np.testing.assert_array_equal(a.xyz, b.xyz)
        np.testing.assert_allclose(a.point_time, b.point_time, atol=1e-6)
    assert [m.point.x for m in gt] == list(seq.ground_truth.xyz[:, 0])


def test_frames_recorded_out_of_stamp_order_come_out_in_order(tmp_path: Path) -> None:
    """Avia messages recorded 0.35 s late (record time != header stamp) are re-ordered."""
    from rosbags.rosbag2 import Writer

    from clusterfilter_ros.io.pointcloud2 import frame_to_pointcloud2, seconds_to_stamp

    store = typestore_for(2)
    types = store.types
    seq = _sequence(6)
    path = tmp_path / "late"
    with Writer(path, version=9) as writer:
        conns = {
            s: writer.add_connection(f"/livox/{s}", "sensor_msgs/msg/PointCloud2", typestore=store)
            for s in (AVIA, MID360)
        }
        for frame in seq.frames:
            sec, nsec = seconds_to_stamp(frame.stamp)
            header = types["std_msgs/msg/Header"](
                stamp=types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id="l"
            )
            msg = frame_to_pointcloud2(
                frame,
                types["sensor_msgs/msg/PointCloud2"],
                types["sensor_msgs/msg/PointField"],
                header,
            )
            delay = 0.35 if frame.sensor == AVIA else 0.0
            record_ns = int(round((frame.stamp + delay) * 1e9))
            raw = bytes(store.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2"))
            writer.write(conns[frame.sensor], record_ns, raw)
    lazy = list(iter_bag_frames(path))
    assert [(f.sensor, f.stamp) for f in lazy] == [(f.sensor, f.stamp) for f in seq.frames]
    assert [len(f) for f in read_bag(path).frames] == [len(f) for f in seq.frames]


@pytest.mark.parametrize("fmt, lidar_msg", [("rosbag2", "PointCloud2"), ("rosbag2", "CustomMsg")])
def test_stamp_beyond_a_ros2_time_is_an_input_error(
    tmp_path: Path, fmt: str, lidar_msg: str
) -> None:
    # ROS 2 builtin_interfaces/Time.sec is an int32: 2**31 s would fail in struct.pack.
    frame = Frame(2.0**31 + 0.5, MID360, np.ones((2, 3), dtype=np.float32))
    out = tmp_path / "bag"
    with pytest.raises(InputError, match=r"cannot make a ROS stamp .*0 \.\. 2147483647"):
        write_bag(Sequence("s", [frame], None), out, fmt=fmt, lidar_msg=lidar_msg)
    assert not out.exists()
