"""Depth frames fused into one coloured surface cloud: Open3D's TSDF integration, on plain arrays.

Each frame (:class:`DepthFrame`: depth in metres, 0 for none, its pinhole, its camera-to-world
pose with OpenCV axes, its colour) is integrated at its pose into a TSDF volume of ``voxel_size``
voxels truncated at ``truncation``; with ``refine_poses`` every frame after the first is first
aligned to the model fused so far (:mod:`.refine`), starting from its reported pose composed with
the previous frame's correction, and integrated at the refined pose. The volume's zero level is
extracted (:func:`surface_samples`: the voxel edges' crossings and its marching-cubes mesh sampled
every ``spacing``); the points some frame measured (:func:`supported`) are the surface, in metres
in the frames' world, with their colours. :data:`SCALES` holds the defaults of a single plant
(5 mm voxels) and of a greenhouse row (1 cm).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from tpvp.errors import ConfigError, PointCloudError
from tpvp.fusion.refine import PointModel, RefineConfig, align_frame, backproject, correction_size, sample_pixels
from tpvp.sensor.camera import Intrinsics, project

GREY = 128  # the colour of a frame without a colour image
BLOCK_RESOLUTION = 8  # voxels along a block's side
INITIAL_BLOCKS = 10_000  # the block hash map's first capacity (it grows)
#: The nearest a subject is seen from, in voxels: nearer, a frame's whole view spans a few dozen.
NEAREST_VOXELS = 20
#: The seed of the surface sampling: the same cloud on every run.
SAMPLING_SEED = 0


@dataclass(frozen=True)
class FusionConfig:
    """TSDF fusion options (defaults: a single plant seen from about half a metre)."""

    voxel_size: float = 0.005  # m
    truncation: float = 0.01  # m: the signed distance's band, two voxels
    max_depth: float = 1.5  # m: depth farther than this is background
    min_confidence: int = 1  # ARKit's levels: 0 low, 1 medium, 2 high
    min_weight: float = 1.0  # a surface voxel is kept when seen by more frames (weighted) than this; one frame: all
    spacing: float | None = 0.00125  # m: the surface mesh is sampled this far apart, a quarter voxel (None: not)
    support: float = 0.005  # m: a surface point is kept where a frame measured it within this
    refine_poses: bool = False  # align each frame to the model fused so far before integrating it
    refine: RefineConfig = field(default_factory=RefineConfig)

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
        if not isinstance(self.refine_poses, bool):
            raise ConfigError(f"fusion: refine_poses is true or false, got {self.refine_poses!r}")


#: Defaults by the scale of what was captured.
SCALES = {"plant": FusionConfig(),
          "row": FusionConfig(voxel_size=0.01, truncation=0.02, max_depth=3.0, spacing=0.005, support=0.01)}


def fusion_config(scale: str = "plant", **options) -> FusionConfig:
    """The defaults of ``scale`` with the given options (None: the default) replaced."""
    if scale not in SCALES:
        raise ConfigError(f"unknown scale {scale!r}; choose one of {', '.join(SCALES)}")
    return replace(SCALES[scale], **{k: v for k, v in options.items() if v is not None})


@dataclass(frozen=True)
class DepthFrame:
    """One frame as the fusion takes it: ``depth`` (H, W) float32 metres (0: no measurement, all
    within ``max_depth``), its ``intrinsics``, ``camera_to_world`` (4, 4, OpenCV axes, metres) and
    ``colour`` (H, W, 3) uint8 or None (grey)."""

    depth: np.ndarray
    intrinsics: Intrinsics
    camera_to_world: np.ndarray
    colour: np.ndarray | None = None
    name: str = ""


@dataclass(frozen=True)
class PoseCorrection:
    """One frame's correction: ``delta`` (4, 4, world frame: refined = delta @ reported), the
    camera centre's shift (mm) and turn (degrees); ``status`` is ``first`` (the anchor),
    ``refined``, ``off`` (refinement off) or ``kept: REASON`` (the carried correction kept)."""

    name: str
    delta: np.ndarray
    translation_mm: float
    rotation_deg: float
    fitness: float
    rmse_mm: float
    status: str


@dataclass(frozen=True)
class Fused:
    """The fused surface (``points`` (N, 3) metres, ``colours`` (N, 3) uint8), every frame's pose
    as integrated and its correction."""

    points: np.ndarray
    colours: np.ndarray
    poses: np.ndarray
    corrections: tuple[PoseCorrection, ...]

    def largest_correction(self) -> PoseCorrection | None:
        """The correction that moved its camera farthest (ties: the larger turn), None without frames."""
        return max(self.corrections, key=lambda c: (c.translation_mm, c.rotation_deg), default=None)


def new_volume(config: FusionConfig):
    """An empty TSDF volume: Open3D's tensor voxel-block grid (its hash map grows as blocks are
    touched); its legacy ScalableTSDFVolume integrated nothing in open3d-cpu 0.20."""
    import open3d as o3d
    import open3d.core as o3c

    return o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight", "color"), attr_dtypes=(o3c.float32, o3c.float32, o3c.float32),
        attr_channels=(1, 1, 3), voxel_size=config.voxel_size, block_resolution=BLOCK_RESOLUTION,
        block_count=INITIAL_BLOCKS, device=o3c.Device("CPU:0"))


def fuse_frames(frames, config: FusionConfig = FusionConfig(), progress: bool = True, source: str = "") -> Fused:
    """Every frame of ``frames`` (a sequence of :class:`DepthFrame`: read twice, to integrate and to
    check support) fused, refined first with ``config.refine_poses``; ``source`` names the frames
    in an error. A :class:`PointCloudError` when no surface is left."""
    import open3d as o3d
    import open3d.core as o3c
    from tqdm.auto import tqdm

    volume = new_volume(config)
    band = config.truncation / config.voxel_size  # Open3D's truncation, in voxels
    carried = np.eye(4)  # the previous frame's correction: drift is smooth
    model = PointModel(config.refine.cell_voxels * config.voxel_size)
    poses, corrections = [], []
    for i, frame in enumerate(tqdm(frames, desc="fusing", unit="frame", disable=not progress)):
        depth, k = frame.depth, frame.intrinsics
        depth_image = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(depth, dtype=np.float32)))
        intrinsic = o3c.Tensor(k.matrix())
        reported = np.asarray(frame.camera_to_world, dtype=np.float64)
        pose, fitness, rmse, status = reported, float("nan"), float("nan"), "off"
        if config.refine_poses and i == 0:
            status = "first"
        elif config.refine_poses:
            aligned = align_frame(model.model(), depth, k, carried @ reported, config.voxel_size, config.refine)
            pose, fitness, rmse = aligned.pose, aligned.fitness, aligned.rmse
            status = "refined" if aligned.accepted else f"kept: {aligned.reason}"
            carried = pose @ np.linalg.inv(reported)
        delta = pose @ np.linalg.inv(reported)
        corrections.append(PoseCorrection(frame.name, delta, *correction_size(delta, reported), fitness,
                                          1000.0 * rmse, status))
        poses.append(pose)
        if config.refine_poses:
            measured = backproject(depth, k, sample_pixels(depth, depth.size))
            model.add(measured @ pose[:3, :3].T + pose[:3, 3])
        extrinsic = o3c.Tensor(np.linalg.inv(pose))
        colour = (np.full((*depth.shape, 3), GREY / 255.0) if frame.colour is None
                  else np.asarray(frame.colour) / 255.0)
        colour_image = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(colour, dtype=np.float32)))
        blocks = volume.compute_unique_block_coordinates(depth_image, intrinsic, extrinsic, 1.0, config.max_depth, band)
        volume.integrate(blocks, depth_image, colour_image, intrinsic, intrinsic, extrinsic, 1.0, config.max_depth,
                         band)
    if len(poses) == 1:  # one frame sees each voxel once at most: keep what it saw
        config = replace(config, min_weight=min(config.min_weight, 0.0))
    points, colours = surface_samples(volume, config)
    where = f"{source}: " if source else ""
    if len(points) == 0:
        raise PointCloudError(f"{where}the fusion found no surface: no voxel was seen by more than "
                              f"{config.min_weight:g} of the {len(poses)} frames, so their views do not "
                              f"overlap: are the poses right (camera-to-world, metres)?")
    kept = supported(points, poses, [(frame.depth, frame.intrinsics) for frame in frames], config.support)
    if not kept.any():
        raise PointCloudError(f"{where}no fused surface point lies within {config.support} m of a "
                              f"measured depth (--support)")
    order = np.lexsort(points[kept].T[::-1])
    return Fused(points[kept][order], colours[kept][order], np.array(poses), tuple(corrections))


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
