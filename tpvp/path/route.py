"""The robot's whole route. A plant's: the executed views in order, then the shortest open path
through the selected ones, around the plant's obstacle sphere. A row's: the selected views ordered
by a route chosen by name (:data:`ROW_ROUTES`)."""

from __future__ import annotations

import numpy as np

from tpvp.path.local import local_path_lengths, obstacle_radius
from tpvp.path.tsp import BandPathResult, TspConfig, band_path, shortest_open_path
from tpvp.registry import Registry


def path_through(space, executed, selected, coarse, config):
    """The executed views' path, then the shortest open path from the last one through ``selected``;
    the obstacle sphere is sized on the coarse reconstruction. Returns (planned views in order,
    whole path length, the TSP result, obstacle radius)."""
    centre = np.zeros(3)
    radius = obstacle_radius(coarse, centre)
    stops = [executed[-1], *selected]
    tsp = shortest_open_path(local_path_lengths(space.positions[stops], centre, radius), start=0, config=config.path)
    planned = [int(stops[i]) for i in tsp.order[1:]]
    return planned, path_along(space.positions[executed], radius) + tsp.length, tsp, radius


def path_along(positions, radius: float) -> float:
    """The length of the path through ``positions`` in their order, around the obstacle sphere of
    ``radius`` at the origin (0 for fewer than two)."""
    if len(positions) < 2:
        return 0.0
    return float(np.trace(local_path_lengths(positions, np.zeros(3), radius), offset=1))


#: How a row's selected views are ordered (``RowConfig.route``): name -> function
#: ``(positions, split_height, start_position, TspConfig) -> BandPathResult``.
ROW_ROUTES = Registry("row route")


@ROW_ROUTES.register("band", "the paper's: an open path in each height band (split at the view box's mid height), "
                             "upper band first, joined at the lower band's nearest view", default=True)
def band_route(positions, split_height: float, start_position, config: TspConfig) -> BandPathResult:
    return band_path(positions, split_height=split_height, start_position=start_position, config=config)


@ROW_ROUTES.register("open", "one open path through every view from the start, heights mixed")
def open_route(positions, split_height: float, start_position, config: TspConfig) -> BandPathResult:
    lowest = float(np.min(np.asarray(positions, dtype=np.float64).reshape(-1, 3)[:, 2], initial=np.inf))
    return band_path(positions, split_height=lowest, start_position=start_position, config=config)


def row_path(room, positions, config: TspConfig = TspConfig(), with_passive: bool = True, route: str = "band"):
    """The path over the views in ``room`` by ``route`` (:data:`ROW_ROUTES`; bands split at the
    view box's mid height), from where the passive sweep ends when it ran; returns the path result
    and the reported length (sweep included)."""
    split = float(room.view_box.center[2])
    start = np.asarray(room.initial_positions[-1]) if with_passive else None
    result = ROW_ROUTES.get(route)(positions, split, start, config)
    return result, result.length + (room.passive_cost if with_passive else 0.0)


def row_path_warnings(path, config: TspConfig) -> list[str]:
    """A warning when the band path stopped above its target gap to the lower bound."""
    if path.gap > config.band_gap:
        return [f"band path ends {100 * path.gap:.1f} % above its lower bound (target {100 * config.band_gap:g} %) "
                f"after {config.band_seconds:g} s per band"]
    return []
