"""End-to-end single-plant pipeline on a small generated plant pair."""

import pytest

from tpvp.config_loading import make_config
from tpvp.simulate.single_plant import build_scene, run_case
from tpvp.synthetic.plants import generate_session_pair


@pytest.fixture(scope="module")
def maize_scene():
    pair = generate_session_pair("maize", 2, days=2.0)
    config = make_config("plant", {"registration.embedded_deformation.iterations": 120})
    return build_scene(pair.previous.points, pair.current.points, config), config


def test_generated_pair_end_to_end(maize_scene):
    scene, config = maize_scene
    result = run_case(scene, config)
    assert result.executed_views[0] == config.initial_view and len(result.executed_views) == 2
    assert set(result.planned_views).isdisjoint(result.executed_views)
    assert result.n_views == len(result.executed_views) + len(result.planned_views)
    assert result.coverage > result.coverage_captured and result.coverage > 0.9
    assert result.chamfer_after < result.chamfer_before
    assert result.selection.optimal and result.set_cover.optimal and result.path.optimal
    # The path starts at the initial view, visits the NBV, then the planned views in TSP order.
    assert result.path_length > 0
    assert result.timings["planning"] < 30  # generous: the speed target lives in the benchmark


def test_without_inflation_plans_on_the_transferred_model_only(maize_scene):
    scene, config = maize_scene
    plain = run_case(scene, make_config("plant", {"registration.embedded_deformation.iterations": 120,
                                                   "inflation.enabled": False}))
    assert len(plain.clouds["inflation"]) == 0
    assert len(plain.clouds["planning"]) == len(scene.previous)


def test_bad_initial_view(maize_scene):
    from tpvp.errors import ConfigError

    scene, config = maize_scene
    with pytest.raises(ConfigError, match="initial_view"):
        run_case(scene, make_config("plant", initial_view=99))
