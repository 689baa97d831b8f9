"""Robot-facing plan files: the ordered 6D views (position, look-at, orientation quaternion)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.io.atomic import atomic_write_text
from tpvp.sensor.camera import look_at_rotation, rotation_to_quaternion


def plan_table(positions, look_ats, roles=None) -> pd.DataFrame:
    """One row per view in execution order: step, role, position, look-at, quaternion (x y z w).

    The quaternion rotates camera coordinates (OpenCV: x right, y down, z forward) into the world
    frame; the roll is fixed by the world +Z axis.
    """
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    look_ats = np.broadcast_to(np.asarray(look_ats, dtype=np.float64).reshape(-1, 3), positions.shape)
    quats = np.array([rotation_to_quaternion(look_at_rotation(p, t)) for p, t in zip(positions, look_ats)])
    table = pd.DataFrame({
        "step": np.arange(len(positions)),
        "role": list(roles) if roles is not None else ["planned"] * len(positions),
        "x": positions[:, 0], "y": positions[:, 1], "z": positions[:, 2],
        "look_x": look_ats[:, 0], "look_y": look_ats[:, 1], "look_z": look_ats[:, 2],
    })
    for i, axis in enumerate("xyzw"):
        table[f"q{axis}"] = quats[:, i] if len(quats) else []
    return table


def write_plan(folder, table: pd.DataFrame, frame: str, stem: str = "plan") -> tuple[Path, Path]:
    """Write the plan as ``<stem>.csv`` and ``<stem>.json`` (atomic writes)."""
    folder = Path(folder)
    csv_path = atomic_write_text(folder / f"{stem}.csv", table.to_csv(index=False, float_format="%.6f"))
    payload = {"frame": frame, "units": "m", "quaternion_order": "x y z w",
               "camera_axes": "x right, y down, z forward (OpenCV)",
               "views": json.loads(table.to_json(orient="records", double_precision=6))}
    json_path = atomic_write_text(folder / f"{stem}.json", json.dumps(payload, indent=2) + "\n")
    return csv_path, json_path
