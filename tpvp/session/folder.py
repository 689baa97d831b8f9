"""A session folder: the previous model, the configuration and today's captures, one step at a time.

``session.json`` (format, version, kind: plant or row, the previous model's file and units, the
captures, the last plan), ``config.yaml`` (the resolved configuration), ``previous.npy`` (the
previous model in the world frame, metres), ``captures/NNN.npy`` (each capture's voxel keys at the
ground-truth resolution, planning frame) and ``plan/`` (the last plan, as ``tpvp plan`` writes it).
Every step rewrites the folder through :func:`tpvp.io.publish.staged_folder`: a crash or Ctrl-C
leaves it as it was after the last finished step. A step holds the folder's lock from its read to
its commit (:meth:`Session.held`), and a commit refuses a state that changed since it was read, so
two commands on one folder never lose a capture. :meth:`Session.open` refuses a damaged folder with
one line (:mod:`tpvp.session.check` lists and repairs). :class:`Session` holds what plants and rows
share; :mod:`tpvp.session.plant` and :mod:`tpvp.session.row` what differs.
"""

from __future__ import annotations

import contextlib
import json
from dataclasses import dataclass
from datetime import datetime, timezone
from io import BytesIO
from pathlib import Path

import numpy as np

from tpvp import __version__
from tpvp.config_loading import config_yaml, load_config
from tpvp.errors import BusyError, ConfigError, InputFileError, PointCloudError, TpvpError, checked_cloud
from tpvp.io import atomic_write_bytes, atomic_write_text, write_point_cloud
from tpvp.io.publish import hold_folder, staged_folder
from tpvp.scene import voxels
from tpvp.fusion.tsdf import DepthFrame, fuse_frames, fusion_config
from tpvp.sensor.camera import Intrinsics, look_at_rotation, rotation_to_quaternion
from tpvp.session.captures import Pose, back_project, surface_voxel_keys
from tpvp.session.check import (DROP_PLAN, FORMAT, ORGANS_FILE, PREDICTION_FILE, STATE, VERSION, Problem,
                                 capture_number, centroid_file, depth_file, folder_problems, prediction_views, state_text)

#: How another command is told to wait for the folder: the session's own advice, not another folder.
BUSY_ADVICE = "run this command again when that one has finished (--wait SECONDS waits longer)"
#: A cloud counts as in the world frame when at least this fraction of its points lies near the plant.
MIN_INSIDE = 0.5
KINDS: dict = {}  # kind -> Session subclass (plant, row), filled by the subclasses' modules


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def npy_bytes(array: np.ndarray) -> bytes:
    buffer = BytesIO()
    np.save(buffer, np.ascontiguousarray(array), allow_pickle=False)
    return buffer.getvalue()


@dataclass(frozen=True)
class Request:
    """The next pose to capture (world frame), or nothing to capture (``view`` None; ``role`` says
    what comes next: ``plan`` or ``export``)."""

    view: int | None
    position: np.ndarray | None = None
    look_at: np.ndarray | None = None
    quaternion: np.ndarray | None = None  # camera-to-world, (x, y, z, w)
    role: str = ""

    def describe(self) -> str:
        if self.view is None:
            return {"export": "every planned view is captured: `tpvp session export` writes today's model",
                    "replan": "planned views were captured (selection.replan_after): run `tpvp session plan` to "
                              "re-plan the rest from them",
                    "close": "every planned view is captured: `tpvp session plan` checks the captures against the "
                             "coverage target and adds the views that close a gap (or `tpvp session export` writes "
                             "today's model as it is)"}.get(self.role, "the warm-up is done: run `tpvp session plan`")
        fmt = lambda v: "(" + ", ".join(f"{x:.4f}" for x in v) + ")"  # noqa: E731
        return (f"next: capture view {self.view} ({self.role}) at {fmt(self.position)} looking at "
                f"{fmt(self.look_at)}, quaternion xyzw {fmt(self.quaternion)} (world frame, m)")


class Session:
    """A session folder. :meth:`start` and :meth:`open` return the plant or row session its
    configuration (``setting``) or state (``kind``) names."""

    kind = ""

    def __init__(self, folder: Path, config, state: dict, previous_scan: np.ndarray,
                 previous_organs: np.ndarray | None = None):
        self.folder, self.config, self.state = Path(folder), config, state
        self.previous_scan, self.previous_organs = previous_scan, previous_organs
        self.scene = self._scene(previous_scan)
        self._read = state_text(state)  # session.json as read: a commit refuses a changed one

    # -- what plants and rows define ----------------------------------------------------------------

    def _scene(self, previous_scan):  # pragma: no cover - abstract
        raise NotImplementedError

    def views(self) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - abstract
        """Positions and look-ats (planning frame) of every view a capture may be taken at."""
        raise NotImplementedError

    def warm_up_request(self, done: int) -> Request:  # pragma: no cover - abstract
        raise NotImplementedError

    def warm_up_views(self) -> int:  # pragma: no cover - abstract
        raise NotImplementedError

    def _near(self, planning: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _keep(self, keys: np.ndarray) -> np.ndarray:
        """Which captured voxels (keys) belong to the plants (all, unless a subclass drops some)."""
        return np.ones(len(keys), dtype=bool)

    # -- the folder -------------------------------------------------------------------------------

    @classmethod
    def start(cls, folder, previous_scan, config, previous_file: str = "previous model", units: str = "m",
              wait: float = 0.0, previous_organs=None) -> "Session":
        """A new session in ``folder`` (new or empty) planning on ``previous_scan`` (metres, its own
        frame: the world frame); ``units``: the units its file was read in, for the captures' files;
        ``wait``: seconds to wait for another command on the folder; ``previous_organs``: the organ
        code of each of its points (:mod:`tpvp.scene.organs`), kept as ``previous_organs.npy``."""
        if config.setting not in KINDS:
            raise ConfigError(f"tpvp session plans {' and '.join(KINDS)} settings, not {config.setting!r}")
        kind = KINDS[config.setting]
        config = kind.session_config(config)
        points = checked_cloud(previous_scan, previous_file)
        if previous_organs is not None:
            previous_organs = np.asarray(previous_organs, dtype=np.int64)
            if previous_organs.shape != (len(points),):
                raise ConfigError(f"{previous_file}: {len(previous_organs)} organ labels for {len(points)} points")
        kind.check_organ_targets(config, previous_organs, str(previous_file))
        state = {"format": FORMAT, "version": VERSION, "tpvp": __version__, "kind": config.setting,
                 "created_utc": _now(), "previous_file": str(previous_file), "units": units, "captures": []}
        if previous_organs is not None:
            state["previous_organs"] = ORGANS_FILE  # named, so that the file deleted is a problem, not "no labels"
        session = kind(folder, config, state, points, previous_organs)
        with cls.locked(folder, wait):
            if (Path(folder) / STATE).is_file():  # checked under the lock: two starts cannot both pass
                raise ConfigError(f"{folder} already holds a session: continue it (`tpvp session add {folder}`), "
                                  f"or start the new one in a new folder")
            with staged_folder(folder, what="session folder") as stage:
                atomic_write_bytes(stage.path("previous.npy"), npy_bytes(points))
                if previous_organs is not None:
                    atomic_write_bytes(stage.path(ORGANS_FILE), npy_bytes(previous_organs))
                atomic_write_text(stage.path("config.yaml"), config_yaml(config, "the session's configuration"))
                atomic_write_text(stage.path(STATE), state_text(state))
        return session

    @staticmethod
    def locked(folder, wait: float = 0.0, on_wait=None):
        """Hold ``folder``'s lock for a block (:func:`tpvp.io.publish.hold_folder`), as a step does."""
        return hold_folder(folder, what="session folder", wait=wait, on_wait=on_wait, advice=BUSY_ADVICE)

    @classmethod
    def problems(cls, folder) -> list:
        """Every problem of the session folder (:func:`tpvp.session.check.folder_problems`); when its
        files are sound, those of the session they make (:meth:`_opened`)."""
        return folder_problems(folder, KINDS) or cls._opened(folder)[1]

    @classmethod
    @contextlib.contextmanager
    def held(cls, folder, wait: float = 0.0, on_wait=None):
        """The session in ``folder`` (:meth:`open`), its lock held for the block: no other command's
        commit falls between this one's read and its own commit. Waits up to ``wait`` seconds for
        another command (``on_wait()`` once if it has to), then :class:`~tpvp.errors.BusyError`."""
        if not (Path(folder) / STATE).is_file():
            cls.open(folder)  # not a session folder: refused before a lock file is made beside it
        with cls.locked(folder, wait, on_wait):
            yield cls.open(folder)

    @classmethod
    def session_config(cls, config):
        return config

    @classmethod
    def check_organ_targets(cls, config, organs, name: str) -> None:
        """Refuse ``config``'s organ targets before any work when this kind plans them (a plant)."""

    @classmethod
    def open(cls, folder) -> "Session":
        """The session in ``folder``; one clear error (:class:`~tpvp.errors.InputFileError`) for a
        folder that is not one, is damaged or is of another version: its first problem and what to
        do (``tpvp session check`` lists them all)."""
        folder = Path(folder)
        problems = folder_problems(folder, KINDS)
        session, more = (None, []) if problems else cls._opened(folder)
        problems += more
        if problems:
            more = (f" ({len(problems) - 1} more: `tpvp session check {folder}` lists them)"
                    if len(problems) > 1 else "")
            raise InputFileError(problems[0].line(folder) + more)
        return session

    @classmethod
    def _opened(cls, folder: Path) -> tuple["Session | None", list[Problem]]:
        """``(the session, [])`` of a folder whose files are sound, or ``(None, its problems)``: what
        only the session they make shows (a view session.json names that it has not; its view space
        or previous model refused)."""
        state = json.loads((folder / STATE).read_text())
        previous = np.load(folder / "previous.npy", allow_pickle=False)
        organs = np.load(folder / ORGANS_FILE, allow_pickle=False) if (folder / ORGANS_FILE).is_file() else None
        try:
            session = KINDS[state["kind"]](folder, load_config(folder / "config.yaml"), state, previous, organs)
        except TpvpError as exc:
            return None, [Problem(f"{folder}: the session cannot be opened: {exc}")]
        views = len(session.views()[0])
        restore = f"restore {folder / STATE} from a backup"
        wrong = [c["view"] for c in session.captures if c["view"] >= views]
        if wrong:
            return None, [Problem(f"{folder / STATE}: a capture of view {wrong[0]}, but this session's views are "
                                  f"0..{views - 1} (edited by hand?)", "restore it from a backup")]
        plan = state.get("plan") or {}
        wrong = [v for v in plan.get("planned_views", []) + plan.get("executed_views", []) if v >= views]
        if wrong:
            return None, [Problem(f"{folder / STATE}: the plan names view {wrong[0]}, but this session's views are "
                                  f"0..{views - 1} (edited by hand?)", restore, repair=DROP_PLAN, drop_plan=True)]
        predicted = prediction_views(folder) if plan and session.kind == "plant" else None
        if predicted not in (None, views):  # a re-plan reads the rows of the views captured
            return None, [Problem(f"{folder / PREDICTION_FILE} is damaged (it predicts what {predicted} views see, "
                                  f"this session has {views})", repair=DROP_PLAN, drop_plan=True)]
        return session, []

    def commit(self, state: dict, files: dict | None = None, write=None) -> None:
        """Write ``files`` (relative name -> bytes or text), what ``write(staging folder)`` writes
        and the new state, in one step. Refused (:class:`~tpvp.errors.BusyError`) when session.json
        changed since this session read it."""
        with staged_folder(self.folder, keep_existing=True, what="session folder") as stage:
            try:
                on_disk = state_text(json.loads(stage.existing(STATE).read_text()))  # formatting aside
            except (OSError, ValueError):
                on_disk = None
            if on_disk != self._read:
                raise BusyError(f"session folder {self.folder} changed since this command read it (another command "
                                f"recorded a step); nothing was written: run this command again")
            for name, data in (files or {}).items():
                writer = atomic_write_text if isinstance(data, str) else atomic_write_bytes
                writer(stage.path(name), data)
            if write is not None:
                write(stage.folder)
            atomic_write_text(stage.path(STATE), state_text(state))
        self.state, self._read = state, state_text(state)

    def commit_plan(self, write_outputs, plan: dict) -> None:
        """Write ``plan/`` (``write_outputs(folder)``) and record ``plan`` in the state, in one step."""
        self.commit(dict(self.state, plan={**plan, "planned_utc": _now()}),
                    write=lambda staged: write_outputs(staged / "plan"))

    # -- poses ------------------------------------------------------------------------------------

    @property
    def captures(self) -> list[dict]:
        return self.state["captures"]

    #: Whether a plan of this kind re-plans from its captures (``selection.replan_after``, and the
    #: closing check of a one-shot plan: role ``close``).
    replans = False

    def request(self) -> Request:
        """The next pose to capture: the warm-up's, then (once planned) the planned views in the
        path's order; none when there is nothing to capture (role ``plan``, ``replan``, ``close``:
        a one-shot plan's views are all captured and not yet checked, or ``export``)."""
        done = len(self.captures)
        if done < self.warm_up_views():
            return self.warm_up_request(done)
        plan = self.state.get("plan")
        if plan is None:
            return Request(None, role="plan")
        captured = {c["view"] for c in self.captures}
        left = [v for v in plan["planned_views"] if v not in captured]
        since = done - plan.get("views_so_far", done)  # captures since the plan (re-planned after K of them)
        every = plan.get("replan_after", 0)
        if every and since and (since >= every or not left):
            return Request(None, role="replan")
        if not left:
            return Request(None, role="close" if self.replans and since else "export")
        number = len(plan["planned_views"]) - len(left) + 1
        return self.pose_request(left[0], f"planned view {number} of {len(plan['planned_views'])}")

    def pose_request(self, view: int, role: str) -> Request:
        pose = self.view_pose(view)
        look_at = self.scene.to_scan(self.views()[1][[view]])[0]
        return Request(int(view), pose[:3, 3], look_at, rotation_to_quaternion(pose[:3, :3]), role)

    def view_pose(self, view: int) -> np.ndarray:
        """The camera-to-world pose of ``view`` (4x4, world frame, metres; OpenCV camera axes)."""
        positions, look_ats = self.views()
        linear = self.scene.plant_from_scan[:3, :3] / self.scene.scan_scale
        pose = np.eye(4)
        pose[:3, :3] = linear.T @ look_at_rotation(positions[view], look_ats[view])
        pose[:3, 3] = self.scene.to_scan(positions[[view]])[0]
        return pose

    def capture_poses(self) -> np.ndarray:
        """Every capture's camera-to-world pose (:meth:`view_pose` of its view), in capture order: (N, 4, 4)."""
        return np.stack([self.view_pose(c["view"]) for c in self.captures]) if self.captures else np.zeros((0, 4, 4))

    def resolve_view(self, view=None, pose: Pose | None = None) -> tuple[int, float]:
        """``(view index, distance from the given pose in m)``: ``view`` (an index, or a name of the
        view space), else the nearest view to ``pose`` (world frame), else the view the session asked for."""
        positions, _ = self.views()
        if pose is not None:
            distance = np.linalg.norm(self.scene.to_scan(positions) - pose.position, axis=1)
            nearest = int(np.argmin(distance))
            return nearest, float(distance[nearest])
        if view is not None:
            return self.view_index(view), 0.0
        asked = self.request()
        if asked.view is None:
            raise ConfigError(f"{self.folder}: no capture is pending ({asked.describe()}); give --pose VIEW for an "
                              f"extra capture")
        return asked.view, 0.0

    def view_index(self, view) -> int:
        positions, _ = self.views()
        if not str(view).lstrip("-").isdigit() or not 0 <= int(view) < len(positions):
            raise ConfigError(f"--pose {view}: not one of this session's views (0..{len(positions) - 1}), nor a pose file")
        return int(view)

    # -- captures ---------------------------------------------------------------------------------

    def capture_keys(self) -> list[np.ndarray]:
        return [np.load(self.folder / c["file"], allow_pickle=False) for c in self.captures]

    def observations(self) -> list[tuple[int, np.ndarray]]:
        """Every capture as planning integrates it: (view, voxel centres in the planning frame)."""
        resolution = self.config.gt_resolution
        return [(c["view"], voxels.key_centres(keys, resolution)) for c, keys in zip(self.captures, self.capture_keys())]

    def add(self, points_world, view: int, source: str) -> dict:
        """Fuse a captured cloud (world frame) taken at ``view``; returns its record."""
        points = checked_cloud(points_world, source)
        planning = self.scene.to_planning(points)
        near = self._near(planning)
        # A cloud is placed by whoever exported it: most of it must lie near the plants.
        if near.mean() < MIN_INSIDE:
            raise PointCloudError(self._far_message(points, near, source))
        keys = voxels.voxel_keys(planning[near], self.config.gt_resolution)
        return self._add_voxels(keys, planning[near], view, source, "cloud", len(points))

    def add_depth(self, depth, intrinsics, view: int, source: str) -> dict:
        """Fuse a depth image (metres) captured at ``view`` with ``intrinsics``. It is placed by the
        view's pose and holds the background too: only the points near the plants count."""
        request = self.pose_request(view, "")
        rotation = look_at_rotation(request.position, request.look_at)
        points, rays = back_project(np.asarray(depth, dtype=np.float64), intrinsics, request.position, rotation,
                                    source)
        planning = self.scene.to_planning(points)
        near = self._near(planning)
        if not near.any():
            raise PointCloudError(f"{source}: no depth of the image lies near the plants ({len(points):,} pixels with "
                                  f"depth); is it the depth of view {view}, in metres (--intrinsics depth_scale)?")
        keys = surface_voxel_keys(planning[near], rays[near] @ self.scene.plant_from_scan[:3, :3].T,
                                  self.config.gt_resolution)
        image = np.nan_to_num(np.asarray(depth, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
        k = intrinsics
        frame = {"depth": image, "camera_to_world": self.view_pose(view),
                 "intrinsics": np.array([k.fx, k.fy, k.cx, k.cy, k.width, k.height], dtype=np.float64)}
        return self._add_voxels(keys, planning[near], view, source, "depth", len(points), frame)

    def _add_voxels(self, keys, points, view, source, kind, total, depth_frame=None) -> dict:
        """Record a capture: its voxels (keys of ``points``, planning frame; code order), those the
        plants hold, the centroid of its points in each (``captures/NNN_centroids.npy``) and, for a
        depth image, the image with its intrinsics and pose (``captures/NNN_depth.npz``)."""
        codes, centroids = voxels.code_centroids(keys, points)
        keys = voxels.decode_keys(codes)
        kept = self._keep(keys)
        keys, centroids = keys[kept], centroids[kept]
        record = {"view": int(view), "file": f"captures/{self._next_capture_number():03d}.npy", "source": str(source),
                  "kind": kind, "points": int(total), "points_kept": int(len(points)), "voxels": int(len(keys)), "added_utc": _now()}
        files = {record["file"]: npy_bytes(keys), centroid_file(record): npy_bytes(centroids)}
        if depth_frame is not None:
            record["depth_image"] = True
            buffer = BytesIO()
            np.savez_compressed(buffer, **depth_frame)
            files[depth_file(record)] = buffer.getvalue()
        self.commit(dict(self.state, captures=[*self.captures, record]), files)
        return record

    def _next_capture_number(self) -> int:
        """One past every capture file's number, recorded or on disk: a capture never replaces a file."""
        names = [c["file"] for c in self.captures]
        if (self.folder / "captures").is_dir():
            names += [p.relative_to(self.folder).as_posix() for p in (self.folder / "captures").iterdir()]
        numbers = [n for n in map(capture_number, names) if n is not None]
        return max(numbers, default=-1) + 1

    def _far_message(self, points, near, source) -> str:
        centre = self.scene.to_scan(self.scene.previous.mean(axis=0, keepdims=True))[0]
        distance = np.linalg.norm(np.median(points, axis=0) - centre)
        extent = self.scene.previous.max(axis=0) - self.scene.previous.min(axis=0)
        size = extent.max() / self.scene.scan_scale
        return (f"{source}: {100 * (1 - near.mean()):.0f} % of the capture's points lie away from the previous "
                f"model (their median is {distance:.3g} m from its centre, the model is {size:.3g} m across); a "
                f"capture must be in the previous model's frame and units (metres as read from "
                f"{self.state['previous_file']}): transform it, or check --units")

    # -- today's model ----------------------------------------------------------------------------

    def fused_model(self) -> np.ndarray:
        """Today's model, world frame: the depth images kept with their captures fused
        (:func:`tpvp.fusion.fuse_frames` at the session's scale, the code of ``tpvp capture fuse``
        and of the simulated season), only what lies near the plants, with the voxel centres of
        every other capture (distinct, key order)."""
        keys = self.capture_keys()
        if not keys:
            raise ConfigError(f"{self.folder}: no capture yet: nothing to export")
        images = [c.get("depth_image", False) for c in self.captures]
        others = [k for k, image in zip(keys, images) if not image]
        model = (self.scene.to_scan(voxels.key_centres(voxels.unique_keys(np.concatenate(others)),
                                                       self.config.gt_resolution)) if others else np.zeros((0, 3)))
        if any(images):
            config = fusion_config(self.kind)
            frames = [self.depth_frame(c, config.max_depth) for c, image in zip(self.captures, images) if image]
            fused = fuse_frames(frames, config, progress=False, source=str(self.folder)).points
            planning = self.scene.to_planning(fused)
            near = self._near(planning)
            near[near] = self._keep(voxels.voxel_keys(planning[near], self.config.gt_resolution))
            model = np.concatenate([fused[near], model])
        return model

    def depth_frame(self, record: dict, max_depth: float) -> DepthFrame:
        """A depth capture's image at the pose it was placed (world frame), as the fusion takes it:
        the background beyond ``max_depth`` (m) dropped."""
        with np.load(self.folder / depth_file(record), allow_pickle=False) as data:
            fx, fy, cx, cy, width, height = data["intrinsics"]
            depth = np.where(data["depth"] <= max_depth, data["depth"], np.float32(0.0))
            return DepthFrame(depth, Intrinsics(fx=fx, fy=fy, cx=cx, cy=cy, width=int(width),
                                                        height=int(height)),
                              data["camera_to_world"], name=record["file"])

    def export(self, path) -> Path:
        """Write today's fused model (world frame; PLY/PCD/XYZ by the extension)."""
        return write_point_cloud(path, self.fused_model())

    def check_captured(self) -> None:
        if not self.captures:
            raise ConfigError(f"{self.folder}: no capture yet: add the first view first (`tpvp session add`)")
