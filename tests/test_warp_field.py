"""Warp-field ICP (tpvp.registration.warp_field): the greenhouse-row registration."""

from dataclasses import replace

import numpy as np
import pytest
from scipy import sparse
from scipy.sparse import linalg as splinalg
from scipy.spatial import cKDTree

from tpvp.config import RowConfig
from tpvp.config_loading import make_config
from tpvp.errors import ConfigError, PointCloudError
from tpvp.registration.methods import REGISTRATION_METHODS, register
from tpvp.registration.warp_field import (
    WarpFieldConfig,
    WarpFieldResult,
    _build_graph,
    _LinearSolver,
    _normal_equations,
    conjugate_gradient,
    euler_zyx,
    nearest_rotation,
    register_warp_field,
    smallest_eigenvectors,
    target_normals,
)
from tpvp.scene import voxels
from tpvp.synthetic.greenhouse import generate_row


@pytest.fixture(scope="module")
def row():
    """Half of a generated room1 row (session 1) at 1 cm voxel centroids (~50k points) and its box."""
    session = generate_row("room1", 0, 1, point_spacing=0.01)
    box = session.plant_box
    P = voxels.voxel_centroids(session.points, 0.01)
    return P[box.to_local(P)[:, 0] < 0.0], box


def bend(points, box):
    """A known smooth warp in the row's box frame: a 1 degree turn about the box's vertical axis,
    a sideways bend growing with height (up to 3 cm) and a 1 cm vertical wave along the row."""
    L = box.to_local(points)
    length, height = box.extent[0], box.extent[2]
    c, s = np.cos(np.deg2rad(1.0)), np.sin(np.deg2rad(1.0))
    out = L @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T
    out[:, 1] += 0.03 * np.sin(np.pi * L[:, 0] / length) * (L[:, 2] / height + 0.5)
    out[:, 2] += 0.01 * np.cos(2 * np.pi * L[:, 0] / length)
    return box.to_world(out)


# ------------------------------------------------------------------------------------------------
# registration
# ------------------------------------------------------------------------------------------------


def test_recovers_a_known_smooth_deformation_of_a_row(row):
    P, box = row
    target = bend(P, box)
    moved = np.linalg.norm(target - P, axis=1).mean()
    result = register_warp_field(P, target, WarpFieldConfig(voxel=None))
    error = np.linalg.norm(result.warped - target, axis=1)
    assert moved > 0.02  # the warp to undo: ~2.6 cm on average
    assert error.mean() < 0.005, error.mean()
    assert result.chamfer_after < result.chamfer_before / 4
    assert 1 <= result.iterations <= 15 and result.gn_iterations >= result.iterations
    assert result.cg_iterations > 0 and result.matches == len(P)
    # the field applies to any points: the source itself gives the same warp
    np.testing.assert_allclose(result.warp(P), result.warped, atol=1e-12)


def test_identity_input_stays_put_after_one_iteration(row):
    P = row[0][::4]
    result = register_warp_field(P, P, WarpFieldConfig(voxel=None))
    assert result.iterations == 1 and result.update_norms[0] == 0.0 and result.gn_iterations == 1
    np.testing.assert_allclose(result.warped, P, atol=1e-12, rtol=0)
    assert result.chamfer_before == 0.0 and result.chamfer_after < 1e-12
    np.testing.assert_allclose(result.rotations, np.tile(np.eye(3), (result.n_nodes, 1, 1)), atol=1e-15)


@pytest.fixture(scope="module")
def unchanged_row():
    """A generated room1 row that did not change between sessions: P = its full cloud, Q = what the
    15 passive views see of it (~half of the row), as the greenhouse experiments build them."""
    from tpvp.simulate.greenhouse import build_row_scene
    from tpvp.simulate.row_cases import quick_config

    config = quick_config({"view_space": "room1"})
    points = generate_row("room1", 0, 1, point_spacing=0.008).points
    scene = build_row_scene(points, points, config, cache_dir=False)
    return scene.previous, scene.coarse, config.registration


def test_an_unchanged_row_stays_put(unchanged_row):
    """Issue 27.5: the row's registration moved what did not move. Correspondences searched from the
    partial scan Q onto P give the unseen parts of P no data term; Q inside P then stays put."""
    P, Q, config = unchanged_row
    seen = cKDTree(Q).query(P)[0] < 1e-9
    assert 0.2 < seen.mean() < 0.8  # a partial scan
    alignment = register(P, Q, config)
    moved = np.linalg.norm(alignment.warped - P, axis=1)
    assert moved.mean() <= 1e-3
    assert alignment.chamfer_after <= alignment.chamfer_before
    # the authors' previous -> coarse search pulls the unseen half onto the seen one
    authors = register_warp_field(P, Q, replace(config.warp_field, correspondences="previous-to-coarse"))
    assert np.linalg.norm(authors.warped - P, axis=1).mean() > 5e-3
    assert authors.chamfer_after > authors.chamfer_before


def test_coarse_to_previous_recovers_a_known_deformation(row):
    """Searched from the target side the field still undoes a smooth warp: seen whole, and seen
    only in part (the rest follows the regularisation)."""
    P, box = row
    P = P[::2]
    target = bend(P, box)
    config = WarpFieldConfig(voxel=None, correspondences="coarse-to-previous")
    whole = register_warp_field(P, target, config)
    assert np.linalg.norm(whole.warped - target, axis=1).mean() < 0.003  # measured 2.0 mm
    front = box.to_local(P)[:, 1] < 0.0  # the half facing one side of the row
    part = register_warp_field(P, target[front], config)
    error = np.linalg.norm(part.warped - target, axis=1)
    assert np.linalg.norm(target - P, axis=1)[~front].mean() > 0.025
    assert error[front].mean() < 0.0035 and error[~front].mean() < 0.006  # measured 2.4 and 4.2 mm


def test_matches_cilantro_on_a_small_patch():
    """The reference itself: cilantro @ cd473eb (SimpleCombinedMetricSparseRigidWarpFieldICP3f, float32,
    the settings of TPVP's cilantro_nicp Registration.cpp) run on this patch with these target normals
    (float32) gave 45 nodes, 2 iterations (converged) and the points below; all 400 points agreed
    with this implementation to 1.2 micrometres (max)."""
    def surface(u, v):
        return np.column_stack([u - 2.5, v + 0.2, 0.8 + 0.06 * np.sin(5 * u) * np.cos(4 * v)])

    rng = np.random.default_rng(7)
    P = surface(rng.uniform(0, 1.2, 400), rng.uniform(0, 0.6, 400)).astype(np.float32).astype(np.float64)
    Q = surface(rng.uniform(0, 1.2, 900), rng.uniform(0, 0.6, 900))
    x = Q[:, 0] + 2.5
    Q[:, 1] += 0.02 * np.sin(2.6 * x)
    Q[:, 2] += 0.01 * x
    Q = Q.astype(np.float32).astype(np.float64)
    result = register_warp_field(P, Q, WarpFieldConfig(voxel=None), viewpoint=(-1.9, -1.0, 1.5))
    assert result.n_nodes == 45 and result.iterations == 2
    cilantro = np.array([[-1.749948025, 0.414243728, 0.783586919], [-2.045246124, 0.454628617, 0.830803037],
                         [-1.884628534, 0.502684772, 0.807747424], [-1.710487604, 0.669833660, 0.818673491],
                         [-1.601935506, 0.488267243, 0.782311201], [-1.784100294, 0.623795331, 0.808861732]])
    np.testing.assert_allclose(result.warped[[0, 57, 123, 201, 288, 399]], cilantro, atol=5e-6)
    np.testing.assert_allclose((result.warped - P).mean(axis=0), [-0.000201548, 0.016776756, 0.006045130], atol=1e-6)


def test_linear_solvers_and_centred_rotations_agree(row):
    P, box = row
    P = P[::6]
    target = bend(P, box)
    default = register_warp_field(P, target, WarpFieldConfig(voxel=None))
    for solver in ("cg", "direct"):  # Eigen's Jacobi CG (the reference) and an exact solve
        other = register_warp_field(P, target, WarpFieldConfig(voxel=None, solver=solver))
        np.testing.assert_allclose(other.warped, default.warped, atol=1e-5)
        assert other.iterations == default.iterations
    assert other.cg_iterations == 0 and default.cg_iterations < default.gn_iterations * 10
    centred = register_warp_field(P, target, WarpFieldConfig(voxel=None, centre=True))
    assert np.linalg.norm(centred.origin - P.mean(axis=0)) < 1e-12
    assert np.linalg.norm(centred.warped - target, axis=1).mean() < 0.01
    np.testing.assert_allclose(centred.warp(P), centred.warped, atol=1e-12)


def test_voxel_reduction_and_the_registry(row):
    P, box = row
    P = P[::3]
    config = RowConfig().registration
    assert config.method == "warp-field" and config.warp_field == WarpFieldConfig(correspondences="coarse-to-previous")
    assert "warp-field" in REGISTRATION_METHODS
    dense = np.concatenate([P, P + 0.003])  # two points in most 1 cm voxels
    alignment = register(dense, bend(dense, box), config)
    assert isinstance(alignment.details, WarpFieldResult)
    assert alignment.warped.shape == voxels.voxel_centroids(dense, 0.01).shape  # the reduced session
    assert alignment.chamfer_after < alignment.chamfer_before / 2
    loaded = make_config("row", {"registration.warp_field.solver": "direct", "registration.warp_field.voxel": None})
    assert loaded.registration.warp_field.solver == "direct" and loaded.registration.warp_field.voxel is None


# ------------------------------------------------------------------------------------------------
# the linearised Gauss-Newton system against brute force
# ------------------------------------------------------------------------------------------------


def _sqrt_huber(x, delta):
    return np.sqrt(0.5) * abs(x) if abs(x) <= delta else np.sqrt(delta * (abs(x) - 0.5 * delta))


def _rotation(a, b, c):
    Rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    Ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    Rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _brute_residuals(theta, s, d, n, mask, nodes, config):
    """Every residual of the reference's least-squares problem, point by point and arc by arc."""
    out = []
    sigma_c, sigma_r = config.anchor_sigma, config.regularisation_sigma
    for p in range(len(s)):
        if not mask[p]:
            continue
        dist = np.linalg.norm(nodes - s[p], axis=1)  # s = the source itself here (first iteration)
        near = np.argsort(dist)[:config.anchors]
        w = np.exp(-0.5 * dist[near] ** 2 / sigma_c**2)
        avg = (w[:, None] * theta[near]).sum(axis=0) / w.sum()
        out.append(n[p] @ (_rotation(*avg[:3]) @ s[p] + avg[3:] - d[p]))
    for i in range(len(nodes)):
        dist = np.linalg.norm(nodes - nodes[i], axis=1)
        for j in np.argsort(dist)[1:config.regularisation_neighbours]:
            weight = np.sqrt(config.stiffness * np.exp(-0.5 * dist[j] ** 2 / sigma_r**2))
            out.extend(weight * _sqrt_huber(theta[i, k] - theta[j, k], config.huber) for k in range(6))
    return np.array(out)


def test_normal_equations_match_a_finite_difference_jacobian():
    rng = np.random.default_rng(3)
    config = WarpFieldConfig()
    # a wavy 0.5 x 0.35 m patch 2-3 m from the origin: 12 nodes, 8-NN graph
    u, v = rng.uniform(0, 0.5, 150), rng.uniform(0, 0.35, 150)
    s = np.column_stack([u - 2.0, v + 1.0, 0.05 * np.sin(6 * u) + 0.6])
    graph = _build_graph(s, config)
    cells = {}
    for point, key in zip(s, map(tuple, np.floor(s / config.node_spacing).astype(int))):
        cells.setdefault(key, []).append(point)
    brute_nodes = np.array([np.mean(cells[k], axis=0) for k in sorted(cells)])
    np.testing.assert_allclose(graph.nodes, brute_nodes, atol=1e-12)
    M = graph.n_nodes
    assert 8 <= M <= 20
    d = s + rng.normal(scale=0.02, size=s.shape)
    n = rng.normal(size=s.shape)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    mask = (rng.random(len(s)) > 0.2).astype(float)
    theta = rng.normal(scale=0.02, size=(M, 6))
    diffs = np.abs(theta[graph.arc_i] - theta[graph.arc_j])
    assert np.abs(diffs - config.huber).min() > 1e-5 and diffs.min() > 1e-5  # away from the kinks

    H, grad, cost = _normal_equations(graph, theta, s.T.copy(), d.T.copy(), n.T.copy(), mask, config)
    r = _brute_residuals(theta, s, d, n, mask, graph.nodes, config)
    h = 1e-6
    J = np.empty((len(r), 6 * M))
    for k in range(6 * M):
        step = np.zeros(6 * M)
        step[k] = h
        J[:, k] = (_brute_residuals(theta + step.reshape(M, 6), s, d, n, mask, graph.nodes, config)
                   - _brute_residuals(theta - step.reshape(M, 6), s, d, n, mask, graph.nodes, config)) / (2 * h)
    scale = np.abs(J.T @ J).max()
    np.testing.assert_allclose(H.toarray(), J.T @ J, atol=1e-6 * scale)
    np.testing.assert_allclose(grad, J.T @ r, atol=1e-6 * np.abs(J.T @ r).max())
    assert cost == pytest.approx(r @ r, rel=1e-12)

    # the same pairs as a correspondence list (the coarse -> previous search): the same system;
    # a pair listed twice counts twice
    source = np.flatnonzero(mask)
    listed = _normal_equations(graph, theta, s.T.copy(), d[source].T.copy(), n[source].T.copy(),
                               np.ones(len(source)), config, source)
    np.testing.assert_allclose(listed[0].toarray(), H.toarray(), rtol=1e-12, atol=1e-12 * scale)
    np.testing.assert_allclose(listed[1], grad, rtol=1e-12, atol=1e-12 * np.abs(grad).max())
    assert listed[2] == pytest.approx(cost, rel=1e-12)
    def listed_system(ids):
        return _normal_equations(graph, theta, s.T.copy(), d[ids].T.copy(), n[ids].T.copy(), np.ones(len(ids)),
                                 config, ids)

    doubled, once, none = (listed_system(ids) for ids in (np.append(source, source[0]), source[:1], source[:0]))
    for k in range(3):  # full + (one pair + regularisation) - regularisation
        expected = listed[k] + once[k] - none[k]
        np.testing.assert_allclose(doubled[k].toarray() if k == 0 else doubled[k],
                                   expected.toarray() if k == 0 else expected, rtol=1e-10, atol=1e-12 * scale)

    # every linear solver solves the system; the CG ones stop at Eigen's relative residual
    exact = np.linalg.solve(H.toarray(), -grad)
    for solver in ("cg", "lu-cg"):
        solve = _LinearSolver(WarpFieldConfig(solver=solver))
        x = solve(H, -grad)
        assert 0 < solve.iterations <= config.cg_iterations
        assert np.linalg.norm(H @ x + grad) <= config.cg_tolerance * np.linalg.norm(grad)
    x = solve(H * 1.01, -grad)  # lu-cg: the factorisation of the first system preconditions the next
    assert solve.iterations <= 4 and np.linalg.norm(1.01 * H @ x + grad) <= config.cg_tolerance * np.linalg.norm(grad)
    x_direct = _LinearSolver(WarpFieldConfig(solver="direct"))(H, -grad)
    np.testing.assert_allclose(x_direct, exact, atol=1e-6 * np.abs(exact).max())  # the 1e-13 ridge


def test_conjugate_gradient_is_eigens():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(40, 40))
    A = sparse.csr_matrix(A @ A.T + 40 * np.eye(40))
    b = rng.normal(size=40)
    x, steps = conjugate_gradient(A, b, 1e-10, 500)
    np.testing.assert_allclose(x, splinalg.spsolve(A.tocsc(), b), rtol=1e-8)
    assert steps <= 60
    assert conjugate_gradient(A, np.zeros(40))[1] == 0
    x3, steps3 = conjugate_gradient(A, b, 1e-10, 3)
    assert steps3 == 3 and np.linalg.norm(A @ x3 - b) > 1e-10 * np.linalg.norm(b)


def test_rotations_and_normals_match_dense_linear_algebra():
    rng = np.random.default_rng(1)
    angles = rng.normal(scale=0.5, size=(50, 3))
    R = euler_zyx(angles)
    np.testing.assert_allclose(R, [_rotation(*a) for a in angles], atol=1e-14)
    X = R + rng.normal(scale=0.05, size=R.shape)
    X[0] = -X[0]  # det < 0: cilantro's sign fix
    X[1] = 0.0
    U, _, Vt = np.linalg.svd(X)
    U[np.linalg.det(U @ Vt) < 0, :, 0] *= -1
    np.testing.assert_allclose(nearest_rotation(X), U @ Vt, atol=1e-12)
    cov = rng.normal(size=(200, 3, 3))
    cov = cov @ cov.transpose(0, 2, 1)
    cov[0] = np.diag([1.0, 0.0, 0.0])  # a line: the two smallest eigenvalues coincide
    vectors = np.linalg.eigh(cov)[1][:, :, 0]
    assert np.abs(np.einsum("ij,ij->i", smallest_eigenvectors(cov), vectors)).min() > 1 - 1e-9
    plane = np.column_stack([rng.uniform(0, 1, 500), rng.uniform(0, 1, 500), np.zeros(500)])
    up = target_normals(plane, 30, viewpoint=(0.5, 0.5, 2.0))
    np.testing.assert_allclose(up, np.tile([0.0, 0.0, 1.0], (500, 1)), atol=1e-12)
    np.testing.assert_allclose(target_normals(plane, 30, viewpoint=(0.5, 0.5, -2.0)), -up, atol=1e-12)


# ------------------------------------------------------------------------------------------------
# bad input
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("previous, coarse, message", [
    (np.zeros((0, 3)), None, "previous session P is empty"),
    (None, np.full((5, 3), np.nan), "coarse cloud Q contains NaN"),
    (np.zeros((5, 2)), None, r"previous session P must be an \(N, 3\) array"),
    ("abc", None, r"previous session P must be an \(N, 3\) array of numbers"),
    (None, "shift", "do not overlap"),
    (None, "mm", "look like millimetres"),
    (None, np.zeros((2, 3)), "coarse cloud Q has 1 point"),
])
def test_bad_input_is_one_clear_line(row, previous, coarse, message):
    P = row[0][::20]
    previous = P if previous is None else previous
    coarse = {"shift": P + [5.0, 0.0, 0.0], "mm": P * 1000.0}.get(coarse, coarse) if isinstance(coarse, str) else coarse
    coarse = P if coarse is None else coarse
    with pytest.raises(PointCloudError, match=message) as info:
        register_warp_field(previous, coarse)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("kwargs, message", [
    ({"node_spacing": 0}, "node_spacing must be a positive number"),
    ({"voxel": -0.01}, "voxel must be a positive number"),
    ({"anchors": 0}, "anchors must be an integer >= 1"),
    ({"icp_iterations": 2.5}, "icp_iterations must be an integer"),
    ({"solver": "lu"}, "solver must be one of lu-cg, cg, direct"),
    ({"correspondences": "nearest"}, "correspondences must be one of previous-to-coarse, coarse-to-previous, both"),
    ({"workers": 0}, "workers must be an integer >= 1 or -1"),
    ({"stiffness": -1.0}, "stiffness must be a number >= 0"),
])
def test_bad_configuration_is_one_clear_line(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        WarpFieldConfig(**kwargs)
    with pytest.raises(ConfigError, match="config must be a WarpFieldConfig"):
        register_warp_field(np.zeros((5, 3)), np.zeros((5, 3)), config={"node_spacing": 0.15})
    with pytest.raises(ConfigError, match="registration.warp_field"):
        make_config("row", {"registration.warp_field." + next(iter(kwargs)): next(iter(kwargs.values()))})
