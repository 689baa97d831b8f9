"""Embedded-deformation registration (tpvp.registration)."""

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from tpvp.errors import ConfigError, PointCloudError
from tpvp.registration.config import EDConfig
from tpvp.registration.embedded_deformation import register_embedded_deformation
from tpvp.registration.autograd_reference import axis_angle_to_matrix, optimise_autograd, torch_losses
from tpvp.registration.embedded_deformation import (
    _Adam,
    _anchors,
    _edges,
    _grid_knn,
    _kth_smallest,
    _loss_and_gradient,
    _rodrigues,
    _warp_numpy,
)
from tpvp.scene.normalise import normalise_plant
from tpvp.scene.voxels import voxel_centroids
from tpvp.synthetic.plants import generate_plant


@pytest.fixture(scope="module")
def plant():
    """A generated tomato normalised to a 0.24 m largest side (~77k points)."""
    return normalise_plant(generate_plant("tomato", 0).points).points


def bend_twist(p, amp=0.004, twist_deg=3.0):
    """A known smooth warp: twist about z and a bend growing with height (mean ~3.7 mm, max ~8 mm)."""
    s = (p[:, 2] - p[:, 2].min()) / np.ptp(p[:, 2])
    a = np.deg2rad(twist_deg) * s
    out = p.copy()
    out[:, 0] = np.cos(a) * p[:, 0] - np.sin(a) * p[:, 1] + amp * s**2
    out[:, 1] = np.sin(a) * p[:, 0] + np.cos(a) * p[:, 1] + 0.5 * amp * np.sin(np.pi * s)
    return out


@pytest.fixture(scope="module")
def warped_pair(plant):
    rng = np.random.default_rng(0)
    P = plant[rng.choice(len(plant), 20000, replace=False)]
    Q = bend_twist(plant[rng.choice(len(plant), 8000, replace=False)])  # other samples of the surface
    return P, Q, bend_twist(P)


# ------------------------------------------------------------------------------------------------
# building blocks
# ------------------------------------------------------------------------------------------------


def test_rodrigues_matches_scipy_and_is_smooth_at_zero():
    rng = np.random.default_rng(0)
    phi = np.concatenate([rng.normal(size=(20, 3)), rng.normal(size=(5, 3)) * 1e-6, np.zeros((1, 3))])
    R = axis_angle_to_matrix(torch.as_tensor(phi)).numpy()
    np.testing.assert_allclose(R, Rotation.from_rotvec(phi).as_matrix(), atol=1e-12)
    x = torch.zeros((1, 3), dtype=torch.float64, requires_grad=True)
    axis_angle_to_matrix(x).sum().backward()
    assert torch.isfinite(x.grad).all()


def test_voxel_centroids_match_a_python_grouping():
    rng = np.random.default_rng(1)
    pts = rng.uniform(-0.02, 0.02, size=(500, 3))
    groups = {}
    for p in pts:
        groups.setdefault(tuple(np.floor(p / 0.004).astype(int)), []).append(p)
    expected = sorted(tuple(np.mean(v, axis=0)) for v in groups.values())
    got = sorted(map(tuple, voxel_centroids(pts, 0.004)))
    np.testing.assert_allclose(got, expected, atol=1e-15)


def test_graph_edges_and_anchor_weights():
    rng = np.random.default_rng(2)
    nodes = rng.uniform(0, 0.05, size=(40, 3))
    idx, w = _edges(nodes, 8)
    assert idx.shape == (40, 8) and not np.any(idx == np.arange(40)[:, None])
    np.testing.assert_allclose(w.sum(1), 1.0)
    pts = rng.uniform(0, 0.05, size=(100, 3))
    a_idx, a_w = _anchors(nodes, pts, EDConfig())
    d = np.linalg.norm(pts[:, None] - nodes[a_idx], axis=2)
    expected = np.exp(-(d**2) / 0.006**2)  # sigma = 1.5 * 4 mm, no factor 2
    np.testing.assert_allclose(a_w, expected / expected.sum(1, keepdims=True))


def test_same_rigid_motion_on_every_node_moves_points_rigidly(plant):
    nodes = voxel_centroids(plant, 0.004)
    R = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    T = np.array([0.01, 0.0, -0.02])
    rotations = np.repeat(R[None], len(nodes), axis=0)
    translations = T - nodes + nodes @ R.T  # R(x - g) + g + t = R x + T
    pts = plant[:2000]
    idx, w = _anchors(nodes, pts, EDConfig())
    np.testing.assert_allclose(_warp_numpy(pts, nodes, rotations, translations, idx, w), pts @ R.T + T, atol=1e-12)


def test_adam_is_torch_adam_with_exponential_lr():
    """The numpy Adam against torch.optim.Adam + ExponentialLR: equal up to the rounding of the
    multiply-adds torch fuses (a few ulps after 300 steps)."""
    torch.manual_seed(0)
    A = torch.randn(20, 3, dtype=torch.float64)

    def loss(p):
        return (A @ p.T).sin().sum() + (p**4).sum()

    p1 = torch.randn(400, 3, dtype=torch.float64, requires_grad=True)
    p2 = p1.detach().numpy().copy()
    opt = torch.optim.Adam([p1], lr=1e-2)
    sched = torch.optim.lr_scheduler.ExponentialLR(opt, 0.99)
    mine = _Adam((p2,), 1e-2)
    start = p2.copy()
    for _ in range(300):
        opt.zero_grad()
        loss(p1).backward()
        opt.step()
        sched.step()
        at = torch.tensor(p2, requires_grad=True)
        mine.step((torch.autograd.grad(loss(at), (at,))[0].numpy(),))
        mine.lr *= 0.99
    assert np.abs(p2 - start).max() > 0.1  # the parameters moved
    np.testing.assert_allclose(p2, p1.detach().numpy(), rtol=0, atol=1e-14)


def test_registration_never_imports_torch():
    """A command that registers does not pay torch's ~2 s import."""
    import subprocess
    import sys

    code = ("import sys, numpy as np; from tpvp.registration.config import EDConfig; "
            "from tpvp.registration.embedded_deformation import register_embedded_deformation; "
            "P = np.random.default_rng(0).uniform(0, 0.02, (200, 3)); "
            "register_embedded_deformation(P, P + 0.0005, EDConfig(iterations=3)); "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_numba_rodrigues_matches_torch():
    rng = np.random.default_rng(5)
    phi = np.concatenate([rng.normal(size=(20, 3)), rng.normal(size=(5, 3)) * 1e-6, np.zeros((1, 3))])
    R = np.empty((len(phi), 3, 3))
    _rodrigues(phi, R, np.empty(len(phi)), np.empty(len(phi)))
    np.testing.assert_allclose(R, axis_angle_to_matrix(torch.as_tensor(phi)).numpy(), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(R[-1], np.eye(3))  # exact identity at zero


@pytest.mark.parametrize("k", [1, 4, 9])
def test_grid_knn_matches_kdtree(k):
    rng = np.random.default_rng(6)
    clouds = {
        "plant-like": np.concatenate([rng.normal(size=(700, 3)) * [0.05, 0.05, 0.002],
                                      rng.normal(size=(300, 3)) * [0.002, 0.002, 0.08]]),
        "flat": np.c_[rng.uniform(0, 0.1, size=(300, 2)), np.zeros(300)],
        "duplicates": np.repeat(rng.uniform(0, 0.01, size=(40, 3)), 3, axis=0),
        "few": rng.uniform(0, 0.01, size=(k, 3)),
    }
    for name, ref in clouds.items():
        queries = np.concatenate([ref[: len(ref) // 2] + rng.normal(size=(len(ref) // 2, 3)) * 0.003,
                                  rng.uniform(-0.3, 0.3, size=(50, 3)),  # outside the grid, far away
                                  ref[:10]])  # exact hits
        idx = np.empty((len(queries), k), np.int64)
        d2 = np.empty((len(queries), k))
        _grid_knn(ref, queries, k, idx, d2)
        d_ref, _ = cKDTree(ref).query(queries, k=k)
        d_ref = d_ref.reshape(len(queries), k)
        np.testing.assert_array_equal(np.sqrt(d2), d_ref, err_msg=name)  # the same distances, bit for bit
        np.testing.assert_array_equal(((queries[:, None] - ref[idx]) ** 2).sum(-1), d2, err_msg=name)
        assert np.all(np.diff(d2, axis=1) >= 0)


def _ring_scan_knn(ref, queries, k):
    """The grid search without skipping a cell, in plain Python: every cell of every ring scanned,
    each point entering the k best only when strictly closer (so ties keep the first found)."""
    from tpvp.registration.embedded_deformation import _grid_build

    lo, h, dims, start, order, pts = _grid_build(ref)
    margin = 1e-9 * h
    idx, d2 = np.full((len(queries), k), -1), np.full((len(queries), k), np.inf)
    for s, q in enumerate(queries):
        c = np.clip(np.floor((q - lo) / h).astype(int), 0, dims - 1)
        r = 0
        while True:
            ring = [(x, y, z) for x in range(max(c[0] - r, 0), min(c[0] + r, dims[0] - 1) + 1)
                    for y in range(max(c[1] - r, 0), min(c[1] + r, dims[1] - 1) + 1)
                    for z in range(max(c[2] - r, 0), min(c[2] + r, dims[2] - 1) + 1)
                    if max(abs(x - c[0]), abs(y - c[1]), abs(z - c[2])) == r]
            for x, y, z in ring:
                cell = (x * dims[1] + y) * dims[2] + z
                for j in range(start[cell], start[cell + 1]):
                    d = float(((q - pts[j]) ** 2).sum())
                    if d < d2[s, -1]:
                        m = int(np.searchsorted(d2[s], d, side="right"))
                        d2[s, m + 1:], idx[s, m + 1:] = d2[s, m:-1].copy(), idx[s, m:-1].copy()
                        d2[s, m], idx[s, m] = d, order[j]
            bounds = [q[a] - (lo[a] + (c[a] - r) * h) for a in range(3) if c[a] - r > 0]
            bounds += [lo[a] + (c[a] + r + 1) * h - q[a] for a in range(3) if c[a] + r + 1 < dims[a]]
            if not bounds or d2[s, -1] <= max(min(bounds) - margin, 0.0) ** 2:
                break
            r += 1
    return idx, d2


@pytest.mark.parametrize("k", [1, 3, 9])
def test_grid_knn_keeps_the_first_found_of_equal_distances_as_a_full_ring_scan(k):
    """Skipping the cells no closer than the k-th found changes nothing, ties included: the same
    indices as scanning every cell of every ring (duplicate points, a lattice's equal distances)."""
    rng = np.random.default_rng(8)
    lattice = np.stack(np.meshgrid(*[np.arange(5.0)] * 3), -1).reshape(-1, 3) * 0.01
    clouds = {"duplicates": np.repeat(rng.uniform(0, 0.02, size=(30, 3)), 3, axis=0),
              "lattice": np.concatenate([lattice, lattice[:20]]),
              "plant-like": np.concatenate([rng.normal(size=(150, 3)) * [0.05, 0.05, 0.002],
                                            rng.normal(size=(50, 3)) * [0.002, 0.002, 0.08]])}
    for name, ref in clouds.items():
        queries = np.concatenate([ref[:40], ref[:40] + 0.005, rng.uniform(-0.1, 0.1, size=(20, 3))])
        idx, d2 = np.empty((len(queries), k), np.int64), np.empty((len(queries), k))
        _grid_knn(ref, queries, k, idx, d2)
        expected_idx, expected_d2 = _ring_scan_knn(ref, queries, k)
        np.testing.assert_array_equal(idx, expected_idx, err_msg=name)
        np.testing.assert_array_equal(d2, expected_d2, err_msg=name)


def test_kth_smallest_is_torch_lower_median():
    rng = np.random.default_rng(7)
    for n in (1, 2, 7, 8, 1000):
        values = np.round(rng.uniform(0, 1, size=n), 2)  # with ties
        assert _kth_smallest(values, (n - 1) // 2) == torch.as_tensor(values).median().item()


def _small_problem(n_p=300, n_q=250):
    rng = np.random.default_rng(8)
    plant = normalise_plant(generate_plant("tomato", 1).points).points
    P = plant[rng.choice(len(plant), n_p, replace=False)]
    Q = bend_twist(plant[rng.choice(len(plant), n_q, replace=False)])
    config = EDConfig(node_coverage=0.02)
    nodes = voxel_centroids(P, config.node_coverage)
    e_idx, e_w = _edges(nodes, config.k_edges)
    a_idx, a_w = _anchors(nodes, P, config)
    M = len(nodes)
    phi = rng.normal(size=(M, 3)) * 0.05
    phi[:3] *= 1e-5  # the small-angle branch of Rodrigues
    phi[3] = 0.0
    t = rng.normal(size=(M, 3)) * 2e-3
    sel = (rng.choice(n_p, 200, replace=False), rng.choice(n_q, 150, replace=False),
           rng.choice(n_p, 200, replace=False))
    return P, Q, nodes, e_idx, e_w, a_idx, a_w, phi, t, sel


def _analytic(P, Q, nodes, e_idx, e_w, a_idx, a_w, phi, t, sel, config):
    g_phi, g_t = np.zeros_like(phi), np.zeros_like(t)
    g_ij = nodes[e_idx] - nodes[:, None, :]
    terms = _loss_and_gradient(phi, t, P, Q, nodes, a_idx, a_w, e_idx, e_w, g_ij, *sel, config.w_arap,
                               config.w_chamfer, config.w_laplacian, config.laplacian_in_gradient,
                               config.laplacian_k, config.chamfer_truncation, g_phi, g_t)
    return np.array(terms), g_phi, g_t


@pytest.mark.parametrize("laplacian_in_gradient", [False, True])
def test_analytic_gradient_equals_autograd(laplacian_in_gradient):
    """The numba losses and hand-written gradient against the torch reference + autograd, at
    random non-zero parameters (both Rodrigues branches, one node at exactly zero)."""
    P, Q, nodes, e_idx, e_w, a_idx, a_w, phi, t, sel = _small_problem()
    config = EDConfig(node_coverage=0.02, laplacian_in_gradient=laplacian_in_gradient, w_laplacian=0.5)
    terms, g_phi, g_t = _analytic(P, Q, nodes, e_idx, e_w, a_idx, a_w, phi, t, sel, config)
    phi_t = torch.tensor(phi, requires_grad=True)
    t_t = torch.tensor(t, requires_grad=True)
    total, *ref_terms = torch_losses(P, Q, nodes, e_idx, e_w, a_idx, a_w, config)(phi_t, t_t, *sel)
    ref_phi, ref_t = torch.autograd.grad(total, (phi_t, t_t))
    np.testing.assert_allclose(terms, [x.item() for x in ref_terms], rtol=1e-13, atol=0)
    assert np.all(terms > 0)
    for mine, ref in ((g_phi, ref_phi.numpy()), (g_t, ref_t.numpy())):
        assert np.abs(ref).max() > 0
        np.testing.assert_allclose(mine, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


def test_analytic_gradient_equals_finite_differences():
    """Independent of the torch code: central differences of w_arap L_arap + w_chamfer L_cd (the
    nearest neighbours do not change for such small steps). The Laplacian is left out: its
    gradient holds the weights W constant (reference), finite differences would not."""
    P, Q, nodes, e_idx, e_w, a_idx, a_w, phi, t, sel = _small_problem()
    config = EDConfig(node_coverage=0.02)
    weights = np.array([config.w_arap, config.w_chamfer, 0.0])
    _, g_phi, g_t = _analytic(P, Q, nodes, e_idx, e_w, a_idx, a_w, phi, t, sel, config)
    rng = np.random.default_rng(9)
    for params, grad, h in ((phi, g_phi, 1e-6), (t, g_t, 1e-8)):
        for m in [0, 3] + list(rng.choice(len(nodes), 6, replace=False)):  # 0: small angle, 3: zero
            for a in range(3):
                old = params[m, a]
                params[m, a] = old + h
                up = _analytic(P, Q, nodes, e_idx, e_w, a_idx, a_w, phi, t, sel, config)[0] @ weights
                params[m, a] = old - h
                down = _analytic(P, Q, nodes, e_idx, e_w, a_idx, a_w, phi, t, sel, config)[0] @ weights
                params[m, a] = old
                fd = (up - down) / (2 * h)
                assert abs(fd - grad[m, a]) <= 1e-6 * np.abs(grad).max(), (m, a, fd, grad[m, a])


# ------------------------------------------------------------------------------------------------
# registration
# ------------------------------------------------------------------------------------------------


def test_recovers_known_smooth_warp(warped_pair):
    """Paper settings: 3.65 mm mean motion -> ~1.0 mm. The residual is the reference's noise floor
    (fresh 1000-point Chamfer subsets + Adam moving every node ~lr = 1 mm per step), not bias: with
    a faster lr decay (0.99) the same run ends at ~0.7 mm."""
    P, Q, truth = warped_pair
    before = np.linalg.norm(P - truth, axis=1).mean()
    paper = register_embedded_deformation(P, Q)
    err_paper = np.linalg.norm(paper.warped - truth, axis=1).mean()
    assert before > 3e-3
    assert err_paper < 1.5e-3 and err_paper < before / 2.5
    assert paper.chamfer_after < 0.6 * paper.chamfer_before
    assert paper.iterations == 300 and paper.losses.shape == (300,) and paper.loss_terms.shape == (300, 3)
    assert 900 <= paper.n_nodes <= 2400
    decayed = register_embedded_deformation(P, Q, EDConfig(lr_decay=0.99))
    assert np.linalg.norm(decayed.warped - truth, axis=1).mean() < 1e-3
    # the graph can be applied to other points: on P itself it reproduces the output
    np.testing.assert_allclose(paper.warp(P[:500]), paper.warped[:500], atol=1e-12)


def test_identity_when_p_equals_q(plant):
    # With N <= chamfer_samples the subsets are the whole clouds: every gradient is exactly 0 at
    # the identity, so nothing may move (the ED blend and ARAP are written to be exact there).
    P = plant[np.random.default_rng(3).choice(len(plant), 900, replace=False)]
    r = register_embedded_deformation(P, P, EDConfig(iterations=40, stop_loss=0.0))
    assert r.iterations == 40
    np.testing.assert_array_equal(r.warped, P)
    assert r.chamfer_before == r.chamfer_after == 0.0


def test_no_deformation_stays_put(plant):
    """P and Q are different samples of one surface: Chamfer must not get worse beyond the
    stochastic-subset noise floor (~1 mm of jitter at the paper's lr)."""
    rng = np.random.default_rng(4)
    P = plant[rng.choice(len(plant), 20000, replace=False)]
    Q = plant[rng.choice(len(plant), 8000, replace=False)]
    r = register_embedded_deformation(P, Q, EDConfig(iterations=150))
    assert r.chamfer_after <= r.chamfer_before + 0.2e-3
    assert np.linalg.norm(r.warped - P, axis=1).mean() < 1.5e-3


def test_deterministic_and_seeded(warped_pair):
    P, Q, _ = warped_pair
    cfg = EDConfig(iterations=25)
    a = register_embedded_deformation(P, Q, cfg)
    b = register_embedded_deformation(P, Q, cfg)
    np.testing.assert_array_equal(a.warped, b.warped)
    np.testing.assert_array_equal(a.losses, b.losses)
    c = register_embedded_deformation(P, Q, EDConfig(iterations=25, seed=1))
    assert not np.array_equal(a.warped, c.warped)
    d = register_embedded_deformation(P, Q, EDConfig(iterations=25, threads=None))  # torch's own setting
    np.testing.assert_array_equal(a.warped, d.warped)
    assert torch.get_num_threads() >= 1  # the thread setting is restored


@pytest.mark.parametrize("config", [EDConfig(iterations=60),
                                    EDConfig(iterations=30, laplacian_in_gradient=True, w_laplacian=10.0),
                                    EDConfig(iterations=30, chamfer_samples=300, k_edges=3, k_anchors=2)])
def test_equals_the_autograd_implementation(warped_pair, config):
    """The analytic-gradient optimiser reproduces the torch-autograd one (the implementation it
    replaced, kept as optimise_autograd) up to rounding: same subsets, same steps."""
    P, Q, _ = warped_pair
    fast = register_embedded_deformation(P, Q, config)
    ref = register_embedded_deformation(P, Q, config, optimise_autograd)
    assert fast.iterations == ref.iterations == config.iterations
    np.testing.assert_allclose(fast.warped, ref.warped, rtol=0, atol=1e-14)
    np.testing.assert_allclose(fast.translations, ref.translations, rtol=0, atol=1e-14)
    np.testing.assert_allclose(fast.rotations, ref.rotations, rtol=0, atol=1e-13)
    np.testing.assert_allclose(fast.losses, ref.losses, rtol=1e-12, atol=0)
    np.testing.assert_allclose(fast.loss_terms, ref.loss_terms, rtol=1e-12, atol=0)
    assert np.abs(fast.warped - P).max() > 1e-3  # it did move


def test_laplacian_flag(warped_pair):
    P, Q, _ = warped_pair
    off = register_embedded_deformation(P, Q, EDConfig(iterations=10))
    on = register_embedded_deformation(P, Q, EDConfig(iterations=10, laplacian_in_gradient=True, w_laplacian=10.0))
    no_lap = register_embedded_deformation(P, Q, EDConfig(iterations=10, w_laplacian=0.0))
    np.testing.assert_array_equal(off.warped, no_lap.warped)  # reference: no gradient by default
    assert not np.array_equal(off.warped, on.warped)
    assert np.all(off.loss_terms[:, 2] > 0)


# ------------------------------------------------------------------------------------------------
# bad input
# ------------------------------------------------------------------------------------------------


def test_bad_clouds(warped_pair):
    P, Q, _ = warped_pair
    with pytest.raises(PointCloudError, match="source cloud P is empty"):
        register_embedded_deformation(np.zeros((0, 3)), Q)
    with pytest.raises(PointCloudError, match="target cloud Q is empty"):
        register_embedded_deformation(P, np.zeros((0, 3)))
    bad = Q.copy()
    bad[5, 1] = np.nan
    with pytest.raises(PointCloudError, match="target cloud Q contains NaN"):
        register_embedded_deformation(P, bad)
    with pytest.raises(PointCloudError, match=r"\(N, 3\)"):
        register_embedded_deformation(P[:, :2], Q)
    with pytest.raises(PointCloudError, match="units"):
        register_embedded_deformation(P * 1000, Q)  # P in mm, Q in m
    with pytest.raises(PointCloudError, match="coarse/rigid alignment"):
        register_embedded_deformation(P + [1.0, 0, 0], Q)
    with pytest.raises(PointCloudError, match="metres"):
        register_embedded_deformation(P * 1000, Q * 1000, EDConfig(iterations=1))  # both in mm


def test_bad_config():
    with pytest.raises(ConfigError, match="node_coverage"):
        EDConfig(node_coverage=0)
    with pytest.raises(ConfigError, match="k_anchors"):
        EDConfig(k_anchors=0)
    with pytest.raises(ConfigError, match="iterations"):
        EDConfig(iterations=-1)
    with pytest.raises(ConfigError, match="lr_decay"):
        EDConfig(lr_decay=1.5)
    with pytest.raises(ConfigError, match="w_chamfer"):
        EDConfig(w_chamfer=-1)
    with pytest.raises(ConfigError, match="config"):
        register_embedded_deformation(np.zeros((3, 3)), np.zeros((3, 3)), config={"iterations": 3})


def test_tiny_clouds_do_not_crash():
    P = np.array([[0.0, 0, 0], [0.001, 0, 0], [0.02, 0.01, 0]])
    r = register_embedded_deformation(P, P + 0.0005, EDConfig(iterations=5))
    assert r.warped.shape == (3, 3) and np.all(np.isfinite(r.warped))
    one = register_embedded_deformation(P[:1], P[:1] + 0.001, EDConfig(iterations=5))
    assert one.n_nodes == 1 and np.all(np.isfinite(one.warped))
