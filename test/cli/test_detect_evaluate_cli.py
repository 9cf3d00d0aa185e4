"""`clusterfilter detect` and `clusterfilter evaluate` end to end on small recordings."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from clusterfilter_ros.cli import main
from clusterfilter_ros.core.frame import AVIA, MID360, Sequence, TimedPositions
from clusterfilter_ros.io.dataset import write_output
from clusterfilter_ros.io.groundtruth import read_positions_csv

_spec = importlib.util.spec_from_file_location(
    "detector_scenes", Path(__file__).parents[1] / "core" / "conftest.py"
)
scenes = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(scenes)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    root = tmp_path_factory.mktemp("rec")
    frames, tt, tx = scenes.build_scene(duration=10.0, wall_points=200)
    gt = TimedPositions(tt[::3], tx[::3])
    seq = Sequence("flight", frames, gt)
    write_output(seq, root / "mmaud" / "flight", fmt="mmaud")
    write_output(seq, root / "bag2", fmt="rosbag2")
    renamed = {AVIA: "/up/points", MID360: "/around/points"}
    write_output(seq, root / "renamed.bag", fmt="rosbag1", topics=renamed, ground_truth_topic="/gt")
    quiet, _, _ = scenes.build_scene(duration=6.0, drone=False, seed=5, wall_points=200)
    write_output(Sequence("empty", quiet, None), root / "mmaud" / "empty", fmt="mmaud")
    write_output(Sequence("empty", quiet, None), root / "empty_bag", fmt="rosbag2")
    return root


@pytest.mark.parametrize("mode", ["offline", "stream"])
@pytest.mark.parametrize("source", ["mmaud/flight", "bag2"])
def test_detect_then_evaluate(recordings, tmp_path, mode, source, capsys):
    out = tmp_path / "pred.csv"
    rc = main(["detect", str(recordings / source), "--mode", mode, "-o", str(out), "--quiet"])
    assert rc == 0
    header = out.read_text().splitlines()[0]
    assert header == "timestamp,x,y,z,confidence,points"
    pred = read_positions_csv(out)
    assert len(pred) > 50
    capsys.readouterr()
    png = tmp_path / "eval.png"
    gt_path = recordings / "mmaud" / "flight"
    rc = main(["evaluate", str(out), str(gt_path), "--json", "--plot", str(png)])
    assert rc == 0
    metrics = json.loads(capsys.readouterr().out)
    assert metrics["rmse"] < 0.6
    assert metrics["detection_rate"] > (0.9 if mode == "offline" else 0.45)  # 5 s warm-up
    assert png.stat().st_size > 10_000


def test_ug2_format_over_a_folder_of_sequences(recordings, tmp_path):
    out = tmp_path / "results.csv"
    rc = main(["detect", str(recordings / "mmaud"), "--format", "ug2", "-o", str(out), "--quiet"])
    assert rc == 0
    lines = out.read_text().splitlines()
    assert lines[0] == "Sequence,Timestamp,Position,Classification"
    names = {line.split(",")[0] for line in lines[1:]}
    assert names == {"flight"}  # the drone-free sequence yields no rows
    first = lines[1].split(",", 2)[2]
    xyz = json.loads(first.rsplit(",", 1)[0].strip('"'))
    assert len(xyz) == 3


def test_ug2_rows_are_csv_for_any_sequence_name(recordings, tmp_path):
    # A folder name with a comma and one that is not UTF-8: each row still has four
    # fields, and the undecodable byte is written as an escape, not an error.
    import csv
    import os
    import shutil

    root = tmp_path / "root"
    root.mkdir()
    shutil.copytree(recordings / "mmaud" / "flight", root / "seq,1")
    odd = os.fsdecode(b"seq\xff")
    shutil.copytree(recordings / "mmaud" / "flight", root / odd)
    out = tmp_path / "results.csv"
    assert main(["detect", str(root), "--format", "ug2", "-o", str(out), "--quiet"]) == 0
    rows = list(csv.reader(out.read_text(encoding="utf-8").splitlines()))
    assert rows[0] == ["Sequence", "Timestamp", "Position", "Classification"]
    assert {len(r) for r in rows} == {4}
    assert {r[0] for r in rows[1:]} == {"seq,1", "seq\\xff"}
    # Printed to a strict UTF-8 stdout, the odd name is escaped, not an error.
    import subprocess
    import sys

    env = {**os.environ, "PYTHONIOENCODING": "utf-8"}
    cmd = [sys.executable, "-m", "clusterfilter_ros.cli", "info", str(root)]
    done = subprocess.run(cmd, capture_output=True, env=env, timeout=120, check=False)
    assert done.returncode == 0, done.stderr.decode(errors="replace")
    assert b"seq\\udcff" in done.stdout


def test_ug2_skips_a_sequence_the_timestamps_file_does_not_name(recordings, tmp_path, capsys):
    stamps = tmp_path / "stamps.csv"
    stamps.write_text("sequence,timestamp\nflight,1006.5\nother,1.0\n")
    out = tmp_path / "results.csv"
    args = ["detect", str(recordings / "mmaud"), "--format", "ug2", "-o", str(out), "--quiet"]
    assert main([*args, "--timestamps", str(stamps)]) == 0
    assert "no sequence 'empty'" in capsys.readouterr().err  # warned and skipped
    assert out.read_text().splitlines()[1].startswith("flight,1006.5,")
    # One sequence in csv format whose name the file lacks: an error, not an empty file.
    single = ["detect", str(recordings / "mmaud" / "empty"), "-o", str(tmp_path / "x.csv")]
    assert main([*single, "--quiet", "--timestamps", str(stamps)]) == 2
    assert "names no sequence 'empty'" in capsys.readouterr().err


def test_stream_mode_warns_of_frames_stored_out_of_order(recordings, tmp_path, monkeypatch, capsys):
    # A bag whose messages were logged in another order than their header stamps (a
    # lagging clock): the stream mode takes them as stored, and says so.
    from clusterfilter_ros.io import dataset

    real = dataset.iter_input_frames

    def shuffled(*args, **kwargs):
        frames = list(real(*args, **kwargs))
        frames[10], frames[40] = frames[40], frames[10]  # 40 is ~3 s after 10
        return iter(frames)

    monkeypatch.setattr(dataset, "iter_input_frames", shuffled)
    out = tmp_path / "o.csv"
    args = ["detect", str(recordings / "bag2"), "-o", str(out), "--quiet", "--mode", "stream"]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "frame(s) came more than 1 s behind the newest stamp" in err
    assert err.count("warning") == 1
    assert main([*args[:-2], "--mode", "offline"]) == 0
    assert "behind the newest" not in capsys.readouterr().err


def test_timestamps_and_params(recordings, tmp_path):
    stamps = tmp_path / "stamps.csv"
    stamps.write_text("timestamp\n1001.0\n1006.5\n1050.0\n")
    out = tmp_path / "at.csv"
    args = ["detect", str(recordings / "mmaud" / "flight"), "-o", str(out), "--quiet"]
    assert main([*args, "--timestamps", str(stamps), "--param", "target_offset=[0,0,1]"]) == 0
    pred = read_positions_csv(out)
    assert pred.stamps.tolist() == [1001.0, 1006.5]
    truth = scenes.drone_path(pred.stamps - 1000.0)
    assert np.all(np.abs(pred.xyz[:, 2] - truth[:, 2] - 1.0) < 0.5)
    stream_out = tmp_path / "at_stream.csv"
    args = ["detect", str(recordings / "mmaud" / "flight"), "-o", str(stream_out), "--quiet"]
    assert main([*args, "--mode", "stream", "--timestamps", str(stamps)]) == 0
    assert read_positions_csv(stream_out).stamps.tolist() == [1006.5]  # 1001 is in warm-up
    # With report_lag each frame is estimated again 3 s later, from the returns on both
    # sides of it: the warm-up's frames too, once the track is confirmed.
    lagged = ["--mode", "stream", "--timestamps", str(stamps), "--param", "report_lag=3.0"]
    assert main([*args, *lagged]) == 0
    pred = read_positions_csv(stream_out)
    assert pred.stamps.tolist() == [1001.0, 1006.5]
    assert np.all(np.linalg.norm(pred.xyz - scenes.drone_path(pred.stamps - 1000.0), axis=1) < 0.5)


def test_drone_free_evaluation_and_user_errors(recordings, tmp_path, capsys):
    out = tmp_path / "none.csv"
    seq = recordings / "mmaud" / "empty"
    assert main(["detect", str(seq), "-o", str(out), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(out), str(seq), "--json"]) == 0
    metrics = json.loads(capsys.readouterr().out)
    assert metrics["false_alarm_seconds"] == 0.0 and metrics["n_gt"] == 0
    assert main(["detect", str(seq), "-o", str(out), "--param", "eps=-3"]) == 2
    assert "eps" in capsys.readouterr().err
    assert main(["detect", str(tmp_path / "missing"), "-o", str(out)]) == 2
    assert main(["detect", str(recordings / "mmaud"), "-o", str(out)]) == 2  # csv needs one
    assert main(["evaluate", str(tmp_path / "missing.csv"), str(seq)]) == 2


def _evaluate_json(capsys, *argv: str) -> dict:
    capsys.readouterr()
    assert main(["evaluate", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_bag_with_its_own_topic_names(recordings, tmp_path, capsys):
    """--topic maps a bag's lidar topics; evaluate reads the bag's ground-truth topic."""
    bag = recordings / "renamed.bag"
    out = tmp_path / "pred.csv"
    assert main(["detect", str(bag), "-o", str(out), "--quiet"]) == 2
    assert "/up/points" in capsys.readouterr().err  # the error lists the bag's topics
    topics = ["--topic", "/up/points=avia", "--topic", "/around/points=mid360"]
    assert main(["detect", str(bag), "-o", str(out), "--quiet", *topics]) == 0
    reference = tmp_path / "reference.csv"
    assert main(["detect", str(recordings / "bag2"), "-o", str(reference), "--quiet"]) == 0
    assert out.read_text() == reference.read_text()

    from_bag = _evaluate_json(capsys, str(out), str(bag), "--ground-truth-topic", "/gt")
    from_folder = _evaluate_json(capsys, str(out), str(recordings / "mmaud" / "flight"))
    assert from_bag == pytest.approx(from_folder, rel=1e-6)
    assert from_bag["detection_rate"] > 0.9
    # The default topic is absent from this bag: no ground truth, so every row is a false alarm.
    drone_free = _evaluate_json(capsys, str(out), str(bag))
    assert drone_free["false_alarm_fraction"] > 0.5


def test_sensors_option_reads_one_lidar(recordings, tmp_path):
    both, avia = tmp_path / "both.csv", tmp_path / "avia.csv"
    flight = str(recordings / "mmaud" / "flight")
    assert main(["detect", flight, "-o", str(both), "--quiet"]) == 0
    assert main(["detect", flight, "-o", str(avia), "--quiet", "--sensors", "avia"]) == 0
    assert len(read_positions_csv(avia)) > 50  # the drone is in both lidars' frames
    assert out_points(avia) < out_points(both)


def out_points(path: Path) -> int:
    """Supporting points summed over a CSV's rows."""
    return int(read_positions_csv(path).extra["points"].sum())


def test_drone_free_bag_counts_every_report(recordings, tmp_path, capsys):
    pred = tmp_path / "pred.csv"
    pred.write_text("timestamp,x,y,z\n1001.0,1,2,3\n1001.1,1,2,3\n")
    metrics = _evaluate_json(capsys, str(pred), str(recordings / "empty_bag"))
    assert metrics["false_alarm_seconds"] > 0
    assert metrics["duration"] == pytest.approx(6.0, abs=0.3)
