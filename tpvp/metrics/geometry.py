"""Chamfer distance and F-score (precision, recall, F1) between point clouds, via KD-trees."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from tpvp.errors import ConfigError, checked_cloud


def nearest_distances(source, target) -> np.ndarray:
    """Distance from every source point to its nearest target point. ``target``: an ``(M, 3)`` array
    or a prebuilt ``cKDTree`` of it (to query one large cloud many times without rebuilding it)."""
    tree = target if isinstance(target, cKDTree) else cKDTree(checked_cloud(target, "target cloud"))
    return tree.query(checked_cloud(source, "source cloud"), workers=-1)[0]


def chamfer_from_distances(a_to_b, b_to_a) -> float:
    """Symmetric Chamfer distance from the two directed nearest-neighbour distance arrays."""
    return 0.5 * (np.asarray(a_to_b).mean() + np.asarray(b_to_a).mean())


def chamfer_distance(a, b) -> float:
    """Symmetric Chamfer distance: mean of both directed mean nearest-neighbour distances (metres).

    This is the convention of the paper's tables (mm there); the registration loss uses squared
    distances instead.
    """
    return chamfer_from_distances(nearest_distances(a, b), nearest_distances(b, a))


@dataclass(frozen=True)
class FScore:
    precision: float
    recall: float
    f1: float


def f_score(reconstruction, ground_truth, threshold: float) -> FScore:
    """Precision = share of reconstructed points within ``threshold`` of the ground truth; recall the
    converse; F1 their harmonic mean."""
    if not threshold > 0:
        raise ConfigError(f"F-score threshold must be > 0 m, got {threshold!r}")
    return f_score_from_distances(nearest_distances(reconstruction, ground_truth),
                                  nearest_distances(ground_truth, reconstruction), threshold)


def f_score_from_distances(to_truth, to_reconstruction, threshold: float) -> FScore:
    """:func:`f_score` from the directed distances (reconstruction -> truth, truth -> reconstruction),
    to score several thresholds with one pair of nearest-neighbour searches."""
    precision = float((np.asarray(to_truth) <= threshold).mean())
    recall = float((np.asarray(to_reconstruction) <= threshold).mean())
    f1 = 0.0 if precision + recall == 0 else 2 * precision * recall / (precision + recall)
    return FScore(precision, recall, f1)
