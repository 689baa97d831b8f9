"""Compile (or load from numba's cache) the numba kernels a run needs, up front.

Every kernel is ``@njit(cache=True)``: the first run on a machine compiles it and writes the
machine code next to the source (``__pycache__``, or ``NUMBA_CACHE_DIR``); later processes only
load it. Numba compiles a kernel on its first call anyway; :func:`compile_kernels` makes those first
calls on tiny inputs, through the same public functions and with the same argument types as the
pipeline, so that a run timed after it measures the work, not the compilation. It compiles only the
pieces it is given (:data:`PIECES`): a single-plant run needs those of :func:`plant_pieces`, a few
seconds on a cold cache and a fraction of a second from the cache; a kernel of another piece is
compiled (or loaded) when something first calls it.

Numba keys a cache on the kernel's own source file only: after editing a kernel that others call
(e.g. :mod:`tpvp.sensor.raycast`, called by the sensor and occupancy-map kernels), delete the
cached ``*.nbi`` / ``*.nbc`` files so the callers are recompiled.
"""

from __future__ import annotations

import time

import numpy as np

from tpvp.errors import ConfigError
from tpvp.nbv.information_gain import information_gain, next_best_view
from tpvp.nbv.occupancy import OccupancyMap
from tpvp.path.tsp import TspConfig, shortest_open_path
from tpvp.registration.embedded_deformation import compile_kernels as compile_registration
from tpvp.scene.grid import build_grid
from tpvp.sensor.sensor import SensorConfig, depth_image, observe
from tpvp.visibility import visibility_matrix
from tpvp.visibility.oracle import greenhouse_oracle


def _scene():
    """A 4 x 4 x 4 voxel block (countable) on a 6 x 6 slab (occludes only), around the origin; three
    views and the centre."""
    block = np.stack(np.meshgrid(*[np.arange(-2, 2)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    slab = np.stack(np.meshgrid(np.arange(-3, 3), np.arange(-3, 3), [-3], indexing="ij"),
                    axis=-1).reshape(-1, 3)
    grid = build_grid(np.concatenate([block, slab]), 0.01,
                      np.r_[np.ones(len(block), bool), np.zeros(len(slab), bool)])
    views = np.array([[0.3, 0.05, 0.1], [-0.1, 0.25, 0.2], [0.05, -0.2, 0.3]])
    return grid, views, np.zeros(3)


def _visibility(sensor: SensorConfig) -> None:
    grid, views, centre = _scene()
    visibility_matrix(grid, views, centre, sensor, progress=False)


def _single_views() -> None:
    grid, views, centre = _scene()
    pixel = SensorConfig(model="pixel", pixel_stride=16)
    for sensor in (SensorConfig(), pixel):
        observe(grid, views[0], centre, sensor)
    depth_image(grid, views[0], centre, pixel)


def _occupancy_map():
    """A map as the warm-up NBV builds it (observed voxel centres, pixel-ray carving); the views."""
    grid, views, centre = _scene()
    observed = [grid.centres[:32], grid.centres[32:64]]
    observed[1] = np.concatenate([observed[1], [[0.5, 0.5, 0.5]]])  # a return outside the map
    return OccupancyMap.from_observations(centre, views[:2], observed, look_ats=centre, stride=32), views, centre


def _nbv() -> None:
    occupancy, views, centre = _occupancy_map()
    next_best_view(occupancy, views, centre, executed=[0], stride=32)


def _gain_walk() -> None:
    occupancy, views, centre = _occupancy_map()
    information_gain(occupancy, views, centre, stride=32, unknown_visibility=0.5)


def _path() -> None:
    distance = np.abs(np.subtract.outer(np.arange(6.0), np.arange(6.0)))
    shortest_open_path(distance, 0, config=TspConfig(method="heuristic", kicks=1))


def _oracle() -> None:
    grid, views, _ = _scene()
    greenhouse_oracle(grid, views, progress=False)


#: Piece name -> (what it covers, the calls that compile it).
PIECES = {
    "reference": ("the reference sensor model on many views (visibility matrices, observe_many)",
                  lambda: _visibility(SensorConfig())),
    "pixel": ("the pixel sensor model on many views",
              lambda: _visibility(SensorConfig(model="pixel", pixel_stride=16))),
    "views": ("both sensor models on single views (observe) and depth images", _single_views),
    "nbv": ("the warm-up NBV: the occupancy map's carving (point and pixel rays) and the information "
            "gain counts", _nbv),
    "gain-walk": ("the information gain by walking every ray (reference=True, visibility-weighted)", _gain_walk),
    "registration": ("the embedded-deformation registration's loss/gradient and nearest-neighbour kernels",
                     compile_registration),
    "path": ("the open-path heuristic's local search", _path),
    "oracle": ("the greenhouse-row oracle", _oracle),
}


def plant_pieces(config) -> tuple[str, ...]:
    """The pieces a single-plant run with ``config`` (a :class:`tpvp.config.PlantConfig`) calls: its
    sensor model, the geometric warm-up NBV, the embedded-deformation registration and the path
    heuristic when so configured. (``path`` method ``auto`` runs the heuristic only beyond
    ``ilp_max_nodes`` views, where its kernel is compiled on first use.)"""
    pieces = [config.sensor.model]
    if config.nbv.method == "geometric" and config.nbv.warm_up_views > 0:
        pieces.append("nbv")
    if config.registration.method == "embedded-deformation":
        pieces.append("registration")
    if config.path.method == "heuristic":
        pieces.append("path")
    return tuple(pieces)


def compile_kernels(*pieces: str, greenhouse: bool = False) -> float:
    """Trigger compilation or cache loading of the numba kernels of ``pieces`` (names of
    :data:`PIECES`; none: every piece but the greenhouse oracle, which ``greenhouse`` adds);
    returns the seconds."""
    unknown = [p for p in pieces if p not in PIECES]
    if unknown:
        raise ConfigError(f"unknown kernel pieces {unknown}; choose from {', '.join(PIECES)}")
    chosen = list(pieces) or [p for p in PIECES if p != "oracle"]
    if greenhouse and "oracle" not in chosen:
        chosen.append("oracle")
    start = time.perf_counter()
    for piece in chosen:
        PIECES[piece][1]()
    return time.perf_counter() - start
