"""One configuration per setting: every stage's parameters, the paper's values as defaults.

:class:`PlantConfig` (individual plants) and :class:`RowConfig` (greenhouse rows) nest the stages'
own frozen dataclasses. Resolutions that the authors' YAML derives from the ground-truth resolution
are derived here the same way, in one place (:data:`DERIVED`, documented in
``docs/configuration.md``): a derived key that the user does not set follows ``gt_resolution``; a
key the user sets wins. Build configurations with :func:`make_config` (Python keywords or dotted
``key=value`` overrides) or :func:`load_config` (a YAML file or a named configuration); write the
resolved configuration with :func:`config_yaml` so any result can be re-run exactly.

The named configuration ``paper`` (and ``paper-row``) is the one behind every reproduced table;
new methods are added beside it and chosen by name, never swapped into it silently.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tpvp.errors import ConfigError, InputFileError
from tpvp.inflation import InflationConfig
from tpvp.inflation.weights import SurfaceWeightsConfig
from tpvp.nbv import OccupancyMapConfig
from tpvp.nbv.blockwise import BlockwiseNbvConfig
from tpvp.nbv.methods import NBV_METHODS
from tpvp.path.route import ROW_ROUTES
from tpvp.path.tsp import TspConfig
from tpvp.registration import EDConfig
from tpvp.registration.methods import REGISTRATION_METHODS
from tpvp.registration.warp_field import WarpFieldConfig
from tpvp.scene.organs import ORGANS
from tpvp.sensor.sensor import ROW_RANGE, SensorConfig
from tpvp.setcover import SetCoverConfig
from tpvp.setcover.methods import SELECTION_METHODS
from tpvp.viewspace import get_view_space
from tpvp.viewspace.priors import LOOK_AT_PRIORS

SCALES = ("normalised", "native")
UP_AXES = ("+z", "-z", "+y", "-y", "+x", "-x")
FRAMES = ("current", "previous")  # the scan that defines the planning frame
COARSE_POINTS = ("centroids", "centres")  # what an observed voxel adds to a row's passive reconstruction
PAPER_NOISE_LEVELS = ((0.0, 0.0), (0.002, 0.5), (0.005, 1.0), (0.01, 2.0))  # Table VII: (sigma_t m, sigma_r deg)
ICP_METHODS = ("point_to_plane", "point_to_point")


@dataclass(frozen=True)
class SceneConfig:
    """How a scan becomes the simulator's scene (docs/single_plant.md#normalisation).

    scale: ``normalised`` (the paper's protocol: the plant scaled to ``largest_side``) or
    ``native`` (the plant keeps its size; ``radius`` is the view-sphere radius in the scan's metres
    and every resolution scales with the plant, see docs/configuration.md#native-scale).
    radius: view-sphere radius; None keeps the view space's own (0.4 m) in normalised mode and means
    0.4 m around the real plant in native mode. table: None = the view space's choice.
    up_axis: the scan axis that points up; the plant is turned so that it becomes +Z.
    frame: the scan that defines the planning frame (scale, centre, table): ``current`` (the
    paper's protocol: today's full scan) or ``previous`` (the previous session's model: all a real
    session has before planning, see ``tpvp session``).
    reduce_above / reduce_resolution: scans with more points are reduced to voxel centroids at
    ``reduce_resolution`` (planning frame; half the ground-truth voxel, so the ground truth
    is unchanged) before anything else. min_plant_voxels: fewer occupied ground-truth voxels than
    this is not a plant scan (the bundled tomato has 3,890).
    """

    largest_side: float = 0.24
    rotation_deg: float = 0.0
    centre: str = "bbox"
    table: bool | None = None
    table_size: float = 0.4
    table_resolution: float = 0.002
    scale: str = "normalised"
    radius: float | None = None
    up_axis: str = "+z"
    frame: str = "current"
    reduce_above: int = 1_000_000
    reduce_resolution: float = 0.001
    min_plant_voxels: int = 100

    def __post_init__(self):
        _positive(self, "largest_side", "table_size", "table_resolution", "reduce_resolution")
        _integer(self, "reduce_above", minimum=1)
        _integer(self, "min_plant_voxels", minimum=1)
        if self.radius is not None:
            _positive(self, "radius")
        if self.centre not in ("bbox", "centroid"):
            raise ConfigError(f"scene.centre must be 'bbox' or 'centroid', got {self.centre!r}")
        if self.scale not in SCALES:
            raise ConfigError(f"scene.scale must be one of {', '.join(SCALES)}, got {self.scale!r}")
        if self.up_axis not in UP_AXES:
            raise ConfigError(f"scene.up_axis must be one of {', '.join(UP_AXES)}, got {self.up_axis!r}")
        if self.frame not in FRAMES:
            raise ConfigError(f"scene.frame must be one of {', '.join(FRAMES)}, got {self.frame!r}")


@dataclass(frozen=True)
class NbvConfig:
    """The warm-up next-best view. method: a name of :data:`tpvp.nbv.NBV_METHODS`.
    warm_up_views: NBVs after the initial view (the paper: 1). pixel_stride: information-gain rays
    every n-th pixel in u and v (4 for plants, 20 for rows). map: the occupancy map of what was
    observed (voxel = 2 x predicted size / map.voxels_across)."""

    method: str = "geometric"
    warm_up_views: int = 1
    pixel_stride: int = 4
    map: OccupancyMapConfig = field(default_factory=OccupancyMapConfig)

    def __post_init__(self):
        _integer(self, "warm_up_views", minimum=0)
        _integer(self, "pixel_stride", minimum=1)


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
            _positive(self, "map_resolution")
        if self.tie_break not in TIE_BREAKS:
            raise ConfigError(f"gmc.tie_break must be one of {', '.join(TIE_BREAKS)}, got {self.tie_break!r}")


@dataclass(frozen=True)
class RegistrationConfig:
    """Alignment of the previous session onto the coarse reconstruction. method: a name of
    :data:`tpvp.registration.methods.REGISTRATION_METHODS`; each method reads its own section.
    warn_chamfer_fraction: warn when the aligned previous session stays farther than this fraction
    of the plant's size from the coarse scan (Chamfer): a matching pair ends near 0.5 %."""

    method: str = "embedded-deformation"
    embedded_deformation: EDConfig = field(default_factory=EDConfig)
    warp_field: WarpFieldConfig = field(default_factory=WarpFieldConfig)
    warn_chamfer_fraction: float = 0.03

    def __post_init__(self):
        _positive(self, "warn_chamfer_fraction")


# Share of a coverage target's allowance (1 - target) that the plan may leave uncovered on the
# *predicted* planning surface, per view space: planning target = 1 - ratio x (1 - target).
# Calibrated on generated pairs of seeds 10-12 (never the evaluation seeds 0-2) for a 98 % request:
# the largest ratio whose mean true coverage reaches it with no case more than one point below,
# with either warm-up NBV (geometric or prior). Other view spaces (the greenhouse rooms, view-space
# files) take the smallest, the most cautious: not calibrated there. docs/cli.md, "Asking for a
# coverage level"; benchmarks/coverage_target_calibration.py. The weighted surface of a plant
# (PlantConfig.surface_weights, off by default) was calibrated with the same ratios.
CALIBRATED_MISS_RATIO = {"hemisphere": 0.5, "sphere": 0.25}
# The same ratio for a plan that is re-planned from its captures (selection.replan_after > 0): the
# captures correct the prediction, so the plan may leave more of it to them. Calibrated the same
# way (mean >= 98.1 %, no case below 97.1 %), on the same seeds 10-12, re-planning after every view,
# r in 0.25 ... 1: benchmarks/replanning.py --mode calibrate (results/replanning_calibrate.md).
CALIBRATED_REPLAN_MISS_RATIO = {"hemisphere": 0.75, "sphere": 0.75}


@dataclass(frozen=True)
class SelectionConfig:
    """View selection on the planning surface. method: a name of
    :data:`tpvp.setcover.SELECTION_METHODS`. cover_resolution: voxel of the planning surface (m).
    coverage_target: the true coverage of today's plant the plan aims for (1.0 = the paper's full
    set cover of the planning surface). planning_miss_ratio: the plan must see
    ``1 - planning_miss_ratio x (1 - coverage_target)`` of the planning surface (None: the
    calibrated ratio of the view space, :data:`CALIBRATED_MISS_RATIO`; 1: the target applies to the
    prediction as it is). replan_after: a plant's plan is re-planned from the captures after every
    this many planned views (:mod:`tpvp.pipeline.replan`; 0: the paper's one-shot plan).
    organ_targets: per-organ shares of the planning surface (:meth:`organ_target_values`);
    organ_margin_voxels: a named organ's share also holds the planning voxels within this many
    voxels of its predicted ones (organs grow between sessions and a fruit swells into what the
    registered prior labels leaf; 2: calibrated on Helios tomato and maize,
    benchmarks/species_calibration.py)."""

    method: str = "set-cover"
    cover_resolution: float = 0.004
    coverage_target: float = 1.0
    planning_miss_ratio: float | None = None
    replan_after: int = 0
    organ_targets: str = ""
    organ_margin_voxels: int = 2
    set_cover: SetCoverConfig = field(default_factory=SetCoverConfig)

    def __post_init__(self):
        _positive(self, "cover_resolution")
        _integer(self, "replan_after", minimum=0)
        _integer(self, "organ_margin_voxels", minimum=0)
        self.organ_target_values()  # one line now for a malformed organ_targets, not mid-run
        if not (isinstance(self.coverage_target, (int, float)) and 0 < self.coverage_target <= 1):
            raise ConfigError(f"selection.coverage_target must be in (0, 1], got {self.coverage_target!r}")
        if self.planning_miss_ratio is not None:
            _positive(self, "planning_miss_ratio")

    def organ_target_values(self) -> dict:
        """``organ_targets`` (``"fruit=1.0,leaf=0.95"``: organ classes of
        :data:`tpvp.scene.organs.ORGANS` and the share of each one's predicted planning voxels the
        selection must see) as a mapping; the organs it does not name keep the planning target."""
        values, given = {}, {}
        for item in filter(None, (part.strip() for part in str(self.organ_targets or "").split(","))):
            name, _, value = item.partition("=")
            name = name.strip()
            try:
                number = float(value)
            except ValueError:
                number = float("nan")
            if name not in ORGANS or not 0 <= number <= 1:
                raise ConfigError(f"selection.organ_targets: {item!r} is not ORGAN=SHARE with ORGAN one of "
                                  f"{', '.join(ORGANS)} and SHARE in [0, 1] (e.g. fruit=1.0,leaf=0.95)")
            if name in values:  # which share was meant is not ours to guess (the last one used to win)
                raise ConfigError(f"selection.organ_targets: {name!r} is given twice ({given[name]}, {item}); give "
                                  f"each organ one share (e.g. fruit=1.0,leaf=0.95)")
            values[name], given[name] = number, item
        return values

    def planning_target(self, view_space: str) -> float:
        """The fraction of the *predicted planning surface* the selected views must see in
        ``view_space`` for ``coverage_target`` of today's plant (resolved, never stored in
        ``coverage_target``): ``1 - r x (1 - coverage_target)``, of its voxels or of their weight
        (a plant's ``surface_weights``)."""
        if self.coverage_target >= 1.0:
            return 1.0
        ratio = self.planning_miss_ratio
        if ratio is None:
            calibrated = CALIBRATED_REPLAN_MISS_RATIO if self.replan_after else CALIBRATED_MISS_RATIO
            ratio = calibrated.get(view_space, min(calibrated.values()))
        target = 1.0 - ratio * (1.0 - self.coverage_target)
        if target <= 0:
            raise ConfigError(f"selection.planning_miss_ratio={ratio!r} with coverage_target="
                              f"{self.coverage_target!r} asks for {target:.3g} of the planning surface; "
                              f"it must stay above 0")
        return target


@dataclass(frozen=True)
class PlantConfig:
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
        _positive(self, "gt_resolution")
        _integer(self, "seed", minimum=0)
        if not isinstance(self.initial_view, (int, str)) or isinstance(self.initial_view, bool):
            raise ConfigError(f"initial_view must be a view index or a named initial view, got {self.initial_view!r}")

    @property
    def uses_table(self) -> bool:
        """Whether the scene has a table: ``scene.table`` if set, else the view space's choice."""
        if self.scene.table is not None:
            return bool(self.scene.table)

        return get_view_space(self.view_space).table


@dataclass(frozen=True)
class RowTargetsConfig:
    """Look-at targets of the greenhouse planner: ``count`` by farthest-point sampling, then each
    target takes its nearest unused candidate position, ``rounds`` times (docs/greenhouse.md)."""

    count: int = 100
    rounds: int = 8

    def __post_init__(self):
        _integer(self, "count", minimum=1)
        _integer(self, "rounds", minimum=1)


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
        _integer(self, "repetitions", minimum=1)
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
        _positive(self, "cover_resolution")
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
class RowConfig:
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
        _positive(self, "gt_resolution", "oracle_grid")
        _integer(self, "seed", minimum=0)
        if self.coarse not in COARSE_POINTS:
            raise ConfigError(f"coarse must be one of {', '.join(COARSE_POINTS)}, got {self.coarse!r}")
        LOOK_AT_PRIORS.get(self.candidates)  # one line naming the choices
        ROW_ROUTES.get(self.route)
        if self.selection.replan_after:
            raise ConfigError(f"selection.replan_after={self.selection.replan_after}: re-planning from the captures "
                              f"is for single plants; a row is planned once (0)")
        if self.selection.organ_targets:
            raise ConfigError(f"selection.organ_targets={self.selection.organ_targets!r}: organ targets need a plant's "
                              f"organ labels; a row has none (leave it empty)")


SETTINGS = {"plant": PlantConfig, "row": RowConfig}
NAMED = {"paper": ("plant", {}), "paper-row": ("row", {})}

# Derived parameters: key -> (rule in words, function of the raw settings). A key the user sets
# explicitly wins over its rule. docs/configuration.md has the same table with the authors' names.
DERIVED = {
    "plant": {
        "scene.table_resolution": ("1 x gt_resolution", lambda c: c["gt_resolution"]),
        "scene.reduce_resolution": ("gt_resolution / 2 (large scans only)", lambda c: c["gt_resolution"] / 2),
        "registration.embedded_deformation.node_coverage": ("2 x gt_resolution (nricp_resolution_factor)",
                                                            lambda c: 2 * c["gt_resolution"]),
        "registration.embedded_deformation.seed": ("seed", lambda c: c["seed"]),
        "inflation.step": ("2 x gt_resolution (inflation_resolution_factor)", lambda c: 2 * c["gt_resolution"]),
        "inflation.gamma_near": ("1.5 x gt_resolution (near_current_inflation_distance_factor)",
                                 lambda c: 1.5 * c["gt_resolution"]),
        "inflation.gamma_far": ("2.5 x gt_resolution (far_history_inflation_distance_factor)",
                                lambda c: 2.5 * c["gt_resolution"]),
        "selection.cover_resolution": ("2 x gt_resolution (history_resolution_factor)",
                                       lambda c: 2 * c["gt_resolution"]),
        "gmc.map_resolution": ("1 x gt_resolution (the authors: 2 x, probabilistic map; docs/deviations.md)",
                               lambda c: c["gt_resolution"]),
        "sensor.max_range": ("the view space's range (1.0 m plants)", lambda c: _view_space_range(c["view_space"])),
    },
    "row": {
        "oracle_grid": ("10 x gt_resolution", lambda c: 10 * c["gt_resolution"]),
        "registration.embedded_deformation.seed": ("seed", lambda c: c["seed"]),
        "registration.warp_field.voxel": ("1 x gt_resolution (clouds reduced to voxel centroids)",
                                          lambda c: c["gt_resolution"]),
        "inflation.step": ("1 x gt_resolution (voxel of the morphology)", lambda c: c["gt_resolution"]),
        "inflation.gamma_near": ("1 x gt_resolution", lambda c: c["gt_resolution"]),
        "inflation.gamma_far": ("1 x gt_resolution", lambda c: c["gt_resolution"]),
        "selection.cover_resolution": ("4 x gt_resolution (history_resolution_factor)",
                                       lambda c: 4 * c["gt_resolution"]),
        "sensor.max_range": (f"the view space's range ({ROW_RANGE} m rows)",
                             lambda c: _view_space_range(c["view_space"])),
        "pose_noise.seed": ("seed", lambda c: c["seed"]),
    },
}


def _view_space_range(spec) -> float:
    if not isinstance(spec, str):
        raise ConfigError(f"configuration key 'view_space': expected a name or a file path, got {spec!r}")
    try:
        return float(get_view_space(spec).max_range)
    except (ConfigError, InputFileError) as exc:
        raise ConfigError(f"configuration key 'view_space': {exc}") from None


def _positive(obj, *names):
    for name in names:
        v = getattr(obj, name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (v > 0 and v < float("inf")):
            raise ConfigError(f"{name} must be a positive number, got {v!r}")


def _integer(obj, name, minimum):
    v = getattr(obj, name)
    if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
        raise ConfigError(f"{name} must be an integer >= {minimum}, got {v!r}")


# --------------------------------------------------------------------------------------------------
# dataclass <-> nested dict
# --------------------------------------------------------------------------------------------------


def to_dict(config) -> dict:
    """Nested plain dict of a configuration (every value explicit)."""
    out = {}
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        out[f.name] = to_dict(value) if dataclasses.is_dataclass(value) else value
    return out


def flatten_keys(tree: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            flat.update(flatten_keys(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def _as_tuple(value) -> tuple:
    """A YAML list (of lists) as the tuple (of tuples) a frozen configuration holds."""
    return tuple(_as_tuple(v) if isinstance(v, (list, tuple)) else v for v in value)


def _coerce(key: str, value, hint):
    """``value`` checked against the field's type hint (int -> float allowed, ``X | None``, a list
    for a tuple; the section checks the tuple's items)."""
    options = typing.get_args(hint) if typing.get_origin(hint) in (typing.Union, types.UnionType) else (hint,)
    for option in options:
        if option is type(None) and value is None:
            return None
        if option is bool and isinstance(value, bool):
            return value
        if option is int and isinstance(value, int) and not isinstance(value, bool):
            return value
        if option is float and isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        if option is str and isinstance(value, str):
            return value
        if option is tuple and isinstance(value, (list, tuple)):
            return _as_tuple(value)
    words = {bool: "true or false", int: "an integer", float: "a number", str: "a string", type(None): "null",
             tuple: "a list"}
    expected = " or ".join(words.get(o, getattr(o, "__name__", str(o))) for o in options)
    raise ConfigError(f"configuration key {key!r}: expected {expected}, got {value!r}")


def _build(cls, values: dict, prefix: str, defaults):
    """Construct ``cls`` from a flat dict of dotted keys below ``prefix`` over ``defaults``."""
    kwargs = {}
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        key = f"{prefix}{f.name}"
        default = getattr(defaults, f.name)
        if dataclasses.is_dataclass(default):
            kwargs[f.name] = _build(type(default), values, f"{key}.", default)
        else:
            kwargs[f.name] = _coerce(key, values[key], hints[f.name]) if key in values else default
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        where = prefix.rstrip(".") or "configuration"
        if str(exc).startswith(f"{where}."):  # the message names its key already
            raise
        raise ConfigError(f"{where}: {exc}") from None


def _known_keys(cls) -> set:
    return set(flatten_keys(to_dict(cls())))


def with_overrides(config, overrides: dict):
    """``config`` (a resolved configuration) with dotted-key ``overrides`` applied, checked and
    coerced as :func:`make_config` does; every other value stays as it is (nothing re-derived)."""
    if not overrides:
        return config
    setting = next(name for name, cls in SETTINGS.items() if isinstance(config, cls))
    return make_config(setting, flatten_keys(to_dict(config)) | dict(overrides))


def make_config(setting: str = "plant", overrides: dict | None = None, **keywords):
    """A resolved configuration of ``setting`` (``plant`` or ``row``) with dotted-key ``overrides``
    (``{"registration.embedded_deformation.iterations": 100}``) and top-level ``keywords``
    (``gt_resolution=0.001``). Derived keys not given follow their rule (:data:`DERIVED`); unknown
    keys and bad values are one :class:`ConfigError` line naming the key."""
    if setting not in SETTINGS:
        raise ConfigError(f"unknown setting {setting!r}; choose one of {', '.join(SETTINGS)}")
    cls = SETTINGS[setting]
    given = dict(overrides or {})
    for key, value in keywords.items():
        if dataclasses.is_dataclass(value):
            given.update({f"{key}.{k}": v for k, v in flatten_keys(to_dict(value)).items()})
        else:
            given[key] = value
    given.pop("setting", None)
    known = _known_keys(cls)
    for key in given:
        if key not in known:
            close = sorted(k for k in known if k.split(".")[-1] == key.split(".")[-1])
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise ConfigError(f"unknown configuration key {key!r} for the {setting} setting{hint}")
    base = to_dict(cls())
    raw = {**flatten_keys(base), **given}
    for key, (_, rule) in DERIVED[setting].items():
        if key not in given:
            raw[key] = rule(raw)
    config = _build(cls, raw, "", cls())
    _check_methods(config)
    return config


def _check_methods(config) -> None:
    """Method names must be registered (the registries import their packages lazily)."""
    for registry, name, key in ((NBV_METHODS, config.nbv.method, "nbv.method"),
                                (REGISTRATION_METHODS, config.registration.method, "registration.method"),
                                (SELECTION_METHODS, config.selection.method, "selection.method")):
        if name not in registry:
            raise ConfigError(f"configuration key {key!r}: unknown {registry.kind} {name!r}; "
                              f"choose one of {', '.join(registry.names())}")
    _view_space_range(config.view_space)


def parse_overrides(items) -> dict:
    """``["a.b=1", "c=true"]`` -> ``{"a.b": 1, "c": True}`` (values read as YAML scalars)."""
    import yaml

    out = {}
    for item in items or ():
        key, sep, text = str(item).partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set {item!r}: write key=value, e.g. --set registration.embedded_deformation.iterations=100")
        try:
            value = yaml.safe_load(text) if text.strip() else None
        except yaml.YAMLError:
            value = text
        if isinstance(value, (dict, list)):
            raise ConfigError(f"--set {item!r}: the value must be a single number, word or true/false")
        out[key.strip()] = value
    return out


def load_config(source: str | Path | None = "paper", overrides: dict | None = None):
    """A named configuration (``paper``, ``paper-row``) or a YAML file, plus dotted ``overrides``.

    The file may give ``setting: plant|row`` and ``base: paper`` and any keys, nested or dotted.
    A resolved file written by :func:`config_yaml` loads back to the same configuration.
    """
    import yaml

    source = "paper" if source is None else source
    if str(source) in NAMED:
        setting, values = NAMED[str(source)]
        values = {**values, "name": str(source)}
    else:
        path = Path(source)
        if not path.is_file():
            raise InputFileError(f"configuration {str(source)!r} is neither one of {', '.join(NAMED)} nor an existing file")
        try:
            tree = yaml.safe_load(path.read_text())
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise InputFileError(f"{path}: not a readable YAML configuration ({first})") from None
        tree = {} if tree is None else tree
        if not isinstance(tree, dict):
            raise InputFileError(f"{path}: a configuration must be a mapping of keys to values")
        tree.pop("provenance", None)
        base = tree.pop("base", None)
        setting = tree.pop("setting", None)
        if base is not None:
            if base not in NAMED:
                raise ConfigError(f"{path}: base {base!r} is not one of {', '.join(NAMED)}")
            base_setting, base_values = NAMED[base]
            setting = setting or base_setting
            values = {**base_values, **flatten_keys(tree)}
        else:
            values = flatten_keys(tree)
        setting = setting or "plant"
    return make_config(setting, {**values, **(overrides or {})})


def config_yaml(config, header: str = "") -> str:
    """The fully resolved configuration as YAML (loads back with :func:`load_config`)."""
    import yaml

    tree = {"setting": config.setting, **to_dict(config)}
    lines = [f"# {line}" for line in header.splitlines()] if header else []
    return "\n".join(lines + [yaml.safe_dump(tree, sort_keys=False, default_flow_style=False)])


def derived_table(setting: str = "plant") -> list[tuple[str, str]]:
    """``(key, rule)`` of every derived parameter of ``setting``."""
    return [(key, rule) for key, (rule, _) in DERIVED[setting].items()]
