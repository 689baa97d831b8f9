"""Re-planning from the captures (tpvp.pipeline.replan, selection.replan_after): the disagreement
of captures with a prediction against brute force; captures equal to the prediction keep the plan;
the simulator's re-planned run and a real session's re-plans with the same captures agree."""

import json

import numpy as np
import pandas as pd
import pytest
from scipy import sparse

from tpvp.cli import main
from tpvp.config_loading import load_config, make_config, with_overrides
from tpvp.errors import ConfigError
from tpvp.simulate.single_plant import build_scene, known, run_case, transfer
from tpvp.simulate.robot_camera import StandInCamera
from tpvp.nbv.methods import start_nbv
from tpvp.pipeline.plan import plan, planning_surface
from tpvp.pipeline.replan import AGREEMENT_VOXELS, Prediction, disagreement, prediction_of, replan
from tpvp.scene import voxels
from tpvp.scene.samples import load_sample
from tpvp.session import Session

CONFIG = make_config("plant", {"selection.coverage_target": 0.98})


@pytest.fixture(scope="module")
def pair():
    return load_sample("tomato_0305"), load_sample("tomato_0306")


@pytest.fixture(scope="module")
def planned(pair):
    scene = build_scene(*pair, CONFIG)
    transferred = transfer(scene, CONFIG)
    surface = planning_surface(known(scene), CONFIG, transferred)
    return scene, transferred, surface, plan(known(scene), CONFIG, transferred, surface=surface)


def _near_by_brute_force(keys, query) -> np.ndarray:
    distance = ((query[:, None, :] - keys[None, :, :]) ** 2).sum(axis=2)
    return (distance <= AGREEMENT_VOXELS ** 2 + 1e-9).any(axis=1)


def test_disagreement_matches_brute_force():
    rng = np.random.default_rng(3)
    resolution = 0.01
    for _ in range(20):
        keys = voxels.unique_keys(rng.integers(0, 6, size=(25, 3)))
        visibility = sparse.csr_matrix(rng.random((4, len(keys))) < 0.4)
        prediction = Prediction(voxels.key_centres(keys, resolution), resolution, visibility, 1)
        views = [1, 3]
        seen = [voxels.key_centres(rng.integers(-1, 7, size=(12, 3)), resolution) for _ in views]
        captured = np.concatenate([voxels.key_centres(rng.integers(0, 6, size=(10, 3)), resolution), *seen])
        unexpected, contradicted = disagreement(prediction, views, seen, captured)
        seen_keys = voxels.unique_keys(voxels.voxel_keys(np.concatenate(seen), resolution))
        expected = keys[np.unique(visibility[views].indices)]
        assert unexpected == int((~_near_by_brute_force(keys, seen_keys)).sum())
        assert contradicted == int((~_near_by_brute_force(voxels.voxel_keys(captured, resolution), expected)).sum())


def test_captures_equal_to_the_prediction_keep_the_plan(planned):
    scene, transferred, surface, result = planned
    prediction = prediction_of(surface, len(result.executed_views))
    nbv = start_nbv(scene, CONFIG)
    for view, seen in zip(transferred.nbv.executed, transferred.nbv.observations):
        nbv.integrate(view, seen)
    for view in result.planned_views[:2]:  # each capture: exactly the voxels the plan predicted it sees
        nbv.integrate(view, prediction.centres[prediction.visibility[view].indices])
    again, _, step = replan(known(scene), CONFIG, nbv, len(result.executed_views), result.planned_views, prediction)
    assert (step.unexpected_voxels, step.contradicted_voxels) == (0, 0)
    assert (step.views_added, step.views_dropped) == (0, 0)
    assert again.planned_views == result.planned_views
    assert again.executed_views == result.executed_views
    assert step.remaining_after == len(result.planned_views) - 2


def test_a_replanned_run_executes_every_view_once_and_ends_with_nothing_left(pair):
    config = with_overrides(CONFIG, {"selection.replan_after": 2})
    scene = build_scene(*pair, config)
    result = run_case(scene, config)
    assert result.replans and result.replans[-1].remaining_after == 0
    assert len(set(result.order)) == len(result.order) == result.n_views
    so_far = [len(result.executed_views), *(step.views_so_far for step in result.replans)]
    assert all(0 < b - a <= 2 for a, b in zip(so_far, so_far[1:]))  # after every 2 planned views (or the last)
    for step in result.replans:
        assert step.remaining_after == step.remaining_before + step.views_added - step.views_dropped
    # the true coverage is that of the views it executed, recounted here on the truth: every voxel one
    # of them sees, over the voxels some candidate view sees
    truth = sparse.csr_matrix(scene.truth_visibility)
    seeable = set(truth.indices.tolist())

    def seen_by(views):
        return {int(i) for view in views for i in truth.indices[truth.indptr[view]:truth.indptr[view + 1]]}

    assert result.coverage == len(seen_by(result.order)) / len(seeable)
    assert result.coverage_captured == len(seen_by(result.executed_views)) / len(seeable)
    assert result.coverage > result.coverage_captured
    assert "replanning" in result.timings


def test_a_session_replans_what_the_simulator_replans(tmp_path, pair):
    config = make_config("plant", {"selection.coverage_target": 0.98, "selection.replan_after": 2,
                                   "view_space": "sphere"})
    camera = StandInCamera(*pair, config)
    simulated = run_case(camera.scene, camera.config)
    session = Session.start(tmp_path / "session", pair[0], config, "tomato_0305")
    roles = []
    while True:
        request = session.request()
        if request.view is None:
            roles.append(request.role)
            if request.role in ("plan", "replan"):
                result = session.plan()
                continue
            break
        session.add(camera.cloud(request.view), request.view, f"view {request.view}")
    assert roles.count("replan") == len(simulated.replans)
    assert result.planned_views == simulated.planned_views
    assert result.executed_views == simulated.executed_views
    columns = lambda steps: [{k: v for k, v in s.row().items() if k != "seconds"} for s in steps]  # noqa: E731
    assert columns(result.replans) == columns(simulated.replans)
    state = Session.open(tmp_path / "session").state["plan"]
    assert state["planned_views"] == simulated.planned_views and len(state["replans"]) == len(simulated.replans)


def test_a_one_shot_session_checks_its_captures_at_the_end_as_the_simulator_closes(tmp_path, pair, capsys):
    """Every planned view captured, a one-shot session asks for the closing check (role ``close``);
    ``tpvp session plan`` then re-plans from the captures and says whether the target holds; with
    the same captures its views equal ``run_case(closing=True)``'s, and it ends with ``export``."""
    camera = StandInCamera(*pair, CONFIG)
    simulated = run_case(camera.scene, camera.config, closing=True)
    one_shot = run_case(camera.scene, camera.config)
    assert simulated.replans and simulated.replans[0].remaining_before == 0  # the first check: after every view
    assert simulated.planned_views[:len(one_shot.planned_views)] == one_shot.planned_views
    session = Session.start(tmp_path / "session", pair[0], CONFIG, "tomato_0305")
    roles, printed = [], ""
    while True:
        request = session.request()
        if request.view is None:
            roles.append(request.role)
            if request.role == "plan":
                session.plan()
            elif request.role == "close":
                assert main(["session", "plan", str(tmp_path / "session")]) == 0
                printed += capsys.readouterr().out
                session = Session.open(tmp_path / "session")
            else:
                break
            continue
        session.add(camera.cloud(request.view), request.view, f"view {request.view}")
    assert roles == ["plan", *["close"] * len(simulated.replans), "export"]
    state = session.state["plan"]
    assert state["planned_views"] == simulated.planned_views
    columns = lambda steps: [{k: v for k, v in s.items() if k != "seconds"} for s in steps]  # noqa: E731
    assert columns(state["replans"]) == columns([step.row() for step in simulated.replans])
    # a folder's re-plan rows from before captured_coverage was recorded read as sound; other keys do not
    from tpvp.session.check import _plan_record_problem

    assert _plan_record_problem(state, "plant") is None
    old = {**state, "replans": [{k: v for k, v in row.items() if k != "captured_coverage"} for row in state["replans"]]}
    assert _plan_record_problem(old, "plant") is None
    assert _plan_record_problem({**state, "replans": [{**state["replans"][0], "surprise": 1}]}, "plant") == \
        "the plan's 'replans' are not re-plan rows"
    for step in simulated.replans:
        seen = f"the captures see {100 * step.captured_coverage:.2f} % of the planning surface"
        assert seen + (f"): {step.views_added} view(s) added to close the gap" if step.views_added else
                       "): the plan's target holds, nothing to add") in printed.replace(
            f" (the plan asks {100 * simulated.planning_target:.2f} %", "")


def test_plan_replan_after_prints_each_replan_and_writes_its_rows(tmp_path, capsys):
    out = tmp_path / "plan"
    assert main(["demo", "--output", str(out), "--coverage-target", "0.98", "--replan-after", "3"]) == 0
    printed = capsys.readouterr().out
    results = pd.read_csv(out / "results.csv")
    steps = results[results["plan"].str.startswith("re-plan")]
    assert results["plan"].iloc[0] == "final" and len(steps) == printed.count("re-plan ") >= 1
    assert {"views_so_far", "predicted_coverage", "views_added", "views_dropped"} <= set(steps.columns)
    assert json.loads((out / "results.json").read_text())["replans"] == len(steps)


def test_replan_after_is_checked_and_refused_for_rows():
    with pytest.raises(ConfigError, match="replan_after"):
        load_config("paper", {"selection.replan_after": -1})
    with pytest.raises(ConfigError, match="single plants"):
        load_config("paper-row", {"selection.replan_after": 2})
