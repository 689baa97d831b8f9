"""Single-plant scene set-up (docs/single_plant.md#normalisation).

Order matters: scale by the largest bounding-box side of the *unrotated* plant, rotate about +Z,
then centre on the rotated plant's bounding box (scaling after rotating would change the 45-degree
plant's size, and its oracle, by about 30%).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tpvp.errors import ConfigError, PointCloudError, checked_cloud
from tpvp.io.units import length
from tpvp.scene import voxels


@dataclass(frozen=True)
class PlantScene:
    """A normalised plant ready for the simulator (all in metres, plant centre at the origin)."""

    points: np.ndarray  # (N, 3) plant points after scaling, rotation and centring
    scale: float  # factor applied to the input coordinates
    rotation_deg: float
    offset: np.ndarray  # subtracted after scaling and rotating: p' = R (s p) - offset
    table_points: np.ndarray  # (M, 3) supporting-table voxel centres (empty without a table)

    @property
    def centre(self) -> np.ndarray:
        return np.zeros(3)

    def transform(self, points: np.ndarray) -> np.ndarray:
        """Apply the same scale, rotation and centring to another cloud (e.g. the other session)."""
        return _rotate_z(np.asarray(points, dtype=np.float64) * self.scale, self.rotation_deg) - self.offset

    @property
    def matrix(self) -> np.ndarray:
        """The 4x4 map of :meth:`transform`: ``p' = M[:3, :3] p + M[:3, 3]`` (scale included)."""
        m = np.eye(4)
        m[:3, :3] = self.scale * _rotate_z(np.eye(3), self.rotation_deg).T
        m[:3, 3] = -self.offset
        return m


def _rotate_z(points: np.ndarray, degrees: float) -> np.ndarray:
    if degrees == 0:
        return points.copy()
    a = np.deg2rad(degrees)
    c, s = np.cos(a), np.sin(a)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return points @ rot.T


# Two sessions of one plant differ in size by growth, not by this factor: beyond it the units differ.
UNIT_RATIO = 20.0


def _bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis minimum and maximum, column by column (fast on large (N, 3) arrays)."""
    return (np.array([points[:, a].min() for a in range(3)]), np.array([points[:, a].max() for a in range(3)]))


def _span(size_m: float, choice) -> str:
    """A size in metres as the user gave it: in the file's units (``choice.used``) when known."""
    if choice is None:
        return length(1e3 * size_m, "mm")
    return length(size_m * (1e3 if choice.used == "mm" else 1.0), choice.used)


def _units_advice(units) -> str:
    """What to do about two scans a units factor apart, given how their units were chosen
    (``units``: their two :class:`~tpvp.io.units.UnitChoice`, or None for arrays in metres)."""
    if units is None:
        return "they look like different units (mm vs m?): give both arrays in metres"
    requested = units[0].requested
    if requested != "auto":
        return (f"the files look like different units, and --units {requested} applies to both: try --units "
                f"auto (it decides each file's units on its own) or convert one file")
    read = (f"both as {units[0].used}" if units[0].used == units[1].used else
            f"one as {units[0].used}, the other as {units[1].used}")
    return (f"the files look like different units (--units auto read {read}; cm? inches?): convert them to "
            f"the same units, m or mm, and give --units m or --units mm")


def check_session_pair(previous: np.ndarray, current: np.ndarray, names=("previous", "current"),
                       units=None) -> None:
    """Refuse two scans that cannot be sessions of one plant in one frame, in the scans' own units
    (metres): sizes a units factor apart, or bounding boxes far apart for the plant's size.
    ``units`` (the two files' :class:`~tpvp.io.units.UnitChoice`, from ``read_point_cloud(...,
    return_units=True)``) words the sizes in the files' own units and the advice by how their units
    were chosen (``--units`` given or ``auto``)."""
    (lo_p, hi_p), (lo_q, hi_q) = (_bounds(c) for c in (previous, current))
    size_p, size_q = float((hi_p - lo_p).max()), float((hi_q - lo_q).max())
    choice_p, choice_q = (None, None) if units is None else units
    small, large = sorted((size_p, size_q))
    if small > 0 and large / small > UNIT_RATIO:
        raise PointCloudError(
            f"{names[0]} spans {_span(size_p, choice_p)} and {names[1]} {_span(size_q, choice_q)}, a factor "
            f"{large / small:.0f} apart (more than growth between sessions): {_units_advice(units)}")
    gap = np.maximum(0.0, np.maximum(lo_p - hi_q, lo_q - hi_p))
    gap = float(np.linalg.norm(gap))
    size = max(size_p, size_q)
    if gap > 0.2 * size:
        unit = choice_q if choice_q is not None and (choice_p is None or choice_p.used == choice_q.used) else None
        raise PointCloudError(
            f"{names[0]} and {names[1]} do not overlap: their bounding boxes are {_span(gap, unit)} apart for a "
            f"plant of {_span(size, unit)}; the two sessions must be in one frame (align them first, e.g. "
            f"python -m data_tools prepare-session)")


def up_rotation(up_axis: str = "+z") -> np.ndarray:
    """Proper rotation taking the scan axis ``up_axis`` (``+z``, ``-y``, ...) to +Z."""
    axes = {"x": 0, "y": 1, "z": 2}
    if len(up_axis) != 2 or up_axis[0] not in "+-" or up_axis[1] not in axes:
        raise ConfigError(f"up axis must be one of +z, -z, +y, -y, +x, -x, got {up_axis!r}")
    up = np.zeros(3)
    up[axes[up_axis[1]]] = 1.0 if up_axis[0] == "+" else -1.0
    z = np.array([0.0, 0.0, 1.0])
    if up @ z > 0.5:
        return np.eye(3)
    if up @ z < -0.5:
        return np.diag([1.0, -1.0, -1.0])  # half turn about x
    # Rotate by 90 degrees about the axis up x z (Rodrigues with sin = 1, cos = 0).
    k = np.cross(up, z)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + kx + kx @ kx


def rotate_z(points: np.ndarray, degrees: float) -> np.ndarray:
    """Rotate points about the +Z axis through the origin."""
    return _rotate_z(np.asarray(points, dtype=np.float64).reshape(-1, 3), degrees)


def normalise_plant(points, largest_side: float = 0.24, rotation_deg: float = 0.0,
                    centre: str = "bbox", table: bool = False, table_size: float = 0.4,
                    table_resolution: float = 0.002, reference_points=None,
                    name: str = "plant cloud") -> PlantScene:
    """Scale, rotate and centre a plant; optionally add the supporting table of the hemisphere setup.

    ``reference_points`` (e.g. the current session) defines scale and centre instead of ``points``,
    so that two sessions of one plant stay in one frame. ``centre`` is ``"bbox"`` (paper) or
    ``"centroid"`` (the authors' code). ``name`` names the cloud in errors (e.g. its file).
    """
    points = checked_cloud(points, name)
    ref = points if reference_points is None else checked_cloud(reference_points, "reference cloud")
    if not (largest_side > 0):
        raise ConfigError(f"largest_side must be > 0 m, got {largest_side!r}")
    if centre not in ("bbox", "centroid"):
        raise ConfigError(f"centre must be 'bbox' or 'centroid', got {centre!r}")
    lo, hi = _bounds(ref)
    extent = (hi - lo).max()
    if extent <= 0:
        raise PointCloudError(f"{name} has zero extent (all points coincide)")
    scale = largest_side / extent
    rotated = _rotate_z(ref * scale, rotation_deg)
    if centre == "bbox":
        lo, hi = _bounds(rotated)
        offset = 0.5 * (lo + hi)
    else:
        offset = rotated.mean(axis=0)
    plant = rotated if ref is points else _rotate_z(points * scale, rotation_deg)
    plant -= offset  # in place: large scans are hundreds of MB
    table_points = np.zeros((0, 3))
    if table:
        table_points = table_slab(plant, table_size, table_resolution)
    return PlantScene(points=plant, scale=float(scale), rotation_deg=float(rotation_deg),
                      offset=offset, table_points=table_points)


def table_slab(plant_points: np.ndarray, size: float = 0.4, resolution: float = 0.002) -> np.ndarray:
    """Voxel centres of a one-voxel-thick square table under the plant (centred at x = y = 0).

    The slab sits at ``z = lowest plant point - resolution`` (docs/single_plant.md#table).
    """
    z = np.asarray(plant_points)[:, 2].min() - resolution
    half = size / 2
    lo = voxels.voxel_keys(np.array([[-half, -half, z]]), resolution)[0]
    hi = voxels.voxel_keys(np.array([[half, half, z]]), resolution)[0]
    ii, jj = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
    keys = np.stack([ii.ravel(), jj.ravel(), np.full(ii.size, lo[2])], axis=1)
    return voxels.key_centres(keys, resolution)

