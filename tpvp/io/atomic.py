"""Atomic file writes: write a temporary file beside the destination, then ``os.replace`` it.

A reader (or a crashed run) therefore sees either the old file or the complete new one, never a
half-written file. The temporary file lives in the destination's directory because ``os.replace``
is only atomic within one file system.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from pathlib import Path
from typing import Iterator

from tpvp.errors import InputFileError
from tpvp.io import faults

__all__ = ["atomic_path", "atomic_write_bytes", "atomic_write_text"]


def _make_parent(path: Path) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputFileError(f"cannot create directory {path.parent}: {exc.strerror or exc}") from exc


def _create_temp(path: Path) -> tuple[Path, int]:
    """Create an exclusive temporary file next to ``path``; keep its extension for writers that
    pick the format from the file name (open3d, trimesh)."""
    for _ in range(100):
        tmp = path.with_name(f".{path.stem}.{secrets.token_hex(4)}.tmp{path.suffix}")
        try:
            # 0o666 lets the umask decide the final permissions, like a plain open(path, "w").
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            continue
        except OSError as exc:
            raise InputFileError(f"cannot write {path}: {exc.strerror or exc}") from exc
        return tmp, fd
    raise InputFileError(f"cannot write {path}: no free temporary file name in {path.parent}")


def fsync_path(path: Path) -> None:
    """Flush a file's or a folder's entries to disk (best effort)."""
    with contextlib.suppress(OSError):
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _remove_quietly(tmp: Path) -> None:
    with contextlib.suppress(OSError):
        tmp.unlink()


def _commit(tmp: Path, path: Path) -> None:
    try:
        if path.exists():
            # Keep the permissions of the file being replaced.
            with contextlib.suppress(OSError):
                os.chmod(tmp, path.stat().st_mode & 0o7777)
        os.replace(tmp, path)
    except OSError as exc:
        _remove_quietly(tmp)
        raise InputFileError(f"cannot write {path}: {exc.strerror or exc}") from exc


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on normal exit rename it onto ``path``.

    If the body raises, the temporary file is removed and ``path`` keeps its old content.
    The yielded path already exists (empty) and has the same extension as ``path``.
    """
    path = Path(path)
    _make_parent(path)
    tmp, fd = _create_temp(path)
    os.close(fd)
    try:
        yield tmp
        faults.checkpoint("write")
    except BaseException as exc:
        _remove_quietly(tmp)
        if isinstance(exc, OSError) and not isinstance(exc, InputFileError):
            raise InputFileError(f"cannot write {path}: {exc.strerror or exc}") from exc
        raise
    if not tmp.exists():
        raise InputFileError(f"cannot write {path}: the temporary file {tmp.name} disappeared")
    fsync_path(tmp)  # flush the data before the rename: a power cut cannot leave an empty file
    _commit(tmp, path)


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (parent directories are created). Returns the path."""
    path = Path(path)
    _make_parent(path)
    tmp, fd = _create_temp(path)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        faults.checkpoint("write")
    except BaseException as exc:
        _remove_quietly(tmp)
        if isinstance(exc, OSError):
            raise InputFileError(f"cannot write {path}: {exc.strerror or exc}") from exc
        raise
    _commit(tmp, path)
    return path


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (parent directories are created). Returns the path."""
    return atomic_write_bytes(path, text.encode(encoding))
