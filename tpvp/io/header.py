"""Headers of PLY and PCD files: their lines one by one, and the binary data they declare.

Both formats start with ASCII header lines and then hold data (text or binary) whose size the
header declares; the two readers walk the header with :func:`header_lines` and refuse data beyond
what it declares with :func:`check_trailing`.
"""

from __future__ import annotations

from typing import Iterator, NamedTuple

from tpvp.errors import InputFileError

#: Windows editors may start a header with a UTF-8 byte-order mark.
BOM_UTF8 = b"\xef\xbb\xbf"


class HeaderLine(NamedTuple):
    number: int  # 1 for the first line of the file
    text: str | None  # stripped ASCII text; None when the line is not ASCII (binary data)
    end: int  # offset after the line and its newline: where the next line, or the data, starts
    last: bool  # the file ends on this line (no newline after it)


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
        yield HeaderLine(number, text, len(data) if nl < 0 else nl + 1, nl < 0)
        if nl < 0:
            return
        pos = nl + 1


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
