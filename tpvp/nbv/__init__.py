"""Next-best-view methods: geometric information gain on an occupancy map of what was observed, and
the prior-guided gain on the previous session (each registers itself in ``NBV_METHODS``)."""

from tpvp.nbv.information_gain import information_gain, next_best_view  # noqa: F401
from tpvp.nbv.occupancy import (  # noqa: F401
    FREE,
    OCCUPIED,
    UNKNOWN,
    OccupancyMap,
    OccupancyMapConfig,
)
from tpvp.nbv import prior as _prior  # noqa: E402,F401  (registers "prior")
