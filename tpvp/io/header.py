"""Headers of PLY and PCD files: their lines one by one, and the binary data they declare.

Both formats start with ASCII header lines and then hold data (text or binary) whose size the
header declares; the two readers walk the header with :func:`header_lines` and refuse data beyond
what it declares with :func:`check_trailing`.
"""

from __future__ import annotations

import re
from typing import Iterator, NamedTuple

from tpvp.errors import InputFileError

#: Windows editors may start a header with a UTF-8 byte-order mark.
BOM_UTF8 = b"\xef\xbb\xbf"


class HeaderLine(NamedTuple):
    number: int  # 1 for the first line of the file
    text: str | None  # stripped ASCII text; None when the line is not ASCII (binary data)
    end: int  # offset after the line and its newline: where the next line, or the data, starts
    last: bool  # the file ends on this line (no newline after it)
    start: int = 0  # offset of the line's first byte


def without_bom(data: bytes) -> bytes:
    return data[len(BOM_UTF8):] if data.startswith(BOM_UTF8) else data


def header_lines(data: bytes) -> Iterator[HeaderLine]:
    """Every line of ``data`` from the start, until the caller stops at its end-of-header line.
    The last line is the bytes after the final newline (empty when the file ends with one)."""
    pos, number = 0, 0
    while True:
        nl = data.find(b"\n", pos)
        end = len(data) if nl < 0 else nl
        number += 1
        try:
            text = data[pos:end].decode("ascii").strip()
        except UnicodeDecodeError:
            text = None
        yield HeaderLine(number, text, len(data) if nl < 0 else nl + 1, nl < 0, pos)
        if nl < 0:
            return
        pos = nl + 1


#: How far past a non-ASCII header line to look for the header's end line.
_END_SEARCH = 1 << 20


def not_ascii(path, data: bytes, header: HeaderLine, kind: str, end_line: bytes, end_name: str):
    """The error for a header line that is not ASCII text (``header.text`` is None). When the
    header's end line (``end_line``: a regular expression, e.g. ``rb"end_header\\r?"``) follows
    within 1 MiB, the line is a damaged header line (typically a comment with an accented letter):
    say which line, which byte and what to do. Otherwise binary data began before the header ended."""
    end = re.compile(rb"(?m)^" + end_line + rb"$")
    if not end.search(data[header.end:header.end + _END_SEARCH]):
        return InputFileError(f"{path}: {kind} header has no {end_name} line (binary data at line "
                              f"{header.number})")
    raw = data[header.start:header.end].rstrip(b"\r\n")
    column = next(i for i, b in enumerate(raw) if b > 0x7F) + 1
    shown = raw.decode("utf-8", errors="backslashreplace")
    shown = shown if len(shown) <= 50 else shown[:47] + "..."
    return InputFileError(
        f"{path}: line {header.number} of the {kind} header is not ASCII text (byte "
        f"0x{raw[column - 1]:02x} at column {column}: '{shown}'); a {kind} header must be plain ASCII: "
        f"replace that character (e.g. an accented letter in a comment) or export the scan again")


#: Bytes a writer may leave after binary data (a final newline, NUL padding).
_PADDING = b" \t\r\n\x00"


def check_trailing(path, tail: bytes, row_size: int, declared: str, worth: str) -> None:
    """Refuse bytes after all declared binary data: the header undercounts (the rest would be
    dropped without a word) or the file is damaged. Less than one row of whitespace or NUL
    padding (a trailing newline) is accepted."""
    if not tail or (len(tail) < max(row_size, 1) and not tail.strip(_PADDING)):
        return
    raise InputFileError(f"{path}: {declared} but the file holds {len(tail):,} more bytes after "
                         f"them ({worth})")
