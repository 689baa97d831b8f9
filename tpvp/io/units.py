"""Units of a point cloud: metres or millimetres, detected or declared, and checked.

Rule (``units="auto"``, see :func:`detect_units`): a cloud whose largest bounding-box side exceeds
10 is taken as millimetres (no plant or greenhouse-row scan is 10 m long, while a plant scanned in
millimetres spans tens to hundreds of units); otherwise it is metres, even when its coordinates
reach |c| >= 10 (the reference simulator's mm switch), because a small extent far from the origin
is a metric scan with an offset, not a plant under 1 cm tall. That ambiguous case is reported with
a warning. After conversion a cloud larger than 100 m, or (for an explicit ``units="mm"``) smaller
than 1 mm, raises :class:`~tpvp.errors.PointCloudError`. To tell the user what ``"auto"`` chose,
ask ``read_point_cloud(..., return_units=True)`` (or :func:`unit_choice` on a raw array) for a
:class:`UnitChoice`; ``str()`` of it reads ``auto -> mm (largest extent 230 mm)``.
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import numpy as np

from tpvp.errors import ConfigError, PointCloudError

#: Largest bounding-box side (in file units) still taken as metres by ``units="auto"``.
MM_EXTENT_THRESHOLD = 10.0
#: The reference simulator's rule: any |coordinate| >= this means millimetres.
REFERENCE_MM_COORD = 10.0
#: Largest plausible side of a scan in metres (a greenhouse row is a few metres).
MAX_EXTENT_M = 100.0
#: Smallest plausible side in metres when the caller declares millimetres.
MIN_EXTENT_M = 1e-3

UNITS = ("auto", "m", "mm")


def as_points(points, name: str = "points") -> np.ndarray:
    """``points`` as a float64 (N, 3) array (no copy when it is one); anything else is a ConfigError."""
    try:
        pts = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{name} must be a numeric (N, 3) array: {exc}") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ConfigError(f"{name} must be an (N, 3) array, got shape {pts.shape}")
    return pts


def _who(source) -> str:
    return f"{source}: " if source is not None else ""


def _finite(pts: np.ndarray) -> np.ndarray:
    """The finite rows; the array itself (no copy) when all are finite, as in nearly every scan."""
    if np.isfinite(pts).all():
        return pts
    return pts[np.isfinite(pts).all(axis=1)]


def _extent(pts: np.ndarray) -> np.ndarray:
    """Bounding-box sides of finite points; column by column (contiguous reductions are ~8x faster
    than axis-0 reductions on a large (N, 3) array)."""
    return np.array([pts[:, a].max() - pts[:, a].min() for a in range(3)]) if len(pts) else np.zeros(3)


def _largest_side(pts: np.ndarray) -> float:
    finite = _finite(pts)
    return float(_extent(finite).max()) if len(finite) else 0.0


def detect_units(points, source=None) -> str:
    """Return ``"mm"`` if the largest bounding-box side exceeds 10, else ``"m"`` (see module doc)."""
    pts = as_points(points)
    finite = _finite(pts)
    if len(finite) == 0:
        raise PointCloudError(f"{_who(source)}cannot detect units of a cloud with no finite points")
    lo = np.array([finite[:, a].min() for a in range(3)])
    hi = np.array([finite[:, a].max() for a in range(3)])
    side = float((hi - lo).max())
    if side > MM_EXTENT_THRESHOLD:
        return "mm"
    reach = float(max(np.abs(lo).max(), np.abs(hi).max()))
    if reach >= REFERENCE_MM_COORD:
        warnings.warn(
            f"{_who(source)}coordinates reach |c| = {reach:.4g} but the cloud spans only {side:.4g}: "
            f"taken as metres (offset from the origin); pass units='mm' if it is a tiny mm scan",
            stacklevel=2,
        )
    return "m"


class UnitChoice(NamedTuple):
    """Which units a cloud was read in: ``str()`` gives ``auto -> mm (largest extent 230 mm)``."""

    requested: str  # "auto", "m" or "mm", as asked
    used: str  # "m" or "mm": what the file's numbers were taken to be
    largest_side: float  # largest bounding-box side in the file's units (``used``)

    @property
    def largest_side_m(self) -> float:
        return self.largest_side * (1e-3 if self.used == "mm" else 1.0)

    def __str__(self) -> str:
        return f"{self.requested} -> {self.used} (largest extent {self.largest_side:.3g} {self.used})"


def unit_choice(points, units: str = "auto", source=None) -> UnitChoice:
    """The :class:`UnitChoice` for raw (file-unit) points: :func:`detect_units` for "auto"."""
    if units not in UNITS:
        raise ConfigError(f"units must be one of {UNITS}, got {units!r}")
    pts = as_points(points)
    used = detect_units(pts, source) if units == "auto" else units
    return UnitChoice(units, used, _largest_side(pts))


def to_metres(points, units: str = "auto", source=None) -> np.ndarray:
    """Return a new float64 (N, 3) array in metres; ``units`` is "auto", "m" or "mm".

    Raises PointCloudError when the result is implausible for a plant or greenhouse row
    (larger than 100 m, or under 1 mm for an explicit ``units="mm"``); ``source`` (a file name)
    is put in the message.
    """
    if units not in UNITS:
        raise ConfigError(f"units must be one of {UNITS}, got {units!r}")
    pts = as_points(points)
    used = detect_units(pts, source) if units == "auto" else units
    out = in_metres(pts, units, used, source)
    return out.copy() if out is points else out


def in_metres(pts: np.ndarray, units: str, used: str, source) -> np.ndarray:
    """``pts`` read as ``used`` units ("m" or "mm"), in metres (the array itself for metres),
    refused when implausible; ``units`` is what the caller asked, to say what went wrong."""
    out = pts * 1e-3 if used == "mm" else pts
    side = _largest_side(out)
    if side > MAX_EXTENT_M:
        if units == "auto":
            why = f"even after mm -> m conversion it spans {side:.0f} m (a {side:.0f} m plant?)"
        elif units == "m":
            why = (f"units='m' makes it a {side:.0f} m plant; it looks like millimetres "
                   f"(use units='mm' or 'auto')")
        else:
            why = f"even in millimetres it spans {side:.0f} m (a {side:.0f} m plant?)"
        raise PointCloudError(f"{_who(source)}wrong units? {why}")
    if units == "mm" and 0.0 < side < MIN_EXTENT_M:
        raise PointCloudError(
            f"{_who(source)}wrong units? units='mm' shrinks the cloud to {side * 1e3:.3g} mm across; "
            f"it looks like metres already (use units='m' or 'auto')"
        )
    return out
