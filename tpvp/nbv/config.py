"""The next-best-view stage's configuration (``nbv`` and its occupancy ``map``, the GMC baseline's
``gmc``, the rows' ``blockwise``), light: no kernel or registry is imported with it; the method
name is checked against :data:`tpvp.nbv.methods.NBV_METHODS` when a configuration is loaded."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from tpvp.configuration_checks import check_integer, check_positive
from tpvp.errors import ConfigError


@dataclass(frozen=True)
class OccupancyMapConfig:
    """Map geometry (defaults: docs/single_plant.md#occupancy-map). ``resolution``: a fixed voxel
    size (m) instead of ``2 * predicted_size / voxels_across`` (None, the default; the GMC baseline
    sets it, :class:`tpvp.nbv.config.GmcConfig`)."""

    voxels_across: int = 32  # voxel = 2 * predicted_size / voxels_across
    size_factor: float = 17 / 16  # predicted_size = size_factor * max distance centre -> point
    padding: int = 1  # voxels added on every side of the cube centre +- predicted_size
    resolution: float | None = None  # fixed voxel (m); None: 2 * predicted_size / voxels_across

    def __post_init__(self):
        if self.resolution is not None and not (isinstance(self.resolution, (int, float))
                                                and not isinstance(self.resolution, bool)
                                                and math.isfinite(self.resolution) and self.resolution > 0):
            raise ConfigError(f"resolution must be a voxel size > 0 m or None, got {self.resolution!r}")
        if int(self.voxels_across) < 1:
            raise ConfigError(f"voxels_across must be a positive integer, got {self.voxels_across!r}")
        if not (self.size_factor > 0):
            raise ConfigError(f"size_factor must be > 0, got {self.size_factor!r}")
        if int(self.padding) < 0:
            raise ConfigError(f"padding must be >= 0 voxels, got {self.padding!r}")


@dataclass(frozen=True)
class NbvConfig:
    """The warm-up next-best view. method: a name of :data:`tpvp.nbv.methods.NBV_METHODS`.
    warm_up_views: NBVs after the initial view (the paper: 1). pixel_stride: information-gain rays
    every n-th pixel in u and v (4 for plants, 20 for rows). map: the occupancy map of what was
    observed (voxel = 2 x predicted size / map.voxels_across)."""

    method: str = "geometric"
    warm_up_views: int = 1
    pixel_stride: int = 4
    map: OccupancyMapConfig = field(default_factory=OccupancyMapConfig)

    def __post_init__(self):
        check_integer(self, "warm_up_views", minimum=0)
        check_integer(self, "pixel_stride", minimum=1)


TIE_BREAKS = ("shortest-move", "lowest-index")


@dataclass(frozen=True)
class GmcConfig:
    """The GMC baseline (the sequential NBV curve of Table I, :func:`tpvp.experiments.baselines.nbv_curve`;
    docs/experiments.md#gmc). Its NBV method and pixel stride are ``nbv``'s; these settings are its own.

    map_resolution: voxel (m) of GMC's occupancy map; derived: 1 x gt_resolution (0.002 m). The
    authors' GMC maps at ``ground_truth_resolution x voxel_resolution_factor`` = 2 x gt_resolution =
    0.004 m, but in OctoMap's probabilistic map, where a voxel both hit and passed through stays
    unknown; in this three-state map every candidate's gain is 0 after 4-6 views at 4 mm, and stays
    positive until 13-17 views at the ground-truth voxel (docs/deviations.md, benchmarks/gmc_gain.py).
    None: ``nbv.map``'s rule, 32 voxels across the plant (about 9 mm on a tomato; every gain 0 after
    3-4 views), the warm-up's map.
    tie_break: among the candidates that share the largest gain, ``shortest-move`` takes the one of
    shortest sphere-avoiding local path from the current view (the authors' ``view_utility_compare``:
    equal utility, smaller ``robot_cost``), then the lowest index; ``lowest-index`` takes the lowest index.
    """

    map_resolution: float | None = 0.002
    tie_break: str = "shortest-move"

    def __post_init__(self):
        if self.map_resolution is not None:
            check_positive(self, "map_resolution")
        if self.tie_break not in TIE_BREAKS:
            raise ConfigError(f"gmc.tie_break must be one of {', '.join(TIE_BREAKS)}, got {self.tie_break!r}")


@dataclass(frozen=True)
class BlockwiseNbvConfig:
    """Parameters of the block-wise NBV (defaults: the paper's row setting, see the module doc)."""

    blocks_along: int = 5  # segments along the row (view-box local x)
    bands: int = 2  # height bands (view-box local z)
    look_ats_per_block: int = 50  # frontier targets sampled per NBV step
    map_resolution: float = 0.05  # m, occupancy map voxel
    pixel_stride: int = 20  # gain rays: every n-th pixel in u and v
    target_margin: float | None = 0.5  # m, block region for targets: segment and band grown by this
    plan_views: int | None = 500  # block quotas from this planned length (None: from the budget)
    carve_pixels: bool = True  # carve free space along pixel rays without a return

    def __post_init__(self):
        for name in ("blocks_along", "bands", "look_ats_per_block", "pixel_stride"):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or int(value) < 1:
                raise ConfigError(f"{name} must be a positive integer, got {value!r}")
        if not (np.isfinite(self.map_resolution) and self.map_resolution > 0):
            raise ConfigError(f"map_resolution must be > 0 m, got {self.map_resolution!r}")
        if self.target_margin is not None and not (np.isfinite(self.target_margin) and self.target_margin >= 0):
            raise ConfigError(f"target_margin must be >= 0 m or None, got {self.target_margin!r}")
        if self.plan_views is not None and (isinstance(self.plan_views, bool) or int(self.plan_views) != self.plan_views
                                            or int(self.plan_views) < 1):
            raise ConfigError(f"plan_views must be a positive integer or None, got {self.plan_views!r}")

    @property
    def n_blocks(self) -> int:
        return int(self.blocks_along) * int(self.bands)
