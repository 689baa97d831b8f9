"""Geometric fidelity metrics between reconstructions and ground truth."""

from tpvp.metrics.geometry import chamfer_distance, f_score  # noqa: F401
from tpvp.visibility.matrix import coverage_ratio  # noqa: F401
