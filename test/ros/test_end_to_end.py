"""Node, replay and recorder as three processes over loopback DDS (the ros_env domain)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rclpy")

from clusterfilter_ros.cli import main  # noqa: E402
from clusterfilter_ros.core.evaluation import evaluate  # noqa: E402
from clusterfilter_ros.core.params import detector_params  # noqa: E402
from clusterfilter_ros.core.streaming import run_streaming  # noqa: E402
from clusterfilter_ros.io.dataset import open_input, write_output  # noqa: E402
from clusterfilter_ros.io.groundtruth import read_positions_csv  # noqa: E402
from clusterfilter_ros.io.pointcloud2 import make_pointcloud2, pointcloud2_to_frame  # noqa: E402
from clusterfilter_ros.resources import config_file  # noqa: E402
from clusterfilter_ros.ros import processes  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_detector_replay_recorder_processes(tmp_path, ros_env, small_sequence):
    folder = write_output(small_sequence, tmp_path / "seq", fmt="mmaud")
    sequence = open_input(folder)
    n_frames = len(sequence.frames)
    logs = tmp_path / "logs"
    csv = tmp_path / "poses.csv"
    detector = processes.start(
        "detector",
        processes.cli_command(
            "detector",
            "--params-file",
            str(config_file("detector.yaml")),
            "-p",
            "sync_timeout=1.0",  # margin for a busy CI machine; order must never need it
            "-p",
            "recluster_in_background=false",  # reproducible: compared with run_streaming
        ),
        ros_env,
        logs,
    )
    recorder = processes.start(
        "recorder",
        processes.cli_command(
            "record",
            str(csv),
            "--bag",
            str(tmp_path / "bag"),
            "--until-frames",
            str(n_frames),
            "--timeout",
            "90",
        ),
        ros_env,
        logs,
    )
    children = [detector, recorder]
    try:
        assert processes.wait_for_log(recorder, "record: matched", 60.0), (
            recorder.log_tail() + detector.log_tail()
        )
        replay = processes.start(
            "replay",
            processes.cli_command("replay", str(folder), "--rate", "2", "--wait-for", "/uav/pose"),
            ros_env,
            logs,
        )
        children.append(replay)
        assert replay.wait(90) == 0, replay.log_tail()
        assert recorder.wait(60) == 0, recorder.log_tail() + detector.log_tail()
        assert "detector handled" in recorder.log_tail(), recorder.log_tail()
        assert detector.interrupt() == 0, detector.log_tail()  # Ctrl-C exits 0
    finally:
        for child in children:
            if child.running():
                child.interrupt(timeout=5.0)

    report = "\n".join(c.log_tail(8) for c in children)
    poses = read_positions_csv(csv)
    # Three processes, DDS in between: still exactly the streaming core's answer.
    wire = [pointcloud2_to_frame(make_pointcloud2(f, f.sensor), f.sensor) for f in sequence.frames]
    expected = run_streaming(wire, detector_params())
    assert len(poses) == len(expected), report
    np.testing.assert_array_equal(poses.xyz, [e.position for e in expected])
    result = evaluate(poses, sequence.ground_truth)
    # ... and the offline command's stream mode on the same folder, up to the
    # nanosecond rounding of header stamps.
    detect_csv = tmp_path / "detect.csv"
    assert (
        main(
            [
                "detect",
                str(folder),
                "--mode",
                "stream",
                "-o",
                str(detect_csv),
                "--quiet",
                "--params-file",
                str(config_file("detector.yaml")),
            ]
        )
        == 0
    )
    offline = read_positions_csv(detect_csv)
    assert len(offline) == len(poses)
    np.testing.assert_allclose(offline.stamps, poses.stamps, rtol=0, atol=1e-9)
    np.testing.assert_allclose(offline.xyz, poses.xyz, rtol=0, atol=1e-9)
    # Coverage is the core's business (the poses equal run_streaming's, above); what
    # crossed the three processes must still be a drone track close to ground truth.
    assert len(poses) >= 20 and result.coverage > 0.25, (result.as_dict(), report)
    assert result.median_error < 0.5 and result.p95_error < 1.5, (result.as_dict(), report)
    assert (tmp_path / "bag" / "metadata.yaml").is_file()
