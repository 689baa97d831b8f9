"""Re-planning a plant's plan from its captures (``selection.replan_after``).

A plan predicts what each of its views will see (:class:`Prediction`: the planning voxels and the
views x voxels visibility). After some of its views are captured, :func:`replan` compares the new
captures with that prediction. Where they agree (every voxel a captured view was to see was seen,
nothing seen that the prediction did not hold), the rest of the plan stands as it is. Where they
disagree, the planner starts again from everything captured so far: it registers the previous
model again onto all the captures, inflates and casts rays again, drops the predicted voxels that
the executed views should have seen and did not (the captures contradict them), and selects the
fewest further views for the planning target with the executed views fixed. The remaining plan is
kept when it still reaches the target and the new selection is not smaller; otherwise the new
views are ordered from the current pose. The simulation (:mod:`tpvp.simulate.single_plant`)
and a real session (:mod:`tpvp.session.plant`) call the same function with the same captures.
"""

from __future__ import annotations

import io
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy import sparse

from tpvp.path.local import obstacle_radius
from tpvp.path.route import path_along
from tpvp.path.tsp import PathResult
from tpvp.pipeline.plan import Known, plan, planning_surface, selection_problem, transfer
from tpvp.scene import voxels
from tpvp.setcover.methods import Selection, cover_requirement

#: A predicted voxel agrees with the captures when a captured point lies in it or in one of its 6
#: face neighbours (and a captured voxel with the prediction likewise): the two are quantised apart.
AGREEMENT_VOXELS = 1.0


@dataclass(frozen=True, eq=False)
class Prediction:
    """What a plan predicts the views see: the planning voxels' centres (planning frame, metres),
    their resolution and the (views x voxels) visibility."""

    centres: np.ndarray
    resolution: float
    visibility: sparse.csr_matrix
    views_so_far: int  # views executed when the plan was made

    def to_bytes(self) -> bytes:
        buffer = io.BytesIO()
        matrix = sparse.csr_matrix(self.visibility)
        np.savez_compressed(buffer, centres=self.centres, resolution=np.float64(self.resolution),
                            indptr=matrix.indptr, indices=matrix.indices, shape=np.asarray(matrix.shape),
                            views_so_far=np.int64(self.views_so_far))
        return buffer.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes) -> "Prediction":
        with np.load(io.BytesIO(data), allow_pickle=False) as f:
            matrix = sparse.csr_matrix((np.ones(len(f["indices"]), bool), f["indices"], f["indptr"]),
                                       shape=tuple(f["shape"]))
            return cls(f["centres"], float(f["resolution"]), matrix, int(f["views_so_far"]))


@dataclass(frozen=True)
class Replan:
    """One re-plan: the views executed when it ran, how the captures disagreed with the prediction
    (captured voxels it did not hold, predicted voxels the captured views did not see), the
    predicted coverage of the planning surface with the remaining views, the views added to and
    dropped from the remaining plan, the seconds it took, and the share of the planning surface
    the executed views see alone (NaN in rows written before it was recorded)."""

    views_so_far: int
    unexpected_voxels: int
    contradicted_voxels: int
    predicted_coverage: float
    remaining_before: int
    remaining_after: int
    views_added: int
    views_dropped: int
    seconds: float
    captured_coverage: float = float("nan")

    @property
    def changed(self) -> bool:
        return bool(self.views_added or self.views_dropped)

    def line(self) -> str:
        what = (f"+{self.views_added} / -{self.views_dropped} views" if self.changed else "the plan stands")
        return (f"after {self.views_so_far} views: {self.unexpected_voxels} unexpected, "
                f"{self.contradicted_voxels} contradicted voxels; {what}, {self.remaining_after} left, "
                f"{100 * self.predicted_coverage:.2f} % of the planning surface predicted ({self.seconds:.1f} s)")

    def row(self) -> dict:
        return {"views_so_far": self.views_so_far, "unexpected_voxels": self.unexpected_voxels,
                "contradicted_voxels": self.contradicted_voxels, "predicted_coverage": self.predicted_coverage,
                "remaining_before": self.remaining_before, "remaining_after": self.remaining_after,
                "views_added": self.views_added, "views_dropped": self.views_dropped, "seconds": self.seconds,
                "captured_coverage": self.captured_coverage}


def prediction_of(surface, views_so_far: int) -> Prediction:
    """The prediction of a :class:`~tpvp.pipeline.plan.PlanningSurface` planned with
    ``views_so_far`` views executed."""
    grid = surface.grid
    return Prediction(grid.centres, float(grid.resolution), sparse.csr_matrix(surface.visibility), int(views_so_far))


def _near(keys: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Which ``query`` keys lie within :data:`AGREEMENT_VOXELS` of a key of ``keys``."""
    if len(keys) == 0 or len(query) == 0:
        return np.zeros(len(query), dtype=bool)
    return voxels.contains_keys(voxels.dilate_keys(keys, AGREEMENT_VOXELS), query)


def disagreement(prediction: Prediction, views, observations, captured) -> tuple[int, int]:
    """(unexpected, contradicted): voxels of ``observations`` (the points ``views`` captured) that
    the prediction holds nothing near, and voxels the prediction says ``views`` see with no point
    of ``captured`` (every capture so far) near them. Both at the prediction's resolution."""
    resolution = prediction.resolution
    predicted = voxels.voxel_keys(prediction.centres, resolution)
    seen = _keys_of(list(observations), resolution)
    unexpected = int((~_near(predicted, seen)).sum())
    expected = np.unique(prediction.visibility[list(views)].indices) if len(views) else np.zeros(0, np.int64)
    return unexpected, int(_unconfirmed(predicted[expected], captured, resolution).sum())


def _keys_of(points, resolution: float) -> np.ndarray:
    """The distinct voxel keys of a list of point arrays (or one array)."""
    if isinstance(points, list):
        points = np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in points] or [np.zeros((0, 3))])
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return voxels.unique_keys(voxels.voxel_keys(points, resolution)) if len(points) else np.zeros((0, 3), np.int64)


def _unconfirmed(keys: np.ndarray, captured, resolution: float) -> np.ndarray:
    """Which predicted voxel ``keys`` have no point of ``captured`` near them."""
    return ~_near(_keys_of(captured, resolution), keys)


def contradicted_voxels(grid, visibility, executed, captured) -> np.ndarray:
    """Mask of the planning voxels some executed view should see (``visibility``) with no captured
    point near them: the captures contradict them."""
    expected = np.unique(sparse.csr_matrix(visibility)[list(executed)].indices)
    mask = np.zeros(grid.size, dtype=bool)
    mask[expected] = _unconfirmed(grid.keys[expected], captured, grid.resolution)
    return mask


def _reaches(problem, views) -> tuple[bool, float]:
    """Whether the executed views and ``views`` see the planning target of ``problem`` (as its
    selection counts it, :func:`~tpvp.setcover.methods.cover_requirement`), and the share they see."""
    matrix, weights, coverable, required = cover_requirement(problem)
    seen = np.zeros(matrix.shape[1], dtype=bool)
    rows = [*problem.executed, *views]
    if rows:
        seen[matrix[rows].indices] = True
    total, covered = float(weights[coverable].sum()), float(weights[seen & coverable].sum())
    share = covered / total if total else 1.0
    if problem.planning_target >= 1.0:
        return bool(np.all(seen[coverable])), share
    return covered >= required - 1e-9, share


def replan(known: Known, config, nbv, warm_up: int, planned, prediction: Prediction, progress=None):
    """Re-plan the rest of ``planned`` (the plan's views in order, after ``warm_up`` warm-up views)
    from every capture ``nbv`` holds (the warm-up's, then the planned views'). Returns the new
    :class:`~tpvp.pipeline.plan.PlanResult` (its executed views: the warm-up; its planned views:
    those captured, in capture order, then the remaining ones), its :class:`Prediction` and the
    :class:`Replan` row. With captures that agree with ``prediction`` the remaining plan stands."""
    started = time.perf_counter()
    executed = [int(v) for v in nbv.executed]
    remaining = [int(v) for v in planned if int(v) not in set(executed)]
    new = range(prediction.views_so_far, len(executed))  # captured since the prediction
    captured = np.concatenate(nbv.observations)
    unexpected, contradicted = disagreement(prediction, [executed[i] for i in new],
                                            [nbv.observations[i] for i in new], captured)
    agree = unexpected == 0 and contradicted == 0
    transferred = replace(transfer(known, config, nbv, progress), executed=executed)
    surface = planning_surface(known, config, transferred, progress)
    if not agree:  # the captures show where the prediction is wrong: its voxels there are dropped
        visible = sparse.csr_matrix(surface.visibility, dtype=bool, copy=True)
        visible.data &= ~contradicted_voxels(surface.grid, visible, executed, captured)[visible.indices]
        visible.eliminate_zeros()
        surface = replace(surface, visibility=visible)
    result = plan(known, config, transferred, progress, surface)
    problem = selection_problem(known, config, transferred, surface)
    reaches, _ = _reaches(problem, remaining)
    if agree or (reaches and len(remaining) <= len(result.planned_views)):
        length = path_along(known.view_space.positions[executed + remaining],
                            obstacle_radius(transferred.coarse, np.zeros(3)))
        kept = Selection(np.sort(np.asarray(remaining, dtype=np.int64)), False,
                         "kept: the remaining plan " + ("agrees with the captures" if agree
                                                        else "still reaches the planning target"), 0.0)
        result = replace(result, planned_views=remaining, path_length=length, selection=kept,
                         path=PathResult(np.arange(len(remaining) + 1), length, False, 0.0, "kept"))
    order = [int(v) for v in result.planned_views]
    _, share = _reaches(problem, order)
    row = Replan(len(executed), unexpected, contradicted, share, len(remaining), len(order),
                 len(set(order) - set(remaining)), len(set(remaining) - set(order)), time.perf_counter() - started,
                 _reaches(problem, [])[1])
    result = replace(result, executed_views=executed[:warm_up], planned_views=executed[warm_up:] + order,
                     n_views=len(executed) + len(order))
    return result, prediction_of(surface, len(executed)), row
