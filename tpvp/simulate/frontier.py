"""The coverage-effort frontier of one case in one call: for each coverage target on the predicted
planning surface, the plan's views, path and true coverage, beside the exact optimum with perfect
knowledge of today's plant for the same true-coverage target.

The warm-up, registration and planning surface (inflation, visibility) are computed once and
shared by every target (they do not depend on it); each target then costs one selection (exact
partial set cover) and one path.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.config import PlantConfig
from tpvp.config_loading import with_overrides
from tpvp.errors import ConfigError
from tpvp.simulate.optimum import optimum
from tpvp.simulate.single_plant import Scene, known, run_case, transfer
from tpvp.pipeline.plan import planning_surface
from tpvp.io import atomic_write_text
from tpvp.io.publish import staged_folder
from tpvp.viz.background import draw

DEFAULT_TARGETS = (0.90, 0.92, 0.94, 0.95, 0.96, 0.97, 0.98, 0.99, 0.995, 1.0)
#: Seconds for the exact optimum of every target together (one model); a target not proven by
#: then keeps its best selection, with ``optimum_optimal`` False.
OPTIMUM_SECONDS = 45.0
FRONTIER_COLUMNS = ("target", "views", "coverage", "path_length_m", "selection_optimal", "optimum_views",
                    "optimum_coverage", "optimum_path_length_m", "optimum_optimal")


def coverage_frontier(scene: Scene, config: PlantConfig, targets=DEFAULT_TARGETS, transferred=None) -> pd.DataFrame:
    """One row per target t (ascending): the plan for ``selection.coverage_target = t`` (views with
    the initial and warm-up views, true coverage of the oracle, path in m) and the exact optimum
    on the ground truth for t of the oracle (``optimum_*``), from the same initial view, every
    target in one model within :data:`OPTIMUM_SECONDS` (``optimum_optimal`` says which were
    proven).
    ``transferred``: the case's :func:`transfer` when already computed."""
    values = sorted({float(t) for t in np.atleast_1d(np.asarray(targets, dtype=float))})
    if not values or values[0] <= 0 or values[-1] > 1:
        raise ConfigError(f"coverage targets must be fractions in (0, 1], got {list(targets)!r}")
    shared = transferred or transfer(scene, config)
    surface = planning_surface(known(scene), config, shared)
    bounded = with_overrides(config, {"selection.set_cover.time_limit": OPTIMUM_SECONDS})
    best = optimum(scene, bounded, targets=tuple(values), shared=True).set_index("target")
    rows = []
    for target in values:
        result = run_case(scene, with_overrides(config, {"selection.coverage_target": target}),
                          transferred=shared, surface=surface)
        limit = best.loc[target]
        rows.append({"target": target, "views": result.n_views, "coverage": result.coverage,
                     "path_length_m": result.path_length, "selection_optimal": bool(result.selection.optimal),
                     "optimum_views": int(limit["views"]), "optimum_coverage": float(limit["coverage"]),
                     "optimum_path_length_m": float(limit["path_length"]), "optimum_optimal": bool(limit["optimal"])})
    return pd.DataFrame(rows, columns=list(FRONTIER_COLUMNS))


def write_frontier_files(folder, frontier: pd.DataFrame, title: str = "", pool=None) -> dict:
    """``frontier.csv`` and ``frontier.png`` of a :func:`coverage_frontier` table in ``folder``
    (each file written atomically; ``folder`` is usually a staged output folder; the figure drawn
    in ``pool``, :func:`tpvp.viz.background.drawing_pool`, when one is given)."""
    folder = Path(folder)
    atomic_write_text(folder / "frontier.csv", frontier.to_csv(index=False))
    draw([("tpvp.viz.experiments:plot_frontier", (folder / "frontier.png", frontier, title), {})], pool)
    return {"table": frontier, "csv": folder / "frontier.csv", "figure": folder / "frontier.png"}


def write_frontier(folder, scene: Scene, config: PlantConfig, targets=DEFAULT_TARGETS, title: str = "") -> dict:
    """:func:`coverage_frontier` as ``frontier.csv`` and ``frontier.png`` in ``folder`` (published
    whole or not at all)."""
    frontier = coverage_frontier(scene, config, targets)
    with staged_folder(folder) as stage:
        write_frontier_files(stage.folder, frontier, title)
    return {"table": frontier, "csv": Path(folder) / "frontier.csv", "figure": Path(folder) / "frontier.png"}
