"""Partial set cover: the fewest views whose coverage reaches a required amount, as an exact 0/1 ILP.

``min sum_v x_v  s.t.  sum_c w_c y_c >= R,  y_c <= sum_{v sees c} x_v,  x_v in {0, 1},  0 <= y_c <= 1``

over the views not yet executed (``x_v``) and the voxel classes ``c`` not yet covered (``y_c``);
``R`` is the required weight minus what the executed views already cover. ``y`` need not be
integer: for integral ``x`` a class can count only when a selected view sees it. With ``R`` equal
to everything coverable this is the ordinary set cover; with ``R`` a fraction of it, the paper's
full cover becomes "98 % with as few views as possible".

Why not "max coverage for k = 1, 2, ... views" (:mod:`tpvp.setcover.maxcover`): proving that k views
*cannot* reach ``R`` is much cheaper as this single minimisation than as k maximisations solved to
optimality (a sphere maize case: 5.2 s here against 44 s for the max-coverage ILPs at k = 3, 4).

Exact reductions and bounds before the ILP (vectorised):

* voxels covered by an executed view and voxels no allowed view sees leave the problem; voxels
  with the same set of allowed views merge into one weighted class (as in max coverage);
* the greedy selection (largest new weight first) that reaches ``R`` is an upper bound ``U``: the
  ILP gets ``sum x <= U``;
* a lower bound ``L``: the smallest k whose k largest single-view weights sum to ``R`` or more
  (coverage is subadditive); if ``L == U`` greedy is optimal and no ILP is solved.

A target above what the allowed views can see is not an error: the result has ``reachable=False``
and is the fewest views reaching the best achievable coverage (every coverable voxel).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from tpvp.errors import ConfigError
from tpvp.setcover.ilp import SetCoverConfig
from tpvp.setcover.maxcover import _prune, _value, coverage_model, reduce_coverage
from tpvp.solvers import solve_pulp_milp

_TOLERANCE = 1e-9


@dataclass(frozen=True, eq=False)
class PartialCoverResult:
    """The chosen views and what the solver proved about their number.

    ``covered_weight`` includes what the executed views cover; ``required_weight`` is what was
    asked (clipped to the best achievable when ``reachable`` is False).
    """

    selected: np.ndarray  # sorted view indices, executed views excluded
    objective: int  # number of selected views
    bound: float  # proven lower bound on the number of views (== objective when optimal)
    gap: float  # (objective - bound) / objective; 0 when optimal
    optimal: bool
    reachable: bool  # the requested weight can be reached by the allowed views
    covered: int  # voxels seen by the executed or selected views
    covered_weight: float
    required_weight: float
    achievable_weight: float  # weight covered by executed + every allowed view
    status: str
    solve_seconds: float
    n_voxels: int
    n_classes: int
    solver: str  # "cbc", "highs", or "none" when the bounds decided it


def _greedy_until(by_view: sparse.csr_matrix, weights: np.ndarray, need: float) -> list:
    """Greedy (largest new weight, lowest index on ties) until ``need`` weight is covered."""
    open_weight = weights.copy()
    chosen, got = [], 0.0
    while got < need - _TOLERANCE:
        gain = by_view @ open_weight
        j = int(np.argmax(gain))
        if gain[j] <= 0:
            break
        chosen.append(j)
        got += gain[j]
        open_weight[by_view.indices[by_view.indptr[j]:by_view.indptr[j + 1]]] = 0.0
    return chosen


def _solve(members: sparse.csr_matrix, weights: np.ndarray, need: float, max_views: int, config: SetCoverConfig):
    """The reduced ILP; (chosen view columns or None, optimal, lower bound or None, status)."""
    import pulp

    prob, x, covered = coverage_model(members, weights, "min")
    views = pulp.LpAffineExpression([(v, 1) for v in x])
    prob += views
    prob.addConstraint(pulp.LpConstraint(covered, pulp.LpConstraintGE, "required", need))
    prob.addConstraint(pulp.LpConstraint(views, pulp.LpConstraintLE, "greedy_bound", max_views))
    # The objective (a view count) is integral: an absolute gap below 1 is an exact stopping rule.
    return solve_pulp_milp(prob, x, config.solver, config.time_limit, config.threads, 0.999)


def partial_set_cover(visibility, required, executed=(), config: SetCoverConfig = SetCoverConfig(),
                      weights=None) -> PartialCoverResult:
    """Fewest allowed views that, with the executed ones, cover at least ``required`` weight.

    ``visibility``: (views, voxels) boolean matrix, scipy sparse or dense; every column is a voxel.
    ``required``: the weight to reach (a voxel count without ``weights``), executed views'
    coverage included. ``executed``: views already taken (never selected). ``weights``: optional
    (voxels,) non-negative weights. ``config``: solver, time limit, threads. Deterministic.
    """
    if not isinstance(config, SetCoverConfig):
        raise ConfigError(f"config must be a SetCoverConfig, got {type(config).__name__}")
    if isinstance(required, (bool, np.bool_)) or not isinstance(required, (int, float, np.integer, np.floating)) \
            or not np.isfinite(required) or required < 0:
        raise ConfigError(f"required must be a finite weight >= 0, got {required!r}")
    t0 = time.perf_counter()
    reduced = reduce_coverage(visibility, executed, weights)
    a, w, covered = reduced.visibility, reduced.weights, reduced.covered
    members, class_weights, cols, base = reduced.members, reduced.class_weights, reduced.columns, reduced.base
    n_voxels = a.shape[1]
    achievable = base + float(class_weights.sum())
    reachable = float(required) <= achievable + _TOLERANCE
    target = float(required) if reachable else achievable
    need = target - base

    solver, status = "none", ""
    if need <= _TOLERANCE:
        chosen, lower, optimal = np.zeros(0, np.int64), 0, True
        status = "the executed views reach the target"
    else:
        by_view = sparse.csr_matrix(members.T)
        greedy = np.asarray(_greedy_until(by_view, class_weights, need), dtype=np.int64)
        single = np.sort(by_view @ class_weights)[::-1]
        lower = int(np.searchsorted(np.cumsum(single), need - _TOLERANCE) + 1)
        if lower >= greedy.size:
            chosen, optimal, status = np.sort(greedy), True, "greedy meets the subadditive lower bound"
        else:
            chosen, optimal, bound, status = _solve(members, class_weights, need, greedy.size, config)
            solver = config.solver
            if chosen is None or _value(members, class_weights, chosen) < need - 1e-6 or chosen.size > greedy.size:
                chosen, optimal, status = np.sort(greedy), False, f"{status}; greedy fallback"
            # Views the others make redundant (possible in a time-limited incumbent) are dropped.
            chosen = _prune(members, class_weights, chosen)
            if optimal:
                lower = chosen.size
            elif bound is not None and np.isfinite(bound):
                lower = max(lower, math.ceil(bound - 1e-6))
            optimal = optimal or lower >= chosen.size
    selected = np.sort(cols[chosen]).astype(np.int64)
    hit = covered.copy()
    if selected.size:
        hit[a[selected].indices] = True
    objective = int(selected.size)
    bound_views = float(min(lower, objective))
    if not reachable:
        status = f"target {float(required):g} unreachable, best achievable {achievable:g}; {status}"
    return PartialCoverResult(
        selected=selected, objective=objective, bound=bound_views,
        gap=float((objective - bound_views) / objective) if objective else 0.0, optimal=bool(optimal),
        reachable=bool(reachable), covered=int(hit.sum()), covered_weight=float(w[hit].sum()),
        required_weight=target, achievable_weight=achievable, status=status,
        solve_seconds=time.perf_counter() - t0, n_voxels=int(n_voxels), n_classes=int(members.shape[0]),
        solver=solver)

