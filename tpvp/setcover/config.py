"""View selection's configuration (``selection`` and its ``set_cover`` solver settings), light: no
solver or registry is imported with it; the method name is checked against
:data:`tpvp.setcover.methods.SELECTION_METHODS` when a configuration is loaded."""

from __future__ import annotations

from dataclasses import dataclass, field

from tpvp.configuration_checks import check_integer, check_positive
from tpvp.errors import ConfigError
from tpvp.scene.config import ORGANS
from tpvp.solvers import check_solver_settings


@dataclass(frozen=True)
class SetCoverConfig:
    """Solver settings.

    The reference implementation stops Gurobi after 10 s (docs/single_plant.md#set-cover); here
    the default limit is generous so that realistic instances finish with a proof of optimality.
    Pass ``time_limit=10.0`` to mimic the reference.
    """

    solver: str = "cbc"  # "cbc" (PuLP's bundled CBC) or "highs" (highspy)
    time_limit: float = 60.0  # seconds for the ILP solve
    threads: int = 1  # one thread keeps the selection deterministic
    reduce: bool = True  # apply the exact reductions before solving

    def __post_init__(self):
        check_solver_settings(self.solver, self.time_limit, self.threads)


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
#: ``selection.miss_model``: the ratios above, or the per-case model of :mod:`tpvp.setcover.miss_model`.
MISS_MODELS = ("constant", "per-case")


@dataclass(frozen=True)
class SelectionConfig:
    """View selection on the planning surface. method: a name of
    :data:`tpvp.setcover.methods.SELECTION_METHODS`. cover_resolution: voxel of the planning surface (m).
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
    benchmarks/species_calibration.py). captures_seen: a planning voxel holding a point an
    executed view captured counts as seen by that view (a plant's; off in ``paper``, where the ray
    cast of the planning grid alone decides, on in ``realistic``:
    :func:`tpvp.pipeline.surface.with_captures_seen`). miss_model: how a coverage target below 1
    becomes a planning target when no ``planning_miss_ratio`` is given: ``constant``, the calibrated
    ratio of the view space; ``per-case``, the smallest share whose true coverage the miss model
    predicts at the target (:mod:`tpvp.setcover.miss_model`; a plant's one-shot plan in the
    hemisphere or the sphere, other plans keep the constant rule). It missed its evaluation on the
    sphere (docs/results.md#coverage-a-plan-predicts-per-case), so ``constant`` stays the default;
    either way the plan reports the model's predicted true coverage."""

    method: str = "set-cover"
    cover_resolution: float = 0.004
    coverage_target: float = 1.0
    planning_miss_ratio: float | None = None
    replan_after: int = 0
    organ_targets: str = ""
    organ_margin_voxels: int = 2
    captures_seen: bool = False
    miss_model: str = "constant"
    set_cover: SetCoverConfig = field(default_factory=SetCoverConfig)

    def __post_init__(self):
        check_positive(self, "cover_resolution")
        check_integer(self, "replan_after", minimum=0)
        check_integer(self, "organ_margin_voxels", minimum=0)
        self.organ_target_values()  # one line now for a malformed organ_targets, not mid-run
        if not (isinstance(self.coverage_target, (int, float)) and 0 < self.coverage_target <= 1):
            raise ConfigError(f"selection.coverage_target must be in (0, 1], got {self.coverage_target!r}")
        if self.planning_miss_ratio is not None:
            check_positive(self, "planning_miss_ratio")
        if self.miss_model not in MISS_MODELS:
            raise ConfigError(f"selection.miss_model must be one of {', '.join(MISS_MODELS)}, got {self.miss_model!r}")

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
