"""Ground truth: challenge folders, CSV round trips, atomic writes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from clusterfilter_ros.core.frame import TimedPositions
from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io.atomic import atomic_output_path, atomic_write_text
from clusterfilter_ros.io.groundtruth import (
    read_ground_truth,
    read_positions_csv,
    write_positions_csv,
)


def test_csv_round_trip_exact_with_extras(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    pos = TimedPositions(1706255621.600227 + np.arange(5) * 0.1, rng.normal(size=(5, 3)) * 40)
    score = rng.random(5)
    labels = np.array(["drone", "drone", "none", "a,b", "drone"])
    path = write_positions_csv(tmp_path / "out" / "gt.csv", pos, {"score": score, "label": labels})
    assert path.read_text().splitlines()[0] == "timestamp,x,y,z,score,label"
    back = read_positions_csv(path)
    np.testing.assert_array_equal(back.stamps, pos.stamps)
    np.testing.assert_array_equal(back.xyz, pos.xyz)
    np.testing.assert_array_equal(back.extra["score"], score)
    assert list(back.extra["label"]) == list(labels)
    assert read_ground_truth(path).xyz.shape == (5, 3)


def test_csv_extra_columns_ignored_and_reordered(tmp_path: Path) -> None:
    path = tmp_path / "gt.csv"
    path.write_text("z,quality,timestamp,x,y\n3,0.9,10.5,1,2\n6,0.8,10.0,4,5\n")
    pos = read_ground_truth(path)
    np.testing.assert_array_equal(pos.stamps, [10.0, 10.5])
    np.testing.assert_array_equal(pos.xyz, [[4, 5, 6], [1, 2, 3]])
    np.testing.assert_array_equal(pos.extra["quality"], [0.8, 0.9])


def test_empty_csv_with_header(tmp_path: Path) -> None:
    path = tmp_path / "gt.csv"
    path.write_text("timestamp,x,y,z\n")
    assert len(read_positions_csv(path)) == 0


@pytest.mark.parametrize(
    "text, match",
    [
        ("", "empty"),
        ("time_s,a,b,c\n1,2,3,4\n", "lacks"),
        ("timestamp,x,y,z\n1,2,3\n", "line 2"),
        ("timestamp,x,y,z\n1,2,three,4\n", "'y'"),
    ],
)
def test_bad_csv(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(InputError, match=match) as info:
        read_ground_truth(path)
    assert "bad.csv" in str(info.value) and "\n" not in str(info.value)


def test_ground_truth_folder_forms(tmp_path: Path) -> None:
    gt = tmp_path / "seq1" / "ground_truth"
    gt.mkdir(parents=True)
    np.save(gt / "2.5.npy", np.array([1.0, 2.0, 3.0]))
    np.save(gt / "1.25.npy", np.array([4.0, 5.0, 6.0]))
    for path in (gt, tmp_path / "seq1"):
        pos = read_ground_truth(path)
        np.testing.assert_array_equal(pos.stamps, [1.25, 2.5])
        np.testing.assert_array_equal(pos.xyz, [[4, 5, 6], [1, 2, 3]])
    with pytest.raises(InputError, match="missing"):
        read_ground_truth(tmp_path / "missing")


def test_atomic_writers_keep_old_file_on_failure(tmp_path: Path) -> None:
    path = tmp_path / "result.txt"
    atomic_write_text(path, "old")
    with pytest.raises(RuntimeError), atomic_output_path(path) as tmp:
        tmp.write_text("half")
        raise RuntimeError("writer failed")
    assert path.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.txt"]
    atomic_write_text(path, "new")
    assert path.read_text() == "new"


def test_csv_with_bom_and_crlf(tmp_path: Path) -> None:
    path = tmp_path / "excel.csv"
    path.write_bytes("\ufefftimestamp,x,y,z\r\n1.5,1,2,3\r\n".encode())
    pos = read_positions_csv(path)
    np.testing.assert_array_equal(pos.xyz, [[1, 2, 3]])


def test_csv_field_over_the_csv_size_limit_names_the_line(tmp_path: Path) -> None:
    path = tmp_path / "gt.csv"
    path.write_text("timestamp,x,y,z\n1.0,1,2,3\n" + "1" * 200_000 + ",1,2,3\n")
    with pytest.raises(InputError, match=r"gt\.csv: line 3: not a valid CSV row \(field larger"):
        read_positions_csv(path)
