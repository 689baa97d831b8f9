"""How a scene's candidate views see its voxels: views per voxel, the coverage curve of a view
order, the step at which each voxel is first seen, forced views, and an occlusion summary.

Each function takes a visibility matrix ``visibility`` (sparse ``(views x voxels)``, entry
``(v, j)`` non-zero when view ``v`` observes voxel ``j``, e.g. ``Scene.truth_visibility``) and,
where it matters, the oracle set ``oracle`` (the voxels some candidate view sees).
"""

from __future__ import annotations

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
