"""How likely each planning voxel is to be real today: a class per voxel of the planning surface
P~ u Q u I, and a weight per class for the partial cover of a coverage target below 1
(docs/cli.md#asking-for-a-coverage-level).

Classes, in the order that claims a voxel:

0. observed: the voxel holds a point of the coarse reconstruction Q (seen today by an executed view);
1. transferred near: it holds a point of the aligned previous session P~ (and none of Q), and its
   centre lies within ``near_voxels`` planning voxels of Q;
2. transferred far: the same, farther from Q (the registration extrapolates there);
3. inflation: only growth-allowance points I (no point of Q or P~).

The full set cover (coverage target 1) ignores weights: the paper's results do not depend on them.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from tpvp.errors import ConfigError, checked_cloud
from tpvp.inflation.config import SurfaceWeightsConfig
from tpvp.scene import voxels

SURFACE_CLASSES = ("observed", "transferred near", "transferred far", "inflation")


def surface_classes(keys, resolution: float, warped, coarse, near: float) -> np.ndarray:
    """The class (index into :data:`SURFACE_CLASSES`) of each planning voxel.

    ``keys``: (n, 3) integer keys of the planning voxels at ``resolution`` (m), e.g. the planning
    grid's ``keys``. ``warped``: the aligned previous session P~; ``coarse``: the coarse
    reconstruction Q (both (k, 3), m). ``near``: the distance (m) from a voxel's centre to the
    nearest Q point within which a transferred voxel is "near". Returns (n,) int8.
    """
    keys = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
    coarse = checked_cloud(coarse, "coarse reconstruction Q")
    warped = np.asarray(warped, dtype=np.float64).reshape(-1, 3)
    if not (np.isfinite(near) and near > 0):
        raise ConfigError(f"near must be a positive distance in metres, got {near!r}")
    observed = voxels.contains_keys(voxels.voxelise(coarse, resolution), keys)
    transferred = (voxels.contains_keys(voxels.voxelise(warped, resolution), keys) if len(warped)
                   else np.zeros(len(keys), dtype=bool))
    classes = np.full(len(keys), 3, dtype=np.int8)
    classes[transferred] = 2
    pending = transferred & ~observed
    if pending.any():
        # The bound lets the KD-tree prune; the test decides (inf beyond the bound counts as far).
        distance = cKDTree(coarse).query(voxels.key_centres(keys[pending], resolution), distance_upper_bound=2 * near)[0]
        classes[np.flatnonzero(pending)[distance <= near]] = 1
    classes[observed] = 0
    return classes


def surface_area(keys, resolution: float, cloud, subdivisions: int = 2) -> np.ndarray:
    """How much surface each planning voxel stands for: the number of sub-voxels (``resolution /
    subdivisions``) that ``cloud`` occupies inside it, at least 1 (a voxel of the planning grid
    holds a point of the cloud). ``keys``: (n, 3) planning voxel keys at ``resolution``. (n,) int64."""
    keys = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
    if isinstance(subdivisions, bool) or not isinstance(subdivisions, (int, np.integer)) or subdivisions < 1:
        raise ConfigError(f"subdivisions must be an integer >= 1, got {subdivisions!r}")
    cloud = checked_cloud(cloud, "planning cloud")
    sub = voxels.voxelise(cloud, resolution / subdivisions)
    parents, counts = voxels.unique_keys(np.floor_divide(sub, subdivisions), return_counts=True)
    area = np.ones(len(keys), dtype=np.int64)
    if len(keys):
        codes = voxels.encode_keys(parents)
        wanted = voxels.encode_keys(keys)
        at = np.searchsorted(codes, wanted)  # unique_keys returns the keys in code order
        found = (at < len(codes)) & (codes[np.minimum(at, len(codes) - 1)] == wanted)
        area[found] = np.maximum(counts[at[found]], 1)
    return area


def surface_weights(classes, config: SurfaceWeightsConfig, area=None) -> np.ndarray | None:
    """The weight of each planning voxel from its class (:func:`surface_classes`), times its
    ``area`` (:func:`surface_area`) when ``config.area``; None when ``config.enabled`` is False
    (the unweighted surface)."""
    if not isinstance(config, SurfaceWeightsConfig):
        raise ConfigError(f"config must be a SurfaceWeightsConfig, got {type(config).__name__}")
    if not config.enabled:
        return None
    classes = np.asarray(classes)
    if classes.size and (classes.min() < 0 or classes.max() >= len(SURFACE_CLASSES)):
        raise ConfigError(f"surface classes must be in 0..{len(SURFACE_CLASSES) - 1}")
    weights = config.class_weights[classes.astype(np.int64)]
    if config.area:
        if area is None or np.shape(area) != classes.shape:
            raise ConfigError("surface_weights.area needs the area of every planning voxel")
        weights = weights * np.asarray(area, dtype=np.float64)
    return weights
