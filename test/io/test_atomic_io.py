"""Atomic outputs: temporaries left by a killed writer are cleaned up later."""

from __future__ import annotations

import errno
import os
import sqlite3
import stat
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from clusterfilter_ros.core.frame import MID360, Frame
from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io import atomic
from clusterfilter_ros.io.atomic import (
    atomic_output_dir,
    atomic_write_text,
    remove_stale_temporaries,
)
from clusterfilter_ros.io.challenge import write_frames_folder


def test_stale_temporary_of_a_killed_writer_is_removed_by_the_next_write(tmp_path):
    out = tmp_path / "estimates.csv"
    stale = tmp_path / ".estimates.csv.abc123.tmp"
    stale.write_text("half a file")
    old = time.time() - 2 * 3600
    os.utime(stale, (old, old))
    fresh = tmp_path / ".estimates.csv.def456.tmp"  # a writer that may still be running
    fresh.write_text("in progress")
    other = tmp_path / ".other.csv.xyz.tmp"  # someone else's output
    other.write_text("x")
    os.utime(other, (old, old))
    atomic_write_text(out, "timestamp,x,y,z\n")
    assert out.read_text() == "timestamp,x,y,z\n"
    assert not stale.exists()
    assert fresh.exists()
    assert other.exists()


def test_remove_stale_temporaries_counts_and_tolerates_a_missing_folder(tmp_path):
    target = tmp_path / "a[1].csv"  # glob metacharacters in the name
    tmp = tmp_path / ".a[1].csv.q.tmp.npy"
    tmp.write_text("x")
    os.utime(tmp, (0, 0))
    assert remove_stale_temporaries(target) == 1
    assert remove_stale_temporaries(tmp_path / "missing" / "b.csv") == 0


def _frames(n: int = 3) -> list[Frame]:
    xyz = np.arange(30, dtype=np.float32).reshape(10, 3)
    return [Frame(1706255621.6 + 0.1 * i, MID360, xyz) for i in range(n)]


@pytest.mark.parametrize(
    "exc, reason",
    [
        (OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)), os.strerror(errno.ENOSPC)),
        (sqlite3.OperationalError("disk I/O error"), "disk I/O error"),
    ],
)
def test_write_error_in_an_output_folder_is_an_input_error(
    tmp_path: Path, exc: Exception, reason: str
) -> None:
    out = tmp_path / "out"
    with pytest.raises(InputError, match=f"cannot write {out}: {reason}$"):
        with atomic_output_dir(out) as tmp:
            (tmp / "half").write_text("x")
            raise exc
    assert list(tmp_path.iterdir()) == []  # temporary folder removed, nothing in place


def test_disk_full_while_writing_a_sequence_folder(tmp_path: Path, monkeypatch) -> None:
    out = tmp_path / "seq"
    out.mkdir()
    (out / "keep.txt").write_text("previous result")

    def full(*args: object, **kwargs: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(np, "save", full)
    with pytest.raises(InputError, match="No space left on device"):
        write_frames_folder(_frames(), out, overwrite=True)
    assert [p.name for p in tmp_path.iterdir()] == ["seq"]
    assert (out / "keep.txt").read_text() == "previous result"


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_write_error_while_writing_a_ros2_bag(tmp_path: Path, monkeypatch, storage: str) -> None:
    pytest.importorskip("rosbags")
    from rosbags.rosbag2 import storage_mcap, storage_sqlite3

    from clusterfilter_ros.io.bags import write_bag_frames

    def io_error(*args: object, **kwargs: object) -> None:
        if storage == "sqlite3":
            raise sqlite3.OperationalError("disk I/O error")
        raise OSError(errno.EFBIG, os.strerror(errno.EFBIG))

    module = storage_sqlite3.Sqlite3Writer if storage == "sqlite3" else storage_mcap.McapWriter
    monkeypatch.setattr(module, "write", io_error)
    out = tmp_path / "bag"
    reason = "disk I/O error" if storage == "sqlite3" else os.strerror(errno.EFBIG)
    with pytest.raises(InputError, match=f"cannot write {out}: {reason}$"):
        write_bag_frames(_frames(), out, storage=storage)
    assert list(tmp_path.iterdir()) == []


def test_output_through_a_symlink_replaces_the_linked_file_and_keeps_the_link(
    tmp_path: Path,
) -> None:
    real = tmp_path / "results" / "estimates.csv"
    real.parent.mkdir()
    real.write_text("old\n")
    link = tmp_path / "latest.csv"
    link.symlink_to(real)
    atomic_write_text(link, "new\n")
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert real.read_text() == "new\n"
    assert sorted(p.name for p in real.parent.iterdir()) == ["estimates.csv"]


def test_output_to_a_fifo_is_written_into_it_not_replaced(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received: list[bytes] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()
    atomic_write_text(fifo, "timestamp,x,y,z\n")
    reader.join(timeout=10)
    assert received == [b"timestamp,x,y,z\n"]
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)  # still a FIFO, not a regular file
    assert [p.name for p in tmp_path.iterdir()] == ["pipe"]  # no temporary left beside it


def test_output_to_a_device_like_file_is_copied_into_it(tmp_path: Path, monkeypatch) -> None:
    # Stand-in for /dev/null (a test must not touch the real one): a file the check
    # reports as special is written in place, never replaced by os.replace.
    target = tmp_path / "device"
    target.write_text("")
    inode = target.stat().st_ino
    monkeypatch.setattr(atomic, "_is_special_file", lambda path: path == target)
    atomic_write_text(target, "data\n")
    assert target.stat().st_ino == inode and target.read_text() == "data\n"
    assert [p.name for p in tmp_path.iterdir()] == ["device"]
