"""Organ labels through the plant pipeline: each source's labels as organ codes, voxel labels
against a brute force, the previous model's labels following the registration onto the planning
voxels, per-organ targets met on the predicted surface, per-organ true coverage, and the lines
users see when the labels are missing or the targets malformed."""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from scipy import sparse

from tpvp.cli import main
from tpvp.config_loading import make_config
from tpvp.errors import ConfigError
from tpvp.simulate.single_plant import build_scene, run_case
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


def test_the_true_organ_coverage_of_a_scene_built_by_hand():
    """Eight 1 cm voxels in a row, their labelled points and what three views see, all written out:
    the true coverage per organ of each set of views is known by hand."""
    from tpvp.simulate.single_plant import organ_coverage
    from tpvp.scene.grid import build_grid
    from tpvp.simulate.world import Scene
    from tpvp.visibility import covered_voxels, oracle_voxels

    stem, leaf, petiole, unknown = CODE["stem"], CODE["leaf"], CODE["petiole"], CODE["unknown"]
    resolution = 0.01
    # voxel (x, 0, 0) -> the organs of the points in it; its organ is their majority (leaf on the
    # leaf-petiole tie of x = 2: the lower code); x = 6 is the table (no labelled point); x = 7 is
    # a stem voxel that no view sees
    labels = {0: [stem] * 3, 1: [stem, stem, leaf], 2: [petiole, leaf], 3: [leaf, leaf], 4: [leaf],
              5: [petiole, petiole, leaf], 6: [], 7: [stem]}
    points = np.array([[(x + 0.1 + 0.2 * i) * resolution, 0.005, 0.005]
                       for x, organs in labels.items() for i in range(len(organs))])
    organs = np.array([code for codes in labels.values() for code in codes])
    keys = np.array([[x, 0, 0] for x in labels])
    grid = build_grid(keys, resolution, np.array([x != 6 for x in labels]))
    ids = grid.ids_of(keys)  # voxel x -> its id in the grid
    sees = {0: [0, 2, 6], 1: [1, 3, 4], 2: [3, 5]}  # view -> the voxels x it sees
    rows = [view for view, xs in sees.items() for _ in xs]
    truth = sparse.csr_matrix((np.ones(len(rows)), (rows, ids[[x for xs in sees.values() for x in xs]])),
                              shape=(3, len(keys)))
    scene = Scene(points, points, grid, None, None, truth, oracle_voxels(truth), np.eye(4), np.zeros((0, 3)),
                  voxel_organs=voxel_organs(grid.keys, resolution, points, organs))
    np.testing.assert_array_equal(scene.voxel_organs[ids], [stem, stem, leaf, leaf, leaf, petiole, unknown, stem])
    np.testing.assert_array_equal(scene.oracle, np.sort(ids[:7]))

    def coverage(views):
        return organ_coverage(scene, covered_voxels(truth, views))

    # stem: x 0, 1 (x 7 unseen by any view: not counted); leaf: x 2, 3, 4; petiole: x 5; the table: none
    assert coverage([0, 2]) == {"stem": 1 / 2, "leaf": 2 / 3, "petiole": 1.0}
    assert coverage([1]) == {"stem": 1 / 2, "leaf": 2 / 3, "petiole": 0.0}
    assert coverage([2]) == {"stem": 0.0, "leaf": 1 / 3, "petiole": 1.0}
    assert coverage([0, 1, 2]) == {"stem": 1.0, "leaf": 1.0, "petiole": 1.0}
    assert coverage([]) == {"stem": 0.0, "leaf": 0.0, "petiole": 0.0}


def true_organ_coverage(scene, point_organs, views, resolution) -> dict:
    """Brute force of the true coverage per organ of ``views``: each ground-truth voxel some view
    sees takes the most frequent organ of today's labelled points in it (the lowest code on ties;
    the table's voxels hold none), and counts as covered when one of ``views`` sees it."""
    assert len(scene.current) == len(point_organs)  # today's points as labelled: none reduced
    votes = {}
    for key, code in zip(map(tuple, np.floor(scene.current / resolution).astype(np.int64)), point_organs):
        votes.setdefault(key, Counter())[int(code)] += 1
    truth = sparse.csr_matrix(scene.truth_visibility)
    seen = {int(i) for view in views for i in truth.indices[truth.indptr[view]:truth.indptr[view + 1]]}
    flags = {}
    for voxel in sorted(set(truth.indices.tolist())):
        count = votes.get(tuple(scene.grid.keys[voxel]))
        organ = min(count, key=lambda code: (-count[code], code)) if count else CODE["unknown"]
        if organ != CODE["unknown"]:
            flags.setdefault(ORGANS[organ], []).append(voxel in seen)
    return {organ: sum(covered) / len(covered) for organ, covered in flags.items()}


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
    scene, _, (_, current_organs) = labelled_scene
    config = make_config("plant")
    full = run_case(scene, config)
    targeted = run_case(scene, replace(config, selection=replace(config.selection, organ_targets="leaf=0.9")))
    assert targeted.planning_organs["leaf"] >= 0.9 and targeted.planning_organs["stem"] == 1.0
    assert targeted.n_views < full.n_views
    # the true coverage per organ of the views each plan executed, against a brute force
    assert set(full.organ_coverage) == {"stem", "leaf", "petiole"}
    for result in (full, targeted):
        assert result.organ_coverage == true_organ_coverage(scene, current_organs, result.order, config.gt_resolution)
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
    from tpvp.simulate.robot_camera import StandInCamera
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


@pytest.mark.slow
def test_organ_targets_hold_through_re_planning(labelled_scene):
    scene, _, _ = labelled_scene
    config = make_config("plant", {"selection.organ_targets": "leaf=0.9", "selection.replan_after": 2})
    result = run_case(scene, config)
    assert result.replans and result.planning_organs["leaf"] >= 0.9 and result.planning_organs["stem"] == 1.0


def test_a_named_organ_s_target_holds_its_neighbours_when_stricter():
    from tpvp.pipeline.plan import organ_groups

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


# --- per-organ targets that cannot be what was meant (issue 47) ------------------------------------

@pytest.fixture(scope="module")
def leafy_pair():
    """A generated pair with organ labels: stem, leaf and petiole, no flower or fruit."""
    pair = generate_session_pair("tomato", 1)
    return pair, tuple(part_organ_codes(s.part_kinds, s.part) for s in (pair.previous, pair.current))


def test_an_organ_given_twice_is_refused_naming_it():
    config = make_config("plant")
    with pytest.raises(ConfigError, match=r"'fruit' is given twice \(fruit=1.0, fruit=0.9\); give each organ one"):
        replace(config.selection, organ_targets="fruit=1.0,leaf=0.9,fruit=0.9")
    assert replace(config.selection, organ_targets="fruit=1.0,leaf=0.9").organ_target_values() == {"fruit": 1.0,
                                                                                                  "leaf": 0.9}


def test_a_target_on_an_organ_without_points_names_it_and_the_organs_there_are():
    from tpvp.scene.organs import check_organ_targets

    organs = np.array([CODE["stem"]] * 3 + [CODE["leaf"]] * 1200)
    with pytest.raises(ConfigError) as refused:
        check_organ_targets({"leaf": 0.9, "flower": 1.0, "fruit": 0.95}, organs, "day1.ply")
    assert str(refused.value) == ("organ targets flower=1,fruit=0.95: day1.ply has no flower or fruit point (its "
                                  "organs: stem 3 points, leaf 1,200 points); target an organ it has, or check the "
                                  "scan and its --labels")
    check_organ_targets({"leaf": 0.9, "stem": 1.0}, organs, "day1.ply")  # organs it has
    check_organ_targets({"fruit": 1.0}, None, "day1.ply")  # no labels: the planner's own line


def test_a_session_refuses_a_target_on_an_absent_organ_at_start_and_plan(leafy_pair, tmp_path, capsys):
    from tpvp.session import Session
    from tpvp.session.check import ORGANS_FILE

    pair, (previous_organs, _) = leafy_pair
    previous = write_point_cloud(tmp_path / "previous.ply", pair.previous.points, labels=previous_organs)
    start = ["session", "start", "--previous", str(previous), "--units", "m", "--labels", "organ"]
    assert main([*start, "--organ-targets", "fruit=1.0", "--output", str(tmp_path / "refused")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "previous.ply has no fruit point (its organs: stem " in err[0], err
    assert not (tmp_path / "refused").exists()
    folder = tmp_path / "session"
    assert main([*start, "--output", str(folder)]) == 0
    state = (folder / "session.json").read_text()
    assert main(["session", "plan", str(folder), "--organ-targets", "leaf=0.9,flower=1.0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("tpvp session plan: error: organ targets flower=1: ") and \
        "has no flower point" in err[0], err
    assert (folder / "session.json").read_text() == state and not (folder / "plan").exists()
    # the labels are named in the state: their file deleted is damage, not a session without labels
    (folder / ORGANS_FILE).unlink()
    assert any("previous_organs.npy (the previous model's organ labels) is missing" in p.what
               for p in Session.problems(folder))


def test_tpvp_plan_refuses_a_target_on_an_absent_organ(leafy_pair, tmp_path, capsys):
    pair, organs = leafy_pair
    scans = [write_point_cloud(tmp_path / f"{name}.ply", s.points, labels=codes)
             for name, s, codes in (("previous", pair.previous, organs[0]), ("current", pair.current, organs[1]))]
    assert main(["plan", "--previous", str(scans[0]), "--current", str(scans[1]), "--units", "m", "--labels", "organ",
                 "--organ-targets", "fruit=1.0", "--set", "registration.embedded_deformation.iterations=5",
                 "--output", str(tmp_path / "plan")]) == 2
    assert "previous.ply has no fruit point" in capsys.readouterr().err
