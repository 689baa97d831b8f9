"""One individual-plant case of the paper, end to end in the simulator.

The simulator (:mod:`tpvp.simulate.world`) renders the initial view and the warm-up NBVs on
today's ground truth; the planner (:mod:`tpvp.pipeline.plan`) plans from what they observed and
what the robot knew before (:func:`known`: never the ground truth); the plan is then executed on
the ground truth and its coverage measured against the oracle set.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from scipy import sparse

from tpvp.config import PlantConfig
from tpvp.nbv.methods import start_nbv
from tpvp.nbv.warm_up import warm_up
from tpvp.pipeline.plan import PlanResult, Known, PlanningSurface, Transfer, plan, planning_surface
from tpvp.pipeline.plan import transfer as transfer_known
from tpvp.pipeline.replan import prediction_of, replan
from tpvp.scene.organs import organ_shares
from tpvp.simulate.world import Scene, build_scene  # noqa: F401 (callers build the case's scene here)
from tpvp.visibility import coverage_ratio, covered_voxels


def known(scene: Scene) -> Known:
    """What the robot knows of a simulated case before it plans: the scene without its ground truth."""
    return Known(scene.previous, scene.sensor, scene.names, scene.view_space, scene.plant_from_scan,
                 scene.table_points, scene.reduction or {}, scene.previous_organs)


def added_coverage(scene, executed) -> np.ndarray:
    """Per view: the oracle voxels it sees that none of ``executed`` sees (``(V,)`` int)."""
    truth = sparse.csr_matrix(scene.truth_visibility)
    new = np.zeros(truth.shape[1], dtype=bool)
    new[scene.oracle] = True
    for v in executed:
        new[truth.indices[truth.indptr[v]:truth.indptr[v + 1]]] = False
    return np.asarray(truth @ new.astype(np.int64)).ravel()


def rank_of(added: np.ndarray, executed, view: int) -> int:
    """1 + the number of non-executed candidates that add strictly more than ``view``."""
    candidates = np.ones(len(added), dtype=bool)
    candidates[list(executed)] = False
    return 1 + int((added[candidates] > added[view]).sum())


def transfer(scene: Scene, config: PlantConfig = PlantConfig(), progress=None) -> Transfer:
    """The initial view and the warm-up NBVs executed in the simulator, then the planner's
    registration of the previous session onto what they saw."""
    say = progress or (lambda stage: None)
    t = time.perf_counter()
    say("warm-up NBV")
    nbv = warm_up(scene, config)
    seconds = time.perf_counter() - t
    transferred = transfer_known(known(scene), config, nbv, progress)
    return replace(transferred, timings={"warm_up": seconds, **transferred.timings})


def run_case(scene: Scene, config: PlantConfig = PlantConfig(), progress=None,
             transferred: Transfer | None = None, surface: PlanningSurface | None = None,
             closing: bool = False) -> PlanResult:
    """Warm-up, transfer, plan and execute one case; ``progress(stage)`` is called per stage.
    ``transferred``: the :func:`transfer` of this scene and configuration when already computed
    (methods that differ only after registration share it); ``surface``: likewise its
    :func:`tpvp.pipeline.plan.planning_surface` (plans that differ only in the selection share it).
    ``closing``: a one-shot plan (``selection.replan_after`` 0) is re-planned once all its views
    are captured, and again after the views that adds, as a session does when asked to
    (``tpvp session plan`` at its end)."""
    transferred = transferred or transfer(scene, config, progress)
    surface = surface or planning_surface(known(scene), config, transferred, progress)
    result = plan(known(scene), config, transferred, progress, surface)
    if config.selection.replan_after or closing:
        result = execute_replanning(scene, config, transferred, result, surface, progress)
    executed, planned = result.executed_views, result.planned_views
    covered = covered_voxels(scene.truth_visibility, executed + planned)
    return replace(result, coverage=coverage_ratio(covered, scene.oracle),
                   coverage_captured=coverage_ratio(covered_voxels(scene.truth_visibility, executed), scene.oracle),
                   organ_coverage=organ_coverage(scene, covered))


def organ_coverage(scene: Scene, covered) -> dict:
    """Organ -> the true coverage of its oracle voxels (those some candidate view sees); empty when
    today's scan is not labelled."""
    if scene.voxel_organs is None:
        return {}
    shares = organ_shares(covered, scene.oracle, scene.voxel_organs)
    shares.pop("unknown", None)
    return shares


def execute_replanning(scene: Scene, config: PlantConfig, transferred: Transfer, result: PlanResult,
                       surface: PlanningSurface, progress=None) -> PlanResult:
    """Execute ``result``'s plan on the ground truth ``selection.replan_after`` views at a time (all
    that are left when it is 0), re-planning the rest from the captures after each batch
    (:func:`tpvp.pipeline.replan.replan`), until no view is left. The result holds every re-plan's
    row; its timings add the re-planning."""
    step = config.selection.replan_after or None
    nbv = start_nbv(scene, config)  # a copy of the warm-up's state: ``transferred`` may be shared
    for view, seen in zip(transferred.nbv.executed, transferred.nbv.observations):
        nbv.integrate(view, seen)
    warm_up_views, timings = len(result.executed_views), dict(result.timings)
    prediction, rows = prediction_of(surface, warm_up_views), []
    while left := result.planned_views[len(nbv.executed) - warm_up_views:]:
        for view in left[:step]:
            nbv.integrate(view, scene.observe(view, len(nbv.executed)))  # its place among the captures
        result, prediction, row = replan(known(scene), config, nbv, warm_up_views, result.planned_views, prediction,
                                         progress)
        rows.append(row)
    return replace(result, replans=tuple(rows),
                   timings={**timings, "replanning": sum(row.seconds for row in rows)})
