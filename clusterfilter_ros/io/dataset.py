"""One entry point for every input and output format.

``detect``, ``evaluate``, ``replay``, ``simulate`` and ``convert`` call these instead of
the format modules, so a user can pass a challenge sequence folder, a ROS 1 ``.bag`` or a
ROS 2 bag (sqlite3 or mcap) anywhere.

Input kinds (:func:`detect_input_kind`):

- ``"mmaud"``: a challenge sequence folder (has ``lidar_360/`` or ``livox_avia/``),
- ``"mmaud-root"``: a folder of such sequence folders (``seq1``, ``seq2``, ...),
- ``"rosbag1"``: a ROS 1 ``.bag`` file,
- ``"rosbag2"``: a ROS 2 bag folder (``metadata.yaml`` + ``.db3``/``.mcap``) or a bare
  ``.db3``/``.mcap`` file.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from clusterfilter_ros.core.frame import Frame, Sequence, TimedPositions
from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io import challenge

INPUT_KINDS = ("mmaud", "mmaud-root", "rosbag1", "rosbag2")
OUTPUT_FORMATS = ("mmaud", "rosbag2", "rosbag1")


def is_bag(path: str | os.PathLike[str]) -> bool:
    """True if ``path`` is a ROS 1 ``.bag``, a bare ``.db3``/``.mcap`` or a ROS 2 bag folder."""
    p = Path(path)
    try:
        if p.is_dir():
            return (p / "metadata.yaml").is_file() or any(p.glob("*.db3")) or any(p.glob("*.mcap"))
        return p.is_file() and p.suffix.lower() in (".bag", ".db3", ".mcap")
    except OSError as exc:  # unreadable folder, symlink loop, ...
        raise challenge.access_error(p, exc) from exc


def detect_input_kind(path: str | os.PathLike[str]) -> str:
    """Which of :data:`INPUT_KINDS` ``path`` is; :class:`InputError` if none."""
    p = Path(path)
    try:
        exists = p.exists()
    except OSError as exc:
        raise challenge.access_error(p, exc) from exc
    if not exists:
        raise InputError(f"{p}: no such file or folder")
    if is_bag(p):
        return "rosbag1" if p.is_file() and p.suffix.lower() == ".bag" else "rosbag2"
    if p.is_file():
        suffix = p.suffix.lower()
        if suffix == ".npy":
            raise InputError(
                f"{p}: a single .npy file; pass its sequence folder (the one holding lidar_360/)"
            )
        raise InputError(f"{p}: unknown input file type (expected .bag, .db3, .mcap or a folder)")
    if challenge.is_sequence_folder(p):
        return "mmaud"
    try:
        challenge.list_sequence_folders(p)
    except InputError:
        raise InputError(
            f"{p}: not a challenge sequence folder (no lidar_360/ or livox_avia/), "
            "not a ROS 2 bag (no metadata.yaml/.db3/.mcap) and no sequence folders inside"
        ) from None
    return "mmaud-root"


def _bag_kwargs(kw: Mapping[str, Any]) -> dict[str, Any]:
    return {
        k: v
        for k, v in kw.items()
        if k in ("topics", "ground_truth_topic", "sensors") and v is not None
    }


def open_input(
    path: str | os.PathLike[str],
    sensors: Iterable[str] | None = None,
    topics: Mapping[str, str] | None = None,
    ground_truth_topic: str | None = None,
    ground_truth: str | os.PathLike[str] | None = None,
) -> Sequence:
    """Read one recording (challenge sequence folder or bag) into memory.

    Args:
        path: sequence folder, ``.bag`` file, or ROS 2 bag folder/file.
        sensors: keep only these sensor names (default: all).
        topics: bags only: lidar topic -> sensor name (default: guessed from topic names).
        ground_truth_topic: bags only: PointStamped/PoseStamped topic with ground truth.
        ground_truth: optional CSV or ``ground_truth/`` folder overriding the input's own.

    A folder of several sequences is an :class:`InputError` naming them; use
    :func:`open_inputs` for that.
    """
    p = Path(path)
    kind = detect_input_kind(p)
    if kind == "mmaud-root":
        seqs = challenge.list_sequence_folders(p)
        names = ", ".join(s.name for s in seqs[:5]) + (", ..." if len(seqs) > 5 else "")
        raise InputError(
            f"{p} holds {len(seqs)} sequences ({names}); pass one of them, e.g. {seqs[0]}"
        )
    if kind == "mmaud":
        if topics or ground_truth_topic:
            raise InputError(f"{p}: --topic options apply to bags, not challenge folders")
        seq = challenge.read_sequence_folder(p, sensors)
    else:
        from clusterfilter_ros.io import bags

        seq = bags.read_bag(
            p,
            **_bag_kwargs(
                dict(topics=topics, ground_truth_topic=ground_truth_topic, sensors=sensors)
            ),
        )
    if ground_truth is not None:
        from clusterfilter_ros.io.groundtruth import read_ground_truth

        seq.ground_truth = read_ground_truth(ground_truth)
    return seq


def open_inputs(path: str | os.PathLike[str], **kw: Any) -> list[Sequence]:
    """Like :func:`open_input` but a folder of sequence folders gives all of them."""
    p = Path(path)
    if detect_input_kind(p) == "mmaud-root":
        return [open_input(s, **kw) for s in challenge.list_sequence_folders(p)]
    return [open_input(p, **kw)]


def list_inputs(path: str | os.PathLike[str]) -> list[Path]:
    """The recordings ``path`` stands for: its sequence folders, or ``[path]`` itself."""
    p = Path(path)
    if detect_input_kind(p) == "mmaud-root":
        return challenge.list_sequence_folders(p)
    return [p]


def iter_input_frames(
    path: str | os.PathLike[str],
    sensors: Iterable[str] | None = None,
    topics: Mapping[str, str] | None = None,
) -> Iterator[Frame]:
    """Frames of one recording in time order, read lazily (constant memory)."""
    p = Path(path)
    kind = detect_input_kind(p)
    if kind == "mmaud-root":
        open_input(p)  # raises the "pass one of them" error
    if kind == "mmaud":
        if topics:
            raise InputError(f"{p}: --topic options apply to bags, not challenge folders")
        return challenge.iter_frames_folder(p, sensors)
    from clusterfilter_ros.io import bags

    return bags.iter_bag_frames(p, **_bag_kwargs(dict(topics=topics, sensors=sensors)))


def require_frames(frames: Iterable[Frame], path: str | os.PathLike[str]) -> Iterator[Frame]:
    """Pass ``frames`` through; raise :class:`InputError` naming ``path`` if there were none.

    For commands that cannot do anything useful with a recording without lidar frames
    (an empty ``lidar_360/`` folder, a bag whose lidar topics hold no messages).
    """
    n = 0
    for frame in frames:
        n += 1
        yield frame
    if n == 0:
        raise InputError(
            f"{path}: no lidar frames (empty lidar_360/ and livox_avia/ folders, "
            "or no messages on the lidar topics)"
        )


def write_output(
    seq: Sequence,
    path: str | os.PathLike[str],
    fmt: str = "mmaud",
    overwrite: bool = False,
    **kw: Any,
) -> Path:
    """Write ``seq`` as ``fmt`` (one of :data:`OUTPUT_FORMATS`) to ``path``.

    Extra keywords go to the writer: ``pad_rows`` for ``mmaud``
    (:func:`challenge.write_sequence_folder`); ``storage``, ``topics``,
    ``ground_truth_topic`` for bags (:func:`bags.write_bag`).
    """
    if fmt == "mmaud":
        return challenge.write_sequence_folder(seq, path, overwrite=overwrite, **kw)
    if fmt in ("rosbag2", "rosbag1"):
        from clusterfilter_ros.io import bags

        return bags.write_bag(seq, path, fmt=fmt, overwrite=overwrite, **kw)
    raise InputError(f"unknown output format {fmt!r}; choose one of {', '.join(OUTPUT_FORMATS)}")


def read_input_ground_truth(
    path: str | os.PathLike[str], ground_truth_topic: str | None = None
) -> TimedPositions | None:
    """The ground truth a recording carries (None if it has none), without its frames.

    Challenge folders: ``ground_truth/``. Bags: ``ground_truth_topic`` (must exist if
    given) or the default ``/uav/ground_truth`` (if present).
    """
    p = Path(path)
    kind = detect_input_kind(p)
    if kind == "mmaud-root":
        open_input(p)  # raises the "pass one of them" error
    if kind == "mmaud":
        return challenge.sequence_ground_truth(p)
    from clusterfilter_ros.io import bags

    if ground_truth_topic:
        return bags.read_bag_ground_truth(p, ground_truth_topic)
    try:
        return bags.read_bag_ground_truth(p)
    except InputError as exc:
        if "no ground-truth topic" in str(exc):
            return None
        raise


def count_input_frames(
    path: str | os.PathLike[str],
    sensors: Iterable[str] | None = None,
    topics: Mapping[str, str] | None = None,
) -> int:
    """How many lidar frames :func:`iter_input_frames` will yield (from file lists or bag
    indexes; nothing is decoded)."""
    p = Path(path)
    kind = detect_input_kind(p)
    if kind == "mmaud-root":
        open_input(p)
    if kind == "mmaud":
        return len(challenge.list_lidar_files(p, sensors))
    from clusterfilter_ros.io import bags

    return bags.count_bag_frames(p, topics=topics, sensors=sensors)


def write_output_frames(
    frames: Iterable[Frame],
    path: str | os.PathLike[str],
    fmt: str = "mmaud",
    ground_truth: TimedPositions | None = None,
    overwrite: bool = False,
    progress: Callable[[int], object] | None = None,
    **kw: Any,
) -> Path:
    """Like :func:`write_output` for a time-ordered stream of frames (constant memory)."""
    if fmt == "mmaud":
        return challenge.write_frames_folder(
            frames, path, ground_truth, overwrite=overwrite, progress=progress, **kw
        )
    if fmt in ("rosbag2", "rosbag1"):
        from clusterfilter_ros.io import bags

        return bags.write_bag_frames(
            frames,
            path,
            ground_truth=ground_truth,
            fmt=fmt,
            overwrite=overwrite,
            progress=progress,
            **kw,
        )
    raise InputError(f"unknown output format {fmt!r}; choose one of {', '.join(OUTPUT_FORMATS)}")
