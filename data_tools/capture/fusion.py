"""Depth frames fused into one coloured surface cloud: Open3D's TSDF integration.

Each frame's depth (metres, past ``max_depth`` and below the confidence floor dropped) is
integrated with its colour at its camera-to-world pose into a TSDF volume of ``voxel_size`` voxels
truncated at ``truncation``; its zero level is extracted (:func:`surface_samples`: the voxel edges'
crossings and its marching-cubes mesh sampled every ``spacing``); the points some frame
measured (:func:`supported`) are the surface, in metres in the capture's world frame, with their
colours. :data:`SCALES` holds the defaults of a single plant (5 mm voxels) and of
a greenhouse row (1 cm).

Before any fusion, :func:`frame_depths` reads and checks every frame (enough frames, image sizes,
depth at the distances the scale fuses: :func:`depth_bounds`), so a bad frame is one line naming
it and no frame without depth in range reaches Open3D.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from data_tools.capture.formats import Capture, load_colour, load_confidence, load_depth
from data_tools.errors import ConfigError, InputFileError, PointCloudError
from tpvp.sensor.camera import project

GREY = 128  # the colour of a frame without a colour image
BLOCK_RESOLUTION = 8  # voxels along a block's side
INITIAL_BLOCKS = 10_000  # the block hash map's first capacity (it grows)
#: A frame's depth is judged by its nearest tenth (this percentile of its measured depth): the
#: subject is the nearest thing a capture looks at; background beyond it (a room's walls) is not.
NEAR_PERCENTILE = 10
#: The nearest a subject is seen from, in voxels: nearer, a frame's whole view spans a few dozen.
NEAREST_VOXELS = 20


@dataclass(frozen=True)
class FusionConfig:
    """TSDF fusion options (defaults: a single plant seen from about half a metre)."""

    voxel_size: float = 0.005  # m
    truncation: float = 0.01  # m: the signed distance's band, two voxels
    max_depth: float = 1.5  # m: depth farther than this is background
    min_confidence: int = 1  # ARKit's levels: 0 low, 1 medium, 2 high
    min_weight: float = 1.0  # frames (weighted) that must have seen a surface voxel to keep it
    spacing: float | None = 0.00125  # m: the surface mesh is sampled this far apart, a quarter voxel (None: not)
    support: float = 0.005  # m: a surface point is kept where a frame measured it within this

    def __post_init__(self):
        for name in ("voxel_size", "truncation", "max_depth", "spacing", "support"):
            if getattr(self, name) is not None and not getattr(self, name) > 0:
                raise ConfigError(f"fusion: {name} must be > 0 m, got {getattr(self, name)!r}")
        if self.max_depth <= NEAREST_VOXELS * self.voxel_size:  # depth_bounds would be empty
            raise ConfigError(f"fusion: max_depth ({self.max_depth} m) must be beyond {NEAREST_VOXELS} voxels "
                              f"({NEAREST_VOXELS * self.voxel_size:g} m), the nearest a subject is fused from")
        if self.truncation < self.voxel_size:
            raise ConfigError(f"fusion: the truncation ({self.truncation} m) must be at least one voxel "
                              f"({self.voxel_size} m)")
        if not self.min_weight >= 0:
            raise ConfigError(f"fusion: min_weight must be >= 0, got {self.min_weight!r}")
        if self.min_confidence not in (0, 1, 2):
            raise ConfigError(f"fusion: min_confidence is an ARKit level 0, 1 or 2, got {self.min_confidence!r}")


#: Defaults by the scale of what was captured.
SCALES = {"plant": FusionConfig(),
          "row": FusionConfig(voxel_size=0.01, truncation=0.02, max_depth=3.0, spacing=0.005, support=0.01)}
#: The seed of the surface sampling: the same cloud on every run.
SAMPLING_SEED = 0


def fusion_config(scale: str = "plant", **options) -> FusionConfig:
    """The defaults of ``scale`` with the given options (None: the default) replaced."""
    if scale not in SCALES:
        raise ConfigError(f"unknown scale {scale!r}; choose one of {', '.join(SCALES)}")
    return replace(SCALES[scale], **{k: v for k, v in options.items() if v is not None})


def depth_bounds(config: FusionConfig) -> tuple[float, float]:
    """Where a frame's nearest tenth of depth (:data:`NEAR_PERCENTILE`) must lie, metres, to be fused
    at ``config``: from :data:`NEAREST_VOXELS` voxels to ``max_depth`` (a plant 0.1-1.5 m, a row
    0.2-3 m). The range spans a factor 15, so depth 10 or more times off moves a frame out of it
    unless the frame was seen from within a factor 1.5 of the range's ends."""
    return NEAREST_VOXELS * config.voxel_size, config.max_depth


def frames_needed(config: FusionConfig) -> int:
    """The fewest frames a surface can come from: each frame adds weight 1 to the voxels it sees, and
    a voxel is kept with more than ``min_weight``."""
    return int(np.floor(config.min_weight)) + 1


def frame_depths(capture: Capture, config: FusionConfig):
    """Every frame's ``(depth, intrinsics)`` as the fusion integrates it (float32 metres, 0: none;
    below the confidence floor and beyond ``max_depth`` dropped), all read and checked before any
    fusion: enough frames (:func:`frames_needed`), images of their intrinsics' size, some depth in
    every frame, and every frame's nearest tenth within :func:`depth_bounds` (else a units
    mistake: one line naming the first such frame and the ``--depth-scale`` that fits it). So every
    frame holds depth within ``max_depth``: Open3D aborts on a frame without any. No progress bar:
    an error is then the only line on stderr (reading is a fraction of the fusion's time)."""
    needed = frames_needed(config)
    if len(capture.frames) < needed:
        raise InputFileError(f"{capture.folder}: the capture holds {len(capture.frames)} frame"
                             f"{'s' if len(capture.frames) != 1 else ''}, and a surface is kept only where more than "
                             f"{config.min_weight:g} frame{'s' if config.min_weight != 1 else ''} saw it: fusion needs "
                             f"at least {needed} frames that overlap (capture the subject from several places)")
    low, high = depth_bounds(config)
    depths, outside = [], []
    for frame in capture.frames:
        depth, k = load_depth(frame)
        if not np.isfinite(depth).any():
            raise InputFileError(f"{frame.depth}: frame {frame.name} holds no depth (every pixel is 0 or NaN); export "
                                 f"the frame again, or remove it")
        confidence = load_confidence(frame, depth.shape)
        if confidence is not None:
            depth[confidence < config.min_confidence] = np.nan
        measured = depth[np.isfinite(depth)]
        if measured.size == 0:
            raise InputFileError(f"{frame.confidence}: frame {frame.name} holds no depth at confidence "
                                 f"{config.min_confidence} or more: lower --min-confidence, or remove the frame")
        near = float(np.percentile(measured, NEAR_PERCENTILE))
        if not low <= near <= high:
            outside.append((frame, near))
        depth[~(depth <= config.max_depth)] = 0.0  # NaN and beyond the range: no measurement
        depths.append((depth.astype(np.float32), k))
    if outside:
        raise _units_error(outside, len(capture.frames), low, high)
    return depths


def _units_error(outside, count: int, low: float, high: float) -> InputFileError:
    """The line for frames whose nearest tenth lies outside ``low``-``high``: the first such frame,
    the power of ten its depth would need, and whether ``--depth-scale`` (one for every frame) can
    give it."""
    frame, near = outside[0]
    scale = frame.depth_scale or (0.001 if frame.depth.suffix.lower() == ".png" else 1.0)
    power = round(np.log10(np.sqrt(low * high) / near))  # nearest the range's middle: within it if it spans 10x
    fit = scale * 10.0**power
    head = (f"{frame.depth}: frame {frame.name}'s depth lies {near:.3g} m away (its nearest tenth) read at {scale:g} m "
            f"per unit, outside the {low:g}-{high:g} m these settings fuse ({NEAREST_VOXELS} voxels to --max-depth)")
    if len(outside) == count:
        # one power of ten too far may be a real distance, not units
        farther = "; if it is that far, raise --max-depth" if power == -1 else ""
        return InputFileError(f"{head}; all {count} frames do: are the units wrong? try --depth-scale {fit:g}{farther}")
    return InputFileError(f"{head}, while {count - len(outside)} of the {count} frames lie within: if its units differ "
                          f"from theirs, convert that file ({fit:g} m per unit would fit it; --depth-scale applies to "
                          f"every frame), else remove the frame")


def fuse(capture: Capture, config: FusionConfig = FusionConfig(), progress: bool = True):
    """``(points, colours)``: the fused surface of every frame, ``(N, 3)`` metres in the capture's
    world frame and ``(N, 3)`` uint8 RGB. Every frame is read and checked first (:func:`frame_depths`)."""
    import open3d as o3d
    import open3d.core as o3c
    from tqdm.auto import tqdm

    measured = frame_depths(capture, config)  # every frame's depth and intrinsics, checked

    # Open3D's tensor voxel-block grid (its hash map grows as blocks are touched); its legacy
    # ScalableTSDFVolume integrated nothing in open3d-cpu 0.20.
    volume = o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight", "color"), attr_dtypes=(o3c.float32, o3c.float32, o3c.float32),
        attr_channels=(1, 1, 3), voxel_size=config.voxel_size, block_resolution=BLOCK_RESOLUTION,
        block_count=INITIAL_BLOCKS, device=o3c.Device("CPU:0"))
    band = config.truncation / config.voxel_size  # Open3D's truncation, in voxels
    frames = zip(capture.frames, measured)
    for frame, (depth, k) in tqdm(frames, total=len(measured), desc="fusing", unit="frame", disable=not progress):
        colour = load_colour(frame, depth.shape)
        colour = np.full((*depth.shape, 3), GREY / 255.0) if colour is None else colour / 255.0
        depth_image = o3d.t.geometry.Image(o3c.Tensor(depth))
        colour_image = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(colour, dtype=np.float32)))
        intrinsic = o3c.Tensor(k.matrix())
        extrinsic = o3c.Tensor(np.linalg.inv(frame.camera_to_world))
        blocks = volume.compute_unique_block_coordinates(depth_image, intrinsic, extrinsic, 1.0, config.max_depth, band)
        volume.integrate(blocks, depth_image, colour_image, intrinsic, intrinsic, extrinsic, 1.0, config.max_depth,
                         band)
    points, colours = surface_samples(volume, config)
    if len(points) == 0:  # every frame has depth in range (frame_depths): their views do not meet
        raise PointCloudError(f"{capture.folder}: the fusion found no surface: no voxel was seen by more than "
                              f"{config.min_weight:g} of the {len(capture.frames)} frames, so their views do not "
                              f"overlap: are the poses right (camera-to-world, metres)?")
    poses = [frame.camera_to_world for frame in capture.frames]
    kept = supported(points, poses, measured, config.support)
    if not kept.any():
        raise PointCloudError(f"{capture.folder}: no fused surface point lies within {config.support} m of a "
                              f"measured depth (--support)")
    order = np.lexsort(points[kept].T[::-1])
    return points[kept][order], colours[kept][order]


def surface_samples(volume, config: FusionConfig):
    """``(points, colours)`` of the volume's zero level: its crossings on the voxel edges (one per
    edge, thin parts included) and, with ``config.spacing``, points sampled uniformly (seeded) that
    far apart over the mesh marching cubes closes, colours interpolated from its vertices: the
    crossings alone leave the surface half a voxel apart."""
    import open3d as o3d

    crossings = volume.extract_point_cloud(weight_threshold=config.min_weight)
    if "positions" not in crossings.point:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.uint8)
    points, colours = [crossings.point.positions.numpy().astype(np.float64)], [crossings.point.colors.numpy()]
    mesh = (canonical_mesh(volume.extract_triangle_mesh(weight_threshold=config.min_weight).to_legacy())
            if config.spacing else None)
    if mesh is not None and len(mesh.triangles):
        o3d.utility.random.seed(SAMPLING_SEED)
        cloud = mesh.sample_points_uniformly(max(int(mesh.get_surface_area() / config.spacing**2), 1))
        points.append(np.asarray(cloud.points, dtype=np.float64))
        colours.append(np.asarray(cloud.colors))
    return np.concatenate(points), np.clip(np.rint(np.concatenate(colours) * 255.0), 0, 255).astype(np.uint8)


def canonical_mesh(mesh):
    """The mesh with its vertices in coordinate order and its triangles in vertex order: the voxel
    blocks' hash map orders them by its threads, and the sampling follows the triangles' order."""
    import open3d as o3d

    vertices = np.asarray(mesh.vertices)
    order = np.lexsort(vertices.T[::-1])
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    triangles = rank[np.asarray(mesh.triangles)]
    triangles = triangles[np.lexsort(triangles.T[::-1])]
    canonical = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices[order]),
                                          o3d.utility.Vector3iVector(triangles))
    canonical.vertex_colors = o3d.utility.Vector3dVector(np.asarray(mesh.vertex_colors)[order])
    return canonical


def supported(points, poses, measured, tolerance: float) -> np.ndarray:
    """Mask of the ``points`` some frame measured: projected into a frame (``poses``: its
    camera-to-world, OpenCV axes; ``measured``: its depth in metres, 0 for none, and intrinsics),
    the depth of the nearest pixel lies within ``tolerance`` of the point's own depth.

    Where the views of a thin leaf from both sides meet, the truncated distances cancel and the
    volume holds zero crossings up to a truncation away from any surface; no frame measured those.
    """
    points = np.asarray(points, dtype=np.float64)
    kept = np.zeros(len(points), dtype=bool)
    for pose, (depth, k) in zip(poses, measured):
        u, v, z = project(points, pose[:3, 3], pose[:3, :3], k)
        with np.errstate(invalid="ignore"):  # points behind the camera project to inf or NaN
            u, v = np.rint(u), np.rint(v)
            inside = np.flatnonzero((z > 0) & (u >= 0) & (u < k.width) & (v >= 0) & (v < k.height))
        at = depth[v[inside].astype(np.int64), u[inside].astype(np.int64)]
        kept[inside[(at > 0) & (np.abs(at - z[inside]) <= tolerance)]] = True
    return kept
