"""Chamfer distance and F-score (precision, recall, F1) between point clouds, via KD-trees."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from tpvp.errors import ConfigError, checked_cloud


def nearest_distances(source, target) -> np.ndarray:
    """Distance from every source point to its nearest target point."""
    return cKDTree(checked_cloud(target, "target cloud")).query(checked_cloud(source, "source cloud"), workers=-1)[0]


def chamfer_distance(a, b) -> float:
    """Symmetric Chamfer distance: mean of both directed mean nearest-neighbour distances (metres).

    This is the convention of the paper's tables (mm there); the registration loss uses squared
    distances instead.
    """
    return 0.5 * (nearest_distances(a, b).mean() + nearest_distances(b, a).mean())


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
    precision = float((nearest_distances(reconstruction, ground_truth) <= threshold).mean())
    recall = float((nearest_distances(ground_truth, reconstruction) <= threshold).mean())
    f1 = 0.0 if precision + recall == 0 else 2 * precision * recall / (precision + recall)
    return FScore(precision, recall, f1)
