"""A session folder: the previous model, the configuration and today's captures, one step at a time.

``session.json`` (format, version, kind: plant or row, the previous model's file and units, the
captures, the last plan), ``config.yaml`` (the resolved configuration), ``previous.npy`` (the
previous model in the world frame, metres), ``captures/NNN.npy`` (each capture's voxel keys at the
ground-truth resolution, planning frame) and ``plan/`` (the last plan, as ``tpvp plan`` writes it).
Every step rewrites the folder through :func:`tpvp.io.publish.staged_folder`: a crash or Ctrl-C
leaves it as it was after the last finished step. :class:`Session` holds what plants and rows
share; :mod:`tpvp.session.plant` and :mod:`tpvp.session.row` what differs.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import datetime, timezone
from io import BytesIO
from pathlib import Path

import numpy as np

from tpvp import __version__
from tpvp.config import config_yaml, load_config
from tpvp.errors import ConfigError, InputFileError, PointCloudError, checked_cloud
from tpvp.io import atomic_write_bytes, atomic_write_text, write_point_cloud
from tpvp.io.publish import staged_folder
from tpvp.scene import voxels
from tpvp.sensor.camera import look_at_rotation, rotation_to_quaternion
from tpvp.session.captures import Pose, back_project, surface_voxel_keys

FORMAT = "tpvp-session"
VERSION = 1
STATE = "session.json"
#: A cloud counts as in the world frame when at least this fraction of its points lies near the plant.
MIN_INSIDE = 0.5
KINDS: dict = {}  # kind -> Session subclass (plant, row), filled by the subclasses' modules


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def npy_bytes(array: np.ndarray) -> bytes:
    buffer = BytesIO()
    np.save(buffer, np.ascontiguousarray(array), allow_pickle=False)
    return buffer.getvalue()


def centroid_file(record: dict) -> str:
    """The file of a capture's per-voxel point centroids, beside its voxel keys."""
    return record["file"].replace(".npy", "_centroids.npy")


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
            return ("every planned view is captured: `tpvp session export` writes today's model" if self.role == "export"
                    else "the warm-up is done: run `tpvp session plan`")
        fmt = lambda v: "(" + ", ".join(f"{x:.4f}" for x in v) + ")"  # noqa: E731
        return (f"next: capture view {self.view} ({self.role}) at {fmt(self.position)} looking at "
                f"{fmt(self.look_at)}, quaternion xyzw {fmt(self.quaternion)} (world frame, m)")


class Session:
    """A session folder. :meth:`start` and :meth:`open` return the plant or row session its
    configuration (``setting``) or state (``kind``) names."""

    kind = ""

    def __init__(self, folder: Path, config, state: dict, previous_scan: np.ndarray):
        self.folder, self.config, self.state = Path(folder), config, state
        self.previous_scan = previous_scan
        self.scene = self._scene(previous_scan)

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
    def start(cls, folder, previous_scan, config, previous_file: str = "previous model", units: str = "m") -> "Session":
        """A new session in ``folder`` (new or empty) planning on ``previous_scan`` (metres, its own
        frame: the world frame); ``units``: the units its file was read in, for the captures' files."""
        if config.setting not in KINDS:
            raise ConfigError(f"tpvp session plans {' and '.join(KINDS)} settings, not {config.setting!r}")
        if (Path(folder) / STATE).is_file():
            raise ConfigError(f"{folder} already holds a session: continue it (`tpvp session add {folder}`), or start "
                              f"the new one in a new folder")
        kind = KINDS[config.setting]
        config = kind.session_config(config)
        points = checked_cloud(previous_scan, previous_file)
        state = {"format": FORMAT, "version": VERSION, "tpvp": __version__, "kind": config.setting,
                 "created_utc": _now(), "previous_file": str(previous_file), "units": units, "captures": []}
        session = kind(folder, config, state, points)
        with staged_folder(folder, what="session folder") as stage:
            atomic_write_bytes(stage.path("previous.npy"), npy_bytes(points))
            atomic_write_text(stage.path("config.yaml"), config_yaml(config, "the session's configuration"))
            atomic_write_text(stage.path(STATE), json.dumps(state, indent=1) + "\n")
        return session

    @classmethod
    def session_config(cls, config):
        return config

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
        if state.get("version") != VERSION or state.get("kind") not in KINDS:
            raise InputFileError(f"{folder}: a session of format version {state.get('version')!r} (tpvp "
                                 f"{state.get('tpvp', '?')}); this tpvp reads version {VERSION}: finish it with "
                                 f"that version, or start a new session")
        try:
            previous = np.load(folder / "previous.npy", allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputFileError(f"{folder / 'previous.npy'}: unreadable ({exc})") from None
        return KINDS[state["kind"]](folder, load_config(folder / "config.yaml"), state, previous)

    def commit(self, state: dict, files: dict | None = None, write=None) -> None:
        """Write ``files`` (relative name -> bytes or text), what ``write(staging folder)`` writes
        and the new state, in one step."""
        with staged_folder(self.folder, keep_existing=True, what="session folder") as stage:
            for name, data in (files or {}).items():
                writer = atomic_write_text if isinstance(data, str) else atomic_write_bytes
                writer(stage.path(name), data)
            if write is not None:
                write(stage.folder)
            atomic_write_text(stage.path(STATE), json.dumps(state, indent=1) + "\n")
        self.state = state

    def commit_plan(self, write_outputs, plan: dict) -> None:
        """Write ``plan/`` (``write_outputs(folder)``) and record ``plan`` in the state, in one step."""
        self.commit(dict(self.state, plan={**plan, "planned_utc": _now()}),
                    write=lambda staged: write_outputs(staged / "plan"))

    # -- poses ------------------------------------------------------------------------------------

    @property
    def captures(self) -> list[dict]:
        return self.state["captures"]

    def request(self) -> Request:
        """The next pose to capture: the warm-up's, then (once planned) the planned views in the
        path's order; none when there is nothing to capture."""
        done = len(self.captures)
        if done < self.warm_up_views():
            return self.warm_up_request(done)
        plan = self.state.get("plan")
        if plan is None:
            return Request(None, role="plan")
        captured = {c["view"] for c in self.captures}
        left = [v for v in plan["planned_views"] if v not in captured]
        if not left:
            return Request(None, role="export")
        number = len(plan["planned_views"]) - len(left) + 1
        return self.pose_request(left[0], f"planned view {number} of {len(plan['planned_views'])}")

    def pose_request(self, view: int, role: str) -> Request:
        positions, look_ats = self.views()
        position, look_at = self.scene.to_scan(positions[[view]])[0], self.scene.to_scan(look_ats[[view]])[0]
        linear = self.scene.plant_from_scan[:3, :3] / self.scene.scan_scale
        rotation = linear.T @ look_at_rotation(positions[view], look_ats[view])
        return Request(int(view), position, look_at, rotation_to_quaternion(rotation), role)

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
            raise ConfigError(f"--pose {view}: this session's views are 0..{len(positions) - 1}")
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
        return self._add_voxels(keys, planning[near], view, source, "depth", len(points))

    def _add_voxels(self, keys, points, view, source, kind, total) -> dict:
        """Record a capture: its voxels (keys of ``points``, planning frame; code order), those the
        plants hold, and the centroid of its points in each (``captures/NNN_centroids.npy``)."""
        codes, inverse = np.unique(voxels.encode_keys(keys), return_inverse=True)
        counts = np.bincount(inverse, minlength=len(codes)).astype(np.float64)
        centroids = np.stack([np.bincount(inverse, weights=points[:, a], minlength=len(codes)) for a in range(3)],
                             axis=1) / counts[:, None]
        keys = voxels.decode_keys(codes)
        kept = self._keep(keys)
        keys, centroids = keys[kept], centroids[kept]
        index = len(self.captures)
        record = {"view": int(view), "file": f"captures/{index:03d}.npy", "source": str(source), "kind": kind,
                  "points": int(total), "points_kept": int(len(points)), "voxels": int(len(keys)), "added_utc": _now()}
        self.commit(dict(self.state, captures=[*self.captures, record]),
                    {record["file"]: npy_bytes(keys), centroid_file(record): npy_bytes(centroids)})
        return record

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
        """Today's model: the voxel centres of every capture (distinct, key order), world frame."""
        keys = self.capture_keys()
        if not keys:
            raise ConfigError(f"{self.folder}: no capture yet: nothing to export")
        fused = voxels.unique_keys(np.concatenate(keys))
        return self.scene.to_scan(voxels.key_centres(fused, self.config.gt_resolution))

    def export(self, path) -> Path:
        """Write today's fused model (world frame; PLY/PCD/XYZ by the extension)."""
        return write_point_cloud(path, self.fused_model())

    def check_captured(self) -> None:
        if not self.captures:
            raise ConfigError(f"{self.folder}: no capture yet: add the first view first (`tpvp session add`)")
