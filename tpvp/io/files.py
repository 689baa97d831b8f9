"""Input files read safely: checked before they are opened, decompressed when gzip-compressed.

Only regular files are read: a directory, FIFO (which would block), device (which would never
end) or socket, a missing file, a broken or looping symlink are refused before anything opens
them, each with one line saying which. A name ending in ``.gz`` is decompressed in memory and
parsed like the plain file; errors still name it.
"""

from __future__ import annotations

import errno
import gzip
import os
import stat
import zlib
from pathlib import Path

from tpvp.errors import InputFileError

def _is_gzip(path: Path) -> bool:
    return path.suffix.lower() == ".gz"


def cloud_extension(path) -> tuple[str, bool]:
    """``(format extension, gzip-compressed)`` of a file name, lower case:
    ``scan.PLY.gz`` -> ``(".ply", True)``, ``scan.xyz`` -> ``(".xyz", False)``. Test
    ``cloud_extension(p)[0] in READ_EXTENSIONS`` (:mod:`tpvp.io.readers`) to know whether
    :func:`~tpvp.io.readers.read_point_cloud` takes it."""
    path = Path(path)
    if _is_gzip(path):
        return Path(path.stem).suffix.lower(), True
    return path.suffix.lower(), False


def _gunzip(path: Path, data: bytes) -> bytes:
    try:
        out = gzip.decompress(data)
    except EOFError:
        raise InputFileError(f"{path}: truncated gzip file (the compressed data ends early; "
                             f"the download or copy is incomplete)") from None
    except (gzip.BadGzipFile, zlib.error, OSError) as exc:
        raise InputFileError(f"{path}: not a valid gzip file ({exc})") from None
    if not out:
        raise InputFileError(f"{path}: empty file (0 bytes after gzip decompression)")
    return out


_FILE_KINDS = (
    (stat.S_ISDIR, "is a directory"),
    (stat.S_ISFIFO, "is a FIFO (named pipe)"),
    (stat.S_ISCHR, "is a character device"),
    (stat.S_ISBLK, "is a block device"),
    (stat.S_ISSOCK, "is a socket"),
)


def _not_a_file(path: Path, mode: int) -> str | None:
    """Why ``mode`` is not a regular file (``"is a FIFO (named pipe), not a file"``), or None."""
    if stat.S_ISREG(mode):
        return None
    what = next((w for test, w in _FILE_KINDS if test(mode)), "is not a regular file")
    why = f"{what}, not a file" if what != "is not a regular file" else what
    if os.path.islink(path):
        try:
            why += f" (it is a symlink to {os.path.realpath(path)})"
        except (OSError, ValueError):
            why += " (it is a symlink)"
    return why


def _stat_problem(path: Path, exc: OSError) -> str:
    """One line saying why ``os.stat(path)`` failed: missing, broken or looping symlink, ..."""
    code = exc.errno
    if code == errno.ELOOP:
        return f"{path}: symlink loop (following its links never reaches a file)"
    if code == errno.ENOENT:
        if os.path.islink(path):
            try:
                target = os.readlink(path)
                final = os.path.realpath(path)
            except (OSError, ValueError):
                return f"{path}: broken symlink (its target does not exist)"
            if os.path.lexists(os.path.join(path.parent, target)):  # a chain of links
                return (f"{path}: broken symlink pointing to {target}, which leads to "
                        f"{final} (which does not exist)")
            return f"{path}: broken symlink pointing to {target} (which does not exist)"
        missing = None  # the outermost missing folder
        for folder in path.parents:
            if os.path.lexists(folder):
                break
            missing = folder
        if missing is not None:
            return f"{path}: file not found (folder {missing} does not exist)"
        return f"{path}: file not found"
    if code == errno.ENOTDIR:
        blocker = next((a for a in reversed(path.parents)
                        if os.path.lexists(a) and not os.path.isdir(a)), None)
        if blocker is not None:
            return f"{path}: file not found ({blocker} is a file, not a folder)"
        return f"{path}: file not found (a part of the path is not a folder)"
    if code in (errno.EACCES, errno.EPERM):
        return f"{path}: permission denied (cannot look into one of its folders)"
    if code == errno.ENAMETOOLONG:
        return f"{path}: file name too long"
    return f"{path}: cannot read: {exc.strerror or exc}"


def check_input_file(path: Path) -> os.stat_result:
    """``os.stat`` of an input file (symlinks followed), checked BEFORE anything opens it: a
    missing path, a broken or looping symlink, a directory, FIFO, device or socket, or an empty
    file raises :class:`InputFileError` with one line saying which."""
    try:
        st = os.stat(path)
    except ValueError:  # an embedded NUL byte
        raise InputFileError(f"{str(path)!r}: the file name contains a NUL byte") from None
    except OSError as exc:
        raise InputFileError(_stat_problem(path, exc)) from None
    why = _not_a_file(path, st.st_mode)
    if why is not None:
        raise InputFileError(f"{path}: {why}")
    if st.st_size == 0:
        raise InputFileError(f"{path}: empty file (0 bytes)")
    return st


def _open_problem(path: Path, exc: OSError) -> str:
    if exc.errno in (errno.EACCES, errno.EPERM):
        return f"{path}: permission denied (cannot read it)"
    if exc.errno == errno.EISDIR:
        return f"{path}: is a directory, not a file"
    return f"{path}: cannot read: {exc.strerror or exc}"


def read_input_bytes(path: Path) -> bytes:
    """The file's bytes, decompressed when its name ends in ``.gz``. Only regular files are
    read: the file is checked before it is opened (a FIFO would block, a device never end), and
    opened without blocking and checked again in case it was swapped in between."""
    check_input_file(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
                     | getattr(os, "O_BINARY", 0))
    except OSError as exc:
        raise InputFileError(_open_problem(path, exc)) from None
    try:
        with os.fdopen(fd, "rb") as f:
            why = _not_a_file(path, os.fstat(f.fileno()).st_mode)
            if why is not None:
                raise InputFileError(f"{path}: {why}")
            data = f.read()
    except OSError as exc:
        if isinstance(exc, InputFileError):
            raise
        raise InputFileError(_open_problem(path, exc)) from None
    if not data:
        raise InputFileError(f"{path}: empty file (0 bytes)")
    if _is_gzip(path):
        data = _gunzip(path, data)
    return data


def check_not_utf16(path, data: bytes) -> None:
    """Refuse UTF-16 text (Windows tools write it): every second byte is NUL."""
    head = data[:64]
    bom = head[:2] in (b"\xff\xfe", b"\xfe\xff")
    if len(head) >= 4 and not bom:
        even, odd = head[0::2], head[1::2]
        pattern = (odd.count(0) == len(odd) and 0 not in even) or \
                  (even.count(0) == len(even) and 0 not in odd)
    else:
        pattern = False
    if bom or pattern:
        raise InputFileError(f"{path}: is UTF-16 encoded text; save it as UTF-8 or ASCII "
                             f"(e.g. iconv -f UTF-16 -t UTF-8)")
