"""Units of a point cloud: metres or millimetres, detected or declared, and checked.

Rule (``units="auto"``, see :func:`detect_units`): a cloud whose largest bounding-box side exceeds
10 is taken as millimetres (no plant or greenhouse-row scan is 10 m long, while a plant scanned in
millimetres spans tens to hundreds of units); otherwise it is metres, even when its coordinates
reach |c| >= 10 (the reference simulator's mm switch), because a small extent far from the origin
is a metric scan with an offset, not a plant under 1 cm tall. That ambiguous case is reported with
a warning. After conversion a cloud larger than 100 m, or (for an explicit ``units="mm"``) smaller
than 1 mm, raises :class:`~tpvp.errors.PointCloudError`, unless a few points far from all the others
make it so large: then they are named instead (:func:`stray_points`). A coordinate beyond 1e10, in
metres or millimetres (the Earth's radius is 6.4e9 mm; a UTM northing 1e7 m), is damaged data, not a
units question, and is refused first (:func:`check_coordinates`). ``tpvp plan`` also warns about a
single plant larger than 5 m (:func:`plant_size_warning`). To tell the user what ``"auto"`` chose,
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
#: No scan coordinate in metres or millimetres is larger (module doc): beyond it the data is damaged.
ABSURD_COORDINATE = 1e10
#: A single plant larger than this (m) is warned about by ``tpvp plan``: millimetres read as metres?
PLANT_WARN_EXTENT_M = 5.0
#: A point farther than this many bulk extents from the bulk of the cloud (its 1st-99th
#: percentile box) is a stray point, when such points are at most :data:`STRAY_SHARE` of the cloud.
STRAY_FACTOR = 100.0
STRAY_SHARE = 0.01

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
    than axis-0 reductions on a large (N, 3) array). A side beyond the float range is inf, silently."""
    if not len(pts):
        return np.zeros(3)
    with np.errstate(over="ignore", invalid="ignore"):
        return np.array([pts[:, a].max() - pts[:, a].min() for a in range(3)])


def length(value: float, unit: str) -> str:
    """A length for a message: ``46.2 mm``, ``47,890 m``, ``1e+30 m`` (never 30 digits)."""
    return f"{value:,.0f} {unit}" if 100 <= abs(value) < 1e7 else f"{value:.3g} {unit}"


def _points(n: int) -> str:
    return f"{n:,} point{'s' if n != 1 else ''}"


def _largest_side(pts: np.ndarray) -> float:
    finite = _finite(pts)
    return float(_extent(finite).max()) if len(finite) else 0.0


def check_coordinates(points, source=None) -> None:
    """Refuse coordinates beyond :data:`ABSURD_COORDINATE` (damaged data in any unit), naming how
    many points, the first one (0-based index) and its value; NaN/inf are left to the caller."""
    pts = as_points(points)
    # Column extremes first (NaN ignored): no (N, 3) temporary for the nearly every scan that passes.
    flat = pts.reshape(-1)  # a view of a C-contiguous array: one pass over contiguous memory
    if not len(flat) or (-ABSURD_COORDINATE <= np.fmin.reduce(flat) and np.fmax.reduce(flat) <= ABSURD_COORDINATE):
        return
    with np.errstate(invalid="ignore"):
        big = np.isfinite(pts) & (np.abs(pts) > ABSURD_COORDINATE)  # NaN/inf are left to the caller
    rows = big.any(axis=1)
    if not rows.any():
        return
    first = int(np.flatnonzero(rows)[0])
    axis = int(np.flatnonzero(big[first])[0])
    n = int(rows.sum())
    which = "all" if n == len(pts) else f"{n:,} of"
    raise PointCloudError(
        f"{_who(source)}{which} {_points(len(pts))} {'has' if n == 1 else 'have'} absurd coordinates "
        f"(first: {'xyz'[axis]} = {pts[first, axis]:g} at point index {first}, counting from 0), beyond "
        f"{ABSURD_COORDINATE:g} in metres or millimetres: the file is damaged or holds something else; "
        f"remove those points or export the scan again")


def stray_points(pts: np.ndarray):
    """``(indices, extent of the others)`` of the few points far from the bulk of the cloud
    (module constants :data:`STRAY_FACTOR`, :data:`STRAY_SHARE`), or None when there are none
    or too many to be strays. Only called on a cloud already found implausibly large."""
    pts = as_points(pts)
    ok = np.isfinite(pts).all(axis=1)
    finite = pts[ok]
    if len(finite) < 10:
        return None
    # "nearest": no interpolation, so no overflow between huge values.
    lo, hi = (np.array([np.percentile(finite[:, a], q, method="nearest") for a in range(3)]) for q in (1, 99))
    with np.errstate(over="ignore", invalid="ignore"):
        width = float((hi - lo).max())
        if not (np.isfinite(width) and width > 0):
            return None
        margin = STRAY_FACTOR * width
        far = ((pts < lo - margin) | (pts > hi + margin)).any(axis=1)
    n = int(far.sum())
    if n == 0 or n > STRAY_SHARE * len(pts):
        return None
    return np.flatnonzero(far), float(_extent(pts[ok & ~far]).max())


def stray_message(pts: np.ndarray, unit: str, source=None, side: float | None = None) -> str | None:
    """One line naming the stray points of ``pts`` (in ``unit``) that make it ``side`` across, or
    None when there are none."""
    found = stray_points(pts)
    if found is None:
        return None
    index, rest = found
    first = int(index[0])
    pts = as_points(pts)
    with np.errstate(over="ignore", invalid="ignore"):
        axis = int(np.nanargmax(np.abs(pts[first] - np.nanmedian(pts, axis=0))))
    side = _largest_side(pts) if side is None else side
    n, one = len(index), len(index) == 1
    return (f"{_who(source)}{n:,} of {_points(len(pts))} {'lies' if one else 'lie'} far from all the others "
            f"({'' if one else 'first: '}{'xyz'[axis]} = {pts[first, axis]:g} at point index {first}, counting "
            f"from 0): with {'it' if one else 'them'} the scan spans {length(side, unit)}, without "
            f"{'it' if one else 'them'} {length(rest, unit)}; remove "
            f"{'it (a stray or damaged point)' if one else 'them (stray or damaged points)'}")


def detect_units(points, source=None) -> str:
    """Return ``"mm"`` if the largest bounding-box side exceeds 10, else ``"m"`` (see module doc)."""
    pts = as_points(points)
    finite = _finite(pts)
    if len(finite) == 0:
        raise PointCloudError(f"{_who(source)}cannot detect units of a cloud with no finite points")
    lo = np.array([finite[:, a].min() for a in range(3)])
    hi = np.array([finite[:, a].max() for a in range(3)])
    with np.errstate(over="ignore", invalid="ignore"):
        side = float((hi - lo).max())
    if side > MM_EXTENT_THRESHOLD:
        return "mm"
    reach = float(max(np.abs(lo).max(), np.abs(hi).max()))
    if reach >= REFERENCE_MM_COORD:
        warnings.warn(
            f"{_who(source)}coordinates reach |c| = {reach:.4g} but the cloud spans only {side:.4g}: "
            f"taken as metres (offset from the origin); if it is a tiny scan in millimetres, give --units mm "
            f"(units='mm')",
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
    check_coordinates(pts, source)
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
    check_coordinates(pts, source)
    used = detect_units(pts, source) if units == "auto" else units
    out = in_metres(pts, units, used, source)
    return out.copy() if out is points else out


def in_metres(pts: np.ndarray, units: str, used: str, source) -> np.ndarray:
    """``pts`` read as ``used`` units ("m" or "mm"), in metres (the array itself for metres),
    refused when implausible; ``units`` is what the caller asked, to say what went wrong (in the
    command line's terms: ``--units m`` is ``units="m"``)."""
    out = pts * 1e-3 if used == "mm" else pts
    side = _largest_side(out)
    if side > MAX_EXTENT_M:
        stray = stray_message(pts, used, source)
        if stray is not None:
            raise PointCloudError(stray)
        span = length(side, "m")
        if units == "auto":
            why = (f"read as millimetres (--units auto) it still spans {span} (a {span} plant?), more than "
                   f"the {MAX_EXTENT_M:g} m of a greenhouse row; convert the file to metres or millimetres")
        elif units == "m":
            why = (f"--units m makes it a {span} plant (limit {MAX_EXTENT_M:g} m); it looks like millimetres: "
                   f"use --units mm or --units auto")
        else:
            why = (f"even read as millimetres (--units mm) it spans {span} (a {span} plant?), more than the "
                   f"{MAX_EXTENT_M:g} m of a greenhouse row; convert the file to metres or millimetres")
        raise PointCloudError(f"{_who(source)}wrong units? {why}")
    if units == "mm" and 0.0 < side < MIN_EXTENT_M:
        raise PointCloudError(
            f"{_who(source)}wrong units? --units mm shrinks the cloud to {side * 1e3:.3g} mm across; "
            f"it looks like metres already: use --units m or --units auto"
        )
    return out


def plant_size_warning(points_m: np.ndarray, choice: UnitChoice, source=None) -> str | None:
    """A warning (one line) when the single plant ``points_m`` (metres, read as ``choice`` says)
    spans more than :data:`PLANT_WARN_EXTENT_M`: stray points, or millimetres read as metres.
    The plan in the normalised frame does not change with the units; its scan-frame coordinates
    (``plan.csv``) do."""
    side = choice.largest_side_m
    if not side > PLANT_WARN_EXTENT_M:
        return None
    stray = stray_message(points_m, "m", source, side)
    if stray is not None:
        return stray
    given = "--units auto" if choice.requested == "auto" else f"--units {choice.requested}"
    if choice.used == "m":
        return (f"{_who(source)}read as metres ({given}) the plant spans {length(side, 'm')}, more than "
                f"the {PLANT_WARN_EXTENT_M:g} m of any single plant; if the file is in millimetres, give "
                f"--units mm, or plan.csv's coordinates are 1000 times too large")
    return (f"{_who(source)}read as millimetres ({given}) the plant spans {length(side, 'm')}, more than "
            f"the {PLANT_WARN_EXTENT_M:g} m of any single plant; check the file's units and coordinates")
