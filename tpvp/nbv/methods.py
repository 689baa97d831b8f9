"""NBV methods, chosen by name (``nbv.method``) from :data:`NBV_METHODS`.

Interface (sized for sequential and learned methods, not only the one-shot warm-up):

* a factory ``make(context: NbvContext) -> method`` is registered under a name;
* the method object keeps its own state between calls (an occupancy map, a learned model's view
  state): ``method.integrate(view, points)`` adds an executed view and the points it observed;
  ``method.next_view()`` returns an :class:`NbvChoice` among the views not yet executed.

A new NBV method is one class with these two methods plus one ``@NBV_METHODS.register`` line.

Registered: ``geometric`` (information gain on an occupancy map of what was observed; the default),
``pc-nbv`` (the learned gain network of :mod:`tpvp.learning`) and ``prior`` (:mod:`tpvp.nbv.prior`: the previous session's voxels that a view would observe and
no executed view did; needs ``NbvContext.prior``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tpvp.nbv.information_gain import next_best_view
from tpvp.nbv.occupancy import OccupancyMap, observed_radius
from tpvp.registry import Registry

NBV_METHODS = Registry("NBV method")


@dataclass(frozen=True, eq=False)
class NbvContext:
    """What an NBV method may know: the candidate views (``tpvp.viewspace.space.ViewSpace``: positions,
    look-ats), the object centre, the sensor (``SensorConfig``), its own ``NbvConfig`` and,
    optionally, the previous session's model ``prior`` (``(N, 3)`` points in the planning frame;
    None when there is none; methods that need it say so)."""

    view_space: object
    centre: np.ndarray
    sensor: object
    config: object
    prior: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class NbvChoice:
    """The chosen view and every candidate's score (executed views included, as computed)."""

    view: int
    scores: np.ndarray = field(default_factory=lambda: np.zeros(0))


class ObservedViews:
    """What every NBV method keeps: the executed views, in order, and the points each observed."""

    def __init__(self, context: NbvContext):
        self.context = context
        self.executed: list[int] = []
        self.observations: list[np.ndarray] = []

    @property
    def view_state(self) -> np.ndarray:
        """Boolean mask of the executed views (the input learned methods take beside the map)."""
        state = np.zeros(len(self.context.view_space), dtype=bool)
        state[self.executed] = True
        return state

    def integrate(self, view: int, points: np.ndarray) -> None:
        self.executed.append(int(view))
        self.observations.append(np.asarray(points, dtype=np.float64).reshape(-1, 3))


class GeometricNbv(ObservedViews):
    """Information gain on an occupancy map of what was observed: unknown voxels reached by a
    view's pixel rays (every ``pixel_stride``-th pixel), free space carved along the executed
    views' pixel rays; the paper's warm-up NBV in this library (docs/sensor.md#information-gain).

    The map is sized on all observed points, so a view that sees farther from the centre than
    every earlier one changes its geometry and the map is rebuilt from every view; otherwise
    (``incremental``, the default) the new views are integrated into the current map, the same
    ``integrate`` calls in the same order as a rebuild, hence the same map. ``incremental=False``
    rebuilds after every view (the reference).
    """

    def __init__(self, context: NbvContext, incremental: bool = True):
        super().__init__(context)
        self.incremental = bool(incremental)
        self._radii: list[float] = []  # per view (once mapped): farthest observed point from the centre
        self._occupancy: OccupancyMap | None = None
        self._radius = 0.0  # the radius that _occupancy is sized on
        self._integrated = 0  # views in _occupancy

    @property
    def occupancy(self) -> OccupancyMap:
        """The occupancy map of every integrated view (sized on all observed points)."""
        if self._occupancy is not None and self._integrated == len(self.executed):
            return self._occupancy
        space, sensor, config = self.context.view_space, self.context.sensor, self.context.config
        carving = {"stride": config.pixel_stride, "max_range": sensor.max_range,
                   "intrinsics": sensor.intrinsics}
        for i in range(len(self._radii), len(self.observations)):
            self._radii.append(observed_radius(self.context.centre, self.observations[i],
                                               f"observed points of view {i}"))
        radius = max(self._radii, default=0.0)
        if self.incremental and self._occupancy is not None and radius == self._radius:
            occupancy = self._occupancy
            for i in range(self._integrated, len(self.executed)):
                view = self.executed[i]
                occupancy = occupancy.integrate(space.positions[view], self.observations[i],
                                                space.look_ats[view], **carving)
        else:
            occupancy = OccupancyMap.from_observations(
                self.context.centre, space.positions[self.executed], self.observations, config.map,
                look_ats=space.look_ats[self.executed], **carving)
        self._occupancy, self._radius, self._integrated = occupancy, radius, len(self.executed)
        return occupancy

    def next_view(self) -> NbvChoice:
        space, sensor = self.context.view_space, self.context.sensor
        view, gains = next_best_view(self.occupancy, space.positions, space.look_ats, executed=self.executed,
                                     stride=self.context.config.pixel_stride, max_range=sensor.max_range,
                                     intrinsics=sensor.intrinsics)
        return NbvChoice(view, gains)


NBV_METHODS.register("geometric")(GeometricNbv)


def make_nbv(context: NbvContext):
    """The NBV method named by ``context.config.method``."""
    return NBV_METHODS.get(context.config.method)(context)


def start_nbv(scene, config):
    """The configured NBV method on ``scene``'s view space and sensor, nothing executed yet (its
    ``prior`` is the previous session in the planning frame): a simulator scene or what a real
    session knows (:class:`tpvp.pipeline.plan.Known`)."""
    return make_nbv(NbvContext(scene.view_space, np.zeros(3), scene.sensor, config.nbv, prior=scene.previous))
