"""Block-wise NBV (tpvp.nbv.blockwise): budget, prefixes, block order, frontier and gain against
brute force, monotone coverage. Small generated row (2 cm point spacing, 3 cm truth grid)."""

import numpy as np
import pytest

from tpvp.errors import ConfigError
from tpvp.nbv.blockwise import (
    FREE,
    NOT_SEEN,
    OCCUPIED,
    START,
    UNKNOWN,
    BlockwiseNbvConfig,
    RowOccupancyMap,
    block_cells,
    block_order,
    block_quotas,
    blockwise_nbv,
    farthest_point_sampling,
    look_at_rotations_fast,
    round_robin_pairing,
)
from tpvp.scene.boxes import OrientedBox, room_config
from tpvp.scene.grid import grid_from_points
from tpvp.sensor.camera import D435, look_at_rotation, pixel_ray_directions
from tpvp.sensor.sensor import SensorConfig
from tpvp.synthetic.greenhouse import generate_row

FAST = BlockwiseNbvConfig(map_resolution=0.1, look_ats_per_block=20, plan_views=None)  # quotas from the budget
SENSOR = SensorConfig(max_range=2.0)


@pytest.fixture(scope="module")
def row():
    room = room_config("room1")
    points = generate_row("room1", seed=0, session=1, point_spacing=0.02).points
    return grid_from_points(points, 0.03), room


@pytest.fixture(scope="module")
def run30(row):
    grid, room = row
    return blockwise_nbv(grid, room, 30, BlockwiseNbvConfig(map_resolution=0.1, look_ats_per_block=20,
                                                            plan_views=50), seed=3, progress=False)


# ----------------------------------------------------------------------------- runs
def test_budget_executes_exactly_k_views(row, run30):
    grid, room = row
    for k in (0, 1, 7):
        result = blockwise_nbv(grid, room, k, FAST, progress=False)
        assert len(result) == k
        assert result.positions.shape == result.look_ats.shape == (k, 3)
        for name in ("candidate_index", "block", "gains", "path", "seconds", "plan_seconds", "new_voxels"):
            assert getattr(result, name).shape == (k,)
    r = run30
    assert len(r) == 30 and len(np.unique(r.candidate_index)) == 30  # each position once
    np.testing.assert_array_equal(r.positions, room.candidate_positions[r.candidate_index])
    assert np.all(room.plant_box.contains(r.look_ats, tol=0.05))  # map voxel centres (0.1 m voxels)
    assert np.all(r.seconds >= r.plan_seconds)
    with pytest.raises(ConfigError):
        blockwise_nbv(grid, room, 1001, FAST, progress=False)


def test_prefixes_coincide_with_a_fixed_plan(row, run30):
    """Runs are deterministic given the seed: with plan_views fixed, a shorter budget is a prefix."""
    grid, room = row
    short = blockwise_nbv(grid, room, 12, BlockwiseNbvConfig(map_resolution=0.1, look_ats_per_block=20,
                                                             plan_views=50), seed=3, progress=False)
    np.testing.assert_array_equal(short.candidate_index, run30.candidate_index[:12])
    np.testing.assert_array_equal(short.look_ats, run30.look_ats[:12])
    np.testing.assert_array_equal(short.gains, run30.gains[:12])
    np.testing.assert_array_equal(short.path, run30.path[:12])
    for n in (0, 5, 12):
        np.testing.assert_array_equal(short.covered_after(n), run30.covered_after(n))
    # Another seed gives another run.
    other = blockwise_nbv(grid, room, 12, BlockwiseNbvConfig(map_resolution=0.1, look_ats_per_block=20,
                                                             plan_views=50), seed=4, progress=False)
    assert not np.array_equal(other.look_ats, short.look_ats)


def test_blocks_visited_in_order(row, run30):
    grid, room = row
    # plan 50 -> 5 views per block: 30 views fill the first 6 blocks, 5 each, in order.
    np.testing.assert_array_equal(run30.block, np.repeat(np.arange(6), 5))
    segment, band = block_cells(room.view_box, run30.positions)
    np.testing.assert_array_equal(np.c_[segment, band], run30.block_order[run30.block])
    # Budget-sized plan (plan_views=None): every block gets budget / 10 views.
    r = blockwise_nbv(grid, room, 20, FAST, progress=False)
    np.testing.assert_array_equal(r.block, np.repeat(np.arange(10), 2))
    # Default start (passive view 0, lower left): lower band left to right, then upper band back.
    expected = [(s, 0) for s in range(5)] + [(s, 1) for s in range(4, -1, -1)]
    np.testing.assert_array_equal(r.block_order, expected)


def test_block_order_and_quotas():
    box = room_config("room1").view_box
    up_left = box.to_world([[-1.9, 0.1, 1.0]])[0]
    low_right = box.to_world([[1.9, 0.1, -1.0]])[0]
    assert [tuple(r) for r in block_order(box)] == [(s, 1) for s in range(5)] + [(s, 0) for s in range(4, -1, -1)]
    assert [tuple(r) for r in block_order(box, up_left)][:5] == [(s, 1) for s in range(5)]
    assert [tuple(r) for r in block_order(box, low_right)] == (
        [(s, 0) for s in range(4, -1, -1)] + [(s, 1) for s in range(5)])
    np.testing.assert_array_equal(block_quotas(500, 10), np.full(10, 50))
    q = block_quotas(23, 10)
    assert q.sum() == 23 and set(q) <= {2, 3}


def test_block_out_of_positions_passes_quota_on(row):
    """A block without positions left hands its quota to the next block; k views are still run."""
    grid, room = row
    rc = room_config("room1")
    segment, band = block_cells(rc.view_box, rc.candidate_positions)
    # Views of the first block: passive view 0 is lower-left, so block 0 = (segment 0, band 0).
    n0 = int(((segment == 0) & (band == 0)).sum())
    r = blockwise_nbv(grid, room, n0 + 4, BlockwiseNbvConfig(map_resolution=0.1, look_ats_per_block=10,
                                                             plan_views=10 * (n0 + 10)), progress=False)
    assert len(r) == n0 + 4
    assert np.all(r.block[:n0] == 0) and np.all(r.block[n0:] == 1)


def test_coverage_increases_monotonically(row, run30):
    grid, room = row
    r = run30
    curve = r.coverage_curve()
    assert curve.shape == (31,)
    assert np.all(np.diff(curve) >= 0) and curve[-1] > curve[0] > 0
    np.testing.assert_array_equal(np.diff(np.round(curve * grid.size).astype(int)), r.new_voxels)
    for n in range(30):
        a, b = r.covered_after(n), r.covered_after(n + 1)
        assert np.all(b[a])  # covered stays covered
    assert np.all(np.diff(r.path) >= 0)
    assert r.path[0] == pytest.approx(np.linalg.norm(r.positions[0] - room.initial_positions[0]))
    np.testing.assert_allclose(np.diff(r.path), np.linalg.norm(np.diff(r.positions, axis=0), axis=1))
    assert set(np.unique(r.first_seen)) <= set(range(30)) | {START, NOT_SEEN}
    # Oracle-normalised form: a subset of voxels.
    ids = np.flatnonzero(r.covered_after(30))[:50]
    assert r.coverage_curve(ids)[-1] == 1.0


def test_start_views(row):
    grid, room = row
    passive = blockwise_nbv(grid, room, 2, FAST, start_views="passive", progress=False)
    first = blockwise_nbv(grid, room, 2, FAST, progress=False)
    assert len(passive.start_positions) == 15 and len(first.start_positions) == 1
    assert passive.covered_after(0).sum() > first.covered_after(0).sum()
    none = blockwise_nbv(grid, room, 2, FAST, start_views="none", progress=False)
    assert none.covered_after(0).sum() == 0 and none.path[0] == 0.0
    assert none.frontier_targets[0] == 0  # empty map: no surface frontier yet
    assert tuple(none.block_order[0]) == (0, 1)  # no start: upper band, left end
    with pytest.raises(ConfigError):
        blockwise_nbv(grid, room, 1, FAST, start_views="sideways", progress=False)


# ----------------------------------------------------------------------------- map pieces
def _frontier_brute(state):
    out = np.zeros(state.shape, dtype=np.uint8)
    n = state.shape
    for i in range(n[0]):
        for j in range(n[1]):
            for k in range(n[2]):
                if state[i, j, k] != UNKNOWN:
                    continue
                nb = [state[a, b, c] for a in range(i - 1, i + 2) for b in range(j - 1, j + 2)
                      for c in range(k - 1, k + 2)
                      if (a, b, c) != (i, j, k) and 0 <= a < n[0] and 0 <= b < n[1] and 0 <= c < n[2]]
                free, occ = FREE in nb, OCCUPIED in nb
                out[i, j, k] = 2 if free and occ else (1 if free else 0)
    return out


def test_frontier_against_brute_force():
    box = OrientedBox(np.zeros(3), np.eye(3), [0.7, 0.6, 0.5])
    rng = np.random.default_rng(0)
    for p in ([0.6, 0.3, 0.1], [0.9, 0.05, 0.05], [0.2, 0.6, 0.2]):
        occupancy = RowOccupancyMap(box, 0.1)
        occupancy.state[...] = rng.choice([UNKNOWN, FREE, OCCUPIED], size=occupancy.shape, p=p)
        expected = _frontier_brute(occupancy.state)
        np.testing.assert_array_equal(occupancy.frontier_kinds(), expected)
        np.testing.assert_array_equal(occupancy.surface_frontier(), expected == 2)


def _gain_brute(occupancy, position, look_at, stride, max_range):
    """Unknown voxels visited before the first occupied one, by exact slab intersection of every
    pixel ray with every voxel (no DDA); the rays' map-frame directions from pixel_ray_directions."""
    res = occupancy.resolution
    state = occupancy.state
    idx = np.argwhere(np.ones(state.shape, bool))
    lo, hi = idx * res, (idx + 1) * res
    origin = occupancy.to_map(position)[0]
    rot = occupancy.box.rotation.T @ look_at_rotation(position, look_at)
    seen = set()
    for d in pixel_ray_directions(rot, D435, stride):
        t_stop = max_range / np.linalg.norm(d)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (lo - origin) / d, (hi - origin) / d
        t1 = np.where(d == 0, np.where((origin >= lo) & (origin < hi), -np.inf, np.inf), t1)
        t2 = np.where(d == 0, np.where((origin >= lo) & (origin < hi), np.inf, -np.inf), t2)
        t_in = np.maximum(np.minimum(t1, t2).max(axis=1), 0.0)
        t_out = np.maximum(t1, t2).min(axis=1)
        hit = (t_in < t_out) & (t_in <= t_stop)
        for n in np.flatnonzero(hit)[np.argsort(t_in[hit])]:
            s = state[tuple(idx[n])]
            if s == OCCUPIED:
                break
            if s == UNKNOWN:
                seen.add(n)
    return len(seen)


def test_gain_against_brute_force_ray_count():
    rotation = np.array([[0.6, -0.8, 0.0], [0.8, 0.6, 0.0], [0.0, 0.0, 1.0]])  # a row box turned about z
    box = OrientedBox([0.1, -0.2, 0.3], rotation, [0.5, 0.35, 0.45])
    occupancy = RowOccupancyMap(box, 0.05)
    rng = np.random.default_rng(1)
    occupancy.state[...] = rng.choice([UNKNOWN, FREE, OCCUPIED], size=occupancy.shape, p=[0.6, 0.33, 0.07])
    positions = box.to_world([[0.2, -0.7, 0.1], [-0.4, -0.5, 0.3], [0.0, 0.9, -0.2], [0.05, 0.05, 0.05]])
    look_ats = box.to_world([[0.0, 0.0, 0.0], [0.1, 0.05, -0.1], [-0.1, 0.0, 0.1], [0.2, 0.1, 0.0]])
    for stride, max_range in ((20, 2.0), (37, 0.45)):
        sensor = SensorConfig(max_range=max_range)
        gains = occupancy.gains(positions, look_ats, sensor, stride)
        expected = [_gain_brute(occupancy, p, t, stride, max_range) for p, t in zip(positions, look_ats)]
        np.testing.assert_array_equal(gains, expected)
        assert gains.max() > 0
        # Repeated calls (stamps are tagged, not reset) give the same counts.
        np.testing.assert_array_equal(occupancy.gains(positions, look_ats, sensor, stride), gains)


def test_integrate_marks_returns_and_carves_rays():
    box = OrientedBox(np.zeros(3), np.eye(3), [1.0, 1.0, 1.0])
    occupancy = RowOccupancyMap(box, 0.1)
    camera, target = np.array([0.0, -1.5, 0.0]), np.array([0.0, 0.0, 0.0])
    wall = np.array([[x, 0.25, z] for x in np.arange(-0.45, 0.5, 0.1) for z in np.arange(-0.45, 0.5, 0.1)])
    occupancy.integrate(camera, target, wall, SensorConfig(max_range=2.0), stride=20, carve_pixels=False)
    keys, _ = occupancy.keys_of(wall)
    assert np.all(occupancy.state[tuple(keys.T)] == OCCUPIED)
    assert occupancy.state[5, 0:7, 5].tolist() == [FREE] * 7  # in front of the wall
    assert np.all(occupancy.state[:, 8:, :] == UNKNOWN)  # behind it
    # A second view from the other side carves the back but never frees the wall.
    occupancy.integrate(-camera, target, np.zeros((0, 3)), SensorConfig(max_range=2.0), stride=20)
    assert np.all(occupancy.state[tuple(keys.T)] == OCCUPIED)
    assert occupancy.state[5, 8:, 5].tolist() == [FREE] * 2


def test_sampling_and_pairing_helpers():
    rng = np.random.default_rng(0)
    pts = rng.random((200, 3))
    idx = farthest_point_sampling(pts, 10, np.random.default_rng(5))
    assert len(set(idx.tolist())) == 10
    assert len(farthest_point_sampling(pts[:4], 10, rng)) == 4
    positions, targets = rng.random((23, 3)), rng.random((5, 3))
    pairs = round_robin_pairing(positions, targets, np.random.default_rng(2))
    assert np.all(pairs >= 0)
    assert sorted(np.bincount(pairs, minlength=5).tolist()) == [4, 4, 5, 5, 5]  # balanced
    p = rng.normal(size=(50, 3))
    t = p + rng.normal(size=(50, 3))
    t[0] = p[0] + [0, 0, 1.0]  # straight up: the fallback axis
    np.testing.assert_array_equal(look_at_rotations_fast(p, t),
                                  np.stack([look_at_rotation(a, b) for a, b in zip(p, t)]))


def test_bad_config():
    for kwargs in ({"blocks_along": 0}, {"map_resolution": 0.0}, {"pixel_stride": 2.5}, {"plan_views": 0},
                   {"target_margin": -1.0}, {"plan_views": 2.5}):
        with pytest.raises(ConfigError):
            BlockwiseNbvConfig(**kwargs)
