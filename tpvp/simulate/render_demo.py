"""Render the bundled real tomato from every view of a view space and report coverage view by view.

This is the simulator's smoke run: ground truth at 2 mm (with the supporting table in the
hemisphere setting only, as in the paper; the sphere setting has none), the voxel-driven
``reference`` sensor, the oracle visible set as the union over all views, and the coverage
accumulated in view order. With an output folder it also writes depth images of a few views
(:func:`render_depth_images`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.errors import ConfigError
from tpvp.scene.grid import plant_grid
from tpvp.scene.normalise import normalise_plant
from tpvp.scene.samples import load_sample
from tpvp.sensor.sensor import SensorConfig, depth_image
from tpvp.viewspace.single_plant import load_view_space
from tpvp.visibility import coverage_ratio, oracle_voxels, visibility_matrix
from tpvp.viz.figures import plot_depth_images

#: Views shown in the depth figure: the three initial views of the paper (17 near-horizontal,
#: 8 oblique, 21 near-top), then three more around the plant (see :func:`default_depth_views`).
DEPTH_VIEWS = (17, 8, 21, 0, 12, 28)
DEPTH_FIGURE = "depth_views.png"


@dataclass(frozen=True)
class RenderDemoConfig:
    sample: str = "tomato_0306"
    view_space: str = "hemisphere"
    resolution: float = 0.002
    largest_side: float = 0.24
    table: bool | None = None  # None: a table for the hemisphere view space only (paper setting)
    model: str = "reference"

    @property
    def uses_table(self) -> bool:
        return self.view_space == "hemisphere" if self.table is None else bool(self.table)


def render_scene(config: RenderDemoConfig = RenderDemoConfig()):
    """``(grid, views)``: the ground-truth occupancy grid (plant, plus the table when
    ``config.uses_table``) and the ``(V, 3)`` view positions, all looking at the origin."""
    scene = normalise_plant(load_sample(config.sample), largest_side=config.largest_side,
                            table=config.uses_table, table_resolution=config.resolution)
    grid = plant_grid(scene.points, scene.table_points, config.resolution)
    return grid, load_view_space(config.view_space)


def default_depth_views(views, look_at=(0.0, 0.0, 0.0), count: int = 6) -> list[int]:
    """The initial views 17, 8, 21, then the lowest view when it looks from below (sphere view
    spaces), then the rest of :data:`DEPTH_VIEWS`; ``count`` views at most, all in range."""
    views = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    offsets = views - np.asarray(look_at, dtype=np.float64).reshape(3)
    lowest = int(np.argmin(offsets[:, 2])) if len(views) else -1
    order = list(DEPTH_VIEWS[:3])
    if lowest >= 0 and offsets[lowest, 2] < 0:
        order.append(lowest)
    order += list(DEPTH_VIEWS[3:])
    out: list[int] = []
    for i in order:
        if 0 <= i < len(views) and i not in out:
            out.append(i)
    return out[:count]


def run_render_demo(config: RenderDemoConfig = RenderDemoConfig(), output=None,
                    depth_views=None):
    """Return ``(table, summary)``: per-view coverage rows and a dict of scene figures.

    With ``output`` (a folder) the depth figure of ``depth_views`` (default:
    :func:`default_depth_views`) is written there too (:func:`render_depth_images`);
    ``summary["depth_images"]`` lists the written files (strings).
    """
    started = time.perf_counter()
    grid, views = render_scene(config)
    t0 = time.perf_counter()
    matrix = visibility_matrix(grid, views, np.zeros(3), SensorConfig(model=config.model))
    render_seconds = time.perf_counter() - t0
    oracle = oracle_voxels(matrix)
    covered = np.zeros(grid.size, dtype=bool)
    rows = []
    for i in range(len(views)):
        seen = matrix[i].indices
        new = int((~covered[seen]).sum())
        covered[seen] = True
        rows.append({
            "view": i,
            "x": views[i, 0], "y": views[i, 1], "z": views[i, 2],
            "seen_voxels": len(seen),
            "new_voxels": new,
            "coverage": coverage_ratio(np.flatnonzero(covered), oracle),
        })
    summary = {
        "sample": config.sample,
        "view_space": config.view_space,
        "plant_voxels": int(grid.countable.sum()),
        "table_voxels": int((~grid.countable).sum()),
        "oracle_voxels": int(len(oracle)),
        "views": len(views),
        "render_ms_per_view": 1e3 * render_seconds / len(views),
    }
    if output is not None:
        if depth_views is None:
            depth_views = default_depth_views(views)
        written = render_depth_images(output, grid, views, depth_views,
                                      title=f"{config.sample}, {config.view_space} view space")
        summary["depth_images"] = [str(p) for p in written]
    summary["total_seconds"] = time.perf_counter() - started
    return pd.DataFrame(rows), summary


def render_depth_images(output, grid, views, indices=None, *, look_at=(0.0, 0.0, 0.0),
                        sensor: SensorConfig | None = None, title: str = "") -> list[Path]:
    """Write one PNG (``output/depth_views.png``) with the depth image of each view in
    ``indices`` (indices into ``views``, an ``(V, 3)`` array of positions looking at ``look_at``;
    default :func:`default_depth_views`):
    the pixel sensor's first surface per pixel, colour-mapped in metres (camera-z depth, one
    shared colour bar), white where a pixel sees nothing within range. Indices beyond the view
    space are skipped; none left raises ConfigError. Returns the written paths.
    """
    views = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    if indices is None:
        indices = default_depth_views(views, look_at)
    chosen = [int(i) for i in indices if 0 <= int(i) < len(views)]
    if not chosen:
        raise ConfigError(f"none of the depth views {list(indices)} is one of the {len(views)} views")
    sensor = sensor or SensorConfig(model="pixel")
    if sensor.model != "pixel":
        sensor = SensorConfig(model="pixel", max_range=sensor.max_range,
                              pixel_stride=sensor.pixel_stride, intrinsics=sensor.intrinsics)
    target = np.asarray(look_at, dtype=np.float64).reshape(3)
    depths = [depth_image(grid, views[i], target, sensor)[0] for i in chosen]
    offsets = views[chosen] - target
    elevations = np.degrees(np.arctan2(offsets[:, 2], np.hypot(offsets[:, 0], offsets[:, 1])))
    labels = [f"view {i} (elevation {e:+.0f} deg)" for i, e in zip(chosen, elevations)]
    figure = plot_depth_images(Path(output) / DEPTH_FIGURE, depths, labels, title=title)
    return [figure]
