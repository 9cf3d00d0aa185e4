"""The ROS subcommands' argument handling: detector, replay, record, demo."""

from __future__ import annotations

import json
import subprocess

import pytest

from clusterfilter_ros.cli import main
from clusterfilter_ros.cli.detector import ros_arguments
from clusterfilter_ros.errors import InputError, ParameterError
from clusterfilter_ros.resources import config_file
from clusterfilter_ros.ros import processes


def test_detector_arguments_typed_for_ros():
    args = ros_arguments(
        str(config_file("detector.yaml")),
        ["eps=1", "frame_id=world", "target_offset=0,0,0.25", "min_samples=5"],
        ["--", "-r", "__node:=other"],
    )
    assert args[:2] == ["clusterfilter-detector", "--ros-args"]
    assert "eps:=1.0" in args  # a double must be written as one for ROS
    assert "target_offset:=[0.0,0.0,0.25]" in args
    assert "min_samples:=5" in args and "frame_id:=world" in args
    assert args[-2:] == ["-r", "__node:=other"] and args.count("--ros-args") == 1
    merged = ros_arguments(None, ["eps=1.5"], ["--ros-args", "-r", "__node:=x"])
    assert merged == ["clusterfilter-detector", "--ros-args", "-p", "eps:=1.5", "-r", "__node:=x"]
    with pytest.raises(ParameterError, match="unknown parameter 'epss'"):
        ros_arguments(None, ["epss=1"], [])
    with pytest.raises(ParameterError, match="eps"):
        ros_arguments(None, ["eps=-3"], [])
    with pytest.raises(InputError, match="does not exist"):
        ros_arguments("/no/such.yaml", [], [])


def test_user_errors_exit_2_before_ros_starts(tmp_path, capsys):
    assert main(["replay", str(tmp_path / "missing")]) == 2
    assert "missing" in capsys.readouterr().err
    assert main(["replay", str(tmp_path), "--rate", "-1"]) == 2
    assert main(["record", str(tmp_path / "a.csv"), "--duration", "0"]) == 2
    assert main(["demo", "--rate", "0", "--out", str(tmp_path / "d")]) == 2
    assert main(["detector", "-p", "eps=abc"]) == 2
    assert "eps" in capsys.readouterr().err


@pytest.mark.ros
def test_detector_rejects_bad_params_file_at_start(tmp_path, ros_env):
    bad = tmp_path / "bad.yaml"
    bad.write_text("/**:\n  ros__parameters:\n    eps: 100.0\n")
    proc = subprocess.run(
        processes.cli_command("detector", "--params-file", str(bad)),
        env=ros_env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2, proc.stderr
    assert "eps" in proc.stderr


@pytest.mark.ros
def test_record_without_publisher_writes_empty_csv(tmp_path, ros_env):
    out = tmp_path / "poses.csv"
    proc = subprocess.run(
        processes.cli_command("record", str(out), "--duration", "0.5", "--topic", "/nobody"),
        env=ros_env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    assert out.read_text() == "timestamp,x,y,z\n"
    assert "no message arrived" in proc.stderr


@pytest.mark.ros
def test_record_stops_on_ctrl_c_and_writes_its_csv(tmp_path, ros_env):
    out = tmp_path / "poses.csv"
    child = processes.start(
        "record",
        processes.cli_command("record", str(out), "--topic", "/nobody"),
        ros_env,
        tmp_path / "logs",
    )
    try:
        assert processes.wait_for_log(child, "recording /nobody", 60.0), child.log_tail()
    finally:
        code = child.interrupt()
    log = child.log_path.read_text(errors="replace")
    assert code == 0, log
    assert "record: interrupted" in log and "Traceback" not in log
    assert out.read_text() == "timestamp,x,y,z\n"


@pytest.mark.ros
@pytest.mark.slow
def test_short_demo_writes_outputs(tmp_path, ros_env):
    out = tmp_path / "demo"
    proc = subprocess.run(
        processes.cli_command(
            "demo", "--duration", "4", "--rate", "2", "--out", str(out), "--seed", "3"
        ),
        env=ros_env,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = json.loads((out / "metrics.json").read_text())
    assert summary["frames"] > 0 and "coverage" in summary["metrics"]
    # The late output (report_lag 3 s) is recorded and evaluated too.
    late = summary["late_metrics"]
    assert summary["report_lag"] == 3.0 and "coverage" in late and late["poses"] >= 0
    assert (out / "estimates_late.csv").read_text().startswith("timestamp,x,y,z")
    assert (out / "trajectory.png").stat().st_size > 10_000
    assert (out / "estimates.csv").read_text().startswith("timestamp,x,y,z")
    assert "trajectory plot" in proc.stdout
    assert "stopping: received" in (out / "logs" / "detector.log").read_text()


@pytest.mark.ros
def test_replay_reads_a_ros2_bag(tmp_path, ros_env):
    import numpy as np

    from clusterfilter_ros.core.frame import Frame, Sequence, TimedPositions
    from clusterfilter_ros.io.dataset import write_output

    frames = [
        Frame(10.0 + 0.1 * i, sensor, np.full((5, 3), i, np.float32))
        for i in range(5)
        for sensor in ("avia", "mid360")
    ]
    gt = TimedPositions([10.0, 10.2], [[1.0, 2.0, 3.0], [1.0, 2.0, 3.5]])
    bag = write_output(Sequence("s", frames, gt), tmp_path / "bag", fmt="rosbag2")
    proc = subprocess.run(
        processes.cli_command("replay", str(bag), "--no-wait", "--rate", "0"),
        env=ros_env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    assert "published {'avia': 5, 'mid360': 5} frames and 2 ground-truth points" in proc.stdout
