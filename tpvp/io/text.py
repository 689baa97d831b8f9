"""Text tables: numeric tables (``read_text_table``) and text point clouds (.xyz .txt .pts .csv).

A table is whitespace-, comma- or semicolon-separated numbers; '#' starts a comment. It may start
with a row count (``.pts``) or, for a cloud, a line of column names (CloudCompare writes
``//X,Y,Z``). Errors name the file and the offending line.
"""

from __future__ import annotations

import io
import logging
import re
import warnings
from pathlib import Path

import numpy as np

from tpvp.errors import ConfigError, InputFileError, PointCloudError
from tpvp.io.fields import int_labels, label_index
from tpvp.io.files import check_not_utf16, read_input_bytes

log = logging.getLogger(__name__)

TEXT_EXTENSIONS = (".xyz", ".txt", ".pts", ".csv")

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


def locate_text_error(path, body: str, delim, first_lineno: int, exc: Exception) -> str:
    """The one-line error for a table numpy could not parse, naming the offending line (the ASCII
    PLY and PCD readers use it too). Error path only."""
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
    check_not_utf16(path, data)
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
            raise InputFileError(locate_text_error(path, body, delim, body_line, exc)) from None
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
    arr, header = _parse_text_table(path, read_input_bytes(path), count_header=count_header, allow_names=names)
    if columns is not None and len(arr) and arr.shape[1] != columns:
        raise InputFileError(f"{path}: has {arr.shape[1]} columns, expected {columns}")
    if columns is not None and not len(arr):
        arr = np.empty((0, columns))
    if not np.isfinite(arr).all():
        row = int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])
        raise InputFileError(f"{path}: data row {row + 1} holds a NaN/inf value")
    return (arr, header) if names else arr


def read_text_cloud(path: Path, return_labels: bool, mesh_samples: int, seed: int):
    """``(points, labels or None)`` of a text cloud: x y z in the first three columns (or the
    columns named x, y, z), labels from a 4th column or one named like a label. ``mesh_samples``
    and ``seed`` are unused: every reader of the registry takes the same arguments."""
    arr, names = _parse_text_table(path, read_input_bytes(path), count_header="auto", allow_names=True)
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
        label_col = label_index(names)
    labels = None
    if label_col is not None:
        labels = int_labels(path, arr[:, label_col], f"column {label_col + 1}")
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
