"""``clusterfilter detect``: drone positions from a recording, offline or streaming."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from clusterfilter_ros.cli._detector_args import add_detector_options, detector_params_from_args
from clusterfilter_ros.cli._input_args import add_input_options, input_kwargs_from_args

#: The detector does not tell drone models apart; the UG2+ Classification column says so.
UG2_CLASSIFICATION = "unknown"


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "detect",
        help="detect the drone in a recording and write its positions (CSV or UG2+ format)",
        description="Run the cluster-filter detector on a challenge sequence folder or a bag. "
        "--mode offline is the paper's whole-sequence method; --mode stream pushes frames "
        "one at a time exactly like the ROS node (with --param report_lag=L, its "
        "/uav/pose_delayed output: every frame estimated again L seconds later). Writes "
        "timestamp,x,y,z,confidence,points rows only where a drone is believed present.",
    )
    p.add_argument("input", metavar="INPUT", help="sequence folder, .bag file or ROS 2 bag")
    p.add_argument("--mode", choices=("stream", "offline"), default="offline")
    p.add_argument("-o", "--output", required=True, metavar="OUT.csv", help="output file")
    p.add_argument(
        "--timestamps",
        metavar="FILE",
        help="estimate at these times instead of every frame stamp: a text/CSV file with "
        "one stamp per row (column 'timestamp', optionally 'sequence' for --format ug2) "
        "or a ground_truth folder",
    )
    p.add_argument(
        "--format",
        choices=("csv", "ug2"),
        default="csv",
        help="csv: timestamp,x,y,z,confidence,points for one recording; ug2: the "
        "challenge's Sequence,Timestamp,Position,Classification for one or a folder of "
        "sequences",
    )
    p.add_argument(
        "--max-gap",
        type=float,
        default=0.3,
        help="stream mode with --timestamps: interpolate estimates no more than this "
        "many seconds away (default 0.3)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_input_options(p, ground_truth=False)
    add_detector_options(p)
    p.set_defaults(func=run)


def read_timestamps(path: str) -> dict:
    """Stamps from a file: {sequence name or None: (M,) float64 array}."""
    import numpy as np

    from clusterfilter_ros.errors import InputError
    from clusterfilter_ros.io.groundtruth import csv_rows

    p = Path(path)
    if p.is_dir():
        from clusterfilter_ros.io.groundtruth import read_ground_truth

        return {None: read_ground_truth(p).stamps}
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{p}: no such timestamps file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{p}: cannot read timestamps ({exc})") from None
    rows = csv_rows(text, p)
    if not rows:
        raise InputError(f"{p}: no timestamps in file")
    header = [c.strip().lower() for c in rows[0]]
    try:
        float(header[0])
        has_header = False
    except ValueError:
        has_header = True
    body = rows[1:] if has_header else rows
    t_col, s_col = 0, None
    if has_header:
        names = [h for h in ("timestamp", "stamp", "time", "t") if h in header]
        if not names:
            raise InputError(f"{p}: header has no 'timestamp' column: {rows[0]}")
        t_col = header.index(names[0])
        s_col = header.index("sequence") if "sequence" in header else None
    out: dict[str | None, list[float]] = {}
    for i, row in enumerate(body, start=2 if has_header else 1):
        try:
            stamp = float(row[t_col])
        except (ValueError, IndexError):
            raise InputError(f"{p}: line {i}: not a timestamp: {row}") from None
        if not np.isfinite(stamp):
            raise InputError(f"{p}: line {i}: timestamp {row[t_col]!r} is not a finite number")
        key = row[s_col].strip() if s_col is not None and s_col < len(row) else None
        out.setdefault(key, []).append(stamp)
    return {k: np.asarray(v, dtype=np.float64) for k, v in out.items()}


def detect_one(
    input_path: Path,
    mode: str,
    params,
    stamps,
    max_gap: float,
    progress: bool,
    select: dict | None = None,
):
    """Estimates (TimedPositions with confidence/points) for one recording.

    ``select``: ``topics`` / ``sensors`` for :func:`iter_input_frames`.
    """
    import numpy as np

    from clusterfilter_ros.core.evaluation import interpolate_predictions
    from clusterfilter_ros.core.frame import TimedPositions
    from clusterfilter_ros.io.dataset import iter_input_frames, require_frames

    frames = require_frames(iter_input_frames(input_path, **(select or {})), input_path)
    order = _OrderCount(frames)
    frames = iter(order)
    if progress:
        from tqdm import tqdm

        frames = tqdm(frames, desc=f"{mode} {input_path.name}", unit="frame", file=sys.stderr)
    if mode == "offline":
        from clusterfilter_ros.core.offline import detect_offline

        return detect_offline(frames, params, timestamps=stamps).estimates
    from clusterfilter_ros.core.streaming import run_streaming

    est = run_streaming(frames, params)
    if order.late:
        print(
            f"clusterfilter detect: warning: {input_path}: {order.late} frame(s) came more than "
            f"{_LATE_SECONDS:g} s behind the newest stamp; the stream mode takes frames in the "
            "order they are stored (the offline mode does not depend on it)",
            file=sys.stderr,
        )
    result = TimedPositions(
        np.array([e.stamp for e in est], dtype=np.float64),
        np.array([e.position for e in est], dtype=np.float64).reshape(-1, 3),
        {
            "confidence": np.array([e.confidence for e in est], dtype=np.float64),
            "points": np.array([e.n_points for e in est], dtype=np.int64),
        },
    )
    if stamps is None:
        return result
    # Several frames may share a stamp (two lidars): keep the last estimate per stamp.
    _, last = np.unique(result.stamps[::-1], return_index=True)
    keep = len(result) - 1 - last
    uniq = TimedPositions(
        result.stamps[keep], result.xyz[keep], {k: v[keep] for k, v in result.extra.items()}
    )
    xyz = interpolate_predictions(uniq, stamps, max_gap)
    ok = np.isfinite(xyz).all(axis=1)
    conf = np.interp(stamps, uniq.stamps, uniq.extra["confidence"]) if len(uniq) else stamps * 0
    pts = np.interp(stamps, uniq.stamps, uniq.extra["points"]) if len(uniq) else stamps * 0
    return TimedPositions(
        stamps[ok],
        xyz[ok],
        {"confidence": conf[ok], "points": np.rint(pts[ok]).astype(np.int64)},
    )


def run(args: argparse.Namespace) -> int:
    from clusterfilter_ros.errors import InputError
    from clusterfilter_ros.io.atomic import atomic_write_text
    from clusterfilter_ros.io.dataset import list_inputs
    from clusterfilter_ros.io.groundtruth import write_positions_csv

    if not math.isfinite(args.max_gap) or args.max_gap <= 0:
        raise InputError(f"--max-gap must be a positive number, got {args.max_gap}")
    params = detector_params_from_args(args)
    if args.mode == "stream" and params.clustering == "dbscan":
        raise InputError(
            "clustering=dbscan is offline only; use --mode offline or clustering=voxel"
        )
    inputs = list_inputs(args.input)
    select = input_kwargs_from_args(args)
    stamps_by_seq = read_timestamps(args.timestamps) if args.timestamps else None
    progress = not args.quiet
    if args.format == "csv":
        if len(inputs) != 1:
            raise InputError(
                f"{args.input} holds {len(inputs)} sequences; --format csv takes one "
                "(pass one of them, or use --format ug2)"
            )
        stamps = _stamps_for(stamps_by_seq, inputs[0])
        est = detect_one(inputs[0], args.mode, params, stamps, args.max_gap, progress, select)
        write_positions_csv(args.output, est)
        print(f"{len(est)} estimates -> {args.output}", file=sys.stderr)
        return 0
    import csv
    import io

    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["Sequence", "Timestamp", "Position", "Classification"])
    total = 0
    for path in inputs:
        try:
            stamps = _stamps_for(stamps_by_seq, path)
        except InputError as exc:  # a sequence the timestamps file does not ask for
            print(f"clusterfilter detect: warning: {exc}; skipped", file=sys.stderr)
            continue
        est = detect_one(path, args.mode, params, stamps, args.max_gap, progress, select)
        name = _printable(_sequence_name(path))
        for t, p in zip(est.stamps, est.xyz, strict=True):
            x, y, z = (float(v) for v in p)
            writer.writerow([name, repr(float(t)), f"[{x!r}, {y!r}, {z!r}]", UG2_CLASSIFICATION])
        total += len(est)
    atomic_write_text(args.output, buffer.getvalue())
    print(f"{total} estimates from {len(inputs)} sequence(s) -> {args.output}", file=sys.stderr)
    return 0


#: A frame this many seconds older than the newest one read before it is counted late.
_LATE_SECONDS = 1.0


class _OrderCount:
    """Pass frames through, counting those more than :data:`_LATE_SECONDS` older than
    the newest stamp before them (a bag recorded with a lagging clock, say)."""

    def __init__(self, frames) -> None:
        self.frames = frames
        self.late = 0

    def __iter__(self):
        newest = -math.inf
        for frame in self.frames:
            if frame.stamp < newest - _LATE_SECONDS:
                self.late += 1
            newest = max(newest, frame.stamp)
            yield frame


def _sequence_name(path: Path) -> str:
    name = path.name
    for suffix in (".bag", ".db3", ".mcap"):
        name = name.removesuffix(suffix)
    return name


def _printable(name: str) -> str:
    """``name`` as UTF-8 text: bytes of a file name that are not UTF-8 (kept by Python
    as surrogates) become ``\\xNN`` escapes."""
    return name.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


def _stamps_for(stamps_by_seq, path: Path):
    """The requested stamps for one recording (None: every frame stamp); InputError if a
    timestamps file with a sequence column has no rows for it."""
    if stamps_by_seq is None:
        return None
    name = _sequence_name(path)
    if name in stamps_by_seq:
        return stamps_by_seq[name]
    if None in stamps_by_seq:
        return stamps_by_seq[None]
    if len(stamps_by_seq) == 1:
        return next(iter(stamps_by_seq.values()))
    from clusterfilter_ros.errors import InputError

    named = ", ".join(sorted(_printable(str(k)) for k in stamps_by_seq))
    raise InputError(
        f"--timestamps names no sequence {_printable(name)!r} (it names {named}); "
        "its sequence column must hold the sequence folder or bag names"
    )
