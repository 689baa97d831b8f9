"""A real greenhouse-row session: the room's passive sweep captured, then the row pipeline.

``start`` with a room's view space (``room1``, ``room4``; the world frame is the room's, metres,
as the datasets' rows are aligned) asks for the 15 passive-sweep views in order; ``add`` fuses each
capture; ``plan`` runs the row pipeline on what was captured (warp-field registration, voxel
inflation, the transfer look-at prior's candidates, set cover at the covering voxel with the
passive views as executed, band path from the end of the sweep) and asks for the planned views.
With the same captures the plan equals the simulator's (:func:`tpvp.simulate.greenhouse.run_row_case`):
both run :func:`tpvp.pipeline.plan.plan`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tpvp.config import RowConfig
from tpvp.config_loading import with_overrides
from tpvp.errors import ConfigError
from tpvp.pipeline.plan import Known, plan
from tpvp.scene import voxels
from tpvp.scene.boxes import room_config
from tpvp.scene.frame import check_row
from tpvp.session.check import centroid_file
from tpvp.session.folder import KINDS, Request, Session


@dataclass(frozen=True, eq=False)
class RowSessionScene:
    """A row session's frame and what it knows before the captures: the room (its frame is the
    world and the planning frame) and the previous session as voxel centroids."""

    room: object  # tpvp.scene.boxes.RoomConfig
    previous: np.ndarray
    sensor: object
    names: tuple
    plant_from_scan: np.ndarray = field(default_factory=lambda: np.eye(4))
    scan_scale: float = 1.0

    def to_scan(self, points) -> np.ndarray:
        return np.asarray(points, dtype=np.float64)

    to_planning = to_scan


class RowSession(Session):
    """A greenhouse row in a room: the passive sweep, then the planned 6D views."""

    kind = "row"

    def _scene(self, previous_scan) -> RowSessionScene:
        room = room_config(self.config.view_space)
        name = self.state["previous_file"]
        check_row(previous_scan, name, room)
        return RowSessionScene(room, voxels.voxel_centroids(previous_scan, self.config.gt_resolution),
                               self.config.sensor, (name, "today's captures"))

    def views(self) -> tuple[np.ndarray, np.ndarray]:
        """The passive views (0..14), then the last plan's views in execution order."""
        room, plan = self.scene.room, self.state.get("plan") or {}
        planned = np.asarray(plan.get("positions", []), dtype=np.float64).reshape(-1, 3)
        looks = np.asarray(plan.get("look_ats", []), dtype=np.float64).reshape(-1, 3)
        return np.concatenate([room.initial_positions, planned]), np.concatenate([room.initial_look_ats, looks])

    def warm_up_views(self) -> int:
        return len(self.scene.room.initial_positions)

    def warm_up_request(self, done: int) -> Request:
        return self.pose_request(done, f"passive sweep view {done + 1} of {self.warm_up_views()}")

    def _near(self, planning: np.ndarray) -> np.ndarray:
        """Points within the cube around the room's plant box (inflation's region of interest)."""
        box = self.scene.room.plant_box
        return np.all(np.abs(planning - box.center) <= 1.5 * box.half_extent.max(), axis=1)

    def known(self) -> Known:
        """What the planner knows from the passive captures: the coarse reconstruction (key
        order; per voxel the centroid of the points the first passive view that saw it captured
        there, or the voxel centre: ``config.coarse``) and, per voxel, that view's position."""
        passive = sorted((c["view"], i) for i, c in enumerate(self.captures) if c["view"] < self.warm_up_views())
        if not passive:
            raise ConfigError(f"{self.folder}: no passive-sweep capture yet: add view 0 first (`tpvp session add`)")
        centroids = self.config.coarse == "centroids"
        captures = [(view, voxels.encode_keys(np.load(self.folder / self.captures[i]["file"], allow_pickle=False)),
                     np.load(self.folder / centroid_file(self.captures[i]), allow_pickle=False) if centroids else None)
                    for view, i in passive]
        coarse, first = voxels.first_seen(captures, self.config.gt_resolution)
        room = self.scene.room
        return Known(self.scene.previous, self.config.sensor, self.scene.names, room=room, coarse=coarse,
                     passive_cameras=room.initial_positions[first])

    def plan(self, overrides: dict | None = None, progress=None):
        """Plan on the passive captures: writes ``plan/`` as ``tpvp greenhouse`` writes its folder
        and returns the :class:`~tpvp.pipeline.plan.PlanResult` (coverages NaN)."""
        self.check_captured()
        from tpvp.pipeline.outputs import write_row_plan_outputs  # matplotlib, pandas: only a plan writes figures
        config: RowConfig = with_overrides(self.config, overrides or {})
        known = self.known()
        result = plan(known, config, progress=progress)
        n = self.warm_up_views()
        self.commit_plan(lambda folder: write_row_plan_outputs(folder, known, result, config,
                                                               name=self.folder.name),
                         {"planned_views": list(range(n, n + len(result.planned_views))),
                          "positions": result.positions.tolist(), "look_ats": result.look_ats.tolist(),
                          "path_length_m": result.path_length})
        return result


KINDS["row"] = RowSession
