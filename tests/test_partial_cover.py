"""Partial set cover (fewest views for a required coverage) against brute-force enumeration."""

import itertools

import numpy as np
import pytest
from scipy import sparse

from tpvp.errors import ConfigError
from tpvp.setcover.config import SetCoverConfig
from tpvp.setcover.ilp import solve_set_cover
from tpvp.setcover.partial import PartialCoverResult, partial_set_cover, partial_set_covers
from tpvp.solvers import SOLVERS


def brute_fewest(a, required, executed=(), weights=None):
    """Fewest non-executed views whose union with the executed ones reaches ``required``; None
    when no subset does."""
    a = np.asarray(a, dtype=bool)
    weights = np.ones(a.shape[1]) if weights is None else np.asarray(weights, float)
    base = a[list(executed)].any(axis=0) if len(executed) else np.zeros(a.shape[1], bool)
    views = [v for v in range(a.shape[0]) if v not in set(executed)]
    for size in range(len(views) + 1):
        for combo in itertools.combinations(views, size):
            union = base | (a[list(combo)].any(axis=0) if combo else False)
            if weights[union].sum() >= required - 1e-9:
                return size
    return None


@pytest.mark.slow
@pytest.mark.parametrize("solver", SOLVERS)
def test_partial_cover_equals_brute_force(solver):
    rng = np.random.default_rng(11)
    config = SetCoverConfig(solver=solver, time_limit=30.0)
    ilp_used = 0
    for trial in range(8):
        a = rng.random((9, 40)) < rng.uniform(0.08, 0.3)
        if trial % 2:
            a[:, 5:10] = a[:, [0]]  # identical columns merge into one weighted class
            a[:, 12] = False  # a voxel no view sees
        executed = sorted(rng.choice(9, size=int(rng.integers(0, 3)), replace=False).tolist())
        coverable = int(a.any(axis=0).sum())
        for fraction in (0.5, 0.8, 0.9, 0.95, 1.0):
            required = int(np.ceil(fraction * coverable))
            result = partial_set_cover(sparse.csr_matrix(a), required, executed=executed, config=config)
            assert isinstance(result, PartialCoverResult)
            assert result.objective == brute_fewest(a, required, executed), (trial, fraction, executed)
            assert result.optimal and result.gap == 0.0 and result.bound == result.objective and result.reachable
            sel = result.selected
            assert np.all(np.diff(sel) > 0) and not set(sel.tolist()) & set(executed)
            union = a[list(executed) + sel.tolist()].any(axis=0) if len(executed) + sel.size else np.zeros(40, bool)
            assert result.covered == int(union.sum()) >= required
            ilp_used += result.solver == solver
            if fraction == 1.0:  # the whole cover is the ordinary set cover
                assert result.objective == solve_set_cover(a, executed=executed, config=config).objective
    assert ilp_used > 0  # the ILP path, not only the bounds, was exercised


@pytest.mark.parametrize("solver", SOLVERS)
def test_partial_cover_weights(solver):
    rng = np.random.default_rng(3)
    a = rng.random((8, 25)) < 0.25
    weights = rng.uniform(0.0, 3.0, 25)
    seen = a.any(axis=0)
    for fraction in (0.6, 0.85, 0.97):
        required = fraction * float(weights[seen].sum())
        result = partial_set_cover(a, required, executed=[2], config=SetCoverConfig(solver=solver), weights=weights)
        assert result.objective == brute_fewest(a, required, [2], weights)
        assert result.covered_weight >= required - 1e-9 and result.optimal


def test_partial_cover_unreachable_and_trivial():
    a = np.array([[1, 1, 0, 0, 0], [0, 1, 1, 0, 0], [0, 0, 0, 1, 0]], dtype=bool)  # voxel 4 unseen
    result = partial_set_cover(a, 5)
    assert not result.reachable and result.achievable_weight == 4.0 and result.required_weight == 4.0
    assert result.objective == 3 and result.covered == 4 and "unreachable" in result.status
    done = partial_set_cover(a, 2, executed=[0])  # the executed view already covers 2 voxels
    assert done.objective == 0 and done.optimal and done.solver == "none"
    assert partial_set_cover(np.zeros((3, 4), bool), 0).objective == 0


def test_partial_cover_time_limit_reports_bound():
    rng = np.random.default_rng(5)
    a = rng.random((60, 2000)) < 0.04
    required = int(0.99 * a.any(axis=0).sum())
    result = partial_set_cover(a, required, config=SetCoverConfig(time_limit=0.2))
    assert result.covered >= required  # a feasible selection always (incumbent or greedy)
    assert result.bound <= result.objective
    assert result.optimal == (result.bound == result.objective)
    assert result.gap == pytest.approx((result.objective - result.bound) / result.objective)


def test_partial_cover_bad_input():
    a = np.eye(3, dtype=bool)
    for bad in (-1, float("nan"), "x", True):
        with pytest.raises(ConfigError, match="required"):
            partial_set_cover(a, bad)
    with pytest.raises(ConfigError, match="weights"):
        partial_set_cover(a, 1, weights=[1, 2])
    with pytest.raises(ConfigError, match="SetCoverConfig"):
        partial_set_cover(a, 1, config={"solver": "cbc"})


def test_one_model_for_many_targets_equals_brute_force():
    """The frontier's shared model (HiGHS, warm starts from the next larger target) finds each
    target's optimum, in the order asked, with the model solving some of them."""
    rng = np.random.default_rng(7)
    solved = 0
    for trial in range(8):
        a = rng.random((10, 50)) < rng.uniform(0.1, 0.3)
        executed = [int(rng.integers(10))]
        weights = rng.uniform(0.5, 2.0, 50) if trial % 3 == 2 else None
        total = float((np.ones(50) if weights is None else weights)[a.any(axis=0)].sum())
        required = [round(f * total, 6) for f in (0.95, 0.6, 1.0, 0.8, 0.9)] + [total + 5]
        results = partial_set_covers(sparse.csr_matrix(a), required, executed=executed, weights=weights)
        for need, result in zip(required, results):
            reachable = need <= total + 1e-9
            assert result.reachable == reachable
            assert result.objective == brute_fewest(a, min(need, total), executed, weights), (trial, need)
            assert result.optimal and result.bound == result.objective
            assert result.covered_weight >= min(need, total) - 1e-6 and not set(result.selected) & set(executed)
            solved += result.solver == "highs"
    assert solved > 0
    assert partial_set_covers(np.eye(3, dtype=bool), []) == []
    with pytest.raises(ConfigError, match="required"):
        partial_set_covers(np.eye(3, dtype=bool), [1, -1])


def test_one_model_for_many_targets_keeps_to_its_time():
    rng = np.random.default_rng(5)
    a = rng.random((60, 2000)) < 0.04
    seen = int(a.any(axis=0).sum())
    results = partial_set_covers(a, [int(f * seen) for f in (0.9, 0.95, 0.99)], time_limit=0.5)
    for f, result in zip((0.9, 0.95, 0.99), results):
        assert result.covered >= int(f * seen) and result.bound <= result.objective
        assert result.optimal == (result.bound == result.objective)
    assert [r.objective for r in results] == sorted(r.objective for r in results)


def brute_fewest_grouped(a, groups, required, executed=()):
    """Fewest non-executed views whose union with the executed ones covers ``required[g]`` voxels of
    every group ``g`` (each clipped to what all views see)."""
    a = np.asarray(a, dtype=bool)
    base = a[list(executed)].any(axis=0) if len(executed) else np.zeros(a.shape[1], bool)
    target = np.minimum(required, np.bincount(groups[a.any(axis=0)], minlength=len(required)))
    views = [v for v in range(a.shape[0]) if v not in set(executed)]
    for size in range(len(views) + 1):
        for combo in itertools.combinations(views, size):
            union = base | (a[list(combo)].any(axis=0) if combo else False)
            if (np.bincount(groups[union], minlength=len(required)) >= target).all():
                return size


@pytest.mark.parametrize("solver", SOLVERS)
def test_grouped_cover_equals_brute_force(solver):
    """A target per group (a plant's organs): the fewest views meeting every group's, as a brute
    force over all view subsets finds them; identical columns of two groups never merge."""
    from tpvp.setcover.grouped import grouped_set_cover

    rng = np.random.default_rng(5)
    config = SetCoverConfig(solver=solver, time_limit=30.0)
    ilp_used = 0
    for trial in range(8):
        a = rng.random((9, 45)) < rng.uniform(0.08, 0.3)
        groups = rng.integers(0, 3, 45)
        if trial % 2:
            a[:, 5:10] = a[:, [0]]  # identical columns in several groups
        executed = sorted(rng.choice(9, size=int(rng.integers(0, 3)), replace=False).tolist())
        sizes = np.bincount(groups[a.any(axis=0)], minlength=3)
        for fractions in ((1.0, 0.5, 0.0), (0.9, 0.95, 0.6), (1.0, 1.0, 1.0), (0.3, 0.0, 1.0)):
            required = np.ceil(np.asarray(fractions) * sizes)
            result = grouped_set_cover(sparse.csr_matrix(a), groups, required, executed=executed, config=config)
            assert result.objective == brute_fewest_grouped(a, groups, required, executed), (trial, fractions)
            assert result.optimal and result.reachable.all()
            union = a[list(executed) + result.selected.tolist()].any(axis=0)
            got = np.bincount(groups[union], minlength=3)
            assert (got >= required).all() and np.array_equal(got, result.covered_weight)
            assert not set(result.selected.tolist()) & set(executed)
            ilp_used += result.solver == solver
    assert ilp_used > 0
    # a group asked for more than its voxels: clipped to the achievable, and said
    result = grouped_set_cover(a, groups, [sizes[0] + 5, 0, 0], config=config)
    assert not result.reachable[0] and result.required_weight[0] == sizes[0] and "clipped" in result.status
