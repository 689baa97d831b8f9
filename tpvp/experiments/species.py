"""Why one species needs more views than another (Table II, notebook 03): what each view of a
plan sees, the coverage curve in execution order, and how many candidate views see each voxel.

All functions take the scene's ground-truth visibility ``visibility`` (a sparse ``(views x
voxels)`` matrix, ``Scene.truth_visibility``: entry ``(v, j)`` non-zero when view ``v`` observes
voxel ``j``) and the oracle set ``oracle`` (``Scene.oracle``: the voxels some candidate view
sees), so they apply to any scene; :func:`showcase` builds one case's scene and plan.
"""

from __future__ import annotations

from dataclasses import dataclass

from tpvp.config import make_config
from tpvp.experiments.baselines import optimum
from tpvp.experiments.single_plant import build_scene, run_case
from tpvp.metrics.views import (  # noqa: F401 (the notebook's statistics, used here too)
    coverage_curve,
    first_seen_step,
    forced_views,
    occlusion_summary,
    share_seen_by_at_most,
    views_per_voxel,
)


@dataclass(frozen=True, eq=False)
class Showcase:
    """One case planned by Ours: the case, its configuration, its scene and the result."""

    case: object  # tpvp.experiments.plants.Case
    config: object  # PlantConfig of the case
    scene: object  # tpvp.experiments.single_plant.Scene
    result: object  # tpvp.pipeline.plant.CaseResult

    @property
    def order(self) -> list:
        """Every executed view in execution order: initial, warm-up, planned."""
        return self.result.order

    @property
    def label(self) -> str:
        return f"{self.case.instance.species} ({self.case.view_space})"


def showcase(case, base_config=None) -> Showcase:
    """Build ``case``'s scene (``tpvp.experiments.plants.Case``) and plan it with Ours."""
    config = case.config(base_config or make_config("plant"))
    name = case.instance.name
    scene = build_scene(*case.instance.load(), config, names=(f"{name} previous", f"{name} current"))
    return Showcase(case, config, scene, run_case(scene, config))


def plan_row(item: Showcase, with_optimum: bool = True) -> dict:
    """One row about a showcase plan: species, view space, what Ours did (views, of them planned,
    coverage after the warm-up and at the end in percent, path length), the occlusion summary and,
    with ``optimum``, the fewest views that see 100 % of the oracle set with perfect knowledge of
    today's plant (same initial view; ``tpvp.experiments.baselines.optimum``)."""
    result = item.result
    row = {"species": item.case.instance.species, "view_space": item.case.view_space,
           "ours_views": result.n_views, "ours_planned_views": len(result.planned_views),
           "coverage_after_warm_up_pct": 100 * result.coverage_warm_up, "ours_coverage_pct": 100 * result.coverage,
           "path_length_m": result.path_length, **occlusion_summary(item.scene.truth_visibility, item.scene.oracle)}
    if with_optimum:
        row["optimum_views_100pct"] = int(optimum(item.scene, item.config, targets=(1.0,))["views"].iloc[0])
    return row
