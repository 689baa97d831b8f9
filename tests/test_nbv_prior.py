"""Prior-guided NBV (tpvp.nbv.prior): exact gains, determinism, registry, pipeline, errors."""

import numpy as np
import pytest

from tpvp.config_loading import make_config
from tpvp.nbv.config import NbvConfig
from tpvp.errors import ConfigError, PointCloudError
from tpvp.nbv.occupancy import OCCUPIED
from tpvp.nbv.methods import NBV_METHODS, NbvContext, make_nbv
from tpvp.nbv.prior import PriorNbv, prior_gains, prior_grid
from tpvp.scene import voxels
from tpvp.sensor import bruteforce
from tpvp.sensor.sensor import SensorConfig
from tpvp.viewspace.space import ViewSpace

RES = 0.01


def tiny_prior():
    """Voxel centres (1 cm) of a 'stem' and two 'leaves' that hide each other from some views."""
    stem = np.stack(np.meshgrid([0], [0], np.arange(-4, 5), indexing="ij"), axis=-1).reshape(-1, 3)
    leaf = np.stack(np.meshgrid(np.arange(1, 6), np.arange(-2, 3), [1], indexing="ij"), axis=-1).reshape(-1, 3)
    low = np.stack(np.meshgrid(np.arange(-5, 0), np.arange(-1, 3), [-2], indexing="ij"), axis=-1).reshape(-1, 3)
    keys = np.concatenate([stem, leaf, low, leaf + [0, 0, 3]])
    return (keys + 0.5) * RES


def tiny_space(n=10):
    """``n`` views on a 0.3 m sphere around the origin (Fibonacci), looking at the centre."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = np.pi * (1 + 5 ** 0.5) * i
    r = np.sqrt(1 - z * z)
    positions = 0.3 * np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return ViewSpace("tiny", positions, np.zeros(3))


def context(prior="default", space=None, **nbv):
    prior = tiny_prior() if isinstance(prior, str) else prior
    return NbvContext(space or tiny_space(), np.zeros(3), SensorConfig(), NbvConfig(method="prior", **nbv),
                      prior=prior)


def test_gain_equals_bruteforce_count():
    """Every view's gain is the number of prior voxels it observes (plain-numpy ray marching of
    the reference sensor) that no executed view observes."""
    space = tiny_space()
    points = tiny_prior()
    grid = prior_grid(points, RES)
    assert voxels.encode_keys(grid.keys).tolist() == sorted(voxels.encode_keys(voxels.voxelise(points, RES)).tolist())
    seen = [set(bruteforce.reference_observation(grid, p, t).tolist())
            for p, t in zip(space.positions, space.look_ats)]
    assert len(set(map(frozenset, seen))) > 5 and all(seen)  # the views differ; each sees something
    assert max(map(len, seen)) < len(points)  # the voxels occlude each other
    for executed in ([], [0], [0, 7], [3, 4, 5]):
        nbv = PriorNbv(context(points, space), resolution=RES)
        for view in executed:
            nbv.integrate(view, grid.centres[sorted(seen[view])])
        explained = set().union(*[seen[v] for v in executed])
        expected = [len(s - explained) for s in seen]
        gains = nbv.gains()
        assert gains.dtype == np.int64 and gains.tolist() == expected
        if executed:
            choice = nbv.next_view()
            assert choice.scores.tolist() == expected
            masked = [g if v not in executed else -1 for v, g in enumerate(expected)]
            assert choice.view == masked.index(max(masked))  # largest gain, lowest index on ties
    # The function behind it, on the method's own matrix.
    assert prior_gains(nbv.visibility, [3, 4, 5]).tolist() == expected


def test_deterministic():
    a, b = make_nbv(context()), make_nbv(context())
    for nbv in (a, b):
        nbv.integrate(2, tiny_prior()[:5])
    first, second = a.next_view(), b.next_view()
    assert first.view == second.view and np.array_equal(first.scores, second.scores)
    again = a.next_view()
    assert again.view == first.view and np.array_equal(again.scores, first.scores)


def test_registry_and_config():
    assert "prior" in NBV_METHODS and NBV_METHODS.get("prior") is PriorNbv
    assert NBV_METHODS.help("prior")
    assert isinstance(make_nbv(context()), PriorNbv)
    assert make_config("plant", {"nbv.method": "prior"}).nbv.method == "prior"
    assert make_config("plant").nbv.method == "geometric"  # the default stays


def test_missing_prior_is_one_clear_error():
    with pytest.raises(ConfigError, match=r"'prior' needs the previous session") as info:
        make_nbv(context(prior=None))
    assert "\n" not in str(info.value)
    with pytest.raises(PointCloudError, match="prior"):
        make_nbv(context(prior=np.zeros((0, 3))))
    with pytest.raises(PointCloudError, match="NaN"):
        make_nbv(context(prior=np.full((3, 3), np.nan)))


def test_executed_views_are_never_chosen():
    """Sequentially to the end: every view once, the largest-gain candidate each time (ties to the
    lowest index, also once every prior voxel is explained); then no candidate is left."""
    space = tiny_space(8)
    nbv = make_nbv(context(space=space))
    nbv.integrate(5, np.zeros((0, 3)))
    order = [5]
    for _ in range(len(space) - 1):
        choice = nbv.next_view()
        assert choice.view not in order
        masked = np.where(nbv.view_state, -1, choice.scores)
        assert choice.view == int(np.argmax(masked)) and (choice.scores[order] == 0).all()
        nbv.integrate(choice.view, np.zeros((0, 3)))
        order.append(choice.view)
    assert sorted(order) == list(range(len(space)))
    with pytest.raises(ConfigError, match="no candidate view left"):
        nbv.next_view()
    with pytest.raises(ConfigError, match="out of range"):
        nbv.integrate(len(space), np.zeros((0, 3)))


def test_camera_inside_the_prior_is_left_out():
    """A candidate camera in a prior voxel would make the sensor refuse the view: that voxel is dropped."""
    space = tiny_space(6)
    prior = np.concatenate([tiny_prior(), space.positions[:1]])
    nbv = PriorNbv(context(prior, space), resolution=RES)
    assert len(nbv.grid.keys) == len(tiny_prior())
    nbv.integrate(1, np.zeros((0, 3)))
    assert nbv.next_view().view != 1


def test_run_case_with_prior_nbv():
    """The pipeline with nbv.method=prior: transfer() hands the previous session to the method."""
    from tpvp.simulate.single_plant import build_scene, run_case
    from tpvp.synthetic.plants import generate_session_pair

    pair = generate_session_pair("maize", 2, days=2.0)
    config = make_config("plant", {"nbv.method": "prior", "registration.embedded_deformation.iterations": 30})
    scene = build_scene(pair.previous.points, pair.current.points, config)
    result = run_case(scene, config)
    initial = scene.view_space.view_index(config.initial_view)
    assert result.executed_views[0] == initial and len(result.executed_views) == 2
    nbv = make_nbv(NbvContext(scene.view_space, np.zeros(3), scene.sensor, config.nbv, prior=scene.previous))
    nbv.integrate(initial, scene.grid.centres[scene.truth_visibility[initial].indices])
    assert result.executed_views[1] == nbv.next_view().view
    assert nbv.occupancy.count(OCCUPIED) > 0  # the map of what was observed, for selection methods
    assert set(result.planned_views).isdisjoint(result.executed_views) and result.coverage > 0.9
