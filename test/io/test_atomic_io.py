"""Atomic outputs: temporaries left by a killed writer are cleaned up later."""

from __future__ import annotations

import os
import time

from clusterfilter_ros.io.atomic import atomic_write_text, remove_stale_temporaries


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
