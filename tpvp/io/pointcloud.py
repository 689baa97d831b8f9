"""Point-cloud reading and writing: PLY, PCD, text tables and meshes, to float64 (N, 3) metres.

PLY and PCD are parsed by hand with numpy (a structured dtype built from the header and
``np.frombuffer``) so that every malformed file gets a precise one-line error naming the file,
instead of the silent empty cloud that open3d returns.

Units rule (``units="auto"``, see :func:`detect_units`): a cloud whose largest bounding-box side
exceeds 10 is taken as millimetres (no plant or greenhouse-row scan is 10 m long, while a plant
scanned in millimetres spans tens to hundreds of units); otherwise it is metres, even when its
coordinates reach |c| >= 10 (the reference simulator's mm switch), because a small extent far from
the origin is a metric scan with an offset, not a plant under 1 cm tall. That ambiguous case is
reported with a warning. After conversion a cloud larger than 100 m, or (for an explicit
``units="mm"``) smaller than 1 mm, raises :class:`~tpvp.errors.PointCloudError`. To tell the user
what ``"auto"`` chose, ask ``read_point_cloud(..., return_units=True)`` (or :func:`unit_choice` on a
raw array) for a :class:`UnitChoice`; ``str()`` of it reads ``auto -> mm (largest extent 230 mm)``.

Only regular files are read: a directory, FIFO (which would block), device (which would never
end) or socket, a missing file, a broken or looping symlink are refused before anything opens
them. Declared sizes are checked against the file before anything is allocated, and data beyond
what a header declares (PLY, binary PCD) is refused rather than dropped without a word.

Every format can be read gzip-compressed (``scan.ply.gz``, ``scan.xyz.gz``, ``mesh.obj.gz``, ...):
the file is decompressed in memory and parsed like the plain file, errors still name it.
"""

from __future__ import annotations

import errno
import gzip
import io
import logging
import os
import re
import stat
import warnings
import zlib
from pathlib import Path
from typing import NamedTuple

import numpy as np

from tpvp.errors import ConfigError, InputFileError, PointCloudError
from tpvp.io.atomic import atomic_write_bytes

__all__ = [
    "read_point_cloud",
    "write_point_cloud",
    "read_text_table",
    "detect_units",
    "unit_choice",
    "UnitChoice",
    "to_metres",
    "cloud_extension",
    "READ_EXTENSIONS",
    "GZIP_READ_EXTENSIONS",
    "WRITE_EXTENSIONS",
]

log = logging.getLogger(__name__)

#: Largest bounding-box side (in file units) still taken as metres by ``units="auto"``.
MM_EXTENT_THRESHOLD = 10.0
#: The reference simulator's rule: any |coordinate| >= this means millimetres.
REFERENCE_MM_COORD = 10.0
#: Largest plausible side of a scan in metres (a greenhouse row is a few metres).
MAX_EXTENT_M = 100.0
#: Smallest plausible side in metres when the caller declares millimetres.
MIN_EXTENT_M = 1e-3

UNITS = ("auto", "m", "mm")
#: Column/property names taken as per-point integer labels.
LABEL_NAMES = ("label", "labels", "class", "classification", "scalar_label", "semantic",
               "semantic_label", "category")

TEXT_EXTENSIONS = (".xyz", ".txt", ".pts", ".csv")
MESH_EXTENSIONS = (".obj", ".stl", ".off", ".glb")
READ_EXTENSIONS = (".ply", ".pcd") + TEXT_EXTENSIONS + MESH_EXTENSIONS
#: Every readable format also gzip-compressed (``.ply.gz``, ``.xyz.gz``, ...).
GZIP_READ_EXTENSIONS = tuple(e + ".gz" for e in READ_EXTENSIONS)
WRITE_EXTENSIONS = (".ply", ".pcd") + TEXT_EXTENSIONS


# --------------------------------------------------------------------------------------------
# units


def _as_points(points, name: str = "points") -> np.ndarray:
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name} must be a numeric (N, 3) array: {exc}") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ConfigError(f"{name} must be an (N, 3) array, got shape {pts.shape}")
    return pts


def _who(source) -> str:
    return f"{source}: " if source is not None else ""


def _finite(pts: np.ndarray) -> np.ndarray:
    """The finite rows; the array itself (no copy) when all are finite, as in nearly every scan."""
    if np.isfinite(pts).all():
        return pts
    return pts[np.isfinite(pts).all(axis=1)]


def _extent(pts: np.ndarray) -> np.ndarray:
    """Bounding-box sides of finite points; column by column (contiguous reductions are ~8x faster
    than axis-0 reductions on a large (N, 3) array)."""
    return np.array([pts[:, a].max() - pts[:, a].min() for a in range(3)]) if len(pts) else np.zeros(3)


def _largest_side(pts: np.ndarray) -> float:
    finite = _finite(pts)
    return float(_extent(finite).max()) if len(finite) else 0.0


def detect_units(points, source=None) -> str:
    """Return ``"mm"`` if the largest bounding-box side exceeds 10, else ``"m"`` (see module doc)."""
    pts = _as_points(points)
    finite = _finite(pts)
    if len(finite) == 0:
        raise PointCloudError(f"{_who(source)}cannot detect units of a cloud with no finite points")
    lo = np.array([finite[:, a].min() for a in range(3)])
    hi = np.array([finite[:, a].max() for a in range(3)])
    side = float((hi - lo).max())
    if side > MM_EXTENT_THRESHOLD:
        return "mm"
    reach = float(max(np.abs(lo).max(), np.abs(hi).max()))
    if reach >= REFERENCE_MM_COORD:
        warnings.warn(
            f"{_who(source)}coordinates reach |c| = {reach:.4g} but the cloud spans only {side:.4g}: "
            f"taken as metres (offset from the origin); pass units='mm' if it is a tiny mm scan",
            stacklevel=2,
        )
    return "m"


class UnitChoice(NamedTuple):
    """Which units a cloud was read in: ``str()`` gives ``auto -> mm (largest extent 230 mm)``."""

    requested: str  # "auto", "m" or "mm", as asked
    used: str  # "m" or "mm": what the file's numbers were taken to be
    largest_side: float  # largest bounding-box side in the file's units (``used``)

    @property
    def largest_side_m(self) -> float:
        return self.largest_side * (1e-3 if self.used == "mm" else 1.0)

    def __str__(self) -> str:
        return f"{self.requested} -> {self.used} (largest extent {self.largest_side:.3g} {self.used})"


def unit_choice(points, units: str = "auto", source=None) -> UnitChoice:
    """The :class:`UnitChoice` for raw (file-unit) points: :func:`detect_units` for "auto"."""
    if units not in UNITS:
        raise ConfigError(f"units must be one of {UNITS}, got {units!r}")
    pts = _as_points(points)
    used = detect_units(pts, source) if units == "auto" else units
    return UnitChoice(units, used, _largest_side(pts))


def to_metres(points, units: str = "auto", source=None) -> np.ndarray:
    """Return a new float64 (N, 3) array in metres; ``units`` is "auto", "m" or "mm".

    Raises PointCloudError when the result is implausible for a plant or greenhouse row
    (larger than 100 m, or under 1 mm for an explicit ``units="mm"``); ``source`` (a file name)
    is put in the message.
    """
    if units not in UNITS:
        raise ConfigError(f"units must be one of {UNITS}, got {units!r}")
    pts = _as_points(points)
    used = detect_units(pts, source) if units == "auto" else units
    out = _scaled(pts, units, used, source)
    return out.copy() if out is points else out


def _scaled(pts: np.ndarray, units: str, used: str, source) -> np.ndarray:
    out = pts * 1e-3 if used == "mm" else pts
    side = _largest_side(out)
    if side > MAX_EXTENT_M:
        if units == "auto":
            why = f"even after mm -> m conversion it spans {side:.0f} m (a {side:.0f} m plant?)"
        elif units == "m":
            why = (f"units='m' makes it a {side:.0f} m plant; it looks like millimetres "
                   f"(use units='mm' or 'auto')")
        else:
            why = f"even in millimetres it spans {side:.0f} m (a {side:.0f} m plant?)"
        raise PointCloudError(f"{_who(source)}wrong units? {why}")
    if units == "mm" and 0.0 < side < MIN_EXTENT_M:
        raise PointCloudError(
            f"{_who(source)}wrong units? units='mm' shrinks the cloud to {side * 1e3:.3g} mm across; "
            f"it looks like metres already (use units='m' or 'auto')"
        )
    return out


# --------------------------------------------------------------------------------------------
# shared helpers


def _is_gzip(path: Path) -> bool:
    return path.suffix.lower() == ".gz"


def cloud_extension(path) -> tuple[str, bool]:
    """``(format extension, gzip-compressed)`` of a file name, lower case:
    ``scan.PLY.gz`` -> ``(".ply", True)``, ``scan.xyz`` -> ``(".xyz", False)``. Test
    ``cloud_extension(p)[0] in READ_EXTENSIONS`` to know whether :func:`read_point_cloud` takes it."""
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


def _stat_input(path: Path) -> os.stat_result:
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


def _read_bytes(path: Path) -> bytes:
    """The file's bytes, decompressed when its name ends in ``.gz``. Only regular files are
    read: the file is checked before it is opened (a FIFO would block, a device never end), and
    opened without blocking and checked again in case it was swapped in between."""
    _stat_input(path)
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


def _check_file(path: Path) -> None:
    _stat_input(path)


_BOM_UTF8 = b"\xef\xbb\xbf"


def _check_not_utf16(path, data: bytes) -> None:
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


def _unique(names: list[str]) -> list[str]:
    # Structured dtypes need unique field names; PCL pads with several "_" fields.
    seen: set[str] = set()
    out = []
    for n in names:
        key, i = n, 1
        while key in seen:
            key, i = f"{n}_{i}", i + 1
        seen.add(key)
        out.append(key)
    return out


def _label_index(names: list[str]) -> int | None:
    low = [n.lower() for n in names]
    return next((i for i, n in enumerate(low) if n in LABEL_NAMES), None)


def _int_labels(path, values: np.ndarray, what: str) -> np.ndarray | None:
    values = np.asarray(values)
    if values.dtype.kind in "iu":
        return values.astype(np.int64)
    if np.isfinite(values).all() and np.array_equal(values, np.round(values)):
        return values.astype(np.int64)
    log.info("%s: %s is not integer-valued; not returned as labels", path, what)
    return None


# --------------------------------------------------------------------------------------------
# text tables

_NAME_RE = re.compile(r"^[A-Za-z_][\w.\-]*$")


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _guess_delim(line: str) -> str | None:
    if "," in line:
        return ","
    if ";" in line:
        return ";"
    return None  # any whitespace


def _split(line: str, delim: str | None) -> list[str]:
    return [t.strip() for t in line.split(delim)] if delim else line.split()


def _next_data_line(text: str, pos: int, lineno: int):
    """(stripped line, line number, start, next start) of the next non-blank, non-'#' line."""
    while pos < len(text):
        nl = text.find("\n", pos)
        end = len(text) if nl < 0 else nl
        nxt = len(text) if nl < 0 else nl + 1
        lineno += 1
        line = text[pos:end].split("#", 1)[0].strip()
        if line:
            return line, lineno, pos, nxt
        pos = nxt
    return None


def _locate_text_error(path, body: str, delim, first_lineno: int, exc: Exception) -> str:
    # Error path only: find the offending line so the message can name it.
    expected = None
    for n, raw in enumerate(body.splitlines(), start=first_lineno):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        toks = _split(line, delim)
        for t in toks:
            if not _is_number(t):
                shown = repr(t) if t else "an empty field"
                return f"{path}: line {n}: non-numeric value {shown}"
        if expected is None:
            expected = len(toks)
        elif len(toks) != expected:
            return f"{path}: line {n} has {len(toks)} columns, earlier lines have {expected}"
    return f"{path}: cannot parse as a numeric table ({exc})"


def _decode(path, data: bytes) -> str:
    _check_not_utf16(path, data)
    if b"\x00" in data[:4096]:
        raise InputFileError(f"{path}: contains binary data, expected a text table")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")  # numbers are ASCII; only comments can be affected


def _parse_text_table(path, data: bytes, *, count_header="auto", allow_names=False):
    """Parse a numeric text table. Returns (float64 array (N, C), column names or None)."""
    text = _decode(path, data)
    first = _next_data_line(text, 0, 0)
    if first is None:
        raise InputFileError(f"{path}: no data (the file is blank or only comments)")
    line, ln, start, nxt = first
    names = None
    count = None
    provisional = None  # a single integer before a 1-column table: count only if it matches
    body_start, body_line = start, ln
    is_names = line.startswith("//")  # CloudCompare writes "//X,Y,Z" headers
    toks = _split(line.lstrip("/"), _guess_delim(line))
    if is_names or not all(_is_number(t) for t in toks):
        if allow_names and toks and all(_NAME_RE.match(t) for t in toks):
            names = [t.lower() for t in toks]
            body_start, body_line = nxt, ln + 1
        else:
            bad = next((t for t in toks if not _is_number(t)), line)
            raise InputFileError(f"{path}: line {ln}: non-numeric value {bad!r}")
    elif len(toks) == 1 and re.fullmatch(r"\+?\d+", toks[0]) and count_header is not False:
        second = _next_data_line(text, nxt, ln)
        multi = second is not None and len(_split(second[0], _guess_delim(second[0]))) >= 2
        if count_header is True or multi:
            count = int(toks[0])
            body_start, body_line = nxt, ln + 1
        elif second is not None:
            provisional = int(toks[0])
    elif count_header is True:
        raise InputFileError(f"{path}: line {ln}: expected a row count, found {line[:40]!r}")

    body = text[body_start:]
    nxt_line = _next_data_line(body, 0, 0)
    delim = _guess_delim(nxt_line[0]) if nxt_line else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
        try:
            arr = np.loadtxt(io.StringIO(body), dtype=np.float64, delimiter=delim, comments="#",
                             ndmin=2)
        except ValueError as exc:
            raise InputFileError(_locate_text_error(path, body, delim, body_line, exc)) from None
    if nxt_line is None:
        arr = np.empty((0, len(names) if names else 0))
    if provisional is not None and provisional == len(arr) - 1:
        arr = arr[1:]
    if count is not None and count != len(arr):
        raise InputFileError(f"{path}: line {ln} declares {count} rows, the file holds {len(arr)}")
    if names is not None and arr.shape[1] != len(names) and len(arr):
        raise InputFileError(f"{path}: the header names {len(names)} columns, rows have {arr.shape[1]}")
    return arr, names


def read_text_table(path, columns: int | None = None, count_header="auto", *, names: bool = False):
    """Read a whitespace- or comma-separated numeric table as float64 (N, C).

    ``count_header``: "auto" treats a first line holding one integer as the row count when the
    other rows have 2+ columns (or when it equals the number of rows of a 1-column table);
    True requires it, False never uses it. A declared count must match. ``columns`` requires that
    many columns. A file holding a single number returns shape (1, 1). '#' starts a comment.
    With ``names`` a first line of column names is allowed and ``(table, lower-case names or
    None)`` is returned. A name ending in ``.gz`` is decompressed first.
    """
    if count_header not in ("auto", True, False):
        raise ConfigError(f"count_header must be 'auto', True or False, got {count_header!r}")
    if columns is not None and (not isinstance(columns, (int, np.integer)) or columns < 1):
        raise ConfigError(f"columns must be a positive integer or None, got {columns!r}")
    path = Path(path)
    arr, header = _parse_text_table(path, _read_bytes(path), count_header=count_header, allow_names=names)
    if columns is not None and len(arr) and arr.shape[1] != columns:
        raise InputFileError(f"{path}: has {arr.shape[1]} columns, expected {columns}")
    if columns is not None and not len(arr):
        arr = np.empty((0, columns))
    if not np.isfinite(arr).all():
        row = int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])
        raise InputFileError(f"{path}: data row {row + 1} holds a NaN/inf value")
    return (arr, header) if names else arr


def _read_text_cloud(path: Path, return_labels: bool):
    arr, names = _parse_text_table(path, _read_bytes(path), count_header="auto", allow_names=True)
    if len(arr) == 0:
        raise PointCloudError(f"{path}: holds no points")
    ncol = arr.shape[1]
    if ncol < 3:
        raise InputFileError(f"{path}: {ncol} column(s) per line; a point cloud needs 3 (x y z)")
    xyz = [0, 1, 2]
    label_col = 3 if ncol >= 4 else None
    if names is not None:
        if all(c in names for c in "xyz"):
            xyz = [names.index(c) for c in "xyz"]
        label_col = _label_index(names)
    labels = None
    if label_col is not None:
        labels = _int_labels(path, arr[:, label_col], f"column {label_col + 1}")
        if labels is None:
            label_col = None
    ignored = [i + 1 for i in range(ncol) if i not in xyz and i != label_col]
    used = f"x y z from columns {', '.join(str(i + 1) for i in xyz)}"
    if label_col is not None:
        used += f", labels from column {label_col + 1}"
    if ignored:
        warnings.warn(f"{path}: {ncol} columns per line; read {used}; ignored column(s) "
                      f"{', '.join(map(str, ignored))}", stacklevel=3)
    elif label_col is not None and not return_labels:
        log.info("%s: read %s (labels not requested)", path, used)
    return arr[:, xyz], labels


# --------------------------------------------------------------------------------------------
# binary payload sizes

#: Bytes a writer may leave after binary data (a final newline, NUL padding).
_PADDING = b" \t\r\n\x00"


def _check_trailing(path, tail: bytes, row_size: int, declared: str, worth: str) -> None:
    """Refuse bytes after all declared binary data: the header undercounts (the rest would be
    dropped without a word) or the file is damaged. Less than one row of whitespace or NUL
    padding (a trailing newline) is accepted."""
    if not tail or (len(tail) < max(row_size, 1) and not tail.strip(_PADDING)):
        return
    raise InputFileError(f"{path}: {declared} but the file holds {len(tail):,} more bytes after "
                         f"them ({worth})")


# --------------------------------------------------------------------------------------------
# PLY

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")


class _Prop(NamedTuple):
    name: str
    type: str  # numpy code of the scalar or of the list items
    count_type: str | None  # numpy code of the list length, None for scalars


class _Element(NamedTuple):
    name: str
    count: int
    props: list


def _ply_type(path, word: str, lineno: int) -> str:
    try:
        return _PLY_TYPES[word]
    except KeyError:
        raise InputFileError(
            f"{path}: line {lineno}: unknown PLY property type {word!r} "
            f"(known: {', '.join(sorted(set(_PLY_TYPES)))})") from None


def _parse_ply_header(path, data: bytes):
    """Return (format, elements, payload offset, header line count)."""
    if not data.startswith(b"ply"):
        _check_not_utf16(path, data)
        raise InputFileError(f"{path}: not a PLY file (does not start with 'ply')")
    pos, lineno, fmt, elements = 0, 0, None, []
    while True:
        nl = data.find(b"\n", pos)
        end = len(data) if nl < 0 else nl
        nxt = len(data) if nl < 0 else nl + 1
        lineno += 1
        try:
            line = data[pos:end].decode("ascii").strip()
        except UnicodeDecodeError:
            line = None
        if line == "end_header":
            break
        if line is None or nl < 0:
            raise InputFileError(f"{path}: PLY header has no 'end_header' line (the file ends "
                                 f"inside the header, at line {lineno})" if line is not None else
                                 f"{path}: PLY header has no 'end_header' line")
        words = line.split()
        key = words[0] if words else ""
        bad = False
        if not words:
            pass  # tolerate blank header lines
        elif lineno == 1:
            bad = line != "ply"
        elif key in ("comment", "obj_info"):
            pass
        elif key == "format":
            if len(words) != 3 or words[1] not in _PLY_FORMATS:
                raise InputFileError(f"{path}: line {lineno}: unknown PLY format {line!r} "
                                     f"(known: {', '.join(_PLY_FORMATS)})")
            fmt = words[1]
        elif key == "element":
            if len(words) != 3 or not words[2].isdigit():
                raise InputFileError(f"{path}: line {lineno}: malformed element line {line!r}")
            elements.append(_Element(words[1], int(words[2]), []))
        elif key == "property":
            if not elements:
                raise InputFileError(f"{path}: line {lineno}: property before any element")
            if len(words) == 5 and words[1] == "list":
                prop = _Prop(words[4], _ply_type(path, words[3], lineno),
                             _ply_type(path, words[2], lineno))
                if prop.count_type[0] == "f":
                    raise InputFileError(f"{path}: line {lineno}: list length type must be an integer")
            elif len(words) == 3:
                prop = _Prop(words[2], _ply_type(path, words[1], lineno), None)
            else:
                raise InputFileError(f"{path}: line {lineno}: malformed property line {line!r}")
            elements[-1].props.append(prop)
        else:
            bad = True
        if bad:
            raise InputFileError(
                f"{path}: PLY header line {lineno} is not a header line ({line[:40]!r}); "
                f"is 'end_header' missing?")
        if nl < 0:
            raise InputFileError(f"{path}: PLY header has no 'end_header' line")
        pos = nxt
    if fmt is None:
        raise InputFileError(f"{path}: PLY header has no 'format' line")
    return fmt, elements, nxt, lineno


def _ply_first_row_counts(data: bytes, offset: int, elem: _Element, endian: str):
    """The list lengths of the element's first row (an empty row walk stops at the file's end:
    None), to guess a fixed row layout."""
    counts, off = [], offset
    for p in elem.props:
        if p.count_type is None:
            off += np.dtype(p.type).itemsize
            continue
        cdt = np.dtype(endian + p.count_type)
        if off + cdt.itemsize > len(data):
            return None
        k = int(np.frombuffer(data, cdt, 1, off)[0])
        counts.append(max(k, 0))
        off += cdt.itemsize + max(k, 0) * np.dtype(p.type).itemsize
    return counts


def _ply_row_size(elem: _Element, counts=()) -> int:
    """Bytes of one row whose lists have the lengths ``counts`` (Python integers: no overflow)."""
    size, it = 0, iter(counts)
    for p in elem.props:
        if p.count_type is None:
            size += np.dtype(p.type).itemsize
        else:
            size += np.dtype(p.count_type).itemsize + next(it, 0) * np.dtype(p.type).itemsize
    return size


def _ply_row_dtype(elem: _Element, endian: str, counts=()) -> np.dtype:
    fields, it = [], iter(counts)
    for i, (p, name) in enumerate(zip(elem.props, _unique([p.name for p in elem.props]))):
        if p.count_type is None:
            fields.append((name, endian + p.type))
        else:
            fields.append((f"__count{i}", endian + p.count_type))
            k = next(it)
            if k:
                fields.append((name, endian + p.type, (k,)))
    return np.dtype(fields)


def _ply_walk_kernel(buf, off, rows, sizes, csizes, signed, big):
    """End offset of ``rows`` rows from ``off`` (-(row + 1) when the data ends inside a row).
    Property i is a scalar of ``sizes[i]`` bytes (``csizes[i] == 0``) or a list: a count of
    ``csizes[i]`` bytes (at most 4), then that many items of ``sizes[i]`` bytes."""
    n = buf.shape[0]
    for r in range(rows):
        for i in range(sizes.shape[0]):
            cs = csizes[i]
            if cs == 0:
                off += sizes[i]
            else:
                if off + cs > n:
                    return -(r + 1)
                k = np.int64(0)
                for b in range(cs):
                    shift = 8 * (cs - 1 - b) if big else 8 * b
                    k += np.int64(buf[off + b]) << shift
                if signed[i] and k >= (np.int64(1) << (8 * cs - 1)):
                    k -= np.int64(1) << (8 * cs)
                off += cs + max(k, 0) * sizes[i]
            if off > n:
                return -(r + 1)
    return off


_walk_impl = None


def _ply_walk(path, data: bytes, offset: int, elem: _Element, endian: str) -> int:
    # Variable-length lists (e.g. mixed triangles and quads) need a row-by-row walk to find
    # where the element ends; compiled with numba (lazily, like the LZF decoder) when available.
    global _walk_impl
    sizes = np.array([np.dtype(p.type).itemsize for p in elem.props], dtype=np.int64)
    csizes = np.array([0 if p.count_type is None else np.dtype(p.count_type).itemsize
                       for p in elem.props], dtype=np.int64)
    signed = np.array([p.count_type is not None and np.dtype(p.count_type).kind == "i"
                       for p in elem.props], dtype=np.bool_)
    # Every row takes at least its scalars and list counts: refuse a huge count at once.
    least = int(sum(sz for sz, cs in zip(sizes, csizes) if cs == 0) + csizes.sum())
    avail = len(data) - offset
    if elem.count * least > avail:
        raise InputFileError(
            f"{path}: truncated: header declares {elem.count:,} '{elem.name}' rows of at least "
            f"{least} byte{'s' if least != 1 else ''} each, the file holds {avail:,} bytes for "
            f"them")
    if _walk_impl is None:
        try:  # imported lazily: numba costs ~1 s and only mixed-length lists need it
            import numba

            _walk_impl = numba.njit(cache=True, nogil=True)(_ply_walk_kernel)
        except Exception:  # pragma: no cover - numba missing or unusable
            _walk_impl = _ply_walk_kernel
    end = int(_walk_impl(np.frombuffer(data, np.uint8), np.int64(offset), np.int64(elem.count),
                         sizes, csizes, signed, endian == ">"))
    if end < 0:
        raise InputFileError(
            f"{path}: truncated: header declares {elem.count:,} '{elem.name}' rows, file ends "
            f"inside row {-end:,}")
    return end


def _ply_binary_block(path, data: bytes, offset: int, elem: _Element, endian: str, is_vertex: bool):
    """Return (structured array or None, offset after the element)."""
    nlists = sum(1 for p in elem.props if p.count_type)
    counts = _ply_first_row_counts(data, offset, elem, endian) if (nlists and elem.count) else None
    if counts is None:
        counts = [0] * nlists
    row = _ply_row_size(elem, counts)
    if row == 0:  # an element without properties takes no bytes, however many rows
        return None, offset
    avail = len(data) - offset
    fits = avail >= elem.count * row  # Python integers: a huge count builds no array
    if fits:
        try:
            dt = _ply_row_dtype(elem, endian, counts)
        except ValueError:  # a list too long for numpy's shape limits
            dt = None
        if dt is not None:
            arr = np.frombuffer(data, dt, elem.count, offset)
            uniform = all((arr[f"__count{i}"] == k).all() for i, k in
                          zip([i for i, p in enumerate(elem.props) if p.count_type], counts))
            if uniform:
                return arr, offset + elem.count * row
    if not is_vertex:
        return None, _ply_walk(path, data, offset, elem, endian)
    if not fits:
        holds = avail // row
        lists = " (with the first row's list lengths)" if nlists else ""
        raise InputFileError(
            f"{path}: truncated: header declares {elem.count} vertices, file holds {holds}"
            f"{lists}")
    raise InputFileError(f"{path}: vertex list properties of varying length are not supported")


def _rows(elements) -> str:
    return ", ".join(f"{e.count:,} '{e.name}' rows" for e in elements)


def _ply_binary_end(path, data: bytes, offset: int, elements, vi: int, endian: str,
                    vrow: int) -> None:
    """Walk the elements after the vertices (``offset``: where they start; ``vrow``: bytes per
    vertex) and refuse a file that ends inside them or holds bytes after them."""
    vertex = elements[vi]
    vbytes = vertex.count * vrow
    end = offset
    for elem in elements[vi + 1:]:
        _, end = _ply_binary_block(path, data, end, elem, endian, is_vertex=False)
    after = elements[vi + 1:]
    if after:
        declared = (f"header declares {vertex.count:,} vertices and {_rows(after)} after them "
                    f"(data ends at byte {end:,})")
        worth = "is an element count in the header wrong?"
    else:
        declared = f"header declares {vertex.count:,} vertices ({vbytes:,} bytes of data)"
        worth = (f"{(len(data) - end) / vrow:.3g} vertices' worth; is the 'element vertex' "
                 f"count wrong?")
    _check_trailing(path, data[end:], vrow, declared, worth)


def _nonblank_lines(buf: np.ndarray) -> int:
    """Lines of ``buf`` (uint8) holding anything but whitespace."""
    if not len(buf):
        return 0
    ink = ~np.isin(buf, np.frombuffer(b" \t\r\n\x0b\x0c", np.uint8))
    line = np.cumsum(buf == 10)[ink]
    return 0 if not len(line) else 1 + int(np.count_nonzero(np.diff(line)))


def _ply_vertex_columns(path, elem: _Element):
    names = [p.name for p in elem.props]
    low = [n.lower() for n in names]
    idx = []
    for c in "xyz":
        if c in names:
            idx.append(names.index(c))
        elif c in low:
            idx.append(low.index(c))
        else:
            raise InputFileError(f"{path}: the vertex element has no '{c}' property "
                                 f"(properties: {' '.join(names) or 'none'})")
    for i in idx:
        if elem.props[i].count_type is not None:
            raise InputFileError(f"{path}: vertex property '{names[i]}' is a list, expected a scalar")
    lab = _label_index(names)
    if lab is not None and elem.props[lab].count_type is not None:
        lab = None
    return idx, lab


def _as_declared(cols: np.ndarray, codes: list[str]) -> np.ndarray:
    """Round text values to the declared float type, so ASCII and binary files read alike."""
    out = np.array(cols, dtype=np.float64)
    for j, code in enumerate(codes):
        if code in ("f2", "f4"):
            out[:, j] = out[:, j].astype(code)
    return out


def _ply_ascii_vertices(path, data, offset, header_lines, elements, vi, idx, lab):
    buf = np.frombuffer(data, np.uint8, offset=offset)
    nl = np.flatnonzero(buf == 10)
    tail_start = nl[-1] + 1 if len(nl) else 0
    total = len(nl) + (1 if bytes(buf[tail_start:]).strip() else 0)
    skip = sum(e.count for e in elements[:vi])  # ASCII PLY: one line per element row
    elem = elements[vi]
    if total < skip + elem.count:
        raise InputFileError(f"{path}: truncated: header declares {elem.count} vertices, "
                             f"file holds {max(total - skip, 0)}")
    start = nl[skip - 1] + 1 if skip else 0
    last = skip + elem.count - 1
    end = nl[last] if last < len(nl) else len(buf)
    block = bytes(buf[start:end]).decode("latin-1")
    first_line = header_lines + skip + 1
    try:
        arr = np.loadtxt(io.StringIO(block), dtype=np.float64, comments=None, ndmin=2)
    except ValueError as exc:
        msg = _locate_text_error(path, block, None, first_line, exc)
        if any(p.count_type for p in elem.props):
            msg += " (vertex list properties of varying length are not supported)"
        raise InputFileError(msg) from None
    if len(arr) != elem.count:
        raise InputFileError(f"{path}: expected {elem.count} vertex lines from line {first_line}, "
                             f"found {len(arr)} (blank lines inside the data?)")
    _ply_ascii_end(path, buf[end:], elements, vi)
    # Column of each property; lists take 1 + length columns, equal in every row.
    col, cols = 0, []
    for p in elem.props:
        cols.append(col)
        if p.count_type is None:
            col += 1
            continue
        if col >= arr.shape[1]:
            break
        k = arr[0, col]
        if not (arr[:, col] == k).all() or k < 0 or k != int(k):
            raise InputFileError(f"{path}: vertex list '{p.name}' has varying lengths; not supported")
        col += 1 + int(k)
    if col != arr.shape[1]:
        raise InputFileError(f"{path}: vertex lines hold {arr.shape[1]} values, "
                             f"the header declares {col}")
    pts = _as_declared(arr[:, [cols[i] for i in idx]], [elem.props[i].type for i in idx])
    labels = _int_labels(path, arr[:, cols[lab]], "the label property") if lab is not None else None
    return pts, labels


def _ply_ascii_end(path, tail: np.ndarray, elements, vi: int) -> None:
    """``tail``: the bytes after the vertex lines. Refuse a file with fewer or more non-blank
    lines after the vertices than the header declares (one line per row in ASCII PLY)."""
    after = elements[vi + 1:]
    expected = sum(e.count for e in after)
    have = _nonblank_lines(tail)
    if have < expected:
        raise InputFileError(f"{path}: truncated: header declares {_rows(after)} after the "
                             f"vertices ({expected:,} lines), the file holds {have:,}")
    if have > expected:
        n = elements[vi].count
        if not after:
            raise InputFileError(
                f"{path}: header declares {n:,} vertices, the file holds {n + have:,} vertex "
                f"lines ({have:,} more than declared); is the 'element vertex' count wrong?")
        raise InputFileError(
            f"{path}: header declares {n:,} vertices and {_rows(after)} after them, the file "
            f"holds {have:,} lines after the vertices ({have - expected:,} more than declared); "
            f"is an element count in the header wrong?")


def _read_ply(path: Path, return_labels: bool):
    data = _read_bytes(path)
    if data.startswith(_BOM_UTF8):
        data = data[len(_BOM_UTF8):]
    fmt, elements, offset, header_lines = _parse_ply_header(path, data)
    vi = next((i for i, e in enumerate(elements) if e.name == "vertex"), None)
    if vi is None:
        raise InputFileError(f"{path}: the PLY has no 'vertex' element")
    vertex = elements[vi]
    idx, lab = _ply_vertex_columns(path, vertex)
    if vertex.count == 0:
        raise PointCloudError(f"{path}: holds no points (element vertex 0)")
    if fmt == "ascii":
        return _ply_ascii_vertices(path, data, offset, header_lines, elements, vi, idx, lab)
    endian = "<" if fmt == "binary_little_endian" else ">"
    for elem in elements[:vi]:
        _, offset = _ply_binary_block(path, data, offset, elem, endian, is_vertex=False)
    arr, vend = _ply_binary_block(path, data, offset, vertex, endian, is_vertex=True)
    _ply_binary_end(path, data, vend, elements, vi, endian, arr.dtype.itemsize)
    names = _unique([p.name for p in vertex.props])
    pts = np.empty((vertex.count, 3), dtype=np.float64)
    for j, i in enumerate(idx):
        pts[:, j] = arr[names[i]]
    labels = None
    if lab is not None and return_labels:
        labels = _int_labels(path, arr[names[lab]], "the label property")
    return pts, labels


# --------------------------------------------------------------------------------------------
# PCD

_PCD_TYPES = {("F", 2): "f2", ("F", 4): "f4", ("F", 8): "f8",
              ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8",
              ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}
_PCD_KEYS = ("VERSION", "FIELDS", "COLUMNS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT",
             "VIEWPOINT", "POINTS", "DATA")


def _parse_pcd_header(path, data: bytes):
    """Return (header: key -> words, payload offset, header line count, key -> line number)."""
    pos, lineno, hdr, where = 0, 0, {}, {}
    while True:
        if pos >= len(data):
            raise InputFileError(f"{path}: PCD header has no DATA line")
        nl = data.find(b"\n", pos)
        end = len(data) if nl < 0 else nl
        nxt = len(data) if nl < 0 else nl + 1
        lineno += 1
        try:
            line = data[pos:end].decode("ascii").strip()
        except UnicodeDecodeError:
            raise InputFileError(f"{path}: PCD header has no DATA line (binary data at line "
                                 f"{lineno})") from None
        pos = nxt
        if not line or line.startswith("#"):
            continue
        words = line.split()
        key = words[0].upper()
        if key not in _PCD_KEYS:
            raise InputFileError(f"{path}: PCD header line {lineno} is not a header line "
                                 f"({line[:40]!r}); is the DATA line missing?")
        if key in where:
            raise InputFileError(f"{path}: PCD header gives {key} twice (lines {where[key]} "
                                 f"and {lineno})")
        hdr[key] = words[1:]
        where[key] = lineno
        if key == "DATA":
            return hdr, pos, lineno, where


def _pcd_ints(path, hdr, key, n=None, where=None):
    vals = hdr.get(key)
    if vals is None:
        return None
    at = f"line {where[key]}: " if where and key in where else ""
    if not vals or not all(re.fullmatch(r"\d+", v) for v in vals):
        raise InputFileError(f"{path}: {at}malformed PCD {key} line {' '.join([key, *vals])!r} "
                             f"(expected {'whole numbers' if n != 1 else 'one whole number'})")
    if n is not None and len(vals) != n:
        raise InputFileError(f"{path}: {at}PCD {key} line lists {len(vals)} values, "
                             f"expected {n}: {' '.join([key, *vals])!r}")
    return [int(v) for v in vals]


def _pcd_field_count_problem(path, hdr, where) -> str | None:
    """FIELDS, SIZE, TYPE and COUNT must list as many entries each; name the line(s) that do not
    (the odd one out against the others' majority), with its line number."""
    keys = [k for k in ("FIELDS" if "FIELDS" in hdr else "COLUMNS", "SIZE", "TYPE", "COUNT")
            if k in hdr]
    lengths = {k: len(hdr[k]) for k in keys}
    if len(set(lengths.values())) <= 1:
        return None

    def entry(k):
        shown = " ".join(hdr[k]) if len(hdr[k]) <= 12 else " ".join(hdr[k][:12]) + " ..."
        return f"{k} (line {where[k]}) lists {lengths[k]} ({shown})"

    tally: dict[int, list[str]] = {}
    for k in keys:
        tally.setdefault(lengths[k], []).append(k)
    ranked = sorted(tally.items(), key=lambda kv: -len(kv[1]))
    if len(ranked[0][1]) > len(ranked[1][1]):  # a strict majority: the others are the culprits
        common, agree = ranked[0]
        odd = [k for k in keys if lengths[k] != common]
        others = ", ".join(f"{k} (line {where[k]})" for k in agree)
        return (f"{path}: PCD {'; '.join(entry(k) for k in odd)}, but {others} "
                f"list{'s' if len(agree) == 1 else ''} {common}; "
                f"FIELDS, SIZE, TYPE and COUNT need one entry per field")
    return (f"{path}: PCD header lines disagree on the number of fields: "
            f"{'; '.join(entry(k) for k in keys)}")


def _pcd_fields(path, hdr, where=None):
    where = where or {}
    key = "FIELDS" if "FIELDS" in hdr else "COLUMNS"
    if key not in hdr:
        raise InputFileError(f"{path}: PCD header has no FIELDS line")
    names = hdr[key]
    if not names:
        raise InputFileError(f"{path}: line {where.get(key, '?')}: PCD {key} line names no fields")
    for k in ("SIZE", "TYPE"):
        if k not in hdr:
            raise InputFileError(f"{path}: PCD header has no {k} line")
    problem = _pcd_field_count_problem(path, hdr, where)
    if problem:
        raise InputFileError(problem)
    n = len(names)
    sizes = _pcd_ints(path, hdr, "SIZE", n, where)
    counts = _pcd_ints(path, hdr, "COUNT", n, where) or [1] * n
    types = [t.upper() for t in hdr["TYPE"]]
    codes = []
    for name, t, sz in zip(names, types, sizes):
        code = _PCD_TYPES.get((t, sz))
        if code is None:
            at = f"line {where['TYPE']}: " if "TYPE" in where else ""
            raise InputFileError(f"{path}: {at}unknown PCD type/size '{t} {sz}' for field "
                                 f"'{name}' (known: F 2/4/8, I 1/2/4/8, U 1/2/4/8)")
        codes.append(code)
    return list(names), _unique(list(names)), codes, counts


def _lzf_kernel(src, out):
    """LZF decompression (the liblzf format PCL uses). Returns bytes written, -1 if corrupt."""
    ip, op = 0, 0
    n, m = src.shape[0], out.shape[0]
    while ip < n:
        ctrl = np.int64(src[ip])
        ip += 1
        if ctrl < 32:  # literal run of ctrl + 1 bytes
            length = ctrl + 1
            if ip + length > n or op + length > m:
                return -1
            for k in range(length):
                out[op + k] = src[ip + k]
            ip += length
            op += length
        else:  # back reference; may overlap the bytes being written, so copy bytewise
            length = ctrl >> 5
            if length == 7:
                if ip >= n:
                    return -1
                length += np.int64(src[ip])
                ip += 1
            if ip >= n:
                return -1
            ref = op - ((ctrl & 31) << 8) - 1 - np.int64(src[ip])
            ip += 1
            length += 2
            if ref < 0 or op + length > m:
                return -1
            for k in range(length):
                out[op + k] = out[ref + k]
            op += length
    return op


_lzf_impl = None
#: LZF expands at most ~88 times (a 3-byte back reference copies up to 264 bytes).
_LZF_MAX_RATIO = 90


def _lzf_decompress(payload: bytes, size: int) -> np.ndarray | None:
    global _lzf_impl
    if _lzf_impl is None:
        try:  # imported lazily: numba costs ~1 s and only compressed PCDs need it
            import numba

            _lzf_impl = numba.njit(cache=True, nogil=True)(_lzf_kernel)
        except Exception:  # pragma: no cover - numba missing or unusable
            _lzf_impl = _lzf_kernel
    out = np.empty(size, dtype=np.uint8)
    written = _lzf_impl(np.frombuffer(payload, dtype=np.uint8), out)
    return out if written == size else None


def _read_pcd(path: Path, return_labels: bool):
    data = _read_bytes(path)
    if data.startswith(_BOM_UTF8):
        data = data[len(_BOM_UTF8):]
    _check_not_utf16(path, data)
    hdr, offset, header_lines, where = _parse_pcd_header(path, data)
    names, keys, codes, counts = _pcd_fields(path, hdr, where)
    width = _pcd_ints(path, hdr, "WIDTH", 1, where)
    height = _pcd_ints(path, hdr, "HEIGHT", 1, where)
    points = _pcd_ints(path, hdr, "POINTS", 1, where)
    if points is None and width is None:
        raise InputFileError(f"{path}: PCD header has neither POINTS nor WIDTH")
    n = points[0] if points else width[0] * (height[0] if height else 1)
    if width and height and width[0] * height[0] != n:
        raise InputFileError(f"{path}: PCD WIDTH x HEIGHT = {width[0]} x {height[0]} "
                             f"does not match POINTS {n}")
    mode = (hdr["DATA"] or [""])[0].lower()
    if mode not in ("ascii", "binary", "binary_compressed"):
        raise InputFileError(f"{path}: unknown PCD DATA mode {mode!r} "
                             f"(known: ascii, binary, binary_compressed)")
    idx = []
    for c in "xyz":
        if c not in names:
            raise InputFileError(f"{path}: the PCD has no '{c}' field (fields: {' '.join(names)})")
        idx.append(names.index(c))
        if counts[idx[-1]] != 1:
            raise InputFileError(f"{path}: PCD field '{c}' has COUNT {counts[idx[-1]]}, expected 1")
    lab = _label_index(names)
    if lab is not None and counts[lab] != 1:
        lab = None
    if n == 0:
        raise PointCloudError(f"{path}: holds no points (POINTS 0)")

    cols: list[np.ndarray] = [None] * len(names)  # only x, y, z and the label are filled
    wanted = idx + ([lab] if lab is not None and return_labels else [])
    if mode == "ascii":
        block = data[offset:].decode("latin-1")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
            try:
                arr = np.loadtxt(io.StringIO(block), dtype=np.float64, comments="#", ndmin=2)
            except ValueError as exc:
                raise InputFileError(
                    _locate_text_error(path, block, None, header_lines + 1, exc)) from None
        width_total = sum(counts)
        if len(arr) < n:
            raise InputFileError(f"{path}: truncated: header declares {n} points, file holds {len(arr)}")
        if len(arr) > n:
            raise InputFileError(f"{path}: header declares {n} points, file holds {len(arr)} rows")
        if arr.shape[1] != width_total:
            raise InputFileError(f"{path}: rows hold {arr.shape[1]} values, the header declares "
                                 f"{width_total}")
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        for i in wanted:
            cols[i] = _as_declared(arr[:, starts[i]][:, None], [codes[i]])[:, 0]
    elif mode == "binary":
        # Sizes in Python integers first: a huge POINTS or COUNT must not build a dtype or array.
        row = sum(np.dtype(c).itemsize * cnt for c, cnt in zip(codes, counts))
        avail = len(data) - offset
        if row > avail and max(counts) > 1:
            big = max(range(len(counts)), key=counts.__getitem__)
            raise InputFileError(
                f"{path}: line {where.get('COUNT', '?')}: PCD COUNT {counts[big]:,} for field "
                f"'{names[big]}' makes one point {row:,} bytes, more than the file holds "
                f"({avail:,} bytes of data)")
        if avail < n * row:
            raise InputFileError(f"{path}: truncated: header declares {n} points of {row} bytes, "
                                 f"file holds {avail // row if row else 0}")
        _check_trailing(path, data[offset + n * row:], row,
                        f"header declares {n:,} points ({n * row:,} bytes of data)",
                        f"{(avail - n * row) / row:.3g} points' worth; is POINTS wrong?")
        try:
            dt = np.dtype([(k, "<" + c) if cnt == 1 else (k, "<" + c, (cnt,))
                           for k, c, cnt in zip(keys, codes, counts)])
        except ValueError as exc:
            raise InputFileError(f"{path}: PCD COUNT values are too large for a row: {exc}") from None
        arr = np.frombuffer(data, dt, n, offset)
        for i in wanted:
            cols[i] = arr[keys[i]]
    else:
        if len(data) < offset + 8:
            raise InputFileError(f"{path}: truncated: the compressed block header is missing")
        csize, usize = (int(v) for v in np.frombuffer(data, "<u4", 2, offset))
        payload = data[offset + 8: offset + 8 + csize]
        if len(payload) < csize:
            raise InputFileError(f"{path}: truncated: compressed block declares {csize} bytes, "
                                 f"file holds {len(payload)}")
        sizes = [np.dtype(c).itemsize * cnt for c, cnt in zip(codes, counts)]
        if usize > _LZF_MAX_RATIO * csize + 64:
            raise InputFileError(f"{path}: corrupt binary_compressed block: {csize:,} compressed "
                                 f"bytes cannot unpack to the declared {usize:,} (LZF expands at "
                                 f"most ~88 times)")
        if usize != n * sum(sizes):
            raise InputFileError(f"{path}: compressed block unpacks to {usize} bytes, "
                                 f"{n} points need {n * sum(sizes)}")
        raw = _lzf_decompress(payload, usize)
        if raw is None:
            raise InputFileError(f"{path}: corrupt LZF data in the binary_compressed block")
        # Compressed PCD stores each field contiguously (all x, then all y, ...).
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]) * n
        for i in wanted:
            cols[i] = np.frombuffer(raw, "<" + codes[i], n, int(starts[i]))
    pts = np.column_stack([cols[i] for i in idx]).astype(np.float64, copy=False)
    labels = None
    if lab is not None and return_labels:
        labels = _int_labels(path, cols[lab], "the label field")
    return pts, labels


# --------------------------------------------------------------------------------------------
# meshes


def _read_mesh(path: Path, mesh_samples: int, seed: int):
    import trimesh  # imported lazily: only meshes need it

    ext, compressed = cloud_extension(path)
    if compressed:
        source, kwargs = io.BytesIO(_read_bytes(path)), {"file_type": ext.lstrip(".")}
    else:
        _check_file(path)
        source, kwargs = str(path), {}
    try:
        mesh = trimesh.load(source, force="mesh", process=False, **kwargs)
    except Exception as exc:  # trimesh raises many unrelated types on bad files
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise InputFileError(f"{path}: cannot read mesh: {reason}") from None
    vertices = np.asarray(getattr(mesh, "vertices", np.empty((0, 3))), dtype=np.float64)
    faces = np.asarray(getattr(mesh, "faces", np.empty((0, 3))))
    if len(faces) == 0:
        if len(vertices) == 0:
            raise PointCloudError(f"{path}: the mesh holds no geometry")
        log.info("%s: mesh has no faces; returning its %d vertices", path, len(vertices))
        return vertices, None
    if not np.isfinite(vertices).all():
        raise PointCloudError(f"{path}: mesh vertices contain NaN/inf")
    if not mesh.area > 0:
        raise PointCloudError(f"{path}: the mesh has zero surface area; cannot sample it")
    pts, _ = trimesh.sample.sample_surface(mesh, int(mesh_samples), seed=seed)
    return np.asarray(pts, dtype=np.float64), None


# --------------------------------------------------------------------------------------------
# public reader


def _drop_nonfinite(path, pts, labels, drop_invalid):
    bad = ~np.isfinite(pts).all(axis=1)
    nbad = int(bad.sum())
    if not nbad:
        return pts, labels
    if not drop_invalid:
        first = int(np.flatnonzero(bad)[0])
        raise PointCloudError(
            f"{path}: {nbad:,} of {len(pts):,} points have NaN/inf coordinates "
            f"(first at point {first + 1:,}); remove them, or pass --drop-invalid (tpvp plan) / "
            f"drop_invalid=True (tpvp.io.read_point_cloud)")
    warnings.warn(f"{path}: dropped {nbad:,} of {len(pts):,} points with NaN/inf coordinates",
                  stacklevel=3)
    keep = ~bad
    return pts[keep], (labels[keep] if labels is not None else None)


def read_point_cloud(path, units: str = "auto", return_labels: bool = False, *,
                     drop_invalid: bool = False, mesh_samples: int = 100_000, seed: int = 0,
                     return_units: bool = False):
    """Read a point cloud as float64 (N, 3) metres (``(points, labels or None)`` with
    ``return_labels``).

    Formats by extension (case-insensitive): .ply (ascii / binary LE / binary BE), .pcd (ascii,
    binary, binary_compressed), .xyz .txt .pts .csv (3+ columns: x y z, then an optional integer
    label), and meshes .obj .stl .off .glb, surface-sampled with ``mesh_samples`` points
    (deterministic for a given ``seed``); each of them also gzip-compressed (``.ply.gz``, ...).
    ``units``: "auto", "m" or "mm" (see module doc). NaN/inf points raise PointCloudError unless
    ``drop_invalid`` is True. With ``return_units`` a :class:`UnitChoice` is appended to the
    result (``(points, choice)`` or ``(points, labels, choice)``); ``str(choice)`` reads
    ``auto -> mm (largest extent 230 mm)``.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise ConfigError(f"path must be a file path, got {type(path).__name__}")
    if units not in UNITS:
        raise ConfigError(f"units must be one of {UNITS}, got {units!r}")
    if not isinstance(mesh_samples, (int, np.integer)) or isinstance(mesh_samples, bool) \
            or mesh_samples < 1:
        raise ConfigError(f"mesh_samples must be a positive integer, got {mesh_samples!r}")
    path = Path(path)
    _stat_input(path)  # before anything opens it: a FIFO would block, a device never end
    ext, compressed = cloud_extension(path)
    if ext == ".ply":
        pts, labels = _read_ply(path, return_labels)
    elif ext == ".pcd":
        pts, labels = _read_pcd(path, return_labels)
    elif ext in TEXT_EXTENSIONS:
        pts, labels = _read_text_cloud(path, return_labels)
    elif ext in MESH_EXTENSIONS:
        pts, labels = _read_mesh(path, mesh_samples, seed)
    else:
        what = f"{ext or '(none)'}.gz" if compressed else (ext or "(none)")
        raise InputFileError(f"{path}: unknown point-cloud extension {what!r} "
                             f"(supported: {' '.join(READ_EXTENSIONS)}, each optionally .gz)")
    pts, labels = _drop_nonfinite(path, pts, labels, drop_invalid)
    if len(pts) == 0:
        raise PointCloudError(f"{path}: holds no points")
    choice = unit_choice(pts, units, source=path)
    pts = _scaled(_as_points(pts), units, choice.used, path)
    out = (pts, labels) if return_labels else (pts,)
    if return_units:
        out = (*out, choice)
    return out if len(out) > 1 else out[0]


# --------------------------------------------------------------------------------------------
# writer


def write_point_cloud(path, points, labels=None, binary: bool = True, *, dtype=None) -> Path:
    """Write points (and optional integer labels) atomically; returns the path.

    By extension: .ply (binary little-endian, or ascii with ``binary=False``), .pcd (binary or
    ascii), .xyz/.txt/.pts/.csv text (``x y z [label]``; .csv comma-separated; .pts starts with
    the point count). ``dtype`` is "float64" or "float32"; the default (None) is float64
    (lossless) except for PCD, which gets float32 because PCL tools expect it and open3d 0.20
    reads binary ``F 8`` fields as zeros. Parent directories are created.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise ConfigError(f"path must be a file path, got {type(path).__name__}")
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in WRITE_EXTENSIONS:
        raise ConfigError(f"{path}: cannot write extension {ext or '(none)'!r} "
                          f"(supported: {' '.join(WRITE_EXTENSIONS)})")
    if dtype is None:
        dtype = "float32" if ext == ".pcd" else "float64"
    try:
        dt = np.dtype(dtype)
    except TypeError:
        dt = None
    if dt not in (np.dtype("f4"), np.dtype("f8")):
        raise ConfigError(f"dtype must be float32 or float64, got {dtype!r}")
    pts = _as_points(points)
    if len(pts) == 0:
        raise PointCloudError(f"cannot write {path}: points is empty")
    if not np.isfinite(pts).all():
        nbad = int((~np.isfinite(pts).all(axis=1)).sum())
        raise PointCloudError(f"cannot write {path}: {nbad} points have NaN/inf coordinates")
    if labels is not None:
        lab = np.asarray(labels)
        if lab.shape != (len(pts),):
            raise ConfigError(f"labels must have shape ({len(pts)},), got {lab.shape}")
        if lab.dtype.kind not in "iu" and not (
                lab.dtype.kind in "fb" and np.isfinite(lab).all()
                and np.array_equal(lab, np.round(lab))):
            raise ConfigError("labels must be integers")
        lab = lab.astype(np.int64)
        if lab.size and (lab.min() < np.iinfo(np.int32).min or lab.max() > np.iinfo(np.int32).max):
            raise ConfigError("labels must fit in 32-bit integers")
        labels = lab
    pts = pts.astype(dt)
    n = len(pts)
    fmt = "%.9g" if dt == np.float32 else "%.17g"

    if ext == ".ply":
        ptype = "float" if dt == np.float32 else "double"
        header = [
            "ply",
            f"format {'binary_little_endian' if binary else 'ascii'} 1.0",
            "comment written by tpvp",
            f"element vertex {n}",
            *(f"property {ptype} {c}" for c in "xyz"),
            *(["property int label"] if labels is not None else []),
            "end_header",
        ]
        head = ("\n".join(header) + "\n").encode("ascii")
        if binary:
            body = _packed(pts, labels, "<", "i4")
        else:
            body = _text_body(pts, labels, fmt, " ")
        atomic_write_bytes(path, head + body)
    elif ext == ".pcd":
        size = dt.itemsize
        fields, sizes, types = "x y z", [size] * 3, ["F"] * 3
        if labels is not None:
            fields += " label"
            sizes.append(4)
            # PCL's label is unsigned; negative labels (e.g. -1 = unlabelled) need a signed type.
            types.append("U" if labels.min() >= 0 else "I")
        k = len(sizes)
        header = [
            "# .PCD v0.7 - Point Cloud Data file format",
            "VERSION 0.7",
            f"FIELDS {fields}",
            f"SIZE {' '.join(map(str, sizes))}",
            f"TYPE {' '.join(types)}",
            f"COUNT {' '.join(['1'] * k)}",
            f"WIDTH {n}",
            "HEIGHT 1",
            "VIEWPOINT 0 0 0 1 0 0 0",
            f"POINTS {n}",
            f"DATA {'binary' if binary else 'ascii'}",
        ]
        head = ("\n".join(header) + "\n").encode("ascii")
        if binary:
            body = _packed(pts, labels, "<", "u4" if types[-1] == "U" else "i4")
        else:
            body = _text_body(pts, labels, fmt, " ")
        atomic_write_bytes(path, head + body)
    else:
        delim = "," if ext == ".csv" else " "
        head = f"{n}\n".encode() if ext == ".pts" else b""
        atomic_write_bytes(path, head + _text_body(pts, labels, fmt, delim))
    return path


def _packed(pts: np.ndarray, labels, endian: str, label_code: str) -> bytes:
    fields = [(c, endian + pts.dtype.str[1:]) for c in "xyz"]
    if labels is not None:
        fields.append(("label", endian + label_code))
    rec = np.empty(len(pts), dtype=fields)
    for j, c in enumerate("xyz"):
        rec[c] = pts[:, j]
    if labels is not None:
        rec["label"] = labels
    return rec.tobytes()


def _text_body(pts: np.ndarray, labels, fmt: str, delim: str) -> bytes:
    buf = io.StringIO()
    if labels is None:
        np.savetxt(buf, pts, fmt=fmt, delimiter=delim)
    else:
        table = np.column_stack([pts.astype(np.float64), labels.astype(np.float64)])
        np.savetxt(buf, table, fmt=[fmt] * 3 + ["%d"], delimiter=delim)
    return buf.getvalue().encode("ascii")
