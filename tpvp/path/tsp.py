"""Global path through the selected views: shortest open path (paper Eq. global_path).

``shortest_open_path`` orders views from a fixed start (and optionally a fixed end) so that the
sum of ``distance[v_i, v_{i+1}]`` is minimal: a shortest Hamiltonian path, i.e. an open TSP.

* ``"dp"``: Held-Karp dynamic programme over subsets, vectorised with numpy; exact, for up to
  ~16 views (memory and time grow as 2^n).
* ``"ilp"``: exact 0/1 ILP solved with PuLP (CBC or HiGHS) with lazily added subtour-elimination
  constraints; exact, practical up to a few dozen views.
* ``"heuristic"``: nearest neighbour, then 2-opt and Or-opt local search restarted from ``kicks``
  double-bridge perturbations (fixed seed); for bands of hundreds of views; never longer than
  nearest neighbour, not proven optimal. The local search is a numba loop: vectorised
  best-improvement scans redo O(n^2) array work per move (10 s for 400 views).
* ``"auto"`` (default): dp up to ``dp_max_nodes`` views, ilp up to ``ilp_max_nodes``, heuristic
  beyond.

Distances may be asymmetric: all three methods use ``distance[i, j]`` as the cost of going from i
to j (the local path lengths of :mod:`tpvp.path.local` are symmetric).

``band_path`` is the greenhouse-row variant (docs/greenhouse.md#band-path): views split into an
upper and a lower height band, an open path in each, joined through a connection view. Bands
solved by the heuristic get a Held-Karp lower bound (:mod:`tpvp.path.bound`) and a reported gap.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numba import njit

from tpvp.errors import ConfigError
from tpvp.path.bound import open_path_lower_bound
from tpvp.path.config import _DP_HARD_LIMIT, TspConfig
from tpvp.solvers import milp_solver


@dataclass(frozen=True, eq=False)
class PathResult:
    """An open path: node indices in visiting order (start first, fixed end last)."""

    order: np.ndarray  # int64 node indices
    length: float  # sum of distance[order[i], order[i + 1]]
    optimal: bool  # proven shortest
    solve_seconds: float
    method: str  # "trivial", "dp", "ilp-cbc", "ilp-highs", "heuristic" (+ " (time limit)")


@dataclass(frozen=True, eq=False)
class BandPathResult:
    """Greenhouse-row path: first band's open path, then the second band's from the connection view."""

    order: np.ndarray  # indices into the positions, in visiting order
    length: float  # including the leg from start_position when one was given
    optimal: bool  # both band paths proven optimal (the band split itself is a heuristic)
    solve_seconds: float
    bands: tuple  # (first band's indices, second band's indices), each in visiting order
    connection_view: int  # first view of the second band (-1 when a band is empty)
    split_height: float
    # Lower bounds (tpvp.path.bound, Held-Karp) for the same band split and band start views:
    # per band (in ``bands`` order; a band solved exactly has bound = its length, an empty one 0)
    # and overall (band bounds + the start and connection legs). Gaps are (length - bound) / length;
    # NaN when bound_iterations = 0 left a heuristic band without a bound.
    band_lengths: tuple = ()  # each band's open-path length (legs excluded)
    band_bounds: tuple = ()
    band_gaps: tuple = ()
    bound: float = float("nan")
    gap: float = float("nan")


# --- input checks ----------------------------------------------------------------------------


def _as_distance(distance) -> np.ndarray:
    d = np.asarray(distance, dtype=np.float64)
    if d.ndim != 2 or d.shape[0] != d.shape[1]:
        raise ConfigError(f"distance must be a square (n, n) matrix, got shape {d.shape}")
    if d.shape[0] == 0:
        raise ConfigError("distance is empty: there must be at least the start node")
    if not np.all(np.isfinite(d)):
        raise ConfigError("distance contains NaN or infinite entries")
    return d


def _as_node(value, n: int, name: str) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"{name} must be an integer node index, got {value!r}")
    if not 0 <= int(value) < n:
        raise ConfigError(f"{name} must be in [0, {n}), got {value}")
    return int(value)


def path_length(distance, order) -> float:
    """Sum of ``distance`` along consecutive nodes of ``order``."""
    d = np.asarray(distance, dtype=np.float64)
    order = np.asarray(order, dtype=np.int64)
    if order.size < 2:
        return 0.0
    return float(d[order[:-1], order[1:]].sum())


# --- Held-Karp -------------------------------------------------------------------------------


def _held_karp(d: np.ndarray, start: int, end: int | None) -> np.ndarray:
    n = d.shape[0]
    inner = np.array([v for v in range(n) if v != start and v != end], dtype=np.int64)
    k = inner.size
    dk = d[np.ix_(inner, inner)]
    full = (1 << k) - 1
    # dp[mask, j]: shortest path from start through exactly the inner nodes in mask, ending at j.
    dp = np.full((1 << k, k), np.inf)
    parent = np.full((1 << k, k), -1, dtype=np.int8)
    bits = 1 << np.arange(k)
    dp[bits, np.arange(k)] = d[start, inner]
    masks = np.arange(1 << k)
    popcount = np.zeros(1 << k, dtype=np.int64)
    for b in range(k):
        popcount += (masks >> b) & 1
    layers = np.argsort(popcount, kind="stable")
    bounds = np.searchsorted(popcount[layers], np.arange(k + 2))
    for size in range(2, k + 1):
        layer = layers[bounds[size]:bounds[size + 1]]
        for j in range(k):
            sel = layer[(layer >> j) & 1 == 1]
            # dp is inf outside each mask, so the min runs over predecessors i in mask - {j} only.
            cand = dp[sel ^ (1 << j)] + dk[:, j]
            best = np.argmin(cand, axis=1)
            dp[sel, j] = cand[np.arange(sel.size), best]
            parent[sel, j] = best
    last = dp[full] + (d[inner, end] if end is not None else 0.0)
    j = int(np.argmin(last))
    rev = []
    mask = full
    while j >= 0:
        rev.append(inner[j])
        prev = int(parent[mask, j])
        mask ^= 1 << j
        j = prev
    order = [start] + rev[::-1] + ([end] if end is not None else [])
    return np.asarray(order, dtype=np.int64)


# --- exact ILP with lazy subtour elimination --------------------------------------------------


def _cycles(succ: np.ndarray) -> list[list[int]]:
    seen = np.zeros(succ.size, dtype=bool)
    out = []
    for s in range(succ.size):
        if seen[s]:
            continue
        cyc = []
        v = s
        while not seen[v]:
            seen[v] = True
            cyc.append(v)
            v = int(succ[v])
        out.append(cyc)
    return out


def _ilp(d: np.ndarray, start: int, end: int | None, config: TspConfig, deadline: float):
    """Exact open path by an ILP; ``None`` when the time limit stops the cutting loop."""
    import pulp

    n = d.shape[0]
    # Close the path into a tour: returning to the start is free (any end) or only allowed from
    # the fixed end. A shortest such tour minus its return arc is a shortest open path.
    arcs = [(i, j) for i in range(n) for j in range(n)
            if i != j and (j != start or end is None or i == end)]
    cost = {(i, j): (0.0 if j == start else float(d[i, j])) for i, j in arcs}
    prob = pulp.LpProblem("open_path", pulp.LpMinimize)
    x = {a: prob.add_variable(f"x_{a[0]}_{a[1]}", 0, 1, cat=pulp.LpBinary) for a in arcs}
    prob += pulp.LpAffineExpression([(x[a], cost[a]) for a in arcs])
    outgoing = {i: [] for i in range(n)}
    incoming = {i: [] for i in range(n)}
    for i, j in arcs:
        outgoing[i].append(x[i, j])
        incoming[j].append(x[i, j])
    for v in range(n):
        prob += pulp.lpSum(outgoing[v]) == 1, f"out_{v}"
        prob += pulp.lpSum(incoming[v]) == 1, f"in_{v}"
    if n >= 3:
        # Two-cycles dominate the first rounds of the assignment relaxation; forbid them up front.
        for i, j in arcs:
            if i < j and (j, i) in x:
                prob += x[i, j] + x[j, i] <= 1, f"two_{i}_{j}"
    n_cuts = 0
    while True:
        remaining = deadline - time.perf_counter()
        if remaining <= 0:
            return None
        prob.solve(milp_solver(config.solver, remaining, config.threads, gapRel=0.0, gapAbs=1e-9))
        if prob.sol_status != pulp.LpSolutionOptimal:
            return None
        succ = np.full(n, -1, dtype=np.int64)
        for (i, j), var in x.items():
            if var.value() is not None and var.value() > 0.5:
                succ[i] = j
        cycles = _cycles(succ)
        if len(cycles) == 1:
            break
        for cyc in cycles:
            terms = [(x[i, j], 1) for i in cyc for j in cyc if (i, j) in x]
            prob += pulp.LpAffineExpression(terms) <= len(cyc) - 1, f"sec_{n_cuts}"
            n_cuts += 1
    order = [start]
    while len(order) < n:
        order.append(int(succ[order[-1]]))
    return np.asarray(order, dtype=np.int64)


# --- heuristic -------------------------------------------------------------------------------


def nearest_neighbour_path(distance, start: int, end: int | None = None) -> np.ndarray:
    """Greedy open path: from ``start`` always to the nearest unvisited node, ``end`` (if given) last.

    Ties go to the lowest index. The starting point of the ``"heuristic"`` method, which is never
    longer; useful as a baseline.
    """
    d, start, end = _path_problem(distance, start, end)
    return _nearest_neighbour(d, start, end)


def _path_problem(distance, start, end):
    """Checked ``(distance, start, end)``; ``end == start`` on a one-node problem means no end."""
    d = _as_distance(distance)
    n = d.shape[0]
    start = _as_node(start, n, "start")
    if end is not None:
        end = _as_node(end, n, "end")
        if end == start and n > 1:
            raise ConfigError(f"end must differ from start ({start}) when there are other nodes")
        if end == start:
            end = None
    return d, start, end


def _nearest_neighbour(d: np.ndarray, start: int, end: int | None) -> np.ndarray:
    n = d.shape[0]
    free = np.ones(n, dtype=bool)
    free[start] = False
    if end is not None:
        free[end] = False
    order = [start]
    for _ in range(int(free.sum())):
        row = np.where(free, d[order[-1]], np.inf)
        v = int(np.argmin(row))
        order.append(v)
        free[v] = False
    if end is not None:
        order.append(end)
    return np.asarray(order, dtype=np.int64)


@njit(cache=True)
def _prefix(d, a, fwd, bwd):
    """fwd[k] / bwd[k]: length of a[0..k] walked forwards / with every arc reversed."""
    fwd[0] = 0.0
    bwd[0] = 0.0
    for t in range(1, a.size):
        fwd[t] = fwd[t - 1] + d[a[t - 1], a[t]]
        bwd[t] = bwd[t - 1] + d[a[t], a[t - 1]]


@njit(cache=True)
def _local_search_kernel(d, a, free_end, tol):
    """2-opt and Or-opt (segments of 1-3, either direction) to a local optimum, first improvement.

    ``a[0]`` (start) and, unless ``free_end``, ``a[-1]`` stay in place. Deltas are exact for
    asymmetric distances (reversed stretches are re-priced from the prefix sums).
    """
    n = a.size
    last = n - 1 if free_end else n - 2
    fwd = np.empty(n)
    bwd = np.empty(n)
    buf = np.empty_like(a)
    improved = True
    while improved:
        improved = False
        _prefix(d, a, fwd, bwd)
        # 2-opt: reverse a[i..j].
        for i in range(1, last):
            for j in range(i + 1, last + 1):
                delta = d[a[i - 1], a[j]] - d[a[i - 1], a[i]] + (bwd[j] - bwd[i]) - (fwd[j] - fwd[i])
                if j < n - 1:
                    delta += d[a[i], a[j + 1]] - d[a[j], a[j + 1]]
                if delta < -tol:
                    lo, hi = i, j
                    while lo < hi:
                        a[lo], a[hi] = a[hi], a[lo]
                        lo += 1
                        hi -= 1
                    _prefix(d, a, fwd, bwd)
                    improved = True
        # Or-opt: move a[i..e] (e = i + L - 1) between a[k] and a[k + 1] (k = n - 1: append).
        for seg in range(1, 4):
            i = 1
            while i + seg - 1 <= last:
                e = i + seg - 1
                p = a[i - 1]
                remove = -d[p, a[i]]
                if e < n - 1:
                    remove += d[p, a[e + 1]] - d[a[e], a[e + 1]]
                inner = (bwd[e] - bwd[i]) - (fwd[e] - fwd[i])
                k_max = n - 1 if free_end else n - 2
                best, best_k, best_rev = -tol, -1, False
                for k in range(k_max + 1):
                    if i - 1 <= k <= e:
                        continue
                    x = a[k]
                    broken = 0.0
                    tail_f = 0.0
                    tail_r = 0.0
                    if k < n - 1:
                        y = a[k + 1]
                        broken = d[x, y]
                        tail_f = d[a[e], y]
                        tail_r = d[a[i], y]
                    delta = remove + d[x, a[i]] + tail_f - broken
                    if delta < best:
                        best, best_k, best_rev = delta, k, False
                    if seg > 1:
                        delta = remove + d[x, a[e]] + tail_r - broken + inner
                        if delta < best:
                            best, best_k, best_rev = delta, k, True
                if best_k >= 0:
                    # Rebuild: the rest without the segment, the segment inserted after a[best_k].
                    m = 0
                    for t in range(n):
                        if t < i or t > e:
                            buf[m] = a[t]
                            m += 1
                            if t == best_k:
                                for u in range(seg):
                                    buf[m] = a[e - u] if best_rev else a[i + u]
                                    m += 1
                    a[:] = buf
                    _prefix(d, a, fwd, bwd)
                    improved = True
                i += 1
    return a


def _local_search(d: np.ndarray, a: np.ndarray, free_end: bool) -> np.ndarray:
    a = np.array(a, dtype=np.int64)
    if a.size - (1 if free_end else 2) < 2:
        return a
    tol = 1e-12 * max(float(np.abs(d).max()), 1e-300)
    return _local_search_kernel(np.ascontiguousarray(d), a, free_end, tol)


def _iterated_local_search(d: np.ndarray, start: int, end: int | None, kicks: int,
                           deadline: float, initial: np.ndarray | None = None, seed: int = 0) -> np.ndarray:
    """Nearest neighbour (or ``initial``), local search, then ``kicks`` double-bridge perturbations
    (kept if better)."""
    free_end = end is None
    best = _local_search(d, _nearest_neighbour(d, start, end) if initial is None else initial, free_end)
    best_len = path_length(d, best)
    n = best.size
    last_movable = n - 1 if free_end else n - 2
    if last_movable < 4:
        return best
    rng = np.random.default_rng(seed)  # fixed seed: the heuristic is deterministic
    for _ in range(kicks):
        if time.perf_counter() >= deadline:
            break
        # Double bridge on the movable part a[1..last_movable]: A B C D -> A C B D, a move that
        # 2-opt and Or-opt cannot undo in one step.
        cut = np.sort(rng.choice(np.arange(2, last_movable + 1), size=3, replace=False))
        p, q, r = cut
        cand = np.r_[best[:p], best[q:r], best[p:q], best[r:]]
        cand = _local_search(d, cand, free_end)
        cand_len = path_length(d, cand)
        if cand_len < best_len - 1e-12 * max(best_len, 1.0):
            best, best_len = cand, cand_len
    return best


# --- public API ------------------------------------------------------------------------------


def shortest_open_path(distance, start: int, end: int | None = None,
                       config: TspConfig = TspConfig()) -> PathResult:
    """Shortest path from ``start`` through every node (ending at ``end`` when given).

    ``distance``: (n, n) matrix, ``distance[i, j]`` the cost from i to j (need not be symmetric).
    """
    if not isinstance(config, TspConfig):
        raise ConfigError(f"config must be a TspConfig, got {type(config).__name__}")
    t0 = time.perf_counter()
    d, start, end = _path_problem(distance, start, end)
    n = d.shape[0]
    n_inner = n - 1 - (end is not None)

    def result(order, optimal, method):
        return PathResult(order=order, length=path_length(d, order), optimal=bool(optimal),
                          solve_seconds=time.perf_counter() - t0, method=method)

    if n_inner <= 1:
        order = [start] + [v for v in range(n) if v != start and v != end] + ([end] if end is not None else [])
        return result(np.asarray(order, dtype=np.int64), True, "trivial")

    method = config.method
    if method == "auto":
        method = "dp" if n <= config.dp_max_nodes else "ilp" if n <= config.ilp_max_nodes else "heuristic"
    if method == "dp":
        if n > _DP_HARD_LIMIT:
            raise ConfigError(f"method 'dp' handles at most {_DP_HARD_LIMIT} nodes, got {n}")
        return result(_held_karp(d, start, end), True, "dp")
    deadline = t0 + float(config.time_limit)
    if method == "ilp":
        order = _ilp(d, start, end, config, deadline)
        if order is not None:
            return result(order, True, f"ilp-{config.solver}")
        # Time limit: fall back to the heuristic with a short budget of its own.
        deadline = time.perf_counter() + max(1.0, 0.1 * float(config.time_limit))
    order = _iterated_local_search(d, start, end, int(config.kicks), deadline)
    return result(order, False, "heuristic" if method == "heuristic" else "heuristic (time limit)")


def band_path(positions, split_height: float | None = None, start_position=None, first: str = "upper",
              distance=None, config: TspConfig = TspConfig()) -> BandPathResult:
    """Greenhouse-row path: an open path in each height band, joined through a connection view.

    Views with ``z >= split_height`` form the upper band, the others the lower band
    (``split_height`` defaults to the median view height; pass the view box's mid height to
    split by the box). The ``first`` band is visited first, starting at the view nearest
    ``start_position`` (e.g. the end of the passive sweep; the leg is counted in the length) or,
    without one, at whichever view gives the shortest path. The connection view is the second
    band's view nearest the end of the first band's path; the second band's path starts there.
    ``distance`` (V, V) replaces the default Euclidean distances between positions.
    """
    t0 = time.perf_counter()
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] == 0:
        raise ConfigError(f"positions must be a non-empty (n, 3) array, got shape {pos.shape}")
    if not np.all(np.isfinite(pos)):
        raise ConfigError("positions contains NaN or infinite coordinates")
    if first not in ("upper", "lower"):
        raise ConfigError(f"first must be 'upper' or 'lower', got {first!r}")
    if distance is None:
        d = np.sqrt(((pos[:, None, :] - pos[None, :, :]) ** 2).sum(axis=-1))
    else:
        d = _as_distance(distance)
        if d.shape[0] != pos.shape[0]:
            raise ConfigError(f"distance must be ({pos.shape[0]}, {pos.shape[0]}) to match positions, got {d.shape}")
    split = float(np.median(pos[:, 2])) if split_height is None else float(split_height)
    if not np.isfinite(split):
        raise ConfigError(f"split_height must be finite, got {split_height!r}")
    start_pt = None
    if start_position is not None:
        start_pt = np.asarray(start_position, dtype=np.float64)
        if start_pt.size != 3 or not np.all(np.isfinite(start_pt)):
            raise ConfigError(f"start_position must be 3 finite coordinates, got {start_position!r}")
        start_pt = start_pt.reshape(3)
    upper = np.flatnonzero(pos[:, 2] >= split)
    lower = np.flatnonzero(pos[:, 2] < split)
    bands = [upper, lower] if first == "upper" else [lower, upper]
    if bands[0].size == 0:
        bands = [bands[1], bands[0]]

    optimal = True
    legs = 0.0
    band_lengths = [0.0, 0.0]
    band_bounds = [0.0, 0.0]
    visited = []
    entry_pt = start_pt
    connection = -1
    for b, members in enumerate(bands):
        if members.size == 0:
            continue
        sub = d[np.ix_(members, members)]
        if b == 0 and entry_pt is None:
            # Free start: a virtual node at zero distance to every view of the band.
            aug = np.zeros((members.size + 1, members.size + 1))
            aug[1:, 1:] = sub
            res = shortest_open_path(aug, 0, config=config)
            local = res.order[1:] - 1
        else:
            if b == 0:
                first_view = int(np.argmin(np.linalg.norm(pos[members] - entry_pt, axis=1)))
                legs += float(np.linalg.norm(pos[members[first_view]] - entry_pt))
            else:
                # Connection view: the band's view nearest the end of the previous band's path.
                first_view = int(np.argmin(d[visited[-1], members]))
                connection = int(members[first_view])
                legs += float(d[visited[-1], connection])
            res = shortest_open_path(sub, first_view, config=config)
            local = res.order
        optimal &= res.optimal
        band_lengths[b] = res.length
        if res.optimal:
            band_bounds[b] = res.length
        elif config.bound_iterations > 0:
            problem, root = (aug, 0) if (b == 0 and entry_pt is None) else (sub, first_view)
            band_bounds[b] = open_path_lower_bound(problem, root, iterations=int(config.bound_iterations),
                                                   upper=res.length).bound
            # More perturbation rounds from the best path while the gap is above the target and the
            # band's time lasts (each round a new fixed seed: still deterministic given the budget).
            order, rounds = res.order, 0
            band_deadline = time.perf_counter() + float(config.band_seconds) - res.solve_seconds
            while (path_length(problem, order) - band_bounds[b] > config.band_gap * path_length(problem, order)
                   and time.perf_counter() < band_deadline):
                rounds += 1
                order = _iterated_local_search(problem, root, None, int(config.kicks), band_deadline,
                                               initial=order, seed=rounds)
            band_lengths[b] = path_length(problem, order)
            local = order[1:] - 1 if (b == 0 and entry_pt is None) else order
        else:
            band_bounds[b] = float("nan")
        visited.extend(members[local].tolist())
    length = legs + sum(band_lengths)
    bound = legs + sum(band_bounds)

    def rel_gap(total, lower):
        if np.isnan(lower):
            return float("nan")
        return 0.0 if total <= 0 else max(0.0, (total - lower) / total)

    order = np.asarray(visited, dtype=np.int64)
    split_bands = tuple(order[np.isin(order, m)] for m in bands)
    return BandPathResult(order=order, length=float(length), optimal=bool(optimal),
                          solve_seconds=time.perf_counter() - t0, bands=split_bands,
                          connection_view=connection, split_height=split,
                          band_lengths=tuple(band_lengths), band_bounds=tuple(band_bounds),
                          band_gaps=tuple(rel_gap(t, lo) for t, lo in zip(band_lengths, band_bounds)),
                          bound=float(bound), gap=rel_gap(length, bound))
