"""Robot-facing plan files: the ordered 6D views (position, look-at, orientation quaternion)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.io.atomic import atomic_write_text

CAMERA_AXES = "x right, y down, z forward (OpenCV)"


def plan_table(positions, look_ats, quaternions, roles=None) -> pd.DataFrame:
    """One row per view in execution order: step, role, position, look-at, quaternion (x y z w).

    The quaternion rotates camera coordinates (OpenCV: x right, y down, z forward) into the frame
    of the positions.
    """
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
