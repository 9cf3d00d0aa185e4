"""``clusterfilter convert`` and ``clusterfilter info``: round trips and one-line errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clusterfilter_ros.cli import main
from clusterfilter_ros.core.frame import AVIA, MID360, Frame, Sequence, TimedPositions
from clusterfilter_ros.io.challenge import read_sequence_folder, write_sequence_folder

T0 = 1706255621.6


def _seq_folder(path: Path) -> Sequence:
    rng = np.random.default_rng(4)
    frames = []
    for i in range(4):
        frames.append(Frame(T0 + 0.1 * i, MID360, rng.normal(size=(50, 3)).astype(np.float32) * 9))
        frames.append(Frame(T0 + 0.1 * i + 0.03, AVIA, rng.normal(size=(i, 3)).astype(np.float32)))
    seq = Sequence(path.name, frames, TimedPositions(T0 + np.arange(3) * 0.1, np.ones((3, 3))))
    write_sequence_folder(seq, path, pad_rows={MID360: [80, 90], AVIA: 100})
    return seq


def test_convert_chain_round_trip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    original = _seq_folder(tmp_path / "seq1")
    steps = [
        (tmp_path / "seq1", tmp_path / "b2", ["--to", "rosbag2", "--storage", "mcap"]),
        (tmp_path / "b2", tmp_path / "b1.bag", ["--to", "rosbag1", "--lidar-msg", "CustomMsg"]),
        (tmp_path / "b1.bag", tmp_path / "seq1_again", ["--to", "mmaud", "--pad", "none"]),
    ]
    for src, dst, opts in steps:
        assert main(["convert", str(src), str(dst), *opts, "--quiet"]) == 0
        assert "wrote 8 frames and 3 ground-truth positions" in capsys.readouterr().out
    back = read_sequence_folder(tmp_path / "seq1_again")
    assert [(f.sensor, len(f)) for f in back.frames] == [
        (f.sensor, len(f)) for f in original.frames
    ]
    for a, b in zip(original.frames, back.frames, strict=True):
        np.testing.assert_array_equal(a.xyz, b.xyz)
        assert abs(a.stamp - b.stamp) < 1e-6
    np.testing.assert_array_equal(back.ground_truth.xyz, original.ground_truth.xyz)
    padded = sorted((tmp_path / "seq1" / "lidar_360").iterdir())
    assert np.load(padded[0]).shape == (80, 3)
    unpadded = sorted((tmp_path / "seq1_again" / "lidar_360").iterdir())
    assert np.load(unpadded[0]).shape == (50, 3)


def test_info(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _seq_folder(tmp_path / "root" / "seq2")
    _seq_folder(tmp_path / "root" / "seq10")
    assert main(["info", str(tmp_path / "root")]) == 0
    out = capsys.readouterr().out
    assert out.index("seq2") < out.index("seq10")
    assert "mid360: 4 frames, 10.00 Hz, 0.30 s" in out
    assert "avia: 4 frames" in out and "median 1" in out
    assert "ground truth: 3 positions" in out
    assert (
        main(
            [
                "convert",
                str(tmp_path / "root" / "seq2"),
                str(tmp_path / "b"),
                "--to",
                "rosbag2",
                "--quiet",
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert main(["info", str(tmp_path / "b"), "--sensors", "avia"]) == 0
    out = capsys.readouterr().out
    assert "topic /livox/avia: sensor_msgs/msg/PointCloud2, 4 messages" in out
    assert "  mid360:" not in out and "  avia: 4 frames" in out


@pytest.mark.parametrize(
    "argv, culprit",
    [
        (["info", "{tmp}/missing"], "missing"),
        (["convert", "{tmp}/missing", "{tmp}/out", "--to", "rosbag2"], "missing"),
        (["convert", "{tmp}/b", "{tmp}/out", "--to", "mmaud", "--topic", "/nope=avia"], "/nope"),
        (["convert", "{tmp}/b", "{tmp}/out", "--to", "mmaud", "--topic", "bad"], "TOPIC=SENSOR"),
        (["convert", "{tmp}/seq1", "{tmp}/b", "--to", "rosbag2"], "already exists"),
    ],
)
def test_errors_are_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], culprit: str
) -> None:
    _seq_folder(tmp_path / "seq1")
    assert (
        main(["convert", str(tmp_path / "seq1"), str(tmp_path / "b"), "--to", "rosbag2", "--quiet"])
        == 0
    )
    capsys.readouterr()
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert culprit in err and "\n" not in err and "Traceback" not in err


def test_console_script_exit_code(tmp_path: Path) -> None:
    """The installed entry point exits non-zero with one line for a corrupt .npy."""
    seq = tmp_path / "seq1"
    _seq_folder(seq)
    victim = sorted((seq / "livox_avia").iterdir())[1]
    victim.write_bytes(b"garbage")
    proc = subprocess.run(
        [sys.executable, "-m", "clusterfilter_ros.cli", "info", str(seq)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert victim.name in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
