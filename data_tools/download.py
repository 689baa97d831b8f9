"""Resumable HTTP downloads with size and SHA-256 checks (standard library only).

Data is written to ``<destination>.part``. A later call resumes that file with an HTTP ``Range``
request, so an interrupted multi-gigabyte download never starts over. The ``.part`` file becomes
``destination`` (``os.replace``) only after every check passed, and a ``<destination>.sha256``
sidecar in ``sha256sum`` format then records the verified digest: a destination with a sidecar
was checked once and is returned without downloading again.

Every failure is a :class:`~data_tools.errors.DownloadError` (or
:class:`~data_tools.errors.InputFileError`) with a one-line message naming the URL or file.
"""

from __future__ import annotations

import contextlib
import hashlib
import http.client
import os
import re
import urllib.error
import urllib.parse
import urllib.request
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

from data_tools.errors import DownloadError, InputFileError
from tpvp.io import atomic_write_text

__all__ = ["DownloadResult", "download_file", "file_sha256", "verify_zip"]

USER_AGENT = "tpvp-data-tools (+https://github.com; python urllib)"
_HEX64 = re.compile(r"^[0-9a-f]{64}$")
_CONTENT_RANGE = re.compile(r"^\s*bytes\s+(?:(\d+)-(\d+)|\*)\s*/\s*(\d+|\*)\s*$", re.IGNORECASE)


@dataclass(frozen=True)
class DownloadResult:
    """A verified file on disk."""

    path: Path
    size: int  # bytes
    sha256: str  # lower-case hex digest of the whole file
    resumed: bool  # True when part of the data came from an earlier, interrupted run


def _sidecar(destination: Path) -> Path:
    return destination.with_name(destination.name + ".sha256")


def _part(destination: Path) -> Path:
    return destination.with_name(destination.name + ".part")


def _checked_sha256(sha256) -> str | None:
    if sha256 is None:
        return None
    digest = str(sha256).strip().lower()
    if not _HEX64.match(digest):
        raise DownloadError(f"--sha256 must be 64 hexadecimal digits, got {sha256!r}")
    return digest


def _read_sidecar(destination: Path) -> str | None:
    """The digest recorded in ``destination.sha256`` when it names this file, else None."""
    try:
        words = _sidecar(destination).read_text(encoding="utf-8").split()
    except (OSError, UnicodeDecodeError):
        return None
    if len(words) != 2 or words[1].lstrip("*") != destination.name:
        return None
    digest = words[0].lower()
    return digest if _HEX64.match(digest) else None


def file_sha256(path, chunk_size: int = 1 << 20) -> str:
    """SHA-256 hex digest of a file, read in chunks (constant memory)."""
    digest = hashlib.sha256()
    _hash_prefix(Path(path), None, digest, chunk_size)
    return digest.hexdigest()


def _reason(exc: BaseException) -> str:
    """Short human reason of a socket/URL error ("Connection refused", "timed out", ...)."""
    inner = exc.reason if isinstance(exc, urllib.error.URLError) else exc
    if isinstance(inner, BaseException):
        text = getattr(inner, "strerror", None) or str(inner) or type(inner).__name__
    else:
        text = str(inner)
    return text.strip().splitlines()[0] if text.strip() else type(exc).__name__


def _unreachable(url: str, exc: BaseException, hint: str) -> DownloadError:
    host = urllib.parse.urlsplit(url).hostname or url
    return DownloadError(f"cannot reach {host} ({_reason(exc)}): offline? {hint}")


def _open(url: str, offset: int, timeout: float, hint: str):
    """Send the request (a Range request when ``offset`` > 0). Returns the response, or the
    HTTPError of a 416 answer so the caller can read its Content-Range."""
    headers = {"User-Agent": USER_AGENT, "Accept-Encoding": "identity"}
    if offset > 0:
        headers["Range"] = f"bytes={offset}-"
    request = urllib.request.Request(url, headers=headers)
    try:
        return urllib.request.urlopen(request, timeout=timeout)
    except urllib.error.HTTPError as exc:
        if exc.code == 416 and offset > 0:
            return exc
        exc.close()
        raise DownloadError(f"HTTP {exc.code} {exc.reason} for {url}") from None
    except (urllib.error.URLError, OSError, http.client.HTTPException) as exc:
        # URLError wraps DNS failures and refused connections; a bare timeout can surface too.
        raise _unreachable(url, exc, hint) from None


def _content_range(response):
    """(start, total) from a Content-Range header; each None when absent or '*'."""
    match = _CONTENT_RANGE.match(response.headers.get("Content-Range", "") or "")
    if not match:
        return None, None
    start = int(match.group(1)) if match.group(1) is not None else None
    total = int(match.group(3)) if match.group(3) != "*" else None
    return start, total


def _content_length(response) -> int | None:
    value = response.headers.get("Content-Length")
    try:
        return int(value) if value is not None else None
    except ValueError:
        return None


def download_file(url: str, destination, *, sha256: str | None = None,
                  expected_size: int | None = None, timeout: float = 30.0,
                  chunk_size: int = 1 << 20, progress: bool = True,
                  offline_hint: str | None = None) -> DownloadResult:
    """Download ``url`` to ``destination``, resuming an earlier ``.part`` file, and verify it.

    Checks: the byte count against the server's total (Content-Length / Content-Range) and
    ``expected_size``; the SHA-256 against ``sha256`` when given. A checksum or size mismatch of
    a complete transfer removes the ``.part`` file; an interrupted transfer keeps it so that the
    next call resumes. A ``destination`` with a matching ``.sha256`` sidecar is returned at once.
    ``offline_hint`` ends the message when the server cannot be reached (what to do instead).
    """
    from tqdm.auto import tqdm  # imported here: only downloads need it

    destination = Path(destination)
    want = _checked_sha256(sha256)
    if urllib.parse.urlsplit(url).scheme not in ("http", "https"):
        raise DownloadError(f"cannot download {url!r}: only http:// and https:// URLs are supported")
    if expected_size is not None and expected_size < 0:
        raise DownloadError(f"expected_size must be >= 0 bytes, got {expected_size!r}")
    if chunk_size < 1:
        raise DownloadError(f"chunk_size must be >= 1 byte, got {chunk_size!r}")

    # Already downloaded and verified by an earlier run?
    recorded = _read_sidecar(destination)
    if destination.is_file() and recorded is not None and (want is None or recorded == want):
        size = destination.stat().st_size
        if expected_size is None or size == expected_size:
            return DownloadResult(destination, size, recorded, resumed=False)

    offline_hint = offline_hint or f"Download {url} by hand (e.g. in a browser) and save it as {destination}"
    part = _part(destination)
    try:
        destination.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputFileError(f"cannot create directory {destination.parent}: "
                             f"{exc.strerror or exc}") from None
    offset = part.stat().st_size if part.is_file() else 0
    if expected_size is not None and offset > expected_size:
        offset = _discard(part)  # longer than the whole file: not a prefix of it

    response, total = _open(url, offset, timeout, offline_hint), None
    if isinstance(response, urllib.error.HTTPError):  # 416: nothing left to send from offset
        _, total = _content_range(response)
        response.close()
        known = total if total is not None else expected_size
        if known is not None and known == offset:
            response = None  # the .part is already complete
        else:
            offset = _discard(part)  # the .part does not match the file on the server
            response = _open(url, 0, timeout, offline_hint)
    elif offset > 0 and not (response.status == 206 and _content_range(response)[0] == offset):
        # Range ignored (200) or answered with another range: keep a 200 body, else ask again.
        offset = _discard(part)
        if response.status != 200:
            response.close()
            response = _open(url, 0, timeout, offline_hint)

    digest = hashlib.sha256()
    resumed = offset > 0
    if response is not None:
        with response:
            if resumed:
                total = _content_range(response)[1]
            elif response.status == 200:
                total = _content_length(response)
            else:
                raise DownloadError(f"HTTP {response.status} {response.reason} for {url}: "
                                    f"expected the whole file (200)")
            if total is not None and expected_size is not None and total != expected_size:
                raise DownloadError(f"{url}: the server reports {total} bytes, expected "
                                    f"{expected_size}; has the file on the server changed?")
            if resumed:
                _hash_prefix(part, offset, digest, chunk_size)
            with tqdm(total=total if total is not None else expected_size, initial=offset,
                      unit="B", unit_scale=True, unit_divisor=1024, desc=destination.name,
                      disable=not progress, leave=False) as bar:
                _stream(response, part, "ab" if resumed else "wb", digest, bar, chunk_size,
                        url, offset, total)
    else:
        _hash_prefix(part, offset, digest, chunk_size)

    size = part.stat().st_size
    needed = total if total is not None else expected_size
    if needed is not None and size < needed:
        # The connection ended early: keep the .part so that the next run resumes it.
        raise DownloadError(f"{url}: transfer interrupted after {size} of {needed} bytes "
                            f"(kept {part.name}); run again to resume")
    if needed is not None and size > needed:
        _discard(part)
        raise DownloadError(f"{destination.name}: size mismatch: got {size} bytes, "
                            f"expected {needed} (removed {part.name})")
    if expected_size is not None and size != expected_size:
        _discard(part)
        raise DownloadError(f"{destination.name}: size mismatch: got {size} bytes, "
                            f"expected {expected_size} (removed {part.name})")
    got = digest.hexdigest()
    if want is not None and got != want:
        _discard(part)
        raise DownloadError(f"{destination.name}: SHA-256 mismatch: expected {want}, got {got} "
                            f"(removed {part.name}; run again to download afresh)")

    # Remove the old sidecar first: a crash between the two steps then leaves a destination
    # without sidecar (downloaded again next time), never a sidecar vouching for a stale file.
    with contextlib.suppress(FileNotFoundError):
        _sidecar(destination).unlink()
    try:
        os.replace(part, destination)
    except OSError as exc:
        raise InputFileError(f"cannot write {destination}: {exc.strerror or exc}") from None
    atomic_write_text(_sidecar(destination), f"{got}  {destination.name}\n")
    return DownloadResult(destination, size, got, resumed)


def _discard(part: Path) -> int:
    with contextlib.suppress(FileNotFoundError):
        part.unlink()
    return 0


def _hash_prefix(part: Path, size: int | None, digest, chunk_size: int) -> None:
    """Feed the first ``size`` bytes of a file (all of it for None) into ``digest``."""
    try:
        with open(part, "rb") as fh:
            left = size if size is not None else float("inf")
            while left > 0 and (chunk := fh.read(int(min(chunk_size, left)))):
                digest.update(chunk)
                left -= len(chunk)
    except OSError as exc:
        raise InputFileError(f"{part}: cannot read: {exc.strerror or exc}") from None


def _stream(response, part: Path, mode: str, digest, bar, chunk_size: int, url: str,
            offset: int, total: int | None) -> int:
    """Copy the response body into ``part``; returns the bytes now in ``part``."""
    try:
        out = open(part, mode)
    except OSError as exc:
        raise InputFileError(f"cannot write {part}: {exc.strerror or exc}") from None
    with out:
        while True:
            try:
                chunk = response.read(chunk_size)
            except (OSError, http.client.HTTPException) as exc:
                out.flush()
                shown = f"{offset} of {total}" if total is not None else f"{offset}"
                raise DownloadError(f"{url}: transfer interrupted after {shown} bytes "
                                    f"({_reason(exc)}; kept {part.name}); run again to resume"
                                    ) from None
            if not chunk:
                return offset
            try:
                out.write(chunk)
            except OSError as exc:
                raise InputFileError(f"cannot write {part}: {exc.strerror or exc}") from None
            digest.update(chunk)
            offset += len(chunk)
            bar.update(len(chunk))


def verify_zip(path, *, progress: bool = False) -> int:
    """Check every member's CRC (what ``ZipFile.testzip`` does); returns the member count.

    Raises :class:`InputFileError` naming the file (and member) for a missing, truncated or
    corrupt archive.
    """
    from tqdm.auto import tqdm

    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: file not found")
    hint = "truncated or corrupt download? delete it and download again"
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
        raise InputFileError(f"{path}: not a readable ZIP archive ({_reason(exc)}): {hint}") from None
    with archive:
        members = archive.infolist()
        total = sum(m.file_size for m in members)
        with tqdm(total=total, unit="B", unit_scale=True, unit_divisor=1024,
                  desc=f"check {path.name}", disable=not progress, leave=False) as bar:
            for member in members:
                try:
                    # Reading a member to its end makes zipfile compare the CRC (BadZipFile).
                    with archive.open(member) as fh:
                        while chunk := fh.read(1 << 20):
                            bar.update(len(chunk))
                except (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError,
                        NotImplementedError, RuntimeError) as exc:
                    raise InputFileError(f"{path}::{member.filename}: corrupt ZIP member "
                                         f"({_reason(exc)}): {hint}") from None
    return len(members)
