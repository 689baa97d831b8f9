"""A real single-plant session: the previous session's model and today's captures, no ground truth.

* ``start`` fixes the planning frame from the previous model (``scene.frame = previous``, the
  plant at its true size: ``scene.scale = native``), the candidate views around it, and asks for
  the initial view;
* ``add`` fuses a capture (a cloud in the world frame, or a depth image and its intrinsics) taken
  at a candidate view: its voxels (ground-truth resolution, planning frame) join today's coarse
  reconstruction, and the warm-up NBV (the configured method, free space carved along the rays)
  asks for the next view until the warm-up is done;
* ``plan`` runs registration, inflation, visibility, selection and the exact path on what was
  captured, and writes the plan as ``tpvp plan`` does (``plan/``, with ``prediction.npz``: what
  the plan predicts its views see); the planned views are asked next. Run again after planned
  views were captured (asked for every ``selection.replan_after`` views), it re-plans the rest from
  the captures (:func:`tpvp.pipeline.replan.replan`), as the simulator does; once a one-shot plan's
  views are all captured, run again it checks them against the coverage target and adds the views
  that close a gap (the simulator's ``run_case(closing=True)``);
* ``export`` writes today's fused model (every capture's voxel centres, world frame).

The world frame is the previous model's own (metres after ``--units``). With the same captures,
the plan equals the simulator's plan of the pair with ``scene.frame = previous`` at native scale
(``tests/test_session.py`` renders the captures from today's scan at the poses the session asks).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from tpvp.config import PlantConfig
from tpvp.config_loading import with_overrides
from tpvp.errors import ConfigError
from tpvp.io import atomic_write_bytes
from tpvp.nbv.methods import start_nbv
from tpvp.pipeline.plan import Known, plan, planning_surface, transfer
from tpvp.pipeline.replan import Prediction, Replan, prediction_of, replan
from tpvp.scene.frame import known_from_previous, planning_frame
from tpvp.scene.organs import check_organ_targets
from tpvp.session.folder import KINDS, Request, Session


#: What the last plan predicts its views see (:class:`~tpvp.pipeline.replan.Prediction`), beside it.
PREDICTION = Path("plan") / "prediction.npz"


class PlantSession(Session):
    """A single plant: candidate views on a sphere or hemisphere around the previous model."""

    kind = "plant"
    replans = True

    @classmethod
    def session_config(cls, config: PlantConfig) -> PlantConfig:
        """``config`` as a real session runs it: the planning frame from the previous model, the
        plant at its true size (candidate views and sensor range in metres)."""
        return with_overrides(config, {"scene.frame": "previous", "scene.scale": "native"})

    @classmethod
    def check_organ_targets(cls, config: PlantConfig, organs, name: str) -> None:
        check_organ_targets(config.selection.organ_target_values(), organs, name)

    def _scene(self, previous_scan) -> Known:
        config, name = self.config, self.state["previous_file"]
        frame = planning_frame(previous_scan, config, name)
        frame.view_space.view_index(config.initial_view)  # refuse a bad initial view up front
        previous, organs, reduction = known_from_previous(frame.to_planning(previous_scan), config, name,
                                                          self.previous_organs)
        return Known(previous, frame.sensor, (name, "today's captures"), frame.view_space, frame.plant_from_scan,
                     frame.reference.table_points, reduction, organs)

    def views(self) -> tuple[np.ndarray, np.ndarray]:
        space = self.scene.view_space
        return space.positions, space.look_ats

    def view_index(self, view) -> int:
        space = self.scene.view_space
        try:
            return space.view_index(int(view) if str(view).lstrip("-").isdigit() else view)
        except ConfigError:
            names = f" or a name ({', '.join(sorted(space.initial_views))})" if space.initial_views else ""
            raise ConfigError(f"--pose {view}: not one of this session's views: an index 0..{len(space) - 1}"
                              f"{names}, or a pose file") from None

    def nbv(self):
        """The NBV method with every capture integrated, in order."""
        nbv = start_nbv(self.scene, self.config)
        for view, seen in self.observations():
            nbv.integrate(view, seen)
        return nbv

    def warm_up_views(self) -> int:
        """Captures the warm-up takes: the initial view and ``nbv.warm_up_views`` NBVs."""
        return 1 + self.config.nbv.warm_up_views

    def warm_up_request(self, done: int) -> Request:
        if done == 0:
            return self.pose_request(self.scene.view_space.view_index(self.config.initial_view), "initial view")
        return self.pose_request(int(self.nbv().next_view().view), f"warm-up NBV {done} of {self.warm_up_views() - 1}")

    def _near(self, planning: np.ndarray) -> np.ndarray:
        """Points within the previous model's box grown by half its largest side on every side."""
        lo, hi = self.scene.previous.min(axis=0), self.scene.previous.max(axis=0)
        margin = 0.5 * (hi - lo).max()
        return np.all((planning >= lo - margin) & (planning <= hi + margin), axis=1)

    def _keep(self, keys: np.ndarray) -> np.ndarray:
        """The voxels that reach above the supporting table's top, when the view space has a
        table: it occludes but is not the plant, as in the simulator."""
        table = self.scene.table_points
        if not len(table):
            return np.ones(len(keys), dtype=bool)
        top = table[:, 2].max() + 0.5 * self.config.scene.table_resolution
        resolution = self.config.gt_resolution
        return (keys[:, 2] + 1) * resolution > top + 1e-9 * resolution

    def plan(self, overrides: dict | None = None, progress=None):
        """Plan on the captures (``overrides``: configuration keys for this plan, e.g. the
        coverage target): writes ``plan/`` as ``tpvp plan`` writes its folder (the world frame is
        the scan frame) and returns the :class:`~tpvp.pipeline.plan.PlanResult` (its
        coverages are NaN: there is no ground truth). After captures of a plan's views, the rest
        is re-planned from them (the result's ``replans`` end with this one)."""
        config = with_overrides(self.config, overrides or {})
        self.check_organ_targets(config, self.previous_organs, self.state["previous_file"])  # before any work
        self.check_captured()
        from tpvp.pipeline.outputs import write_plan_outputs  # matplotlib, pandas: only a plan writes figures
        last, captured, nbv = self.state.get("plan"), len(self.captures), self.nbv()
        predicted = self.folder / PREDICTION
        if last and captured > last.get("views_so_far", captured) and predicted.is_file():
            result, prediction, step = replan(self.scene, config, nbv, last["warm_up"], last["planned_views"],
                                              Prediction.from_bytes(predicted.read_bytes()), progress)
            result = replace(result, replans=(*(Replan(**row) for row in last.get("replans", [])), step))
        else:
            transferred = transfer(self.scene, config, nbv, progress)
            surface = planning_surface(self.scene, config, transferred, progress)
            result = plan(self.scene, config, transferred, progress, surface)
            prediction = prediction_of(surface, captured)

        def write(folder):
            write_plan_outputs(folder, self.scene, result, config, name=self.folder.name)
            atomic_write_bytes(folder / PREDICTION.name, prediction.to_bytes())

        self.commit_plan(write, {"planned_views": [int(v) for v in result.planned_views],
                                 "executed_views": [int(v) for v in result.executed_views],
                                 "path_length_planning_m": result.path_length,
                                 "warm_up": len(result.executed_views), "views_so_far": captured,
                                 "replan_after": config.selection.replan_after,
                                 "replans": [step.row() for step in result.replans]})
        return result


KINDS["plant"] = PlantSession
