"""Lower bound on the shortest open path from a fixed start (free end): Held-Karp 1-tree bound.

Used to report an optimality gap for the heuristic band paths (``band_path``).

Relaxation. Join a dummy node D to every node at cost 0. An open path ``start -> ... -> end``
through all n nodes plus the edges ``end - D`` and ``D - start`` is a Hamiltonian cycle of the
augmented graph that uses the edge ``D - start``; such a cycle is a *1-tree*: a spanning tree on
the n original nodes (the path) plus two edges at D, one of them to ``start``. The cheapest such
1-tree is a minimum spanning tree on the original nodes, plus ``D - start``, plus D's cheapest
other edge. With node penalties ``pi`` (edge ``i - j`` costs ``c_ij + pi_i + pi_j``, D's penalty
is 0 since D's degree is always 2) every 1-tree weight minus ``2 * sum(pi)`` is a lower bound on
every path (weak Lagrangian duality: on a Hamiltonian cycle every node has degree 2, so the
penalties cancel). The penalties are raised by subgradient optimisation (``pi += t * (deg - 2)``)
with the Polyak step ``t = lam * (upper - L) / |deg - 2|^2``; ``lam`` starts at 2 and halves when
the bound stops improving. The best bound seen is returned: it is valid for any ``pi``.

Asymmetric distances are relaxed to ``min(d_ij, d_ji)``: any path costs at least that much.
The spanning tree is a dense O(n^2) Prim in numba (n up to a few hundred).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numba import njit

from tpvp.errors import ConfigError


@dataclass(frozen=True)
class BoundResult:
    """Lower bound on the shortest open path from ``start``."""

    bound: float  # valid lower bound on the length of every open path from start through all nodes
    iterations: int  # subgradient iterations run
    seconds: float


@njit(cache=True)
def _one_tree(c, pi, start, deg):
    """Weight of the cheapest penalised 1-tree (Prim on the n nodes + two edges at the dummy).

    Fills ``deg`` with the node degrees in the 1-tree (the dummy's two edges included).
    """
    n = c.shape[0]
    for i in range(n):
        deg[i] = 0
    in_tree = np.zeros(n, dtype=np.bool_)
    best = np.empty(n)
    parent = np.zeros(n, dtype=np.int64)
    for j in range(n):
        best[j] = np.inf
    best[0] = 0.0
    total = 0.0
    for _ in range(n):
        u = -1
        bu = np.inf
        for j in range(n):
            if not in_tree[j] and best[j] < bu:
                bu = best[j]
                u = j
        in_tree[u] = True
        if u != 0:
            total += bu
            deg[u] += 1
            deg[parent[u]] += 1
        pu = pi[u]
        for j in range(n):
            if not in_tree[j]:
                w = c[u, j] + pu + pi[j]
                if w < best[j]:
                    best[j] = w
                    parent[j] = u
    # Dummy node: edge to start (forced) and its cheapest other edge (cost 0 + pi_j).
    total += pi[start]
    deg[start] += 1
    k = -1
    bk = np.inf
    for j in range(n):
        if j != start and pi[j] < bk:
            bk = pi[j]
            k = j
    total += bk
    deg[k] += 1
    s = 0.0
    for j in range(n):
        s += pi[j]
    return total - 2.0 * s


@njit(cache=True)
def _subgradient(c, start, iterations, upper):
    n = c.shape[0]
    pi = np.zeros(n)
    deg = np.zeros(n, dtype=np.int64)
    best = -np.inf
    lam = 2.0
    stall = 0
    patience = max(20, min(100, n // 4))
    it = 0
    while it < iterations:
        it += 1
        value = _one_tree(c, pi, start, deg)
        if value > best + 1e-12 * abs(best if np.isfinite(best) else 1.0):
            best = value
            stall = 0
        else:
            stall += 1
            if stall >= patience:
                lam *= 0.5
                stall = 0
                if lam < 1e-5:
                    break
        norm = 0.0
        for j in range(n):
            g = deg[j] - 2
            norm += g * g
        if norm == 0.0:  # the 1-tree is a Hamiltonian cycle: the bound is the optimum
            break
        gap = upper - value
        if gap <= 1e-12 * abs(upper):
            break
        t = lam * gap / norm
        for j in range(n):
            pi[j] += t * (deg[j] - 2)
    return best, it


def _nn_length(c: np.ndarray, start: int) -> float:
    n = c.shape[0]
    seen = np.zeros(n, dtype=bool)
    seen[start] = True
    u, total = start, 0.0
    for _ in range(n - 1):
        row = np.where(seen, np.inf, c[u])
        v = int(np.argmin(row))
        total += float(row[v])
        seen[v] = True
        u = v
    return total


def open_path_lower_bound(distance, start: int, iterations: int = 1000,
                          upper: float | None = None) -> BoundResult:
    """Held-Karp lower bound on the shortest open path from ``start`` through every node (free end).

    ``distance``: (n, n) finite matrix (asymmetric entries are relaxed to ``min(d_ij, d_ji)``);
    ``iterations``: subgradient iterations (at most); ``upper``: a known path length (e.g. the
    heuristic's) for the Polyak step, a nearest-neighbour path when omitted. The bound never
    exceeds the true optimum (up to floating-point rounding) and is clipped at ``upper``.
    """
    t0 = time.perf_counter()
    d = np.asarray(distance, dtype=np.float64)
    if d.ndim != 2 or d.shape[0] != d.shape[1] or d.shape[0] == 0:
        raise ConfigError(f"distance must be a non-empty square (n, n) matrix, got shape {d.shape}")
    if not np.all(np.isfinite(d)):
        raise ConfigError("distance contains NaN or infinite entries")
    if np.any(d < 0):
        raise ConfigError("distance must be non-negative")
    n = d.shape[0]
    if isinstance(start, (bool, np.bool_)) or not isinstance(start, (int, np.integer)) or not 0 <= int(start) < n:
        raise ConfigError(f"start must be an integer node index in [0, {n}), got {start!r}")
    if isinstance(iterations, (bool, np.bool_)) or not isinstance(iterations, (int, np.integer)) or iterations < 1:
        raise ConfigError(f"iterations must be an integer >= 1, got {iterations!r}")
    if upper is not None and not (np.isfinite(upper) and upper >= 0):
        raise ConfigError(f"upper must be a finite length >= 0, got {upper!r}")
    start = int(start)
    if n == 1:
        return BoundResult(bound=0.0, iterations=0, seconds=time.perf_counter() - t0)
    c = np.minimum(d, d.T)
    np.fill_diagonal(c, 0.0)
    c = np.ascontiguousarray(c)
    ub = _nn_length(c, start) if upper is None else float(upper)
    best, it = _subgradient(c, start, int(iterations), ub)
    bound = max(0.0, float(best))
    if upper is not None:
        bound = min(bound, float(upper))
    return BoundResult(bound=bound, iterations=int(it), seconds=time.perf_counter() - t0)
