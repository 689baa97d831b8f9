"""Pluggable stages and view spaces: registries, dummy methods behind each interface, the plan in
the scan's own frame."""

import json

import numpy as np
import pytest

from tpvp.config_loading import make_config
from tpvp.setcover.config import CALIBRATED_MISS_RATIO
from tpvp.errors import ConfigError, InputFileError
from tpvp.simulate.outputs import write_case_outputs
from tpvp.simulate.single_plant import build_scene, run_case
from tpvp.nbv.methods import NBV_METHODS, NbvChoice
from tpvp.registration.methods import REGISTRATION_METHODS, Alignment
from tpvp.scene.normalise import up_rotation
from tpvp.setcover.methods import SELECTION_METHODS, Selection
from tpvp.synthetic.plants import generate_session_pair
from tpvp.viewspace.space import VIEW_SPACES, get_view_space

FAST = {"registration.embedded_deformation.iterations": 40}


@pytest.fixture(scope="module")
def pair():
    generated = generate_session_pair("maize", 2, days=2.0)
    return generated.previous.points, generated.current.points


@pytest.fixture(scope="module")
def scene(pair):
    return build_scene(*pair, make_config("plant", FAST))


@pytest.mark.parametrize("registry", [NBV_METHODS, REGISTRATION_METHODS, SELECTION_METHODS, VIEW_SPACES])
def test_each_registry_rejects_an_unknown_name_with_one_line(registry):
    with pytest.raises(ConfigError) as info:
        registry.get("no-such-method")
    message = str(info.value)
    assert "'no-such-method'" in message and registry.names()[0] in message and len(message.splitlines()) == 1


def _with(registry, name, obj):
    registry.register(name)(obj)
    return name


class LowestIndexNbv:
    """A sequential NBV that keeps its own state: always the lowest view not executed yet."""

    def __init__(self, context):
        self.context, self.executed, self.observations = context, [], []

    def integrate(self, view, points):
        self.executed.append(view)
        self.observations.append(points)

    def next_view(self):
        free = [v for v in range(len(self.context.view_space)) if v not in self.executed]
        return NbvChoice(free[0], np.zeros(len(self.context.view_space)))


def test_a_dummy_nbv_method_plugs_in(scene):
    name = _with(NBV_METHODS, "test-lowest-index", LowestIndexNbv)
    try:
        result = run_case(scene, make_config("plant", {**FAST, "nbv.method": name, "nbv.warm_up_views": 2}))
    finally:
        NBV_METHODS.unregister(name)
    assert result.executed_views == [17, 0, 1]


def test_a_dummy_registration_method_plugs_in(scene):
    seen = {}

    def shift(previous, coarse, config):
        seen["coarse"] = len(coarse)
        return Alignment(previous + [0.001, 0, 0], 1.0, 0.5, 0.0)

    name = _with(REGISTRATION_METHODS, "test-shift", shift)
    try:
        result = run_case(scene, make_config("plant", {"registration.method": name}))
    finally:
        REGISTRATION_METHODS.unregister(name)
    np.testing.assert_array_equal(result.clouds["warped"], scene.previous + [0.001, 0, 0])
    assert seen["coarse"] > 0 and (result.chamfer_before, result.chamfer_after) == (1.0, 0.5)


def test_a_dummy_selection_method_sees_the_problem_and_its_choice_is_executed(scene):
    seen = {}

    def every_view(problem, config):
        seen["target"] = problem.planning_target
        seen["shape"] = problem.visibility.shape
        seen["occupancy"] = problem.nbv.occupancy is not None and problem.nbv.view_state.sum() == len(problem.executed)
        views = np.setdiff1d(np.arange(len(problem.view_space)), problem.executed)
        return Selection(views, False, "every view", 0.0)

    name = _with(SELECTION_METHODS, "test-every-view", every_view)
    try:
        result = run_case(scene, make_config("plant", {**FAST, "selection.method": name,
                                                       "selection.coverage_target": 0.9}))
    finally:
        SELECTION_METHODS.unregister(name)
    # the problem carries the planning target the asked 0.9 maps to in the hemisphere
    assert seen["target"] == pytest.approx(1 - CALIBRATED_MISS_RATIO["hemisphere"] * 0.1) == result.planning_target
    assert seen["shape"][0] == 32 and seen["occupancy"]
    assert sorted(result.executed_views + result.planned_views) == list(range(32))


def test_a_coverage_target_takes_fewer_views_and_uses_only_what_the_robot_has(scene):
    from dataclasses import replace

    from scipy import sparse

    full = run_case(scene, make_config("plant", FAST))
    part = run_case(scene, make_config("plant", {**FAST, "selection.coverage_target": 0.9}))
    assert part.executed_views == full.executed_views
    assert len(part.planned_views) < len(full.planned_views) and part.selection.optimal
    details = part.selection.details
    assert details.covered_weight >= 0.9 * details.achievable_weight - 1e-9 and details.reachable
    # Ground truth that no executed view saw is not known to the robot: changing it (here: every
    # unexecuted view's observation) must not change the plan.
    truth = sparse.lil_matrix(scene.truth_visibility)
    rng = np.random.default_rng(0)
    for view in set(range(truth.shape[0])) - set(part.executed_views):
        truth.rows[view] = sorted(rng.choice(truth.shape[1], size=50, replace=False).tolist())
        truth.data[view] = [True] * 50
    changed = replace(scene, truth_visibility=sparse.csr_matrix(truth))
    again = run_case(changed, make_config("plant", {**FAST, "selection.coverage_target": 0.9}))
    assert again.planned_views == part.planned_views and again.coverage != part.coverage
    for bad in (0.0, 1.5, -0.1):
        with pytest.raises(ConfigError, match="coverage_target"):
            make_config("plant", {"selection.coverage_target": bad})


def test_a_view_space_file_with_origin_look_ats_reproduces_the_hemisphere(tmp_path, pair):
    hemisphere = get_view_space("hemisphere")
    file = tmp_path / "views.txt"
    rows = np.hstack([hemisphere.positions, np.zeros((32, 3))])
    file.write_text(f"{len(rows)}\n" + "\n".join(" ".join(repr(float(v)) for v in row) for row in rows) + "\n")
    from_file = get_view_space(str(file))
    np.testing.assert_array_equal(from_file.positions, hemisphere.positions)
    np.testing.assert_array_equal(from_file.look_ats, hemisphere.look_ats)
    builtin_config = make_config("plant", FAST)
    file_config = make_config("plant", {**FAST, "view_space": str(file), "scene.table": True})
    builtin, custom = build_scene(*pair, builtin_config), build_scene(*pair, file_config)
    assert (builtin.truth_visibility != custom.truth_visibility).nnz == 0
    a, b = run_case(builtin, builtin_config), run_case(custom, file_config)
    assert (a.executed_views, a.planned_views, a.coverage, a.path_length) == \
        (b.executed_views, b.planned_views, b.coverage, b.path_length)


def test_view_space_errors(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("inf\n1 0 0\n")
    with pytest.raises(InputFileError, match="whole number of views, got 'inf'"):
        get_view_space(str(bad))
    bad.write_text("1 0 0 0\n")
    with pytest.raises(InputFileError, match="3 .* or 6"):
        get_view_space(str(bad))
    with pytest.raises(ConfigError, match="tammes:N"):
        get_view_space("tammes:many")
    assert len(get_view_space("tammes:12")) == 12 and get_view_space("tammes-hemisphere:8").table
    room = get_view_space("room1")
    assert len(room) == 1000 and room.passive_views.shape == (15, 6) and room.max_range == 2.0
    with pytest.raises(ConfigError, match="initial_view 40"):
        get_view_space("hemisphere").view_index(40)
    assert get_view_space("sphere").view_index("near_top") == 21


def test_scan_frame_plan_maps_onto_the_planning_frame_through_the_written_transform(tmp_path, pair):
    # A scan lying on its side (up = scan -y), rotated 45 degrees in the protocol, planned at its true size.
    up = up_rotation("-y")
    previous, current = (p @ up for p in pair)  # inverse rotation: the scan's -y is the plant's up
    config = make_config("plant", {**FAST, "scene.up_axis": "-y", "scene.rotation_deg": 45.0,
                                   "scene.scale": "native", "scene.radius": 0.3})
    scene = build_scene(previous, current, config)
    result = run_case(scene, config)
    write_case_outputs(tmp_path, scene, result, config, "sideways")
    plan = json.loads((tmp_path / "plan.json").read_text())
    matrix = np.array(plan["plant_from_scan"])
    for key in ("", "look_"):
        scan = np.array([[v[f"{key}x"], v[f"{key}y"], v[f"{key}z"]] for v in plan["views"]])
        planning = np.array([[v[f"{key}x"], v[f"{key}y"], v[f"{key}z"]] for v in plan["views_normalised"]])
        mapped = scan @ matrix[:3, :3].T + matrix[:3, 3]
        assert np.abs(mapped - planning).max() < 1e-9
    # The view sphere has the asked radius around the real plant (scan metres).
    scan = np.array([[v["x"], v["y"], v["z"]] for v in plan["views"]])
    centre = np.array(plan["views"][0]["look_x"]), plan["views"][0]["look_y"], plan["views"][0]["look_z"]
    np.testing.assert_allclose(np.linalg.norm(scan - np.array(centre, dtype=float), axis=1), 0.3, rtol=1e-9)
    # Camera axes rotate with the frame: the optical axis (third column) points at the look-at in both.
    for v in plan["views"]:
        q = np.array([v["qx"], v["qy"], v["qz"], v["qw"]])
        x, y, z, w = q
        forward = np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
        direction = np.array([v["look_x"] - v["x"], v["look_y"] - v["y"], v["look_z"] - v["z"]])
        np.testing.assert_allclose(forward, direction / np.linalg.norm(direction), atol=1e-9)
    csv = (tmp_path / "plan.csv").read_text().splitlines()
    assert csv[0].startswith("# frame: the input scans' own frame") and "units: m" in csv[0]
    assert (tmp_path / "plan_normalised.csv").read_text().startswith("# frame: planning frame")
    assert "setting: plant" in (tmp_path / "config.yaml").read_text()
    provenance = json.loads((tmp_path / "provenance.json").read_text())
    assert provenance["tpvp_version"] and provenance["libraries"]["numpy"] and provenance["seeds"]["seed"] == 0


def test_configuration_round_trip_runs_the_same_case(tmp_path, scene):
    from tpvp.config_loading import config_yaml, load_config

    config = make_config("plant", {**FAST, "nbv.pixel_stride": 8})
    (tmp_path / "config.yaml").write_text(config_yaml(config))
    loaded = load_config(tmp_path / "config.yaml")
    assert loaded == config
    a, b = run_case(scene, config), run_case(scene, loaded)
    assert (a.executed_views, a.planned_views, a.coverage, a.path_length, a.chamfer_after) == \
        (b.executed_views, b.planned_views, b.coverage, b.path_length, b.chamfer_after)
