"""Why one species needs more views than another (Table II, notebook 03): what each view of a
plan sees, the coverage curve in execution order, and how many candidate views see each voxel.

All functions take the scene's ground-truth visibility ``visibility`` (a sparse ``(views x
voxels)`` matrix, ``Scene.truth_visibility``: entry ``(v, j)`` non-zero when view ``v`` observes
voxel ``j``) and the oracle set ``oracle`` (``Scene.oracle``: the voxels some candidate view
sees), so they apply to any scene; :func:`showcase` builds one case's scene and plan.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import sparse


def _csr(visibility) -> sparse.csr_matrix:
    matrix = sparse.csr_matrix(visibility)
    matrix.eliminate_zeros()
    return matrix


def views_per_voxel(visibility, voxels=None) -> np.ndarray:
    """Per voxel, the number of candidate views that observe it (``(voxels,)`` int; only the
    listed ``voxels``, in their order, when given). A voxel seen by one view forces that view
    into any plan that must see it; a voxel seen by many can be left to whichever view is cheap."""
    matrix = sparse.csc_matrix(_csr(visibility))
    counts = np.diff(matrix.indptr).astype(np.int64)
    return counts if voxels is None else counts[np.asarray(voxels, dtype=np.int64)]


def coverage_curve(visibility, oracle, order) -> pd.DataFrame:
    """The coverage of the oracle set after each view of ``order`` (execution order: the initial
    view, the warm-up views, then the planned ones). One row per view: ``step`` (1-based),
    ``view``, ``new_voxels`` (oracle voxels this view sees that no earlier view saw), ``covered``
    (oracle voxels seen so far) and ``coverage`` (``covered / |oracle|``)."""
    matrix = _csr(visibility)
    in_oracle = np.zeros(matrix.shape[1], dtype=bool)
    in_oracle[np.asarray(oracle, dtype=np.int64)] = True
    total = int(in_oracle.sum())
    seen = np.zeros(matrix.shape[1], dtype=bool)
    rows = []
    for step, view in enumerate(order, start=1):
        voxels = matrix.indices[matrix.indptr[view]:matrix.indptr[view + 1]]
        fresh = voxels[in_oracle[voxels] & ~seen[voxels]]
        seen[fresh] = True
        covered = int((seen & in_oracle).sum())
        rows.append({"step": step, "view": int(view), "new_voxels": int(len(fresh)), "covered": covered,
                     "coverage": covered / total if total else 0.0})
    return pd.DataFrame(rows, columns=["step", "view", "new_voxels", "covered", "coverage"])


def first_seen_step(visibility, order, voxels=None) -> np.ndarray:
    """Per voxel (or per listed ``voxels``), the 1-based step of ``order`` at which a view first
    observes it; 0 where no view of ``order`` does."""
    matrix = _csr(visibility)
    step = np.zeros(matrix.shape[1], dtype=np.int64)
    for k, view in enumerate(order, start=1):
        voxels_seen = matrix.indices[matrix.indptr[view]:matrix.indptr[view + 1]]
        fresh = voxels_seen[step[voxels_seen] == 0]
        step[fresh] = k
    return step if voxels is None else step[np.asarray(voxels, dtype=np.int64)]


def forced_views(visibility, oracle) -> np.ndarray:
    """The views that are the only view of some oracle voxel (sorted). Seeing all of the oracle
    set needs every one of them, so their number is a lower bound on the views of any plan that
    covers 100 % of it."""
    matrix = sparse.csc_matrix(_csr(visibility)[:, np.asarray(oracle, dtype=np.int64)])
    single = np.flatnonzero(np.diff(matrix.indptr) == 1)
    return np.unique(matrix.indices[matrix.indptr[single]]).astype(np.int64)


def share_seen_by_at_most(counts, k_max: int) -> np.ndarray:
    """``share[k - 1]`` = the fraction of voxels seen by at most ``k`` views, ``k = 1 .. k_max``
    (``counts`` from :func:`views_per_voxel`; voxels seen by no view count as seen by at most k)."""
    counts = np.asarray(counts)
    if counts.size == 0:
        return np.zeros(k_max)
    return np.array([(counts <= k).mean() for k in range(1, k_max + 1)])


def occlusion_summary(visibility, oracle) -> dict:
    """How hard a plant is to see from a view space: the oracle voxels, the share of them seen
    by exactly one view and by at most two (percent), the median number of views per oracle voxel
    and the number of forced views (:func:`forced_views`)."""
    counts = views_per_voxel(visibility, oracle)
    n = max(len(counts), 1)
    return {"oracle_voxels": int(len(counts)), "only_1_view_pct": 100 * int((counts == 1).sum()) / n,
            "at_most_2_views_pct": 100 * int((counts <= 2).sum()) / n,
            "median_views": float(np.median(counts)) if len(counts) else 0.0,
            "forced_views": int(len(forced_views(visibility, oracle)))}


@dataclass(frozen=True, eq=False)
class Showcase:
    """One case planned by Ours: the case, its configuration, its scene and the result."""

    case: object  # tpvp.experiments.plants.Case
    config: object  # PlantConfig of the case
    scene: object  # tpvp.experiments.single_plant.Scene
    result: object  # tpvp.experiments.single_plant.CaseResult

    @property
    def order(self) -> list:
        """Every executed view in execution order: initial, warm-up, planned."""
        return self.result.order

    @property
    def label(self) -> str:
        return f"{self.case.instance.species} ({self.case.view_space})"


def showcase(case, base_config=None) -> Showcase:
    """Build ``case``'s scene (``tpvp.experiments.plants.Case``) and plan it with Ours."""
    from tpvp.config import make_config
    from tpvp.experiments.single_plant import build_scene, run_case

    config = case.config(base_config or make_config("plant"))
    name = case.instance.name
    scene = build_scene(*case.instance.load(), config, names=(f"{name} previous", f"{name} current"))
    return Showcase(case, config, scene, run_case(scene, config))


def plan_row(item: Showcase, optimum: bool = True) -> dict:
    """One row about a showcase plan: species, view space, what Ours did (views, of them planned,
    coverage after the warm-up and at the end in percent, path length), the occlusion summary and,
    with ``optimum``, the fewest views that see 100 % of the oracle set with perfect knowledge of
    today's plant (same initial view; ``tpvp.experiments.baselines.optimum``)."""
    result = item.result
    row = {"species": item.case.instance.species, "view_space": item.case.view_space,
           "ours_views": result.n_views, "ours_planned_views": len(result.planned_views),
           "coverage_after_warm_up_pct": 100 * result.coverage_warm_up, "ours_coverage_pct": 100 * result.coverage,
           "path_length_m": result.path_length, **occlusion_summary(item.scene.truth_visibility, item.scene.oracle)}
    if optimum:
        from tpvp.experiments.baselines import optimum as exact

        row["optimum_views_100pct"] = int(exact(item.scene, item.config, targets=(1.0,))["views"].iloc[0])
    return row
