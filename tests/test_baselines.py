"""Baselines: max coverage against brute force, the NBV (GMC) curve and the exact optimum."""

import itertools

import numpy as np
import pandas as pd
import pytest
from scipy import sparse

from tpvp.errors import ConfigError
from tpvp.config_loading import with_overrides
from tpvp.experiments.baselines import NBV_COLUMNS, break_tie, nbv_curve
from tpvp.path.local import local_path_lengths, obstacle_radius
from tpvp.setcover.config import SetCoverConfig
from tpvp.setcover.maxcover import MaxCoverResult, max_coverage
from tpvp.simulate.optimum import OPTIMUM_COLUMNS, optimum
from tpvp.solvers import SOLVERS
from tpvp.visibility import coverage_ratio, covered_voxels


def subsets_cover(a, base, views, max_size):
    """Covered count of ``base | union(combo)`` for every combo of at most ``max_size`` views."""
    best = int(base.sum())
    for size in range(1, max_size + 1):
        combos = np.asarray(list(itertools.combinations(views, size)), dtype=np.int64)
        if combos.size == 0:
            break
        union = a[combos].any(axis=1) | base
        best = max(best, int(union.sum(axis=1).max()))
    return best


def brute_max_cover(a, k, executed=(), weights=None):
    a = np.asarray(a, dtype=bool)
    base = a[list(executed)].any(axis=0) if len(executed) else np.zeros(a.shape[1], bool)
    views = [v for v in range(a.shape[0]) if v not in set(executed)]
    if weights is None:
        return subsets_cover(a, base, views, k)
    best = float(weights[base].sum())
    for size in range(1, k + 1):
        for combo in itertools.combinations(views, size):
            best = max(best, float(weights[base | a[list(combo)].any(axis=0)].sum()))
    return best


@pytest.mark.parametrize("solver", SOLVERS)
def test_max_coverage_equals_brute_force(solver):
    rng = np.random.default_rng(7)
    config = SetCoverConfig(solver=solver, time_limit=30.0)
    used = set()
    for trial in range(6):
        a = rng.random((8, 30)) < rng.uniform(0.1, 0.4)
        if trial % 2:
            a[:, 5:10] = a[:, [0]]  # identical columns, merged into one weighted class
            a[:, 12] = False  # a voxel no view sees
        executed = sorted(rng.choice(8, size=int(rng.integers(0, 3)), replace=False).tolist())
        for k in (1, 2, 3, 5):
            result = max_coverage(sparse.csr_matrix(a), k, executed=executed, config=config)
            assert isinstance(result, MaxCoverResult)
            assert result.covered == brute_max_cover(a, k, executed), (trial, k, executed)
            assert result.optimal and result.gap == 0.0 and result.bound == result.objective == result.covered
            sel = result.selected
            assert sel.size <= k and np.all(np.diff(sel) > 0) and not set(sel.tolist()) & set(executed)
            assert covered_voxels(sparse.csr_matrix(a), list(sel) + executed).size == result.covered
            used.add(result.solver)
    assert solver in used  # the ILP ran (not only the trivial cases)


@pytest.mark.parametrize("solver", SOLVERS)
def test_max_coverage_time_limit_reports_incumbent_and_bound(solver):
    rng = np.random.default_rng(0)
    a = rng.random((80, 4000)) < 0.05
    result = max_coverage(a, 8, executed=[0], config=SetCoverConfig(solver=solver, time_limit=0.5))
    assert not result.optimal and result.bound > result.objective
    assert result.gap == pytest.approx((result.bound - result.objective) / result.bound)
    assert result.selected.size == 8 and result.covered == covered_voxels(sparse.csr_matrix(a),
                                                                          [0, *result.selected]).size


@pytest.mark.parametrize("solver", SOLVERS)
def test_max_coverage_weights(solver):
    rng = np.random.default_rng(3)
    a = rng.random((7, 25)) < 0.3
    weights = rng.integers(0, 5, size=25).astype(float)
    result = max_coverage(a, 2, executed=[1], config=SetCoverConfig(solver=solver), weights=weights)
    assert result.objective == pytest.approx(brute_max_cover(a, 2, [1], weights))
    assert result.optimal


def test_max_coverage_trivial_and_bad_input():
    a = np.eye(4, dtype=bool)
    result = max_coverage(a, 5, executed=[0])  # every useful view fits the budget: no solver
    assert result.selected.tolist() == [1, 2, 3] and result.covered == 4 and result.solver == "none"
    assert max_coverage(np.zeros((3, 4), bool), 1).covered == 0
    for k in (0, -1, 1.5, True, None):
        with pytest.raises(ConfigError, match="k must be"):
            max_coverage(a, k)
    with pytest.raises(ConfigError, match="weights"):
        max_coverage(a, 1, weights=[1, 2])
    with pytest.raises(ConfigError, match="weights"):
        max_coverage(a, 1, weights=[1, -1, 0, 0])
    with pytest.raises(ConfigError, match="executed"):
        max_coverage(a, 1, executed=[7])
    with pytest.raises(ConfigError, match="SetCoverConfig"):
        max_coverage(a, 1, config={"solver": "cbc"})


@pytest.fixture(scope="module")
def small_case():
    from tpvp.config_loading import make_config
    from tpvp.simulate.single_plant import build_scene
    from tpvp.synthetic.plants import generate_session_pair

    config = make_config("plant", {"view_space": "tammes:10", "initial_view": 0,
                                   "registration.embedded_deformation.iterations": 20})
    pair = generate_session_pair("maize", 2, days=2.0)
    return build_scene(pair.previous.points, pair.current.points, config), config


def test_nbv_curve(small_case):
    scene, config = small_case
    n_views = len(scene.view_space)
    curve = nbv_curve(scene, config, max_views=n_views + 2)  # more than there are: stops at all views
    assert tuple(curve.columns) == NBV_COLUMNS
    assert curve["views"].tolist() == list(range(1, n_views + 1))
    views = curve["view"].tolist()
    assert views[0] == 0 and sorted(views) == list(range(n_views))
    assert curve["path_length"].iloc[0] == 0.0 and curve["step_length"].iloc[0] == 0.0
    assert np.all(np.diff(curve["coverage"]) >= 0) and np.all(np.diff(curve["path_length"]) >= 0)
    assert curve["coverage"].iloc[-1] == pytest.approx(1.0)
    for k in (1, 3, n_views):
        expected = coverage_ratio(covered_voxels(scene.truth_visibility, views[:k]), scene.oracle)
        assert curve["coverage"].iloc[k - 1] == pytest.approx(expected)
    # The move into view n uses the obstacle radius of what views 1..n-1 observed.
    seen = scene.grid.centres[scene.truth_visibility[views[:2]].indices]
    assert curve["radius"].iloc[2] == pytest.approx(obstacle_radius(seen, np.zeros(3)))
    step = local_path_lengths(scene.views[views[1:3]], np.zeros(3), curve["radius"].iloc[2])[0, 1]
    assert curve["step_length"].iloc[2] == pytest.approx(step)
    assert curve["path_length"].iloc[-1] == pytest.approx(curve["step_length"].sum())

    short = nbv_curve(scene, config, max_views=3)
    assert short["view"].tolist() == views[:3] and len(short) == 3
    for bad in (0, 2.5, True):
        with pytest.raises(ConfigError, match="max_views"):
            nbv_curve(scene, config, max_views=bad)


def test_break_tie_brute_force():
    """The tied candidate of shortest sphere-avoiding move, then the lowest index, by enumeration."""
    rng = np.random.default_rng(5)
    centre = np.zeros(3)
    for trial in range(40):
        n = int(rng.integers(3, 12))
        positions = rng.normal(size=(n, 3))
        positions *= 0.4 / np.linalg.norm(positions, axis=1, keepdims=True)
        if trial % 4 == 0:
            positions[-1] = positions[-2]  # two tied candidates at the same move length: the lower index
        scores = rng.integers(0, 3, size=n).astype(float)
        executed = sorted(rng.choice(n, size=int(rng.integers(1, n)), replace=False).tolist())
        current, radius = executed[-1], float(rng.uniform(0.0, 0.3))

        def moves(ids):
            return local_path_lengths(positions[[current, *ids]], centre, radius)[0, 1:]

        free = [v for v in range(n) if v not in executed]
        best = max(scores[free])
        tied = [v for v in free if scores[v] == best]
        lengths = {v: local_path_lengths(positions[[current, v]], centre, radius)[0, 1] for v in tied}
        expected = min(tied, key=lambda v: (lengths[v], v))
        assert break_tie(scores, tied[0], executed, moves) == (expected, len(tied))
        assert break_tie(scores, tied[0], executed, moves, "lowest-index") == (tied[0], len(tied))
    # a pick that is not among the largest scores, or scores that do not cover the views: kept
    assert break_tie([0.0, 1.0, 1.0], 0, [], lambda ids: np.zeros(len(ids))) == (0, 1)
    assert break_tie([], 3, [0, 1], lambda ids: np.zeros(len(ids))) == (3, 1)


def test_nbv_curve_breaks_ties_by_the_shortest_move(small_case, monkeypatch):
    """An NBV method whose gains are all 0: every pick is a tie, decided by the shortest move."""
    from tpvp.experiments import baselines
    from tpvp.nbv.methods import NbvChoice, ObservedViews

    class Flat(ObservedViews):
        def next_view(self):
            return NbvChoice(min(set(range(len(self.context.view_space))) - set(self.executed)),
                             np.zeros(len(self.context.view_space)))

    monkeypatch.setattr(baselines, "make_nbv", Flat)
    scene, config = small_case
    n_views = len(scene.view_space)
    curve = nbv_curve(scene, config, max_views=n_views)
    views = curve["view"].tolist()
    assert curve["tied"].tolist() == [0, *range(n_views - 1, 0, -1)]
    for k in range(1, n_views):
        free = [v for v in range(n_views) if v not in views[:k]]
        radius = curve["radius"].iloc[k]
        lengths = [local_path_lengths(scene.views[[views[k - 1], v]], np.zeros(3), radius)[0, 1] for v in free]
        assert views[k] == free[int(np.argmin(lengths))]
        assert curve["step_length"].iloc[k] == pytest.approx(min(lengths))
    lowest = nbv_curve(scene, with_overrides(config, {"gmc.tie_break": "lowest-index"}), max_views=n_views)
    assert lowest["view"].tolist() == [0, *range(1, n_views)]


def test_gmc_gain_after_four_views_on_the_bundled_tomato():
    """Issue 27: on the warm-up's 32-voxel map every gain is 0 after three or four views (the picks
    were the tie rule's); GMC's map (gmc.map_resolution) keeps telling the candidates apart."""
    from dataclasses import replace

    from tpvp.config_loading import make_config
    from tpvp.experiments import plants
    from tpvp.experiments.baselines import gmc_nbv_config
    from tpvp.nbv.methods import NbvContext, make_nbv

    case = plants.case_list([plants.bundled_instance()], view_spaces=("sphere",), rotations=(0.0,),
                            initial_views=(17,))[0]
    config = case.config(make_config("plant"))
    scene = plants.case_scene(case, config)
    curve = nbv_curve(scene, config, max_views=4)
    executed = curve["view"].tolist()
    assert (curve["tied"].iloc[1:4] == 1).all()  # the gain alone chose views 2..4

    def gains(nbv_config):
        space = scene.view_space
        nbv = make_nbv(NbvContext(space, np.zeros(3), scene.sensor, nbv_config, prior=scene.previous))
        for view in executed:
            nbv.integrate(view, scene.observe(view))
        scores = nbv.next_view().scores
        return np.delete(scores, executed)

    after = gains(gmc_nbv_config(config))
    assert after.max() > 0 and np.unique(after).size > 2
    assert gains(config.nbv).max() == 0  # the 32-voxel map: the old straw man
    assert gmc_nbv_config(replace(config, gmc=replace(config.gmc, map_resolution=None))) == config.nbv


def brute_min_views(a, initial, required):
    """Fewest further views (initial executed) whose union with the initial view covers
    ``required`` voxels, by enumeration."""
    base = a[initial]
    views = [v for v in range(a.shape[0]) if v != initial]
    for size in range(0, len(views) + 1):
        if subsets_cover(a, base, views, size) >= required:
            return size
    raise AssertionError("unreachable")


def test_optimum(small_case):
    scene, config = small_case
    table = optimum(scene, config, targets=(1.0, 0.98))
    assert tuple(table.columns) == OPTIMUM_COLUMNS
    full, partial = table.iloc[0], table.iloc[1]
    a = scene.truth_visibility[:, scene.oracle].toarray()
    assert full["views"] == 1 + brute_min_views(a, 0, a.shape[1])
    assert full["coverage"] == pytest.approx(1.0) and full["optimal"] and full["gap"] == 0.0
    assert partial["views"] == 1 + brute_min_views(a, 0, int(np.ceil(0.98 * a.shape[1])))
    assert partial["coverage"] >= 0.98 and partial["views"] <= full["views"] and partial["optimal"]
    order = [int(v) for v in partial["order"].strip("[]").split(",")]
    assert order[0] == 0 and len(order) == partial["views"]
    stops = scene.views[order]
    d = local_path_lengths(stops, np.zeros(3), obstacle_radius(scene.grid.centres[scene.oracle], np.zeros(3)))
    assert partial["path_length"] == pytest.approx(np.trace(d, offset=1))
    for bad in ((0.0,), (1.2,), (), ("x",), -0.5):
        with pytest.raises(ConfigError, match="targets"):
            optimum(scene, config, targets=bad)


def test_the_frontier_optimum_in_one_model_equals_each_target_alone(small_case):
    scene, config = small_case
    targets = (1.0, 0.8, 0.95, 0.9, 0.99)
    alone = optimum(scene, config, targets=targets)
    together = optimum(scene, config, targets=targets, shared=True)
    assert together["target"].tolist() == alone["target"].tolist()
    assert together["selection_optimal"].all() and alone["selection_optimal"].all()
    assert together["views"].tolist() == alone["views"].tolist()
    assert (together["coverage"] >= together["target"] - 1e-12).all()
    assert together["status"].str.contains("one model for all targets").all()


def test_coverage_frontier(small_case, tmp_path):
    from tpvp.simulate.frontier import FRONTIER_COLUMNS, coverage_frontier, write_frontier
    from tpvp.simulate.single_plant import run_case
    from tpvp.viz.experiments import plot_frontier

    scene, config = small_case
    frontier = coverage_frontier(scene, config, targets=(1.0, 0.8, 0.95, 0.9))
    assert tuple(frontier.columns) == FRONTIER_COLUMNS and frontier["target"].tolist() == [0.8, 0.9, 0.95, 1.0]
    assert np.all(np.diff(frontier["views"]) >= 0) and np.all(np.diff(frontier["optimum_views"]) >= 0)
    reached = frontier[frontier["coverage"] >= frontier["target"]]
    assert len(reached) and (reached["optimum_views"] <= reached["views"]).all()  # nothing beats the optimum
    assert (frontier["optimum_coverage"] >= frontier["target"] - 1e-12).all()
    full = run_case(scene, config)  # target 1.0 is today's plan
    last = frontier.iloc[-1]
    assert last["views"] == full.n_views and last["coverage"] == pytest.approx(full.coverage)
    assert plot_frontier(tmp_path / "frontier.png", frontier).stat().st_size > 0
    written = write_frontier(tmp_path / "out", scene, config, targets=(0.9, 1.0))
    assert written["figure"].is_file() and len(pd.read_csv(written["csv"])) == 2
    with pytest.raises(ConfigError, match="coverage targets"):
        coverage_frontier(scene, config, targets=(0.0, 0.9))
