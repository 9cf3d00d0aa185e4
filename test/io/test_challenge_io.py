"""Challenge (MMAUD/UG2) sequence folders: reading, writing, errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clusterfilter_ros.core.frame import AVIA, MID360, Frame, Sequence, TimedPositions
from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io.challenge import (
    is_sequence_folder,
    iter_frames_folder,
    list_sequence_folders,
    parse_stamp,
    read_sequence_folder,
    write_sequence_folder,
)
from clusterfilter_ros.io.dataset import detect_input_kind, open_input, open_inputs


def _write_raw(folder: Path, name: str, arr: np.ndarray) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    np.save(path, arr)
    return path


def _padded(points: np.ndarray, rows: int) -> np.ndarray:
    out = np.zeros((rows, 3))
    out[: len(points)] = points
    return out


def _make_raw_sequence(root: Path) -> dict[str, np.ndarray]:
    """A hand-made sequence with real-style names, including stripped trailing zeros."""
    rng = np.random.default_rng(0)
    pts = {
        "m1": rng.normal(size=(40, 3)) * 10,
        "m2": rng.normal(size=(55, 3)) * 10,
        "a1": rng.normal(size=(7, 3)) * 50,
        "a2": np.empty((0, 3)),
    }
    _write_raw(root / "lidar_360", "1706255621.600227.npy", _padded(pts["m1"], 100))
    _write_raw(root / "lidar_360", "1706255621.7.npy", _padded(pts["m2"], 120))  # lost zeros
    _write_raw(root / "livox_avia", "1706255621.6.npy", _padded(pts["a1"], 240))
    _write_raw(root / "livox_avia", "1706255621.700012.npy", _padded(pts["a2"], 240))
    _write_raw(root / "ground_truth", "1706255621.65.npy", np.array([1.0, 2.0, 30.0]))
    _write_raw(root / "ground_truth", "1706255621.550001.npy", np.array([1.5, 2.5, 31.0]))
    (root / "Image").mkdir()
    (root / "Image" / "1706255621.6.png").write_bytes(b"not an image")
    (root / "lidar_360" / "notes.txt").write_text("ignored, not .npy")
    return pts


def test_read_real_style_folder(tmp_path: Path) -> None:
    seq_dir = tmp_path / "seq7"
    pts = _make_raw_sequence(seq_dir)
    seq = read_sequence_folder(seq_dir)
    assert seq.name == "seq7"
    got = [(f.stamp, f.sensor, len(f)) for f in seq.frames]
    assert got == [
        (1706255621.6, AVIA, 7),
        (1706255621.600227, MID360, 40),
        (1706255621.7, MID360, 55),
        (1706255621.700012, AVIA, 0),
    ]
    np.testing.assert_array_equal(seq.frames[1].xyz, pts["m1"].astype(np.float32))
    assert all(f.xyz.dtype == np.float32 for f in seq.frames)
    assert seq.ground_truth is not None
    np.testing.assert_array_equal(seq.ground_truth.stamps, [1706255621.550001, 1706255621.65])
    np.testing.assert_array_equal(seq.ground_truth.xyz[1], [1.0, 2.0, 30.0])
    lazy = list(iter_frames_folder(seq_dir))
    assert [(f.stamp, f.sensor) for f in lazy] == [(f.stamp, f.sensor) for f in seq.frames]
    only_avia = read_sequence_folder(seq_dir, sensors=[AVIA])
    assert {f.sensor for f in only_avia.frames} == {AVIA}


def test_stamp_parsing() -> None:
    assert parse_stamp(Path("1706255621.6.npy")) == 1706255621.6
    assert parse_stamp(Path("1706255621.npy")) == 1706255621.0
    with pytest.raises(InputError, match="abc.npy"):
        parse_stamp(Path("abc.npy"))
    assert parse_stamp(Path("0.npy")) == 0.0
    assert parse_stamp(Path("4294967295.npy")) == 4294967295.0
    for name in ("1706255599999223000.npy", "4294967296.npy", "1" * 400 + ".npy"):
        with pytest.raises(InputError, match=r"not a time in seconds up to 4294967295 .*like 17"):
            parse_stamp(Path(name))


def test_nonfinite_and_zero_rows_dropped(tmp_path: Path) -> None:
    arr = np.array(
        [[1, 2, 3], [0, 0, 0], [np.nan, 1, 1], [4, np.inf, 1], [0, 0, 5], [1e300, 0, 0], [0, 0, 0]]
    )
    _write_raw(tmp_path / "s" / "lidar_360", "10.5.npy", arr.astype(np.float64))
    seq = read_sequence_folder(tmp_path / "s")
    np.testing.assert_array_equal(seq.frames[0].xyz, [[1, 2, 3], [0, 0, 5]])
    assert seq.ground_truth is None
    # huge but float32-finite coordinates are points (their sum overflowing changes nothing)
    big = np.array([[3e38, 3e38, -3e38], [0, 0, 0]])
    _write_raw(tmp_path / "s" / "lidar_360", "11.5.npy", big)
    frame = read_sequence_folder(tmp_path / "s").frames[1]
    np.testing.assert_array_equal(frame.xyz, big[:1].astype(np.float32))


def _synthetic_sequence(n: int = 6) -> Sequence:
    rng = np.random.default_rng(1)
    frames = []
    for i in range(n):
        t = 1706255621.6 + 0.1 * i
        frames.append(Frame(t, MID360, rng.normal(size=(30 + i, 3)).astype(np.float32) * 20))
        frames.append(Frame(t + 0.0123, AVIA, rng.normal(size=(i, 3)).astype(np.float32) * 80))
    gt = TimedPositions(1706255621.6 + 0.07 * np.arange(8), rng.normal(size=(8, 3)))
    return Sequence("seq3", frames, gt)


def test_write_read_round_trip_with_padding(tmp_path: Path) -> None:
    seq = _synthetic_sequence()
    out = write_sequence_folder(seq, tmp_path / "seq3", pad_rows={MID360: [100, 120], AVIA: 4})
    rows = [np.load(f).shape[0] for f in sorted((out / "lidar_360").iterdir())]
    assert rows == [100, 120, 100, 120, 100, 120]
    avia_rows = [np.load(f).shape[0] for f in sorted((out / "livox_avia").iterdir())]
    assert avia_rows == [4, 4, 4, 4, 4, 5]  # the 5-point frame is written unpadded
    assert all(np.load(f).dtype == np.float64 for f in (out / "livox_avia").iterdir())
    name = sorted(p.name for p in (out / "lidar_360").iterdir())[0]
    assert name == "1706255621.600000.npy"
    back = read_sequence_folder(out)
    assert len(back.frames) == len(seq.frames)
    for a, b in zip(seq.frames, back.frames, strict=True):
        assert (a.sensor, len(a)) == (b.sensor, len(b))
        assert abs(a.stamp - b.stamp) < 1e-6
        np.testing.assert_array_equal(a.xyz, b.xyz)
    np.testing.assert_allclose(back.ground_truth.stamps, seq.ground_truth.stamps, atol=1e-6)
    np.testing.assert_array_equal(back.ground_truth.xyz, seq.ground_truth.xyz)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp left


def test_write_refuses_existing_and_unknown_sensor(tmp_path: Path) -> None:
    seq = _synthetic_sequence(2)
    write_sequence_folder(seq, tmp_path / "a")
    with pytest.raises(InputError, match="already exists"):
        write_sequence_folder(seq, tmp_path / "a")
    write_sequence_folder(seq, tmp_path / "a", overwrite=True)
    bad = Sequence("x", [Frame(1.0, "velodyne", np.zeros((1, 3)))])
    with pytest.raises(InputError, match="velodyne"):
        write_sequence_folder(bad, tmp_path / "b")
    assert not (tmp_path / "b").exists()


def test_root_of_sequences(tmp_path: Path) -> None:
    seq = _synthetic_sequence(2)
    for name in ("seq10", "seq2", "seq1"):
        write_sequence_folder(seq, tmp_path / "root" / name)
    (tmp_path / "root" / "README").write_text("x")
    assert [p.name for p in list_sequence_folders(tmp_path / "root")] == ["seq1", "seq2", "seq10"]
    assert list_sequence_folders(tmp_path / "root" / "seq2") == [tmp_path / "root" / "seq2"]
    assert detect_input_kind(tmp_path / "root") == "mmaud-root"
    with pytest.raises(InputError, match="3 sequences .*seq1"):
        open_input(tmp_path / "root")
    assert [s.name for s in open_inputs(tmp_path / "root")] == ["seq1", "seq2", "seq10"]
    assert open_input(tmp_path / "root" / "seq1").name == "seq1"


@pytest.mark.parametrize(
    "setup, culprit",
    [
        ("missing", "nope"),
        ("no_lidar", "empty_seq"),
        ("corrupt", "1.5.npy"),
        ("shape", "2.5.npy"),
        ("name", "frame_a.npy"),
        ("gt_shape", "3.5.npy"),
        ("gt_file", "ground_truth: not a folder"),
        ("avia_file", "livox_avia: not a folder"),
        ("broken_link", "4.5.npy: broken symbolic link"),
    ],
)
def test_errors_name_the_culprit(tmp_path: Path, setup: str, culprit: str) -> None:
    seq_dir = tmp_path / "s"
    _write_raw(seq_dir / "lidar_360", "1.0.npy", np.ones((3, 3)))
    if setup == "missing":
        seq_dir = tmp_path / "nope"
    elif setup == "no_lidar":
        seq_dir = tmp_path / "empty_seq"
        (seq_dir / "Image").mkdir(parents=True)
    elif setup == "corrupt":
        (seq_dir / "lidar_360" / "1.5.npy").write_bytes(b"\x93NUMPY garbage")
    elif setup == "shape":
        _write_raw(seq_dir / "livox_avia", "2.5.npy", np.ones((4, 2)))
    elif setup == "name":
        _write_raw(seq_dir / "lidar_360", "frame_a.npy", np.ones((3, 3)))
    elif setup == "gt_shape":
        _write_raw(seq_dir / "ground_truth", "3.5.npy", np.ones(4))
    elif setup == "gt_file":  # a file where a folder belongs is not skipped silently
        (seq_dir / "ground_truth").write_text("x")
    elif setup == "avia_file":
        (seq_dir / "livox_avia").write_text("x")
    elif setup == "broken_link":  # a frame whose file is gone is not skipped silently
        (seq_dir / "lidar_360" / "4.5.npy").symlink_to(tmp_path / "gone.npy")
    with pytest.raises(InputError) as info:
        open_input(seq_dir)
    message = str(info.value)
    assert culprit in message
    assert "\n" not in message


def test_truncated_npy(tmp_path: Path) -> None:
    path = _write_raw(tmp_path / "s" / "livox_avia", "5.0.npy", np.ones((1000, 3)))
    path.write_bytes(path.read_bytes()[:500])
    with pytest.raises(InputError, match="5.0.npy"):
        read_sequence_folder(tmp_path / "s")


def test_symlink_loop_among_the_npy_files_names_the_file(tmp_path: Path) -> None:
    seq_dir = tmp_path / "s"
    _write_raw(seq_dir / "lidar_360", "1.0.npy", np.ones((3, 3)))
    loop = seq_dir / "lidar_360" / "2.0.npy"
    loop.symlink_to(loop.name)  # a link to itself: stat fails with ELOOP
    with pytest.raises(InputError, match=r"2\.0\.npy: cannot access \(Too many levels"):
        read_sequence_folder(seq_dir)


def test_unreadable_folder_is_an_input_error(tmp_path: Path, monkeypatch, deny_inside) -> None:
    seq_dir = tmp_path / "s"
    _write_raw(seq_dir / "lidar_360", "1.0.npy", np.ones((3, 3)))
    deny_inside("is_dir", seq_dir)
    with pytest.raises(InputError, match=r"s/lidar_360: cannot access \(Permission denied\)"):
        is_sequence_folder(seq_dir)

    (tmp_path / "root").mkdir()

    def iterdir(self: Path):
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "iterdir", iterdir)
    with pytest.raises(InputError, match=r"root: cannot access \(Permission denied\)"):
        list_sequence_folders(tmp_path / "root")


def _npy_with_header(path: Path, shape: tuple[int, ...], data: bytes) -> None:
    header = f"{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}"
    header = header + " " * (117 - len(header)) + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(
        b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode() + data
    )


def test_npy_header_claiming_a_huge_shape_is_refused_before_loading(
    tmp_path: Path, monkeypatch
) -> None:
    path = tmp_path / "s" / "lidar_360" / "1.0.npy"
    _npy_with_header(path, (10_000_000_000, 3), b"\0" * 100)
    loaded = []
    monkeypatch.setattr(np, "load", lambda *a, **k: loaded.append(a) or np.ones((1, 3)))
    with pytest.raises(InputError, match=r"1\.0\.npy: truncated .*\(10000000000, 3\)") as info:
        read_sequence_folder(tmp_path / "s")
    assert "100 bytes of data" in str(info.value)
    assert not loaded  # np.load never tried to allocate 240 GB


def test_memory_error_while_loading_an_npy_is_an_input_error(tmp_path: Path, monkeypatch) -> None:
    _write_raw(tmp_path / "s" / "lidar_360", "1.0.npy", np.ones((3, 3)))

    def no_memory(*args: object, **kwargs: object) -> np.ndarray:
        raise MemoryError("Unable to allocate 224. GiB")

    monkeypatch.setattr(np.lib.format, "read_array", no_memory)
    with pytest.raises(InputError, match=r"1\.0\.npy: array too large to load into memory"):
        read_sequence_folder(tmp_path / "s")
