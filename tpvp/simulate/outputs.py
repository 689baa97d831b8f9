"""What one simulated run leaves: the planner's outputs (:mod:`tpvp.pipeline.outputs`) with what
the simulation measured on the ground truth (the oracle, the coverage, the coverage figure, today's
plant under the plan), and interactive views of a plan and what it covered."""

from __future__ import annotations

import numpy as np

from tpvp.simulate import single_plant
from tpvp.simulate.greenhouse import execute
from tpvp.pipeline.outputs import Measured, write_plan_outputs, write_row_plan_outputs
from tpvp.viz.geometry import plan_geometry
from tpvp.viz.interactive import scene_3d


def plan_3d(scene, result, title: str = ""):
    """An interactive (plotly) view of a plant plan: covered plant voxels (blue), observable but
    missed ones (red), the candidate views, the executed and planned views and the path."""
    geometry = plan_geometry(scene, result)
    plant = scene.grid.countable
    centres = scene.grid.centres
    covered, observable = geometry["covered"] & plant, geometry["observable"] & plant
    space = scene.view_space
    return scene_3d({"covered voxels": (centres[covered], "royalblue"),
                     "missed voxels (observable)": (centres[observable & ~covered], "red"),
                     "never observable": (centres[plant & ~observable], "lightgray")},
                    candidates=space.positions, executed=space.positions[result.executed_views],
                    selected=space.positions[result.planned_views], look_ats=space.look_ats[result.planned_views],
                    path_polyline=geometry["polyline"],
                    title=title or f"{result.n_views} views, {100 * result.coverage:.2f} % coverage")


def write_case_outputs(folder, scene, result, config, name: str = "case", extra_summary: dict | None = None,
                       pool=None) -> dict:
    """The planner's outputs of a simulated plant case (:func:`tpvp.pipeline.outputs.write_plan_outputs`)
    with the oracle's size, the coverages and the coverage figure of the ground-truth voxels."""
    def coverage_figure(folder):
        geometry = plan_geometry(scene, result)
        plant = scene.grid.countable
        return [("tpvp.viz.figures:plot_coverage", (folder / "coverage.png", scene.grid.centres[plant], geometry["covered"][plant],
                                 geometry["observable"][plant], f"{name}: ground-truth voxels "
                                 f"({1e3 * config.gt_resolution:g} mm, planning frame)"), {})]
    measured = Measured({"oracle_voxels": int(len(scene.oracle))}, scene.current, coverage_figure)
    return write_plan_outputs(folder, single_plant.known(scene), result, config, name, extra_summary, measured,
                              pool)


def write_row_case_outputs(folder, scene, result, config, name: str = "row case", extra_summary: dict | None = None,
                           pool=None) -> dict:
    """The planner's outputs of a simulated row case (:func:`tpvp.pipeline.outputs.write_row_plan_outputs`)
    with the oracle's size and whether it came from the cache, and the coverages."""
    measured = Measured({"oracle_voxels": int(len(scene.oracle)), "oracle_from_cache": scene.oracle_cached},
                        scene.current)
    return write_row_plan_outputs(folder, scene.known, result, config, name, extra_summary, measured, pool)


def row_plan_3d(scene, result, title: str = ""):
    """An interactive (plotly) view of a row plan: the oracle voxels the passive sweep and the
    planned views covered (blue) and those they missed (red), the passive views (black), the
    planned views in execution order with their look-at rays, and the band path."""
    covered = np.union1d(execute(scene, result.positions, result.look_ats), scene.passive_seen)
    missed = np.setdiff1d(scene.oracle, covered)
    centres, room = scene.grid.centres, scene.room
    return scene_3d({"covered voxels": (centres[np.intersect1d(covered, scene.oracle)], "royalblue"),
                     "missed voxels (observable)": (centres[missed], "red")},
                    executed=room.initial_positions, selected=result.positions, look_ats=result.look_ats,
                    path_polyline=np.concatenate([room.initial_positions[-1:], result.positions]),
                    title=title or f"{result.n_views} views, {100 * result.coverage:.2f} % coverage")
