"""``clusterfilter simulate``: outputs, padding, preview, errors."""

from __future__ import annotations

import numpy as np
import pytest

from clusterfilter_ros.cli import main
from clusterfilter_ros.io.dataset import open_input


def test_list(capsys):
    assert main(["simulate", "--list"]) == 0
    out = capsys.readouterr().out
    for name in ("default", "no_drone", "avia_only", "long_mixed", "m300"):
        assert name in out


def test_mmaud_folder_padded_like_the_challenge_with_preview_and_truth(tmp_path, capsys):
    out = tmp_path / "seq"
    png = tmp_path / "pics" / "preview.png"
    npz = tmp_path / "truth.npz"
    argv = ["simulate", str(out), "--duration", "0.5", "--seed", "1", "--quiet"]
    assert main([*argv, "--preview", str(png), "--truth", str(npz)]) == 0
    assert "wrote 10 frames" in capsys.readouterr().out
    mid_files = sorted((out / "lidar_360").glob("*.npy"))
    avia_files = sorted((out / "livox_avia").glob("*.npy"))
    assert len(mid_files) == len(avia_files) == 5
    rows = [np.load(p).shape for p in mid_files]
    assert [r[0] for r in rows] == [19968, 20064, 19968, 20064, 19968]
    arr = np.load(avia_files[0])
    assert arr.shape == (24000, 3) and arr.dtype == np.float64
    real = np.any(np.load(mid_files[0]) != 0, axis=1).sum()
    assert 3500 < real < 5000
    assert len(list((out / "ground_truth").glob("*.npy"))) >= 5
    seq = open_input(out)
    assert len(seq.frames) == 10 and len(seq.ground_truth) >= 5
    assert png.stat().st_size > 20_000
    truth = np.load(npz)
    assert truth["xyz"].shape[1] == 3 and len(truth["frame_points"]) == 10
    # Existing output is not replaced without --overwrite.
    assert main(argv) == 2
    assert "already exists" in capsys.readouterr().err
    assert main([*argv, "--overwrite"]) == 0


@pytest.mark.parametrize("fmt,name", [("rosbag2", "bag2"), ("rosbag1", "run.bag")])
def test_bags(tmp_path, fmt, name):
    out = tmp_path / name
    assert main(["simulate", str(out), "--duration", "0.3", "--format", fmt, "--quiet"]) == 0
    seq = open_input(out)
    assert sorted(seq.sensors()) == ["avia", "mid360"]
    assert len(seq.frames) == 6
    assert seq.ground_truth is not None and len(seq.ground_truth) >= 3


def test_user_errors_exit_2(tmp_path, capsys):
    cases = [
        (["--scenario", "nope"], "unknown scenario"),
        (["--scenario", "no_drone", "--drone", "mavic2"], "has no drone"),
        (["--drone", "f16"], "unknown drone"),
        (["--duration", "-1"], "duration"),
        (["--duration", "0.05"], "shorter than one 0.1 s lidar frame"),
        (["--preview", str(tmp_path / "x.jpg")], "expected a .png"),
    ]
    for extra, message in cases:
        assert main(["simulate", str(tmp_path / "o"), "--quiet", *extra]) == 2
        assert message in capsys.readouterr().err
    assert main(["simulate", "--quiet"]) == 2
    assert "give an output path" in capsys.readouterr().err
