"""Organ labels through the plant pipeline: each source's labels as organ codes, voxel labels
against a brute force, the previous model's labels following the registration onto the planning
voxels, per-organ targets met on the predicted surface, per-organ true coverage, and the lines
users see when the labels are missing or the targets malformed."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from tpvp.cli import main
from tpvp.config import make_config
from tpvp.errors import ConfigError
from tpvp.experiments.single_plant import build_scene, run_case
from tpvp.io import write_point_cloud
from tpvp.scene import voxels
from tpvp.scene.organs import CODE, ORGANS, organ_codes, part_organ_codes, voxel_organs
from tpvp.synthetic.plants import generate_session_pair


def test_every_source_s_labels_become_organ_codes():
    np.testing.assert_array_equal(organ_codes([0, 1, 2, 7], "pheno4d"),
                                  [CODE["unknown"], CODE["stem"], CODE["leaf"], CODE["leaf"]])
    np.testing.assert_array_equal(organ_codes([0, 1, 2, 3, 9], "generated-row"),
                                  [CODE["stem"], CODE["leaf"], CODE["fruit"], CODE["petiole"], CODE["unknown"]])
    np.testing.assert_array_equal(organ_codes([6, 2, -1, 40], "organ"), [6, 2, 0, 0])
    with pytest.raises(ConfigError, match="unknown label kind"):
        organ_codes([1], "helios")


def test_voxel_organs_are_the_majority_of_their_points():
    rng = np.random.default_rng(2)
    points = rng.uniform(0, 0.05, (3000, 3))
    organs = rng.integers(0, len(ORGANS), len(points))
    resolution = 0.01
    keys = np.concatenate([voxels.voxelise(points, resolution), [[50, 50, 50]]])  # a voxel without points
    got = voxel_organs(keys, resolution, points, organs)
    point_keys = voxels.voxel_keys(points, resolution)
    for key, code in zip(keys, got):
        inside = organs[(point_keys == key).all(axis=1)]
        expected = np.argmax(np.bincount(inside, minlength=len(ORGANS))) if len(inside) else CODE["unknown"]
        assert code == expected


@pytest.fixture(scope="module")
def labelled_scene():
    pair = generate_session_pair("tomato", 1)
    organs = tuple(part_organ_codes(s.part_kinds, s.part) for s in (pair.previous, pair.current))
    return build_scene(pair.previous.points, pair.current.points, make_config("plant"), organs=organs), pair, organs


def test_a_scene_carries_the_labels_of_both_sessions(labelled_scene):
    scene, pair, (_, current_organs) = labelled_scene
    assert scene.previous_organs.shape == (len(scene.previous),)
    assert set(np.unique(scene.previous_organs)) == {CODE["stem"], CODE["leaf"], CODE["petiole"]}
    # every ground-truth voxel holding plant points carries their majority organ; the table none
    planning = scene.current
    config = make_config("plant")
    np.testing.assert_array_equal(scene.voxel_organs, voxel_organs(scene.grid.keys, config.gt_resolution, planning,
                                                                    current_organs))
    assert (scene.voxel_organs[scene.grid.countable] != CODE["unknown"]).mean() > 0.99


def test_organ_targets_are_met_on_the_predicted_surface_with_fewer_views(labelled_scene):
    scene, _, _ = labelled_scene
    config = make_config("plant")
    full = run_case(scene, config)
    targeted = run_case(scene, replace(config, selection=replace(config.selection, organ_targets="leaf=0.9")))
    assert targeted.planning_organs["leaf"] >= 0.9 and targeted.planning_organs["stem"] == 1.0
    assert targeted.n_views < full.n_views
    assert set(full.organ_coverage) == {"stem", "leaf", "petiole"} and all(0 < v <= 1 for v in
                                                                            full.organ_coverage.values())
    row = targeted.summary()
    assert row["coverage_leaf"] == targeted.organ_coverage["leaf"] and "planning_coverage_leaf" in row


def test_organ_targets_without_labels_are_one_line(labelled_scene):
    scene, _, _ = labelled_scene
    config = make_config("plant")
    unlabelled = replace(scene, previous_organs=None, voxel_organs=None)
    with pytest.raises(ConfigError, match="need the previous model's organ labels"):
        run_case(unlabelled, replace(config, selection=replace(config.selection, organ_targets="fruit=1")))
    with pytest.raises(ConfigError, match="ORGAN=SHARE"):
        replace(config.selection, organ_targets="fruits=1")


def test_plan_reads_labels_and_reports_coverage_per_organ(labelled_scene, tmp_path, capsys):
    _, pair, (previous_organs, current_organs) = labelled_scene
    previous = write_point_cloud(tmp_path / "previous.ply", pair.previous.points, labels=previous_organs)
    current = write_point_cloud(tmp_path / "current.ply", pair.current.points, labels=current_organs)
    base = ["plan", "--previous", previous, "--current", current, "--units", "m"]
    assert main([*map(str, base), "--organ-targets", "leaf=0.95", "--output", str(tmp_path / "no_labels")]) == 2
    assert "need the previous model's organ labels" in capsys.readouterr().err
    assert not (tmp_path / "no_labels").exists()
    assert main([*map(str, base), "--labels", "organ", "--organ-targets", "leaf=0.95",
                 "--output", str(tmp_path / "plan")]) == 0
    row = pd.read_csv(tmp_path / "plan" / "results.csv").iloc[0]
    assert row["planning_coverage_leaf"] >= 0.95 and 0 < row["coverage_leaf"] <= 1


def test_a_labelled_session_plans_the_organ_targets_as_the_simulator(labelled_scene, tmp_path):
    """A real session started with the previous model's organ labels plans per-organ targets from
    its captures exactly as the simulator does."""
    from tpvp.experiments.standin import StandInCamera
    from tpvp.session import Session

    _, pair, organs = labelled_scene
    config = make_config("plant", {"view_space": "sphere", "selection.organ_targets": "leaf=0.9,petiole=0.8"})
    camera = StandInCamera(pair.previous.points, pair.current.points, config, organs=organs)
    simulated = run_case(camera.scene, camera.config)
    session = Session.start(tmp_path / "session", pair.previous.points, config, "previous", previous_organs=organs[0])
    while (request := session.request()).view is not None:
        session.add(camera.cloud(request.view), request.view, f"view {request.view}")
    planned = Session.open(tmp_path / "session").plan()
    assert planned.planned_views == simulated.planned_views and planned.planning_organs == simulated.planning_organs
    assert planned.planning_organs["leaf"] >= 0.9 and planned.planning_organs["petiole"] >= 0.8


def test_organ_targets_hold_through_re_planning(labelled_scene):
    scene, _, _ = labelled_scene
    config = make_config("plant", {"selection.organ_targets": "leaf=0.9", "selection.replan_after": 2})
    result = run_case(scene, config)
    assert result.replans and result.planning_organs["leaf"] >= 0.9 and result.planning_organs["stem"] == 1.0


def test_a_named_organ_s_target_holds_its_neighbours_when_stricter():
    from tpvp.pipeline.plant import organ_groups

    keys = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [5, 5, 5]])
    organs = np.array([CODE["fruit"], CODE["leaf"], CODE["leaf"], CODE["stem"], CODE["leaf"]])
    groups, shares = organ_groups(organs, {"fruit": 1.0, "leaf": 0.95}, 0.98, "prior", keys, margin=1)
    assert shares == (1.0, 0.95, 0.98)
    # the leaf voxel next to the fruit is held to the fruit's share, the stem next to it too (stricter
    # than the others' 0.98); the leaf two voxels away and the far one keep the leaves' share
    np.testing.assert_array_equal(groups, [0, 0, 1, 0, 1])
    # two voxels of margin reach the second leaf voxel too; none leaves every voxel its own organ's
    np.testing.assert_array_equal(organ_groups(organs, {"fruit": 1.0, "leaf": 0.95}, 0.98, "prior", keys, margin=2)[0],
                                  [0, 0, 0, 0, 1])
    np.testing.assert_array_equal(organ_groups(organs, {"fruit": 1.0, "leaf": 0.95}, 0.98, "prior", keys, margin=0)[0],
                                  [0, 1, 1, 2, 1])
    groups, _ = organ_groups(organs, {"leaf": 0.9}, 1.0, "prior", keys, margin=1)
    np.testing.assert_array_equal(groups, [1, 0, 0, 1, 0])  # a looser neighbour never lowers a share
