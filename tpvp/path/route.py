"""The robot's whole route: the executed views in order, then the shortest open path through the
selected ones, around the plant's obstacle sphere."""

from __future__ import annotations

import numpy as np

from tpvp.path.local import local_path_lengths, obstacle_radius
from tpvp.path.tsp import shortest_open_path


def path_through(space, executed, selected, coarse, config):
    """The executed views' path, then the shortest open path from the last one through ``selected``;
    the obstacle sphere is sized on the coarse reconstruction. Returns (planned views in order,
    whole path length, the TSP result, obstacle radius)."""
    centre = np.zeros(3)
    radius = obstacle_radius(coarse, centre)
    stops = [executed[-1], *selected]
    tsp = shortest_open_path(local_path_lengths(space.positions[stops], centre, radius), start=0, config=config.path)
    planned = [int(stops[i]) for i in tsp.order[1:]]
    warm_up_path = float(np.trace(local_path_lengths(space.positions[executed], centre, radius), offset=1)) \
        if len(executed) > 1 else 0.0
    return planned, warm_up_path + tsp.length, tsp, radius
