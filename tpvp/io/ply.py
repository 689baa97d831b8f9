"""PLY point clouds: ascii, binary little-endian and big-endian, parsed with numpy.

The header becomes a structured dtype read with ``np.frombuffer``, so that every malformed file
gets a precise one-line error naming the file (open3d returns an empty cloud without a word).
Elements before and after the vertices (faces, edges) are walked to check the file's size: data
beyond what the header declares is refused rather than dropped.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import NamedTuple

import numpy as np

from tpvp.errors import InputFileError, PointCloudError
from tpvp.io.fields import as_declared, int_labels, label_index, unique_names
from tpvp.io.files import check_not_utf16, read_input_bytes
from tpvp.io.header import check_trailing, header_lines, not_ascii, without_bom
from tpvp.io.text import locate_text_error

PLY_EXTENSIONS = (".ply",)
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
        check_not_utf16(path, data)
        raise InputFileError(f"{path}: not a PLY file (does not start with 'ply')")
    fmt, elements = None, []
    for header in header_lines(data):
        line, lineno = header.text, header.number
        if line == "end_header":
            break
        if line is None:
            raise not_ascii(path, data, header, "PLY", rb"end_header\r?", "'end_header'")
        if header.last:
            raise InputFileError(f"{path}: PLY header has no 'end_header' line (the file ends "
                                 f"inside the header, at line {lineno})")
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
    if fmt is None:
        raise InputFileError(f"{path}: PLY header has no 'format' line")
    return fmt, elements, header.end, header.number


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
    for i, (p, name) in enumerate(zip(elem.props, unique_names([p.name for p in elem.props]))):
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
    check_trailing(path, data[end:], vrow, declared, worth)


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
    lab = label_index(names)
    if lab is not None and elem.props[lab].count_type is not None:
        lab = None
    return idx, lab


def _ply_ascii_vertices(path, data, offset, header_count, elements, vi, idx, lab):
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
    first_line = header_count + skip + 1
    try:
        arr = np.loadtxt(io.StringIO(block), dtype=np.float64, comments=None, ndmin=2)
    except ValueError as exc:
        msg = locate_text_error(path, block, None, first_line, exc)
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
    pts = as_declared(arr[:, [cols[i] for i in idx]], [elem.props[i].type for i in idx])
    labels = int_labels(path, arr[:, cols[lab]], "the label property") if lab is not None else None
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


def read_ply(path: Path, return_labels: bool, mesh_samples: int, seed: int):
    """``(points, labels or None)`` of the PLY's vertex element. ``mesh_samples`` and ``seed`` are
    unused: every reader of the registry takes the same arguments."""
    data = without_bom(read_input_bytes(path))
    fmt, elements, offset, header_count = _parse_ply_header(path, data)
    vi = next((i for i, e in enumerate(elements) if e.name == "vertex"), None)
    if vi is None:
        raise InputFileError(f"{path}: the PLY has no 'vertex' element")
    vertex = elements[vi]
    idx, lab = _ply_vertex_columns(path, vertex)
    if vertex.count == 0:
        raise PointCloudError(f"{path}: holds no points (element vertex 0)")
    if fmt == "ascii":
        return _ply_ascii_vertices(path, data, offset, header_count, elements, vi, idx, lab)
    endian = "<" if fmt == "binary_little_endian" else ">"
    for elem in elements[:vi]:
        _, offset = _ply_binary_block(path, data, offset, elem, endian, is_vertex=False)
    arr, vend = _ply_binary_block(path, data, offset, vertex, endian, is_vertex=True)
    _ply_binary_end(path, data, vend, elements, vi, endian, arr.dtype.itemsize)
    names = unique_names([p.name for p in vertex.props])
    pts = np.empty((vertex.count, 3), dtype=np.float64)
    for j, i in enumerate(idx):
        pts[:, j] = arr[names[i]]
    labels = None
    if lab is not None and return_labels:
        labels = int_labels(path, arr[names[lab]], "the label property")
    return pts, labels
