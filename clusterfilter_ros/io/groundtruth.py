"""Ground truth and other timed positions: challenge ``ground_truth/`` folders and CSV.

CSV format: a header row naming at least ``timestamp,x,y,z`` (any order; ``stamp``,
``time`` or ``t`` are accepted for the time column), one row per position. Other columns
are kept in :attr:`TimedPositions.extra` (as float64 when every value is a number,
otherwise as strings).
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from clusterfilter_ros.core.frame import TimedPositions
from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io.atomic import atomic_write_text
from clusterfilter_ros.io.challenge import GROUND_TRUTH_FOLDER, read_ground_truth_folder

_TIME_COLUMNS = ("timestamp", "stamp", "time", "t")


def read_ground_truth(path: str | os.PathLike[str]) -> TimedPositions:
    """Ground truth from a CSV file, a ``ground_truth/`` folder, or a sequence folder."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such ground-truth file or folder")
    if p.is_file():
        return read_positions_csv(p)
    if (p / GROUND_TRUTH_FOLDER).is_dir():
        return read_ground_truth_folder(p / GROUND_TRUTH_FOLDER)
    if any(p.glob("*.npy")):
        return read_ground_truth_folder(p)
    raise InputError(f"{p}: no ground_truth/ folder and no <stamp>.npy files inside")


def csv_rows(text: str, path: str | os.PathLike[str]) -> list[list[str]]:
    """The non-blank rows of CSV ``text`` read from ``path``; a malformed file (a field
    over the csv module's size limit, ...) is an :class:`InputError` naming the line."""
    reader = csv.reader(io.StringIO(text))
    try:
        return [r for r in reader if r and any(c.strip() for c in r)]
    except csv.Error as exc:
        raise InputError(f"{path}: line {reader.line_num}: not a valid CSV row ({exc})") from None


def _column_array(values: list[str]) -> np.ndarray:
    try:
        return np.array(values, dtype=np.float64)
    except ValueError:
        return np.array(values, dtype=str)


def read_positions_csv(path: str | os.PathLike[str]) -> TimedPositions:
    """Read a ``timestamp,x,y,z[,extra...]`` CSV; extra columns go to ``.extra``.

    A timestamp that is not a finite number is an :class:`InputError` naming the line;
    rows whose x, y or z is NaN/Inf are dropped (no position).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")  # tolerate a BOM (spreadsheet exports)
    except FileNotFoundError as exc:
        raise InputError(f"{p}: no such file") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{p}: cannot read as text ({exc})") from exc
    rows = csv_rows(text, p)
    if not rows:
        raise InputError(f"{p}: empty file (expected a header timestamp,x,y,z)")
    header = [c.strip().lower() for c in rows[0]]
    time_col = next((header.index(c) for c in _TIME_COLUMNS if c in header), None)
    missing = [c for c in ("x", "y", "z") if c not in header]
    if time_col is None or missing:
        raise InputError(f"{p}: header {','.join(rows[0])!r} lacks timestamp,x,y,z columns")
    body = rows[1:]
    bad = next((i for i, r in enumerate(body) if len(r) != len(header)), None)
    if bad is not None:
        raise InputError(
            f"{p}: line {bad + 2} has {len(body[bad])} fields, the header has {len(header)}"
        )
    columns = list(zip(*body, strict=True)) if body else [() for _ in header]
    numeric = {}
    for name, idx in (
        ("t", time_col),
        ("x", header.index("x")),
        ("y", header.index("y")),
        ("z", header.index("z")),
    ):
        try:
            numeric[name] = np.array(columns[idx], dtype=np.float64)
        except ValueError as exc:
            raise InputError(
                f"{p}: column {header[idx]!r} has a non-numeric value ({exc})"
            ) from exc
    bad_time = np.flatnonzero(~np.isfinite(numeric["t"]))
    if bad_time.size:
        raise InputError(
            f"{p}: line {int(bad_time[0]) + 2}: timestamp {columns[time_col][bad_time[0]]!r} "
            "is not a finite number"
        )
    used = {time_col, header.index("x"), header.index("y"), header.index("z")}
    extra = {
        rows[0][i].strip(): _column_array(list(columns[i]))
        for i in range(len(header))
        if i not in used
    }
    xyz = np.stack([numeric["x"], numeric["y"], numeric["z"]], axis=1) if body else np.empty((0, 3))
    # Rows without a finite position (NaN/Inf) say "no position": dropped, like the
    # ground_truth/ folder reader does.
    finite = np.isfinite(xyz).all(axis=1)
    if not finite.all():
        return TimedPositions(
            numeric["t"][finite], xyz[finite], {k: v[finite] for k, v in extra.items()}
        )
    return TimedPositions(numeric["t"], xyz, extra)


def _format_column(values: np.ndarray) -> list[str]:
    arr = np.asarray(values)
    if arr.dtype.kind == "f":
        return [repr(float(v)) for v in arr]
    if arr.dtype.kind in "iub":
        return [str(int(v)) for v in arr]
    return [str(v) for v in arr]


def write_positions_csv(
    path: str | os.PathLike[str],
    positions: TimedPositions,
    extra_columns: Mapping[str, np.ndarray] | None = None,
) -> Path:
    """Write ``timestamp,x,y,z[,extras]`` atomically; floats round-trip exactly.

    ``extra_columns`` defaults to ``positions.extra``; each must have one value per row.
    """
    extras = dict(positions.extra if extra_columns is None else extra_columns)
    n = len(positions)
    for name, values in extras.items():
        if np.asarray(values).reshape(-1).shape[0] != n:
            raise InputError(
                f"extra column {name!r} has {np.asarray(values).size} values for {n} rows"
            )
        if name.lower() in ("timestamp", "x", "y", "z"):
            raise InputError(f"extra column name {name!r} clashes with timestamp,x,y,z")
    cols = [_format_column(positions.stamps)] + [
        _format_column(positions.xyz[:, i]) for i in range(3)
    ]
    cols += [_format_column(np.asarray(v).reshape(-1)) for v in extras.values()]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["timestamp", "x", "y", "z", *extras.keys()])
    writer.writerows(zip(*cols, strict=True))
    return atomic_write_text(path, buf.getvalue())
