"""Landmark-guided ICP: align a session's scan to the site's reference day.

The paper aligns every greenhouse session to the first capture day with landmarks picked by hand on
static structures (rail supports, posts), refined by ICP. Here a landmarks file gives the initial
rigid transform (least squares over the picked pairs, Kabsch), and open3d's point-to-plane ICP
refines it on the static structure of both scans (the points outside the plant box, which do not
grow); fitness and inlier RMSE of the final transform are reported for every session.

Landmarks file: CSV with a header ``source_x,source_y,source_z,target_x,target_y,target_z``
(source = the session being aligned, target = the same physical point in the reference day), or
six numbers per line without a header; ``#`` starts a comment. Metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from data_tools.errors import ConfigError, InputFileError, PointCloudError
from tpvp.errors import checked_cloud
from tpvp.io import read_text_table

LANDMARK_COLUMNS = ("source_x", "source_y", "source_z", "target_x", "target_y", "target_z")
#: Fewest pairs that fix a rigid transform (three non-collinear points).
MIN_LANDMARKS = 3


@dataclass(frozen=True)
class IcpConfig:
    """ICP refinement settings (metres)."""

    voxel_size: float = 0.02  # both clouds are downsampled to this before ICP
    max_correspondence: float = 0.05  # pairs farther apart are ignored
    max_iterations: int = 60
    min_static_points: int = 500  # fewer static points outside the plant box: no static-only ICP
    static_margin: float = 0.05  # points this far outside the plant box count as static structure
    min_fitness: float = 0.3  # a poorer ICP result is refused (wrong local minimum, no overlap)


@dataclass(frozen=True)
class Alignment:
    """A rigid transform to the reference frame and how well it fits."""

    transform: np.ndarray  # (4, 4) session -> reference
    fitness: float  # share of the session's (downsampled) points with a partner within max_correspondence
    inlier_rmse: float  # RMSE (m) over those pairs
    landmark_rmse: float | None  # residual (m) of the landmark fit, None without landmarks
    method: str  # how the transform was obtained, e.g. "landmarks+icp(static)"

    @property
    def rotation_deg(self) -> float:
        return rotation_angle_deg(self.transform[:3, :3])

    @property
    def translation(self) -> np.ndarray:
        return self.transform[:3, 3]


def transform_points(points: np.ndarray, transform: np.ndarray) -> np.ndarray:
    """Apply a (4, 4) rigid transform to (N, 3) points."""
    return np.asarray(points, dtype=np.float64) @ transform[:3, :3].T + transform[:3, 3]


def rotation_angle_deg(rotation: np.ndarray) -> float:
    """Angle (degrees) of a rotation matrix, from its trace."""
    cos = (np.trace(rotation) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def rigid_from_pairs(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Least-squares rigid transform (4, 4) mapping ``source`` onto ``target`` (Kabsch; no scale).

    Raises ConfigError for fewer than 3 pairs or (nearly) collinear points, which leave a rotation
    about their line undetermined.
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 3:
        raise ConfigError(f"landmark pairs must be two (K, 3) arrays, got {source.shape} and {target.shape}")
    if len(source) < MIN_LANDMARKS:
        raise ConfigError(f"{len(source)} landmark pair(s): at least {MIN_LANDMARKS} non-collinear pairs are needed")
    src_c, tgt_c = source.mean(axis=0), target.mean(axis=0)
    spread = np.linalg.svd(source - src_c, compute_uv=False)
    if spread[1] < 1e-3 * max(spread[0], 1e-12) or spread[1] < 1e-4:
        raise ConfigError("landmarks are (nearly) collinear: pick points that span a plane or volume")
    u, _, vt = np.linalg.svd((source - src_c).T @ (target - tgt_c))
    fix = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])  # no reflections
    rotation = vt.T @ fix @ u.T
    transform = np.eye(4)
    transform[:3, :3] = rotation
    transform[:3, 3] = tgt_c - rotation @ src_c
    return transform


def read_landmarks(path) -> tuple[np.ndarray, np.ndarray]:
    """Read a landmarks file; returns ``(source (K, 3), target (K, 3))`` with K >= 3."""
    path = Path(path)
    table, names = read_text_table(path, count_header=False, names=True)
    if names is not None:
        missing = [c for c in LANDMARK_COLUMNS if c not in names]
        if missing:
            raise InputFileError(f"{path}: landmarks header lacks {', '.join(missing)} "
                                 f"(expected {','.join(LANDMARK_COLUMNS)})")
        table = table[:, [names.index(c) for c in LANDMARK_COLUMNS]] if len(table) else table
    elif len(table) and table.shape[1] != 6:
        raise InputFileError(f"{path}: each landmark row needs 6 numbers (source xyz, target xyz), "
                             f"got {table.shape[1]}")
    if len(table) < MIN_LANDMARKS:
        raise InputFileError(f"{path}: {len(table)} landmark pair(s), at least {MIN_LANDMARKS} "
                             "non-collinear pairs are needed")
    return table[:, :3], table[:, 3:]


def landmark_transform(path) -> tuple[np.ndarray, float]:
    """Rigid transform from a landmarks file and the RMS residual (m) of the picked pairs."""
    source, target = read_landmarks(path)
    try:
        transform = rigid_from_pairs(source, target)
    except ConfigError as exc:
        raise InputFileError(f"{path}: {exc}") from None
    residual = transform_points(source, transform) - target
    return transform, float(np.sqrt((residual ** 2).sum(axis=1).mean()))


def _o3d_cloud(points: np.ndarray, voxel_size: float):
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud = cloud.voxel_down_sample(voxel_size)
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3 * voxel_size, max_nn=30))
    return cloud


def evaluate(source: np.ndarray, target: np.ndarray, transform: np.ndarray,
             config: IcpConfig = IcpConfig()) -> tuple[float, float]:
    """Fitness and inlier RMSE of ``transform`` (open3d's definitions, on downsampled clouds)."""
    import open3d as o3d

    result = o3d.pipelines.registration.evaluate_registration(
        _o3d_cloud(source, config.voxel_size), _o3d_cloud(target, config.voxel_size),
        config.max_correspondence, transform)
    return float(result.fitness), float(result.inlier_rmse)


def refine_icp(source: np.ndarray, target: np.ndarray, initial: np.ndarray,
               config: IcpConfig = IcpConfig()) -> tuple[np.ndarray, float, float]:
    """Point-to-plane ICP of ``source`` onto ``target`` from ``initial``; ``(transform, fitness, rmse)``."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    result = reg.registration_icp(
        _o3d_cloud(source, config.voxel_size), _o3d_cloud(target, config.voxel_size),
        config.max_correspondence, np.asarray(initial, dtype=np.float64),
        reg.TransformationEstimationPointToPlane(),
        reg.ICPConvergenceCriteria(relative_fitness=1e-7, relative_rmse=1e-7,
                                   max_iteration=config.max_iterations))
    return np.array(result.transformation), float(result.fitness), float(result.inlier_rmse)


def align_to_reference(scan: np.ndarray, reference: np.ndarray, *, landmarks=None, plant_box=None,
                       icp: bool = True, config: IcpConfig = IcpConfig()) -> Alignment:
    """Align ``scan`` to ``reference`` (both (N, 3) metres, each in its own frame).

    ``landmarks`` (a file) gives the initial transform, identity otherwise. With a ``plant_box``
    (reference frame) ICP runs on the static structure, the points outside the box grown by
    ``static_margin``, when both clouds have at least ``config.min_static_points`` of them. With
    less static structure (already cropped models) ICP runs only when landmarks were given: ICP on
    growing plants alone would pull the new growth onto the old shape.
    """
    scan = checked_cloud(scan, "scan")
    reference = checked_cloud(reference, "reference scan")
    initial, landmark_rmse, method = np.eye(4), None, "identity"
    if landmarks is not None:
        initial, landmark_rmse = landmark_transform(landmarks)
        method = "landmarks"
    src, tgt, region = scan, reference, "all"
    if plant_box is not None:
        scan_static = ~plant_box.contains(transform_points(scan, initial), tol=config.static_margin)
        reference_static = ~plant_box.contains(reference, tol=config.static_margin)
        if min(np.count_nonzero(scan_static), np.count_nonzero(reference_static)) >= config.min_static_points:
            src, tgt, region = scan[scan_static], reference[reference_static], "static"
        elif landmarks is None:
            icp = False  # only plants to match: keep the given frame
    transform = initial
    if icp:
        transform, fitness, rmse = refine_icp(src, tgt, initial, config)
        method = f"{method}+icp({region})" if landmarks is not None else f"icp({region})"
        if fitness < config.min_fitness:
            raise PointCloudError(
                f"ICP fitness {fitness:.3f} < {config.min_fitness}: only {100 * fitness:.1f} % of the scan lies "
                f"within {config.max_correspondence} m of the reference after alignment; the scan starts too "
                "far from the reference frame - give a landmarks file (at least 3 picked pairs)")
    else:
        fitness, rmse = evaluate(src, tgt, transform, config)
    return Alignment(transform=transform, fitness=fitness, inlier_rmse=rmse,
                     landmark_rmse=landmark_rmse, method=method)
