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
from tpvp.setcover.maxcover import ReducedCoverage, _prune, _value, coverage_model, reduce_coverage
from tpvp.solvers import highspy_module, solve_pulp_milp

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
    required = _check_required(required)
    t0 = time.perf_counter()
    reduced = reduce_coverage(visibility, executed, weights)
    members, class_weights = reduced.members, reduced.class_weights
    reachable, target, need = _goal(reduced, required)

    solver, status = "none", ""
    if need <= _TOLERANCE:
        chosen, lower, optimal = np.zeros(0, np.int64), 0, True
        status = "the executed views reach the target"
    else:
        greedy, lower = _greedy_and_bound(sparse.csr_matrix(members.T), class_weights, need)
        if lower >= greedy.size:
            chosen, optimal, status = np.sort(greedy), True, "greedy meets the subadditive lower bound"
        else:
            chosen, optimal, bound, status = _solve(members, class_weights, need, greedy.size, config)
            solver = config.solver
            if chosen is None or _value(members, class_weights, chosen) < need - 1e-6 or chosen.size > greedy.size:
                chosen, optimal, status = np.sort(greedy), False, f"{status}; greedy fallback"
            # Views the others make redundant (possible in a time-limited incumbent) are dropped.
            chosen = _prune(members, class_weights, chosen)
            lower, optimal = _proven(chosen, lower, optimal, bound)
    return _result(reduced, chosen, lower, optimal, reachable, required, target, status, time.perf_counter() - t0,
                   solver)


def _proven(chosen: np.ndarray, lower: int, optimal: bool, bound) -> tuple[int, bool]:
    """The lower bound on the view count after a solve (the solver's, when it stated one) and
    whether ``chosen`` is proven optimal (solver's word, or the bound meets it)."""
    if optimal:
        lower = chosen.size
    elif bound is not None and np.isfinite(bound):
        lower = max(lower, math.ceil(bound - 1e-6))
    return lower, optimal or lower >= chosen.size


def _goal(reduced: ReducedCoverage, required: float) -> tuple[bool, float, float]:
    """``(reachable, target, need)``: the weight to reach (``required``, or the best achievable when
    it is out of reach) and what the executed views leave of it."""
    achievable = reduced.base + float(reduced.class_weights.sum())
    reachable = float(required) <= achievable + _TOLERANCE
    target = float(required) if reachable else achievable
    return reachable, target, target - reduced.base


def _greedy_and_bound(by_view: sparse.csr_matrix, weights: np.ndarray, need: float) -> tuple[np.ndarray, int]:
    """The greedy views reaching ``need`` (an upper bound) and the subadditive lower bound: the
    fewest views whose largest single weights sum to ``need``."""
    greedy = np.asarray(_greedy_until(by_view, weights, need), dtype=np.int64)
    single = np.sort(by_view @ weights)[::-1]
    return greedy, int(np.searchsorted(np.cumsum(single), need - _TOLERANCE) + 1)


def _check_required(required) -> float:
    if isinstance(required, (bool, np.bool_)) or not isinstance(required, (int, float, np.integer, np.floating)) \
            or not np.isfinite(required) or required < 0:
        raise ConfigError(f"required must be a finite weight >= 0, got {required!r}")
    return required


def _result(reduced: ReducedCoverage, chosen, lower: int, optimal: bool, reachable: bool, required: float,
            target: float, status: str, seconds: float, solver: str) -> PartialCoverResult:
    """The result of ``chosen`` (columns of the reduced instance) for ``required`` weight."""
    a, w = reduced.visibility, reduced.weights
    achievable = reduced.base + float(reduced.class_weights.sum())
    selected = np.sort(reduced.columns[chosen]).astype(np.int64)
    hit = reduced.covered.copy()
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
        required_weight=target, achievable_weight=achievable, status=status, solve_seconds=seconds,
        n_voxels=int(a.shape[1]), n_classes=int(reduced.members.shape[0]), solver=solver)



def _prune_to(members: sparse.csr_matrix, weights: np.ndarray, chosen: np.ndarray, need: float) -> np.ndarray:
    """``chosen`` without the views it can spare and still cover ``need`` (highest index first)."""
    chosen = list(np.asarray(chosen, dtype=np.int64))
    for view in sorted(chosen, reverse=True):
        rest = np.asarray([v for v in chosen if v != view], dtype=np.int64)
        if _value(members, weights, rest) >= need - 1e-6:
            chosen = list(rest)
    return np.sort(np.asarray(chosen, dtype=np.int64))


class _CoverModel:
    """The partial-cover ILP of a reduced instance in one HiGHS model whose required weight and view
    budget change between solves: columns ``x`` (views, binary) then ``y`` (classes, [0, 1]); rows
    ``y_c - sum_{v sees c} x_v <= 0``, then ``sum w y >= need``, then ``sum x <= budget``."""

    def __init__(self, members: sparse.csr_matrix, weights: np.ndarray, threads: int):
        self.highspy = highspy = highspy_module()
        self.members, self.weights = members, weights
        n_classes, n_views = members.shape
        matrix = sparse.bmat([[-members.astype(np.float64), sparse.identity(n_classes)],
                              [None, sparse.csr_matrix(weights.reshape(1, -1))],
                              [sparse.csr_matrix(np.ones((1, n_views))), None]], format="csc", dtype=np.float64)
        lp = highspy.HighsLp()
        lp.num_col_, lp.num_row_ = n_views + n_classes, n_classes + 2
        lp.col_cost_ = np.concatenate([np.ones(n_views), np.zeros(n_classes)])
        lp.col_lower_ = np.zeros(n_views + n_classes)
        lp.col_upper_ = np.ones(n_views + n_classes)
        lp.row_lower_ = np.concatenate([np.full(n_classes, -highspy.kHighsInf), [0.0, -highspy.kHighsInf]])
        lp.row_upper_ = np.concatenate([np.zeros(n_classes), [highspy.kHighsInf, n_views]])
        lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
        lp.a_matrix_.start_ = matrix.indptr
        lp.a_matrix_.index_ = matrix.indices
        lp.a_matrix_.value_ = matrix.data
        lp.integrality_ = [highspy.HighsVarType.kInteger] * n_views + [highspy.HighsVarType.kContinuous] * n_classes
        self.h = h = highspy.Highs()
        h.silent()
        h.setOptionValue("mip_rel_gap", 0.0)
        h.setOptionValue("mip_abs_gap", 0.999)  # exact for an integral objective
        h.setOptionValue("random_seed", 0)
        h.setOptionValue("threads", int(threads))
        h.passModel(lp)
        self.n_classes, self.n_views = n_classes, n_views

    def solve(self, need: float, incumbent: np.ndarray, seconds: float):
        """Fewest views covering ``need``, starting from ``incumbent`` (which covers it) and no more
        views than it has; (chosen columns or None, optimal, lower bound or None, status)."""
        h, highspy = self.h, self.highspy
        h.changeRowBounds(self.n_classes, float(need), highspy.kHighsInf)
        h.changeRowBounds(self.n_classes + 1, -highspy.kHighsInf, float(len(incumbent)))
        start = highspy.HighsSolution()
        x = np.zeros(self.n_views)
        x[incumbent] = 1.0
        y = (self.members.astype(np.float64) @ x > 0).astype(np.float64)
        start.col_value = list(np.concatenate([x, y]))
        h.setSolution(start)
        h.setOptionValue("time_limit", max(float(seconds), 1e-3))
        h.run()
        status = h.getModelStatus()
        info = h.getInfo()
        found = None
        if info.primal_solution_status == 2:  # kSolutionStatusFeasible
            found = np.flatnonzero(np.asarray(h.getSolution().col_value)[:self.n_views] > 0.5)
        bound = float(info.mip_dual_bound) if np.isfinite(info.mip_dual_bound) else None
        return found, status == highspy.HighsModelStatus.kOptimal, bound, h.modelStatusToString(status)


def partial_set_covers(visibility, required, executed=(), config: SetCoverConfig = SetCoverConfig(),
                       weights=None, time_limit: float | None = None) -> list[PartialCoverResult]:
    """:func:`partial_set_cover` for several ``required`` weights at once (a coverage frontier),
    one model shared by all: the reductions run once, and the weights are solved from the largest
    down in one HiGHS model whose required weight alone changes, each solution the next one's
    starting incumbent (it covers more than the next needs) and its size the next one's budget.
    ``time_limit`` (default ``config.time_limit``) bounds all of them together (each weight may use
    all the time left: a restart loses the search tree, so shares prove fewer). One not proven by
    then keeps the best of its incumbents, with the bounds proved (a smaller weight's bound holds
    for the larger ones). Results in the order of ``required``."""
    if not isinstance(config, SetCoverConfig):
        raise ConfigError(f"config must be a SetCoverConfig, got {type(config).__name__}")
    values = [_check_required(r) for r in np.atleast_1d(np.asarray(required, dtype=object)).tolist()]
    if not values:
        return []
    deadline = time.perf_counter() + float(config.time_limit if time_limit is None else time_limit)
    t0 = time.perf_counter()
    reduced = reduce_coverage(visibility, executed, weights)
    members, class_weights = reduced.members, reduced.class_weights
    by_view = sparse.csr_matrix(members.T)
    model = None
    entries = {}

    def attempt(entry: dict) -> None:
        """Solve the entry's weight in the shared model with the time left."""
        nonlocal model
        started = time.perf_counter()
        model = model or _CoverModel(members, class_weights, config.threads)
        found, optimal, bound, entry["status"] = model.solve(entry["need"], entry["chosen"],
                                                             max(0.0, deadline - started))
        entry["solver"] = "highs"
        if found is not None and found.size <= entry["chosen"].size and \
                _value(members, class_weights, found) >= entry["need"] - 1e-6:
            entry["chosen"] = _prune(members, class_weights, found)
        entry["lower"], entry["optimal"] = _proven(entry["chosen"], entry["lower"], optimal, bound)
        entry["seconds"] += time.perf_counter() - started

    order = sorted(range(len(values)), key=lambda i: -values[i])
    incumbent = None  # the last solution: it reaches every smaller weight
    for done, index in enumerate(order):
        started = time.perf_counter()
        reachable, target, need = _goal(reduced, values[index])
        entry = entries[index] = {"reachable": reachable, "target": target, "need": need, "solver": "none"}
        if need <= _TOLERANCE:
            entry.update(chosen=np.zeros(0, np.int64), lower=0, optimal=True,
                         status="the executed views reach the target")
        else:
            greedy, lower = _greedy_and_bound(by_view, class_weights, need)
            chosen = np.sort(greedy) if incumbent is None or greedy.size <= incumbent.size else incumbent
            entry.update(chosen=_prune_to(members, class_weights, chosen, need), lower=lower, optimal=False,
                         status="an incumbent meets the subadditive lower bound")
            entry["optimal"] = lower >= entry["chosen"].size
        # The first one's time includes the shared reductions.
        entry["seconds"] = time.perf_counter() - (t0 if done == 0 else started)
        if not entry["optimal"]:
            attempt(entry)
        incumbent = entry["chosen"]
    # A larger weight needs at least as many views as a smaller one: its bound holds above it too.
    running = 0
    for index in sorted(range(len(values)), key=lambda i: values[i]):
        entry = entries[index]
        if entry["lower"] < running:
            entry["lower"] = running
            if not entry["optimal"] and running >= entry["chosen"].size:
                entry["optimal"], entry["status"] = True, f"{entry['status']}; proven by a smaller target's bound"
        running = entry["lower"]
    return [_result(reduced, e["chosen"], e["lower"], e["optimal"], e["reachable"], values[i], e["target"],
                    e["status"], e["seconds"], e["solver"]) for i, e in sorted(entries.items())]
