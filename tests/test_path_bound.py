"""Held-Karp lower bound on the open path from a fixed start (tpvp.path.bound) and band_path gaps."""

import itertools

import numpy as np
import pytest

from tpvp.errors import ConfigError
from tpvp.path.bound import open_path_lower_bound
from tpvp.path.config import TspConfig
from tpvp.path.tsp import band_path, shortest_open_path


def _brute_force(d, start):
    others = [v for v in range(d.shape[0]) if v != start]
    best = np.inf
    for perm in itertools.permutations(others):
        order = (start,) + perm
        best = min(best, float(d[order[:-1], order[1:]].sum()))
    return best


def _euclidean(p):
    return np.linalg.norm(p[:, None] - p[None], axis=-1)


@pytest.mark.parametrize("kind", ["euclidean", "random-metric", "asymmetric"])
def test_bound_is_below_brute_force_optimum(kind):
    rng = np.random.default_rng({"euclidean": 1, "random-metric": 2, "asymmetric": 3}[kind])
    for n in range(5, 10):
        for _ in range(3):
            if kind == "euclidean":
                d = _euclidean(rng.uniform(0, 1, size=(n, 2)))
            else:
                d = rng.uniform(1, 2, size=(n, n))  # every entry in [1, 2]: triangle inequality holds
                if kind == "random-metric":
                    d = (d + d.T) / 2
                np.fill_diagonal(d, 0.0)
            start = int(rng.integers(n))
            opt = _brute_force(d, start)
            res = open_path_lower_bound(d, start)
            assert 0 < res.bound <= opt + 1e-9
            assert res.iterations >= 1 and res.seconds >= 0
            if kind == "euclidean":
                assert res.bound >= 0.9 * opt


def test_bound_is_tight_on_a_line():
    x = np.sort(np.random.default_rng(4).uniform(0, 10, size=30))
    d = np.abs(x[:, None] - x[None, :])
    res = open_path_lower_bound(d, 0)
    assert res.bound == pytest.approx(x[-1] - x[0], rel=1e-9)
    assert open_path_lower_bound(d, 0, upper=x[-1] - x[0]).bound == pytest.approx(x[-1] - x[0], rel=1e-9)


def test_trivial_sizes():
    assert open_path_lower_bound(np.zeros((1, 1)), 0).bound == 0.0
    assert open_path_lower_bound(np.array([[0.0, 3.0], [3.0, 0.0]]), 1).bound == pytest.approx(3.0)


@pytest.mark.parametrize("n", [60, 150, 250])
def test_heuristic_gap_on_row_like_bands(n):
    rng = np.random.default_rng(100 + n)
    pos = rng.uniform([0, -1.3, 0.3], [10, -0.8, 2.0], size=(n, 3))
    d = _euclidean(pos)
    path = shortest_open_path(d, 0, config=TspConfig(method="heuristic", kicks=20))
    res = open_path_lower_bound(d, 0, iterations=2000, upper=path.length)
    gap = (path.length - res.bound) / path.length
    print(f"n={n}: heuristic {path.length:.4f}, bound {res.bound:.4f}, gap {gap:.3%}, bound {res.seconds:.3f} s")
    assert 0 < res.bound <= path.length
    assert gap < 0.05


def test_bad_input():
    d = np.ones((4, 4))
    for kwargs in (dict(distance=np.ones((3, 4)), start=0), dict(distance=np.zeros((0, 0)), start=0),
                   dict(distance=np.full((3, 3), np.nan), start=0), dict(distance=-d, start=0),
                   dict(distance=d, start=4), dict(distance=d, start=1.0), dict(distance=d, start=True),
                   dict(distance=d, start=0, iterations=0), dict(distance=d, start=0, upper=np.inf)):
        with pytest.raises(ConfigError):
            open_path_lower_bound(**kwargs)
    with pytest.raises(ConfigError, match="bound_iterations"):
        TspConfig(bound_iterations=-1)


def test_band_path_reports_bounds_and_gaps():
    rng = np.random.default_rng(11)
    pos = rng.uniform([0, -1.3, 0.3], [10, -0.8, 2.0], size=(200, 3))
    cfg = TspConfig(kicks=10)
    for home in (None, np.array([0.0, -1.0, 0.3])):
        res = band_path(pos, start_position=home, config=cfg)
        assert not res.optimal
        assert len(res.band_bounds) == len(res.band_gaps) == len(res.band_lengths) == 2
        for length, lower, gap in zip(res.band_lengths, res.band_bounds, res.band_gaps):
            assert 0 < lower <= length and 0 <= gap < 0.05
            assert gap == pytest.approx((length - lower) / length)
        legs = res.length - sum(res.band_lengths)
        assert res.bound == pytest.approx(legs + sum(res.band_bounds))
        assert 0 <= res.gap < 0.05 and res.bound <= res.length
        print(f"band_path start={home is not None}: gap {res.gap:.3%}, band gaps {res.band_gaps}")
    # Bands small enough for the exact methods: bound = length, gap 0.
    small = band_path(pos[:20], config=cfg)
    assert small.optimal and small.gap == 0.0 and small.band_gaps == (0.0, 0.0)
    assert small.bound == pytest.approx(small.length)
    # No bound requested: heuristic bands report NaN.
    nob = band_path(pos, config=TspConfig(kicks=5, bound_iterations=0))
    assert np.isnan(nob.gap) and all(np.isnan(g) for g in nob.band_gaps)


def test_band_path_improves_a_weak_path_to_the_gap_target():
    """A deliberately weak first heuristic (no perturbations) is improved until every band's gap to
    its bound is below band_gap; the reported lengths are those of the returned order."""
    rng = np.random.default_rng(3)
    pos = rng.uniform([0, -1.3, 0.3], [10, -0.8, 2.0], size=(240, 3))
    weak = band_path(pos, split_height=1.15, config=TspConfig(kicks=0, band_gap=1.0))
    better = band_path(pos, split_height=1.15, config=TspConfig(kicks=10, band_gap=0.008, band_seconds=30.0))
    assert max(better.band_gaps) <= 0.008 < max(weak.band_gaps)
    assert better.length < weak.length
    assert sorted(better.order) == list(range(len(pos)))
    d = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    assert better.length == pytest.approx(float(d[better.order[:-1], better.order[1:]].sum()))
