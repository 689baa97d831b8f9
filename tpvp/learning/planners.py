"""The trained networks as stage methods (docs/learning.md#planning).

* ``pc-nbv`` (NBV method, :class:`PcNbv`): the accumulated cloud (``cloud_points`` random points)
  and the view state -> predicted gain per view; the next view is the best one not yet taken.
* ``ma-scvp`` (view-selection method, :func:`ma_scvp_selection`): the 32^3 grid of what the
  executed views saw and the view state -> the views scoring >= 0.5, executed ones dropped.

Both networks know the 32 hemisphere views only. In a larger view space whose first 32 rows are the
hemisphere (the 63-view sphere) they score those rows and can never pick the others, as in the
paper's sphere runs. :func:`learned_one_shot` is the published MA-SCVP system on a simulator scene:
initial view, one PC-NBV view, the network's set, the exact open path; with ``labels="oracle"`` the
network is replaced by the exact minimum set cover it was trained to predict.
"""

from __future__ import annotations

import time

import numpy as np
import torch
from scipy import sparse

from tpvp.errors import ConfigError
from tpvp.learning.dataset import VIEWS, sample_cloud  # noqa: F401 (VIEWS re-exported)
from tpvp.learning.grid import occupancy_grid
from tpvp.learning.training import THRESHOLD
from tpvp.learning.weights import cached_model
from tpvp.nbv.methods import NbvChoice, ObservedViews
from tpvp.nbv.warm_up import warm_up
from tpvp.path.route import path_through
from tpvp.setcover.ilp import SetCoverConfig, solve_set_cover
from tpvp.setcover.methods import Selection, SelectionProblem
from tpvp.visibility import coverage_ratio, covered_voxels


def learned_views(space) -> int:
    """How many leading views of ``space`` the networks score (32); an error for a smaller space."""
    if len(space) < VIEWS:
        raise ConfigError(f"the learned planners need the 32-view hemisphere (or a space starting with it); "
                          f"this view space has {len(space)} views")
    return VIEWS


def view_state(executed) -> np.ndarray:
    state = np.zeros(VIEWS, dtype=np.float32)
    state[[v for v in executed if v < VIEWS]] = 1.0
    return state


def view_set_probabilities(positions, executed, observations, centre=np.zeros(3), weights=None) -> np.ndarray:
    """MA-SCVP network scores of the 32 views for the executed views and their observed points."""
    model, _ = cached_model("ma-scvp", weights)
    # stored as float16 in the dataset: the same rounding here
    grid = occupancy_grid(centre, np.asarray(positions)[list(executed)], observations).astype(np.float16)
    with torch.no_grad():
        logits = model(torch.from_numpy(grid.astype(np.float32))[None], torch.from_numpy(view_state(executed))[None])
    return torch.sigmoid(logits)[0].numpy()


def predicted_gains(executed, observations, weights=None) -> np.ndarray:
    """PC-NBV network's predicted gain of the 32 views."""
    model, metadata = cached_model("pc-nbv", weights)
    points = np.concatenate([np.asarray(o, dtype=np.float64).reshape(-1, 3) for o in observations])
    if len(points) == 0:
        raise ConfigError("the executed views observed no point: PC-NBV has no input")
    # a fixed draw per step keeps the method deterministic
    cloud = sample_cloud(points, int(metadata.get("cloud_points", 512)), np.random.default_rng(len(executed)))
    with torch.no_grad():
        gains = model(torch.from_numpy(cloud)[None], torch.from_numpy(view_state(executed))[None])
    return gains[0].numpy().astype(np.float64)


class PcNbv(ObservedViews):
    """PC-NBV-style learned NBV (NBV method ``pc-nbv``); the interface of :mod:`tpvp.nbv.methods`."""

    def __init__(self, context, weights=None):
        learned_views(context.view_space)
        super().__init__(context)
        self.weights = weights

    def next_view(self) -> NbvChoice:
        scores = np.full(len(self.context.view_space), -np.inf)
        scores[:VIEWS] = predicted_gains(self.executed, self.observations, self.weights)
        scores[self.executed] = -np.inf
        if not np.isfinite(scores).any():
            raise ConfigError("PC-NBV: every view it knows has been executed")
        return NbvChoice(int(np.argmax(scores)), scores)


def ma_scvp_selection(problem, config=None, weights=None):
    """View-selection method ``ma-scvp``: the network's set for what the NBV method observed."""
    nbv = problem.nbv
    if nbv is None or not hasattr(nbv, "observations"):
        raise ConfigError("view selection 'ma-scvp' reads what the executed views observed: it needs the NBV "
                          "method's state (SelectionProblem.nbv)")
    learned_views(problem.view_space)
    t0 = time.perf_counter()
    centre = getattr(getattr(nbv, "context", None), "centre", np.zeros(3))
    probabilities = view_set_probabilities(problem.view_space.positions, nbv.executed, nbv.observations, centre,
                                           weights)
    chosen = probabilities >= THRESHOLD
    chosen[[v for v in problem.executed if v < VIEWS]] = False
    selected = np.flatnonzero(chosen)
    return Selection(selected, False, f"MA-SCVP network: {len(selected)} views scored >= {THRESHOLD}",
                     time.perf_counter() - t0, probabilities)


def oracle_selection(scene, executed):
    """The exact minimum set of the 32 learned views that sees every oracle voxel the executed views
    did not (voxels only other views see are dropped): what MA-SCVP is trained to predict."""
    t0 = time.perf_counter()
    truth = sparse.csr_matrix(scene.truth_visibility)
    remaining = np.setdiff1d(scene.oracle, covered_voxels(truth, executed))
    result = solve_set_cover(truth[:VIEWS][:, remaining], executed=[v for v in executed if v < VIEWS],
                             config=SetCoverConfig(solver="highs"))
    return Selection(np.asarray(result.selected), result.optimal, f"oracle label: {result.status}",
                     time.perf_counter() - t0, result)


def learned_one_shot(scene, config, labels: str = "network") -> dict:
    """The MA-SCVP system on a simulator scene (``config.nbv`` chooses the warm-up NBV; the paper's
    system uses one ``pc-nbv`` view). Returns one result row, with the executed views, the planned
    ones in execution order and the obstacle radius of its local paths."""
    if labels not in ("network", "oracle"):
        raise ConfigError(f"labels must be 'network' or 'oracle', got {labels!r}")
    space = scene.view_space
    learned_views(space)
    t0 = time.perf_counter()
    nbv = warm_up(scene, config)
    executed = list(nbv.executed)
    warm_up_seconds = time.perf_counter() - t0
    t0 = time.perf_counter()
    if labels == "network":
        selection = ma_scvp_selection(SelectionProblem(None, tuple(executed), space, None, nbv=nbv))
    else:
        selection = oracle_selection(scene, executed)
    coarse = np.concatenate(nbv.observations)
    planned, path_length, tsp, radius = path_through(space, executed, list(selection.selected), coarse, config)
    planning_seconds = time.perf_counter() - t0
    return {"views": len(executed) + len(planned), "coverage": coverage_ratio(
                covered_voxels(scene.truth_visibility, executed + planned), scene.oracle),
            "path_length_m": path_length,
            "coverage_after_warm_up": coverage_ratio(covered_voxels(scene.truth_visibility, executed), scene.oracle),
            "warm_up_views": len(executed), "planned_views": len(planned), "executed_views": executed,
            "planned_order": planned, "obstacle_radius": radius,
            "status": selection.status,
            "optimal": bool(tsp.optimal), "seconds_warm_up": warm_up_seconds, "seconds_planning": planning_seconds}
