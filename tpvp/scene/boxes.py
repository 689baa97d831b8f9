"""Oriented bounding boxes and the greenhouse-row configuration files.

An :class:`OrientedBox` follows the convention of the authors' configuration (Open3D's
``OrientedBoundingBox``): ``rotation`` is a 3x3 matrix whose *columns* are the box axes expressed in
the world frame, ``extent`` holds the full side lengths along those axes, and a world point ``p`` has
local coordinates ``(p - center) @ rotation``. In the greenhouse rows the local x axis runs along the
row, y across it (towards the aisle) and z up.

The configuration of the two real greenhouse rooms ("room1", "room4") ships with the package in
``tpvp/data/greenhouse_row`` (see NOTICE.md there); :func:`room_config` loads it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import yaml

from tpvp.errors import ConfigError, InputFileError

DATA_DIR = Path(__file__).resolve().parent.parent / "data" / "greenhouse_row"
ROOMS = ("room1", "room4")
LOOK_AT_PRIORS = ("PriorBBX", "PriorPassive", "PriorTemporal")

# A configuration file stores R with about 16 significant digits; anything further from a rotation
# than this is a wrong matrix, not float noise.
_ROTATION_TOL = 1e-6


def _as_rotation(matrix, what: str) -> np.ndarray:
    """Validate a proper rotation (orthonormal, det +1) and snap it to the nearest exact one."""
    r = np.asarray(matrix, dtype=np.float64)
    if r.shape != (3, 3):
        raise ConfigError(f"{what}: rotation must be 3x3, got shape {r.shape}")
    if not np.all(np.isfinite(r)):
        raise ConfigError(f"{what}: rotation contains NaN or infinite values")
    err = np.abs(r.T @ r - np.eye(3)).max()
    if err > _ROTATION_TOL:
        raise ConfigError(f"{what}: not a rotation matrix (|R^T R - I| = {err:.3g} > {_ROTATION_TOL:g})")
    if np.linalg.det(r) < 0:
        raise ConfigError(f"{what}: rotation has determinant -1 (a reflection, not a rotation)")
    u, _, vt = np.linalg.svd(r)
    return u @ vt


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class OrientedBox:
    """A box with centre ``center`` (3,), axes = columns of ``rotation`` (3, 3) and full side
    lengths ``extent`` (3,), all in metres. Arrays are stored read-only."""

    center: np.ndarray
    rotation: np.ndarray
    extent: np.ndarray

    def __post_init__(self):
        center = np.asarray(self.center, dtype=np.float64)
        extent = np.asarray(self.extent, dtype=np.float64)
        if center.shape != (3,) or not np.all(np.isfinite(center)):
            raise ConfigError(f"OrientedBox: center must be 3 finite numbers, got {self.center!r}")
        if extent.shape != (3,) or not np.all(np.isfinite(extent)) or np.any(extent <= 0):
            raise ConfigError(f"OrientedBox: extent must be 3 positive lengths, got {self.extent!r}")
        rotation = _as_rotation(self.rotation, "OrientedBox")
        object.__setattr__(self, "center", _frozen(center))
        object.__setattr__(self, "rotation", _frozen(rotation))
        object.__setattr__(self, "extent", _frozen(extent))

    # ------------------------------------------------------------------ basics
    @property
    def half_extent(self) -> np.ndarray:
        return self.extent / 2.0

    @property
    def volume(self) -> float:
        return float(np.prod(self.extent))

    def to_local(self, points) -> np.ndarray:
        """World points -> box-local coordinates (origin at the centre, axes = box axes)."""
        p = np.asarray(points, dtype=np.float64)
        return (p - self.center) @ self.rotation

    def to_world(self, local) -> np.ndarray:
        """Box-local coordinates -> world points (inverse of :meth:`to_local`)."""
        q = np.asarray(local, dtype=np.float64)
        return q @ self.rotation.T + self.center

    def contains(self, points, tol: float = 0.0) -> np.ndarray:
        """Boolean mask of the points inside the box (faces included, grown by ``tol`` metres)."""
        q = self.to_local(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        return np.all(np.abs(q) <= self.half_extent + tol, axis=1)

    def corners(self) -> np.ndarray:
        """The 8 corners ``(8, 3)``; corner ``k`` has signs ``(sx, sy, sz)`` from the bits of ``k``
        (x slowest), the order of the authors' C++ ``OBB::corners``."""
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
        return self.to_world(signs * self.half_extent)

    def axis_aligned_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World axis-aligned bounding box of the oriented box: ``(min (3,), max (3,))``."""
        c = self.corners()
        return c.min(axis=0), c.max(axis=0)

    # ---------------------------------------------------------------- sampling
    def sample_uniform(self, n: int, rng=None) -> np.ndarray:
        """``n`` points uniformly distributed in the box (world frame)."""
        n = int(n)
        if n < 0:
            raise ConfigError(f"sample_uniform: n must be >= 0, got {n}")
        rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        return self.to_world((rng.random((n, 3)) - 0.5) * self.extent)

    def grid_shape(self, spacing) -> tuple[int, int, int]:
        """Number of grid points per box axis for :meth:`grid`."""
        s = self._check_spacing(spacing)
        return tuple(int(v) for v in np.floor(self.extent / s + 1e-9).astype(int) + 1)

    def grid(self, spacing) -> np.ndarray:
        """A regular grid inside the box, in the world frame, ``(nx * ny * nz, 3)``.

        ``spacing`` (a length, or one per box axis) is measured along the box axes. Each axis holds
        ``floor(extent / spacing) + 1`` points, centred in the box (so the leftover
        ``extent - (n - 1) * spacing`` is split equally between both faces). Points are ordered with
        the local x index slowest and z fastest (``reshape(nx, ny, nz, 3)`` recovers the lattice).
        """
        s = self._check_spacing(spacing)
        shape = self.grid_shape(s)
        axes = [(np.arange(n) - (n - 1) / 2.0) * step for n, step in zip(shape, s)]
        local = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        return self.to_world(local)

    def _check_spacing(self, spacing) -> np.ndarray:
        s = np.broadcast_to(np.asarray(spacing, dtype=np.float64), (3,)).copy()
        if not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise ConfigError(f"grid spacing must be positive metres, got {spacing!r}")
        if np.prod(np.floor(self.extent / s) + 1) > 5e7:
            raise ConfigError(f"grid spacing {spacing!r} gives more than 5e7 points for extent {self.extent}")
        return s

    def __repr__(self) -> str:
        f = lambda a: np.array2string(np.asarray(a), precision=4, separator=", ")  # noqa: E731
        return f"OrientedBox(center={f(self.center)}, extent={f(self.extent)}, rotation={f(self.rotation)})"


# ----------------------------------------------------------------------------- YAML files
_YAML_DIRECTIVE = re.compile(r"^\s*%YAML[: ]")


def _load_opencv_yaml(path: Path) -> dict:
    """Parse an OpenCV ``FileStorage`` YAML file (``%YAML:1.0`` header) with ``yaml.safe_load``."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputFileError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{path}: cannot read ({exc})") from None
    lines = text.splitlines()
    # OpenCV writes "%YAML:1.0", which PyYAML rejects; drop directive lines and a "---" marker.
    while lines and (_YAML_DIRECTIVE.match(lines[0]) or lines[0].strip() in ("", "---")):
        lines.pop(0)
    # OpenCV may tag maps as "!!opencv-matrix"; none are expected here, but stay tolerant.
    body = "\n".join(lines).replace("!!opencv-matrix", "")
    try:
        data = yaml.safe_load(body)
    except yaml.YAMLError as exc:
        raise InputFileError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    return data


def _numbers(path: Path, key: str, value, n: int) -> np.ndarray:
    if value is None:
        raise ConfigError(f"{path}: missing key '{key}'")
    if isinstance(value, dict) and "data" in value:  # OpenCV matrix node {rows, cols, dt, data}
        value = value["data"]
    if not isinstance(value, (list, tuple)):
        raise ConfigError(f"{path}: '{key}' must be a list of {n} numbers, got {value!r}")
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError(f"{path}: '{key}' must contain numbers only, got {value!r}") from None
    if arr.size != n:
        raise ConfigError(f"{path}: '{key}' must have {n} values, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{path}: '{key}' contains NaN or infinite values")
    return arr


def _box_from_node(path: Path, name: str, node) -> OrientedBox:
    if not isinstance(node, dict):
        raise ConfigError(f"{path}: '{name}' must be a mapping with center, R_flat and extent")
    for key in ("center", "R_flat", "extent"):
        if key not in node:
            raise ConfigError(f"{path}: missing key '{name}.{key}'")
    center = _numbers(path, f"{name}.center", node["center"], 3)
    r_flat = _numbers(path, f"{name}.R_flat", node["R_flat"], 9)
    extent = _numbers(path, f"{name}.extent", node["extent"], 3)
    if np.any(extent <= 0):
        raise ConfigError(f"{path}: '{name}.extent' must be positive lengths, got {extent.tolist()}")
    rotation = _as_rotation(r_flat.reshape(3, 3), f"{path}: '{name}.R_flat'")
    return OrientedBox(center, rotation, extent)


def read_bbx_config(path, keys: tuple[str, ...] = ("plant_box", "view_box")) -> dict[str, OrientedBox]:
    """Read an OpenCV-style box configuration (``roomN_bbx_config.yaml``).

    Each of ``keys`` must be a mapping with ``center`` (3), ``R_flat`` (row-major 3x3 rotation whose
    columns are the box axes) and ``extent`` (3 full side lengths, metres). Returns ``{key: box}``.
    """
    path = Path(path)
    data = _load_opencv_yaml(path)
    boxes = {}
    for key in keys:
        if key not in data:
            raise ConfigError(f"{path}: missing key '{key}'")
        boxes[key] = _box_from_node(path, key, data[key])
    return boxes


# ----------------------------------------------------------------------------- text files
def _load_table(path: Path, columns: int, rows: int | None = None) -> np.ndarray:
    if not path.is_file():
        raise InputFileError(f"{path}: file not found")
    try:
        arr = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise InputFileError(f"{path}: not a table of numbers ({exc})") from None
    if arr.size == 0:
        raise InputFileError(f"{path}: file is empty")
    if arr.shape[1] != columns:
        raise InputFileError(f"{path}: expected {columns} columns, got {arr.shape[1]}")
    if rows is not None and arr.shape[0] != rows:
        raise InputFileError(f"{path}: expected {rows} rows, got {arr.shape[0]}")
    if not np.all(np.isfinite(arr)):
        raise InputFileError(f"{path}: contains NaN or infinite values")
    return arr


def _load_scalar(path: Path) -> float:
    if not path.is_file():
        raise InputFileError(f"{path}: file not found")
    try:
        values = path.read_text(encoding="utf-8").split()
        value = float(values[0]) if len(values) == 1 else None
    except (OSError, UnicodeDecodeError, ValueError):
        value = None
    if value is None or not np.isfinite(value):
        raise InputFileError(f"{path}: expected a single number")
    return value


def _check_room(room) -> str:
    if room not in ROOMS:
        raise ConfigError(f"room must be one of {', '.join(ROOMS)}, got {room!r}")
    return room


def _data_dir(data_dir) -> Path:
    d = Path(data_dir) if data_dir is not None else DATA_DIR
    if not d.is_dir():
        raise InputFileError(f"{d}: greenhouse-row configuration folder not found")
    return d


@dataclass(frozen=True, eq=False)
class RoomConfig:
    """Configuration of one real greenhouse row (the authors' simulator inputs).

    ``initial_positions``/``initial_look_ats`` are the 15 fixed passive-sweep views, ``passive_cost``
    the path length (m) of that sweep, ``rand_look_at_points`` the 100 PriorOBB look-at targets.
    """

    room: str
    plant_box: OrientedBox
    view_box: OrientedBox
    candidate_positions: np.ndarray  # (1000, 3)
    initial_positions: np.ndarray  # (15, 3)
    initial_look_ats: np.ndarray  # (15, 3)
    passive_cost: float
    rand_look_at_points: np.ndarray  # (100, 3)
    folder: Path

    @property
    def initial_views(self) -> np.ndarray:
        """The passive views as ``(15, 6)`` rows ``px py pz lx ly lz``."""
        return np.hstack([self.initial_positions, self.initial_look_ats])


def room_config(room: str = "room1", data_dir=None) -> RoomConfig:
    """Load the bundled configuration of ``room`` ("room1" or "room4").

    ``data_dir`` overrides the folder (same file names as the authors' ``Environment_Config``).
    """
    _check_room(room)
    return _room_config_cached(room, str(_data_dir(data_dir)))


@lru_cache(maxsize=8)
def _room_config_cached(room: str, folder: str) -> RoomConfig:
    d = Path(folder)
    boxes = read_bbx_config(d / f"{room}_bbx_config.yaml")
    candidates = _load_table(d / f"{room}_candidate_views.txt", 3)
    initial = _load_table(d / f"{room}_initial_views.txt", 6)
    look_ats = _load_table(d / f"{room}_rand_look_at_pts.txt", 3)
    cost = _load_scalar(d / f"{room}_passive_cost.txt")
    ro = lambda a: _frozen(a)  # noqa: E731
    return RoomConfig(
        room=room,
        plant_box=boxes["plant_box"],
        view_box=boxes["view_box"],
        candidate_positions=ro(candidates),
        initial_positions=ro(initial[:, :3]),
        initial_look_ats=ro(initial[:, 3:]),
        passive_cost=cost,
        rand_look_at_points=ro(look_ats),
        folder=d,
    )


def candidate_look_ats(room: str, date: str, prior: str, data_dir=None) -> np.ndarray:
    """Look-at target assigned to each candidate position by the authors (``gap_1`` files).

    Returns ``(n_candidates, 3)``; an all-zero row means the position is unused. ``date`` is a
    session date ``YYYYMMDD`` after the first (20250918, 20250922, 20250925, 20250929); ``prior`` is
    one of ``PriorBBX``, ``PriorPassive``, ``PriorTemporal``.
    """
    _check_room(room)
    if prior not in LOOK_AT_PRIORS:
        raise ConfigError(f"prior must be one of {', '.join(LOOK_AT_PRIORS)}, got {prior!r}")
    date = str(date)
    if not re.fullmatch(r"\d{8}", date):
        raise ConfigError(f"date must be YYYYMMDD, got {date!r}")
    d = _data_dir(data_dir)
    path = d / "gap_1" / f"{room}_{date}_candidate_look_ats_{prior}.txt"
    if not path.is_file():
        available = sorted({p.name.split("_")[1] for p in (d / "gap_1").glob(f"{room}_*_{prior}.txt")})
        raise InputFileError(f"{path}: file not found (dates available for {room}: {', '.join(available) or 'none'})")
    n = room_config(room, data_dir).candidate_positions.shape[0]
    return _load_table(path, 3, rows=n)
