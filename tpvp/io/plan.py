"""Robot-facing plan files: the ordered 6D views (position, look-at, orientation quaternion),
written (:func:`write_plan`) and read back with one clear error for anything else
(:func:`read_plan`; :func:`read_plan_values` without pandas, for a session step that only checks
its plan)."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from tpvp.errors import InputFileError
from tpvp.io.atomic import atomic_write_text

if TYPE_CHECKING:
    import pandas as pd

CAMERA_AXES = "x right, y down, z forward (OpenCV)"
PLAN_COLUMNS = ("step", "role", "x", "y", "z", "look_x", "look_y", "look_z", "qx", "qy", "qz", "qw")
#: The plan's columns that hold numbers (every one but ``role``), step first and the quaternion last.
NUMBER_COLUMNS = tuple(name for name in PLAN_COLUMNS if name != "role")
#: How far a plan's quaternion may be from a unit one (a plan edited by hand, rounded).
QUATERNION_TOLERANCE = 1e-2
PLAN_ADVICE = "correct it, or write the plan again (tpvp plan, tpvp session plan)"
NOT_A_PLAN = "give a plan.csv written by tpvp plan or tpvp session plan"


def plan_table(positions, look_ats, quaternions, roles=None) -> pd.DataFrame:
    """One row per view in execution order: step, role, position, look-at, quaternion (x y z w).

    The quaternion rotates camera coordinates (OpenCV: x right, y down, z forward) into the frame
    of the positions.
    """
    import pandas as pd  # not for a session step that only checks its plan

    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    look_ats = np.broadcast_to(np.asarray(look_ats, dtype=np.float64).reshape(-1, 3), positions.shape)
    quaternions = np.asarray(quaternions, dtype=np.float64).reshape(-1, 4)
    table = pd.DataFrame({
        "step": np.arange(len(positions)),
        "role": list(roles) if roles is not None else ["planned"] * len(positions),
        "x": positions[:, 0], "y": positions[:, 1], "z": positions[:, 2],
        "look_x": look_ats[:, 0], "look_y": look_ats[:, 1], "look_z": look_ats[:, 2],
    })
    for i, axis in enumerate("xyzw"):
        table[f"q{axis}"] = quaternions[:, i]
    return table


def plan_csv(table: pd.DataFrame, frame: str) -> str:
    """CSV text with one header line naming frame, units and conventions (read back with
    ``pandas.read_csv(path, comment="#")``); full float precision."""
    header = f"# frame: {frame}; units: m; quaternion: x y z w, camera axes {CAMERA_AXES}\n"
    return header + table.to_csv(index=False, float_format="%.12g")


def write_plan(folder, tables: dict, frames: dict, extra: dict | None = None, stem: str = "plan") -> dict:
    """Write each frame's plan as ``<stem>.csv`` / ``<stem>_<frame>.csv`` and all of them, the
    frames and ``extra`` (e.g. the transform between frames) in ``<stem>.json`` (atomic writes).

    ``tables``: frame name -> :func:`plan_table`, the first one is the main frame; ``frames``:
    frame name -> description.
    """
    folder = Path(folder)
    written = {}
    for i, (name, table) in enumerate(tables.items()):
        file = folder / (f"{stem}.csv" if i == 0 else f"{stem}_{name}.csv")
        written[name] = atomic_write_text(file, plan_csv(table, frames[name]))
    payload = {"units": "m", "quaternion_order": "x y z w", "camera_axes": CAMERA_AXES,
               "frames": dict(frames), **(extra or {})}
    for i, (name, table) in enumerate(tables.items()):
        payload["views" if i == 0 else f"views_{name}"] = table.to_dict(orient="records")
    written["json"] = atomic_write_text(folder / f"{stem}.json", json.dumps(payload, indent=2, default=_plain) + "\n")
    return written


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def plan_file(path) -> Path:
    """The ``plan.csv`` that ``path`` names: itself, or the one in the folder ``path``."""
    path = Path(path)
    return path / "plan.csv" if path.is_dir() else path


class PlanFileError(InputFileError):
    """A plan file that is not a tpvp plan; ``fault`` is what is wrong, without the file's name or
    the advice (``tpvp session check`` words its own)."""

    def __init__(self, path, fault: str, advice: str = PLAN_ADVICE):
        super().__init__(f"{path}: {fault}; {advice}")
        self.path, self.fault = path, fault


def plan_values(text: str, path) -> tuple[list[str], list[list[str]], np.ndarray]:
    """``(columns, each view's fields, each view's numbers)`` of a ``plan.csv``'s text (the numbers:
    :data:`PLAN_COLUMNS` but ``role``, finite, as float64). A line's ``#`` starts a comment, as
    ``pandas.read_csv(comment="#")`` reads it. :class:`PlanFileError` names the line and the column
    of the first value that is not a finite number, a missing column, a plan without views."""
    lines = [(number, line.split("#", 1)[0]) for number, line in enumerate(text.splitlines(), 1)]
    lines = [(number, line) for number, line in lines if line.strip()]
    if not lines:
        raise PlanFileError(path, "empty: no header line (step,role,x,y,z,...)", NOT_A_PLAN)
    (header_line, header), rows = lines[0], lines[1:]
    columns = [name.strip() for name in next(csv.reader([header]))]
    missing = [name for name in PLAN_COLUMNS if name not in columns]
    if missing:
        raise PlanFileError(path, f"not a tpvp plan: its header (line {header_line}) has no column "
                                  f"{', '.join(missing)}", NOT_A_PLAN)
    twice = sorted({name for name in columns if columns.count(name) > 1})
    if twice:
        raise PlanFileError(path, f"its header (line {header_line}) names the column {twice[0]!r} twice", NOT_A_PLAN)
    if not rows:
        raise PlanFileError(path, f"the plan has no views (nothing after its header, line {header_line})", NOT_A_PLAN)
    where = [columns.index(name) for name in NUMBER_COLUMNS]
    fields, numbers = [], np.empty((len(rows), len(NUMBER_COLUMNS)))
    for row, (number, line) in enumerate(rows):
        values = next(csv.reader([line]))
        if len(values) != len(columns):
            raise PlanFileError(path, f"line {number} has {len(values)} values, its header (line {header_line}) "
                                      f"{len(columns)} columns (truncated?)")
        for column, (name, at) in enumerate(zip(NUMBER_COLUMNS, where)):
            value = values[at].strip()
            try:
                numbers[row, column] = float(value)
            except ValueError:
                what = f"{value!r} is not a number" if value else "no value"
                raise PlanFileError(path, f"line {number}, column {name!r}: {what}") from None
            if not np.isfinite(numbers[row, column]):
                raise PlanFileError(path, f"line {number}, column {name!r}: {value} is not a finite number")
        if not numbers[row, 0].is_integer():
            raise PlanFileError(path, f"line {number}, column 'step': {values[where[0]].strip()} is not a whole number")
        norm = np.linalg.norm(numbers[row, -4:])
        # A rotation's quaternion is a unit one; one far off it is a wrong value, not rounding.
        if abs(norm - 1) > QUATERNION_TOLERANCE:
            raise PlanFileError(path, f"line {number}, columns qx, qy, qz, qw: the quaternion's norm is {norm:.3g}, "
                                      f"not 1")
        fields.append(values)
    return columns, fields, numbers


def read_plan_values(path) -> tuple[list[str], list[list[str]], np.ndarray]:
    """:func:`plan_values` of the ``plan.csv`` that ``path`` names (itself, or the one in the folder)."""
    path = plan_file(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such plan (a plan.csv written by tpvp plan or tpvp session plan)")
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read the plan ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise PlanFileError(path, f"not text (byte {exc.object[exc.start]:#04x} at offset {exc.start})",
                            NOT_A_PLAN) from None
    return plan_values(text, path)


def read_plan(path) -> pd.DataFrame:
    """A plan written by ``tpvp plan`` / ``tpvp session plan`` (``plan.csv``, or the folder holding
    it), its views in execution order; one clear error for anything else (:func:`plan_values`)."""
    import pandas as pd  # not for a session step that only checks its plan

    columns, fields, numbers = read_plan_values(path)
    table = pd.DataFrame(fields, columns=columns)
    for column, name in enumerate(NUMBER_COLUMNS):
        table[name] = numbers[:, column]
    table["step"] = table["step"].astype(np.int64)
    return table
