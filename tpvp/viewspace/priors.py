"""Look-at priors of the greenhouse planner, chosen by name from :data:`LOOK_AT_PRIORS`
(docs/greenhouse.md#look-at-candidates).

A prior turns what is known before planning (:class:`PriorContext`) into 6D candidate views of the
room's candidate positions: ``obb``, ``passive`` and ``transfer`` (the paper's ladder,
:data:`PRIORS`) place ``targets.count`` look-at targets and give each ``targets.rounds`` views by
round robin; ``authors-<prior>`` reads the authors' own assignment of that prior for the session's
date (the bundled ``gap_1`` files, made on the real rows). A new prior is one function plus one
``@LOOK_AT_PRIORS.register`` line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tpvp.errors import ConfigError
from tpvp.registry import Registry
from tpvp.scene.boxes import candidate_look_ats
from tpvp.viewspace.lookat import (PRIORS, CandidateViews, assigned_views, box_targets, passive_targets,
                                   round_robin_views, transfer_targets)

LOOK_AT_PRIORS = Registry("look-at prior")
AUTHORS_PRIORS = {"obb": "PriorBBX", "passive": "PriorPassive", "transfer": "PriorTemporal"}  # their file names


@dataclass(frozen=True, eq=False)
class PriorContext:
    """What a prior may know: the room (``tpvp.scene.boxes.RoomConfig``: boxes, candidate
    positions, the authors' targets and files), the passive reconstruction Q (``coarse``, voxel
    centres) with the passive camera that saw each of its points first, the voxel of the surface
    analysis, and, once registered, the previous session aligned onto Q (``warped``) with its
    inflation voxels; ``date`` (YYYYMMDD) of the current session when known."""

    room: object
    coarse: np.ndarray
    passive_cameras: np.ndarray
    voxel: float
    warped: np.ndarray | None = None
    inflation: np.ndarray | None = None
    date: str | None = None


def candidate_views(prior: str, context: PriorContext, targets, seed: int = 0) -> CandidateViews:
    """The candidate views of ``prior``; ``targets`` holds ``count`` and ``rounds``
    (``tpvp.viewspace.config.RowTargetsConfig``)."""
    return LOOK_AT_PRIORS.get(prior)(context, targets, seed)


def _round_robin(points, context: PriorContext, targets, seed: int, prior: str) -> CandidateViews:
    return round_robin_views(points, context.room.candidate_positions, targets.rounds, seed, prior)


@LOOK_AT_PRIORS.register("obb", "PriorOBB: targets spread in the plant box (the room's own 100 when it has them)")
def obb(context: PriorContext, targets, seed: int) -> CandidateViews:
    room = context.room
    points = (np.asarray(room.rand_look_at_points) if len(room.rand_look_at_points) == targets.count
              else box_targets(room.plant_box, targets.count, seed))
    return _round_robin(points, context, targets, seed, "obb")


@LOOK_AT_PRIORS.register("passive", "PriorPassive: surface frontiers of the passive reconstruction")
def passive(context: PriorContext, targets, seed: int) -> CandidateViews:
    points = passive_targets(context.passive_cameras, context.coarse, context.voxel, targets.count, seed,
                             box=context.room.plant_box)
    return _round_robin(points, context, targets, seed, "passive")


@LOOK_AT_PRIORS.register("transfer", "PriorTransfer: the transferred surface the passive sweep missed")
def transfer(context: PriorContext, targets, seed: int) -> CandidateViews:
    if context.warped is None:
        raise ConfigError("the transfer prior needs the registered previous session (row_transfer)")
    points = transfer_targets(context.warped, context.coarse, context.inflation, context.voxel, targets.count, seed)
    return _round_robin(points, context, targets, seed, "transfer")


def _authors(prior: str):
    def authors(context: PriorContext, targets, seed: int) -> CandidateViews:
        name = f"authors-{prior}"
        if context.date is None:
            raise ConfigError(f"the {name} candidates need the session's date (build_row_scene(..., date=))")
        room = context.room
        table = candidate_look_ats(room.room, context.date, AUTHORS_PRIORS[prior], room.folder)
        return assigned_views(room.candidate_positions, table, name)
    return authors


for _prior in PRIORS:
    LOOK_AT_PRIORS.register(f"authors-{_prior}", f"the authors' {AUTHORS_PRIORS[_prior]} look-ats of the "
                                                 f"session's date (gap_1 files)")(_authors(_prior))
