"""The torch-autograd reference of the embedded-deformation registration: the losses written in
torch and differentiated by autograd (the implementation before the analytic numba gradient,
3-6 s per pair). It is the oracle of the tests and of ``benchmarks/registration_bench.py``; the
library never imports it, so a registration never loads torch.

``optimise_autograd`` plugs into :func:`tpvp.registration.embedded_deformation.register_embedded_deformation` in place
of the numba optimiser; both draw the same random subsets and step the same :class:`_Adam`.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial import cKDTree

from tpvp.registration.embedded_deformation import EDConfig, _Adam


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


def _chamfer_sq_torch(xs, qs, truncation):
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


def _laplacian_torch(x, k):
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




def torch_losses(P, Q, nodes, edge_idx, edge_w, anchor_idx, anchor_w, config: EDConfig):
    """The reference losses in torch: returns ``losses(phi, t, sel_p, sel_q, sel_l) -> (total,
    l_arap, l_cd, l_lap)`` (tensors; autograd gives the gradient). Used by
    :func:`optimise_autograd` and by the tests of the analytic gradient."""
    dt = torch.float64
    g = torch.as_tensor(nodes, dtype=dt)
    Pt, Qt = torch.as_tensor(P, dtype=dt), torch.as_tensor(Q, dtype=dt)
    a_idx, a_w = torch.as_tensor(anchor_idx), torch.as_tensor(anchor_w, dtype=dt)
    e_idx, e_w = torch.as_tensor(edge_idx), torch.as_tensor(edge_w, dtype=dt)
    g_ij = g[e_idx] - g[:, None, :]  # (M, k, 3) undeformed edge vectors

    def losses(phi, t, sel_p, sel_q, sel_l):
        def warp_subset(R, sel):
            ai = a_idx[sel]
            return _warp_torch(Pt[sel], g[ai], a_w[sel], R[ai], t[ai])

        sel_p, sel_q, sel_l = (torch.as_tensor(s) for s in (sel_p, sel_q, sel_l))
        R = axis_angle_to_matrix(phi)
        if e_idx.shape[1]:
            # |R_i(g_j-g_i) + g_i + t_i - (g_j + t_j)| written so that it is exactly 0 at identity
            res = torch.einsum("mij,mkj->mki", R, g_ij) - g_ij + t[:, None, :] - t[e_idx]
            l_arap = (e_w * (res**2).sum(-1)).mean()
        else:
            l_arap = t.sum() * 0.0
        l_cd = _chamfer_sq_torch(warp_subset(R, sel_p), Qt[sel_q], config.chamfer_truncation)
        if config.laplacian_in_gradient:
            l_lap = _laplacian_torch(warp_subset(R, sel_l), config.laplacian_k)
        else:  # reference quirk: @torch.no_grad(), the term only shifts the loss value
            with torch.no_grad():
                l_lap = _laplacian_torch(warp_subset(R, sel_l), config.laplacian_k)
        total = config.w_arap * l_arap + config.w_chamfer * l_cd + config.w_laplacian * l_lap
        return total, l_arap, l_cd, l_lap

    return losses


def optimise_autograd(P, Q, nodes, edge_idx, edge_w, anchor_idx, anchor_w, config: EDConfig):
    """The reference optimisation: losses in torch, gradient by autograd (the implementation before
    the analytic gradient; 3-6 s per pair). Kept as the oracle of the tests and the benchmark."""
    rng = np.random.default_rng(config.seed)
    losses_of = torch_losses(P, Q, nodes, edge_idx, edge_w, anchor_idx, anchor_w, config)
    phi = torch.zeros((len(nodes), 3), dtype=torch.float64, requires_grad=True)
    t = torch.zeros((len(nodes), 3), dtype=torch.float64, requires_grad=True)
    # the registration's Adam, on the parameters' memory (so both optimisers step identically)
    adam = _Adam((phi.detach().numpy(), t.detach().numpy()), config.lr)
    n_p, n_q = min(config.chamfer_samples, len(P)), min(config.chamfer_samples, len(Q))
    losses, terms = [], []
    old_threads = torch.get_num_threads()
    if config.threads is not None:
        torch.set_num_threads(config.threads)
    try:
        for _ in range(config.iterations):
            # fresh subsets each iteration (reference: torch.randperm, non-deterministic)
            sel_p = rng.choice(len(P), n_p, replace=False)
            sel_q = rng.choice(len(Q), n_q, replace=False)
            sel_l = rng.choice(len(P), n_p, replace=False)
            total, l_arap, l_cd, l_lap = losses_of(phi, t, sel_p, sel_q, sel_l)
            losses.append(total.item())
            terms.append((l_arap.item(), l_cd.item(), l_lap.item()))
            if losses[-1] < config.stop_loss:
                break
            grads = torch.autograd.grad(total, (phi, t), allow_unused=True, materialize_grads=True)
            adam.step(tuple(g.numpy() for g in grads))
            adam.lr *= config.lr_decay  # ExponentialLR, stepped every iteration
    finally:
        torch.set_num_threads(old_threads)
    with torch.no_grad():
        R = axis_angle_to_matrix(phi).numpy().copy()
        t_out = t.detach().numpy().copy()
    return R, t_out, np.asarray(losses), np.asarray(terms, dtype=np.float64).reshape(-1, 3)
