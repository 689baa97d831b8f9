"""Voxel grids as plain integer key arrays.

Convention (OctoMap's): the voxel of a point x is ``key = floor(x / resolution)`` per axis, and its
centre is ``(key + 0.5) * resolution``. The grid is world aligned with its origin at 0, so two clouds
voxelised at the same resolution share voxels exactly. A voxel set is an ``(N, 3) int64`` array of
keys; set algebra works on keys packed into one ``int64`` code per voxel (21 bits per axis), which
lets numpy's sorted-array set routines do the work.
"""

from __future__ import annotations

import numpy as np

from tpvp.errors import ConfigError, PointCloudError

KEY_BITS = 21  # bits per axis in a voxel code
KEY_OFFSET = 1 << (KEY_BITS - 1)  # encodable keys: [-2^20, 2^20) per axis, +-1 km at 1 mm voxels
KEY_MASK = (1 << KEY_BITS) - 1


def _check_resolution(resolution: float) -> float:
    resolution = float(resolution)
    if not np.isfinite(resolution) or resolution <= 0:
        raise ConfigError(f"voxel resolution must be a positive number of metres, got {resolution!r}")
    return resolution


def voxel_keys(points: np.ndarray, resolution: float) -> np.ndarray:
    """Integer voxel key of every point (duplicates kept), ``(N, 3) int64``."""
    resolution = _check_resolution(resolution)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    _check_finite(points)
    scaled = points / resolution
    np.floor(scaled, out=scaled)  # in place: one (N, 3) float temporary instead of two
    keys = scaled.astype(np.int64)
    del scaled
    if keys.size and (keys.min() < -KEY_OFFSET or keys.max() >= KEY_OFFSET):
        _raise_span(points, resolution)
    return keys


def _check_finite(points: np.ndarray) -> None:
    if not np.isfinite(points).all():
        raise PointCloudError("cannot voxelise a cloud with NaN or infinite coordinates")


def _raise_span(points: np.ndarray, resolution: float):
    raise PointCloudError(
        f"coordinates span {np.ptp(points, axis=0).max():.3g} m, too large for voxels of "
        f"{resolution} m (wrong units?)"
    )


# A dense table of the keys' bounding box replaces sorting when it has at most this many cells and
# at most _DENSE_PER_POINT cells per point (int32 table: 4 bytes a cell, i.e. <= 128 MB).
_DENSE_MAX_CELLS = 1 << 25
_DENSE_PER_POINT = 8


def _voxel_ranks(points: np.ndarray, resolution: float):
    """Distinct voxels of a cloud in code order and every point's voxel rank, without sorting.

    Returns ``(keys (M, 3) int64, inverse (N,) intp)`` equal to ``decode_keys(np.unique(codes,
    return_inverse=True))``, or None when the cloud's box is too large for a dense table (the
    caller then sorts). Code order is the lexicographic (x, y, z) order of the keys, which is the
    order of the row-major linear index in the keys' bounding box, so ranks over that index are the
    same numbers. Works column by column: no (N, 3) integer temporary.
    """
    n = len(points)
    lo, hi, columns = [], [], []
    for a in range(3):
        k = points[:, a] / resolution
        np.floor(k, out=k)
        if n:
            kmin, kmax = k.min(), k.max()
            if kmin < -KEY_OFFSET or kmax >= KEY_OFFSET:
                _raise_span(points, resolution)
            lo.append(int(kmin))
            hi.append(int(kmax))
        columns.append(k)
    if n == 0:
        return None
    shape = [h - l + 1 for l, h in zip(lo, hi)]
    cells = shape[0] * shape[1] * shape[2]
    if cells > _DENSE_MAX_CELLS or cells > _DENSE_PER_POINT * n:
        return None
    linear = columns[0].astype(np.int64)
    linear -= lo[0]
    for a in (1, 2):
        linear *= shape[a]
        column = columns[a].astype(np.int64)
        column -= lo[a]
        linear += column
        del column
    del columns
    table = np.zeros(cells, dtype=np.int32)
    table[linear] = 1
    occupied = np.flatnonzero(table)
    table[occupied] = np.arange(len(occupied), dtype=np.int32)
    inverse = table[linear].astype(np.intp)
    del table, linear
    keys = np.empty((len(occupied), 3), dtype=np.int64)
    keys[:, 2] = occupied % shape[2] + lo[2]
    rest = occupied // shape[2]
    keys[:, 1] = rest % shape[1] + lo[1]
    keys[:, 0] = rest // shape[1] + lo[0]
    return keys, inverse


def key_centres(keys: np.ndarray, resolution: float) -> np.ndarray:
    """Centres of voxels given by their keys, ``(N, 3) float64``."""
    resolution = _check_resolution(resolution)
    return (np.asarray(keys, dtype=np.int64).reshape(-1, 3) + 0.5) * resolution


def encode_key(kx, ky, kz):
    """Code of the key ``(kx, ky, kz)``: ``KEY_BITS`` bits per axis, each shifted by
    ``KEY_OFFSET``; codes sort like the keys (x, then y, then z).

    The one definition of the packing: :func:`encode_keys` applies it to columns, and numba
    kernels compile it as is (integer arithmetic on module constants only; see
    :data:`tpvp.sensor.raycast.encode_key_jit`). Keys must lie in ``[-KEY_OFFSET, KEY_OFFSET)``;
    this scalar form does not check.
    """
    return ((kx + KEY_OFFSET) << (2 * KEY_BITS)) | ((ky + KEY_OFFSET) << KEY_BITS) | (kz + KEY_OFFSET)


def encode_keys(keys: np.ndarray) -> np.ndarray:
    """Pack ``(N, 3)`` keys into one sortable ``int64`` code each (see :func:`encode_key`).

    Raises :class:`PointCloudError` for keys outside ``[-KEY_OFFSET, KEY_OFFSET)``.
    """
    keys = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
    if keys.size and (keys.min() < -KEY_OFFSET or keys.max() >= KEY_OFFSET):
        raise PointCloudError(
            f"voxel keys span [{keys.min()}, {keys.max()}], outside the encodable range "
            f"[{-KEY_OFFSET}, {KEY_OFFSET}) (points too far from the origin for the voxel size?)"
        )
    return encode_key(keys[:, 0], keys[:, 1], keys[:, 2])


def decode_keys(codes: np.ndarray) -> np.ndarray:
    """Inverse of :func:`encode_keys`."""
    codes = np.asarray(codes, dtype=np.int64).reshape(-1)
    keys = np.stack([(codes >> (2 * KEY_BITS)) & KEY_MASK, (codes >> KEY_BITS) & KEY_MASK,
                     codes & KEY_MASK], axis=1)
    return keys - KEY_OFFSET


def unique_keys(keys: np.ndarray, return_counts: bool = False):
    """Distinct keys in code order (optionally with how many times each occurred)."""
    codes, counts = np.unique(encode_keys(keys), return_counts=True)
    return (decode_keys(codes), counts) if return_counts else decode_keys(codes)


def voxelise(points: np.ndarray, resolution: float) -> np.ndarray:
    """Distinct voxel keys occupied by a cloud (code order)."""
    resolution = _check_resolution(resolution)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    _check_finite(points)
    ranked = _voxel_ranks(points, resolution)
    if ranked is not None:
        return ranked[0]
    return unique_keys(voxel_keys(points, resolution))


def voxel_centres(points: np.ndarray, resolution: float) -> np.ndarray:
    """Centres of the distinct voxels occupied by a cloud (the usual 'voxel-downsampled' cloud)."""
    return key_centres(voxelise(points, resolution), resolution)


def voxel_centroids(points: np.ndarray, resolution: float) -> np.ndarray:
    """Centroid of the points in every occupied voxel (Open3D ``voxel_down_sample``), in key order.
    Each centroid lies in its points' voxel, so the voxel set at ``resolution`` (or any multiple of
    it) is unchanged: the reduction of large scans relies on that."""
    resolution = _check_resolution(resolution)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    _check_finite(points)
    ranked = _voxel_ranks(points, resolution)
    if ranked is not None:
        keys, inverse = ranked
        counts = np.bincount(inverse, minlength=len(keys))
    else:
        codes = encode_keys(voxel_keys(points, resolution))
        _, inverse, counts = np.unique(codes, return_inverse=True, return_counts=True)
        del codes
    # per-point sums in point order, as before: the same floating-point numbers
    sums = np.stack([np.bincount(inverse, weights=points[:, a], minlength=len(counts)) for a in range(3)], 1)
    return sums / counts[:, None]


def code_centroids(keys: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(codes, centroids)``: the distinct codes of ``keys`` (one key per point, code order) and the
    centroid of the ``points`` of each: what a capture records of what it saw."""
    codes, inverse = np.unique(encode_keys(keys), return_inverse=True)
    inverse = inverse.reshape(-1)
    counts = np.bincount(inverse, minlength=len(codes)).astype(np.float64)
    centroids = np.stack([np.bincount(inverse, weights=points[:, a], minlength=len(codes)) for a in range(3)],
                         axis=1) / counts[:, None]
    return codes, centroids


def first_seen(captures, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """A reconstruction from captures ``[(view, codes, centroids or None), ...]``: every voxel
    (code order) any capture holds, each at the centroid the first view (lowest index) that saw it
    recorded there (its centre where centroids are None), and that view: ``(points, first)``."""
    captures = sorted(captures, key=lambda c: c[0])
    union = np.unique(np.concatenate([codes for _, codes, _ in captures]))
    first = np.full(len(union), -1, dtype=np.int64)
    points = key_centres(decode_keys(union), resolution)
    for view, codes, centroids in captures:
        at = np.searchsorted(union, codes)
        new = first[at] < 0
        first[at[new]] = view
        if centroids is not None:
            points[at[new]] = centroids[new]
    return points, first


def union_keys(*key_sets: np.ndarray) -> np.ndarray:
    """Voxels in any of the sets."""
    codes = [encode_keys(k) for k in key_sets]
    return decode_keys(np.unique(np.concatenate(codes))) if codes else np.zeros((0, 3), np.int64)


def intersect_keys(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Voxels in both sets."""
    return decode_keys(np.intersect1d(encode_keys(a), encode_keys(b)))


def difference_keys(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Voxels of ``a`` that are not in ``b``."""
    return decode_keys(np.setdiff1d(encode_keys(a), encode_keys(b)))


def contains_keys(keys: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Boolean mask: which ``query`` keys belong to the set ``keys``."""
    return np.isin(encode_keys(query), encode_keys(keys))


def spherical_offsets(radius_voxels: float) -> np.ndarray:
    """All integer offsets ``o`` with ``|o|^2 <= radius^2`` (the spherical structuring element).

    A radius of 1 gives the 7-voxel cross (centre + 6 face neighbours); 0 gives the centre only.
    The small tolerance keeps offsets that lie exactly on the sphere despite rounding.
    """
    if radius_voxels < 0 or not np.isfinite(radius_voxels):
        raise ConfigError(f"dilation radius must be >= 0 voxels, got {radius_voxels!r}")
    r = int(np.floor(radius_voxels + 1e-9))
    axis = np.arange(-r, r + 1)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    return grid[(grid**2).sum(axis=1) <= radius_voxels**2 + 1e-6].astype(np.int64)


def dilate_keys(keys: np.ndarray, radius_voxels: float) -> np.ndarray:
    """Morphological dilation of a voxel set by a sphere of ``radius_voxels`` voxels."""
    keys = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
    offsets = spherical_offsets(radius_voxels)
    return unique_keys((keys[:, None, :] + offsets[None, :, :]).reshape(-1, 3))
