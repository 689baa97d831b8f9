"""A plan in a robot's frame: ``plan.csv`` read back, moved by a rigid base-from-scan transform,
and written as MoveIt pose goals (YAML).

The plan's quaternion turns camera axes (OpenCV: x right, y down, z forward) into the plan's frame;
moved into the robot's base frame it turns them into the base frame. Which link carries the
camera, and its offset, is the robot's business: the goals are the camera's poses.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml

from tpvp.errors import InputFileError
from tpvp.sensor.camera import rigid_error, rotation_to_quaternion

if TYPE_CHECKING:
    import pandas as pd

PLAN_COLUMNS = ("step", "role", "x", "y", "z", "look_x", "look_y", "look_z", "qx", "qy", "qz", "qw")
#: The plan's columns that hold numbers (every one but ``role``), step first and the quaternion last.
NUMBER_COLUMNS = tuple(name for name in PLAN_COLUMNS if name != "role")
#: How far a plan's quaternion may be from a unit one (a plan edited by hand, rounded).
QUATERNION_TOLERANCE = 1e-2
PLAN_ADVICE = "correct it, or write the plan again (tpvp plan, tpvp session plan)"
NOT_A_PLAN = "give a plan.csv written by tpvp plan or tpvp session plan"
#: How far a transform's rotation may be from a proper rotation (orthonormal, determinant +1).
RIGID_TOLERANCE = 1e-6


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


def read_transform(path) -> np.ndarray:
    """A rigid 4x4 transform from a JSON or YAML file: the matrix itself (4 rows of 4), or a
    mapping with it under ``matrix``; one clear error naming the file when it is not rigid."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())  # JSON is YAML
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read the transform ({exc.strerror or exc})") from None
    except yaml.YAMLError as exc:
        raise InputFileError(f"{path}: not JSON or YAML ({str(exc).splitlines()[0]})") from None
    if isinstance(data, dict):
        data = data.get("matrix")
    try:
        matrix = np.asarray(data, dtype=np.float64)
    except (TypeError, ValueError):
        matrix = np.zeros(0)
    if matrix.shape != (4, 4) or not np.isfinite(matrix).all():
        raise InputFileError(f"{path}: a transform is a 4x4 matrix of numbers (or a mapping with it under "
                             f"'matrix'), got {json.dumps(data)[:80]}")
    error = rigid_error(matrix)
    if error > RIGID_TOLERANCE:
        raise InputFileError(f"{path}: not a rigid transform (its rotation is off a proper rotation by {error:.3g}, "
                             f"or its last row is not 0 0 0 1): a scaled or sheared matrix would move the views "
                             f"off their plant; give the base-from-scan pose in metres")
    return matrix


def quaternion_to_rotation(q) -> np.ndarray:
    """The rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def moved_plan(table: pd.DataFrame, matrix: np.ndarray) -> pd.DataFrame:
    """The plan's views moved by the rigid ``matrix`` (positions, look-ats and orientations)."""
    rotation, translation = matrix[:3, :3], matrix[:3, 3]
    moved = table.copy()
    for columns in (["x", "y", "z"], ["look_x", "look_y", "look_z"]):
        moved[columns] = table[columns].to_numpy(dtype=np.float64) @ rotation.T + translation
    quaternions = [rotation_to_quaternion(rotation @ quaternion_to_rotation(q))
                   for q in table[["qx", "qy", "qz", "qw"]].to_numpy(dtype=np.float64)]
    moved[["qx", "qy", "qz", "qw"]] = np.asarray(quaternions).reshape(-1, 4)
    return moved


def plan_poses(table: pd.DataFrame) -> np.ndarray:
    """The plan's camera-to-world poses in execution order, ``(V, 4, 4)`` (OpenCV camera axes)."""
    poses = np.tile(np.eye(4), (len(table), 1, 1))
    poses[:, :3, 3] = table[["x", "y", "z"]].to_numpy(dtype=np.float64)
    poses[:, :3, :3] = [quaternion_to_rotation(q) for q in table[["qx", "qy", "qz", "qw"]].to_numpy(dtype=np.float64)]
    return poses


def moveit_goals(table: pd.DataFrame, frame: str, matrix: np.ndarray, source: str) -> str:
    """MoveIt pose goals (YAML): the camera pose of every view in execution order in ``frame``,
    the transform used and the camera axes."""
    goals = [{"step": int(row.step), "role": str(row.role),
              "position": {"x": float(row.x), "y": float(row.y), "z": float(row.z)},
              "orientation": {"x": float(row.qx), "y": float(row.qy), "z": float(row.qz), "w": float(row.qw)}}
             for row in moved_plan(table, matrix).itertuples()]
    from tpvp.io.plan import CAMERA_AXES  # pandas: not for a session step that only checks its plan

    document = {"frame_id": frame, "units": "m", "camera_axes": CAMERA_AXES, "source": source,
                "base_from_scan": matrix.tolist(), "pose_goals": goals}
    return ("# tpvp plan as MoveIt pose goals: the camera's pose at each view, in execution order\n"
            + yaml.safe_dump(document, sort_keys=False, default_flow_style=None, width=120))
