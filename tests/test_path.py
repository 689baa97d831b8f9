"""Local paths around the obstacle sphere, exact open TSP against brute force, heuristic, bands."""

import itertools

import numpy as np
import pytest

from tpvp.errors import ConfigError
from tpvp.path.config import TspConfig
from tpvp.path.local import local_path_length, local_path_lengths, local_path_points, obstacle_radius, predicted_size
from tpvp.path.tsp import band_path, nearest_neighbour_path, path_length, shortest_open_path

# --- local path ------------------------------------------------------------------------------


def sphere_points(rng, n, radius=0.4, centre=(0.0, 0.0, 0.0)):
    p = rng.normal(size=(n, 3))
    return np.asarray(centre) + radius * p / np.linalg.norm(p, axis=1, keepdims=True)


def polyline_length(points):
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def test_unobstructed_pairs_are_straight():
    centre, r = np.array([0.1, -0.2, 0.3]), 0.2
    m = centre + [0.5, 0.5, 0.0]
    n = centre + [0.5, -0.5, 0.1]
    assert local_path_length(m, n, centre, r) == pytest.approx(np.linalg.norm(n - m))
    # Segment pointing away from the sphere (the line meets it, the segment does not).
    m, n = centre + [0.3, 0, 0], centre + [0.6, 0, 0]
    assert local_path_length(m, n, centre, r) == pytest.approx(0.3)
    # Tangent segment: touches without entering.
    m, n = centre + [-0.5, r, 0], centre + [0.5, r, 0]
    assert local_path_length(m, n, centre, r) == pytest.approx(1.0)
    # Zero radius: everything is straight.
    pts = sphere_points(np.random.default_rng(0), 6)
    d = local_path_lengths(pts, np.zeros(3), 0.0)
    np.testing.assert_allclose(d, np.linalg.norm(pts[:, None] - pts[None], axis=2), atol=1e-15)


def test_opposite_sides_analytic():
    centre, r, big = np.array([0.0, 0.0, 0.1]), 0.15, 0.4
    m, n = centre + [big, 0, 0], centre - [big, 0, 0]
    expected = 2 * (big - r) + np.pi * r
    assert local_path_length(m, n, centre, r) == pytest.approx(expected, rel=1e-12)
    # Offset chord at distance h from the centre: arc angle 2 * arcsin(sqrt(r^2 - h^2) / r).
    h = 0.09
    m, n = centre + [big, h, 0], centre + [-big, h, 0]
    half = np.sqrt(r * r - h * h)
    expected = 2 * (big - half) + r * 2 * np.arcsin(half / r)
    assert local_path_length(m, n, centre, r) == pytest.approx(expected, rel=1e-12)


def test_matrix_is_symmetric_with_zero_diagonal_and_at_least_straight():
    rng = np.random.default_rng(1)
    pts = sphere_points(rng, 40)
    d = local_path_lengths(pts, np.zeros(3), 0.25)
    assert d.shape == (40, 40)
    np.testing.assert_array_equal(d, d.T)
    np.testing.assert_array_equal(np.diag(d), 0)
    straight = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    assert np.all(d >= straight - 1e-12)
    assert np.any(d > straight + 1e-3)  # some pairs do go around
    # Triangle-ish sanity: the detour never exceeds going around the half circumference twice.
    assert np.all(d <= straight + np.pi * 0.25)


def test_dense_polyline_matches_the_length():
    rng = np.random.default_rng(2)
    centre, r = np.array([0.02, -0.01, 0.05]), 0.23
    pts = sphere_points(rng, 12, centre=centre)
    d = local_path_lengths(pts, centre, r)
    for i, j in itertools.combinations(range(12), 2):
        poly = local_path_points(pts[i], pts[j], centre, r, n_points=4000)
        np.testing.assert_allclose(poly[0], pts[i])
        np.testing.assert_allclose(poly[-1], pts[j])
        assert np.linalg.norm(poly - centre, axis=1).min() >= r * (1 - 1e-9)
        assert polyline_length(poly) == pytest.approx(d[i, j], rel=1e-6)


def test_polyline_through_the_centre_goes_over_the_top():
    poly = local_path_points([0.4, 0, 0], [-0.4, 0, 0], np.zeros(3), 0.2, n_points=101)
    assert poly[:, 2].max() == pytest.approx(0.2)
    assert polyline_length(poly) == pytest.approx(2 * 0.2 + np.pi * 0.2, rel=1e-3)


def test_obstacle_radius_and_bad_input():
    pts = np.array([[0.1, 0, 0], [0, -0.2, 0], [0, 0, 0.05]])
    assert predicted_size(pts, np.zeros(3)) == pytest.approx(17 / 16 * 0.2)
    assert obstacle_radius(pts, np.zeros(3)) == pytest.approx(np.sqrt(2) * 17 / 16 * 0.2)
    with pytest.raises(ConfigError, match="observed_points"):
        obstacle_radius(np.zeros((0, 3)), np.zeros(3))
    with pytest.raises(ConfigError, match="inside the obstacle"):
        local_path_lengths([[0.1, 0, 0], [1, 0, 0]], np.zeros(3), 0.2)
    with pytest.raises(ConfigError, match="positions"):
        local_path_lengths(np.zeros((3, 2)), np.zeros(3), 0.2)
    with pytest.raises(ConfigError, match="radius"):
        local_path_lengths(np.ones((3, 3)), np.zeros(3), -1.0)
    with pytest.raises(ConfigError, match="centre"):
        local_path_lengths(np.ones((3, 3)), [0, 0], 0.1)
    with pytest.raises(ConfigError, match="n_points"):
        local_path_points([1, 0, 0], [-1, 0, 0], np.zeros(3), 0.1, n_points=1)


# --- open TSP --------------------------------------------------------------------------------


def brute_force(d, start, end=None):
    n = d.shape[0]
    inner = [v for v in range(n) if v not in (start, end)]
    best = np.inf
    for perm in itertools.permutations(inner):
        order = [start, *perm] + ([end] if end is not None else [])
        best = min(best, path_length(d, order))
    return best


def random_distances(rng, n, kind="sphere"):
    if kind == "sphere":
        return local_path_lengths(sphere_points(rng, n), np.zeros(3), 0.25)
    if kind == "euclid":
        p = rng.uniform(size=(n, 3))
        return np.linalg.norm(p[:, None] - p[None], axis=2)
    d = rng.uniform(0.1, 1.0, size=(n, n))  # asymmetric
    np.fill_diagonal(d, 0)
    return d


def assert_valid(res, n, start, end=None):
    assert sorted(res.order.tolist()) == list(range(n))
    assert res.order[0] == start
    if end is not None:
        assert res.order[-1] == end


@pytest.mark.parametrize("method", ["dp", "ilp"])
def test_exact_methods_equal_brute_force(method):
    rng = np.random.default_rng(3)
    cfg = TspConfig(method=method)
    for k in range(16):
        n = int(rng.integers(3, 9))
        d = random_distances(rng, n, ("sphere", "euclid", "asym")[k % 3])
        start = int(rng.integers(n))
        res = shortest_open_path(d, start, config=cfg)
        assert_valid(res, n, start)
        assert res.optimal and res.length == pytest.approx(brute_force(d, start), rel=1e-9)
        assert res.length == pytest.approx(path_length(d, res.order))
        end = int((start + 1 + rng.integers(n - 1)) % n)
        res = shortest_open_path(d, start, end, config=cfg)
        assert_valid(res, n, start, end)
        assert res.optimal and res.length == pytest.approx(brute_force(d, start, end), rel=1e-9)


def test_highs_ilp_equals_brute_force():
    rng = np.random.default_rng(4)
    for _ in range(4):
        d = random_distances(rng, 7)
        res = shortest_open_path(d, 2, config=TspConfig(method="ilp", solver="highs"))
        assert res.method == "ilp-highs" and res.length == pytest.approx(brute_force(d, 2), rel=1e-9)


def test_dp_and_ilp_agree_on_twelve_views():
    rng = np.random.default_rng(5)
    for end in (None, 7):
        d = random_distances(rng, 12)
        dp = shortest_open_path(d, 0, end, config=TspConfig(method="dp"))
        ilp = shortest_open_path(d, 0, end, config=TspConfig(method="ilp"))
        assert dp.method == "dp" and ilp.method == "ilp-cbc"
        assert dp.length == pytest.approx(ilp.length, rel=1e-9)


def test_heuristic_never_worse_than_nearest_neighbour_and_close_to_exact():
    rng = np.random.default_rng(6)
    gaps = []
    for k in range(8):
        d = random_distances(rng, 12, ("sphere", "euclid", "asym")[k % 3])
        end = None if k % 2 else 11
        nn = path_length(d, nearest_neighbour_path(d, 0, end))
        heur = shortest_open_path(d, 0, end, config=TspConfig(method="heuristic"))
        exact = shortest_open_path(d, 0, end, config=TspConfig(method="dp"))
        assert_valid(heur, 12, 0, end)
        assert not heur.optimal and heur.method == "heuristic"
        assert heur.length <= nn + 1e-12
        assert heur.length >= exact.length - 1e-12
        gaps.append(heur.length / exact.length - 1)
    assert max(gaps) < 0.05 and np.mean(gaps) < 0.02


def test_heuristic_on_a_large_band_is_fast_and_valid():
    rng = np.random.default_rng(7)
    d = random_distances(rng, 150, "euclid")
    res = shortest_open_path(d, 5, 9, config=TspConfig(method="heuristic"))
    assert_valid(res, 150, 5, 9)
    assert res.length < path_length(d, nearest_neighbour_path(d, 5, 9))
    again = shortest_open_path(d, 5, 9, config=TspConfig(method="heuristic"))
    np.testing.assert_array_equal(res.order, again.order)  # deterministic


def test_auto_method_and_time_limit_fallback():
    rng = np.random.default_rng(8)
    assert shortest_open_path(random_distances(rng, 10), 0).method == "dp"
    assert shortest_open_path(random_distances(rng, 18), 0).method == "ilp-cbc"
    big = shortest_open_path(random_distances(rng, 45, "euclid"), 0)
    assert big.method == "heuristic" and not big.optimal
    res = shortest_open_path(random_distances(rng, 20), 0, config=TspConfig(method="ilp", time_limit=1e-9))
    assert res.method == "heuristic (time limit)" and not res.optimal
    assert_valid(res, 20, 0)


def test_degenerate_sizes():
    res = shortest_open_path(np.zeros((1, 1)), 0)
    assert res.order.tolist() == [0] and res.length == 0 and res.optimal
    assert shortest_open_path(np.zeros((1, 1)), 0, 0).order.tolist() == [0]
    d = np.array([[0, 2.0], [3.0, 0]])
    for method in ("auto", "dp", "ilp", "heuristic"):
        res = shortest_open_path(d, 1, config=TspConfig(method=method))
        assert res.order.tolist() == [1, 0] and res.length == 3.0 and res.optimal
    res = shortest_open_path(d, 0, 1)
    assert res.order.tolist() == [0, 1] and res.length == 2.0
    d3 = random_distances(np.random.default_rng(0), 3)
    assert shortest_open_path(d3, 0, 2).order.tolist() == [0, 1, 2]


def test_bad_tsp_input():
    d = np.zeros((3, 3))
    with pytest.raises(ConfigError, match="distance"):
        shortest_open_path(np.zeros((2, 3)), 0)
    with pytest.raises(ConfigError, match="distance"):
        shortest_open_path(np.zeros((0, 0)), 0)
    with pytest.raises(ConfigError, match="distance"):
        shortest_open_path(np.full((2, 2), np.nan), 0)
    with pytest.raises(ConfigError, match="start"):
        shortest_open_path(d, 3)
    with pytest.raises(ConfigError, match="start"):
        shortest_open_path(d, 1.0)
    with pytest.raises(ConfigError, match="end"):
        shortest_open_path(d, 0, 5)
    with pytest.raises(ConfigError, match="end"):
        shortest_open_path(d, 0, 0)
    with pytest.raises(ConfigError, match="method"):
        TspConfig(method="gurobi")
    with pytest.raises(ConfigError, match="solver"):
        TspConfig(solver="gurobi")
    with pytest.raises(ConfigError, match="dp_max_nodes"):
        TspConfig(dp_max_nodes=40)
    with pytest.raises(ConfigError, match="dp"):
        shortest_open_path(np.zeros((25, 25)), 0, config=TspConfig(method="dp"))


# --- greenhouse bands -----------------------------------------------------------------------


def test_band_path_visits_each_band_then_the_other():
    rng = np.random.default_rng(9)
    pos = rng.uniform([0, -1.3, 0.3], [4, -0.8, 2.0], size=(60, 3))
    res = band_path(pos, split_height=1.1)
    assert sorted(res.order.tolist()) == list(range(60))
    upper, lower = res.bands
    assert np.all(pos[upper, 2] >= 1.1) and np.all(pos[lower, 2] < 1.1)
    np.testing.assert_array_equal(res.order, np.r_[upper, lower])
    # Connection view: the lower band's view nearest the end of the upper band's path.
    d = np.linalg.norm(pos[upper[-1]] - pos[lower], axis=1)
    assert res.connection_view == lower[0] == lower[np.argmin(d)]
    eu = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    assert res.length == pytest.approx(path_length(eu, res.order))
    # Each band's path is no longer than its nearest-neighbour ordering.
    sub = eu[np.ix_(lower, lower)]
    assert path_length(sub, np.arange(lower.size)) <= path_length(sub, nearest_neighbour_path(sub, 0, None)) + 1e-12


def test_band_path_with_start_position_and_lower_first():
    rng = np.random.default_rng(10)
    pos = rng.uniform([0, -1.3, 0.3], [3, -0.8, 2.0], size=(14, 3))
    home = np.array([0.0, -1.0, 0.3])
    res = band_path(pos, start_position=home, first="lower")
    assert res.split_height == pytest.approx(np.median(pos[:, 2]))
    lower, _ = res.bands
    assert res.order[0] == lower[np.argmin(np.linalg.norm(pos[lower] - home, axis=1))]
    eu = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    expected = np.linalg.norm(pos[res.order[0]] - home) + path_length(eu, res.order)
    assert res.length == pytest.approx(expected)
    assert res.optimal  # 7 views a band: Held-Karp


def test_band_path_single_band_and_bad_input():
    pos = np.c_[np.arange(5.0), np.zeros(5), np.ones(5)]
    res = band_path(pos, split_height=0.5)
    assert res.order.tolist() in ([0, 1, 2, 3, 4], [4, 3, 2, 1, 0])
    assert res.connection_view == -1 and res.length == pytest.approx(4.0)
    res = band_path(pos, split_height=5.0)  # everything in the lower band
    assert res.length == pytest.approx(4.0)
    with pytest.raises(ConfigError, match="positions"):
        band_path(np.zeros((0, 3)))
    with pytest.raises(ConfigError, match="first"):
        band_path(pos, first="middle")
    with pytest.raises(ConfigError, match="distance"):
        band_path(pos, distance=np.zeros((4, 4)))


def test_band_path_equals_brute_force_on_small_bands():
    from itertools import permutations

    rng = np.random.default_rng(21)
    for _ in range(3):
        pos = rng.uniform([0, -1.3, 0.3], [3, -0.8, 2.0], size=(12, 3))
        home = np.array([0.0, -1.0, 2.2])
        res = band_path(pos, split_height=1.15, start_position=home)
        eu = np.linalg.norm(pos[:, None] - pos[None], axis=2)
        upper, lower = np.flatnonzero(pos[:, 2] >= 1.15), np.flatnonzero(pos[:, 2] < 1.15)

        def best(first, members):
            rest = [m for m in members if m != first]
            return min((path_length(eu, [first, *p]), [first, *p]) for p in permutations(rest))

        first = upper[np.argmin(np.linalg.norm(pos[upper] - home, axis=1))]
        top, top_order = best(first, upper)
        connection = lower[np.argmin(eu[top_order[-1], lower])]
        bottom, _ = best(connection, lower)
        expected = np.linalg.norm(pos[first] - home) + top + eu[top_order[-1], connection] + bottom
        assert res.optimal and res.length == pytest.approx(expected, abs=1e-12)
