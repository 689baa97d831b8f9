"""A stand-in phone: captures of a generated plant or row written in the layouts
:mod:`data_tools.capture.formats` reads, to check an import before a real scan (and for the tests).

The scene: a generated tomato or maize (:mod:`tpvp.synthetic.plants`) scaled to a real plant's
size, or a generated greenhouse row (:mod:`tpvp.synthetic.greenhouse`), coloured by organ. The
camera: an orbit around the plant (rings of views at three heights, as a person walks around a pot
holding the phone) or the handheld walk along the row's aisle
(:func:`tpvp.synthetic.scan.handheld_trajectory`). Depth is the project's pixel sensor (first
surface along every pixel ray, :func:`tpvp.sensor.sensor.depth_image`) over the scene voxelised at
``render_voxel``, at a phone LiDAR's 256 x 192 pixels; the colour image is the same render at twice
that size, the colour of the voxel each pixel sees; the confidence is high wherever there is depth.
Depth and poses are exact unless a noise profile is named (:func:`noisy_frames`: a phone LiDAR's
depth errors and ARKit-like pose errors, :func:`tpvp.sensor.noise.apply_depth_noise`).

Beside the capture, ``truth.ply`` holds the generated points in the capture's world frame with
label 1 where the capture saw them (their voxel was seen by at least one frame), else 0; for a
plant, ``today.ply`` holds the same plant two days later, in the same frame: ``tpvp plan --previous
cloud.ply --current today.ply`` plans today's session from the fused capture.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from data_tools.capture.formats import ARKIT_TO_Z_UP
from data_tools.errors import ConfigError
from tpvp.export.images import frame_names
from tpvp.export.nerfstudio import nerfstudio_transforms
from tpvp.io import atomic_write_bytes, atomic_write_text, write_point_cloud
from tpvp.io.publish import staged_folder
from tpvp.scene import voxels
from tpvp.scene.grid import build_grid
from tpvp.sensor.camera import PIXEL_CENTRE, Intrinsics, look_at_rotation, switch_camera_axes
from tpvp.sensor.sensor import SensorConfig, depth_image
from tpvp.synthetic.scan import PHONE_LIDAR

#: A phone LiDAR's depth held landscape (:data:`tpvp.synthetic.scan.PHONE_LIDAR` turned).
PHONE_LANDSCAPE = Intrinsics(fx=212.0, fy=212.0, cx=128.0, cy=96.0, width=256, height=192)
IMAGE_SCALE = 2  # the colour image's size over the depth's
ORGAN_COLOURS = {"stem": (96, 120, 48), "petiole": (120, 160, 60), "blade": (50, 140, 40), "fruit": (200, 40, 30)}
ROW_LABEL_KINDS = ("stem", "blade", "fruit", "petiole")  # tpvp.synthetic.greenhouse labels 0..3
BACKGROUND = (200, 200, 205)
SCENES = ("plant", "row")


@dataclass(frozen=True)
class StandinScene:
    """What the stand-in phone films: points (metres, z up), their colours, the camera path."""

    points: np.ndarray
    colours: np.ndarray
    positions: np.ndarray
    look_ats: np.ndarray
    intrinsics: Intrinsics
    render_voxel: float
    max_range: float
    today: np.ndarray | None = None  # a plant's next session (same frame), for a plan from the capture


def plant_scene(species: str = "tomato", seed: int = 0, size: float = 0.4, frames: int = 120,
                days: float = 2.0) -> StandinScene:
    """A generated plant scaled to a largest side of ``size`` metres (stem base at the origin),
    filmed on an orbit (:func:`orbit_scene`); ``today`` is the same plant ``days`` later at the
    same scale, the session a plan from the capture would be for."""
    from tpvp.synthetic.plants import generate_session_pair

    if not size > 0:
        raise ConfigError(f"stand-in plant: size must be > 0 m, got {size!r}")
    pair = generate_session_pair(species, seed, days)
    plant = pair.previous
    scale = size / (plant.points.max(axis=0) - plant.points.min(axis=0)).max()
    return replace(orbit_scene(plant.points * scale, organ_colours(plant), frames), today=pair.current.points * scale)


def organ_colours(plant) -> np.ndarray:
    """``(N, 3)`` uint8: a generated plant's points coloured by the kind of their part."""
    kinds = np.asarray(plant.part_kinds)[plant.part]
    return np.array([ORGAN_COLOURS[k] for k in kinds], dtype=np.uint8)


def orbit_scene(points, colours, frames: int = 120) -> StandinScene:
    """A plant (metres, z up) filmed from ``frames`` views on three rings around it, 15, 40 and 65
    degrees up at 1.5 times its largest side, as a person walks around a pot holding the phone."""
    if int(frames) < 3:
        raise ConfigError(f"stand-in plant: frames must be >= 3, got {frames!r}")
    points = np.asarray(points, dtype=np.float64)
    size = float((points.max(axis=0) - points.min(axis=0)).max())
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    rings = np.radians([15.0, 40.0, 65.0])
    per_ring = np.diff(np.linspace(0, int(frames), len(rings) + 1).astype(int))
    positions = []
    for elevation, count in zip(rings, per_ring):
        azimuth = np.linspace(0, 2 * np.pi, count, endpoint=False) + elevation  # rings start apart
        positions.append(np.column_stack([np.cos(azimuth) * np.cos(elevation), np.sin(azimuth) * np.cos(elevation),
                                          np.full(count, np.sin(elevation))]) * 1.5 * size + centre)
    positions = np.concatenate(positions)
    return StandinScene(points, colours, positions, np.broadcast_to(centre, positions.shape).copy(),
                        PHONE_LANDSCAPE, render_voxel=size / 400, max_range=3 * size)


def row_scene(room: str = "room1", seed: int = 0) -> StandinScene:
    """A generated row (its first session) filmed along the handheld walk of the room's aisle."""
    from tpvp.scene.boxes import room_config
    from tpvp.synthetic.greenhouse import generate_row
    from tpvp.synthetic.scan import HandheldCapture, handheld_trajectory

    row = generate_row(room, seed, 0, point_spacing=0.004)
    colours = np.array([ORGAN_COLOURS[k] for k in ROW_LABEL_KINDS], dtype=np.uint8)[row.labels]
    capture = HandheldCapture()
    positions, look_ats = handheld_trajectory(room_config(room), capture)
    return StandinScene(np.asarray(row.points), colours, positions, look_ats, PHONE_LIDAR, render_voxel=0.004,
                        max_range=capture.max_range)


def render(scene: StandinScene, progress: bool = True):
    """Every frame of the stand-in: ``(camera_to_world, depth, colour)`` with the OpenCV pose, the
    depth in metres (NaN: none) at ``scene.intrinsics`` and the colour image at :data:`IMAGE_SCALE`
    times its size; then the mask of the points some frame saw."""
    keys = voxels.voxel_keys(scene.points, scene.render_voxel)
    grid = build_grid(keys, scene.render_voxel)
    ids = grid.ids_of(keys)
    counts = np.bincount(ids, minlength=grid.size)
    voxel_colours = np.stack([np.bincount(ids, scene.colours[:, c], grid.size) for c in range(3)], axis=1)
    voxel_colours = np.vstack([np.rint(voxel_colours / np.maximum(counts, 1)[:, None]), [BACKGROUND]]).astype(np.uint8)
    k = scene.intrinsics
    depth_sensor = SensorConfig(model="pixel", max_range=scene.max_range, intrinsics=k)
    image_sensor = replace(depth_sensor, intrinsics=image_intrinsics(k))
    seen = np.zeros(grid.size, dtype=bool)
    frames = []
    from tqdm.auto import tqdm

    views = zip(scene.positions, scene.look_ats)
    for position, look_at in tqdm(views, total=len(scene.positions), desc="rendering", unit="frame",
                                  disable=not progress):
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = look_at_rotation(position, look_at), position
        depth, hit = depth_image(grid, position, look_at, depth_sensor)
        seen[hit[hit >= 0]] = True
        _, image_hit = depth_image(grid, position, look_at, image_sensor)
        depth[~np.isfinite(depth)] = np.nan
        frames.append((pose, depth, voxel_colours[image_hit]))  # -1 (nothing) picks the background
    return frames, seen[ids]


def _png(array: np.ndarray) -> bytes:
    from PIL import Image  # matplotlib's dependency

    buffer = io.BytesIO()
    Image.fromarray(array).save(buffer, format="PNG")
    return buffer.getvalue()


def _jpeg(array: np.ndarray) -> bytes:
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(array).save(buffer, format="JPEG", quality=95)
    return buffer.getvalue()


def _millimetres(depth: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(depth), np.rint(depth * 1000.0), 0).clip(0, 65535).astype(np.uint16)


def _confidence(depth: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(depth) & (depth > 0), 2, 0).astype(np.uint8)  # a dropout (0) is no depth


def image_intrinsics(depth: Intrinsics) -> Intrinsics:
    """The colour image's intrinsics: the depth camera's at :data:`IMAGE_SCALE` times its size."""
    return depth.resized(depth.width * IMAGE_SCALE, depth.height * IMAGE_SCALE)


def _write_nerfstudio(folder: Path, scene: StandinScene, frames) -> None:
    names = frame_names(len(frames))
    transforms = nerfstudio_transforms([pose for pose, _, _ in frames], image_intrinsics(scene.intrinsics), names)
    del transforms["ply_file_path"]  # no initial points: the capture is what makes them
    for name, entry, (_, depth, colour) in zip(names, transforms["frames"], frames):
        atomic_write_bytes(folder / entry["file_path"], _png(colour))
        entry["depth_file_path"] = f"depth/{name}"
        atomic_write_bytes(folder / entry["depth_file_path"], _png(_millimetres(depth)))
    atomic_write_text(folder / "transforms.json", json.dumps(transforms, indent=2) + "\n")


def _write_polycam(folder: Path, scene: StandinScene, frames) -> None:
    k = image_intrinsics(scene.intrinsics)
    z_up_to_arkit = np.linalg.inv(ARKIT_TO_Z_UP)
    for i, (pose, depth, colour) in enumerate(frames):
        name = f"{1_000_000 + 100_000 * i}"  # Polycam names keyframes by their timestamp
        arkit = z_up_to_arkit @ switch_camera_axes(pose)
        camera = {"blur_score": 100.0, "fx": k.fx, "fy": k.fy, "cx": k.cx + PIXEL_CENTRE, "cy": k.cy + PIXEL_CENTRE,
                  "width": k.width, "height": k.height,
                  "timestamp": int(name), **{f"t_{r}{c}": float(arkit[r, c]) for r in range(3) for c in range(4)}}
        root = folder / "keyframes"
        atomic_write_text(root / "cameras" / f"{name}.json", json.dumps(camera, indent=2) + "\n")
        atomic_write_bytes(root / "images" / f"{name}.jpg", _jpeg(colour))
        atomic_write_bytes(root / "depth" / f"{name}.png", _png(_millimetres(depth)))
        atomic_write_bytes(root / "confidence" / f"{name}.png", _png(_confidence(depth)))


def _write_depth_folder(folder: Path, scene: StandinScene, frames) -> None:
    k = scene.intrinsics
    atomic_write_text(folder / "intrinsics.yaml", f"fx: {k.fx}\nfy: {k.fy}\ncx: {k.cx}\ncy: {k.cy}\n"
                                                  f"width: {k.width}\nheight: {k.height}\ndepth_scale: 0.001\n")
    for i, (pose, depth, colour) in enumerate(frames):
        name = f"{i:06d}"
        atomic_write_bytes(folder / "depth" / f"{name}.png", _png(_millimetres(depth)))
        atomic_write_bytes(folder / "color" / f"{name}.png", _png(colour))
        atomic_write_bytes(folder / "confidence" / f"{name}.png", _png(_confidence(depth)))
        atomic_write_text(folder / "poses" / f"{name}.txt", "\n".join(" ".join(f"{v:.17g}" for v in row)
                                                                     for row in pose) + "\n")


WRITERS = {"nerfstudio": _write_nerfstudio, "polycam": _write_polycam, "depth": _write_depth_folder}


def _profile(noise):
    """The noise profile ``noise`` names, or ``noise`` itself when it is a profile."""
    from tpvp.sensor.noise import NoiseProfile, noise_profile

    return noise if isinstance(noise, NoiseProfile) else noise_profile(noise)


def noisy_frames(frames, intrinsics: Intrinsics, noise="ideal", seed: int = 0) -> list:
    """``frames`` (:func:`render`'s) as the sensor and tracking of noise profile ``noise`` (a name
    in :data:`tpvp.sensor.noise.NOISE_PROFILES`, or a :class:`~tpvp.sensor.noise.NoiseProfile`) report them: frame i's depth through
    :func:`tpvp.sensor.noise.apply_depth_noise` with ``default_rng([seed, i])`` (the drift's
    direction from ``seed``), its pose the reported one; the colour stays. ``ideal``: ``frames``
    unchanged. An unknown profile is one error line listing the choices."""
    from tpvp.sensor.noise import apply_depth_noise

    profile = _profile(noise)
    if profile.ideal:
        return list(frames)
    out = []
    for i, (pose, depth, colour) in enumerate(frames):
        depth, pose = apply_depth_noise(profile, depth, intrinsics, pose, i, len(frames),
                                        np.random.default_rng([int(seed), i]), drift_seed=int(seed))
        out.append((pose, depth, colour))
    return out


def write_standin(output, fmt: str, scene: StandinScene, progress: bool = True, force: bool = False,
                  noise="ideal", noise_seed: int = 0) -> Path:
    """Render ``scene`` and write it as a ``fmt`` capture (:data:`WRITERS`) with its ``truth.ply``
    into ``output``, published whole; returns the folder. ``noise``, ``noise_seed``: the depth and
    pose errors of :func:`noisy_frames`, a profile's name or the profile (``truth.ply`` and its
    labels stay exact)."""
    if fmt not in WRITERS:
        raise ConfigError(f"unknown capture format {fmt!r}; choose one of {', '.join(WRITERS)}")
    _profile(noise)  # an unknown profile is refused before any rendering
    output = Path(output)
    if output.exists() and any(output.iterdir()) and not force:
        raise ConfigError(f"{output} exists and is not empty: pass --force to replace it, or choose another folder")
    frames, seen = render(scene, progress)
    frames = noisy_frames(frames, scene.intrinsics, noise, noise_seed)
    with staged_folder(output, what="capture folder") as stage:
        WRITERS[fmt](stage.folder, scene, frames)
        write_point_cloud(stage.path("truth.ply"), scene.points, labels=seen.astype(np.int64), colors=scene.colours)
        if scene.today is not None:
            write_point_cloud(stage.path("today.ply"), scene.today)
    return output
