"""Write files and folders so readers never see a half-written result.

Everything is first written to a temporary sibling (same directory, hence same file
system) and then moved into place with :func:`os.replace` / :func:`os.rename`, which is
atomic on POSIX. If writing fails, the temporary is removed and any previous file at the
destination is left untouched. A temporary left by a killed writer (SIGKILL cannot be
caught) is removed by the next successful write of the same output once it is an hour
old.
"""

from __future__ import annotations

import contextlib
import glob
import os
import shutil
import sqlite3
import stat
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

from clusterfilter_ros.errors import InputError


def _ensure_parent(path: Path) -> None:
    for ancestor in reversed(path.parents):
        if ancestor.exists() and not ancestor.is_dir():
            raise InputError(f"cannot write {path}: {ancestor} is a file, not a folder")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create folder {path.parent}: {exc.strerror or exc}") from exc


def _reason(exc: OSError | sqlite3.Error) -> str:
    """The OS (or sqlite: "disk I/O error", from rosbags' bag writer) reason, one line."""
    text = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
    return text.splitlines()[0] if text else type(exc).__name__


def _output_error(target: Path, exc: OSError) -> InputError:
    """A one-line error naming the output that could not be written."""
    with contextlib.suppress(OSError):
        if target.is_dir():
            return InputError(f"cannot write {target}: it is a folder")
    return InputError(f"cannot write {target}: {_reason(exc)}")


def _read_umask() -> int:
    """The process umask (read once at import: os.umask briefly changes it for all threads)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _read_umask()


#: A temporary sibling older than this (s) was left by a writer that was killed.
STALE_SECONDS = 3600.0


def remove_stale_temporaries(target: Path, max_age: float = STALE_SECONDS) -> int:
    """Delete temporary files ``.<name>.*.tmp*`` next to ``target`` older than ``max_age``
    seconds (left behind when a writer was killed with SIGKILL); returns how many.

    Younger ones may belong to a writer still running and are left alone; failures to
    delete are ignored."""
    now = time.time()
    removed = 0
    try:
        candidates = list(target.parent.glob(f".{glob.escape(target.name)}.*.tmp*"))
    except OSError:
        return 0
    for tmp in candidates:
        with contextlib.suppress(OSError):
            if tmp.is_file() and now - tmp.stat().st_mtime > max_age:
                tmp.unlink()
                removed += 1
    return removed


def _is_special_file(path: Path) -> bool:
    """True if ``path`` exists and is neither a regular file nor a folder (a character
    device such as ``/dev/null``, a FIFO, a socket)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


@contextlib.contextmanager
def atomic_output_path(path: str | os.PathLike[str], suffix: str = "") -> Iterator[Path]:
    """Yield a temporary file path next to ``path``; on success move it onto ``path``.

    The caller writes the complete file to the yielded path (by any means: ``np.save``,
    ``open``, a library writer). When the ``with`` block exits normally the file replaces
    ``path`` atomically; on an exception it is deleted and ``path`` is unchanged. An
    :class:`OSError` while writing or moving (disk full, the target is a folder) becomes
    an :class:`InputError` naming ``path``.
    ``suffix`` is appended to the temporary name (some writers insist on an extension).

    A symbolic link is kept: the file it points to is replaced. An existing target that
    is not a regular file (``/dev/null``, a FIFO) is not replaced either: the finished
    temporary (made in the system's temporary folder) is copied into it, non-atomically.
    """
    target = Path(path)
    if target.is_symlink():
        target = Path(os.path.realpath(target))
    special = _is_special_file(target)
    if not special:
        _ensure_parent(target)
        if target.is_dir():
            raise InputError(f"cannot write {target}: it is a folder")
    try:
        fd, tmp_name = tempfile.mkstemp(
            prefix=f".{target.name}.",
            suffix=f".tmp{suffix}",
            dir=None if special else target.parent,
        )
        # mkstemp makes the file private (0600); give the result the usual permissions.
        os.fchmod(fd, 0o666 & ~_UMASK)
        os.close(fd)
    except OSError as exc:
        raise _output_error(target, exc) from exc
    tmp = Path(tmp_name)
    try:
        try:
            yield tmp
            if special:
                with open(tmp, "rb") as src, open(target, "wb") as dst:
                    shutil.copyfileobj(src, dst)
                tmp.unlink()
            else:
                os.replace(tmp, target)
                remove_stale_temporaries(target)
        except OSError as exc:  # disk full, quota, target became a folder, ...
            raise _output_error(target, exc) from exc
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def atomic_write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (temporary file + :func:`os.replace`)."""
    target = Path(path)
    with atomic_output_path(target) as tmp:
        tmp.write_text(text, encoding=encoding)
    return target


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file + :func:`os.replace`)."""
    target = Path(path)
    with atomic_output_path(target) as tmp:
        tmp.write_bytes(data)
    return target


@contextlib.contextmanager
def atomic_output_dir(
    path: str | os.PathLike[str], overwrite: bool = False, create: bool = True
) -> Iterator[Path]:
    """Yield a temporary folder path next to ``path``; on success rename it to ``path``.

    With ``create`` the temporary folder exists when yielded; without it only its name is
    reserved (for writers such as rosbags' that refuse an existing folder). An existing
    non-empty ``path`` is an :class:`InputError` unless ``overwrite`` is true, in which
    case it is replaced (moved aside first, deleted after the new folder is in place).
    """
    target = Path(path)
    if target.exists() and not overwrite:
        if not target.is_dir() or any(target.iterdir()):
            raise InputError(f"output {target} already exists (choose another path or remove it)")
    _ensure_parent(target)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
        os.chmod(tmp, 0o777 & ~_UMASK)  # mkdtemp makes it private (0700)
    except OSError as exc:
        raise InputError(f"cannot write {target}: {exc.strerror or exc}") from exc
    if not create:
        tmp.rmdir()
    try:
        try:
            yield tmp
            _move_dir_into_place(tmp, target)
        except (OSError, sqlite3.Error) as exc:  # disk full, quota, I/O error, ...
            raise InputError(f"cannot write {target}: {_reason(exc)}") from exc
    except BaseException:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        elif tmp.exists():
            tmp.unlink(missing_ok=True)
        raise


def _move_dir_into_place(tmp: Path, target: Path) -> None:
    """Rename the finished folder ``tmp`` to ``target``, replacing what is there."""
    if target.exists():
        if target.is_dir() and not any(target.iterdir()):
            target.rmdir()
        else:
            old = Path(
                tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".old", dir=target.parent)
            )
            old.rmdir()
            os.rename(target, old)
            os.rename(tmp, target)
            if old.is_dir():
                shutil.rmtree(old, ignore_errors=True)
            else:
                old.unlink(missing_ok=True)
            return
    os.rename(tmp, target)
