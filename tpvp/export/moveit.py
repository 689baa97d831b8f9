"""A plan as MoveIt pose goals (YAML): the camera's pose at every view, in execution order, in the
robot's base frame (the plan moved by the base-from-scan transform, :func:`tpvp.export.poses.moved_plan`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import yaml

from tpvp.export.poses import moved_plan
from tpvp.io.plan import CAMERA_AXES

if TYPE_CHECKING:
    import pandas as pd


def moveit_goals(table: pd.DataFrame, frame: str, matrix: np.ndarray, source: str) -> str:
    """MoveIt pose goals (YAML): the camera pose of every view in execution order in ``frame``,
    the transform used and the camera axes."""
    goals = [{"step": int(row.step), "role": str(row.role),
              "position": {"x": float(row.x), "y": float(row.y), "z": float(row.z)},
              "orientation": {"x": float(row.qx), "y": float(row.qy), "z": float(row.qz), "w": float(row.qw)}}
             for row in moved_plan(table, matrix).itertuples()]
    document = {"frame_id": frame, "units": "m", "camera_axes": CAMERA_AXES, "source": source,
                "base_from_scan": matrix.tolist(), "pose_goals": goals}
    return ("# tpvp plan as MoveIt pose goals: the camera's pose at each view, in execution order\n"
            + yaml.safe_dump(document, sort_keys=False, default_flow_style=None, width=120))
