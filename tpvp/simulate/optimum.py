"""The exact optimum of a plant case (``optimum``): the best possible plan with perfect knowledge of
today's plant, the baseline beside the individual-plant experiment's results and the frontier
(:mod:`tpvp.simulate.frontier`): the same executed initial view, then on the ground-truth
visibility restricted to the oracle voxels

* target 1.0: the minimum set cover (:func:`tpvp.setcover.ilp.solve_set_cover`);
* target < 1: the fewest further views that, with the initial view, see ``ceil(target x |oracle|)``
  oracle voxels: one partial set-cover ILP (:func:`tpvp.setcover.partial.partial_set_cover`);

then the exact shortest open path from the initial view through the chosen views
(:func:`tpvp.path.tsp.shortest_open_path` on :func:`tpvp.path.local.local_path_lengths`). The
obstacle radius is ``obstacle_radius`` of the oracle voxel centres: the surface a perfect scan from
every view would have observed, the same kind of points (observed voxel centres) the planner's
coarse reconstruction gives ``run_case``. Among several selections with the fewest views the one the
solver returns is taken; the path is the shortest through that selection, not the shortest over all
minimum selections. When a solver stops at its time limit the row reports its incumbent with the
proven bound and gap and ``optimal=False``.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pandas as pd
from scipy import sparse

from tpvp.config import PlantConfig
from tpvp.errors import ConfigError
from tpvp.path.local import local_path_lengths, obstacle_radius
from tpvp.path.tsp import shortest_open_path
from tpvp.setcover.ilp import solve_set_cover
from tpvp.setcover.partial import partial_set_cover, partial_set_covers

OPTIMUM_COLUMNS = ("target", "views", "coverage", "path_length", "optimal", "bound", "gap", "seconds",
                   "selected", "order", "selection_optimal", "path_optimal", "status")


def _check_config(config) -> PlantConfig:
    if not isinstance(config, PlantConfig):
        raise ConfigError(f"config must be a PlantConfig (make_config('plant', ...)), got {type(config).__name__}")
    return config


def plant_case(scene, config) -> tuple:
    """``(config, view space, plant centre (the origin), initial view index)``, config checked."""
    config = _check_config(config)
    space = scene.view_space
    return config, space, np.zeros(3), space.view_index(config.initial_view)


def _check_targets(targets) -> tuple:
    values = (targets,) if np.ndim(targets) == 0 else tuple(np.asarray(targets, dtype=object).reshape(-1))
    if not values:
        raise ConfigError("targets must name at least one coverage fraction in (0, 1]")
    out = []
    for t in values:
        if isinstance(t, (bool, np.bool_)) or not isinstance(t, (int, float, np.integer, np.floating)) \
                or not (0 < float(t) <= 1):
            raise ConfigError(f"targets must be coverage fractions in (0, 1], got {t!r}")
        out.append(float(t))
    return tuple(out)


def optimum(scene, config: PlantConfig = PlantConfig(), targets=(1.0, 0.98), shared: bool = False) -> pd.DataFrame:
    """The exact optimum with perfect knowledge of the current plant, one row per target.

    Columns: ``target``, ``views`` (initial view included), ``coverage`` (oracle-normalised),
    ``path_length`` (shortest open path from the initial view, planning frame m), ``optimal``
    (the view count and the path are both proven optimal), ``bound`` (proven lower bound on
    ``views``), ``gap`` ((views - bound) / views), ``seconds``, ``selected`` (the chosen views,
    sorted, initial view excluded, as a string), ``order`` (the executed order, initial view first,
    as a string), ``selection_optimal``, ``path_optimal`` and ``status`` (solver words).
    Solver settings: ``config.selection.set_cover`` (solver, time limit, threads) for both ILPs and
    ``config.path`` for the path. ``shared``: every target in one model
    (:func:`tpvp.setcover.partial.partial_set_covers`: HiGHS, each target warm-started from the
    next larger one's views, the time limit for all targets together), as a frontier of many
    targets needs; else each target alone with the configured solver, as Table I is.
    """
    config, space, centre, initial = plant_case(scene, config)
    targets = _check_targets(targets)
    oracle = np.asarray(scene.oracle)
    if oracle.size == 0:
        raise ConfigError("the scene's oracle is empty: no view sees the plant")
    visibility = sparse.csr_matrix(scene.truth_visibility)[:, oracle]
    radius = obstacle_radius(scene.grid.centres[oracle], centre)
    solver_config = config.selection.set_cover
    initial_covered = np.zeros(oracle.size, dtype=bool)
    initial_covered[visibility[initial].indices] = True

    if shared:
        together = partial_set_covers(visibility, [math.ceil(t * oracle.size - 1e-9) for t in targets],
                                      executed=[initial], config=solver_config)
    rows = []
    for i, target in enumerate(targets):
        t0 = time.perf_counter()
        if shared:
            result = together[i]
            selected, selection_optimal = result.selected, bool(result.optimal)
            bound = 1.0 + float(result.bound)
            status = f"partial set cover, one model for all targets: {result.status}"
            t0 -= result.solve_seconds
        elif target >= 1.0:
            result = solve_set_cover(visibility, executed=[initial], config=solver_config)
            selected, selection_optimal = result.selected, bool(result.optimal)
            bound = 1.0 + float(result.bound)
            status = f"set cover: {result.status}"
        else:
            result = partial_set_cover(visibility, math.ceil(target * oracle.size - 1e-9), executed=[initial],
                                       config=solver_config)
            selected, selection_optimal = result.selected, bool(result.optimal)
            bound = 1.0 + float(result.bound)
            status = f"partial set cover: {result.status}"
        stops = [initial, *[int(v) for v in selected]]
        tsp = shortest_open_path(local_path_lengths(space.positions[stops], centre, radius), start=0,
                                 config=config.path)
        order = [stops[i] for i in tsp.order]
        covered = initial_covered.copy()
        if len(selected):
            covered[visibility[np.asarray(selected)].indices] = True
        views = len(stops)
        rows.append({
            "target": target, "views": views, "coverage": float(covered.sum() / oracle.size),
            "path_length": float(tsp.length), "optimal": bool(selection_optimal and tsp.optimal),
            "bound": bound, "gap": float((views - bound) / views), "seconds": time.perf_counter() - t0,
            "selected": str(sorted(int(v) for v in selected)), "order": str(order),
            "selection_optimal": selection_optimal, "path_optimal": bool(tsp.optimal),
            "status": f"{status}; path {tsp.method}"})
    return pd.DataFrame(rows, columns=list(OPTIMUM_COLUMNS))
