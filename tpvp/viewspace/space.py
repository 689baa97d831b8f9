"""View spaces as objects: candidate positions, their look-at targets and what goes with them.

A view space is chosen by name from :data:`VIEW_SPACES` (``hemisphere``, ``sphere``, ``room1``,
``room4``), by a pattern (``tammes:N``, ``tammes-hemisphere:N``) or by a file path (``x y z`` or
``x y z lx ly lz`` rows, an optional count line first). A user's own view space is one file, or
one function registered with ``@VIEW_SPACES.register("name")`` that returns a :class:`ViewSpace`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from tpvp.errors import ConfigError, InputFileError
from tpvp.registry import Registry
from tpvp.scene.boxes import ROOMS, RoomConfig, room_config
from tpvp.sensor.config import ROW_RANGE
from tpvp.viewspace.tammes import generate_view_space

DATA = Path(__file__).resolve().parent.parent / "data" / "view_spaces"
BUNDLED = {"hemisphere": "view_space_hemisphere32.txt", "sphere": "view_space_sphere63.txt"}
# 0-based rows of the hemisphere file (docs/single_plant.md#initial-views): near-horizontal (7 deg),
# oblique (48 deg) and near-top (77 deg). The sphere file starts with the same 32 rows.
INITIAL_VIEW_INDICES = {"near_horizontal": 17, "oblique": 8, "near_top": 21}
PLANT_RADIUS = 0.4  # m, radius of the bundled single-plant view spheres
PLANT_RANGE = 1.0  # m, sensor range of the single-plant setting

VIEW_SPACES = Registry("view space")
#: What a row of a view-space file must look like (for messages).
VIEW_ROW = ("each row must be 3 numbers 'x y z' (a view looking at the origin) or 6 numbers 'x y z lx ly lz' "
            "(position and look-at point), in metres, after an optional count line")


@dataclass(frozen=True, eq=False)
class ViewSpace:
    """Candidate views: ``positions`` and ``look_ats`` ``(V, 3)`` in metres, plant frame.

    table: whether the setting has a supporting table under the plant (occluder, never counted).
    initial_views: named initial views (index into the positions). max_range: the sensor range (m)
    the view space is meant for. passive_views ``(P, 6)`` (position, look-at) and passive_cost (m):
    the fixed passive sweep of a greenhouse room (empty for plants). look_at_fixed: False when the
    planner chooses the look-ats (greenhouse rows), True when they belong to the view space.
    """

    name: str
    positions: np.ndarray
    look_ats: np.ndarray
    table: bool = False
    initial_views: dict = field(default_factory=dict)
    max_range: float = PLANT_RANGE
    passive_views: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    passive_cost: float = 0.0
    look_at_fixed: bool = True

    def __post_init__(self):
        positions = np.array(self.positions, dtype=np.float64).reshape(-1, 3)
        look_ats = np.array(np.broadcast_to(np.asarray(self.look_ats, dtype=np.float64).reshape(-1, 3),
                                            positions.shape))
        if len(positions) == 0:
            raise ConfigError(f"view space {self.name!r} has no views")
        if not (np.all(np.isfinite(positions)) and np.all(np.isfinite(look_ats))):
            raise ConfigError(f"view space {self.name!r} has NaN or infinite coordinates")
        same = np.flatnonzero(np.linalg.norm(positions - look_ats, axis=1) == 0)
        if len(same):
            raise ConfigError(f"view space {self.name!r}: view {same[0]} (counting from 0) looks at its own "
                              f"position {positions[same[0]].tolist()}: give it a look-at point elsewhere")
        for key, index in self.initial_views.items():
            if not 0 <= int(index) < len(positions):
                raise ConfigError(f"view space {self.name!r}: initial view {key!r} = {index} is out of range")
        for a in (positions, look_ats):
            a.flags.writeable = False
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "look_ats", look_ats)

    def __len__(self) -> int:
        return len(self.positions)

    @property
    def poses(self) -> np.ndarray:
        """``(V, 6)`` rows ``x y z lx ly lz``."""
        return np.hstack([self.positions, self.look_ats])

    def view_index(self, view: int | str) -> int:
        """A view given by index or by one of the named initial views; out of range is refused."""
        if isinstance(view, str) and not view.lstrip("-").isdigit():
            if view not in self.initial_views:
                raise ConfigError(f"initial view {view!r} is not one of {sorted(self.initial_views)} "
                                  f"of view space {self.name!r}")
            return int(self.initial_views[view])
        index = int(view)
        if not 0 <= index < len(self):
            raise ConfigError(f"initial_view {index} is not one of the {len(self)} views of view space "
                              f"{self.name!r} (0..{len(self) - 1})")
        return index

    def scaled(self, factor: float) -> "ViewSpace":
        """Positions and look-ats scaled about the origin (the plant centre), range included."""
        if not (np.isfinite(factor) and factor > 0):
            raise ConfigError(f"view-space scale factor must be > 0, got {factor!r}")
        return replace(self, positions=self.positions * factor, look_ats=self.look_ats * factor,
                       max_range=self.max_range * factor,
                       passive_views=self.passive_views * factor, passive_cost=self.passive_cost * factor)

    def with_radius(self, radius: float) -> "ViewSpace":
        """Positions moved onto a sphere of ``radius`` around their look-at (range kept)."""
        if not (np.isfinite(radius) and radius > 0):
            raise ConfigError(f"view-space radius must be > 0 m, got {radius!r}")
        offset = self.positions - self.look_ats
        return replace(self, positions=self.look_ats + offset / np.linalg.norm(offset, axis=1, keepdims=True) * radius)


def read_view_space_file(path, name: str | None = None) -> ViewSpace:
    """A view-space file: an optional count line, then ``x y z`` rows (look at the origin) or
    ``x y z lx ly lz`` rows. No table; the single-plant sensor range."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"view space {str(path)!r} is neither one of {', '.join(VIEW_SPACES.names())}, "
                             f"'tammes:N' nor an existing file")
    try:
        lines = [(number, line.split()) for number, line in enumerate(path.read_text().splitlines(), 1)
                 if line.strip() and not line.startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{path}: cannot read the view-space file ({exc})") from None
    declared = None
    if lines and len(lines[0][1]) == 1:
        (count_line, (declared,)), lines = lines[0], lines[1:]
        if not re.fullmatch(r"\d+", declared):
            raise InputFileError(f"{path}: line {count_line}: the count line must be a whole number of views, "
                                 f"got {declared!r}")
    if not lines:
        raise InputFileError(f"{path}: holds no views; {VIEW_ROW}")
    width = len(lines[0][1])
    for number, words in lines:
        try:
            [float(w) for w in words]
            bad = len(words) not in (3, 6) or len(words) != width
        except ValueError:
            bad = True
        if bad:
            text = " ".join(words)
            text = text if len(text) <= 40 else text[:37] + "..."
            also = "" if len(words) not in (3, 6) or width == len(words) else (
                f" (line {lines[0][0]} has {width} numbers: every row must have the same count)")
            raise InputFileError(f"{path}: line {number} is not a view: {text!r}{also}; {VIEW_ROW}")
    values = np.array([words for _, words in lines], dtype=np.float64)
    if declared is not None and int(declared) != len(values):
        raise InputFileError(f"{path}: first line declares {declared} views but {len(values)} follow")
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise InputFileError(f"{path}: line {lines[first][0]} (view {first}) has NaN or infinite coordinates; "
                             f"{VIEW_ROW}")
    look_ats = values[:, 3:] if values.shape[1] == 6 else np.zeros((len(values), 3))
    same = np.linalg.norm(values[:, :3] - look_ats, axis=1) == 0
    if same.any():
        first = int(np.flatnonzero(same)[0])
        where = "the origin" if values.shape[1] == 3 else "its own position"
        raise InputFileError(f"{path}: line {lines[first][0]} (view {first}, counting from 0) looks at "
                             f"{where}, where the camera is: move the view or give it a look-at point "
                             f"elsewhere ('x y z lx ly lz')")
    return ViewSpace(name or str(path), values[:, :3], look_ats)


@VIEW_SPACES.register("hemisphere", "the authors' 32 views on a 0.4 m hemisphere, with a table")
def hemisphere() -> ViewSpace:
    space = read_view_space_file(DATA / BUNDLED["hemisphere"], "hemisphere")
    return replace(space, table=True, initial_views=dict(INITIAL_VIEW_INDICES))


@VIEW_SPACES.register("sphere", "the authors' 63 views on a 0.4 m sphere (first 32 = hemisphere), no table")
def sphere() -> ViewSpace:
    space = read_view_space_file(DATA / BUNDLED["sphere"], "sphere")
    return replace(space, initial_views=dict(INITIAL_VIEW_INDICES))


def room_view_space(room: RoomConfig) -> ViewSpace:
    """The view space of a greenhouse room (``tpvp.scene.boxes.room_config``, where each room is
    defined): its candidate positions, its passive sweep and the rows' sensor range."""
    # The planner assigns look-at targets per session (docs/greenhouse.md); until then every
    # candidate looks at the plant box centre.
    return ViewSpace(room.room, room.candidate_positions, room.plant_box.center, max_range=ROW_RANGE,
                     passive_views=room.initial_views, passive_cost=room.passive_cost, look_at_fixed=False)


def _named_room(room: str):
    return lambda: room_view_space(room_config(room))


for _room in ROOMS:
    VIEW_SPACES.register(_room, f"greenhouse {_room}: 1,000 candidate positions, 15 passive views")(_named_room(_room))


def get_view_space(spec: str | Path) -> ViewSpace:
    """The view space named ``spec``: a registered name, ``tammes:N`` (N well-spread views on the
    0.4 m sphere), ``tammes-hemisphere:N`` (upper hemisphere, with a table) or a file path."""
    spec_text = str(spec)
    if spec_text in VIEW_SPACES:
        return VIEW_SPACES.get(spec_text)()
    match = re.fullmatch(r"tammes(-hemisphere)?:(\d+)", spec_text)
    if match:
        upper = bool(match.group(1))
        positions = generate_view_space(int(match.group(2)), radius=PLANT_RADIUS, hemisphere=upper)
        return ViewSpace(spec_text, positions, np.zeros(3), table=upper)
    if spec_text.startswith("tammes"):
        raise ConfigError(f"view space {spec_text!r}: write tammes:N or tammes-hemisphere:N with a view count N")
    return read_view_space_file(spec_text)


def view_space_choices() -> str:
    """One line listing the view-space choices (for help texts)."""
    return ", ".join(VIEW_SPACES.names()) + ", tammes:N, tammes-hemisphere:N or a file"
