"""NBV methods, chosen by name (``nbv.method``) from :data:`NBV_METHODS`.

Interface (sized for sequential and learned methods, not only the one-shot warm-up):

* a factory ``make(context: NbvContext) -> method`` is registered under a name;
* the method object keeps its own state between calls (an occupancy map, a learned model's view
  state): ``method.integrate(view, points)`` adds an executed view and the points it observed;
  ``method.next_view()`` returns an :class:`NbvChoice` among the views not yet executed.

A new NBV method is one class with these two methods plus one ``@NBV_METHODS.register`` line.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tpvp.nbv.information_gain import next_best_view
from tpvp.nbv.occupancy import OccupancyMap
from tpvp.registry import Registry

NBV_METHODS = Registry("NBV method")


@dataclass(frozen=True, eq=False)
class NbvContext:
    """What an NBV method may know: the candidate views (``tpvp.viewspace.ViewSpace``: positions,
    look-ats), the object centre, the sensor (``SensorConfig``) and its own ``NbvConfig``."""

    view_space: object
    centre: np.ndarray
    sensor: object
    config: object


@dataclass(frozen=True, eq=False)
class NbvChoice:
    """The chosen view and every candidate's score (executed views included, as computed)."""

    view: int
    scores: np.ndarray = field(default_factory=lambda: np.zeros(0))


class GeometricNbv:
    """Information gain on an occupancy map of what was observed: unknown voxels reached by a
    view's pixel rays (every ``pixel_stride``-th pixel), free space carved along the executed
    views' pixel rays; the paper's warm-up NBV in this library (docs/sensor.md#information-gain)."""

    def __init__(self, context: NbvContext):
        self.context = context
        self.executed: list[int] = []
        self.observations: list[np.ndarray] = []
        self._occupancy: OccupancyMap | None = None

    @property
    def view_state(self) -> np.ndarray:
        """Boolean mask of the executed views (the input learned methods take beside the map)."""
        state = np.zeros(len(self.context.view_space), dtype=bool)
        state[self.executed] = True
        return state

    def integrate(self, view: int, points: np.ndarray) -> None:
        self.executed.append(int(view))
        self.observations.append(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        self._occupancy = None

    @property
    def occupancy(self) -> OccupancyMap:
        """The occupancy map of every integrated view (rebuilt after a new view: it is sized on
        all observed points)."""
        if self._occupancy is None:
            space, sensor, config = self.context.view_space, self.context.sensor, self.context.config
            self._occupancy = OccupancyMap.from_observations(
                self.context.centre, space.positions[self.executed], self.observations, config.map,
                look_ats=space.look_ats[self.executed], stride=config.pixel_stride,
                max_range=sensor.max_range, intrinsics=sensor.intrinsics)
        return self._occupancy

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
