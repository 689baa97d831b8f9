"""Geometric NBV: occupancy map (ray carving) and information gain, against plain-numpy marching."""

import dataclasses
import time

import numpy as np
import pytest

from tpvp.errors import ConfigError, PointCloudError, SensorError
from tpvp.nbv.information_gain import information_gain, next_best_view
from tpvp.nbv.occupancy import FREE, OCCUPIED, OccupancyMap, UNKNOWN
from tpvp.nbv.occupancy import MODE_GAIN, MODE_VISIBILITY, walk
from tpvp.scene import voxels
from tpvp.scene.grid import build_grid
from tpvp.sensor import bruteforce
from tpvp.sensor.camera import D435, Intrinsics, look_at_rotation, pixel_ray_directions
from tpvp.sensor.raycast import cast_ray, encode_key_jit


def codes(keys):
    """Distinct int64 codes of voxel keys ``(n, 3)``."""
    k = np.asarray(keys, dtype=np.int64).reshape(-1, 3) + (1 << 20)
    return (k[:, 0] << 42) | (k[:, 1] << 21) | k[:, 2]


def march(occupancy, origin, directions, t_stop, end_keys=None, stop_keys=None):
    """Brute force: walk every ray voxel by voxel from the camera (plain numpy, no skipping).

    Same DDA convention as the kernels: closed-form event times ``((k + 1) res - o) / d`` via the
    reciprocal, ties to the lowest axis, no voxel entered beyond ``t_stop``. Returns the visited
    in-map voxels as ``(ray, flat index)`` pairs, in walking order for each ray. Gain mode (no
    ``end_keys`` / ``stop_keys``): a ray stops at the first occupied voxel (included). Carve mode:
    a ray stops on reaching its end voxel, or any voxel of ``stop_keys`` (in the map or not),
    excluded; occupied voxels are not recorded.
    """
    carve = end_keys is not None or stop_keys is not None
    stop_codes = None if stop_keys is None else codes(stop_keys)
    res = occupancy.resolution
    lo = occupancy.origin_key
    shape = np.array(occupancy.shape)
    state = occupancy.state
    origin = np.asarray(origin, dtype=np.float64).reshape(1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    n = len(d)
    step = np.sign(d).astype(np.int64)
    with np.errstate(divide="ignore"):
        inv = np.where(step != 0, 1.0 / np.where(step != 0, d, 1.0), 0.0)
    k = np.repeat(np.floor(origin / res).astype(np.int64), n, axis=0)

    def event(k, s, o, i):
        return np.where(s > 0, ((k + 1) * res - o) * i, np.where(s < 0, (k * res - o) * i, np.inf))

    t_next = event(k, step, origin, inv)
    t_stop = np.broadcast_to(np.asarray(t_stop, dtype=np.float64), (n,))
    rays, flats = [], []
    active = np.arange(n)
    while active.size:
        ka = k[active]
        keep = np.ones(active.size, dtype=bool)
        if end_keys is not None:
            keep &= ~np.all(ka == end_keys[active], axis=1)
        if stop_codes is not None:
            keep &= ~np.isin(codes(ka), stop_codes)
        local = ka - lo
        inside = np.all((local >= 0) & (local < shape), axis=1) & keep
        flat = np.ravel_multi_index(tuple(np.where(inside[:, None], local, 0).T), tuple(shape))
        s = np.where(inside, state.reshape(-1)[flat], 255)
        record = inside & ((s != OCCUPIED) if carve else True)
        rays.append(active[record])
        flats.append(flat[record])
        if not carve:
            keep &= s != OCCUPIED
        sa = step[active]
        keep &= ~np.any(((local < 0) & (sa <= 0)) | ((local >= shape) & (sa >= 0)), axis=1)
        tn = t_next[active]
        axis = np.argmin(tn, axis=1)  # first minimum: ties go to the lowest axis
        rows = np.arange(active.size)
        keep &= tn[rows, axis] <= t_stop[active]
        active, axis, rows = active[keep], axis[keep], rows[keep]
        k[active, axis] += step[active, axis]
        t_next[active, axis] = event(k[active, axis], step[active, axis], origin[0, axis],
                                     inv[active, axis])
    return np.concatenate(rays), np.concatenate(flats)


def pixel_rays(position, look_at, stride, max_range):
    d = pixel_ray_directions(look_at_rotation(position, look_at), stride=stride)
    norm = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
    return d, max_range / norm


def bruteforce_gain(occupancy, position, look_at, stride, max_range=1.0, visibility=None):
    rays, flats = march(occupancy, position, *pixel_rays(position, look_at, stride, max_range))
    unknown = occupancy.state.reshape(-1)[flats] == UNKNOWN
    rays, flats = rays[unknown], flats[unknown]
    if visibility is None:
        return int(np.unique(flats).size)
    # n-th unknown voxel of each ray (visits are in walking order within a ray).
    order = np.argsort(rays, kind="stable")
    rays, flats = rays[order], flats[order]
    first = np.searchsorted(rays, rays)
    best = np.zeros(occupancy.state.size)
    np.maximum.at(best, flats, visibility ** (np.arange(rays.size) - first).astype(np.float64))
    return best.sum()


def bruteforce_integrate(occupancy, position, points, look_at=None, stride=4, max_range=1.0):
    keys = voxels.voxelise(points, occupancy.resolution) if len(points) else np.zeros((0, 3), int)
    state = np.array(occupancy.state)
    local = keys - occupancy.origin_key
    inside = np.all((local >= 0) & (local < state.shape), axis=1)
    state[tuple(local[inside].T)] = OCCUPIED
    marked = dataclasses.replace(occupancy, state=state.copy())
    ends = voxels.key_centres(keys, occupancy.resolution) - position
    _, flats = march(marked, position, ends, 1.0, end_keys=keys)
    if look_at is not None:  # pixel rays up to the view's own returns
        d, t_stop = pixel_rays(position, look_at, stride, max_range)
        flats = np.concatenate([flats, march(marked, position, d, t_stop, stop_keys=keys)[1]])
    flat_state = state.reshape(-1)
    flats = np.unique(flats)
    flat_state[flats[flat_state[flats] == UNKNOWN]] = FREE
    return state


def wall_scene(res=0.004):
    """Points of a flat wall x = 0.05, |y|, |z| <= 0.1, seen by a camera on the -x side."""
    a = np.arange(-0.1, 0.1 + 1e-9, res / 2)
    yy, zz = np.meshgrid(a, a)
    wall = np.stack([np.full(yy.size, 0.05), yy.ravel(), zz.ravel()], axis=1)
    return wall, np.array([-0.4, 0.0, 0.0])


def random_map(seed, predicted_size=0.06, p_occ=0.04, p_free=0.4):
    rng = np.random.default_rng(seed)
    m = OccupancyMap.empty(rng.normal(scale=0.01, size=3), predicted_size)
    r = rng.random(m.shape)
    state = np.where(r < p_occ, OCCUPIED, np.where(r < p_occ + p_free, FREE, UNKNOWN)).astype(np.uint8)
    return dataclasses.replace(m, state=state)


def sphere_views(seed, count, radius=0.25, spread=0.05):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d * radius, rng.normal(scale=spread, size=(count, 3))


def test_wall_map_states():
    wall, camera = wall_scene()
    m = OccupancyMap.from_observations(np.zeros(3), [camera], [wall])
    radius = np.sqrt((wall**2).sum(axis=1)).max()
    assert m.predicted_size == pytest.approx(17 / 16 * radius)
    assert m.resolution == pytest.approx(2 * m.predicted_size / 32)
    assert np.all(np.array(m.shape) >= 33)
    assert not m.state.flags.writeable
    # Every wall voxel is occupied.
    assert np.all(m.state_at(wall) == OCCUPIED)
    kw = voxels.voxel_keys(wall[:1], m.resolution)[0, 0]
    keys_x = np.argwhere(np.ones(m.shape, bool))[:, 0] + m.origin_key[0]
    flat = m.state.reshape(-1)
    # Behind the wall nothing was seen: all unknown. Only wall voxels are occupied.
    assert np.all(flat[keys_x > kw] == UNKNOWN)
    assert m.count(OCCUPIED) == len(voxels.voxelise(wall, m.resolution))
    # Between the camera and the wall, on the segments camera -> observed voxel centre: free.
    ends = voxels.voxel_centres(wall[::37], m.resolution)
    f = np.linspace(0.0, 1.0, 201)[:, None, None]
    segment = (camera + f * (ends - camera)).reshape(-1, 3)
    segment = segment[(segment[:, 0] < kw * m.resolution) & (segment[:, 0] > -m.predicted_size)]
    assert len(segment) > 1000 and np.all(m.state_at(segment) == FREE)
    # Out of the wall's shadow, near the camera side: never traversed.
    h = m.predicted_size - m.resolution
    assert np.all(m.state_at(np.array([[-h, h, h], [-h, -h, h], [-h, h, -h]])) == UNKNOWN)
    assert m.count(FREE) > 0.25 * flat.size / 2


def test_wall_pixel_carving():
    """Hand case: the camera also reports where it saw nothing (around the wall)."""
    wall, camera = wall_scene()
    points_only = OccupancyMap.from_observations(np.zeros(3), [camera], [wall])
    m = OccupancyMap.from_observations(np.zeros(3), [camera], [wall], look_ats=np.zeros(3))
    assert m.shape == points_only.shape and m.resolution == points_only.resolution
    assert np.all(m.state[points_only.state == FREE] == FREE)
    np.testing.assert_array_equal(m.state == OCCUPIED, points_only.state == OCCUPIED)
    assert np.all(m.state_at(wall) == OCCUPIED)  # returns stay occupied
    h = m.predicted_size - m.resolution
    kw = voxels.voxel_keys(wall[:1], m.resolution)[0, 0]
    x_behind = (kw + 1.5) * m.resolution
    # In the wall's shadow: unknown.
    shadow = np.array([[x_behind, y, z] for y in (-0.08, 0.0, 0.08) for z in (-0.08, 0.0, 0.08)]
                      + [[h, 0.05, -0.05]])
    assert np.all(m.state_at(shadow) == UNKNOWN)
    # Beside the wall, in the field of view: free, up to the map's end (nothing was seen there).
    beside = np.array([[x_behind, 0.14, 0.0], [h, -0.14, 0.0], [h, 0.0, 0.15], [0.0, 0.13, 0.02]])
    assert np.all(points_only.state_at(beside) == UNKNOWN) and np.all(m.state_at(beside) == FREE)
    # Out of the field of view (vertical half-angle ~21 degrees): unknown.
    assert np.all(m.state_at(np.array([[-h, h, h], [-h, -h, -h], [-0.1, 0.0, h]])) == UNKNOWN)
    assert m.count(FREE) > 2 * points_only.count(FREE)
    # Range: from 0.5 m away the map's far half is out of a 0.5 m range.
    near = OccupancyMap.from_observations(np.zeros(3), [camera], [wall], look_ats=np.zeros(3),
                                          max_range=0.5)
    assert near.state_at(beside[:1])[0] == FREE and near.state_at(beside[1:2])[0] == UNKNOWN
    # Own gain 0; from behind, the gain is the wall's shadow only, far less than without carving.
    behind = np.array([0.4, 0.0, 0.0])
    assert information_gain(m, camera, np.zeros(3))[0] == 0
    g, g0 = information_gain(m, behind, np.zeros(3))[0], information_gain(points_only, behind, np.zeros(3))[0]
    assert 0 < g <= m.count(UNKNOWN) and g < 0.5 * g0


@pytest.mark.parametrize("pixels", [False, True])
def test_carving_matches_bruteforce_and_is_order_independent(pixels):
    rng = np.random.default_rng(3)
    m = OccupancyMap.empty(np.zeros(3), 0.08)
    # Points out of the map too: a blob between the third camera and the map.
    clouds = [rng.normal(scale=0.03, size=(400, 3)), rng.uniform(-0.1, 0.1, size=(300, 3)),
              np.r_[rng.normal(scale=0.02, size=(200, 3)),
                    rng.normal([0.0, -0.15, 0.02], 0.01, size=(100, 3))]]
    # The second camera is inside; the third looks at the map past the blob.
    cameras = [np.array([0.3, -0.2, 0.1]), np.array([-0.05, 0.02, 0.03]), np.array([0.0, -0.35, 0.0])]
    targets = [np.zeros(3), np.array([0.1, 0.05, -0.02]), np.zeros(3)] if pixels else [None] * 3
    opts = {"stride": 16, "max_range": 0.3} if pixels else {}  # the range bites inside the map
    maps, current = [], m
    for camera, cloud, target in zip(cameras, clouds, targets):
        nxt = current.integrate(camera, cloud, target, **opts)
        np.testing.assert_array_equal(
            nxt.state, bruteforce_integrate(current, camera, cloud, target, **opts))
        maps.append(nxt)
        current = nxt
    backwards = m
    for camera, cloud, target in reversed(list(zip(cameras, clouds, targets))):
        backwards = backwards.integrate(camera, cloud, target, **opts)
    np.testing.assert_array_equal(current.state, backwards.state)
    together = OccupancyMap.from_observations(
        np.zeros(3), cameras, clouds, look_ats=np.array(targets) if pixels else None, **opts)
    sequential = OccupancyMap.empty(np.zeros(3), together.predicted_size)
    for camera, cloud, target in zip(cameras, clouds, targets):
        sequential = sequential.integrate(camera, cloud, target, **opts)
    np.testing.assert_array_equal(together.state, sequential.state)
    assert m.count(UNKNOWN) == m.state.size  # the input map is untouched
    if pixels:
        point_rays = m.integrate(cameras[0], clouds[0])
        assert np.all(maps[0].state[point_rays.state == FREE] == FREE)
        assert maps[0].count(FREE) > point_rays.count(FREE) + 1000
        # A view's own gain is then exactly 0, unless returns out of the map (which the gain
        # cannot see) stopped its pixel rays before the map; from inside, they lie beyond it.
        inner = clouds[0][np.all(np.abs(clouds[0]) < m.predicted_size, axis=1)]
        assert len(inner) < len(clouds[0])
        own = [information_gain(m.integrate(cameras[0], inner, targets[0], **opts), cameras[0],
                                targets[0], **opts)[0]]
        own += [information_gain(mm, c, t, **opts)[0] for c, t, mm in zip(cameras, targets, maps)]
        assert own[0] == 0 and own[2] == 0 and own[1] > 0 and own[3] > 0
        # The blob (out of the map) shadows the map from the third camera (full range here).
        solo = m.integrate(cameras[2], clouds[2][200:], targets[2], stride=16)
        np.testing.assert_array_equal(
            solo.state, bruteforce_integrate(m, cameras[2], clouds[2][200:], targets[2], stride=16))
        shadow = np.array([[0.0, -0.06, 0.02], [0.0, 0.06, 0.02]])
        assert np.all(solo.state_at(shadow) == UNKNOWN)
        assert solo.count(FREE) > 0.2 * solo.state.size
        # With no return at all, the view's pixel rays carve all they reach.
        blind = m.integrate(cameras[2], np.zeros((0, 3)), targets[2], stride=16)
        assert np.all(blind.state_at(shadow) == FREE) and blind.count(FREE) > solo.count(FREE)
    else:
        assert current.integrate(cameras[1], np.zeros((0, 3))) is current


@pytest.mark.parametrize("seed", range(4))
def test_gain_matches_bruteforce(seed):
    m = random_map(seed)
    positions, look_ats = sphere_views(seed, 5)
    # Edge cases: a camera inside the map, one on voxel faces looking straight down, one looking away.
    positions = np.concatenate([positions, [m.centre + 0.01, [0.0, 0.0, 0.4], [0.3, 0.0, 0.0]]])
    look_ats = np.concatenate([look_ats, [m.centre - 0.05, [0.0, 0.0, 0.0], [1.0, 0.2, 0.0]]])
    gains = {}
    for max_range in (1.0, 0.27):
        gains[max_range] = information_gain(m, positions, look_ats, stride=40, max_range=max_range)
        expected = [bruteforce_gain(m, p, t, 40, max_range) for p, t in zip(positions, look_ats)]
        np.testing.assert_array_equal(gains[max_range], expected)
        # The walk (the reference kernel) agrees too.
        np.testing.assert_array_equal(information_gain(m, positions, look_ats, stride=40, max_range=max_range,
                                                       reference=True), expected)
    assert gains[1.0][-1] == 0 and np.all(gains[1.0][:5] > 0)
    assert np.all(gains[0.27] <= gains[1.0]) and np.any(gains[0.27] < gains[1.0])  # range bites
    # Visibility-weighted expected gain.
    for p_visible in (0.5, 0.9):
        expected = information_gain(m, positions, look_ats, stride=40, unknown_visibility=p_visible)
        assert expected.dtype == np.float64
        np.testing.assert_allclose(
            expected, [bruteforce_gain(m, p, t, 40, visibility=p_visible)
                       for p, t in zip(positions, look_ats)], rtol=1e-12)
        assert np.all(expected <= gains[1.0]) and expected[-1] == 0


def test_gain_prefers_unknown_and_never_grows_with_knowledge():
    # Hand map: known free space x < 0, a wall across the whole map at x = 0, unknown x > 0.
    half = OccupancyMap.empty(np.zeros(3), 0.1)
    kx = np.arange(half.shape[0]) + half.origin_key[0]
    state = np.where(kx < 0, FREE, np.where(kx == 0, OCCUPIED, UNKNOWN)).astype(np.uint8)
    half = dataclasses.replace(half, state=np.broadcast_to(state[:, None, None], half.shape).copy())
    g = information_gain(half, [[-0.4, 0.0, 0.0], [0.4, 0.0, 0.0], [0.0, 0.0, 0.4]], np.zeros(3))
    # Every ray from the free side meets the wall before anything unknown: exactly 0.
    assert g[0] == 0
    assert g[1] > 0.5 * half.count(UNKNOWN)
    assert 0 < g[2] <= half.count(UNKNOWN)  # from above: the unknown half only, at most all of it

    wall, front = wall_scene()
    m = OccupancyMap.from_observations(np.zeros(3), [front], [wall])
    behind = np.array([0.4, 0.0, 0.0])
    assert information_gain(m, front, [-1.0, 0.0, 0.0])[0] == 0  # looking away from the map
    # A fully known map has no gain anywhere.
    known = dataclasses.replace(m, state=np.where(m.state == UNKNOWN, FREE, m.state).astype(np.uint8))
    assert information_gain(known, [front, behind], np.zeros(3)).tolist() == [0, 0]
    # More knowledge never raises a gain: unknown only shrinks, rays only stop earlier.
    positions, look_ats = sphere_views(1, 12, radius=0.4)
    empty = OccupancyMap.empty(np.zeros(3), m.predicted_size)
    g0 = information_gain(empty, positions, look_ats)
    g1 = information_gain(m, positions, look_ats)
    g2 = information_gain(m.integrate(behind, wall + [0.004, 0, 0]), positions, look_ats)
    assert np.all(g1 <= g0) and np.all(g2 <= g1) and g2.sum() < g1.sum() < g0.sum()
    # Executing a view lowers its own gain.
    g_front = information_gain(empty, front, np.zeros(3))[0]
    assert information_gain(m, front, np.zeros(3))[0] < g_front


def test_next_best_view():
    wall, front = wall_scene()
    m = OccupancyMap.from_observations(np.zeros(3), [front], [wall])
    positions = np.array([[0.4, 0.0, 0.0], front, [0.0, -0.4, 0.0], [0.0, 0.0, 0.4]])
    index, gains = next_best_view(m, positions, np.zeros(3), executed={0})
    np.testing.assert_array_equal(gains, information_gain(m, positions, np.zeros(3)))
    assert index == 1 + int(np.argmax(gains[1:])) and index != 0
    best = int(np.argmax(gains))
    assert gains[best] > np.sort(gains)[-2]  # a strict maximum, so excluding it matters
    assert next_best_view(m, positions, np.zeros(3))[0] == best
    index = next_best_view(m, positions, np.zeros(3), executed=np.array([best]))[0]
    assert index != best and gains[index] == np.sort(gains)[-2]
    # Ties go to the lowest non-executed index.
    known = dataclasses.replace(m, state=np.full(m.shape, FREE, np.uint8))
    assert next_best_view(known, positions, np.zeros(3), executed=[0, 1])[0] == 2
    with pytest.raises(ConfigError, match="all 4 views are executed"):
        next_best_view(m, positions, np.zeros(3), executed=range(4))
    with pytest.raises(ConfigError, match="out of range"):
        next_best_view(m, positions, np.zeros(3), executed=[4])


def test_bad_input():
    wall, front = wall_scene()
    with pytest.raises(PointCloudError, match="no observed points"):
        OccupancyMap.from_observations(np.zeros(3), [], [])
    with pytest.raises(PointCloudError, match="no observed points"):
        OccupancyMap.from_observations(np.zeros(3), [front], [np.zeros((0, 3))])
    with pytest.raises(ConfigError, match="2 observed clouds"):
        OccupancyMap.from_observations(np.zeros(3), [front], [wall, wall])
    with pytest.raises(PointCloudError, match="NaN"):
        OccupancyMap.from_observations(np.zeros(3), [front], [np.full((2, 3), np.nan)])
    with pytest.raises(PointCloudError, match="coincide"):
        OccupancyMap.from_observations(np.zeros(3), [front], [np.zeros((1, 3))])
    with pytest.raises(ConfigError):
        OccupancyMap.empty(np.zeros(3), 0.0)
    m = OccupancyMap.from_observations(np.zeros(3), [front], [wall])
    for stride in (0, -4, 2.5):
        with pytest.raises(ConfigError, match="stride"):
            information_gain(m, front, np.zeros(3), stride=stride)
    with pytest.raises(ConfigError, match="max_range"):
        information_gain(m, front, np.zeros(3), max_range=0)
    with pytest.raises(ConfigError, match="look-ats"):
        information_gain(m, np.zeros((3, 3)) + front, np.zeros((2, 3)))
    with pytest.raises(SensorError, match="zero-length"):
        information_gain(m, front, front)
    assert information_gain(m, np.zeros((0, 3)), np.zeros(3)).shape == (0,)
    for p_visible in (0.0, 1.0, -0.5, np.nan):
        with pytest.raises(ConfigError, match="unknown_visibility"):
            information_gain(m, front, np.zeros(3), unknown_visibility=p_visible)
    # Pixel carving options.
    with pytest.raises(ConfigError, match="look-ats"):
        OccupancyMap.from_observations(np.zeros(3), [front, front], [wall, wall], look_ats=np.zeros((3, 3)))
    with pytest.raises(ConfigError, match="look-at 1"):
        OccupancyMap.from_observations(np.zeros(3), [front, front], [wall, wall],
                                       look_ats=[[0.0, 0.0, 0.0], [np.inf, 0.0, 0.0]])
    for stride in (0, 2.5):
        with pytest.raises(ConfigError, match="stride"):
            m.integrate(front, wall, np.zeros(3), stride=stride)
    with pytest.raises(ConfigError, match="max_range"):
        m.integrate(front, wall, np.zeros(3), max_range=-1.0)
    with pytest.raises(SensorError, match="zero-length"):
        m.integrate(front, wall, front)


def test_tomato_warm_up_nbv(tomato_scene, capsys):
    """Realistic check: initial view 17 of the hemisphere, then the geometric NBV."""
    from tpvp.sensor.sensor import observe

    grid, views = tomato_scene
    centre = np.zeros(3)
    first = observe(grid, views[17], centre)
    m = OccupancyMap.from_observations(centre, [views[17]], [grid.centres[first]], look_ats=centre)
    points_only = OccupancyMap.from_observations(centre, [views[17]], [grid.centres[first]])
    information_gain(m, views, centre)  # compile
    start = time.perf_counter()
    index, gains = next_best_view(m, views, centre, executed={17})
    elapsed = time.perf_counter() - start
    second = observe(grid, views[index], centre)
    both = np.union1d(first, second)
    spread = (np.sort(gains)[-1] - np.sort(gains)[1]) / np.sort(gains)[-1]  # gains[17] is ~0
    with capsys.disabled():
        print(f"\nNBV gains (32 views, {elapsed * 1e3:.0f} ms): {gains.tolist()}; NBV {index}; "
              f"observed voxels {first.size} -> {both.size}; map {m.shape}, res {m.resolution:.4f} m, "
              f"unknown {points_only.count(UNKNOWN)} -> {m.count(UNKNOWN)} with pixel carving")
    assert index != 17 and np.delete(gains, 17).min() > 0
    assert both.size > first.size * 1.2
    # Pixel carving removes the unseen background, which made every view's gain alike (~8%).
    assert m.count(UNKNOWN) < 0.2 * points_only.count(UNKNOWN) and spread > 0.3
    assert elapsed < 5.0  # ~0.25 s on 2 cores; loose because the machine is shared


def test_map_walk_and_sensor_share_the_dda():
    """One DDA for both: on a map whose occupied voxels are a sensor scene (the rest unknown), the
    map's walk visits exactly the brute-force march's voxels and stops on the voxel that the
    sensor's kernel and its brute-force reference report as the first hit, ray by ray."""
    rng = np.random.default_rng(11)
    m = OccupancyMap.empty(np.zeros(3), 0.16)  # 1 cm voxels, keys -17 .. 16 (padding included)
    res = m.resolution
    keys = voxels.unique_keys(np.concatenate([
        rng.integers(-6, 6, size=(150, 3)),
        np.stack(np.meshgrid([3], np.arange(-5, 5), np.arange(-5, 5), indexing="ij"), -1).reshape(-1, 3)]))
    grid = build_grid(keys, res)
    state = np.zeros(m.shape, dtype=np.uint8)
    state[tuple((keys - m.origin_key).T)] = OCCUPIED
    m = dataclasses.replace(m, state=state)
    flat_of_id = np.ravel_multi_index(tuple((grid.keys - m.origin_key).T), m.shape)
    # Outside the map (entry jump of both), inside the map but outside the sensor's grid box
    # (the map walks from the camera, the sensor jumps), and inside the grid box between voxels.
    positions = np.array([[0.3, -0.1, 0.12], [-0.05, 0.31, -0.2], [0.0, 0.0, 0.4],
                          [0.12, 0.03, 0.02], [-0.1, -0.11, 0.09], [0.065, 0.0, 0.0]])
    assert not grid.is_occupied(positions).any()
    empty = np.zeros(0, dtype=np.int64)
    lo = m.origin_key
    checked_hits = 0
    for position in positions:
        d = pixel_ray_directions(look_at_rotation(position, [0.01, -0.02, 0.0]), stride=40)
        sensor_slow = bruteforce.march_rays(grid, position, d, max_range=10.0)
        rays, flats = march(m, position, d, np.inf)  # in walking order, first occupied included
        for r, (dx, dy, dz) in enumerate(d):
            sensor = cast_ray(*position, dx, dy, dz, grid.index, grid.clearance, *grid.origin_key,
                              res, 100.0, np.inf)
            assert sensor == sensor_slow[r]
            visited = flats[rays == r]
            stamp = np.zeros(m.state.size)
            walk(*position, dx, dy, dz, np.inf, state, lo[0], lo[1], lo[2], res, MODE_VISIBILITY,
                 True, 0, 0, 0, stamp, 0.5, empty)
            seen = np.flatnonzero(stamp)
            order = seen[np.argsort(-stamp[seen], kind="stable")]  # n-th visited: 0.5 ** n
            np.testing.assert_array_equal(stamp[order], 0.5 ** np.arange(order.size))
            count = walk(*position, dx, dy, dz, np.inf, state, lo[0], lo[1], lo[2], res, MODE_GAIN,
                         True, 0, 0, 0, np.zeros(m.state.size), 1.0, empty)
            assert count == order.size
            if sensor >= 0:  # the walk stopped on the sensor's first hit
                checked_hits += 1
                np.testing.assert_array_equal(visited, np.r_[order, flat_of_id[sensor]])
            else:
                np.testing.assert_array_equal(visited, order)
    assert checked_hits > 100


def test_voxel_codes_round_trip_and_range():
    rng = np.random.default_rng(2)
    lim = voxels.KEY_OFFSET
    keys = np.concatenate([rng.integers(-lim, lim, size=(500, 3)),
                           [[-lim, -lim, -lim], [lim - 1, lim - 1, lim - 1], [-1, 0, 1], [0, 0, 0]]])
    encoded = voxels.encode_keys(keys)
    np.testing.assert_array_equal(encoded, codes(keys))  # 21 bits per axis, offset 2^20
    np.testing.assert_array_equal(voxels.decode_keys(encoded), keys)
    # Codes sort like the keys (x, then y, then z).
    np.testing.assert_array_equal(np.argsort(encoded, kind="stable"),
                                  np.lexsort((keys[:, 2], keys[:, 1], keys[:, 0])))
    assert [encode_key_jit(*k) for k in keys[-4:]] == encoded[-4:].tolist()  # the kernels' form
    assert [voxels.encode_key(*map(int, k)) for k in keys[-4:]] == encoded[-4:].tolist()
    assert voxels.encode_keys(np.zeros((0, 3), np.int64)).shape == (0,)
    for bad in ([lim, 0, 0], [0, -lim - 1, 0], [0, 0, 2**40]):
        with pytest.raises(PointCloudError, match="encodable range"):
            voxels.encode_keys(np.array([[1, 2, 3], bad]))


def test_gain_by_voxel_equals_walk_on_ties():
    """The default (by-voxel) gain equals the walk exactly where the DDA's tie rules decide:
    power-of-two voxels, camera positions and intrinsics make rays cross voxel edges and corners
    exactly (changing any tie rule of the by-voxel test, its candidate-ray margin or its handling
    of voxels at the camera plane makes this fail). Cameras inside the map too."""
    rng = np.random.default_rng(5)
    res = 2.0 ** -7
    dyadic = Intrinsics(fx=64.0, fy=64.0, cx=32.0, cy=32.0, width=65, height=65)
    compared = 0
    for trial in range(12):
        centre = rng.integers(-3, 3, 3) * res if trial % 2 else rng.normal(scale=0.01, size=3)
        m = OccupancyMap.empty(centre, 16 * res)
        p_occ, p_free = (0.0, 0.005, 0.03, 0.1)[trial % 4], (0.2, 0.6, 0.9)[trial % 3]
        r = rng.random(m.shape)
        m = dataclasses.replace(m, state=np.where(
            r < p_occ, OCCUPIED, np.where(r < p_occ + p_free, FREE, UNKNOWN)).astype(np.uint8))
        positions, look_ats = [], []
        for axis, sign in [(a, s) for a in range(3) for s in (-1, 1)]:  # along the axes
            p = np.zeros(3)
            p[axis] = sign * rng.integers(30, 80) * res
            p[(axis + 1) % 3] = rng.integers(-5, 5) * res
            positions.append(p)
            look_ats.append(p - sign * 0.3 * np.eye(3)[axis])
        for _ in range(3):  # along the diagonals
            positions.append(rng.choice([-1, 1], 3) * rng.integers(20, 60) * res)
            look_ats.append(np.zeros(3))
        for _ in range(3):  # inside the map, looking anywhere
            positions.append(m.centre + rng.normal(scale=0.05, size=3))
            look_ats.append(rng.normal(size=3))
        for intrinsics, stride in ((dyadic, int(rng.choice([1, 3, 4]))), (D435, 16)):
            max_range = (1.0, 0.3, 0.17)[trial % 3]
            fast = information_gain(m, positions, look_ats, stride=stride, max_range=max_range,
                                    intrinsics=intrinsics)
            walked = information_gain(m, positions, look_ats, stride=stride, max_range=max_range,
                                      intrinsics=intrinsics, reference=True)
            np.testing.assert_array_equal(fast, walked)
            assert fast.dtype == walked.dtype == np.int64
            compared += int((walked > 0).sum())
    assert compared > 100


def test_incremental_map_equals_rebuild(tomato_scene, monkeypatch):
    """GeometricNbv integrates new views into its map while the map's geometry (sized on all
    observed points) stays; it equals the map rebuilt from every view, and the choices and gains
    equal those of rebuilding after every view with the walk's gains (the previous path)."""
    from tpvp.nbv.config import NbvConfig
    from tpvp.nbv.methods import GeometricNbv, NbvContext
    from tpvp.sensor.sensor import SensorConfig, observe
    from tpvp.viewspace.space import get_view_space

    grid, _ = tomato_scene
    space = get_view_space("hemisphere")
    centre = np.zeros(3)
    context = NbvContext(space, centre, SensorConfig(), NbvConfig(pixel_stride=8))

    def observation(view, step):
        points = grid.centres[observe(grid, space.positions[view], space.look_ats[view])]
        if step == 3:  # a return farther out than any before: the map's geometry changes
            points = np.concatenate([points, [[0.0, 0.0, 1.2 * np.sqrt((points ** 2).sum(axis=1)).max()]]])
        return points

    def run(nbv, reference):
        maps, choices, view = [], [], 17
        for step in range(7):
            nbv.integrate(view, observation(view, step))
            if step == 4:  # two views before the next map: both integrated
                nbv.integrate(view + 1, observation(view + 1, step))
            maps.append(nbv.occupancy)
            if reference:
                gains = information_gain(nbv.occupancy, space.positions, space.look_ats, stride=8,
                                         reference=True)
                view = int(np.argmax(np.where(nbv.view_state, -1, gains)))
            else:
                choice = nbv.next_view()
                view, gains = choice.view, choice.scores
            choices.append((view, gains))
        return maps, choices

    rebuilds = []
    original = OccupancyMap.from_observations.__func__
    monkeypatch.setattr(OccupancyMap, "from_observations", classmethod(
        lambda cls, *args, **kwargs: rebuilds.append(1) or original(cls, *args, **kwargs)))
    fast_maps, fast_choices = run(GeometricNbv(context), reference=False)
    assert len(rebuilds) == 2  # the first map and the geometry change; 5 maps were incremental
    slow_maps, slow_choices = run(GeometricNbv(context, incremental=False), reference=True)
    assert len(rebuilds) == 2 + 7
    geometries = set()
    for fast, slow in zip(fast_maps, slow_maps):
        np.testing.assert_array_equal(fast.state, slow.state)
        assert fast.predicted_size == slow.predicted_size and fast.resolution == slow.resolution
        np.testing.assert_array_equal(fast.origin_key, slow.origin_key)
        geometries.add((fast.resolution, tuple(fast.origin_key), fast.shape))
    assert len(geometries) == 2
    for (view, gains), (view_slow, gains_slow) in zip(fast_choices, slow_choices):
        assert view == view_slow
        np.testing.assert_array_equal(gains, gains_slow)
    assert fast_choices[0][1].max() > 1000 and len({v for v, _ in fast_choices}) == 7
