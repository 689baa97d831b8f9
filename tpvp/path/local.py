"""Local path between two camera positions around a spherical obstacle.

Facts: docs/single_plant.md#local-path.

The obstacle is a sphere of centre O and radius r around the plant. If the segment MN does not
enter the sphere the path is the segment; otherwise, with P and Q the points where MN enters and
leaves the sphere, the path runs M -> P straight, P -> Q along the sphere's great circle through
P and Q (the short arc), and Q -> N straight:

    length = |MP| + r * angle(P - O, Q - O) + |QN|.

(The reference code measures the arc by a parametric angle that can pick the long way round; the
formula above, the short arc, is used here.) Camera positions inside the obstacle sphere have no
defined local path and are rejected.
"""

from __future__ import annotations

import numpy as np

from tpvp.errors import ConfigError

SIZE_FACTOR = 17 / 16  # predicted_size = SIZE_FACTOR * max distance from the centre to a point
RADIUS_FACTOR = float(np.sqrt(2.0))  # obstacle radius = RADIUS_FACTOR * predicted_size

# Relative tolerance for "on the sphere": a camera exactly on the sphere, or a segment tangent to
# it, counts as outside / not entering.
_EPS = 1e-9


def _as_vector(value, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.size != 3 or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name} must be 3 finite coordinates, got {np.asarray(value).tolist()!r}")
    return arr.reshape(3)


def _as_radius(radius) -> float:
    r = float(radius) if np.ndim(radius) == 0 else np.nan
    if not (np.isfinite(r) and r >= 0):
        raise ConfigError(f"radius must be a finite number >= 0, got {radius!r}")
    return r


def _as_positions(positions, name: str = "positions") -> np.ndarray:
    arr = np.asarray(positions, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ConfigError(f"{name} must be an (n, 3) array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name} contains NaN or infinite coordinates")
    return arr


def _check_outside(points: np.ndarray, centre: np.ndarray, r: float, name: str) -> None:
    dist = np.linalg.norm(points - centre, axis=1)
    inside = dist < r * (1 - _EPS)
    if inside.any():
        idx = np.flatnonzero(inside)
        raise ConfigError(f"{name} {idx[:10].tolist()} lie inside the obstacle sphere (radius {r:.4g} m, "
                          f"distances {np.round(dist[idx[:10]], 4).tolist()} m): no local path is defined")


def predicted_size(observed_points, centre, size_factor: float = SIZE_FACTOR) -> float:
    """``size_factor`` x the largest distance from ``centre`` to an observed point."""
    pts = _as_positions(observed_points, "observed_points")
    if pts.shape[0] == 0:
        raise ConfigError("observed_points is empty: the object size cannot be predicted")
    c = _as_vector(centre, "centre")
    return float(size_factor * np.sqrt(((pts - c) ** 2).sum(axis=1).max()))


def obstacle_radius(observed_points, centre, size_factor: float = SIZE_FACTOR,
                    radius_factor: float = RADIUS_FACTOR) -> float:
    """Obstacle sphere radius ``sqrt(2) * predicted_size`` (docs/single_plant.md#local-path)."""
    return float(radius_factor * predicted_size(observed_points, centre, size_factor))


def _segment_terms(m: np.ndarray, n: np.ndarray, centre: np.ndarray, r: float):
    """Per-pair segment length, entry/exit parameters and an "enters the sphere" mask.

    ``m`` and ``n`` broadcast against each other (..., 3).
    """
    d = n - m
    a = (d * d).sum(axis=-1)
    mo = m - centre
    b = (d * mo).sum(axis=-1)  # half the usual linear coefficient
    c = (mo * mo).sum(axis=-1) - r * r
    disc = b * b - a * c
    length = np.sqrt(a)
    with np.errstate(invalid="ignore", divide="ignore"):
        root = np.sqrt(np.maximum(disc, 0.0))
        t1 = (-b - root) / a
        t2 = (-b + root) / a
    # Enter only through a proper (non-tangent) crossing that lies within the segment. Both
    # endpoints are outside, so the roots are both in [0, 1] or both on one side.
    enters = (a > 0) & (disc > _EPS * a * r * r) & (t1 < 1) & (t2 > 0)
    return length, t1, t2, root, a, enters


def local_path_lengths(positions, centre, radius) -> np.ndarray:
    """(V, V) matrix of local path lengths between camera positions (symmetric, zero diagonal)."""
    pos = _as_positions(positions)
    c = _as_vector(centre, "centre")
    r = _as_radius(radius)
    _check_outside(pos, c, r, "positions")
    length, t1, t2, root, a, enters = _segment_terms(pos[:, None, :], pos[None, :, :], c, r)
    with np.errstate(invalid="ignore", divide="ignore"):
        chord = 2.0 * root / np.sqrt(a)  # |PQ|
        angle = 2.0 * np.arcsin(np.clip(chord / (2.0 * r), 0.0, 1.0)) if r > 0 else np.zeros_like(chord)
        around = length * (1.0 - (t2 - t1)) + r * angle  # |MP| + |QN| + arc
    out = np.where(enters, around, length)
    # Mirror the upper triangle: the two directions differ only by round-off, and exact symmetry
    # lets the path solvers treat the matrix as symmetric.
    out = np.triu(out, 1)
    return out + out.T


def local_path_length(m, n, centre, radius) -> float:
    """Local path length between two camera positions."""
    pts = np.stack([_as_vector(m, "m"), _as_vector(n, "n")])
    return float(local_path_lengths(pts, centre, radius)[0, 1])


def local_path_points(m, n, centre, radius, n_points: int = 64) -> np.ndarray:
    """Polyline (k, 3) from M to N: straight, then the short great-circle arc P -> Q, then straight.

    ``n_points`` samples the arc (P and Q included); an unobstructed path is sampled with as many
    points along the segment. For plotting; the length is :func:`local_path_lengths`'s.
    """
    m = _as_vector(m, "m")
    n = _as_vector(n, "n")
    c = _as_vector(centre, "centre")
    r = _as_radius(radius)
    if int(n_points) < 2:
        raise ConfigError(f"n_points must be >= 2, got {n_points!r}")
    n_points = int(n_points)
    _check_outside(np.stack([m, n]), c, r, "positions (m, n)")
    _, t1, t2, _, _, enters = _segment_terms(m, n, c, r)
    s = np.linspace(0.0, 1.0, n_points)[:, None]
    if not enters:
        return m + s * (n - m)
    p = m + t1 * (n - m)
    q = m + t2 * (n - m)
    u = (p - c) / r
    w = (q - c) / r
    cos_t = float(np.clip(u @ w, -1.0, 1.0))
    theta = float(np.arccos(cos_t))
    perp = w - cos_t * u
    norm = np.linalg.norm(perp)
    if norm < 1e-12:
        # P and Q antipodal (the segment passes through O): every great circle through them is
        # equally short; take the one over the top (+Z), else any perpendicular.
        for axis in (np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])):
            perp = axis - (axis @ u) * u
            norm = np.linalg.norm(perp)
            if norm > 1e-6:
                break
    perp = perp / norm
    ang = s * theta
    arc = c + r * (np.cos(ang) * u + np.sin(ang) * perp)
    return np.vstack([m, arc, n])
