"""The greenhouse-row cases: a consecutive session pair of one row, generated or read from a cleaned
dataset folder, and the coarse configuration of ``--quick``. ``tpvp greenhouse`` runs one of them
(:func:`tpvp.simulate.greenhouse.run_row_case`); the row experiments (:mod:`tpvp.experiments.rows`)
run the paper's eight.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from tpvp.config import RowConfig
from tpvp.config_loading import make_config
from tpvp.errors import InputFileError
from tpvp.io import read_point_cloud
from tpvp.scene.boxes import ROOMS, room_config
from tpvp.synthetic.greenhouse import DATES, generate_row_sessions
from tpvp.synthetic.scan import reference_points

SESSIONS = 5
# --quick: a 2 cm ground truth (the oracle grid and the inflation voxels follow their rules: 0.2 m,
# 2 cm), two covering voxels, fewer budgets and draws.
QUICK = {"gt_resolution": 0.02, "protocol.cover_resolutions": (0.10, 0.05), "protocol.budgets": (100, 300),
         "protocol.repetitions": 2, "protocol.nbv_budgets": (50, 100), "pose_noise.draws": 1,
         "pose_noise.cover_resolution": 0.10, "pose_noise.levels": ((0.0, 0.0), (0.01, 2.0))}
SESSION_FILE = re.compile(r"^(?P<room>room\d+)_(?P<date>20\d{6})\.(pcd|ply)$")


@dataclass(frozen=True)
class RowCase:
    """Sessions ``previous`` -> ``previous + 1`` of a row: generated (``seed``) or files of a
    cleaned dataset (``files``)."""

    room: str
    previous: int
    seed: int = 0
    files: tuple = ()  # (previous file, current file) of a dataset; empty for a generated row
    point_spacing: float = 0.004
    reference: str = "handheld"  # what of a generated row the reference holds (tpvp.synthetic.scan.REFERENCES)

    @property
    def source(self) -> str:
        return "dataset" if self.files else "generated"

    @property
    def name(self) -> str:
        if self.files:
            return f"{Path(self.files[0]).stem} -> {Path(self.files[1]).stem}"
        return f"{self.room} seed {self.seed} sessions {self.previous}->{self.previous + 1}"

    def labels(self) -> dict:
        return {"source": self.source, "reference": "dataset" if self.files else self.reference, "room": self.room,
                "case": self.name, "previous_session": self.previous}

    def config(self, base: RowConfig) -> RowConfig:
        """``base`` in this case's room."""
        return replace(base, view_space=self.room)

    @property
    def date(self) -> str | None:
        """YYYYMMDD of the current session (a generated session k stands for the dataset's k-th date)."""
        if self.files:
            match = SESSION_FILE.match(Path(self.files[1]).name)
            return match["date"] if match else None
        return DATES[self.previous + 1]

    def load(self) -> tuple[np.ndarray, np.ndarray]:
        if self.files:
            return tuple(read_point_cloud(Path(f), units="m") for f in self.files)
        pair = _generated_pair(self.room, self.seed, self.previous, self.point_spacing, self.reference)
        return tuple(points.copy() for points in pair)  # the cached arrays stay as computed


@functools.lru_cache(maxsize=4)
def _generated_pair(room: str, seed: int, previous: int, spacing: float, reference: str) -> tuple:
    """Generated sessions ``previous`` and ``previous + 1`` as the reference holds them, computed once
    per process: the handheld reference ray-casts each session from every keyframe (2 s a session)."""
    sessions = generate_row_sessions(room, seed, previous + 2, spacing)
    return tuple(reference_points(sessions[k].points, room_config(room), reference) for k in (previous, previous + 1))


def dataset_cases(folder, rooms=ROOMS) -> list[RowCase]:
    """Consecutive session pairs of every room in a dataset written by ``python -m data_tools
    greenhouse clean`` (``Processed_3D_Model/<room>_<YYYYMMDD>.pcd``)."""
    folder = Path(folder)
    models = folder / "Processed_3D_Model"
    if not models.is_dir():
        raise InputFileError(f"{folder}: no Processed_3D_Model/ folder - write one with "
                             f"'python -m data_tools greenhouse clean SOURCE --output {folder}'")
    sessions = {}
    for path in sorted(models.iterdir()):
        match = SESSION_FILE.match(path.name)
        if match and match["room"] in rooms:
            sessions.setdefault(match["room"], []).append(path)
    cases = [RowCase(room, i, files=(str(a), str(b))) for room, paths in sorted(sessions.items())
             for i, (a, b) in enumerate(zip(paths[:-1], paths[1:]))]
    if not cases:
        raise InputFileError(f"{models}: no two sessions of one room (files <room>_<YYYYMMDD>.pcd of "
                             f"{', '.join(rooms)}): nothing to pair")
    return cases


def default_row_cases(quick: bool = False, dataset=None, rooms=ROOMS, seed: int = 0,
                      references=("handheld",)) -> list[RowCase]:
    """The paper's 8 cases (4 consecutive pairs of each room) per reference of a generated row
    (``references``; a dataset's rows are used as they are), or the first pair of each in quick mode."""
    if dataset is not None:
        cases = dataset_cases(dataset, rooms)
        return cases[:1] if quick else cases
    pairs = [(room, k) for room in rooms for k in range(SESSIONS - 1)][:1 if quick else None]
    return [RowCase(room, k, seed, reference=reference) for reference in references for room, k in pairs]


def quick_config(overrides: dict | None = None) -> RowConfig:
    """A coarse configuration for CI and quick notebooks (:data:`QUICK`), then ``overrides``."""
    return make_config("row", QUICK | dict(overrides or {}))
