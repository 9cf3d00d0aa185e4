"""MMAUD / UG2+ challenge sequence folders.

Layout (other sub-folders such as ``Image/`` or ``radar_enhance_pcl/`` are ignored)::

    seqN/lidar_360/<stamp>.npy     (N, 3) float64 xyz, zero-padded  -> sensor "mid360"
    seqN/livox_avia/<stamp>.npy    (N, 3) float64 xyz, zero-padded  -> sensor "avia"
    seqN/ground_truth/<stamp>.npy  (3,)   float64 xyz (training sequences only)

A file name is the time in seconds (``1706255621.600227``; some names lost trailing
zeros, ``1706255621.6``). All-zero rows are padding; rows with NaN/Inf are dropped too.
"""

from __future__ import annotations

import heapq
import os
import re
from collections.abc import Callable, Iterable, Iterator, Mapping
from collections.abc import Sequence as SequenceABC
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

from clusterfilter_ros.core.frame import AVIA, MID360, Frame, Sequence, TimedPositions
from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io.atomic import atomic_output_dir
from clusterfilter_ros.io.pointcloud2 import MAX_ROS1_SEC, finite_rows

#: Challenge sub-folder name -> canonical sensor name.
SENSOR_FOLDERS: dict[str, str] = {"lidar_360": MID360, "livox_avia": AVIA}
#: Canonical sensor name -> challenge sub-folder name.
FOLDER_OF_SENSOR: dict[str, str] = {v: k for k, v in SENSOR_FOLDERS.items()}
GROUND_TRUTH_FOLDER = "ground_truth"
#: Rows per file in the real data (Mid360 files alternate between the two sizes).
REAL_PAD_ROWS: dict[str, list[int]] = {MID360: [19968, 20064], AVIA: [24000]}

_STAMP_RE = re.compile(r"^\d+(\.\d*)?$")
#: First bytes of every .npy file.
_NPY_MAGIC = b"\x93NUMPY"


@dataclass(frozen=True)
class StampedFile:
    """One ``<stamp>.npy`` file of a sequence folder."""

    stamp: float
    sensor: str
    path: Path


#: Largest stamp (s) a ROS header can hold (ROS 1 ``time.secs`` is a uint32).
MAX_STAMP_SECONDS = MAX_ROS1_SEC


def parse_stamp(path: Path) -> float:
    """Seconds from a challenge file name (``1706255621.6.npy`` -> 1706255621.6).

    A time beyond :data:`MAX_STAMP_SECONDS` (a name in milli- or nanoseconds, say) is an
    :class:`InputError`.
    """
    stem = path.name[: -len(".npy")] if path.name.endswith(".npy") else path.stem
    if not _STAMP_RE.match(stem):
        raise InputError(
            f"{path}: file name is not a timestamp in seconds (like 1706255621.600227.npy)"
        )
    stamp = float(stem)
    if not stamp <= MAX_STAMP_SECONDS:  # also catches inf from hundreds of digits
        raise InputError(
            f"{path}: file name is not a time in seconds up to {MAX_STAMP_SECONDS} "
            "(names must be seconds like 1706255599.999223.npy, not milli- or nanoseconds)"
        )
    return stamp


def format_stamp(stamp: float) -> str:
    """File-name form of a stamp, six decimals like the real data (``1706255621.600227``)."""
    if not np.isfinite(stamp) or stamp < 0:
        raise InputError(f"cannot name a file after stamp {stamp!r} (need a finite time >= 0)")
    return f"{stamp:.6f}"


def _natural_key(name: str) -> list[object]:
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def access_error(path: str | os.PathLike[str], exc: OSError) -> InputError:
    """A one-line :class:`InputError` for a path the OS refused to inspect or list
    (permission denied, symlink loop, I/O error), naming the path and the OS reason."""
    culprit = exc.filename if exc.filename is not None else path
    return InputError(f"{os.fsdecode(culprit)}: cannot access ({exc.strerror or exc})")


def is_sequence_folder(path: str | os.PathLike[str]) -> bool:
    """True if ``path`` is a folder with a ``lidar_360`` or ``livox_avia`` sub-folder.

    Raises :class:`InputError` if the OS refuses to look (unreadable folder, symlink loop).
    """
    p = Path(path)
    try:
        return p.is_dir() and any((p / name).is_dir() for name in SENSOR_FOLDERS)
    except OSError as exc:
        raise access_error(p, exc) from exc


def list_sequence_folders(root: str | os.PathLike[str]) -> list[Path]:
    """Sequence folders under ``root``: ``[root]`` if it is one, else its sequence children.

    Children are sorted naturally (``seq2`` before ``seq10``). Raises :class:`InputError`
    if ``root`` is missing or holds no sequence folder.
    """
    p = Path(root)
    if not p.exists():
        raise InputError(f"{p}: no such folder")
    if not p.is_dir():
        raise InputError(f"{p}: not a folder (expected a challenge sequence folder)")
    if is_sequence_folder(p):
        return [p]
    try:
        children = [c for c in p.iterdir() if is_sequence_folder(c)]
    except OSError as exc:
        raise access_error(p, exc) from exc
    if not children:
        raise InputError(
            f"{p}: not a challenge sequence folder (no lidar_360/ or livox_avia/ inside) "
            "and no sequence folders below it"
        )
    return sorted(children, key=lambda c: _natural_key(c.name))


def _check_sensors(sensors: Iterable[str] | None) -> set[str]:
    if sensors is None:
        return set(FOLDER_OF_SENSOR)
    wanted = {sensors} if isinstance(sensors, str) else set(sensors)
    unknown = wanted - set(FOLDER_OF_SENSOR)
    if unknown:
        raise InputError(
            f"unknown sensor(s) {', '.join(sorted(unknown))}; "
            f"challenge folders hold {', '.join(sorted(FOLDER_OF_SENSOR))}"
        )
    return wanted


def _require_sequence_folder(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: no such folder")
    if not p.is_dir():
        raise InputError(f"{p}: not a folder (expected a challenge sequence folder)")
    if not is_sequence_folder(p):
        raise InputError(
            f"{p}: no lidar_360/ or livox_avia/ folder inside (not a challenge sequence)"
        )
    for name in (*SENSOR_FOLDERS, GROUND_TRUTH_FOLDER):
        # A file where a folder belongs would otherwise be skipped without a word.
        entry = p / name
        if entry.exists() and not entry.is_dir():
            raise InputError(f"{entry}: not a folder (it should hold <stamp>.npy files)")
    return p


def _npy_files(folder: Path) -> list[Path]:
    try:
        entries = list(os.scandir(folder))
    except OSError as exc:
        raise InputError(f"{folder}: cannot list folder: {exc.strerror or exc}") from exc
    files = []
    for e in entries:
        try:
            if not e.name.endswith(".npy"):
                continue
            if e.is_file():
                files.append(Path(e.path))
            elif e.is_symlink() and not os.path.exists(e.path):
                # A frame whose file is gone would otherwise be skipped without a word.
                raise InputError(f"{e.path}: broken symbolic link (its file is missing)")
        except OSError as exc:  # a symlink loop, ...
            raise access_error(e.path, exc) from exc
    return files


def list_lidar_files(
    path: str | os.PathLike[str], sensors: Iterable[str] | None = None
) -> list[StampedFile]:
    """The lidar files of a sequence folder, ordered by stamp then sensor name."""
    p = _require_sequence_folder(path)
    wanted = _check_sensors(sensors)
    files: list[StampedFile] = []
    for folder_name, sensor in SENSOR_FOLDERS.items():
        folder = p / folder_name
        if sensor not in wanted or not folder.is_dir():
            continue
        files.extend(StampedFile(parse_stamp(f), sensor, f) for f in _npy_files(folder))
    files.sort(key=lambda f: (f.stamp, f.sensor))
    return files


def load_npy(path: Path) -> np.ndarray:
    """Read one ``.npy`` array (no pickles) with every failure turned into a one-line
    :class:`InputError`; the file is opened once."""
    try:
        with open(path, "rb") as fh:
            magic = fh.read(len(_NPY_MAGIC))
            if magic != _NPY_MAGIC:
                what = "empty file" if not magic else "no .npy header"
                raise InputError(f"{path}: not a .npy file ({what}; corrupt or wrongly named?)")
            fh.seek(0)
            _check_npy_size(fh, path)
            fh.seek(0)
            arr = np.lib.format.read_array(fh, allow_pickle=False)
    except MemoryError as exc:  # last resort: a header that _check_npy_size let through
        raise InputError(f"{path}: array too large to load into memory") from exc
    except (OSError, ValueError, EOFError) as exc:
        if isinstance(exc, OSError) and exc.strerror:
            raise InputError(f"{path}: cannot read ({exc.strerror})") from exc
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f"{path}: not a readable .npy file ({msg})") from exc
    if not isinstance(arr, np.ndarray):
        raise InputError(f"{path}: expected one array, found {type(arr).__name__}")
    return arr


def _check_npy_size(fh: BinaryIO, path: Path) -> None:
    """Refuse a .npy file shorter than the array its header describes (``fh`` at the
    file's start; left anywhere).

    A corrupt header claiming a huge shape would otherwise make the reader try to
    allocate it (``MemoryError``) before noticing the file is too short. Headers this
    function cannot parse are left for the reader to report.
    """
    readers = {
        (1, 0): np.lib.format.read_array_header_1_0,
        (2, 0): np.lib.format.read_array_header_2_0,
    }
    try:
        version = np.lib.format.read_magic(fh)
        if version not in readers:
            return
        shape, _, dtype = readers[version](fh)
        data_bytes = os.fstat(fh.fileno()).st_size - fh.tell()
    except (OSError, ValueError, EOFError, SyntaxError, TypeError):
        return  # the reader reports these with its own message
    if dtype.hasobject:
        return  # the reader refuses pickled arrays
    count = 1
    for n in shape:
        count *= int(n)
    claimed = count * dtype.itemsize
    if data_bytes < claimed:
        raise InputError(
            f"{path}: truncated or corrupt .npy file (its header claims shape "
            f"{tuple(int(n) for n in shape)} of {dtype}, {claimed} bytes, but the file holds "
            f"{data_bytes} bytes of data)"
        )


def valid_rows(xyz: np.ndarray) -> np.ndarray:
    """Boolean mask of rows that are real points: not all-zero padding and all finite.

    Column-wise tests (finite; ``|x| + |y| + |z| != 0``) are several times faster than
    ``isfinite(...).all(1) & (... != 0).any(1)`` on (N, 3) arrays.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        a = np.abs(xyz)
        total = a[:, 0] + a[:, 1]
        total += a[:, 2]  # may overflow to inf for huge finite values: still != 0
    return finite_rows(xyz) & (total != 0)


def load_lidar_file(path: Path, sensor: str, stamp: float | None = None) -> Frame:
    """One challenge lidar file as a :class:`Frame` (padding and non-finite rows dropped).

    Coordinates are converted to float32 first; values beyond float32's range become
    non-finite and are dropped with the NaN/Inf rows.
    """
    arr = load_npy(path)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f"{path}: expected an (N, 3) array of xyz, found shape {arr.shape}")
    if arr.dtype.kind not in "fiu":
        raise InputError(f"{path}: expected numbers, found dtype {arr.dtype}")
    with np.errstate(over="ignore", invalid="ignore"):
        xyz = arr.astype(np.float32)
        keep = valid_rows(xyz)
    if not keep.all():
        xyz = xyz[keep]
    return Frame(stamp=parse_stamp(path) if stamp is None else stamp, sensor=sensor, xyz=xyz)


def iter_frames_folder(
    path: str | os.PathLike[str], sensors: Iterable[str] | None = None
) -> Iterator[Frame]:
    """Frames of a sequence folder in time order (stamp, then sensor name), loaded lazily."""
    for f in list_lidar_files(path, sensors):
        yield load_lidar_file(f.path, f.sensor, f.stamp)


def read_ground_truth_folder(folder: str | os.PathLike[str]) -> TimedPositions:
    """Positions from a challenge ``ground_truth/`` folder of ``<stamp>.npy`` (3,) files."""
    p = Path(folder)
    if not p.is_dir():
        raise InputError(f"{p}: no such ground-truth folder")
    files = _npy_files(p)
    stamps = np.array([parse_stamp(f) for f in files], dtype=np.float64)
    xyz = np.empty((len(files), 3), dtype=np.float64)
    for i, f in enumerate(files):
        arr = load_npy(f)
        if arr.size != 3 or arr.dtype.kind not in "fiu":
            raise InputError(
                f"{f}: expected 3 numbers (x, y, z), found shape {arr.shape} {arr.dtype}"
            )
        xyz[i] = arr.reshape(3)
    finite = np.isfinite(xyz).all(axis=1)
    return TimedPositions(stamps[finite], xyz[finite])


def read_sequence_folder(
    path: str | os.PathLike[str], sensors: Iterable[str] | None = None
) -> Sequence:
    """A whole sequence folder: lidar frames in time order plus ground truth if present."""
    p = _require_sequence_folder(path)
    frames = list(iter_frames_folder(p, sensors))
    return Sequence(name=p.name, frames=frames, ground_truth=sequence_ground_truth(p))


def sequence_ground_truth(path: str | os.PathLike[str]) -> TimedPositions | None:
    """The ground truth of a sequence folder (its ``ground_truth/``), None without one."""
    gt_dir = _require_sequence_folder(path) / GROUND_TRUTH_FOLDER
    return read_ground_truth_folder(gt_dir) if gt_dir.is_dir() else None


def _pad_sizes(pad: int | SequenceABC[int] | None) -> list[int] | None:
    if pad is None:
        return None
    sizes = [int(pad)] if isinstance(pad, (int, np.integer)) else [int(v) for v in pad]
    if not sizes or min(sizes) < 0:
        raise InputError(
            f"pad_rows must be a row count >= 0 or a non-empty list of them, got {pad!r}"
        )
    return sizes


def write_sequence_folder(
    seq: Sequence,
    out_dir: str | os.PathLike[str],
    pad_rows: Mapping[str, int | SequenceABC[int]] | None = None,
    overwrite: bool = False,
) -> Path:
    """Write ``seq`` as a challenge sequence folder ``out_dir`` and return its path.

    Each frame becomes ``<folder>/<stamp with 6 decimals>.npy``, an (N, 3) float64 array
    zero-padded to ``pad_rows[sensor]`` rows (an int, or a list used cyclically frame by
    frame, e.g. ``{"mid360": [19968, 20064], "avia": 24000}``; a frame with more points
    than its pad size is written unpadded). Ground truth goes to ``ground_truth/``.
    Intensity and per-point time are not part of the format and are not written. The
    folder is built under a temporary name and renamed into place when complete.
    """
    return write_frames_folder(seq.frames, out_dir, seq.ground_truth, pad_rows, overwrite)


def write_frames_folder(
    frames: Iterable[Frame],
    out_dir: str | os.PathLike[str],
    ground_truth: TimedPositions | None = None,
    pad_rows: Mapping[str, int | SequenceABC[int]] | None = None,
    overwrite: bool = False,
    progress: Callable[[int], object] | None = None,
) -> Path:
    """Like :func:`write_sequence_folder` for a stream of frames (constant memory).

    ``progress`` is called with 1 after each frame is written.
    """
    target = Path(out_dir)
    pads = {s: _pad_sizes(v) for s, v in (pad_rows or {}).items()}
    with atomic_output_dir(target, overwrite=overwrite) as tmp:
        counters: dict[str, int] = {}
        for frame in frames:
            if frame.sensor not in FOLDER_OF_SENSOR:
                raise InputError(
                    f"challenge folders only hold {', '.join(sorted(FOLDER_OF_SENSOR))} frames, "
                    f"not {frame.sensor!r}"
                )
            folder = tmp / FOLDER_OF_SENSOR[frame.sensor]
            if frame.sensor not in counters:
                folder.mkdir()
                counters[frame.sensor] = 0
            index = counters[frame.sensor]
            counters[frame.sensor] += 1
            sizes = pads.get(frame.sensor)
            n = len(frame)
            rows = max(n, sizes[index % len(sizes)]) if sizes else n
            data = np.zeros((rows, 3), dtype=np.float64)
            data[:n] = frame.xyz
            file = folder / f"{format_stamp(frame.stamp)}.npy"
            if file.exists():
                raise InputError(
                    f"two {frame.sensor} frames share stamp {format_stamp(frame.stamp)}"
                )
            np.save(file, data)
            if progress is not None:
                progress(1)
        if not counters:
            raise InputError(f"no lidar frames to write to {target}")
        if ground_truth is not None and len(ground_truth):
            gt_dir = tmp / GROUND_TRUTH_FOLDER
            gt_dir.mkdir()
            for stamp, xyz in zip(ground_truth.stamps, ground_truth.xyz, strict=True):
                np.save(
                    gt_dir / f"{format_stamp(float(stamp))}.npy", np.asarray(xyz, dtype=np.float64)
                )
    return target


def merge_time_ordered(*iterators: Iterable[Frame]) -> Iterator[Frame]:
    """Merge frame streams that are each time-ordered into one (stamp, then sensor)."""
    return heapq.merge(*iterators, key=lambda f: (f.stamp, f.sensor))
