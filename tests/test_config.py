"""The configuration: defaults = the paper, derived parameters, YAML round trip, one-line errors."""

import dataclasses

import pytest

from tpvp.config import PlantConfig, RowConfig
from tpvp.config_loading import DERIVED, config_yaml, flatten_keys, load_config, make_config, parse_overrides, to_dict
from tpvp.errors import ConfigError, InputFileError


def test_paper_configuration_holds_the_papers_values():
    config = load_config("paper")
    assert config == PlantConfig() and config.name == "paper"
    assert config.gt_resolution == 0.002 and config.view_space == "hemisphere" and config.initial_view == 17
    assert config.registration.method == "embedded-deformation" and config.nbv.method == "geometric"
    ed = config.registration.embedded_deformation
    assert (ed.node_coverage, ed.iterations, ed.lr, ed.w_arap, ed.w_chamfer, ed.w_laplacian) == \
        (0.004, 300, 1e-3, 1.0, 0.1, 0.01)
    assert (config.inflation.step, config.inflation.gamma_near, config.inflation.gamma_far) == (0.004, 0.003, 0.005)
    assert config.selection.cover_resolution == 0.004 and config.selection.coverage_target == 1.0
    assert config.sensor.max_range == 1.0 and config.nbv.pixel_stride == 4
    assert config.scene.largest_side == 0.24 and config.scene.scale == "normalised"
    row = load_config("paper-row")
    assert isinstance(row, RowConfig) and row.gt_resolution == 0.01 and row.sensor.max_range == 2.0
    assert row.oracle_grid == pytest.approx(0.1) and row.selection.cover_resolution == pytest.approx(0.04)
    assert row.registration.embedded_deformation.node_coverage == 0.15  # not derived
    assert row.targets.count == 100 and row.targets.rounds == 8 and row.nbv.pixel_stride == 20
    assert row.protocol.cover_resolutions == (0.10, 0.05, 0.04, 0.03) and row.protocol.budgets == (100, 300, 500)
    assert row.pose_noise.cover_resolution == 0.04 and row.pose_noise.draws == 5 and row.blockwise.pixel_stride == 20


@pytest.mark.parametrize("setting", ["plant", "row"])
def test_changing_gt_resolution_changes_every_derived_parameter_by_its_rule_and_nothing_else(setting):
    base = flatten_keys(to_dict(make_config(setting)))
    factor = 0.5
    changed = flatten_keys(to_dict(make_config(setting, gt_resolution=base["gt_resolution"] * factor)))
    differing = {k for k in base if base[k] != changed[k]}
    follows_gt = {k for k, (rule, _) in DERIVED[setting].items() if "gt_resolution" in rule}
    assert differing == follows_gt | {"gt_resolution"}
    for key in follows_gt:
        assert changed[key] == pytest.approx(base[key] * factor), key


def test_an_explicit_derived_key_wins_over_its_rule():
    config = make_config("plant", {"inflation.step": 0.01}, gt_resolution=0.001)
    assert config.inflation.step == 0.01 and config.inflation.gamma_near == pytest.approx(0.0015)
    assert make_config("plant", seed=7).registration.embedded_deformation.seed == 7


def test_yaml_round_trip(tmp_path):
    config = make_config("plant", {"registration.embedded_deformation.iterations": 50, "view_space": "sphere",
                                   "initial_view": "near_top", "scene.radius": 0.5}, gt_resolution=0.003)
    path = tmp_path / "config.yaml"
    path.write_text(config_yaml(config, "a header"))
    assert load_config(path) == config
    # a partial file with a base and dotted keys
    partial = tmp_path / "partial.yaml"
    partial.write_text("base: paper\nselection:\n  set_cover:\n    solver: highs\nnbv.warm_up_views: 2\n")
    loaded = load_config(partial)
    assert loaded.selection.set_cover.solver == "highs" and loaded.nbv.warm_up_views == 2
    assert loaded.registration == PlantConfig().registration


def test_every_row_setting_is_in_the_row_configuration(tmp_path):
    """What the row experiments sweep and the pose-noise study are sections of RowConfig: lists in
    YAML, tuples in the frozen configuration, checked like every other key."""
    config = make_config("row", {"protocol.cover_resolutions": [0.1, 0.05], "pose_noise.levels": [[0, 0], [0.01, 2]]},
                         seed=3)
    assert config.protocol.cover_resolutions == (0.1, 0.05) and config.pose_noise.levels == ((0.0, 0.0), (0.01, 2.0))
    assert config.pose_noise.seed == 3  # derived from the run's seed
    path = tmp_path / "row.yaml"
    path.write_text(config_yaml(config))
    assert load_config(path) == config
    with pytest.raises(ConfigError, match="protocol: budgets must be one or more positive integers"):
        make_config("row", {"protocol.budgets": [100.5]})
    with pytest.raises(ConfigError, match="'protocol.nbv_budgets': expected a list"):
        make_config("row", {"protocol.nbv_budgets": 100})


@pytest.mark.parametrize("overrides, words", [
    ({"registration.embedded_deformation.iteratons": 5}, "unknown configuration key 'registration.embedded_deformation.iteratons'"),
    ({"iterations": 5}, "did you mean registration.embedded_deformation.iterations"),
    ({"inflation.step": "big"}, "'inflation.step': expected a number"),
    ({"inflation.step": -1.0}, "inflation"),
    ({"nbv.method": "magic"}, "unknown NBV method 'magic'"),
    ({"registration.method": "icp"}, "unknown registration method 'icp'"),
    ({"selection.method": "greedy"}, "unknown view-selection method 'greedy'"),
    ({"view_space": "cube"}, "view_space"),
    ({"inflation.enabled": "yes"}, "true or false"),
])
def test_bad_keys_and_values_are_one_line_naming_them(overrides, words):
    with pytest.raises(ConfigError) as info:
        make_config("plant", overrides)
    message = str(info.value)
    assert words in message and len(message.splitlines()) == 1


def test_bad_files_and_overrides(tmp_path):
    with pytest.raises(InputFileError, match="nothere.yaml"):
        load_config(tmp_path / "nothere.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("scene: [1, 2\n")
    with pytest.raises(InputFileError, match="bad.yaml"):
        load_config(bad)
    assert parse_overrides(["a.b=1", "c=true", "d=hemisphere", "e=0.5"]) == {"a.b": 1, "c": True, "d": "hemisphere", "e": 0.5}
    with pytest.raises(ConfigError, match="key=value"):
        parse_overrides(["novalue"])


def test_configs_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        PlantConfig().gt_resolution = 0.1


def test_planning_target_from_the_asked_coverage():
    """The asked true coverage maps to the planning surface through the calibrated miss ratio of the
    view space (the smallest for other view spaces); 1.0 stays the full set cover."""
    from tpvp.setcover.config import CALIBRATED_MISS_RATIO, SelectionConfig

    asked = SelectionConfig(coverage_target=0.98)
    for space, ratio in CALIBRATED_MISS_RATIO.items():
        assert asked.planning_target(space) == pytest.approx(1 - ratio * 0.02)
    assert asked.planning_target("tammes:40") == pytest.approx(1 - min(CALIBRATED_MISS_RATIO.values()) * 0.02)
    assert SelectionConfig(coverage_target=0.98, planning_miss_ratio=1.0).planning_target("sphere") == pytest.approx(0.98)
    assert SelectionConfig().planning_target("hemisphere") == 1.0
    with pytest.raises(ConfigError, match="planning_miss_ratio"):
        SelectionConfig(coverage_target=0.98, planning_miss_ratio=0.0)
    with pytest.raises(ConfigError, match="above 0"):
        SelectionConfig(coverage_target=0.5, planning_miss_ratio=3.0).planning_target("sphere")
