"""Execution path: local paths around the plant and the shortest open path through the views."""

from tpvp.path.bound import BoundResult, open_path_lower_bound  # noqa: F401
from tpvp.path.local import (  # noqa: F401
    local_path_length,
    local_path_lengths,
    local_path_points,
    obstacle_radius,
    predicted_size,
)
from tpvp.path.tsp import (  # noqa: F401
    BandPathResult,
    PathResult,
    TspConfig,
    band_path,
    nearest_neighbour_path,
    path_length,
    shortest_open_path,
)
