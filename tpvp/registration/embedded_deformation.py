"""Embedded-deformation non-rigid registration of the previous session P onto the current coarse
reconstruction Q (paper "Non-Rigid Registration", individual plants; a port of the authors'
``single_plant/Nonrigid_ICP``, see docs/single_plant.md#registration).

Model: nodes g_j (voxel-downsampled P), per node an axis-angle rotation phi_j (R_j = Exp(phi_j),
Rodrigues) and a translation t_j; every point is blended from its K_a nearest nodes,
``x~ = sum_k w_k (R_k (x - g_k) + g_k + t_k)``. Adam minimises
``w_arap L_arap + w_chamfer L_cd (+ w_laplacian L_lap)``.

Reference behaviour kept on purpose (defaults reproduce the authors' code, not the paper's prose):

* nodes are the *centroids* of the points in each ``node_coverage`` voxel (Open3D
  ``voxel_down_sample``), not voxel centres as the paper says;
* edges: each node's k nearest other nodes, directed (not symmetrised), weights 1/(d + 1e-8)
  normalised per node; ARAP term = mean over all M*k arcs of w_ij |R_i(g_j-g_i)+g_i+t_i-(g_j+t_j)|^2;
* anchor weights exp(-d^2 / sigma^2) with sigma = 1.5 * node_coverage (no factor 2), normalised;
* Chamfer loss: fresh random 1000-point subsets of P~ and Q every iteration, squared distances,
  *sum* of the two directed means, terms with d^2 >= 0.3 m^2 zeroed but still counted;
  duplicate points in Q are kept (voxels seen by two views weigh twice);
* the Laplacian ("membrane", 1000-point subset, K = 8, sigma = median kNN distance) is evaluated
  without gradient: it only changes the recorded loss (``laplacian_in_gradient=True`` makes it act,
  with its weights held constant);
* Adam (lr 1e-3) on (phi, t) with ExponentialLR(0.999) stepped every iteration, 300 iterations,
  stop if the total loss drops below 1e-7; the axis-angle vector is never re-linearised.

Deviations (fixes):

* the returned cloud is the warp of the *final* parameters; the reference returns the warp
  computed at the start of its last iteration (one optimiser step earlier);
* deterministic: the random subsets come from ``numpy.random.default_rng(config.seed)``;
* each iteration warps only the sampled points (the losses never look at the others), which is
  exactly equivalent to the reference's warp-everything-then-sample and makes the cost independent
  of N; all N points are warped once at the end. No downsampling of P is needed;
* the blend and the ARAP residual are evaluated in displacement form
  (x + sum_k w_k ((R_k - I)(x - g_k) + t_k), using sum_k w_k = 1): same maths, but zero parameters
  reproduce P bit for bit. In the reference's form rounding leaves ~1e-18 gradients at the identity,
  which Adam's per-coordinate normalisation turns into ~lr = 1 mm steps;
* Adam and the exponential decay are written out in numpy (:class:`_Adam`; torch.optim's numbers up
  to the rounding of its fused multiply-adds, ~1e-15, checked by a test), so registering never
  imports torch (~2 s of a command's start-up; torch.optim's first use imports torch._dynamo too);
* the losses and their gradient are computed by hand (numba kernels, one iteration in
  :func:`_loss_and_gradient`), not by torch autograd: with ~1000-point tensors the reference
  spent its 10 ms per iteration on per-op and autograd overhead and on scipy KD-tree queries.
  Same maths (Rodrigues and its derivative, the displacement-form blend, ARAP, truncated Chamfer
  with the nearest neighbours held fixed, the Laplacian with its weights held constant), same
  random subsets, same Adam, same stop rule: the result equals the autograd implementation
  (:func:`tpvp.registration.autograd_reference.optimise_autograd`, kept as the tests' oracle) up to rounding (~1e-17 m
  on the benchmark pairs after 300 iterations). The nearest neighbours come from an exact uniform
  grid search instead of scipy's KD-tree (:func:`_grid_knn`; among points at exactly equal
  distance it may pick another one: the same loss value, the gradient goes to the other point).
  A benchmark pair (~1000 nodes, 300 iterations) takes ~0.8-1.2 s instead of 3-6 s on a
  shared 2-core machine (``benchmarks/registration_bench.py``); ~3/4 of it is the iterations, of
  which the nearest-neighbour searches are ~60 %. The Laplacian is still evaluated every
  iteration (~40 % of one), since it enters the recorded losses and the stop test. The kernels
  are compiled once per machine and source version (numba cache, ~3.5 s) and loaded in ~0.05 s
  by a process's first call (:func:`compile_kernels` does that up front);
* float64 throughout (reference float32); inputs are checked (empty, NaN, units, overlap);
* if every anchor weight of a point underflows (impossible at the default settings) the point
  follows its nearest node instead of becoming NaN.

Known limit of the reference settings (kept): the 1000-point Chamfer subsets are ~3 mm apart on
the surface, so the gradient is noisy and Adam keeps moving nodes by ~lr per step. On a generated
tomato warped by a known 3.7 mm (mean) bend + twist the result is ~1.0 mm mean error; two
different samplings of an *undeformed* surface end ~1 mm apart. ``lr_decay=0.99`` gives ~0.7 mm.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from tpvp.errors import ConfigError, GraphTooLargeError, PointCloudError, checked_cloud
from tpvp.io.units import MM_EXTENT_THRESHOLD
from tpvp.metrics.geometry import chamfer_distance
from tpvp.numba_tools import JIT
from tpvp.registration.config import EDConfig
from tpvp.registration.warp_field import too_many_nodes
from tpvp.scene import voxels

# Clouds whose largest sides differ by more than this factor are assumed to be in different units.
_UNIT_RATIO = 50.0


@dataclass(frozen=True)
class RegistrationResult:
    """Output of :func:`register_embedded_deformation`.

    warped: (N, 3) float64, P warped by the final parameters. chamfer_before/after: symmetric
    mean-distance Chamfer (m) of P resp. P~ to Q (``tpvp.metrics.chamfer_distance``).
    iterations: optimiser steps taken. seconds: wall time of graph + optimisation + final warp
    (not the Chamfer reporting). nodes (M, 3), rotations (M, 3, 3), translations (M, 3): the
    deformation graph. losses: total loss per iteration, evaluated before its step; loss_terms:
    (iterations, 3) unweighted ARAP, Chamfer, Laplacian.
    """

    warped: np.ndarray
    chamfer_before: float
    chamfer_after: float
    iterations: int
    seconds: float
    nodes: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    losses: np.ndarray
    loss_terms: np.ndarray
    config: EDConfig = field(default_factory=EDConfig)

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    def warp(self, points) -> np.ndarray:
        """Apply the estimated deformation to other points (anchored on the same graph)."""
        points = checked_cloud(points, "points to warp")
        idx, w = _anchors(self.nodes, points, self.config)
        return _warp_numpy(points, self.nodes, self.rotations, self.translations, idx, w)


# --------------------------------------------------------------------------------------------------
# input checks
# --------------------------------------------------------------------------------------------------


def _check_pair(P: np.ndarray, Q: np.ndarray, node_coverage: float) -> None:
    """Refuse pairs that ED cannot register: different units, or clouds that do not overlap."""
    size_p, size_q = np.ptp(P, axis=0).max(), np.ptp(Q, axis=0).max()
    small, large = sorted((size_p, size_q))
    if small > 0 and large / small > _UNIT_RATIO:
        raise PointCloudError(
            f"the previous session spans {size_p:.4g} m and the current (coarse) cloud {size_q:.4g} m "
            f"(largest bounding-box side), a factor {large / small:.0f} apart: they look like different "
            f"units (mm vs m?); convert both to metres")
    size = max(size_p, size_q)
    if size > MM_EXTENT_THRESHOLD:  # the project's mm detection rule (tpvp.io.detect_units)
        raise PointCloudError(
            f"the clouds span {size:.4g} (largest bounding-box side), more than {MM_EXTENT_THRESHOLD:g} m: "
            f"they look like millimetres; registration expects metres (tpvp.io.to_metres)")
    size = max(size, 5 * node_coverage)  # degenerate (tiny) clouds: a few graph nodes of slack
    gap = np.maximum(0.0, np.maximum(P.min(0) - Q.max(0), Q.min(0) - P.max(0)))
    gap = float(np.linalg.norm(gap))
    centre_dist = float(np.linalg.norm(P.mean(0) - Q.mean(0)))
    # ED only corrects local deformations (Adam moves ~1 mm per step): the clouds must already
    # share a frame. A 20% margin tolerates a grown or partial Q next to P.
    if gap > 0.2 * size or centre_dist > 10 * size:
        raise PointCloudError(
            f"the previous session and the current (coarse) cloud do not overlap: their bounding boxes are "
            f"{gap:.4g} m apart and their centroids {centre_dist:.4g} m apart for a plant of {size:.4g} m; bring "
            f"both into one frame first (coarse/rigid alignment) and check that both are in metres")


# --------------------------------------------------------------------------------------------------
# graph
# --------------------------------------------------------------------------------------------------


def _edges(nodes: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Each node's k nearest other nodes and their normalised inverse-distance weights."""
    k = min(k, len(nodes) - 1)
    if k < 1:
        return np.zeros((len(nodes), 0), np.int64), np.zeros((len(nodes), 0))
    d, idx = cKDTree(nodes).query(nodes, k=k + 1)
    # centroids of distinct voxels are distinct, so column 0 is the node itself
    d, idx = d[:, 1:], idx[:, 1:]
    w = 1.0 / (d + 1e-8)
    return idx.astype(np.int64), w / w.sum(axis=1, keepdims=True)


def _anchors(nodes: np.ndarray, points: np.ndarray, config: EDConfig) -> tuple[np.ndarray, np.ndarray]:
    """K_a nearest nodes of every point and their normalised Gaussian weights exp(-d^2/sigma^2)."""
    k = min(config.k_anchors, len(nodes))
    d, idx = cKDTree(nodes).query(points, k=k)
    d, idx = d.reshape(len(points), k), idx.reshape(len(points), k)
    w = np.exp(-(d**2) / config.anchor_sigma**2)
    total = w.sum(axis=1, keepdims=True)
    dead = total[:, 0] <= 0
    if dead.any():  # all weights underflowed: follow the nearest node rather than divide by 0
        w[dead] = 0.0
        w[dead, 0] = 1.0
        total[dead] = 1.0
    return idx.astype(np.int64), w / total


_WARP_CHUNK = 32768  # points per block of the final warp: (block, k, 3, 3) temporaries stay ~10 MB


def _warp_numpy(points, nodes, rotations, translations, idx, w) -> np.ndarray:
    # x~ = x + sum_k w_k ((R_k - I)(x - g_k) + t_k): the ED blend rewritten with sum_k w_k = 1, so
    # zero parameters give x back bit for bit (Adam would amplify rounding noise into 1 mm steps).
    # Done in blocks of points: every row is computed exactly as in one go (same numbers), but the
    # (N, k, 3, 3) gathered rotations no longer cost N * 288 bytes at once (1.4 GB for 5 M points).
    out = np.empty((len(points), 3), dtype=np.result_type(points, nodes, rotations, translations, w))
    for start in range(0, len(points), _WARP_CHUNK):
        block = slice(start, start + _WARP_CHUNK)
        p, i = points[block], idx[block]
        local = p[:, None, :] - nodes[i]  # (n, k, 3)
        moved = np.einsum("nkij,nkj->nki", rotations[i], local) - local + translations[i]
        out[block] = p + np.einsum("nk,nki->ni", w[block], moved)
    return out


# --------------------------------------------------------------------------------------------------
# numba kernels: one optimisation iteration (losses + analytic gradient) and a grid k-NN
# --------------------------------------------------------------------------------------------------

_JIT = dict(JIT, error_model="numpy")  # numpy semantics: 0/0 is NaN (as in torch), no raise


@njit(**_JIT)
def _grid_build(ref):
    """Uniform grid over ``ref`` (n, 3) for k-NN queries: origin, cell size, cells per axis, CSR
    cell starts and the points sorted by cell. About one cell per point of the bounding box volume
    (a plant surface then has a few points per occupied cell)."""
    n = ref.shape[0]
    lo = np.empty(3)
    ext = np.empty(3)
    for a in range(3):
        lo[a] = ref[0, a]
        hi = ref[0, a]
        for i in range(1, n):
            v = ref[i, a]
            if v < lo[a]:
                lo[a] = v
            if v > hi:
                hi = v
        ext[a] = hi - lo[a]
    emax = max(ext[0], max(ext[1], ext[2]))
    if emax > 0:
        vol = 1.0
        for a in range(3):
            vol *= max(ext[a], 1e-3 * emax)  # flat clouds: keep the cells finite
        h = (vol / n) ** (1.0 / 3.0)
    else:
        h = 1.0
    dims = np.empty(3, np.int64)
    while True:
        for a in range(3):
            dims[a] = int(ext[a] / h) + 1
        if dims[0] * dims[1] * dims[2] <= 4 * n + 64:
            break
        h *= 1.25
    cell = np.empty(n, np.int64)
    start = np.zeros(dims[0] * dims[1] * dims[2] + 1, np.int64)
    for i in range(n):
        key = 0
        for a in range(3):
            c = int((ref[i, a] - lo[a]) / h)
            c = min(max(c, 0), dims[a] - 1)
            key = key * dims[a] + c
        cell[i] = key
        start[key + 1] += 1
    for c in range(1, start.shape[0]):
        start[c] += start[c - 1]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[cell[i]]] = i
        fill[cell[i]] += 1
    pts = np.empty((n, 3))
    for j in range(n):
        for a in range(3):
            pts[j, a] = ref[order[j], a]
    return lo, h, dims, start, order, pts


@njit(**_JIT, inline="always")
def _scan_cell(q, pts, order, start, cell, s, k, out_idx, out_d2):
    """Insert the points of one grid cell into query s's sorted k best (strictly closer only)."""
    for j in range(start[cell], start[cell + 1]):
        dx = q[0] - pts[j, 0]
        dy = q[1] - pts[j, 1]
        dz = q[2] - pts[j, 2]
        d2 = dx * dx + dy * dy + dz * dz
        if d2 < out_d2[s, k - 1]:
            m = k - 1
            while m > 0 and out_d2[s, m - 1] > d2:
                out_d2[s, m] = out_d2[s, m - 1]
                out_idx[s, m] = out_idx[s, m - 1]
                m -= 1
            out_d2[s, m] = d2
            out_idx[s, m] = order[j]


@njit(**_JIT)
def _grid_knn(ref, queries, k, out_idx, out_d2):
    """The k nearest points of ``ref`` to each query, ascending squared distance: out_idx, out_d2
    (nq, k). Exact: rings of cells around the query's cell are scanned until no unscanned cell can
    hold a closer point (equal distances keep the first found; k <= len(ref)). A cell no closer
    than the k-th found so far is skipped: none of its points could enter, now or later, so the
    result is that of scanning it."""
    lo, h, dims, start, order, pts = _grid_build(ref)
    margin = 1e-9 * h  # rounding of the cell indices: stop or skip only when clearly done
    c = np.empty(3, np.int64)
    q = np.empty(3)
    for s in range(queries.shape[0]):
        for j in range(k):
            out_d2[s, j] = np.inf
            out_idx[s, j] = -1
        for a in range(3):
            q[a] = queries[s, a]
            ca = int(np.floor((q[a] - lo[a]) / h))
            c[a] = min(max(ca, 0), dims[a] - 1)
        r = 0
        while True:
            for ix in range(max(c[0] - r, 0), min(c[0] + r, dims[0] - 1) + 1):
                edge_x = abs(ix - c[0]) == r
                gap = max(lo[0] + ix * h - q[0], q[0] - (lo[0] + (ix + 1) * h), 0.0)
                gx2 = max(gap - margin, 0.0) ** 2  # squared distance to the slab of cells ix
                if gx2 >= out_d2[s, k - 1]:
                    continue
                for iy in range(max(c[1] - r, 0), min(c[1] + r, dims[1] - 1) + 1):
                    gap = max(lo[1] + iy * h - q[1], q[1] - (lo[1] + (iy + 1) * h), 0.0)
                    gxy2 = gx2 + max(gap - margin, 0.0) ** 2
                    if gxy2 >= out_d2[s, k - 1]:
                        continue
                    base = (ix * dims[1] + iy) * dims[2]
                    face = edge_x or abs(iy - c[1]) == r  # a face of the ring: the whole column
                    first, last = max(c[2] - r, 0), min(c[2] + r, dims[2] - 1)
                    iz = first if face else c[2] - r  # inside the ring's shadow: the column's two end cells
                    while iz <= last:
                        if iz >= 0 and start[base + iz] < start[base + iz + 1]:
                            gap = max(lo[2] + iz * h - q[2], q[2] - (lo[2] + (iz + 1) * h), 0.0)
                            if gxy2 + max(gap - margin, 0.0) ** 2 < out_d2[s, k - 1]:
                                _scan_cell(q, pts, order, start, base + iz, s, k, out_idx, out_d2)
                        iz += 1 if face else 2 * r
            # every unscanned cell lies beyond a face of the scanned block: bound its distance
            lb = np.inf
            for a in range(3):
                if c[a] - r > 0:
                    lb = min(lb, q[a] - (lo[a] + (c[a] - r) * h))
                if c[a] + r + 1 < dims[a]:
                    lb = min(lb, lo[a] + (c[a] + r + 1) * h - q[a])
            if lb == np.inf:
                break  # the whole grid was scanned
            lb = max(lb - margin, 0.0)
            if out_d2[s, k - 1] <= lb * lb:
                break
            r += 1


@njit(**_JIT, inline="always")
def _rodrigues_coefficients(theta2):
    """``(a, b, a', b')``: R = I + a K + b K^2 for theta^2 = |phi|^2, and d(a, b)/d theta^2 (series
    below 1e-8, where the closed forms lose precision)."""
    if theta2 < 1e-8:
        return (1.0 - theta2 / 6.0 + theta2**2 / 120.0, 0.5 - theta2 / 24.0 + theta2**2 / 720.0,
                -1.0 / 6.0 + 2.0 * theta2 / 120.0, -1.0 / 24.0 + 2.0 * theta2 / 720.0)
    th = np.sqrt(theta2)
    s, c = np.sin(th), np.cos(th)
    return (s / th, (1.0 - c) / th**2, (c / th - s / th**2) / (2.0 * th),
            (s / th**2 - 2.0 * (1.0 - c) / th**3) / (2.0 * th))


@njit(**_JIT)
def _rodrigues(phi, R, da, db):
    """R = I + a [phi]x + b [phi]x^2 (as the torch reference's ``axis_angle_to_matrix``) and
    a', b' = d(a, b)/d theta^2."""
    for m in range(phi.shape[0]):
        x, y, z = phi[m, 0], phi[m, 1], phi[m, 2]
        a, b, da[m], db[m] = _rodrigues_coefficients(x * x + y * y + z * z)
        # K = [[0, -z, y], [z, 0, -x], [-y, x, 0]]; K @ K = phi phi^T - theta2 I
        R[m, 0, 0] = 1.0 + b * (-(y * y) - z * z)
        R[m, 0, 1] = a * -z + b * (x * y)
        R[m, 0, 2] = a * y + b * (x * z)
        R[m, 1, 0] = a * z + b * (x * y)
        R[m, 1, 1] = 1.0 + b * (-(x * x) - z * z)
        R[m, 1, 2] = a * -x + b * (y * z)
        R[m, 2, 0] = a * -y + b * (x * z)
        R[m, 2, 1] = a * x + b * (y * z)
        R[m, 2, 2] = 1.0 + b * (-(x * x) - y * y)


@njit(**_JIT)
def _rodrigues_backward(phi, gR, da, db, g_phi):
    """dL/dphi from dL/dR: R = I + a K + b K^2 with a, b functions of theta2 = |phi|^2.

    dL/dphi_m = 2 phi_m (a' <G, K> + b' <G, K^2>) + a <G, E_m> + b <G, E_m K + K E_m>, E_m = dK/dphi_m;
    <H, E_m> = (H21 - H12, H02 - H20, H10 - H01) and <G, E_m K + K E_m> = <-(G K + K G), E_m>.
    """
    K = np.empty((3, 3))
    for m in range(phi.shape[0]):
        x, y, z = phi[m, 0], phi[m, 1], phi[m, 2]
        a, b, _, _ = _rodrigues_coefficients(x * x + y * y + z * z)
        K[0, 0], K[0, 1], K[0, 2] = 0.0, -z, y
        K[1, 0], K[1, 1], K[1, 2] = z, 0.0, -x
        K[2, 0], K[2, 1], K[2, 2] = -y, x, 0.0
        G = gR[m]
        gk = 0.0  # <G, K>
        gk2 = 0.0  # <G, K^2>
        for i in range(3):
            for j in range(3):
                gk += G[i, j] * K[i, j]
                kk = K[i, 0] * K[0, j] + K[i, 1] * K[1, j] + K[i, 2] * K[2, j]
                gk2 += G[i, j] * kk
        # H = -(G K + K G), only its antisymmetric part is needed
        h21 = -(G[2, 0] * K[0, 1] + G[2, 1] * K[1, 1] + G[2, 2] * K[2, 1]
                + K[2, 0] * G[0, 1] + K[2, 1] * G[1, 1] + K[2, 2] * G[2, 1])
        h12 = -(G[1, 0] * K[0, 2] + G[1, 1] * K[1, 2] + G[1, 2] * K[2, 2]
                + K[1, 0] * G[0, 2] + K[1, 1] * G[1, 2] + K[1, 2] * G[2, 2])
        h02 = -(G[0, 0] * K[0, 2] + G[0, 1] * K[1, 2] + G[0, 2] * K[2, 2]
                + K[0, 0] * G[0, 2] + K[0, 1] * G[1, 2] + K[0, 2] * G[2, 2])
        h20 = -(G[2, 0] * K[0, 0] + G[2, 1] * K[1, 0] + G[2, 2] * K[2, 0]
                + K[2, 0] * G[0, 0] + K[2, 1] * G[1, 0] + K[2, 2] * G[2, 0])
        h10 = -(G[1, 0] * K[0, 0] + G[1, 1] * K[1, 0] + G[1, 2] * K[2, 0]
                + K[1, 0] * G[0, 0] + K[1, 1] * G[1, 0] + K[1, 2] * G[2, 0])
        h01 = -(G[0, 0] * K[0, 1] + G[0, 1] * K[1, 1] + G[0, 2] * K[2, 1]
                + K[0, 0] * G[0, 1] + K[0, 1] * G[1, 1] + K[0, 2] * G[2, 1])
        common = 2.0 * (da[m] * gk + db[m] * gk2)
        g_phi[m, 0] = common * x + a * (G[2, 1] - G[1, 2]) + b * (h21 - h12)
        g_phi[m, 1] = common * y + a * (G[0, 2] - G[2, 0]) + b * (h02 - h20)
        g_phi[m, 2] = common * z + a * (G[1, 0] - G[0, 1]) + b * (h10 - h01)


@njit(**_JIT)
def _warp_subset(P, sel, a_idx, a_w, nodes, R, t, out):
    """out = the ED blend of P[sel] in displacement form (as :func:`_warp_numpy`)."""
    for s in range(sel.shape[0]):
        p = sel[s]
        acc0 = 0.0
        acc1 = 0.0
        acc2 = 0.0
        for kk in range(a_idx.shape[1]):
            n = a_idx[p, kk]
            w = a_w[p, kk]
            l0 = P[p, 0] - nodes[n, 0]
            l1 = P[p, 1] - nodes[n, 1]
            l2 = P[p, 2] - nodes[n, 2]
            acc0 += w * (R[n, 0, 0] * l0 + R[n, 0, 1] * l1 + R[n, 0, 2] * l2 - l0 + t[n, 0])
            acc1 += w * (R[n, 1, 0] * l0 + R[n, 1, 1] * l1 + R[n, 1, 2] * l2 - l1 + t[n, 1])
            acc2 += w * (R[n, 2, 0] * l0 + R[n, 2, 1] * l1 + R[n, 2, 2] * l2 - l2 + t[n, 2])
        out[s, 0] = P[p, 0] + acc0
        out[s, 1] = P[p, 1] + acc1
        out[s, 2] = P[p, 2] + acc2


@njit(**_JIT)
def _warp_backward(dX, P, sel, a_idx, a_w, nodes, gR, g_t):
    """Add the parameter gradient of sum_s <dX_s, warp(P[sel_s])>: dR_a += w dX l^T, dt_a += w dX."""
    for s in range(sel.shape[0]):
        p = sel[s]
        for kk in range(a_idx.shape[1]):
            n = a_idx[p, kk]
            w = a_w[p, kk]
            l0 = P[p, 0] - nodes[n, 0]
            l1 = P[p, 1] - nodes[n, 1]
            l2 = P[p, 2] - nodes[n, 2]
            for i in range(3):
                gi = w * dX[s, i]
                gR[n, i, 0] += gi * l0
                gR[n, i, 1] += gi * l1
                gR[n, i, 2] += gi * l2
                g_t[n, i] += gi


@njit(**_JIT, inline="always")
def _add_arc_gradient(gR, g_t, m, j, i, gi, g0, g1, g2):
    gR[m, i, 0] += gi * g0
    gR[m, i, 1] += gi * g1
    gR[m, i, 2] += gi * g2
    g_t[m, i] += gi
    g_t[j, i] -= gi


@njit(**_JIT)
def _arap(R, t, g_ij, e_idx, e_w, scale, gR, g_t):
    """ARAP loss mean over arcs of w_ij |R_i g_ij - g_ij + t_i - t_j|^2; adds scale * its gradient."""
    M, k = e_idx.shape
    if k == 0:
        return 0.0
    inv = 1.0 / (M * k)
    total = 0.0
    for m in range(M):
        for kk in range(k):
            j = e_idx[m, kk]
            w = e_w[m, kk]
            g0, g1, g2 = g_ij[m, kk, 0], g_ij[m, kk, 1], g_ij[m, kk, 2]
            r0 = R[m, 0, 0] * g0 + R[m, 0, 1] * g1 + R[m, 0, 2] * g2 - g0 + t[m, 0] - t[j, 0]
            r1 = R[m, 1, 0] * g0 + R[m, 1, 1] * g1 + R[m, 1, 2] * g2 - g1 + t[m, 1] - t[j, 1]
            r2 = R[m, 2, 0] * g0 + R[m, 2, 1] * g1 + R[m, 2, 2] * g2 - g2 + t[m, 2] - t[j, 2]
            total += w * (r0 * r0 + r1 * r1 + r2 * r2)
            c = 2.0 * scale * w * inv
            _add_arc_gradient(gR, g_t, m, j, 0, c * r0, g0, g1, g2)
            _add_arc_gradient(gR, g_t, m, j, 1, c * r1, g0, g1, g2)
            _add_arc_gradient(gR, g_t, m, j, 2, c * r2, g0, g1, g2)
    return total * inv


@njit(**_JIT)
def _directed_chamfer(X, Qs, x_idx, q_idx, truncation, dX):
    """Mean truncated squared distance over the pairs (X[x_idx[s]], Qs[q_idx[s]]); its gradient
    with respect to X is added to dX."""
    m = x_idx.shape[0]
    c = 2.0 / m
    total = 0.0
    for s in range(m):
        i, j = x_idx[s], q_idx[s]
        e0, e1, e2 = X[i, 0] - Qs[j, 0], X[i, 1] - Qs[j, 1], X[i, 2] - Qs[j, 2]
        d = e0 * e0 + e1 * e1 + e2 * e2
        if d < truncation:
            total += d
            dX[i, 0] += c * e0
            dX[i, 1] += c * e1
            dX[i, 2] += c * e2
    return total / m


def _chamfer(X, Qs, truncation, dX):
    """Two-sided truncated squared Chamfer of two subsets (sum of the directed means) and its
    gradient with respect to X (the NN choice held fixed, as autograd does). Python calling the
    kernels, as :func:`_loss_and_gradient`."""
    n, nq = X.shape[0], Qs.shape[0]
    idx, d2 = np.empty((n, 1), np.int64), np.empty((n, 1))
    _grid_knn(Qs, X, 1, idx, d2)
    idx_q, d2_q = np.empty((nq, 1), np.int64), np.empty((nq, 1))
    _grid_knn(X, Qs, 1, idx_q, d2_q)
    dX[:] = 0.0
    return (_directed_chamfer(X, Qs, np.arange(n), idx.reshape(n), truncation, dX)
            + _directed_chamfer(X, Qs, idx_q.reshape(nq), np.arange(nq), truncation, dX))


@njit(**_JIT)
def _kth_smallest(values, kth):
    """The kth smallest value (0-based) of a 1-D array, by quickselect on a copy."""
    a = values.copy()
    lo, hi = 0, a.shape[0] - 1
    while lo < hi:
        pivot = a[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while a[i] < pivot:
                i += 1
            while a[j] > pivot:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
        if kth <= j:
            hi = j
        elif kth >= i:
            lo = i
        else:
            break
    return a[kth]


def _laplacian(X, k, dX):
    """Membrane Laplacian of a subset (mean of W_ij |x_i - x_j|^2 over its k-NN graph, W held
    constant) and, in dX, its gradient. Python calling the kernels, as :func:`_loss_and_gradient`."""
    n = X.shape[0]
    dX[:] = 0.0
    k = min(k, n - 1)
    if k < 1:
        return 0.0
    idx, d2 = np.empty((n, k + 1), np.int64), np.empty((n, k + 1))
    _grid_knn(X, X, k + 1, idx, d2)
    return _laplacian_terms(X, idx, d2, k, dX)


@njit(**_JIT)
def _laplacian_terms(X, idx, d2, k, dX):
    """:func:`_laplacian` given the k + 1 nearest neighbours of every point (``idx``, ``d2``)."""
    n = X.shape[0]
    # drop column 0, the closest (the point itself, or one copy of a duplicate: the same values)
    d = np.empty(n * k)
    for i in range(n):
        for kk in range(k):
            d[i * k + kk] = np.sqrt(d2[i, kk + 1])  # the distance cKDTree reports
    sigma = max(_kth_smallest(d, (n * k - 1) // 2), 1e-12)  # torch.median: the lower median
    two_s2 = 2 * sigma**2
    W = np.empty(k)
    total = 0.0
    c = 2.0 / (n * k)
    for i in range(n):
        wsum = 0.0
        for kk in range(k):
            W[kk] = np.exp(-(d[i * k + kk] ** 2) / two_s2)
            wsum += W[kk]
        for kk in range(k):
            j = idx[i, kk + 1]
            w = W[kk] / wsum
            e0, e1, e2 = X[i, 0] - X[j, 0], X[i, 1] - X[j, 1], X[i, 2] - X[j, 2]
            total += w * (e0 * e0 + e1 * e1 + e2 * e2)
            g0, g1, g2 = c * w * e0, c * w * e1, c * w * e2
            dX[i, 0] += g0
            dX[i, 1] += g1
            dX[i, 2] += g2
            dX[j, 0] -= g0
            dX[j, 1] -= g1
            dX[j, 2] -= g2
    return total / (n * k)


def _loss_and_gradient(phi, t, P, Q, nodes, a_idx, a_w, e_idx, e_w, g_ij, sel_p, sel_q, sel_l,
                       w_arap, w_chamfer, w_laplacian, laplacian_in_gradient, laplacian_k, truncation,
                       g_phi, g_t):
    """One iteration: the unweighted (ARAP, Chamfer, Laplacian) losses at (phi, t), and the gradient
    of the weighted total (the Laplacian only if ``laplacian_in_gradient``) in g_phi, g_t.

    Python calling the kernels: as one numba kernel it cost a second more to compile on a cold
    cache (numba compiles every kernel a kernel calls once more, inside the caller), for ~20 ms
    less per 300 iterations (~3 % of a registration)."""
    M = phi.shape[0]
    R = np.empty((M, 3, 3))
    da = np.empty(M)
    db = np.empty(M)
    _rodrigues(phi, R, da, db)
    gR = np.zeros((M, 3, 3))
    g_t[:] = 0.0
    l_arap = _arap(R, t, g_ij, e_idx, e_w, w_arap, gR, g_t)
    X = np.empty((sel_p.shape[0], 3))
    _warp_subset(P, sel_p, a_idx, a_w, nodes, R, t, X)
    Qs = Q[sel_q]
    dX = np.empty_like(X)
    l_cd = _chamfer(X, Qs, truncation, dX)
    dX *= w_chamfer
    _warp_backward(dX, P, sel_p, a_idx, a_w, nodes, gR, g_t)
    Xl = np.empty((sel_l.shape[0], 3))
    _warp_subset(P, sel_l, a_idx, a_w, nodes, R, t, Xl)
    dXl = np.empty_like(Xl)
    l_lap = _laplacian(Xl, laplacian_k, dXl)
    if laplacian_in_gradient:
        dXl *= w_laplacian
        _warp_backward(dXl, P, sel_l, a_idx, a_w, nodes, gR, g_t)
    _rodrigues_backward(phi, gR, da, db, g_phi)
    return l_arap, l_cd, l_lap


# --------------------------------------------------------------------------------------------------
# main entry point
# --------------------------------------------------------------------------------------------------


def register_embedded_deformation(P, Q, config: EDConfig | None = None, optimise=None) -> RegistrationResult:
    """Warp the previous-session cloud P (N, 3) onto the current coarse reconstruction Q (metres).

    Both clouds must already share a frame (no rigid pre-alignment is done). Returns the warp of
    the final parameters (the reference returns the one of the start of its last iteration).
    ``optimise``: the optimiser, by default the analytic-gradient one (numba);
    :func:`tpvp.registration.autograd_reference.optimise_autograd` is the torch-autograd reference
    that tests and ``benchmarks/registration_bench.py`` compare it with.
    """
    optimise = _optimise if optimise is None else optimise
    config = EDConfig() if config is None else config
    if not isinstance(config, EDConfig):
        raise ConfigError(f"config must be an EDConfig, got {type(config).__name__}")
    P = checked_cloud(P, "source cloud P")
    Q = checked_cloud(Q, "target cloud Q")
    _check_pair(P, Q, config.node_coverage)
    start = time.perf_counter()
    nodes = voxels.voxel_centroids(P, config.node_coverage)
    if len(nodes) > config.max_nodes:
        raise GraphTooLargeError(too_many_nodes(len(nodes), config.max_nodes, config.node_coverage,
                                                "registration.embedded_deformation", "node_coverage",
                                                "deformation-graph"))
    edge_idx, edge_w = _edges(nodes, config.k_edges)
    anchor_idx, anchor_w = _anchors(nodes, P, config)
    R, t, losses, terms = optimise(P, Q, nodes, edge_idx, edge_w, anchor_idx, anchor_w, config)
    warped = _warp_numpy(P, nodes, R, t, anchor_idx, anchor_w)
    seconds = time.perf_counter() - start
    return RegistrationResult(
        warped=warped, chamfer_before=float(chamfer_distance(P, Q)),
        chamfer_after=float(chamfer_distance(warped, Q)), iterations=len(losses), seconds=seconds,
        nodes=nodes, rotations=R, translations=t, losses=losses, loss_terms=terms, config=config)


class _Adam:
    """torch.optim.Adam's update (betas 0.9/0.999, eps 1e-8, no weight decay) in place on numpy
    arrays, same operations in the same order; torch fuses some multiply-adds, so the two differ by
    rounding (~1e-15 after hundreds of steps). ``lr`` is scaled by the caller (ExponentialLR)."""

    def __init__(self, params, lr, betas=(0.9, 0.999), eps=1e-8):
        self.params, self.lr, self.betas, self.eps, self.steps = params, lr, betas, eps, 0
        self.m = [np.zeros_like(p) for p in params]
        self.v = [np.zeros_like(p) for p in params]

    def step(self, grads):
        b1, b2 = self.betas
        self.steps += 1
        bias1, bias2 = 1 - b1**self.steps, 1 - b2**self.steps
        for p, g, m, v in zip(self.params, grads, self.m, self.v):
            m += (1 - b1) * (g - m)
            v *= b2
            v += (1 - b2) * g * g
            p += (-self.lr / bias1) * m / (np.sqrt(v) / bias2**0.5 + self.eps)


def _optimise(P, Q, nodes, edge_idx, edge_w, anchor_idx, anchor_w, config: EDConfig):
    """The optimisation loop of :func:`tpvp.registration.autograd_reference.optimise_autograd` with the losses and their gradient from
    the numba kernels of :func:`_loss_and_gradient` (same random subsets, same Adam, same stop rule)."""
    rng = np.random.default_rng(config.seed)
    M = len(nodes)
    # one array type for every call (C-contiguous, writeable): other layouts would compile anew
    P, Q, nodes, a_w, e_w = (_c_array(x, np.float64) for x in (P, Q, nodes, anchor_w, edge_w))
    a_idx, e_idx = _c_array(anchor_idx, np.int64), _c_array(edge_idx, np.int64)
    g_ij = nodes[e_idx] - nodes[:, None, :]  # (M, k, 3) undeformed edge vectors
    phi, t = np.zeros((M, 3)), np.zeros((M, 3))
    g_phi, g_t = np.zeros((M, 3)), np.zeros((M, 3))
    adam = _Adam((phi, t), config.lr)  # updates phi and t in place
    n_p, n_q = min(config.chamfer_samples, len(P)), min(config.chamfer_samples, len(Q))
    weights = (float(config.w_arap), float(config.w_chamfer), float(config.w_laplacian))
    losses, terms = [], []
    for _ in range(config.iterations):
        # fresh subsets each iteration, drawn exactly as in the autograd reference
        sel_p = rng.choice(len(P), n_p, replace=False)
        sel_q = rng.choice(len(Q), n_q, replace=False)
        sel_l = rng.choice(len(P), n_p, replace=False)
        l_arap, l_cd, l_lap = _loss_and_gradient(
            phi, t, P, Q, nodes, a_idx, a_w, e_idx, e_w, g_ij, sel_p, sel_q, sel_l, *weights,
            bool(config.laplacian_in_gradient), int(config.laplacian_k), float(config.chamfer_truncation),
            g_phi, g_t)
        total = config.w_arap * l_arap + config.w_chamfer * l_cd + config.w_laplacian * l_lap
        losses.append(total)
        terms.append((l_arap, l_cd, l_lap))
        if total < config.stop_loss:
            break
        adam.step((g_phi, g_t))
        adam.lr *= config.lr_decay  # ExponentialLR, stepped every iteration
    R = np.empty((M, 3, 3))
    _rodrigues(phi, R, np.empty(M), np.empty(M))
    return R, t, np.asarray(losses, dtype=np.float64), np.asarray(terms, dtype=np.float64).reshape(-1, 3)


def _c_array(x, dtype):
    return np.require(x, dtype=dtype, requirements=("C", "W"))


def compile_kernels() -> float:
    """Compile the numba kernels (or load them from numba's on-disk cache) with a 2-iteration
    registration of a tiny pair, through the same code path and argument types as real calls;
    returns the seconds. A run timed after it measures the registration, not the compilation
    (first run on a machine: ~3.5 s on a quiet 2-core machine; cache load: ~0.05 s)."""
    start = time.perf_counter()
    rng = np.random.default_rng(0)
    P = rng.uniform(0.0, 0.02, size=(60, 3))
    register_embedded_deformation(P, P + 0.0005, EDConfig(iterations=2, laplacian_in_gradient=True))
    register_embedded_deformation(P, P + 0.0005, EDConfig(iterations=2))
    return time.perf_counter() - start
