"""Well-spread camera positions on a sphere or hemisphere for any count (Tammes-style).

The Tammes problem maximises the smallest angle between N points on a sphere. We approximate it
by repulsion: start from a Fibonacci lattice and descend the energy sum 1/d^p with a large p
(which is dominated by the closest pairs), projecting back onto the (hemi)sphere after each step.
"""

from __future__ import annotations

import numpy as np

from tpvp.errors import ConfigError


def _fibonacci(n: int, hemisphere: bool) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1 - i / n if hemisphere else 1 - 2 * i / n
    phi = np.pi * (3 - np.sqrt(5)) * i
    r = np.sqrt(np.clip(1 - z**2, 0, None))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def min_angle_deg(points: np.ndarray) -> float:
    """Smallest angle (degrees) between any two directions."""
    u = points / np.linalg.norm(points, axis=1, keepdims=True)
    cos = u @ u.T
    np.fill_diagonal(cos, -1.0)
    return float(np.degrees(np.arccos(np.clip(cos.max(), -1, 1))))


def generate_view_space(count: int, radius: float = 0.4, hemisphere: bool = False,
                        iterations: int = 400, power: float = 12.0) -> np.ndarray:
    """``count`` positions at ``radius`` around the origin, spread as evenly as possible.

    Deterministic (no random start). ``hemisphere`` keeps z >= 0 (the supporting-table setting).
    """
    if int(count) != count or count < 1:
        raise ConfigError(f"view count must be a positive integer, got {count!r}")
    if not radius > 0:
        raise ConfigError(f"view-space radius must be > 0 m, got {radius!r}")
    points = _fibonacci(int(count), hemisphere)
    if count > 1:
        step = 0.1 * np.sqrt(4 * np.pi / count)  # about a tenth of the typical spacing
        for k in range(iterations):
            diff = points[:, None, :] - points[None, :, :]
            dist = np.linalg.norm(diff, axis=2) + np.eye(len(points))
            force = (diff / dist[..., None] ** (power + 2)).sum(axis=1)
            # Keep only the tangential part, normalise so the step size is controlled.
            force -= (force * points).sum(axis=1, keepdims=True) * points
            norm = np.linalg.norm(force, axis=1, keepdims=True)
            points = points + step * (1 - k / iterations) * force / np.maximum(norm.max(), 1e-12)
            if hemisphere:
                points[:, 2] = np.maximum(points[:, 2], 0.0)
            points /= np.linalg.norm(points, axis=1, keepdims=True)
    return points * radius
