"""PCD point clouds (PCL's format): ascii, binary and binary_compressed, parsed with numpy.

FIELDS, SIZE, TYPE and COUNT become a structured dtype read with ``np.frombuffer`` (binary), a
table (ascii) or per-field columns after LZF decompression (binary_compressed); every malformed
header line gets a one-line error with its line number, and data beyond what the header declares
is refused rather than dropped.
"""

from __future__ import annotations

import io
import re
import warnings
from pathlib import Path

import numpy as np

from tpvp.errors import InputFileError, PointCloudError
from tpvp.io.fields import as_declared, int_labels, label_index, unique_names
from tpvp.io.files import check_not_utf16, read_input_bytes
from tpvp.io.header import check_trailing, header_lines, not_ascii, without_bom
from tpvp.io.lzf import LZF_MAX_RATIO, lzf_decompress
from tpvp.io.text import locate_text_error

PCD_EXTENSIONS = (".pcd",)
_PCD_TYPES = {("F", 2): "f2", ("F", 4): "f4", ("F", 8): "f8",
              ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8",
              ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}
_PCD_KEYS = ("VERSION", "FIELDS", "COLUMNS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT",
             "VIEWPOINT", "POINTS", "DATA")


def _parse_pcd_header(path, data: bytes):
    """Return (header: key -> words, payload offset, header line count, key -> line number)."""
    hdr, where = {}, {}
    for header in header_lines(data):
        line, lineno = header.text, header.number
        if line is None:
            raise not_ascii(path, data, header, "PCD", rb"(?i:DATA)[ \t][^\n]*", "DATA")
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
            return hdr, header.end, lineno, where
    raise InputFileError(f"{path}: PCD header has no DATA line")


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
    return list(names), unique_names(list(names)), codes, counts


def read_pcd(path: Path, return_labels: bool, mesh_samples: int, seed: int):
    """``(points, labels or None)`` of a PCD file. ``mesh_samples`` and ``seed`` are unused: every
    reader of the registry takes the same arguments."""
    data = without_bom(read_input_bytes(path))
    check_not_utf16(path, data)
    hdr, offset, header_count, where = _parse_pcd_header(path, data)
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
    lab = label_index(names)
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
                    locate_text_error(path, block, None, header_count + 1, exc)) from None
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
            cols[i] = as_declared(arr[:, starts[i]][:, None], [codes[i]])[:, 0]
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
        check_trailing(path, data[offset + n * row:], row,
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
        if usize > LZF_MAX_RATIO * csize + 64:
            raise InputFileError(f"{path}: corrupt binary_compressed block: {csize:,} compressed "
                                 f"bytes cannot unpack to the declared {usize:,} (LZF expands at "
                                 f"most ~88 times)")
        if usize != n * sum(sizes):
            raise InputFileError(f"{path}: compressed block unpacks to {usize} bytes, "
                                 f"{n} points need {n * sum(sizes)}")
        raw = lzf_decompress(payload, usize)
        if raw is None:
            raise InputFileError(f"{path}: corrupt LZF data in the binary_compressed block")
        # Compressed PCD stores each field contiguously (all x, then all y, ...).
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]) * n
        for i in wanted:
            cols[i] = np.frombuffer(raw, "<" + codes[i], n, int(starts[i]))
    pts = np.column_stack([cols[i] for i in idx]).astype(np.float64, copy=False)
    labels = None
    if lab is not None and return_labels:
        labels = int_labels(path, cols[lab], "the label field")
    return pts, labels
