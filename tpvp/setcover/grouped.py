"""Set cover with a target per group of voxels: the fewest views that see, in every group, at least
its required weight, as an exact 0/1 ILP.

``min sum_v x_v  s.t.  sum_{c in g} w_c y_c >= R_g  for every group g,  y_c <= sum_{v sees c} x_v``

over the views not yet executed (``x_v``, binary) and the voxel classes ``c`` (``0 <= y_c <= 1``).
The groups are a plant's organs (fruit fully, leaves to 95 %, ...): one partial set cover
(:mod:`tpvp.setcover.partial`) per group, sharing the views. The same exact reductions: voxels an
executed view covers and voxels no allowed view sees leave the problem; voxels of one group with the
same set of allowed views merge into one weighted class (never across groups). Bounds before the
ILP: the greedy selection (the view adding the most weight still needed, summed over the groups)
until every group is met is an upper bound; the largest of the groups' own subadditive bounds is a
lower bound; when they meet, no ILP is solved. A group's target above what the allowed views can see
is clipped to its best achievable and said in the result (``reachable`` False).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from tpvp.errors import ConfigError
from tpvp.setcover.ilp import SetCoverConfig
from tpvp.setcover.maxcover import coverage_model, reduce_coverage
from tpvp.setcover.partial import _TOLERANCE, _proven
from tpvp.solvers import solve_pulp_milp


@dataclass(frozen=True, eq=False)
class GroupedCoverResult:
    """The chosen views, what each group got and what the solver proved about their number."""

    selected: np.ndarray  # sorted view indices, executed views excluded
    objective: int
    bound: float  # proven lower bound on the number of views
    gap: float
    optimal: bool
    reachable: np.ndarray  # (groups,) the group's required weight was within reach
    required_weight: np.ndarray  # (groups,) asked, clipped to the achievable
    achievable_weight: np.ndarray  # (groups,) executed + every allowed view
    covered_weight: np.ndarray  # (groups,) executed + selected views
    status: str
    solve_seconds: float
    solver: str


def _group_weights(members_by_view: sparse.csr_matrix, class_weights, class_groups, n_groups: int,
                   open_classes) -> np.ndarray:
    """(views, groups): the weight of each group's open classes each view sees."""
    per_class = sparse.csr_matrix((class_weights * open_classes, (np.arange(len(class_weights)), class_groups)),
                                  shape=(len(class_weights), n_groups))
    return (members_by_view @ per_class).toarray()


def _greedy(by_view, class_weights, class_groups, need: np.ndarray) -> list:
    """Greedy: the view adding the most still-needed weight (summed over the groups, each capped at
    what it still needs; lowest index on ties) until every group is met."""
    open_classes = np.ones(len(class_weights))
    left = need.copy()
    chosen = []
    while (left > _TOLERANCE).any():
        gains = np.minimum(_group_weights(by_view, class_weights, class_groups, len(need), open_classes),
                           np.maximum(left, 0.0)).sum(axis=1)
        view = int(np.argmax(gains))
        if gains[view] <= 0:
            break
        seen = by_view.indices[by_view.indptr[view]:by_view.indptr[view + 1]]
        left -= np.bincount(class_groups[seen], weights=class_weights[seen] * open_classes[seen], minlength=len(need))
        open_classes[seen] = 0.0
        chosen.append(view)
    return chosen


def _lower_bound(by_view, class_weights, class_groups, need: np.ndarray) -> int:
    """The largest over the groups of the fewest views whose largest single weights in the group
    reach its need (coverage is subadditive)."""
    single = _group_weights(by_view, class_weights, class_groups, len(need), np.ones(len(class_weights)))
    bound = 0
    for g in np.flatnonzero(need > _TOLERANCE):
        cumulative = np.cumsum(np.sort(single[:, g])[::-1])
        bound = max(bound, int(np.searchsorted(cumulative, need[g] - _TOLERANCE) + 1))
    return bound


def _covered(members, class_weights, class_groups, chosen, n_groups: int) -> np.ndarray:
    hit = np.asarray(members[:, chosen].sum(axis=1)).ravel() > 0 if len(chosen) else np.zeros(members.shape[0], bool)
    return np.bincount(class_groups[hit], weights=class_weights[hit], minlength=n_groups)


def grouped_set_cover(visibility, groups, required, executed=(), config: SetCoverConfig = SetCoverConfig(),
                      weights=None) -> GroupedCoverResult:
    """Fewest allowed views that, with the executed ones, cover at least ``required[g]`` weight of
    every group ``g``.

    ``visibility``: (views, voxels) boolean, scipy sparse or dense. ``groups``: (voxels,) group
    index 0..G-1 of every voxel. ``required``: (G,) weights to reach (voxel counts without
    ``weights``), the executed views' coverage included. Deterministic.
    """
    if not isinstance(config, SetCoverConfig):
        raise ConfigError(f"config must be a SetCoverConfig, got {type(config).__name__}")
    groups = np.asarray(groups, dtype=np.int64).reshape(-1)
    required = np.asarray(required, dtype=np.float64).reshape(-1)
    if not np.isfinite(required).all() or (required < 0).any():
        raise ConfigError(f"required must be finite weights >= 0, got {required.tolist()}")
    if groups.size and (groups.min() < 0 or groups.max() >= len(required)):
        raise ConfigError(f"groups must be indices 0..{len(required) - 1} of required")
    t0 = time.perf_counter()
    reduced = reduce_coverage(visibility, executed, weights, groups=groups)
    members, class_weights, class_groups = reduced.members, reduced.class_weights, reduced.class_groups
    n_groups = len(required)
    w = reduced.weights
    base = np.bincount(groups[reduced.covered], weights=w[reduced.covered], minlength=n_groups)
    achievable = base + np.bincount(class_groups, weights=class_weights, minlength=n_groups)
    reachable = required <= achievable + _TOLERANCE
    target = np.where(reachable, required, achievable)
    need = target - base
    by_view = sparse.csr_matrix(members.T)

    solver, status = "none", ""
    if (need <= _TOLERANCE).all():
        chosen, lower, optimal = np.zeros(0, np.int64), 0, True
        status = "the executed views reach every group's target"
    else:
        greedy = np.sort(np.asarray(_greedy(by_view, class_weights, class_groups, need), dtype=np.int64))
        lower = _lower_bound(by_view, class_weights, class_groups, need)
        if lower >= greedy.size:
            chosen, optimal, status = greedy, True, "greedy meets the subadditive lower bound"
        else:
            chosen, optimal, bound, status = _solve(members, class_weights, class_groups, need, greedy.size, config)
            solver = config.solver
            met = chosen is not None and (_covered(members, class_weights, class_groups, chosen, n_groups)
                                          >= need - 1e-6).all()
            if not met or chosen.size > greedy.size:
                chosen, optimal, status = greedy, False, f"{status}; greedy fallback"
            lower, optimal = _proven(chosen, lower, optimal, bound)
    chosen = _prune_grouped(members, class_weights, class_groups, chosen, need)
    selected = np.sort(reduced.columns[chosen]).astype(np.int64)
    covered = base + _covered(members, class_weights, class_groups, chosen, n_groups)
    objective = int(selected.size)
    bound_views = float(min(lower, objective))
    if not reachable.all():
        status = f"groups {np.flatnonzero(~reachable).tolist()} clipped to their best achievable; {status}"
    return GroupedCoverResult(selected, objective, bound_views, (objective - bound_views) / objective if objective else 0.0,
                              bool(optimal), reachable, target, achievable, covered, status,
                              time.perf_counter() - t0, solver)


def _prune_grouped(members, class_weights, class_groups, chosen, need) -> np.ndarray:
    """``chosen`` without the views every group can spare (highest index first)."""
    chosen = list(np.asarray(chosen, dtype=np.int64))
    for view in sorted(chosen, reverse=True):
        rest = np.asarray([v for v in chosen if v != view], dtype=np.int64)
        if (_covered(members, class_weights, class_groups, rest, len(need)) >= need - 1e-6).all():
            chosen = list(rest)
    return np.sort(np.asarray(chosen, dtype=np.int64))


def _solve(members, class_weights, class_groups, need, max_views: int, config: SetCoverConfig):
    """The reduced ILP; (chosen view columns or None, optimal, lower bound or None, status)."""
    import pulp

    prob, x, _ = coverage_model(members, class_weights, "min")
    views = pulp.LpAffineExpression([(v, 1) for v in x])
    prob += views
    y = {v.name: v for v in prob.variables() if v.name.startswith("y")}
    for g in np.flatnonzero(need > _TOLERANCE):
        in_group = np.flatnonzero(class_groups == g)
        covered = pulp.LpAffineExpression([(y[f"y{c}"], float(class_weights[c])) for c in in_group])
        prob.addConstraint(pulp.LpConstraint(covered, pulp.LpConstraintGE, f"group{g}", float(need[g])))
    prob.addConstraint(pulp.LpConstraint(views, pulp.LpConstraintLE, "greedy_bound", max_views))
    return solve_pulp_milp(prob, x, config.solver, config.time_limit, config.threads, 0.999)
