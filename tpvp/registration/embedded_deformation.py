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
* Adam and the exponential decay are written out (same numbers as torch.optim, checked by a test)
  because torch.optim's first use imports torch._dynamo (~1.3 s);
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
import torch
from scipy.spatial import cKDTree

from tpvp.errors import ConfigError, PointCloudError, checked_cloud
from tpvp.io.pointcloud import MM_EXTENT_THRESHOLD
from tpvp.metrics.geometry import chamfer_distance
from tpvp.scene import voxels

# Clouds whose largest sides differ by more than this factor are assumed to be in different units.
_UNIT_RATIO = 50.0


@dataclass(frozen=True)
class EDConfig:
    """Parameters of :func:`register_embedded_deformation` (defaults: the paper / authors' code).

    node_coverage: graph voxel size r_graph (m). k_edges: graph neighbours per node.
    k_anchors: nodes blended per point. anchor_sigma_factor: sigma = factor * node_coverage.
    chamfer_samples: points drawn from P~ and from Q per iteration (also the Laplacian subset).
    chamfer_truncation: squared distance (m^2) from which a Chamfer term is zeroed.
    stop_loss: stop when the total loss falls below this. max_nodes: refuse larger graphs (units).
    threads: torch CPU threads during the call (None: leave torch's setting). Default 1: the
        tensors are ~1000 points, intra-op threads gain nothing, and on a shared 2-core machine
        OpenMP spin-waiting made 2 threads up to 5x slower (3.3 s vs 4.5-18 s per 300 iterations).
    """

    node_coverage: float = 0.004
    k_edges: int = 8
    k_anchors: int = 4
    anchor_sigma_factor: float = 1.5
    iterations: int = 300
    lr: float = 1e-3
    lr_decay: float = 0.999
    w_arap: float = 1.0
    w_chamfer: float = 0.1
    w_laplacian: float = 0.01
    laplacian_in_gradient: bool = False
    laplacian_k: int = 8
    chamfer_samples: int = 1000
    chamfer_truncation: float = 0.3
    stop_loss: float = 1e-7
    max_nodes: int = 100_000
    seed: int = 0
    threads: int | None = 1

    def __post_init__(self):
        for name in ("node_coverage", "anchor_sigma_factor", "lr", "chamfer_truncation"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise ConfigError(f"EDConfig.{name} must be a positive number, got {v!r}")
        for name in ("k_edges", "k_anchors", "chamfer_samples", "laplacian_k", "max_nodes"):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1):
                raise ConfigError(f"EDConfig.{name} must be an integer >= 1, got {v!r}")
        if not (isinstance(self.iterations, (int, np.integer)) and not isinstance(self.iterations, bool)
                and self.iterations >= 0):
            raise ConfigError(f"EDConfig.iterations must be an integer >= 0, got {self.iterations!r}")
        if not (np.isfinite(self.lr_decay) and 0 < self.lr_decay <= 1):
            raise ConfigError(f"EDConfig.lr_decay must be in (0, 1], got {self.lr_decay!r}")
        for name in ("w_arap", "w_chamfer", "w_laplacian", "stop_loss"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
                raise ConfigError(f"EDConfig.{name} must be a number >= 0, got {v!r}")
        if self.threads is not None and not (isinstance(self.threads, int) and self.threads >= 1):
            raise ConfigError(f"EDConfig.threads must be an integer >= 1 or None, got {self.threads!r}")
        if not isinstance(self.seed, (int, np.integer)):
            raise ConfigError(f"EDConfig.seed must be an integer, got {self.seed!r}")

    @property
    def anchor_sigma(self) -> float:
        return self.anchor_sigma_factor * self.node_coverage


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
# torch pieces
# --------------------------------------------------------------------------------------------------


def axis_angle_to_matrix(phi: torch.Tensor) -> torch.Tensor:
    """Rodrigues' formula R = I + A [phi]x + B [phi]x^2 for (M, 3) axis-angle vectors."""
    theta2 = (phi * phi).sum(-1)
    small = theta2 < 1e-8
    # evaluate sin/cos on a safe angle so that neither branch produces NaN gradients at 0
    theta = torch.sqrt(torch.where(small, torch.ones_like(theta2), theta2))
    a = torch.where(small, 1.0 - theta2 / 6.0 + theta2**2 / 120.0, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24.0 + theta2**2 / 720.0, (1.0 - torch.cos(theta)) / theta**2)
    zero = torch.zeros_like(phi[:, 0])
    K = torch.stack([zero, -phi[:, 2], phi[:, 1],
                     phi[:, 2], zero, -phi[:, 0],
                     -phi[:, 1], phi[:, 0], zero], dim=-1).reshape(-1, 3, 3)
    eye = torch.eye(3, dtype=phi.dtype).expand_as(K)
    return eye + a[:, None, None] * K + b[:, None, None] * (K @ K)


def _warp_torch(x, g_a, w, R_a, t_a):
    """ED blend of points x (n, 3) with anchor nodes g_a (n, k, 3), weights w (n, k), in the
    displacement form of :func:`_warp_numpy` (exact identity at zero parameters)."""
    local = x[:, None, :] - g_a
    moved = torch.einsum("nkij,nkj->nki", R_a, local) - local + t_a
    return x + (w[..., None] * moved).sum(1)


def _chamfer_sq(xs, qs, truncation):
    """Two-sided squared Chamfer of two subsets, sum of the directed means (reference loss)."""
    # The gradient flows through the distances only, not the NN choice, so the search can run in
    # numpy; two 1000-point KD-trees are several times faster than a dense cdist + argmin on CPU.
    xn, qn = xs.detach().numpy(), qs.detach().numpy()
    nn_xq = torch.as_tensor(cKDTree(qn).query(xn)[1])
    nn_qx = torch.as_tensor(cKDTree(xn).query(qn)[1])
    a = ((xs - qs[nn_xq]) ** 2).sum(-1)
    b = ((qs - xs[nn_qx]) ** 2).sum(-1)
    a = torch.where(a < truncation, a, torch.zeros_like(a))
    b = torch.where(b < truncation, b, torch.zeros_like(b))
    return a.mean() + b.mean()


def _laplacian(x, k):
    """Membrane Laplacian of a subset: mean of W_ij |x_i - x_j|^2 over its k-NN graph."""
    k = min(k, len(x) - 1)
    if k < 1:
        return x.sum() * 0.0
    d, nn = cKDTree(x.detach().numpy()).query(x.detach().numpy(), k=k + 1)
    # drop the point itself (column 0; with duplicate points this drops one of the copies)
    d, nn = torch.as_tensor(d[:, 1:]), torch.as_tensor(nn[:, 1:])
    sigma = d.median().clamp_min(1e-12)
    W = torch.exp(-(d**2) / (2 * sigma**2))  # held constant, as in the reference (no_grad)
    W = W / W.sum(1, keepdim=True)
    diff2 = ((x[:, None, :] - x[nn]) ** 2).sum(-1)
    return (W * diff2).mean()


# --------------------------------------------------------------------------------------------------
# main entry point
# --------------------------------------------------------------------------------------------------


def register_embedded_deformation(P, Q, config: EDConfig | None = None) -> RegistrationResult:
    """Warp the previous-session cloud P (N, 3) onto the current coarse reconstruction Q (metres).

    Both clouds must already share a frame (no rigid pre-alignment is done). Returns the warp of
    the final parameters (the reference returns the one of the start of its last iteration).
    """
    config = EDConfig() if config is None else config
    if not isinstance(config, EDConfig):
        raise ConfigError(f"config must be an EDConfig, got {type(config).__name__}")
    P = checked_cloud(P, "source cloud P")
    Q = checked_cloud(Q, "target cloud Q")
    _check_pair(P, Q, config.node_coverage)
    old_threads = torch.get_num_threads()
    if config.threads is not None:
        torch.set_num_threads(config.threads)
    try:
        start = time.perf_counter()
        nodes = voxels.voxel_centroids(P, config.node_coverage)
        if len(nodes) > config.max_nodes:
            raise PointCloudError(
                f"source cloud P gives {len(nodes)} graph nodes at node_coverage={config.node_coverage} m "
                f"(limit max_nodes={config.max_nodes}); is P in metres?")
        edge_idx, edge_w = _edges(nodes, config.k_edges)
        anchor_idx, anchor_w = _anchors(nodes, P, config)
        R, t, losses, terms = _optimise(P, Q, nodes, edge_idx, edge_w, anchor_idx, anchor_w, config)
        warped = _warp_numpy(P, nodes, R, t, anchor_idx, anchor_w)
        seconds = time.perf_counter() - start
    finally:
        torch.set_num_threads(old_threads)
    return RegistrationResult(
        warped=warped, chamfer_before=float(chamfer_distance(P, Q)),
        chamfer_after=float(chamfer_distance(warped, Q)), iterations=len(losses), seconds=seconds,
        nodes=nodes, rotations=R, translations=t, losses=losses, loss_terms=terms, config=config)


class _Adam:
    """torch.optim.Adam's update (betas 0.9/0.999, eps 1e-8, no weight decay), written out.

    Identical numbers; it avoids torch.optim, whose first use imports torch._dynamo (~1.3 s).
    """

    def __init__(self, params, lr, betas=(0.9, 0.999), eps=1e-8):
        self.params, self.lr, self.betas, self.eps, self.steps = params, lr, betas, eps, 0
        self.m = [torch.zeros_like(p) for p in params]
        self.v = [torch.zeros_like(p) for p in params]

    @torch.no_grad()
    def step(self, grads):
        b1, b2 = self.betas
        self.steps += 1
        bias1, bias2 = 1 - b1**self.steps, 1 - b2**self.steps
        for p, g, m, v in zip(self.params, grads, self.m, self.v):
            m.lerp_(g, 1 - b1)
            v.mul_(b2).addcmul_(g, g, value=1 - b2)
            denom = (v.sqrt() / bias2**0.5).add_(self.eps)
            p.addcdiv_(m, denom, value=-self.lr / bias1)


def _optimise(P, Q, nodes, edge_idx, edge_w, anchor_idx, anchor_w, config: EDConfig):
    dt = torch.float64
    rng = np.random.default_rng(config.seed)
    g = torch.as_tensor(nodes, dtype=dt)
    Pt, Qt = torch.as_tensor(P, dtype=dt), torch.as_tensor(Q, dtype=dt)
    a_idx, a_w = torch.as_tensor(anchor_idx), torch.as_tensor(anchor_w, dtype=dt)
    e_idx, e_w = torch.as_tensor(edge_idx), torch.as_tensor(edge_w, dtype=dt)
    phi = torch.zeros((len(nodes), 3), dtype=dt, requires_grad=True)
    t = torch.zeros((len(nodes), 3), dtype=dt, requires_grad=True)
    adam = _Adam((phi, t), config.lr)
    n_p, n_q = min(config.chamfer_samples, len(P)), min(config.chamfer_samples, len(Q))
    g_ij = g[e_idx] - g[:, None, :]  # (M, k, 3) undeformed edge vectors
    losses, terms = [], []

    def warp_subset(R, sel):
        ai = a_idx[sel]
        return _warp_torch(Pt[sel], g[ai], a_w[sel], R[ai], t[ai])

    for _ in range(config.iterations):
        R = axis_angle_to_matrix(phi)
        if e_idx.shape[1]:
            # |R_i(g_j-g_i) + g_i + t_i - (g_j + t_j)| written so that it is exactly 0 at identity
            res = torch.einsum("mij,mkj->mki", R, g_ij) - g_ij + t[:, None, :] - t[e_idx]
            l_arap = (e_w * (res**2).sum(-1)).mean()
        else:
            l_arap = t.sum() * 0.0
        # fresh subsets each iteration (reference: torch.randperm, non-deterministic)
        sel_p = torch.as_tensor(rng.choice(len(P), n_p, replace=False))
        sel_q = torch.as_tensor(rng.choice(len(Q), n_q, replace=False))
        l_cd = _chamfer_sq(warp_subset(R, sel_p), Qt[sel_q], config.chamfer_truncation)
        sel_l = torch.as_tensor(rng.choice(len(P), n_p, replace=False))
        if config.laplacian_in_gradient:
            l_lap = _laplacian(warp_subset(R, sel_l), config.laplacian_k)
        else:  # reference quirk: @torch.no_grad(), the term only shifts the loss value
            with torch.no_grad():
                l_lap = _laplacian(warp_subset(R, sel_l), config.laplacian_k)
        total = config.w_arap * l_arap + config.w_chamfer * l_cd + config.w_laplacian * l_lap
        losses.append(total.item())
        terms.append((l_arap.item(), l_cd.item(), l_lap.item()))
        if losses[-1] < config.stop_loss:
            break
        grads = torch.autograd.grad(total, (phi, t), allow_unused=True, materialize_grads=True)
        adam.step(grads)
        adam.lr *= config.lr_decay  # ExponentialLR, stepped every iteration
    with torch.no_grad():
        R = axis_angle_to_matrix(phi).numpy().copy()
        t_out = t.detach().numpy().copy()
    return R, t_out, np.asarray(losses), np.asarray(terms, dtype=np.float64).reshape(-1, 3)
