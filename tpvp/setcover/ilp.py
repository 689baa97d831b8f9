"""Minimum set cover of surface voxels by candidate views, as a 0/1 ILP (paper Eq. setcover).

``min sum_v x_v  s.t.  sum_v I(p, v) x_v >= 1 for every remaining voxel p,  x_v in {0, 1}``.

Already executed views are excluded from the decision set and the voxels they see are removed
first (docs/single_plant.md#set-cover); voxels that no allowed view sees cannot be covered and are
dropped (counted, not an error). Before solving, the instance is shrunk by exact reductions, each
of which keeps the optimum value:

* identical voxel columns (same set of covering views) are merged into one constraint;
* a voxel whose cover set is a strict superset of another voxel's is dropped (covering the other
  covers it);
* a voxel seen by exactly one allowed view forces that view (essential view);
* a view whose remaining voxels are a subset of another view's is dropped (swapping it for the
  other never hurts); of identical views the lowest index is kept.

The reduced ILP is solved with CBC (through PuLP, the default) or HiGHS (through highspy) to proven
optimality within ``time_limit``; the result reports the objective, a lower bound and the gap.
Solver names, limits and the CBC command come from :mod:`tpvp.solvers` (shared with the path ILP).
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from tpvp.errors import ConfigError
from tpvp.setcover.config import SetCoverConfig
from tpvp.solvers import highspy_module, solve_with_cbc_log

# Cap on the entries of one chunk of the (sets x sets) intersection-count product; bounds memory of
# the dominance test on large instances.
_PRODUCT_CHUNK_NNZ = 20_000_000


@dataclass(frozen=True, eq=False)
class SetCoverResult:
    """Selected views and what the solver proved about them."""

    selected: np.ndarray  # sorted view indices (row indices of the visibility matrix), int64
    objective: int  # number of selected views
    bound: float  # proven lower bound on the number of views needed (== objective when optimal)
    gap: float  # (objective - bound) / objective; 0 when optimal or nothing to cover
    optimal: bool  # proven optimal
    status: str  # solver status in words
    solve_seconds: float  # wall time of the whole call (reductions, model build, solve)
    n_voxels: int  # columns of the visibility matrix
    n_dropped_infeasible: int  # voxels not already covered that no allowed view sees
    n_already_covered: int  # voxels seen by an executed view
    solver: str  # "cbc", "highs", or "none" when the reductions solved the instance
    n_constraints: int = 0  # coverage constraints left for the ILP after the reductions
    n_forced: int = 0  # views forced by the reductions (essential views)


def _as_visibility(visibility) -> sparse.csr_matrix:
    if sparse.issparse(visibility):
        matrix = sparse.csr_matrix(visibility)
    else:
        arr = np.asarray(visibility)
        if arr.ndim != 2:
            raise ConfigError(f"visibility must be a 2-D (views, voxels) matrix, got shape {arr.shape}")
        matrix = sparse.csr_matrix(arr)
    if matrix.ndim != 2:
        raise ConfigError(f"visibility must be a 2-D (views, voxels) matrix, got shape {matrix.shape}")
    matrix = matrix.astype(bool)
    matrix.eliminate_zeros()
    matrix.sum_duplicates()
    matrix.sort_indices()
    return matrix


def _as_view_indices(values, n_views: int, name: str) -> np.ndarray:
    arr = np.asarray(values if values is not None else [])
    if arr.size == 0:
        return np.zeros(0, dtype=np.int64)
    if arr.dtype == bool:
        raise ConfigError(f"{name} must be view indices, not a boolean mask")
    if not np.issubdtype(arr.dtype, np.integer):
        if not np.all(np.isfinite(arr)) or not np.all(arr == np.round(arr)):
            raise ConfigError(f"{name} must be integer view indices, got {arr.tolist()!r}")
        arr = arr.astype(np.int64)
    arr = arr.reshape(-1).astype(np.int64)
    bad = (arr < 0) | (arr >= n_views)
    if bad.any():
        raise ConfigError(f"{name} holds view indices outside [0, {n_views}): {arr[bad].tolist()}")
    return np.unique(arr)


def _as_candidate_mask(candidates, n_views: int) -> np.ndarray:
    if candidates is None:
        return np.ones(n_views, dtype=bool)
    arr = np.asarray(candidates)
    if arr.dtype == bool:
        if arr.shape != (n_views,):
            raise ConfigError(f"candidates mask must have shape ({n_views},), got {arr.shape}")
        return arr.copy()
    mask = np.zeros(n_views, dtype=bool)
    mask[_as_view_indices(arr, n_views, "candidates")] = True
    return mask


# --- reductions ------------------------------------------------------------------------------


def _unique_rows(m: sparse.csr_matrix) -> np.ndarray:
    """Index of the first occurrence of every distinct row (rows are sets: sorted indices)."""
    seen: dict[bytes, int] = {}
    indptr, indices = m.indptr, m.indices
    keep = []
    for i in range(m.shape[0]):
        key = indices[indptr[i]:indptr[i + 1]].tobytes()
        if key not in seen:
            seen[key] = i
            keep.append(i)
    return np.asarray(keep, dtype=np.int64)


def _subset_matrix_chunks(m: sparse.csr_matrix):
    """Yield ``(start, counts)``: intersection sizes ``|row_i & row_j|`` for rows ``start..``."""
    mt = sparse.csr_matrix(m.T, dtype=np.int32)
    m32 = sparse.csr_matrix(m, dtype=np.int32)
    # Product entries of row i <= sum of the degrees of its elements: size the chunks by that.
    degree = np.diff(mt.indptr).astype(np.int64)
    cum = np.cumsum(m32 @ degree)
    n_chunks = int(cum[-1] // _PRODUCT_CHUNK_NNZ) + 1 if cum.size else 1
    edges = np.searchsorted(cum, np.arange(1, n_chunks) * _PRODUCT_CHUNK_NNZ)
    edges = np.unique(np.r_[0, edges, m.shape[0]])
    for start, stop in itertools.pairwise(edges):
        yield int(start), (m32[start:stop] @ mt).tocoo()


def _dominated_rows(m: sparse.csr_matrix) -> np.ndarray:
    """Mask of rows that strictly contain another row (rows distinct and non-empty)."""
    size = np.diff(m.indptr)
    out = np.zeros(m.shape[0], dtype=bool)
    for start, prod in _subset_matrix_chunks(m):
        i = prod.row + start
        j = prod.col
        # row j is a strict subset of row i when all of j lies in i and j is smaller.
        hit = (prod.data == size[j]) & (size[j] < size[i])
        out[i[hit]] = True
    return out


def _dominated_columns(m: sparse.csr_matrix) -> np.ndarray:
    """Mask of columns contained in another column; of identical columns all but the first."""
    mt = sparse.csr_matrix(m.T)
    size = np.diff(mt.indptr)
    out = np.zeros(mt.shape[0], dtype=bool)
    out[size == 0] = True
    for start, prod in _subset_matrix_chunks(mt):
        u = prod.row + start
        w = prod.col
        hit = (prod.data == size[u]) & (u != w) & ((size[w] > size[u]) | (w < u))
        out[u[hit]] = True
    return out


def _reduce(b: sparse.csr_matrix, cols: np.ndarray, enabled: bool):
    """Apply the exact reductions to ``b`` (constraints x views, view ids ``cols``).

    Returns ``(b, cols, forced)``: the reduced matrix, its view ids and the forced view ids.
    """
    forced: list[np.ndarray] = []
    b = b[_unique_rows(b)]
    if not enabled:
        return b, cols, np.zeros(0, dtype=np.int64)
    while b.shape[0]:
        changed = False
        # Essential views: a voxel with a single covering view forces it.
        single = np.diff(b.indptr) == 1
        if single.any():
            f = np.unique(b.indices[b.indptr[:-1][single]])
            forced.append(cols[f])
            hit = np.zeros(b.shape[1], dtype=bool)
            hit[f] = True
            covered = np.asarray(b[:, hit].sum(axis=1)).ravel() > 0
            b = b[~covered]
            changed = True
        if not b.shape[0]:
            break
        dominated = _dominated_rows(b)
        if dominated.any():
            b = b[~dominated]
        dropped = _dominated_columns(b)
        if dropped.any():
            keep = ~dropped
            b = sparse.csr_matrix(b[:, keep])
            cols = cols[keep]
            b.sort_indices()
            # Fewer columns can make rows identical or create new singletons.
            b = b[_unique_rows(b)]
            changed = True
        if not changed:
            break
    forced_ids = np.unique(np.concatenate(forced)) if forced else np.zeros(0, dtype=np.int64)
    return b, cols, forced_ids


# --- solvers ---------------------------------------------------------------------------------


def _greedy(b: sparse.csr_matrix) -> np.ndarray:
    """Greedy cover (most new voxels first, lowest index on ties): a feasible fallback."""
    bc = sparse.csc_matrix(b)
    uncovered = np.ones(b.shape[0], dtype=bool)
    chosen = []
    while uncovered.any():
        gain = np.asarray(bc.T @ uncovered.astype(np.int64)).ravel()
        j = int(np.argmax(gain))
        chosen.append(j)
        uncovered[bc.indices[bc.indptr[j]:bc.indptr[j + 1]]] = False
    return np.asarray(sorted(chosen), dtype=np.int64)


def _solve_cbc(b: sparse.csr_matrix, config: SetCoverConfig):
    import pulp

    n = b.shape[1]
    prob = pulp.LpProblem("set_cover", pulp.LpMinimize)
    x = [prob.add_variable(f"x{j}", 0, 1, cat=pulp.LpBinary) for j in range(n)]
    prob += pulp.LpAffineExpression([(v, 1) for v in x])
    indptr, indices = b.indptr, b.indices
    for i in range(b.shape[0]):
        expr = pulp.LpAffineExpression([(x[j], 1) for j in indices[indptr[i]:indptr[i + 1]]])
        prob.addConstraint(pulp.LpConstraint(expr, pulp.LpConstraintGE, f"c{i}", 1))
    # gapAbs < 1 is an exact stopping rule: the objective is integral, so a gap below 1 proves
    # the incumbent optimal.
    log = solve_with_cbc_log(prob, config.time_limit, config.threads, gapRel=0.0, gapAbs=0.999)
    values = np.array([v.value() if v.value() is not None else 0.0 for v in x])
    has_solution = prob.sol_status in (pulp.LpSolutionOptimal, pulp.LpSolutionIntegerFeasible)
    result = log.get("result", pulp.LpStatus[prob.status])
    optimal = prob.sol_status == pulp.LpSolutionOptimal and result.startswith("Optimal")
    chosen = np.flatnonzero(values > 0.5) if has_solution else None
    bound = log.get("lower_bound")
    return chosen, optimal, bound, result


def _solve_highs(b: sparse.csr_matrix, config: SetCoverConfig):
    highspy = highspy_module()
    m, n = b.shape
    a = sparse.csc_matrix(b, dtype=np.float64)
    lp = highspy.HighsLp()
    lp.num_col_ = n
    lp.num_row_ = m
    lp.col_cost_ = np.ones(n)
    lp.col_lower_ = np.zeros(n)
    lp.col_upper_ = np.ones(n)
    lp.row_lower_ = np.ones(m)
    lp.row_upper_ = np.full(m, highspy.kHighsInf)
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = a.indptr
    lp.a_matrix_.index_ = a.indices
    lp.a_matrix_.value_ = a.data
    lp.integrality_ = [highspy.HighsVarType.kInteger] * n
    h = highspy.Highs()
    h.silent()
    h.setOptionValue("time_limit", float(config.time_limit))
    h.setOptionValue("mip_rel_gap", 0.0)
    h.setOptionValue("mip_abs_gap", 0.999)  # exact for an integral objective (see _solve_cbc)
    h.setOptionValue("random_seed", 0)
    h.passModel(lp)
    h.run()
    status = h.getModelStatus()
    info = h.getInfo()
    result = h.modelStatusToString(status)
    has_solution = info.primal_solution_status == 2  # kSolutionStatusFeasible
    chosen = np.flatnonzero(np.asarray(h.getSolution().col_value) > 0.5) if has_solution else None
    optimal = status == highspy.HighsModelStatus.kOptimal
    bound = float(info.mip_dual_bound) if np.isfinite(info.mip_dual_bound) else None
    return chosen, optimal, bound, result


def solve_set_cover(visibility, executed=(), candidates=None,
                    config: SetCoverConfig = SetCoverConfig()) -> SetCoverResult:
    """Smallest set of allowed views covering every coverable, not yet covered voxel.

    ``visibility``: (views, voxels) boolean matrix, scipy sparse or dense (e.g. from
    :func:`tpvp.visibility.visibility_matrix`). ``executed``: view indices already taken; they are
    never selected and the voxels they see need no further cover. ``candidates``: optional boolean
    mask (views,) or index array restricting the decision set. Every column counts as a voxel to
    cover; pass a column slice to cover a subset. Deterministic for a given input and config.
    """
    if not isinstance(config, SetCoverConfig):
        raise ConfigError(f"config must be a SetCoverConfig, got {type(config).__name__}")
    t0 = time.perf_counter()
    a = _as_visibility(visibility)
    n_views, n_voxels = a.shape
    executed = _as_view_indices(executed, n_views, "executed")
    allowed = _as_candidate_mask(candidates, n_views)
    allowed[executed] = False

    covered = np.zeros(n_voxels, dtype=bool)
    if executed.size:
        covered[a[executed].indices] = True
    allowed_ids = np.flatnonzero(allowed)
    a_allowed = a[allowed_ids]
    seen = np.zeros(n_voxels, dtype=bool)
    seen[a_allowed.indices] = True
    infeasible = ~covered & ~seen
    remaining = ~covered & seen

    # Constraint matrix: one row per remaining voxel, one column per allowed view.
    b = sparse.csr_matrix(a_allowed[:, remaining].T)
    b.sort_indices()
    b, cols, forced = _reduce(b, allowed_ids, config.reduce)
    if not config.reduce:
        keep = np.flatnonzero(np.diff(sparse.csc_matrix(b).indptr) > 0)
        b, cols = sparse.csr_matrix(b[:, keep]), cols[keep]
        b.sort_indices()

    common = {"n_voxels": int(n_voxels), "n_dropped_infeasible": int(infeasible.sum()),
              "n_already_covered": int(covered.sum()), "n_constraints": int(b.shape[0]),
              "n_forced": int(forced.size)}
    if b.shape[0] == 0:
        selected = np.sort(forced).astype(np.int64)
        return SetCoverResult(selected=selected, objective=int(selected.size), bound=float(selected.size),
                              gap=0.0, optimal=True, status="solved by reductions" if selected.size
                              else "nothing to cover", solve_seconds=time.perf_counter() - t0,
                              solver="none", **common)

    solve = _solve_cbc if config.solver == "cbc" else _solve_highs
    chosen, optimal, bound, status = solve(b, config)
    if chosen is None or not _covers(b, chosen):
        # No incumbent within the time limit (or a numerically broken one): fall back to greedy.
        chosen, optimal = _greedy(b), False
        status = f"{status}; greedy fallback"
    elif not optimal:
        greedy = _greedy(b)
        if greedy.size < chosen.size:
            chosen = greedy
    selected = np.sort(np.concatenate([forced, cols[chosen]])).astype(np.int64)
    objective = int(selected.size)
    if optimal:
        lower = float(objective)
    else:
        # The objective is integral, so the solver's bound rounds up (small tolerance for round-off).
        inner = math.ceil(bound - 1e-6) if bound is not None else 1
        lower = float(min(objective, forced.size + max(inner, 1)))
        optimal = lower >= objective  # the bound may prove the incumbent optimal after all
    gap = (objective - lower) / objective if objective else 0.0
    return SetCoverResult(selected=selected, objective=objective, bound=lower, gap=float(gap),
                          optimal=bool(optimal), status=status, solve_seconds=time.perf_counter() - t0,
                          solver=config.solver, **common)


def _covers(b: sparse.csr_matrix, chosen: np.ndarray) -> bool:
    if chosen.size == 0:
        return b.shape[0] == 0
    return bool((np.asarray(b[:, chosen].sum(axis=1)).ravel() > 0).all())
