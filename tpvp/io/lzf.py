"""LZF decompression, for PCD's binary_compressed data (the liblzf format PCL writes)."""

from __future__ import annotations

import numpy as np

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
LZF_MAX_RATIO = 90


def lzf_decompress(payload: bytes, size: int) -> np.ndarray | None:
    """``size`` bytes unpacked from ``payload`` (uint8), or None when the data is corrupt."""
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
