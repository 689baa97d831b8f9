"""Compile (or load from numba's cache) every numba kernel of the single-plant pipeline up front.

Every kernel is ``@njit(cache=True)``: the first run on a machine compiles it and writes the
machine code next to the source (``__pycache__``, or ``NUMBA_CACHE_DIR``); later processes only
load it. :func:`compile_kernels` runs each kernel once on tiny inputs, through the same public
functions and with the same argument types as the pipeline, so a run timed after it measures the
work, not the compilation. It takes seconds when nothing is cached and little when the cache is
warm.

Numba keys a cache on the kernel's own source file only: after editing a kernel that others call
(e.g. :mod:`tpvp.sensor.raycast`, inlined into the sensor and occupancy-map kernels), delete the
cached ``*.nbi`` / ``*.nbc`` files so the callers are recompiled.
"""

from __future__ import annotations

import time

import numpy as np

from tpvp.nbv import OccupancyMap, information_gain, next_best_view
from tpvp.path.tsp import TspConfig, shortest_open_path
from tpvp.registration.embedded_deformation import compile_kernels as compile_registration
from tpvp.scene.grid import build_grid
from tpvp.sensor.sensor import SensorConfig, depth_image, observe, observe_many
from tpvp.visibility import visibility_matrix
from tpvp.visibility.oracle import greenhouse_oracle


def compile_kernels(greenhouse: bool = False) -> float:
    """Trigger compilation or cache loading of the pipeline's numba kernels; returns the seconds.

    Covered: the sensor (reference and pixel models; single views, batches, depth images), the
    visibility matrix, the occupancy map's carving (point rays and pixel rays), the information
    gain (counts and visibility-weighted) and next-best view, and the open-path heuristic's local
    search, and the embedded-deformation registration's loss/gradient and nearest-neighbour kernels.
    ``greenhouse`` adds the greenhouse-row oracle (not used for single plants).
    """
    start = time.perf_counter()
    res = 0.01
    # A 4 x 4 x 4 voxel block (countable) on a 6 x 6 slab (occludes only), around the origin.
    block = np.stack(np.meshgrid(*[np.arange(-2, 2)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    slab = np.stack(np.meshgrid(np.arange(-3, 3), np.arange(-3, 3), [-3], indexing="ij"),
                    axis=-1).reshape(-1, 3)
    grid = build_grid(np.concatenate([block, slab]), res,
                      np.r_[np.ones(len(block), bool), np.zeros(len(slab), bool)])
    views = np.array([[0.3, 0.05, 0.1], [-0.1, 0.25, 0.2], [0.05, -0.2, 0.3]])
    centre = np.zeros(3)
    for sensor in (SensorConfig(), SensorConfig(model="pixel", pixel_stride=16)):
        matrix = visibility_matrix(grid, views, centre, sensor, progress=False)
        observe_many(grid, views[:1], centre, sensor)
        observe(grid, views[0], centre, sensor)
    depth_image(grid, views[0], centre, SensorConfig(model="pixel", pixel_stride=16))

    # Warm-up NBV as the pipeline runs it: map from observed voxel centres, pixel-ray carving.
    observed = [grid.centres[matrix[v].indices] for v in range(2)]
    observed[1] = np.concatenate([observed[1], [[0.5, 0.5, 0.5]]])  # a return outside the map
    occupancy = OccupancyMap.from_observations(centre, views[:2], observed, look_ats=centre, stride=32)
    OccupancyMap.from_observations(centre, views[:2], observed)
    next_best_view(occupancy, views, centre, executed=[0], stride=32)
    information_gain(occupancy, views, centre, stride=32, unknown_visibility=0.5)

    distance = np.abs(np.subtract.outer(np.arange(6.0), np.arange(6.0)))
    shortest_open_path(distance, 0, config=TspConfig(method="heuristic", kicks=1))

    compile_registration()
    if greenhouse:
        greenhouse_oracle(grid, views, progress=False)
    return time.perf_counter() - start
