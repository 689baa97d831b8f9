"""Geometric next-best-view: occupancy map of what was observed and per-view information gain."""

from tpvp.nbv.information_gain import information_gain, next_best_view  # noqa: F401
from tpvp.nbv.occupancy import (  # noqa: F401
    FREE,
    OCCUPIED,
    UNKNOWN,
    OccupancyMap,
    OccupancyMapConfig,
)
