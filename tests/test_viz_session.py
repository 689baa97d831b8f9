"""The figures of a real session (tpvp.viz.session): drawn offscreen from plain arrays, one PNG each;
session_state reads a session's arrays in the world frame; model_agreement counts points within a
tolerance both ways."""

import numpy as np
import pytest

from tpvp.config_loading import make_config
from tpvp.scene.samples import load_sample
from tpvp.session import Session
from tpvp.viz.session import (model_agreement, plot_model_comparison, plot_session_state, plot_session_workflow,
                              request_row, session_state)

PNG = b"\x89PNG\r\n\x1a\n"


def _cloud(n, seed=0, centre=(0.0, 0.0, 0.0)):
    return np.random.default_rng(seed).normal(scale=0.02, size=(n, 3)) + centre


def test_the_state_figure_before_and_after_captures(tmp_path):
    candidates = np.array([[0.4, 0.0, 0.0], [0.0, 0.4, 0.0], [0.0, 0.0, 0.4]])
    first = plot_session_state(tmp_path / "start.png", _cloud(500), candidates,
                               requested=(candidates[0], np.zeros(3)), title="start")
    capture = _cloud(200, 1)
    # the second capture repeats the first: nothing new, still drawn and counted
    later = plot_session_state(tmp_path / "later.png", _cloud(500), candidates, [capture, capture], [0, 2])
    for path in (first, later):
        assert path.read_bytes()[:8] == PNG


def test_each_capture_needs_its_view(tmp_path):
    with pytest.raises(ValueError, match="2 captures but 1 capture views"):
        plot_session_state(tmp_path / "x.png", _cloud(10), np.eye(3), [_cloud(5), _cloud(5)], [0])
    assert not (tmp_path / "x.png").exists()


def test_session_state_is_in_the_world_frame(tmp_path):
    previous = load_sample("tomato_0305")
    session = Session.start(tmp_path / "session", previous, make_config("plant"), "tomato_0305")
    session.add(previous[::10], 17, "part of the previous model")
    state = session_state(session)
    assert np.array_equal(state["previous"], previous) and state["capture_views"] == [17]
    centre = 0.5 * (previous.min(axis=0) + previous.max(axis=0))
    assert np.allclose(np.linalg.norm(state["candidates"] - centre, axis=1), 0.4)  # 0.4 m around the plant
    voxel = session.config.gt_resolution / session.scene.scan_scale
    nearest = np.min(np.linalg.norm(state["captures"][0][:, None] - previous[None, ::10], axis=2), axis=1)
    assert nearest.max() <= np.sqrt(3) / 2 * voxel + 1e-12  # voxel centres of the added points
    assert plot_session_state(tmp_path / "state.png", **state).is_file()
    row = request_row(session.request())
    assert row["role"] == "warm-up NBV 1 of 1" and list(row)[2:] == ["x", "y", "z", "look_x", "look_y", "look_z",
                                                                      "qx", "qy", "qz", "qw"]


def test_model_agreement_counts_both_ways():
    reference = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0]])
    model = np.array([[0.0, 0, 0.1], [1.0, 0, 0.1], [10.0, 0, 0]])
    agreement = model_agreement(model, reference, 0.2)
    assert agreement["completeness"] == 0.5 and agreement["accuracy"] == pytest.approx(2 / 3)
    assert agreement["model points"] == 3 and agreement["reference points"] == 4


def test_the_comparison_and_the_workflow_figures(tmp_path):
    reference = _cloud(800)
    assert plot_model_comparison(tmp_path / "cmp.png", reference[::2], reference, _cloud(300, 2), 1e-4,
                                 title="x").read_bytes()[:8] == PNG
    assert plot_model_comparison(tmp_path / "two.png", reference, reference).read_bytes()[:8] == PNG
    assert plot_session_workflow(tmp_path / "workflow.png").read_bytes()[:8] == PNG
