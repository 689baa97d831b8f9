"""View-selection methods, chosen by name (``selection.method``) from :data:`SELECTION_METHODS`.

Signature of a method: ``select(problem: SelectionProblem, config: SelectionConfig) -> Selection``.
The problem carries everything a one-shot selector may use: the visibility matrix of the candidate
views on the planning surface, the executed views, the 6D candidates (a ``ViewSpace``), the
planning voxels with optional weights, the coverage target, and for learned methods the NBV
method's state (its occupancy map and view state of what was observed). A new method is one function plus one
``@SELECTION_METHODS.register`` line.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from scipy import sparse

from tpvp.registry import Registry
from tpvp.setcover.grouped import grouped_set_cover
from tpvp.setcover.ilp import solve_set_cover
from tpvp.setcover.partial import partial_set_cover

SELECTION_METHODS = Registry("view-selection method")


@dataclass(frozen=True, eq=False)
class SelectionProblem:
    """visibility: sparse (views, planning voxels). executed: views already taken (never selected;
    what they see needs no cover). view_space: the candidates (positions, look-ats).
    voxel_centres (n, 3) and voxel_weights (n,) or None: the planning surface. planning_target: the
    fraction of the planning surface to see (``SelectionConfig.planning_target``, resolved from the
    coverage target of today's plant). nbv: the NBV method object that chose the warm-up
    views; methods that learn from what was observed read ``nbv.occupancy`` (built on first use)
    and ``nbv.view_state`` (None when not available)."""

    visibility: object
    executed: tuple
    view_space: object
    voxel_centres: np.ndarray
    planning_target: float = 1.0
    voxel_weights: np.ndarray | None = None
    nbv: object = None
    voxel_groups: np.ndarray | None = None  # a group per planning voxel (its organ), with a share each:
    group_targets: tuple | None = None  # the selection must see that share of every group's voxels


@dataclass(frozen=True, eq=False)
class Selection:
    """Selected views (sorted indices, executed ones excluded) and what is known of their quality.

    optimal: proven fewest views for the target. status: in words. details: the method's own
    result (for ``set-cover``: ``SetCoverResult`` at target 1.0, else ``PartialCoverResult``)."""

    selected: np.ndarray
    optimal: bool
    status: str
    seconds: float
    details: object = field(default=None)


@SELECTION_METHODS.register("set-cover")
def set_cover(problem: SelectionProblem, config) -> Selection:
    """The paper's selection: the fewest views that see every coverable planning voxel (exact ILP).
    With ``planning_target`` t < 1: the fewest views that see at least ``ceil(t x coverable)``
    planning voxels (or that share of the voxel weights), executed views included (exact partial
    set-cover ILP, :func:`tpvp.setcover.partial.partial_set_cover`)."""
    t0 = time.perf_counter()
    if problem.voxel_groups is not None:
        return _grouped_cover(problem, config, t0)
    if problem.planning_target >= 1.0:
        result = solve_set_cover(problem.visibility, executed=problem.executed, config=config.set_cover)
        return Selection(result.selected, result.optimal, result.status, time.perf_counter() - t0, result)
    matrix, weights, coverable, required = cover_requirement(problem)
    total = float(weights[coverable].sum())
    result = partial_set_cover(matrix, required, executed=problem.executed, config=config.set_cover,
                               weights=problem.voxel_weights)
    status = (f"{result.status}; {100 * result.covered_weight / total:.2f} % of the coverable planning surface"
              if total else result.status)
    return Selection(result.selected, result.optimal, status, time.perf_counter() - t0, result)


def _grouped_cover(problem: SelectionProblem, config, t0: float) -> Selection:
    """A share of every group's coverable voxels (weights), the fewest views (exact ILP,
    :func:`tpvp.setcover.grouped.grouped_set_cover`)."""
    matrix, weights, coverable, _ = cover_requirement(problem)
    groups = np.asarray(problem.voxel_groups, dtype=np.int64)
    shares = np.asarray(problem.group_targets, dtype=np.float64)
    totals = np.bincount(groups[coverable], weights=weights[coverable], minlength=len(shares))
    required = shares * totals
    if problem.voxel_weights is None:  # whole voxels
        required = np.ceil(required - 1e-9)
    result = grouped_set_cover(matrix, groups, required, executed=problem.executed, config=config.set_cover,
                               weights=problem.voxel_weights)
    got = ", ".join(f"{100 * c / t:.2f} %" for c, t in zip(result.covered_weight, totals) if t)
    return Selection(result.selected, result.optimal, f"{result.status}; per group {got}", time.perf_counter() - t0,
                     result)


def cover_requirement(problem: SelectionProblem):
    """(visibility as csr, voxel weights, coverable voxels, required weight): what a partial cover
    of ``problem`` must see, as :func:`set_cover` counts it (voxels seen by some view, or their
    weights; the planning target's share of them, a whole number of voxels when unweighted)."""
    matrix = sparse.csr_matrix(problem.visibility)
    weights = np.ones(matrix.shape[1]) if problem.voxel_weights is None else np.asarray(problem.voxel_weights, float)
    coverable = np.zeros(matrix.shape[1], dtype=bool)
    coverable[matrix.indices] = True
    total = float(weights[coverable].sum())
    required = math.ceil(problem.planning_target * total - 1e-9) if problem.voxel_weights is None \
        else problem.planning_target * total
    return matrix, weights, coverable, required


def select_views(problem: SelectionProblem, config) -> Selection:
    """Run the selection method named by ``config.method``."""
    return SELECTION_METHODS.get(config.method)(problem, config)
