"""Sparse locally rigid warp-field ICP: the greenhouse-row registration of the previous session P
onto the current coarse reconstruction Q (paper "Non-Rigid Registration", "faster configuration";
a port of cilantro's ``SimpleCombinedMetricSparseRigidWarpFieldICP3f`` as the authors'
``greenhouse_row/cilantro_nicp`` configures it, docs/greenhouse.md#registration and
shared/docs/registration_inflation_reference.md part B).

Model: control nodes g_j = centroids of the source points per ``node_spacing`` grid cell; per node
an accumulated rigid transform T_j = (R_j, t_j), x -> R_j x + t_j, **about the world origin** (not
about the node, as in cilantro: rotations couple with translations for rows far from the origin,
so the result depends on the frame; ``centre=True`` rotates about the source centroid instead).
Each source point p follows its ``anchors`` nearest nodes with weights
a_pj = exp(-0.5 d^2 / sigma_c^2) measured on the *original* positions: R_p = the rotation nearest
to sum a_pj R_j / sum a_pj (polar projection), t_p = sum a_pj t_j / sum a_pj.

One outer ICP iteration:

1. s_p = R_p x_p + t_p; correspondence = nearest target point d_p (its normal n_p), pairs at
   ``max_correspondence`` or farther ignored (no reciprocity, not one-to-one). That is the
   reference's search (``correspondences = "previous-to-coarse"``); ``coarse-to-previous`` pairs
   every target point d with its nearest s_p instead (cilantro's other direction: a source point
   gets several pairs or none, so parts of P that the partial scan Q never saw get no data term
   and follow the regularisation only; the greenhouse rows' default, docs/greenhouse.md
   #registration), ``both`` takes the pairs of both directions.
2. Gauss-Newton on an incremental parameter vector theta (per node ZYX Euler angles a, b, c and a
   translation tau), theta = 0 at the start: data residual n_p^T (R(theta_p) s_p + tau_p - d_p) with
   theta_p = sum_j (a_pj / A_p) theta_j, R = Rz(c) Ry(b) Rx(a), linearised about the current theta
   (full ZYX derivatives); regularisation, per arc i -> j of the 8-NN graph (the node itself
   excluded) and per parameter component k, the residual
   sqrt(stiffness w_ij) sqrt(huber(theta_ik - theta_jk)), w_ij = exp(-0.5 |g_i - g_j|^2 / sigma_r^2)
   (mutual neighbours count twice; raw radians and metres against the same Huber boundary; the
   regulariser acts on the increment, not on the accumulated deformation).
3. Solve (J^T J) delta = -J^T r by conjugate gradients to a relative residual of ``cg_tolerance``
   (at most ``cg_iterations``), theta += delta; at most ``gn_iterations`` steps, stop when every
   node's |delta_j| (6-vector) is below ``gn_tolerance``.
4. T_j <- (R(theta_j), tau_j) o T_j (left composition, rotation re-projected), dense field
   recomputed; update norm = max_j sqrt(|dR_j - I|_F^2 + |tau_j|^2); stop below ``icp_tolerance``,
   at most ``icp_iterations`` iterations.

Target normals: PCA of the ``normal_neighbours`` nearest target points (PCL
``NormalEstimation``), oriented toward ``viewpoint`` (the reference: the view box's centre) or away
from the target's centroid. The point-to-plane residual and its Jacobian are both linear in n_p,
so the orientation never changes the registration.

Checked against the reference itself: cilantro @ cd473eb compiled with the settings of the
authors' ``Registration.cpp`` (float32) and fed the same clouds and normals ends with the same
nodes and iteration counts and warped points within 3 micrometres on average (a few points whose
nearest neighbour flips within float32 rounding differ by up to ~2 mm) on generated room1/room4
pairs and a known deformation (tests/test_warp_field.py keeps a small case).

Departures from the reference (cilantro float32, OpenMP, Eigen):

* float64 numpy/scipy, vectorised over points; J^T J is assembled directly in 6x6 blocks (a fixed
  BSR pattern built once: unordered anchor pairs of every point and the regularisation arcs), the
  data blocks as one sparse product (anchor-pair weights x per-point g g^T), never J itself;
* the linear solve (``solver``): ``cg`` is Eigen's ``ConjugateGradient`` with its Jacobi
  preconditioner as cilantro runs it (~300 iterations per solve on a row); ``lu-cg`` (default)
  is the same CG and stop rule preconditioned by the sparse LU (SuperLU) of an earlier J^T J,
  refactored only when it stops helping (~5 iterations per solve, a single factorisation on
  each benchmark row; the solve goes from ~40 % of the run time to ~10 %); ``direct``
  factorises every system. All three give the same warp to ~1e-5 m; a 1e-13 relative ridge
  keeps the factorisations of nodes that no correspondence reaches finite;
* the dense field's polar projection is Newton's iteration X <- (X + X^-T)/2 (the blend of close
  rotations converges in a few steps to the SVD's U V^T); rows it cannot settle (det <= 0) take the
  SVD with cilantro's sign fix;
* ``voxel``: both clouds are reduced to voxel centroids first (the simulator's 1 cm PCL
  ``VoxelGrid`` before it writes the two PLY files); ``warped`` is that reduced previous session,
  as the reference writes it; ``warp()`` applies the field to any other points;
* inputs are checked (empty, NaN, millimetres, no overlap) instead of silently returning P.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse
from scipy.sparse import linalg as splinalg
from scipy.spatial import cKDTree

from tpvp.errors import ConfigError, GraphTooLargeError, PointCloudError, checked_cloud
from tpvp.io.units import MM_EXTENT_THRESHOLD
from tpvp.metrics.geometry import chamfer_distance
from tpvp.registration.config import WarpFieldConfig
from tpvp.scene import voxels


def too_many_nodes(nodes: int, limit: int, spacing: float, prefix: str, spacing_key: str, what: str) -> str:
    """The refusal of a graph of ``nodes`` > ``limit`` nodes at ``spacing`` m, in the command
    line's terms: the option keys ``{prefix}.max_nodes`` and ``{prefix}.{spacing_key}`` to change."""
    step = 10 ** max(0, len(str(nodes)) - 2)
    coarser = spacing * 1.1 * math.sqrt(nodes / limit)  # a surface's node count goes as 1 / spacing^2
    return (f"the previous session's scan gives {nodes:,} {what} nodes at a {1e3 * spacing:g} mm node spacing "
            f"(planning frame), more than the limit of {limit:,}: raise the limit, e.g. --set "
            f"{prefix}.max_nodes={math.ceil(nodes / step) * step} (more memory and time), or coarsen the graph, "
            f"e.g. --set {prefix}.{spacing_key}={coarser:.2g}")


@dataclass(frozen=True)
class WarpFieldResult:
    """Output of :func:`register_warp_field`.

    warped: (N, 3) the previous session (reduced to ``config.voxel`` centroids unless None) moved by
    the final dense field. chamfer_before/after: symmetric Chamfer (m,
    ``tpvp.metrics.chamfer_distance``) of the reduced previous session resp. ``warped`` to the
    reduced coarse cloud. seconds: reduction + normals + graph + ICP + final warp (not the Chamfer
    reporting). iterations: outer ICP iterations; gn_iterations / cg_iterations: totals over them;
    update_norms: the update norm of every outer iteration; matches: correspondences of the last.
    nodes (M, 3), rotations (M, 3, 3), translations (M, 3): node j maps x to
    ``rotations[j] @ (x - origin) + translations[j] + origin`` (origin = 0 unless ``config.centre``).
    """

    warped: np.ndarray
    chamfer_before: float
    chamfer_after: float
    seconds: float
    iterations: int
    gn_iterations: int
    cg_iterations: int
    update_norms: np.ndarray
    matches: int
    nodes: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    origin: np.ndarray
    config: WarpFieldConfig = field(default_factory=WarpFieldConfig)

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    def warp(self, points) -> np.ndarray:
        """Apply the estimated field to other points (anchored on the nodes' original positions,
        as the source points are)."""
        points = checked_cloud(points, "points to warp") - self.origin
        idx, w, live = _anchors(self.nodes - self.origin, points, self.config)
        blend = _blend_matrix(idx, w, len(self.nodes))
        return _dense_apply(blend, live, self.rotations, self.translations, points) + self.origin


# --------------------------------------------------------------------------------------------------
# rotations
# --------------------------------------------------------------------------------------------------


def euler_zyx(angles) -> np.ndarray:
    """R = Rz(c) Ry(b) Rx(a) of (..., 3) angles (a, b, c), as (..., 3, 3)."""
    angles = np.asarray(angles, dtype=np.float64)
    ca, cb, cc = np.cos(angles[..., 0]), np.cos(angles[..., 1]), np.cos(angles[..., 2])
    sa, sb, sc = np.sin(angles[..., 0]), np.sin(angles[..., 1]), np.sin(angles[..., 2])
    R = np.empty(angles.shape[:-1] + (3, 3))
    R[..., 0, 0] = cc * cb
    R[..., 0, 1] = cc * sb * sa - sc * ca
    R[..., 0, 2] = cc * sb * ca + sc * sa
    R[..., 1, 0] = sc * cb
    R[..., 1, 1] = sc * sb * sa + cc * ca
    R[..., 1, 2] = sc * sb * ca - cc * sa
    R[..., 2, 0] = -sb
    R[..., 2, 1] = cb * sa
    R[..., 2, 2] = cb * ca
    return R


def _euler_apply(angles, s):
    """R(angles) s and dR/da s, dR/db s, dR/dc s, component-major: angles and s are (3, n) rows;
    returns four (3, n) arrays (R = Rz(c) Ry(b) Rx(a))."""
    ca, sa = np.cos(angles[0]), np.sin(angles[0])
    cb, sb = np.cos(angles[1]), np.sin(angles[1])
    cc, sc = np.cos(angles[2]), np.sin(angles[2])
    s0, s1, s2 = s
    zero = np.zeros_like(s0)
    x1 = (s0, ca * s1 - sa * s2, sa * s1 + ca * s2)  # Rx s
    dx1 = (zero, -sa * s1 - ca * s2, ca * s1 - sa * s2)  # dRx/da s

    def ry(v):
        return (cb * v[0] + sb * v[2], v[1], cb * v[2] - sb * v[0])

    def rz(v):
        return np.array((cc * v[0] - sc * v[1], sc * v[0] + cc * v[1], v[2]))

    x2 = ry(x1)
    dB = rz((cb * x1[2] - sb * x1[0], zero, -cb * x1[0] - sb * x1[2]))
    dC = np.array((-sc * x2[0] - cc * x2[1], cc * x2[0] - sc * x2[1], zero))
    return rz(x2), rz(ry(dx1)), dB, dC


_POLAR_ITERATIONS = 30
# Newton's error after a step is about the square of the step's change: a change below 1e-8 leaves
# an iterate within rounding of U V^T.
_POLAR_TOLERANCE = 1e-8
# cofactor C_ij = X[A] X[B] - X[C] X[D] of a row-major 3 x 3 matrix (X^-T = C / det X)
_COF = np.array([[4, 5, 3, 2, 0, 1, 1, 2, 0], [8, 6, 7, 7, 8, 6, 5, 3, 4],
                 [5, 3, 4, 1, 2, 0, 2, 0, 1], [7, 8, 6, 8, 6, 7, 4, 5, 3]])


def _cofactors(Y, out):
    """Cofactor matrices of the (9, n) row-major 3 x 3 matrices Y into out (9, n); returns det."""
    for k, (a, b, c, d) in enumerate(_COF.T):
        np.multiply(Y[a], Y[b], out=out[k])
        out[k] -= Y[c] * Y[d]
    return Y[0] * out[0] + Y[1] * out[1] + Y[2] * out[2]


def nearest_rotation(X) -> np.ndarray:
    """The rotation nearest to every (3, 3) matrix of X (..., 3, 3): the orthogonal polar factor
    U V^T, with cilantro's fix (first column of U negated) where det(U V^T) < 0.

    Newton's iteration X <- (X + X^-T) / 2 on the nine entries as (9, n) arrays (3-4 steps for a
    blend of close rotations); matrices with det <= 0, or that do not settle, take the SVD.
    """
    X = np.asarray(X, dtype=np.float64)
    shape = X.shape
    Y = np.ascontiguousarray(X.reshape(-1, 9).T)  # (9, n)
    C = np.empty_like(Y)
    bad = ~(_cofactors(Y, C) > 0)
    if bad.any():
        Y[:, bad] = np.eye(3).reshape(9, 1)  # placeholders; replaced by the SVD below
    settled = False
    for _ in range(_POLAR_ITERATIONS):
        det = _cofactors(Y, C)
        C /= det
        C -= Y
        C *= 0.5  # the Newton step (X^-T - X) / 2
        Y += C
        if np.abs(C).max(initial=0.0) < _POLAR_TOLERANCE:
            settled = True
            break
    out = Y.T.reshape(-1, 3, 3)
    if not settled:
        bad |= np.abs(np.einsum("nki,nkj->nij", out, out) - np.eye(3)).max(axis=(1, 2)) > 1e-12
    if bad.any():
        U, _, Vt = np.linalg.svd(X.reshape(-1, 3, 3)[bad])
        flip = np.linalg.det(U @ Vt) < 0
        U[flip, :, 0] *= -1.0
        out[bad] = U @ Vt
    return out.reshape(shape)


# --------------------------------------------------------------------------------------------------
# normals
# --------------------------------------------------------------------------------------------------

_CHUNK = 32768


def smallest_eigenvectors(cov) -> np.ndarray:
    """Unit eigenvector of the smallest eigenvalue of every symmetric 3 x 3 matrix (n, 3, 3).

    Closed form (trigonometric eigenvalues of the trace-normalised matrix, the eigenvector as the
    longest cross product of two rows of cov - lambda I), ~10x faster than ``numpy.linalg.eigh``;
    where the two smallest eigenvalues (nearly) coincide, e.g. points on a line, the eigenvector
    is not defined by the rows and ``eigh`` picks one.
    """
    cov = np.asarray(cov, dtype=np.float64)
    q = np.trace(cov, axis1=1, axis2=2) / 3.0
    ok = q > 0
    A = cov / np.where(ok, q, 1.0)[:, None, None]  # eigenvalues now sum to 3 (mean 1)
    B = A - np.eye(3)
    p = np.sqrt(np.einsum("nij,nij->n", B, B) / 6.0)
    ok &= p > 1e-12
    r = np.linalg.det(B) / (2.0 * np.where(ok, p, 1.0) ** 3)
    phi = np.arccos(np.clip(r, -1.0, 1.0)) / 3.0
    lam = 1.0 + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)  # the smallest eigenvalue of A
    A[:, [0, 1, 2], [0, 1, 2]] -= lam[:, None]
    crosses = np.stack([np.cross(A[:, 0], A[:, 1]), np.cross(A[:, 0], A[:, 2]), np.cross(A[:, 1], A[:, 2])], axis=1)
    length = np.einsum("nki,nki->nk", crosses, crosses)
    best = np.argmax(length, axis=1)
    top = length[np.arange(len(A)), best]
    out = crosses[np.arange(len(A)), best] / np.sqrt(np.where(top > 0, top, 1.0))[:, None]
    bad = ~ok | (top < 1e-10)
    if bad.any():
        out[bad] = np.linalg.eigh(cov[bad])[1][:, :, 0]
    return out


def target_normals(points, k: int = 30, viewpoint=None, workers: int = 1) -> np.ndarray:
    """Unit normals by PCA of each point's k nearest points (itself included; PCL
    ``NormalEstimation`` with ``setKSearch(k)``), flipped toward ``viewpoint`` if given, otherwise
    away from the cloud's centroid."""
    points = checked_cloud(points, "target cloud Q")
    k = min(int(k), len(points))
    _, idx = cKDTree(points).query(points, k=k, workers=workers)
    idx = idx.reshape(len(points), k)
    normals = np.empty_like(points)
    for start in range(0, len(points), _CHUNK):
        block = slice(start, start + _CHUNK)
        nb = points[idx[block]]
        nb -= nb.mean(axis=1, keepdims=True)
        normals[block] = smallest_eigenvectors(np.matmul(nb.transpose(0, 2, 1), nb))
    if viewpoint is None:
        towards = points - points.mean(axis=0)
    else:
        viewpoint = np.asarray(viewpoint, dtype=np.float64)
        if viewpoint.shape != (3,) or not np.all(np.isfinite(viewpoint)):
            raise ConfigError(f"viewpoint must be 3 finite numbers, got {viewpoint!r}")
        towards = viewpoint - points
    flip = np.einsum("ij,ij->i", normals, towards) < 0
    normals[flip] *= -1.0
    return normals


# --------------------------------------------------------------------------------------------------
# graph
# --------------------------------------------------------------------------------------------------


def _anchors(nodes, points, config: WarpFieldConfig):
    """Anchor nodes of every point, their normalised weights a_pj / A_p, and whether A_p > 0."""
    k = min(config.anchors, len(nodes))
    d, idx = cKDTree(nodes).query(points, k=k, workers=config.workers)
    d, idx = d.reshape(len(points), k), idx.reshape(len(points), k)
    w = np.exp(-0.5 * d**2 / config.anchor_sigma**2)
    total = w.sum(axis=1)
    live = total > 0
    w = np.where(live[:, None], w / np.where(live, total, 1.0)[:, None], 0.0)
    return idx.astype(np.int64), w, live


def _blend_matrix(idx, w, n_nodes) -> sparse.csr_matrix:
    """(N, M) sparse matrix of the normalised anchor weights: blend @ per-node values."""
    n, k = idx.shape
    return sparse.csr_matrix((w.ravel(), idx.ravel(), np.arange(0, n * k + 1, k)), shape=(n, n_nodes))


def _dense_apply(blend, live, rotations, translations, points) -> np.ndarray:
    """Every point moved by its blended transform (rotation re-projected); identity where a point
    has no anchor weight (``live`` False; cilantro's resampleTransforms)."""
    R = np.asarray(blend @ rotations.reshape(-1, 9)).reshape(-1, 3, 3)
    t = np.asarray(blend @ translations)
    R[~live] = np.eye(3)
    R = nearest_rotation(R)
    return np.einsum("nij,nj->ni", R, points) + t


_UPPER = np.triu_indices(6)  # the 21 distinct entries of a symmetric 6 x 6 block
_FULL = np.empty((6, 6), np.int64)
_FULL[_UPPER] = np.arange(21)
_FULL[(_UPPER[1], _UPPER[0])] = np.arange(21)
_FULL = _FULL.ravel()  # (36,) index into the 21 entries
_DIAG = np.arange(6) * 7  # flat positions of a 6 x 6 block's diagonal


@dataclass(frozen=True, eq=False)
class _Graph:
    """Control nodes, anchors and the fixed block pattern of J^T J (BSR, 6 x 6 blocks)."""

    nodes: np.ndarray
    anchor_idx: np.ndarray
    anchor_w: np.ndarray
    live: np.ndarray
    blend: sparse.csr_matrix  # (N, M)
    blend_t: sparse.csr_matrix  # (M, N)
    pairs: sparse.csr_matrix  # (U, N): weight products of every point's unordered anchor pairs
    pair_pos: np.ndarray  # (U,) block of (lo, hi)
    pair_pos_t: np.ndarray  # (U,) block of (hi, lo), -1 on the diagonal
    arc_i: np.ndarray
    arc_j: np.ndarray
    arc_w: np.ndarray  # sqrt(stiffness * w_ij)
    arc_pos: np.ndarray  # (A, 4) blocks (i, i), (j, j), (i, j), (j, i)
    indices: np.ndarray
    indptr: np.ndarray

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)


def _build_graph(P, config: WarpFieldConfig, origin=None) -> _Graph:
    """The graph of the source P (world frame), every position relative to ``origin`` (the
    rotation pivot; None: the world origin). The node grid is the world's either way."""
    origin = np.zeros(3) if origin is None else origin
    nodes = voxels.voxel_centroids(P, config.node_spacing) - origin
    P = P - origin
    M = len(nodes)
    if M > config.max_nodes:
        raise GraphTooLargeError(too_many_nodes(M, config.max_nodes, config.node_spacing,
                                                "registration.warp_field", "node_spacing", "control"))
    idx, w, live = _anchors(nodes, P, config)
    n, k = idx.shape
    blend = _blend_matrix(idx, w, M)
    # unordered anchor pairs (a <= b) of every point: block (j, k) of J^T J gets w_j w_k g g^T
    a, b = np.triu_indices(k)
    lo = np.minimum(idx[:, a], idx[:, b])
    hi = np.maximum(idx[:, a], idx[:, b])
    codes, pair_of = np.unique(lo * M + hi, return_inverse=True)
    pair_of = pair_of.reshape(n, len(a))
    products = w[:, a] * w[:, b]
    pairs = sparse.csr_matrix((products.ravel(), (pair_of.ravel(), np.repeat(np.arange(n), len(a)))),
                              shape=(len(codes), n))
    p_lo, p_hi = codes // M, codes % M
    # regularisation arcs: column 0 of the k-NN query is the node itself (cilantro's neighbors[0])
    kr = min(config.regularisation_neighbours, M)
    if kr > 1:
        d, nn = cKDTree(nodes).query(nodes, k=kr)
        arc_i = np.repeat(nn[:, 0], kr - 1).astype(np.int64)
        arc_j = nn[:, 1:].ravel().astype(np.int64)
        arc_w = np.sqrt(config.stiffness * np.exp(-0.5 * d[:, 1:].ravel() ** 2 / config.regularisation_sigma**2))
    else:
        arc_i = arc_j = np.zeros(0, np.int64)
        arc_w = np.zeros(0)
    diag = np.arange(M) * (M + 1)
    block_codes = np.unique(np.concatenate([
        codes, p_hi * M + p_lo, diag, arc_i * M + arc_j, arc_j * M + arc_i]))
    rows = block_codes // M
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=M))])
    pos = lambda c: np.searchsorted(block_codes, c)  # noqa: E731
    pair_pos_t = np.where(p_lo != p_hi, pos(p_hi * M + p_lo), -1)
    arc_pos = np.stack([pos(arc_i * (M + 1)), pos(arc_j * (M + 1)), pos(arc_i * M + arc_j),
                        pos(arc_j * M + arc_i)], axis=1)
    return _Graph(nodes=nodes, anchor_idx=idx, anchor_w=w, live=live, blend=blend,
                  blend_t=blend.T.tocsr(), pairs=pairs, pair_pos=pos(codes), pair_pos_t=pair_pos_t,
                  arc_i=arc_i, arc_j=arc_j, arc_w=arc_w, arc_pos=arc_pos,
                  indices=(block_codes % M).astype(np.int32), indptr=indptr.astype(np.int32))


# --------------------------------------------------------------------------------------------------
# Gauss-Newton
# --------------------------------------------------------------------------------------------------


def _sqrt_huber(x, delta):
    """sqrt of the Huber loss and its derivative (cilantro: the derivative at 0 is +sqrt(1/2))."""
    ax = np.abs(x)
    outer = ax > delta
    root = np.sqrt(delta * np.maximum(ax - 0.5 * delta, 0.5 * delta))
    value = np.where(outer, root, np.sqrt(0.5) * ax)
    slope = np.where(outer, delta / (2.0 * root), np.sqrt(0.5))
    return value, np.where(x < 0, -slope, slope)


def _normal_equations(graph: _Graph, theta, s, d, n, mask, config: WarpFieldConfig, source=None):
    """J^T J (BSR, 6M x 6M), J^T r (6M,) and the cost |r|^2 at the increment theta (M, 6).

    s (3, N): the current source points, component-major. ``source`` None (the reference's
    previous -> coarse search): d, n (3, N) the correspondence and its target normal of every
    source point, mask (N,) 1 for the points with a correspondence, 0 otherwise. ``source`` (C,)
    source indices: C correspondences (d, n (3, C), mask (C,)), a source point may have several
    or none (cilantro's coarse -> previous search).
    """
    M = graph.n_nodes
    tb = np.ascontiguousarray(np.asarray(graph.blend @ theta).T)  # (6, N) per-point averages
    if source is not None:
        tb, s = tb[:, source], s[:, source]
    Rs, dA, dB, dC = _euler_apply(tb[:3], s)
    g = np.empty((6, len(mask)))  # d r_p / d theta_bar_p, one row per parameter
    for row, dv in enumerate((dA, dB, dC)):
        np.multiply(n[0], dv[0], out=g[row])
        g[row] += n[1] * dv[1]
        g[row] += n[2] * dv[2]
    np.multiply(n, mask, out=g[3:])
    g[:3] *= mask
    Rs += tb[3:]
    Rs -= d
    r = g[3] * Rs[0] + g[4] * Rs[1] + g[5] * Rs[2]  # n^T (R s + tau - d), 0 without a match
    products = g[_UPPER[0]] * g[_UPPER[1]]  # (21, N or C): the distinct entries of g g^T
    g *= r
    if source is not None:  # sum the correspondences of every source point
        gather = sparse.csr_matrix((np.ones(len(source)), (source, np.arange(len(source)))),
                                   shape=(graph.blend.shape[0], len(source)))
        products = (gather @ products.T).T
        g = (gather @ g.T).T
    blocks = np.zeros((len(graph.indices), 36))
    pair_blocks = np.asarray(graph.pairs @ products.T)[:, _FULL]
    blocks[graph.pair_pos] = pair_blocks
    off = graph.pair_pos_t >= 0
    blocks[graph.pair_pos_t[off]] = pair_blocks[off]
    grad = np.asarray(graph.blend_t @ g.T)
    cost = float(r @ r)
    if len(graph.arc_i):
        x = theta[graph.arc_i] - theta[graph.arc_j]
        value, slope = _sqrt_huber(x, config.huber)
        e = graph.arc_w[:, None] * value
        de = graph.arc_w[:, None] * slope
        c, q = de * de, de * e
        flat = (graph.arc_pos[:, :, None] * 36 + _DIAG).reshape(len(x), 4 * 6)
        values = np.concatenate([c, c, -c, -c], axis=1)
        blocks += np.bincount(flat.ravel(), weights=values.ravel(), minlength=blocks.size).reshape(blocks.shape)
        np.add.at(grad, graph.arc_i, q)
        np.add.at(grad, graph.arc_j, -q)
        cost += float(np.sum(e * e))
    H = sparse.bsr_matrix((blocks.reshape(-1, 6, 6), graph.indices, graph.indptr), shape=(6 * M, 6 * M))
    return H, grad.ravel(), cost


def conjugate_gradient(A, rhs, tolerance: float = 1e-5, max_iterations: int = 500, precondition=None):
    """Eigen's ``ConjugateGradient`` (what cilantro calls): zero start, stop when
    |rhs - A x|^2 < tolerance^2 |rhs|^2 or after ``max_iterations``. ``precondition``: a function
    v -> M^-1 v; None: Eigen's ``DiagonalPreconditioner`` (Jacobi; zero diagonal entries take 1).
    Returns x and the iterations taken."""
    x = np.zeros_like(rhs)
    rhs_norm2 = float(rhs @ rhs)
    if rhs_norm2 == 0.0:
        return x, 0
    if precondition is None:
        diag = A.diagonal()
        inv = np.ones_like(diag)
        np.divide(1.0, diag, out=inv, where=diag != 0)
        precondition = inv.__mul__
    threshold = max(tolerance * tolerance * rhs_norm2, np.finfo(np.float64).tiny)
    residual = rhs.copy()
    p = precondition(residual)
    abs_new = float(residual @ p)
    steps = 0
    while steps < max_iterations:
        tmp = A @ p
        alpha = abs_new / float(p @ tmp)
        x += alpha * p
        residual -= alpha * tmp
        steps += 1
        if float(residual @ residual) < threshold:
            break
        z = precondition(residual)
        abs_old, abs_new = abs_new, float(residual @ z)
        p *= abs_new / abs_old
        p += z
    return x, steps


_RIDGE = 1e-13  # relative to J^T J's largest diagonal entry (factorisations only)
# lu-cg: refactor once the reused factorisation needs more CG iterations than this (it needs 4-5
# on the benchmark rows over all 15 outer iterations)
_REFACTOR_AFTER = 25


def _factorise(H):
    """Sparse LU of J^T J: SuperLU in symmetric mode (minimum-degree ordering of A^T + A, no
    pivoting: H is positive semi-definite); the ridge keeps nodes without any data term solvable."""
    A = H.tocsc()
    ridge = _RIDGE * max(float(np.abs(A.diagonal()).max()), 1e-300)
    A = A + ridge * sparse.identity(A.shape[0], format="csc")
    return splinalg.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})


class _LinearSolver:
    """Solves J^T J x = rhs for one registration: ``cg`` (Eigen's Jacobi CG), ``direct`` (a new
    LU every time) or ``lu-cg`` (CG preconditioned by the LU of an earlier J^T J, refactored when
    it stops helping; the same stop rule as ``cg``). ``iterations``: CG iterations so far."""

    def __init__(self, config: WarpFieldConfig):
        self.config, self.lu, self.iterations = config, None, 0

    def __call__(self, H, rhs):
        config = self.config
        if config.solver == "direct":
            return _factorise(H).solve(rhs)
        if config.solver == "cg":
            x, steps = conjugate_gradient(H, rhs, config.cg_tolerance, config.cg_iterations)
            self.iterations += steps
            return x
        if self.lu is not None:
            x, steps = conjugate_gradient(H, rhs, config.cg_tolerance, min(_REFACTOR_AFTER, config.cg_iterations),
                                          self.lu.solve)
            self.iterations += steps
            if steps < _REFACTOR_AFTER or steps == config.cg_iterations:
                return x
        self.lu = _factorise(H)
        x, steps = conjugate_gradient(H, rhs, config.cg_tolerance, config.cg_iterations, self.lu.solve)
        self.iterations += steps
        return x


def _gauss_newton(graph: _Graph, s, d, n, mask, solve: _LinearSolver, config: WarpFieldConfig, source=None):
    """The increment theta (M, 6) of one outer iteration and its GN steps (s, d, n, mask, source
    as in :func:`_normal_equations`)."""
    theta = np.zeros((graph.n_nodes, 6))
    for step in range(1, config.gn_iterations + 1):
        H, grad, _ = _normal_equations(graph, theta, s, d, n, mask, config, source)
        delta = solve(H, -grad).reshape(-1, 6)
        theta += delta
        if np.max(np.einsum("ij,ij->i", delta, delta)) < config.gn_tolerance**2:
            break
    return theta, step


# --------------------------------------------------------------------------------------------------
# main entry point
# --------------------------------------------------------------------------------------------------


def _nearest(tree, points, config: WarpFieldConfig):
    """Nearest target point of every point and its distance (inf beyond ``max_correspondence``).
    Two passes give the same answer as one: most points are within a few cm, and a tight bound
    prunes the KD-tree search (~25 % faster); the rest are searched again with the full bound."""
    dist, nearest = tree.query(points, distance_upper_bound=_FIRST_BOUND * config.max_correspondence,
                               workers=config.workers)
    far = np.flatnonzero(~np.isfinite(dist))
    if len(far):
        dist[far], nearest[far] = tree.query(points[far], distance_upper_bound=config.max_correspondence,
                                             workers=config.workers)
    return dist, nearest


_FIRST_BOUND = 0.1  # share of max_correspondence searched first


def _coarse_to_previous(tree, Q, s, live, config: WarpFieldConfig):
    """Correspondences (source indices, target indices) searched from the coarse cloud Q onto the
    current source points s (only those with anchors, ``live``): every target point pairs with its
    nearest source point closer than ``max_correspondence`` (a source point may get several or
    none); ``both`` adds the previous -> coarse pairs (cilantro's ``BOTH``)."""
    dist, nearest = cKDTree(s[live]).query(Q, distance_upper_bound=config.max_correspondence,
                                           workers=config.workers)
    keep = np.flatnonzero(dist < config.max_correspondence)
    source, target = live[nearest[keep]], keep
    if config.correspondences == "both":
        dist, nearest = _nearest(tree, s[live], config)
        ok = dist < config.max_correspondence
        source, target = np.concatenate([source, live[ok]]), np.concatenate([target, nearest[ok]])
    return source, target


def _check_units(P, Q) -> None:
    size = max(np.ptp(P, axis=0).max(), np.ptp(Q, axis=0).max())
    if size > MM_EXTENT_THRESHOLD:  # the project's mm rule (tpvp.io.detect_units)
        raise PointCloudError(
            f"the clouds span {size:.4g} (largest bounding-box side), more than {MM_EXTENT_THRESHOLD:g} m: "
            f"they look like millimetres; registration expects metres (tpvp.io.to_metres)")


def register_warp_field(previous, coarse, config: WarpFieldConfig | None = None,
                        viewpoint=None) -> WarpFieldResult:
    """Warp the previous session (N, 3) onto the current coarse reconstruction (M, 3), metres, one
    frame (no rigid pre-alignment). ``viewpoint`` (3,) orients the target normals (the reference:
    the view box's centre); it does not change the result."""
    config = WarpFieldConfig() if config is None else config
    if not isinstance(config, WarpFieldConfig):
        raise ConfigError(f"config must be a WarpFieldConfig, got {type(config).__name__}")
    P = checked_cloud(previous, "previous session P")
    Q = checked_cloud(coarse, "coarse cloud Q")
    _check_units(P, Q)
    start = time.perf_counter()
    if config.voxel is not None:
        P, Q = voxels.voxel_centroids(P, config.voxel), voxels.voxel_centroids(Q, config.voxel)
    if len(Q) < 3:
        raise PointCloudError(f"coarse cloud Q has {len(Q)} point(s); its normals need at least 3")
    origin = P.mean(axis=0) if config.centre else np.zeros(3)
    P0, Q0 = P - origin, Q - origin
    vp = None if viewpoint is None else np.asarray(viewpoint, dtype=np.float64) - origin
    normals = target_normals(Q0, config.normal_neighbours, vp, config.workers)
    graph = _build_graph(P, config, origin)
    M = graph.n_nodes
    tree = cKDTree(Q0)
    Q0_rows, normal_rows = np.ascontiguousarray(Q0.T), np.ascontiguousarray(normals.T)
    R, t = np.tile(np.eye(3), (M, 1, 1)), np.zeros((M, 3))
    s = P0.copy()  # the dense field starts at the identity
    norms, gn_total, matches = [], 0, 0
    solve = _LinearSolver(config)
    live = np.flatnonzero(graph.live)
    for outer in range(config.icp_iterations):
        if config.correspondences == "previous-to-coarse":
            dist, nearest = _nearest(tree, s, config)
            valid = graph.live & (dist < config.max_correspondence)
            matches = int(valid.sum())
            source, target = None, np.where(valid, nearest, 0)
            mask = valid.astype(np.float64)
        else:
            source, target = _coarse_to_previous(tree, Q0, s, live, config)
            matches = len(source)
            mask = np.ones(matches)
        if matches == 0:
            if outer == 0:
                raise PointCloudError(
                    f"no point of the previous session P lies within {config.max_correspondence} m of the "
                    f"coarse cloud Q: the clouds do not overlap (one frame? both in metres?)")
            norms.append(0.0)
            break
        theta, gn_steps = _gauss_newton(graph, np.ascontiguousarray(s.T), Q0_rows[:, target],
                                        normal_rows[:, target], mask, solve, config, source)
        gn_total += gn_steps
        dR, tau = euler_zyx(theta[:, :3]), theta[:, 3:]
        R = nearest_rotation(dR @ R)
        t = np.einsum("nij,nj->ni", dR, t) + tau
        s = _dense_apply(graph.blend, graph.live, R, t, P0)
        norm = float(np.sqrt(np.max(np.sum((dR - np.eye(3)) ** 2, axis=(1, 2)) + np.sum(tau**2, axis=1))))
        norms.append(norm)
        if norm < config.icp_tolerance:
            break
    warped = s + origin
    seconds = time.perf_counter() - start
    return WarpFieldResult(
        warped=warped, chamfer_before=float(chamfer_distance(P, Q)),
        chamfer_after=float(chamfer_distance(warped, Q)), seconds=seconds, iterations=len(norms),
        gn_iterations=gn_total, cg_iterations=solve.iterations, update_norms=np.asarray(norms), matches=matches,
        nodes=graph.nodes + origin, rotations=R, translations=t, origin=origin, config=config)
