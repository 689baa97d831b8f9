"""Maximum coverage with at most k views, as an exact 0/1 ILP.

``max sum_c w_c y_c  s.t.  y_c <= sum_{v sees c} x_v,  sum_v x_v <= k,  x_v in {0, 1},  0 <= y_c <= 1``

over the views not yet executed (``x_v``) and the voxel classes ``c`` not yet covered (``y_c``).
The voxels seen by an executed view count as covered already: they are removed before solving and
their weight is added to the objective. ``y`` need not be declared integer: for integral ``x`` the
best ``y_c`` is 1 exactly when a selected view sees ``c``.

The instance is reduced first, vectorised (no Python loop over voxels):

* voxels covered by an executed view leave the problem (counted as covered);
* voxels seen by no allowed view leave the problem (they can never be covered);
* voxels with the same set of allowed views ("identical columns") merge into one class whose
  weight is the sum of theirs (bit-packed view sets, ``np.unique``);
* views that see no remaining voxel leave the decision set.

If at most ``k`` useful views remain, all of them are taken (optimal without a solver). Otherwise
the ILP goes to CBC (PuLP's bundled binary, the default) or HiGHS through
:func:`tpvp.solvers.milp_solver` with the configuration's time limit and threads. With integral
weights (the default: voxel counts) the objective is an integer, so an absolute gap below 1 is an
exact stopping rule. The solver's bound is reported as an upper bound on the objective; a run
stopped by the time limit reports its incumbent, that bound and the gap, and ``optimal=False``.
Without an incumbent (or with one worse than greedy) the greedy selection is returned, marked not
optimal. Finally, selected views that add no weight are dropped (so at most ``k`` views, none
redundant); this never changes the objective.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from tpvp.errors import ConfigError
from tpvp.setcover.ilp import SetCoverConfig, _as_view_indices, _as_visibility
from tpvp.solvers import solve_pulp_milp

# Voxels per chunk when bit-packing view sets (bounds the dense (chunk, views) block).
_PACK_CHUNK = 200_000


@dataclass(frozen=True, eq=False)
class MaxCoverResult:
    """The chosen views and what the solver proved about them.

    ``covered`` and ``objective`` include the voxels (weight) already covered by the executed
    views; ``bound`` is a proven upper bound on ``objective`` (== objective when optimal) and
    ``gap = (bound - objective) / bound`` (0 when optimal or nothing to cover).
    """

    selected: np.ndarray  # sorted view indices, executed views excluded, at most k
    covered: int  # voxels (columns) seen by the executed or the selected views
    objective: float  # weight of those voxels (== covered without weights)
    bound: float  # proven upper bound on the objective
    gap: float
    optimal: bool  # proven optimal
    status: str  # in words
    solve_seconds: float  # wall time of the whole call
    k: int
    n_voxels: int  # columns of the visibility matrix
    n_already_covered: int  # voxels seen by an executed view
    n_unreachable: int  # voxels neither covered already nor seen by any allowed view
    n_classes: int  # distinct view sets among the remaining voxels (constraints of the ILP)
    solver: str  # "cbc", "highs", or "none" when no ILP was needed


def _as_weights(weights, n_voxels: int) -> tuple[np.ndarray, bool]:
    """Per-voxel weights (float64) and whether they are all integers."""
    if weights is None:
        return np.ones(n_voxels), True
    w = np.asarray(weights, dtype=np.float64).reshape(-1) if np.ndim(weights) else np.array([np.nan])
    if w.shape != (n_voxels,):
        raise ConfigError(f"weights must have one value per voxel ({n_voxels}), got shape {np.shape(weights)}")
    if not np.all(np.isfinite(w)) or (w < 0).any():
        raise ConfigError("weights must be finite and >= 0")
    return w, bool(np.all(w == np.round(w)))


def _check_k(k) -> int:
    if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ConfigError(f"k must be an integer >= 1 (views to select), got {k!r}")
    return int(k)


def _classes(columns: sparse.csc_matrix, weights: np.ndarray, groups: np.ndarray | None = None):
    """Merge identical columns of ``columns`` (views x voxels, bool CSC), within a group when
    ``groups`` (one index per voxel) is given.

    Returns ``(members, class_weights, class_groups)``: ``members`` (classes, views) bool CSR, one
    row per distinct view set (and group), the summed weights of each class, and its group (None
    without ``groups``).
    """
    n_views, n_voxels = columns.shape
    packed = []
    for start in range(0, n_voxels, _PACK_CHUNK):
        block = columns[:, start:start + _PACK_CHUNK].T.toarray()
        packed.append(np.packbits(block, axis=1))
    packed = np.concatenate(packed) if packed else np.zeros((0, (n_views + 7) // 8), dtype=np.uint8)
    if groups is not None:  # the group's index as 8 more bytes of the key
        packed = np.hstack([packed, np.asarray(groups, dtype=">i8").reshape(-1, 1).view(np.uint8)])
    unique, first, inverse = np.unique(packed, axis=0, return_index=True, return_inverse=True)
    members = np.unpackbits(unique[:, :(n_views + 7) // 8], axis=1, count=n_views).astype(bool)
    class_weights = np.bincount(inverse.reshape(-1), weights=weights, minlength=unique.shape[0])
    class_groups = None if groups is None else np.asarray(groups, dtype=np.int64)[first]
    return sparse.csr_matrix(members), class_weights, class_groups


@dataclass(frozen=True, eq=False)
class ReducedCoverage:
    """A coverage instance after the exact reductions: what the executed views cover, and the
    remaining coverable voxels merged into weighted classes over the useful allowed views."""

    visibility: sparse.csr_matrix  # the input (views, voxels)
    weights: np.ndarray  # per voxel
    integral: bool  # all weights integers
    covered: np.ndarray  # (voxels,) seen by an executed view
    seen: np.ndarray  # (voxels,) seen by an allowed view
    base: float  # weight covered by the executed views
    members: sparse.csr_matrix  # (classes, useful views) bool
    class_weights: np.ndarray
    columns: np.ndarray  # view index of each useful view (column of members)
    class_groups: np.ndarray | None = None  # the group of each class (reduce_coverage's ``groups``)


def reduce_coverage(visibility, executed=(), weights=None, groups=None) -> ReducedCoverage:
    """Apply the reductions shared by max coverage and partial set cover (module docstring);
    ``groups`` (one index per voxel): classes never merge voxels of two groups."""
    a = _as_visibility(visibility)
    n_views, n_voxels = a.shape
    w, integral = _as_weights(weights, n_voxels)
    executed = _as_view_indices(executed, n_views, "executed")
    allowed = np.ones(n_views, dtype=bool)
    allowed[executed] = False
    covered = np.zeros(n_voxels, dtype=bool)
    covered[a[executed].indices] = True
    allowed_ids = np.flatnonzero(allowed)
    a_allowed = a[allowed_ids]
    seen = np.zeros(n_voxels, dtype=bool)
    seen[a_allowed.indices] = True
    remaining = seen & ~covered
    members, class_weights, class_groups = _classes(sparse.csc_matrix(a_allowed[:, remaining]), w[remaining],
                                                    None if groups is None else np.asarray(groups)[remaining])
    useful = np.flatnonzero(np.diff(sparse.csc_matrix(members).indptr) > 0)
    members = sparse.csr_matrix(members[:, useful])
    members.sort_indices()
    return ReducedCoverage(a, w, integral, covered, seen, float(w[covered].sum()), members, class_weights,
                           allowed_ids[useful], class_groups)


def _greedy(members: sparse.csr_matrix, weights: np.ndarray, k: int) -> np.ndarray:
    """Greedy max coverage (largest new weight first, lowest index on ties), k steps at most."""
    by_view = sparse.csr_matrix(members.T)
    open_weight = weights.copy()
    chosen: list[int] = []
    for _ in range(k):
        gain = by_view @ open_weight
        j = int(np.argmax(gain))
        if gain[j] <= 0:
            break
        chosen.append(j)
        open_weight[by_view.indices[by_view.indptr[j]:by_view.indptr[j + 1]]] = 0.0
    return np.asarray(sorted(chosen), dtype=np.int64)


def _value(members: sparse.csr_matrix, weights: np.ndarray, chosen: np.ndarray) -> float:
    if chosen.size == 0:
        return 0.0
    hit = np.asarray(members[:, chosen].sum(axis=1)).ravel() > 0
    return float(weights[hit].sum())


def _prune(members: sparse.csr_matrix, weights: np.ndarray, chosen: np.ndarray) -> np.ndarray:
    """Drop chosen views whose classes are all covered by other chosen views (or weigh 0),
    highest index first."""
    chosen = np.asarray(chosen, dtype=np.int64)
    if chosen.size == 0:
        return chosen
    sub = sparse.csc_matrix(members[:, chosen], dtype=np.int64)
    counts = np.asarray(sub.sum(axis=1)).ravel()
    keep = np.ones(chosen.size, dtype=bool)
    for i in range(chosen.size - 1, -1, -1):
        rows = sub.indices[sub.indptr[i]:sub.indptr[i + 1]]
        if weights[rows[counts[rows] == 1]].sum() <= 0:
            keep[i] = False
            counts[rows] -= 1
    return chosen[keep]


def coverage_model(members: sparse.csr_matrix, weights: np.ndarray, sense: str):
    """A PuLP model over the reduced classes: binary ``x`` per view, ``0 <= y_c <= 1`` per class with
    ``y_c <= sum_{v sees c} x_v``; returns ``(problem, x, covered weight expression)`` for the
    caller to add its objective and budget (``sense``: "max" or "min")."""
    import pulp

    n_classes, n_views = members.shape
    prob = pulp.LpProblem("coverage", pulp.LpMaximize if sense == "max" else pulp.LpMinimize)
    x = [prob.add_variable(f"x{j}", 0, 1, cat=pulp.LpBinary) for j in range(n_views)]
    y = [prob.add_variable(f"y{c}", 0, 1) for c in range(n_classes)]
    indptr, indices = members.indptr, members.indices
    # One constraint per merged class (the solver's model is built row by row).
    for c in range(n_classes):
        terms = [(y[c], 1)] + [(x[j], -1) for j in indices[indptr[c]:indptr[c + 1]]]
        prob.addConstraint(pulp.LpConstraint(pulp.LpAffineExpression(terms), pulp.LpConstraintLE, f"c{c}", 0))
    return prob, x, pulp.LpAffineExpression(list(zip(y, weights.tolist())))


def _solve(members: sparse.csr_matrix, weights: np.ndarray, k: int, integral: bool, config: SetCoverConfig):
    """Solve the reduced ILP with PuLP. Returns (chosen columns or None, optimal, upper bound or
    None, status)."""
    import pulp

    prob, x, covered = coverage_model(members, weights, "max")
    prob += covered
    prob.addConstraint(pulp.LpConstraint(pulp.LpAffineExpression([(v, 1) for v in x]), pulp.LpConstraintLE,
                                         "budget", k))
    # With integral weights the objective is an integer: a gap below 1 proves the incumbent optimal.
    return solve_pulp_milp(prob, x, config.solver, config.time_limit, config.threads, 0.999 if integral else 0.0)


def max_coverage(visibility, k, executed=(), config: SetCoverConfig = SetCoverConfig(),
                 weights=None) -> MaxCoverResult:
    """At most ``k`` views, none of them executed, that together with the executed views see the
    most voxels (or the largest total ``weights``).

    ``visibility``: (views, voxels) boolean matrix, scipy sparse or dense; every column is a voxel
    (pass a column slice to count a subset). ``executed``: view indices already taken (never
    selected; what they see is covered already). ``config``: solver, time limit, threads (a
    :class:`SetCoverConfig`; ``reduce`` is ignored: the reductions here are always exact).
    ``weights``: optional (voxels,) non-negative weights. Deterministic for a given input.
    """
    if not isinstance(config, SetCoverConfig):
        raise ConfigError(f"config must be a SetCoverConfig, got {type(config).__name__}")
    k = _check_k(k)
    t0 = time.perf_counter()
    reduced = reduce_coverage(visibility, executed, weights)
    a, w, integral, covered, seen = reduced.visibility, reduced.weights, reduced.integral, reduced.covered, reduced.seen
    members, class_weights, cols, base = reduced.members, reduced.class_weights, reduced.columns, reduced.base
    n_voxels, n_useful = a.shape[1], members.shape[1]
    total = float(class_weights.sum())

    common = {"k": k, "n_voxels": int(n_voxels), "n_already_covered": int(covered.sum()),
              "n_unreachable": int((~covered & ~seen).sum()), "n_classes": int(members.shape[0])}
    if n_useful <= k:
        chosen, optimal, upper, status, solver = np.arange(n_useful), True, total, \
            ("nothing to cover" if n_useful == 0 else "all useful views fit the budget"), "none"
    else:
        chosen, optimal, bound, status = _solve(members, class_weights, k, integral, config)
        solver = config.solver
        greedy = _greedy(members, class_weights, k)
        if chosen is None or chosen.size > k:
            chosen, optimal, status = greedy, False, f"{status}; greedy fallback"
        elif _value(members, class_weights, greedy) > _value(members, class_weights, chosen) + 1e-9:
            chosen, optimal, status = greedy, False, f"{status}; greedy better than the incumbent"
        value = _value(members, class_weights, chosen)
        upper = min(total, bound) if bound is not None and np.isfinite(bound) else total
        if integral:
            upper = float(math.floor(upper + 1e-6))
        if optimal:
            upper = value
        upper = max(upper, value)
        optimal = optimal or upper <= value + 1e-9  # the bound may prove the incumbent optimal
    chosen = _prune(members, class_weights, chosen)
    selected = np.sort(cols[chosen]).astype(np.int64)
    value = _value(members, class_weights, chosen)
    objective = base + value
    bound_total = base + (value if optimal else upper)
    hit = covered.copy()
    if selected.size:
        hit[a[selected].indices] = True
    gap = (bound_total - objective) / bound_total if bound_total > 0 else 0.0
    return MaxCoverResult(selected=selected, covered=int(hit.sum()), objective=float(objective),
                          bound=float(bound_total), gap=float(max(gap, 0.0)), optimal=bool(optimal),
                          status=status, solve_seconds=time.perf_counter() - t0, solver=solver, **common)
