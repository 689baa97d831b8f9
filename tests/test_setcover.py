"""Set cover against brute force, executed views, infeasible voxels, reductions and bad input."""

import itertools

import numpy as np
import pytest
from scipy import sparse

from tpvp.errors import ConfigError
from tpvp.setcover.config import SetCoverConfig
from tpvp.setcover.ilp import SetCoverResult, solve_set_cover
from tpvp.setcover import ilp as ilp_mod
from tpvp.solvers import SOLVERS


def brute_force(matrix, executed=(), candidates=None):
    """Size of a smallest cover by enumeration: (size, coverable voxel mask)."""
    a = np.asarray(matrix.todense() if sparse.issparse(matrix) else matrix, dtype=bool)
    n_views = a.shape[0]
    allowed = np.ones(n_views, bool) if candidates is None else np.asarray(candidates, bool).copy()
    allowed[list(executed)] = False
    covered = a[list(executed)].any(axis=0) if len(executed) else np.zeros(a.shape[1], bool)
    target = ~covered & a[allowed].any(axis=0)
    views = np.flatnonzero(allowed)
    for size in range(len(views) + 1):
        for combo in itertools.combinations(views, size):
            if a[list(combo)].any(axis=0)[target].all() if size else not target.any():
                return size, target
    raise AssertionError("unreachable: the allowed views cover every target voxel")


def random_instance(rng, n_views=None, n_voxels=None, density=None):
    n_views = n_views or int(rng.integers(1, 13))
    n_voxels = n_voxels or int(rng.integers(1, 31))
    density = density or rng.uniform(0.1, 0.5)
    return rng.random((n_views, n_voxels)) < density


def structured_instance(rng, n_views=12, n_voxels=30):
    """Duplicate and nested cover sets, so that every reduction fires."""
    base = rng.random((n_views, 8)) < 0.35
    cols = [base[:, rng.integers(8)] for _ in range(n_voxels // 2)]
    for _ in range(n_voxels - len(cols)):
        c = cols[rng.integers(len(cols))].copy()
        c[rng.integers(n_views)] = True  # a superset of an existing column
        cols.append(c)
    a = np.stack(cols, axis=1)
    a[rng.integers(n_views)] = a[rng.integers(n_views)]  # a duplicate view
    a[:, rng.integers(n_voxels)] = False
    a[rng.integers(n_views), rng.integers(n_voxels)] = True
    return a


def check_cover(result, a, executed=(), candidates=None):
    a = np.asarray(a, dtype=bool)
    sel = result.selected
    assert isinstance(result, SetCoverResult)
    assert np.all(np.diff(sel) > 0), "selection must be sorted and unique"
    assert not set(sel.tolist()) & set(np.asarray(executed, int).tolist())
    if candidates is not None:
        assert np.asarray(candidates, bool)[sel].all()
    _, target = brute_force(a, executed, candidates) if a.shape[0] <= 12 else (None, None)
    if target is not None:
        assert a[sel].any(axis=0)[target].all() if sel.size else not target.any()
    assert result.objective == sel.size


@pytest.mark.parametrize("solver", SOLVERS)
def test_equals_brute_force_on_random_tiny_instances(solver):
    rng = np.random.default_rng(7)
    for _ in range(40):
        a = random_instance(rng)
        expected, _ = brute_force(a)
        res = solve_set_cover(sparse.csr_matrix(a), config=SetCoverConfig(solver=solver))
        assert res.optimal and res.gap == 0.0 and res.bound == res.objective
        assert res.objective == expected
        check_cover(res, a)


@pytest.mark.parametrize("solver", SOLVERS)
def test_reductions_do_not_change_the_optimum(solver):
    rng = np.random.default_rng(11)
    fired = {"forced": 0, "merged": 0}
    for k in range(30):
        a = structured_instance(rng) if k % 2 else random_instance(rng, n_views=12, n_voxels=30)
        expected, _ = brute_force(a)
        full = solve_set_cover(a, config=SetCoverConfig(solver=solver, reduce=False))
        reduced = solve_set_cover(a, config=SetCoverConfig(solver=solver, reduce=True))
        assert full.objective == reduced.objective == expected
        check_cover(reduced, a)
        check_cover(full, a)
        fired["forced"] += reduced.n_forced
        fired["merged"] += reduced.n_constraints < full.n_constraints
    assert fired["forced"] > 0 and fired["merged"] > 0


def test_executed_views_are_excluded_and_their_voxels_removed():
    rng = np.random.default_rng(3)
    for solver in SOLVERS:
        for _ in range(15):
            a = random_instance(rng, n_views=10, n_voxels=25)
            executed = sorted(rng.choice(10, size=int(rng.integers(1, 4)), replace=False).tolist())
            expected, _ = brute_force(a, executed)
            res = solve_set_cover(a, executed=executed, config=SetCoverConfig(solver=solver))
            assert res.objective == expected
            assert res.n_already_covered == int(a[executed].any(axis=0).sum())
            check_cover(res, a, executed)


def test_candidate_mask_and_index_list_agree():
    rng = np.random.default_rng(5)
    for _ in range(10):
        a = random_instance(rng, n_views=11, n_voxels=20)
        mask = rng.random(11) < 0.7
        expected, _ = brute_force(a, (), mask)
        by_mask = solve_set_cover(a, candidates=mask)
        by_index = solve_set_cover(a, candidates=np.flatnonzero(mask))
        assert by_mask.objective == by_index.objective == expected
        np.testing.assert_array_equal(by_mask.selected, by_index.selected)
        check_cover(by_mask, a, (), mask)


def test_infeasible_voxels_are_dropped_and_counted():
    a = np.array([
        # voxel: 0  1  2  3  4  5
        [1, 0, 0, 0, 1, 0],  # view 0 (executed)
        [0, 1, 0, 0, 0, 0],  # view 1
        [0, 0, 1, 0, 0, 0],  # view 2 (not a candidate)
        [0, 1, 0, 0, 0, 1],  # view 3
    ], dtype=bool)
    res = solve_set_cover(a, executed=[0], candidates=np.array([True, True, False, True]))
    # voxel 3: seen by nobody; voxel 2: only by a non-candidate view.
    assert res.n_dropped_infeasible == 2
    assert res.n_already_covered == 2
    assert res.n_voxels == 6
    np.testing.assert_array_equal(res.selected, [3])
    assert res.optimal


def test_empty_problems():
    for a in (np.zeros((4, 0), bool), np.zeros((0, 5), bool), np.zeros((3, 5), bool)):
        res = solve_set_cover(a)
        assert res.objective == 0 and res.selected.size == 0 and res.optimal and res.gap == 0.0
    a = np.eye(3, dtype=bool)
    res = solve_set_cover(a, executed=[0, 1, 2])
    assert res.objective == 0 and res.n_already_covered == 3 and res.status == "nothing to cover"


def test_essential_views_are_forced():
    a = np.array([[1, 1, 0, 0], [0, 1, 1, 0], [0, 0, 1, 1], [0, 0, 0, 1]], dtype=bool)
    res = solve_set_cover(a)
    assert res.n_forced >= 1 and res.objective == 2
    np.testing.assert_array_equal(res.selected, [0, 2])


def test_deterministic_and_dense_sparse_agree():
    rng = np.random.default_rng(9)
    a = rng.random((40, 300)) < 0.08
    for solver in SOLVERS:
        cfg = SetCoverConfig(solver=solver)
        first = solve_set_cover(a, config=cfg)
        second = solve_set_cover(sparse.csr_matrix(a), config=cfg)
        np.testing.assert_array_equal(first.selected, second.selected)
        assert first.optimal
    cbc = solve_set_cover(a)
    highs = solve_set_cover(a, config=SetCoverConfig(solver="highs"))
    assert cbc.objective == highs.objective


def test_greedy_fallback_when_the_solver_finds_nothing(monkeypatch):
    rng = np.random.default_rng(2)
    a = rng.random((30, 200)) < 0.1
    exact = solve_set_cover(a, config=SetCoverConfig(reduce=False))
    monkeypatch.setattr(ilp_mod, "_solve_cbc", lambda b, config: (None, False, 3.2, "Stopped on time limit"))
    res = solve_set_cover(a, config=SetCoverConfig(reduce=False))
    assert not res.optimal and "greedy" in res.status
    assert res.objective >= exact.objective
    assert res.bound == 4.0  # ceil of the solver's bound
    assert res.gap == pytest.approx((res.objective - 4.0) / res.objective)
    covered = a[res.selected].any(axis=0)
    assert covered[a.any(axis=0)].all()


def test_cbc_log_parsing():
    from tpvp.solvers import parse_cbc_log

    log = ("Result - Stopped on time limit\n\nObjective value:                12.00000000\n"
           "Lower bound:                    10.400\nGap:                            0.15\n")
    parsed = parse_cbc_log(log)
    assert parsed == {"result": "Stopped on time limit", "objective": 12.0, "lower_bound": 10.4}
    assert parse_cbc_log("Upper bound:   7.5\n") == {"upper_bound": 7.5}


def test_bad_input_raises_config_error():
    a = np.eye(3, dtype=bool)
    with pytest.raises(ConfigError, match="solver"):
        SetCoverConfig(solver="gurobi")
    with pytest.raises(ConfigError, match="time_limit"):
        SetCoverConfig(time_limit=0)
    with pytest.raises(ConfigError, match="threads"):
        SetCoverConfig(threads=0)
    with pytest.raises(ConfigError, match="visibility"):
        solve_set_cover(np.ones(5, bool))
    with pytest.raises(ConfigError, match="visibility"):
        solve_set_cover(np.ones((2, 2, 2), bool))
    with pytest.raises(ConfigError, match="executed"):
        solve_set_cover(a, executed=[3])
    with pytest.raises(ConfigError, match="executed"):
        solve_set_cover(a, executed=[-1])
    with pytest.raises(ConfigError, match="executed"):
        solve_set_cover(a, executed=[0.5])
    with pytest.raises(ConfigError, match="candidates"):
        solve_set_cover(a, candidates=np.ones(4, bool))
    with pytest.raises(ConfigError, match="candidates"):
        solve_set_cover(a, candidates=[7])
    with pytest.raises(ConfigError, match="config"):
        solve_set_cover(a, config={"solver": "cbc"})


def test_real_tomato_cover_reaches_the_oracle(tomato_scene):
    from tpvp.viewspace.space import INITIAL_VIEW_INDICES
    from tpvp.visibility import covered_voxels, oracle_voxels, visibility_matrix

    grid, views = tomato_scene
    matrix = visibility_matrix(grid, views, np.zeros(3))
    executed = sorted(INITIAL_VIEW_INDICES.values())
    res = solve_set_cover(matrix, executed=executed)
    assert res.optimal and 1 <= res.objective < len(views) - len(executed)
    oracle = oracle_voxels(matrix)
    np.testing.assert_array_equal(covered_voxels(matrix, np.r_[executed, res.selected]), oracle)
    # Every voxel no view sees (hidden ones, the table) is counted as dropped.
    assert res.n_dropped_infeasible == grid.size - oracle.size
