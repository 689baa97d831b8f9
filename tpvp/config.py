"""One configuration per setting: every stage's parameters, the paper's values as defaults.

:class:`PlantConfig` (individual plants) and :class:`RowConfig` (greenhouse rows) compose the
stages' own frozen dataclasses, each of which lives in its package's light ``config`` module
(``tpvp.scene.config``, ``tpvp.sensor.config``, ``tpvp.nbv.config``, ``tpvp.registration.config``,
``tpvp.inflation.config``, ``tpvp.setcover.config``, ``tpvp.path.config``,
``tpvp.viewspace.config``); this module imports no stage implementation and no registry. The
protocol sections of the row experiments (:class:`RowProtocolConfig`, :class:`PoseNoiseConfig`)
live here. Building, deriving, checking method names against their registries, reading and writing
configurations is :mod:`tpvp.config_loading` (:func:`~tpvp.config_loading.make_config`,
:func:`~tpvp.config_loading.load_config`, :func:`~tpvp.config_loading.config_yaml`).

The named configuration ``paper`` (and ``paper-row``) is the one behind every reproduced table;
new methods are added beside it and chosen by name, never swapped into it silently.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from tpvp.configuration_checks import check_integer, check_positive
from tpvp.errors import ConfigError
from tpvp.inflation.config import InflationConfig, SurfaceWeightsConfig
from tpvp.nbv.config import BlockwiseNbvConfig, GmcConfig, NbvConfig
from tpvp.path.config import TspConfig
from tpvp.registration.config import EDConfig, RegistrationConfig, WarpFieldConfig
from tpvp.scene.config import SceneConfig
from tpvp.sensor.config import ROW_RANGE, SensorConfig
from tpvp.setcover.config import SelectionConfig
from tpvp.viewspace.config import RowTargetsConfig

COARSE_POINTS = ("centroids", "centres")  # what an observed voxel adds to a row's passive reconstruction
PAPER_NOISE_LEVELS = ((0.0, 0.0), (0.002, 0.5), (0.005, 1.0), (0.01, 2.0))  # Table VII: (sigma_t m, sigma_r deg)
ICP_METHODS = ("point_to_plane", "point_to_point")


class _ResolvedViewSpace:
    """A setting's view space as an object (``space``), resolved from its name or file once per
    configuration: when the configuration is made (:mod:`tpvp.config_loading`), or at first use
    for one made by hand or by ``dataclasses.replace``."""

    @property
    def space(self):
        space = self.__dict__.get("_space")
        if space is None:
            from tpvp.viewspace.space import get_view_space  # a view space is resolved at load, not at import

            space = get_view_space(self.view_space)
            object.__setattr__(self, "_space", space)  # a cache beside the fields: not compared, not written
        return space


@dataclass(frozen=True)
class PlantConfig(_ResolvedViewSpace):
    """Individual-plant setting (the paper's Tables I-IV); defaults = the ``paper`` configuration.

    gt_resolution: ground-truth voxel (m); derived resolutions follow it (docs/configuration.md).
    initial_view: an index of the view space or one of its named initial views.
    seed: the run's random seed (registration subsets).
    """

    name: str = "paper"
    seed: int = 0
    gt_resolution: float = 0.002
    view_space: str = "hemisphere"
    initial_view: int | str = 17
    scene: SceneConfig = field(default_factory=SceneConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    nbv: NbvConfig = field(default_factory=NbvConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    inflation: InflationConfig = field(default_factory=InflationConfig)
    selection: SelectionConfig = field(default_factory=SelectionConfig)
    # Class weights of the planning surface for a coverage target below 1 (ignored at 1.0).
    surface_weights: SurfaceWeightsConfig = field(default_factory=SurfaceWeightsConfig)
    path: TspConfig = field(default_factory=TspConfig)
    gmc: GmcConfig = field(default_factory=GmcConfig)

    setting = "plant"

    def __post_init__(self):
        check_positive(self, "gt_resolution")
        check_integer(self, "seed", minimum=0)
        if not isinstance(self.initial_view, (int, str)) or isinstance(self.initial_view, bool):
            raise ConfigError(f"initial_view must be a view index or a named initial view, got {self.initial_view!r}")

    @property
    def uses_table(self) -> bool:
        """Whether the scene has a table: ``scene.table`` if set, else the view space's choice."""
        if self.scene.table is not None:
            return bool(self.scene.table)
        return self.space.table


@dataclass(frozen=True)
class RowProtocolConfig:
    """What the row experiments sweep (Tables V-VI): Ours' covering voxels (m), the random
    baselines' budgets and repetitions, Block-wise NBV's budgets and how they are run
    (``nbv_runs``: ``separate``, one run per budget, the paper's protocol: a run spreads its budget
    over the row's blocks; ``prefix``, the first views of one run of the largest budget)."""

    cover_resolutions: tuple = (0.10, 0.05, 0.04, 0.03)
    budgets: tuple = (100, 300, 500)
    repetitions: int = 5
    nbv_budgets: tuple = (100, 300, 500)
    nbv_runs: str = "separate"

    def __post_init__(self):
        check_integer(self, "repetitions", minimum=1)
        if self.nbv_runs not in ("separate", "prefix"):
            raise ConfigError(f"protocol.nbv_runs must be separate or prefix, got {self.nbv_runs!r}")
        for name, kind in (("cover_resolutions", float), ("budgets", int), ("nbv_budgets", int)):
            values = tuple(getattr(self, name))
            if not values or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0
                                 or (kind is int and v != int(v)) for v in values):
                raise ConfigError(f"{name} must be one or more positive {'integers' if kind is int else 'numbers'}, "
                                  f"got {getattr(self, name)!r}")
            object.__setattr__(self, name, tuple(kind(v) for v in values))


@dataclass(frozen=True)
class PoseNoiseConfig:
    """The pose-noise study of Table VII (docs/greenhouse.md, :mod:`tpvp.experiments.pose_noise`,
    whose module doc gives the protocol); defaults are the paper's.

    cover_resolution: the covering voxel of the plan of Ours whose views are perturbed (4 cm).
    levels: (sigma_t in m, sigma_r in deg) pairs. draws: noise draws per noisy level (the
    noise-free level is evaluated once). taus: F-score thresholds (m). fusion_voxel: the
    de-duplication grid of the fused cloud (m). icp: evaluate without and/or with ICP refinement.
    icp_voxel: downsampling of source view and passive target (m). icp_max_correspondence: one ICP
    stage per distance (m), coarse to fine. icp_max_iterations: per stage. icp_min_fitness: accept
    a refinement only at or above this final-stage fitness.
    """

    cover_resolution: float = 0.04
    levels: tuple = PAPER_NOISE_LEVELS
    draws: int = 5
    seed: int = 0
    taus: tuple = (0.01, 0.02)
    fusion_voxel: float = 0.002
    icp: tuple = (False, True)
    icp_method: str = "point_to_plane"
    icp_voxel: float = 0.01
    icp_max_correspondence: tuple = (0.05, 0.02, 0.01)
    icp_max_iterations: int = 10
    icp_min_fitness: float = 0.3

    def __post_init__(self):
        check_positive(self, "cover_resolution")
        try:
            levels = tuple((float(t), float(r)) for t, r in self.levels)
        except (TypeError, ValueError):
            raise ConfigError(f"levels must be (sigma_t, sigma_r) pairs, got {self.levels!r}") from None
        if not levels or any(not (math.isfinite(t) and math.isfinite(r) and t >= 0 and r >= 0) for t, r in levels):
            raise ConfigError(f"levels must be non-negative finite (sigma_t m, sigma_r deg) pairs, got {self.levels!r}")
        if len(set(levels)) != len(levels):
            raise ConfigError(f"levels must be distinct, got {self.levels!r}")
        object.__setattr__(self, "levels", levels)
        taus = tuple(float(t) for t in np.atleast_1d(self.taus))
        if not taus or any(not (math.isfinite(t) and t > 0) for t in taus):
            raise ConfigError(f"taus must be positive distances (m), got {self.taus!r}")
        object.__setattr__(self, "taus", taus)
        icp = tuple(bool(x) for x in np.atleast_1d(self.icp))
        if not icp or len(set(icp)) != len(icp):
            raise ConfigError(f"icp must list False and/or True once each, got {self.icp!r}")
        object.__setattr__(self, "icp", icp)
        for name, low in (("draws", 1), ("icp_max_iterations", 1), ("seed", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise ConfigError(f"{name} must be an integer >= {low}, got {value!r}")
        try:
            stages = tuple(float(d) for d in np.atleast_1d(self.icp_max_correspondence))
        except (TypeError, ValueError):
            stages = ()
        if not stages or any(not (math.isfinite(d) and d > 0) for d in stages):
            raise ConfigError("icp_max_correspondence must be one or more positive distances (m), "
                              f"got {self.icp_max_correspondence!r}")
        object.__setattr__(self, "icp_max_correspondence", stages)
        for name in ("fusion_voxel", "icp_voxel"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ConfigError(f"{name} must be a positive number of metres, got {value!r}")
        if not (isinstance(self.icp_min_fitness, (int, float)) and 0.0 <= self.icp_min_fitness <= 1.0):
            raise ConfigError(f"icp_min_fitness must be in [0, 1], got {self.icp_min_fitness!r}")
        if self.icp_method not in ICP_METHODS:
            raise ConfigError(f"unknown icp_method {self.icp_method!r}; choose one of {', '.join(ICP_METHODS)}")


@dataclass(frozen=True)
class RowConfig(_ResolvedViewSpace):
    """Greenhouse-row setting (the paper's Tables V-VII); defaults = the ``paper-row`` configuration.

    view_space: the room (``room1``, ``room4``; its boxes, candidate positions and passive sweep
    are :func:`tpvp.scene.boxes.room_config`). oracle_grid: spacing of the view-box grid of the
    FOV-free oracle (10 x gt_resolution). The registration section holds the row's control-node
    spacing (0.15 m, not derived) and searches the warp field's correspondences from the partial
    coarse scan onto the previous session (``coarse-to-previous``, not the authors'
    ``previous-to-coarse``: docs/greenhouse.md#registration). protocol: what the experiments sweep (Tables V-VI);
    pose_noise: the Table VII study; blockwise: the Block-wise NBV baseline. coarse: what an
    observed voxel adds to the passive reconstruction Q: ``centroids`` (the points seen in it,
    reduced to their centroid, as the authors' reference is) or ``centres`` (its centre: all a depth
    image of the simulator's voxel geometry can give, see ``tpvp session``). candidates: where Ours'
    candidate views look (a look-at prior of :data:`tpvp.viewspace.priors.LOOK_AT_PRIORS`; the
    paper's ``transfer``); route: how the selected views are ordered
    (:data:`tpvp.path.route.ROW_ROUTES`; the paper's ``band``).
    """

    name: str = "paper-row"
    seed: int = 0
    gt_resolution: float = 0.01
    view_space: str = "room1"
    oracle_grid: float = 0.1
    sensor: SensorConfig = field(default_factory=lambda: SensorConfig(max_range=ROW_RANGE))
    nbv: NbvConfig = field(default_factory=lambda: NbvConfig(pixel_stride=20))
    registration: RegistrationConfig = field(
        default_factory=lambda: RegistrationConfig(
            method="warp-field", embedded_deformation=EDConfig(node_coverage=0.15),
            warp_field=WarpFieldConfig(correspondences="coarse-to-previous")))
    inflation: InflationConfig = field(default_factory=lambda: InflationConfig(0.01, 0.01, 0.01))
    selection: SelectionConfig = field(default_factory=lambda: SelectionConfig(cover_resolution=0.04))
    targets: RowTargetsConfig = field(default_factory=RowTargetsConfig)
    path: TspConfig = field(default_factory=TspConfig)
    protocol: RowProtocolConfig = field(default_factory=RowProtocolConfig)
    pose_noise: PoseNoiseConfig = field(default_factory=PoseNoiseConfig)
    blockwise: BlockwiseNbvConfig = field(default_factory=BlockwiseNbvConfig)
    coarse: str = "centroids"
    candidates: str = "transfer"
    route: str = "band"

    setting = "row"

    def __post_init__(self):
        check_positive(self, "gt_resolution", "oracle_grid")
        check_integer(self, "seed", minimum=0)
        if self.coarse not in COARSE_POINTS:
            raise ConfigError(f"coarse must be one of {', '.join(COARSE_POINTS)}, got {self.coarse!r}")
        if self.selection.replan_after:
            raise ConfigError(f"selection.replan_after={self.selection.replan_after}: re-planning from the captures "
                              f"is for single plants; a row is planned once (0)")
        if self.selection.organ_targets:
            raise ConfigError(f"selection.organ_targets={self.selection.organ_targets!r}: organ targets need a plant's "
                              f"organ labels; a row has none (leave it empty)")
