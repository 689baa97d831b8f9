"""A real single-plant session: the previous session's model and today's captures, no ground truth.

A :class:`Session` lives in a folder (``tpvp session start/add/plan/export`` wrap it):

* ``start`` fixes the planning frame from the previous model (``scene.frame = previous``, the
  plant at its true size: ``scene.scale = native``), the candidate views around it, and asks for
  the initial view;
* ``add`` fuses a capture (a cloud in the world frame, or a depth image and its intrinsics) taken
  at a candidate view: its voxels (ground-truth resolution, planning frame) join today's coarse
  reconstruction, and the warm-up NBV (the configured method, free space carved along the rays)
  asks for the next view until the warm-up is done;
* ``plan`` runs registration, inflation, visibility, selection and the exact path on what was
  captured, and writes the plan as ``tpvp plan`` does (``plan/``);
* ``export`` writes today's fused model (every capture's voxel centres, world frame).

The world frame is the previous model's own (metres after ``--units``). Every step rewrites the
folder through :func:`tpvp.io.publish.staged_folder`: a crash or Ctrl-C between or during steps
leaves it as it was after the last finished step. With the same captures, the plan equals the
simulator's plan of the pair with ``scene.frame = previous`` at native scale
(``tests/test_session.py`` renders the captures from today's scan at the poses the session asks).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from tpvp import __version__
from tpvp.config import PlantConfig, config_yaml, load_config, with_overrides
from tpvp.errors import ConfigError, InputFileError, PointCloudError, checked_cloud
from tpvp.experiments.outputs import write_case_outputs
from tpvp.experiments.single_plant import plan_case, transfer
from tpvp.io import atomic_write_bytes, atomic_write_text, write_point_cloud
from tpvp.io.publish import staged_folder
from tpvp.nbv.warm_up import start_nbv
from tpvp.scene import voxels
from tpvp.scene.simulator import planning_frame
from tpvp.sensor.camera import look_at_rotation, rotation_to_quaternion
from tpvp.session.captures import Pose, back_project, surface_voxel_keys

FORMAT = "tpvp-session"
VERSION = 1
STATE = "session.json"
#: A capture counts as in the previous model's frame when at least this fraction of its points lies
#: within the plant's box grown by half its size on every side.
MIN_INSIDE = 0.5


@dataclass(frozen=True, eq=False)
class SessionScene:
    """What a real session knows in the planning frame: the simulator's scene without ground truth."""

    previous: np.ndarray
    view_space: object
    sensor: object
    plant_from_scan: np.ndarray
    table_points: np.ndarray
    names: tuple
    reduction: dict = field(default_factory=dict)

    @property
    def scan_scale(self) -> float:
        return float(np.cbrt(np.linalg.det(self.plant_from_scan[:3, :3])))

    def to_scan(self, points) -> np.ndarray:
        """Planning-frame points in the world (the previous model's) frame."""
        matrix = self.plant_from_scan
        return (np.asarray(points, dtype=np.float64) - matrix[:3, 3]) @ np.linalg.inv(matrix[:3, :3]).T

    def to_planning(self, points) -> np.ndarray:
        matrix = self.plant_from_scan
        return np.asarray(points, dtype=np.float64) @ matrix[:3, :3].T + matrix[:3, 3]


@dataclass(frozen=True)
class Request:
    """The next pose to capture (world frame), or the warm-up being done (``view`` None)."""

    view: int | None
    position: np.ndarray | None = None
    look_at: np.ndarray | None = None
    quaternion: np.ndarray | None = None  # camera-to-world, (x, y, z, w)
    role: str = ""  # initial view, warm-up NBV, planned view

    def describe(self) -> str:
        if self.view is None:
            return ("every planned view is captured: `tpvp session export` writes today's model" if self.role == "export"
                    else "the warm-up is done: run `tpvp session plan`")
        fmt = lambda v: "(" + ", ".join(f"{x:.4f}" for x in v) + ")"  # noqa: E731
        return (f"next: capture view {self.view} ({self.role}) at {fmt(self.position)} looking at "
                f"{fmt(self.look_at)}, quaternion xyzw {fmt(self.quaternion)} (world frame, m)")


def session_config(config: PlantConfig) -> PlantConfig:
    """``config`` as a real session runs it: the planning frame from the previous model, the plant
    at its true size (candidate views and sensor range in metres)."""
    if config.setting != "plant":
        raise ConfigError("tpvp session plans single plants; greenhouse rows are not supported yet")
    return with_overrides(config, {"scene.frame": "previous", "scene.scale": "native"})


class Session:
    """A session folder: the previous model (world frame), the configuration and the captures."""

    def __init__(self, folder: Path, config: PlantConfig, state: dict, previous_scan: np.ndarray):
        self.folder, self.config, self.state = Path(folder), config, state
        self.previous_scan = previous_scan
        frame = planning_frame(previous_scan, config, state["previous_file"])
        previous = frame.to_planning(previous_scan)
        reduced = (voxels.voxel_centroids(previous, config.scene.reduce_resolution)
                   if len(previous) > config.scene.reduce_above else previous)
        self.scene = SessionScene(reduced, frame.view_space, frame.sensor, frame.plant_from_scan,
                                  frame.reference.table_points, (state["previous_file"], "today's captures"),
                                  {"previous_points": len(previous), "previous_points_used": len(reduced)})

    # -- the folder -------------------------------------------------------------------------------

    @classmethod
    def start(cls, folder, previous_scan, config: PlantConfig, previous_file: str = "previous model",
              units: str = "m") -> "Session":
        """A new session in ``folder`` (new or empty) planning on ``previous_scan`` (metres, its own
        frame: the world frame); ``units``: the units its file was read in, for the captures' files."""
        config = session_config(config)
        points = checked_cloud(previous_scan, previous_file)
        state = {"format": FORMAT, "version": VERSION, "tpvp": __version__, "kind": "plant",
                 "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                 "previous_file": str(previous_file), "units": units, "captures": []}
        session = cls(folder, config, state, points)
        session.scene.view_space.view_index(config.initial_view)  # refuse a bad initial view up front
        with staged_folder(folder, what="session folder") as stage:
            buffer = _npy(points)
            atomic_write_bytes(stage.path("previous.npy"), buffer)
            atomic_write_text(stage.path("config.yaml"), config_yaml(config, "the session's configuration"))
            atomic_write_text(stage.path(STATE), json.dumps(state, indent=1) + "\n")
        return session

    @classmethod
    def open(cls, folder) -> "Session":
        """The session in ``folder``; one clear error for a folder that is not one or is of another version."""
        folder = Path(folder)
        state_file = folder / STATE
        if not state_file.is_file():
            raise InputFileError(f"{folder}: not a session folder (no {STATE}); start one with `tpvp session start`")
        try:
            state = json.loads(state_file.read_text())
        except (OSError, ValueError) as exc:
            raise InputFileError(f"{state_file}: unreadable session state ({exc})") from None
        if not isinstance(state, dict) or state.get("format") != FORMAT:
            raise InputFileError(f"{state_file}: not a tpvp session state file")
        if state.get("version") != VERSION:
            raise InputFileError(f"{folder}: a session of format version {state.get('version')!r} (tpvp "
                                 f"{state.get('tpvp', '?')}); this tpvp reads version {VERSION}: finish it with "
                                 f"that version, or start a new session")
        try:
            previous = np.load(folder / "previous.npy", allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputFileError(f"{folder / 'previous.npy'}: unreadable ({exc})") from None
        return cls(folder, load_config(folder / "config.yaml"), state, previous)

    def _commit(self, files: dict, state: dict) -> None:
        """Write ``files`` (relative name -> bytes or text) and the new state in one step."""
        with staged_folder(self.folder, keep_existing=True, what="session folder") as stage:
            for name, data in files.items():
                if isinstance(data, str):
                    atomic_write_text(stage.path(name), data)
                else:
                    atomic_write_bytes(stage.path(name), data)
            atomic_write_text(stage.path(STATE), json.dumps(state, indent=1) + "\n")
        self.state = state

    # -- captures ---------------------------------------------------------------------------------

    @property
    def captures(self) -> list[dict]:
        return self.state["captures"]

    def capture_keys(self) -> list[np.ndarray]:
        return [np.load(self.folder / c["file"], allow_pickle=False) for c in self.captures]

    def observations(self) -> list[tuple[int, np.ndarray]]:
        """Every capture as the NBV integrates it: (view, voxel centres in the planning frame)."""
        resolution = self.config.gt_resolution
        return [(c["view"], voxels.key_centres(keys, resolution)) for c, keys in zip(self.captures, self.capture_keys())]

    def nbv(self):
        """The NBV method with every capture integrated, in order."""
        nbv = start_nbv(self.scene, self.config)
        for view, seen in self.observations():
            nbv.integrate(view, seen)
        return nbv

    def warm_up_views(self) -> int:
        """Captures the warm-up takes: the initial view and ``nbv.warm_up_views`` NBVs."""
        return 1 + self.config.nbv.warm_up_views

    def request(self) -> Request:
        """The next pose to capture: the initial view, a warm-up NBV, then (once planned) the
        planned views in the path's order; None when there is nothing to capture."""
        done = len(self.captures)
        if done >= self.warm_up_views():
            plan = self.state.get("plan")
            if plan is None:
                return Request(None, role="plan")
            captured = {c["view"] for c in self.captures}
            left = [v for v in plan["planned_views"] if v not in captured]
            if not left:
                return Request(None, role="export")
            number = len(plan["planned_views"]) - len(left) + 1
            return self.pose_request(left[0], f"planned view {number} of {len(plan['planned_views'])}")
        space = self.scene.view_space
        if done == 0:
            view, role = space.view_index(self.config.initial_view), "initial view"
        else:
            view, role = int(self.nbv().next_view().view), f"warm-up NBV {done} of {self.warm_up_views() - 1}"
        return self.pose_request(view, role)

    def pose_request(self, view: int, role: str) -> Request:
        space = self.scene.view_space
        position, look_at = self.scene.to_scan(space.positions[[view]])[0], self.scene.to_scan(space.look_ats[[view]])[0]
        matrix = self.scene.plant_from_scan
        linear = matrix[:3, :3] / self.scene.scan_scale
        rotation = linear.T @ look_at_rotation(space.positions[view], space.look_ats[view])
        return Request(int(view), position, look_at, rotation_to_quaternion(rotation), role)

    def resolve_view(self, view=None, pose: Pose | None = None, tolerance: float | None = None) -> tuple[int, float]:
        """``(candidate view index, distance from the given pose in m)``: ``view`` (an index or a
        name), else the nearest candidate to ``pose`` (world frame), else the view the session asked for."""
        space = self.scene.view_space
        if pose is not None:
            positions = self.scene.to_scan(space.positions)
            distance = np.linalg.norm(positions - pose.position, axis=1)
            nearest = int(np.argmin(distance))
            return nearest, float(distance[nearest])
        if view is not None:
            return space.view_index(int(view) if str(view).lstrip("-").isdigit() else view), 0.0
        asked = self.request()
        if asked.view is None:
            raise ConfigError(f"{self.folder}: no capture is pending ({asked.describe()}); give --pose VIEW for an "
                              f"extra capture")
        return asked.view, 0.0

    def add(self, points_world, view: int, source: str) -> dict:
        """Fuse a captured cloud (world frame) taken at candidate ``view``; returns its record."""
        points = checked_cloud(points_world, source)
        planning = self.scene.to_planning(points)
        near = self._near(planning)
        # A cloud is placed by whoever exported it: most of it must lie near the plant.
        if near.mean() < MIN_INSIDE:
            raise PointCloudError(self._far_message(points, near, source))
        keys = self._above_table(voxels.voxelise(planning[near], self.config.gt_resolution))
        return self._add_keys(keys, view, source, "cloud", len(points), int(near.sum()))

    def add_depth(self, depth, intrinsics, view: int, source: str) -> dict:
        """Fuse a depth image (metres) captured at candidate ``view`` with ``intrinsics``. It is
        placed by the view's pose and holds the background too: only the points near the plant count."""
        request = self.pose_request(view, "")
        rotation = look_at_rotation(request.position, request.look_at)
        points, rays = back_project(np.asarray(depth, dtype=np.float64), intrinsics, request.position, rotation,
                                    source)
        planning = self.scene.to_planning(points)
        near = self._near(planning)
        if not near.any():
            raise PointCloudError(f"{source}: no depth of the image lies near the plant ({len(points):,} pixels with "
                                  f"depth); is it the depth of view {view}, in metres (--intrinsics depth_scale)?")
        keys = surface_voxel_keys(planning[near], rays[near] @ self.scene.plant_from_scan[:3, :3].T,
                                  self.config.gt_resolution)
        keys = self._above_table(voxels.unique_keys(keys))
        return self._add_keys(keys, view, source, "depth", len(points), int(near.sum()))

    def _add_keys(self, keys, view, source, kind, points, kept) -> dict:
        index = len(self.captures)
        record = {"view": int(view), "file": f"captures/{index:03d}.npy", "source": str(source), "kind": kind,
                  "points": int(points), "points_kept": kept, "voxels": int(len(keys)),
                  "added_utc": datetime.now(timezone.utc).isoformat(timespec="seconds")}
        state = dict(self.state, captures=[*self.captures, record])
        self._commit({record["file"]: _npy(keys)}, state)
        return record

    def _near(self, planning: np.ndarray) -> np.ndarray:
        """Points within the previous model's box grown by half its largest side on every side."""
        lo, hi = self.scene.previous.min(axis=0), self.scene.previous.max(axis=0)
        margin = 0.5 * (hi - lo).max()
        return np.all((planning >= lo - margin) & (planning <= hi + margin), axis=1)

    def _above_table(self, keys: np.ndarray) -> np.ndarray:
        """The voxels (keys) that reach above the supporting table's top, when the view space has
        a table: it occludes but is not the plant, as in the simulator."""
        table = self.scene.table_points
        if not len(table):
            return keys
        top = table[:, 2].max() + 0.5 * self.config.scene.table_resolution
        resolution = self.config.gt_resolution
        return keys[(keys[:, 2] + 1) * resolution > top + 1e-9 * resolution]

    def _far_message(self, points, near, source) -> str:
        centre = self.scene.to_scan(np.zeros((1, 3)))[0]
        distance = np.linalg.norm(np.median(points, axis=0) - centre)
        size = self.config.scene.largest_side / self.scene.scan_scale
        return (f"{source}: {100 * (1 - near.mean()):.0f} % of the capture's points lie away from the previous "
                f"model (their median is {distance:.3g} m from its centre, the plant is {size:.3g} m across); a "
                f"capture must be in the previous model's frame and units (metres as read from "
                f"{self.state['previous_file']}): transform it, or check --units")

    # -- planning ---------------------------------------------------------------------------------

    def plan(self, overrides: dict | None = None, progress=None):
        """Plan on the captures (``overrides``: configuration keys for this plan, e.g. the
        coverage target): writes ``plan/`` as ``tpvp plan`` writes its folder (the world frame is
        the scan frame) and returns the :class:`~tpvp.experiments.single_plant.CaseResult`
        (its coverages are NaN: there is no ground truth)."""
        if len(self.captures) == 0:
            raise ConfigError(f"{self.folder}: no capture yet: add the initial view first (`tpvp session add`)")
        config = with_overrides(self.config, overrides or {})
        nbv = self.nbv()
        transferred = transfer(self.scene, config, progress, nbv=nbv)
        result = plan_case(self.scene, config, progress, transferred)
        with staged_folder(self.folder, keep_existing=True, what="session folder") as stage:
            (stage.folder / "plan").mkdir(exist_ok=True)
            write_case_outputs(stage.folder / "plan", self.scene, result, config, name=f"session {self.folder.name}")
            state = dict(self.state, plan={"planned_views": [int(v) for v in result.planned_views],
                                           "executed_views": [int(v) for v in result.executed_views],
                                           "path_length_planning_m": result.path_length,
                                           "planned_utc": datetime.now(timezone.utc).isoformat(timespec="seconds")})
            atomic_write_text(stage.path(STATE), json.dumps(state, indent=1) + "\n")
        self.state = state
        return result

    def fused_model(self) -> np.ndarray:
        """Today's model: the voxel centres of every capture (distinct, key order), world frame."""
        keys = self.capture_keys()
        if not keys:
            raise ConfigError(f"{self.folder}: no capture yet: nothing to export")
        fused = voxels.unique_keys(np.concatenate(keys))
        return self.scene.to_scan(voxels.key_centres(fused, self.config.gt_resolution))

    def export(self, path) -> Path:
        """Write today's fused model (world frame; PLY/PCD/XYZ by the extension)."""
        return write_point_cloud(path, self.fused_model())


def _npy(array: np.ndarray) -> bytes:
    from io import BytesIO

    buffer = BytesIO()
    np.save(buffer, np.ascontiguousarray(array), allow_pickle=False)
    return buffer.getvalue()
