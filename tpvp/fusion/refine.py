"""A frame's pose refined against the model fused so far: point-to-plane ICP, on plain arrays.

The model is the refined frames' measured points averaged in cells, with normals
(:class:`PointModel`). The frame's measured points, placed at its predicted pose (its reported pose
after the previous frame's correction: tracking drift is smooth), are matched to their nearest
model points, and the camera is moved to bring them onto the model's tangent planes (Gauss-Newton,
Huber-weighted residuals, a prior on the move, at most a fixed number of iterations). A result
whose fitness (the share of the frame's points matched) or RMSE (the matched points' distance to
the model's planes) is poor, whose normal equations leave a motion unconstrained, or which barely
lowers the RMSE, is refused: the caller keeps the carried correction.

Written with numpy and scipy rather than with Open3D's ICP so that a run is the same on any
thread count: the model's points are sorted, and the sums are numpy's, in a fixed order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tpvp.errors import ConfigError
from tpvp.sensor.camera import Intrinsics, rotation_from_vector

#: A 6 x 6 system conditioned worse than this leaves a motion unconstrained (a wall seen alone).
MAX_CONDITION = 1e7
#: A model point's normal: the least-variance axis of it and its nearest neighbours, this many.
NORMAL_NEIGHBOURS = 16
#: The model's normals are refitted when its cells have grown by this share since the last fit.
REFIT_GROWTH = 0.02
CELL_OFFSET = 1 << 20  # cell indices shifted positive, 21 bits each: +-1 km at 1 mm cells


@dataclass(frozen=True)
class RefineConfig:
    """Pose refinement options; distances in voxels of the fusion, so one set fits every scale."""

    points: int = 6000  # the frame's measured pixels used, evenly strided (all when fewer)
    cell_voxels: float = 0.5  # the model's cells, in voxels
    iterations: int = 12
    distance_voxels: float = 4.0  # a point farther than this from its model point is not matched
    huber_voxels: float = 0.5  # residuals beyond this weigh less (Huber): mixed pixels, noise
    min_fitness: float = 0.3  # the share of the frame's points matched, at least
    rmse_voxels: float = 1.0  # the matched points' point-to-plane RMSE, at most
    #: The RMSE must fall by this share from the predicted pose's, else the prediction is kept: a
    #: frame already in place would only be moved by the depth's noise.
    min_gain: float = 0.05
    #: How far the predicted pose is trusted (one sigma of a frame's tracking error, translation and
    #: rotation): a prior that keeps the motions the model barely constrains (a sideways shift
    #: against a turn about the camera, when the subject is small in view) at the prediction.
    tracking_m: float = 0.002
    tracking_deg: float = 0.2
    #: One sigma of a matched point's point-to-plane residual, in voxels: weighs the data against the prior.
    residual_voxels: float = 0.5

    def __post_init__(self):
        for name in ("points", "iterations"):
            if not (isinstance(getattr(self, name), int) and getattr(self, name) >= 1):
                raise ConfigError(f"pose refinement: {name} must be an integer >= 1, got {getattr(self, name)!r}")
        for name in ("cell_voxels", "distance_voxels", "huber_voxels", "rmse_voxels", "tracking_m", "tracking_deg",
                     "residual_voxels"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"pose refinement: {name} must be > 0, got {getattr(self, name)!r}")
        if not 0 <= self.min_gain < 1:
            raise ConfigError(f"pose refinement: min_gain is a share in [0, 1), got {self.min_gain!r}")
        if not 0 <= self.min_fitness <= 1:
            raise ConfigError(f"pose refinement: min_fitness is a share in [0, 1], got {self.min_fitness!r}")


@dataclass(frozen=True)
class Alignment:
    """One frame's ICP: ``pose`` its camera-to-world after refinement (the predicted one when
    refused); ``accepted`` and, when not, ``reason``."""

    pose: np.ndarray
    fitness: float
    rmse: float  # m
    accepted: bool
    reason: str = ""


def sample_pixels(depth: np.ndarray, count: int) -> np.ndarray:
    """Flat indices of at most ``count`` measured pixels (depth > 0), evenly strided in row order."""
    measured = np.flatnonzero(depth.ravel() > 0)
    if len(measured) <= count:
        return measured
    return measured[np.linspace(0, len(measured) - 1, count).astype(np.int64)]


def backproject(depth: np.ndarray, k: Intrinsics, pixels: np.ndarray) -> np.ndarray:
    """``(N, 3)`` camera-frame points (OpenCV axes) of the flat pixel indices ``pixels``."""
    v, u = np.divmod(pixels, depth.shape[1])
    z = depth.ravel()[pixels].astype(np.float64)
    return np.column_stack([(u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z])


@dataclass(frozen=True)
class Model:
    """The surface fused so far as matched against: ``points`` (world frame, metres), their unit
    ``normals`` and a k-d tree over the points."""

    points: np.ndarray
    normals: np.ndarray
    tree: object


class PointModel:
    """The refined frames' measured points, averaged in cells of ``cell`` metres: the model a frame
    is aligned to. Not the TSDF's zero level: at 5 mm voxels a plant's thin leaves and stems come
    out fattened by up to a voxel (and open3d 0.20's ``ray_cast`` put a plane half a voxel to a voxel
    off), a bias ICP followed frame after frame as drift; the measured points hold none.
    :meth:`model` refits the normals (PCA of each point's neighbours) only once the cells have grown
    by ``REFIT_GROWTH``: consecutive frames of a dense capture add little."""

    def __init__(self, cell: float):
        self.cell = cell
        self.keys = np.zeros(0, dtype=np.int64)
        self.sums = np.zeros((0, 3))
        self.counts = np.zeros(0, dtype=np.int64)
        self._fitted: Model | None = None

    def add(self, points: np.ndarray) -> None:
        """Average world-frame ``points`` into the cells."""
        cells = np.floor(points / self.cell).astype(np.int64) + CELL_OFFSET
        keys = (cells[:, 0] << 42) | (cells[:, 1] << 21) | cells[:, 2]
        self.keys, inverse = np.unique(np.concatenate([self.keys, keys]), return_inverse=True)
        inverse = inverse.ravel()
        weights = np.concatenate([self.counts, np.ones(len(keys), dtype=np.int64)])
        summed = np.concatenate([self.sums, points])
        self.counts = np.bincount(inverse, weights, len(self.keys)).astype(np.int64)
        self.sums = np.stack([np.bincount(inverse, summed[:, j], len(self.keys)) for j in range(3)], axis=1)

    def model(self) -> Model | None:
        """The cells' mean points with normals and a k-d tree; None with too few cells."""
        import open3d as o3d
        from scipy.spatial import cKDTree

        if len(self.keys) < NORMAL_NEIGHBOURS:
            return None
        if self._fitted is None or len(self.keys) > (1 + REFIT_GROWTH) * len(self._fitted.points):
            points = self.sums / self.counts[:, None]
            cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
            cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(NORMAL_NEIGHBOURS))
            self._fitted = Model(points, np.asarray(cloud.normals), cKDTree(points))
        return self._fitted


def point_to_plane(source: np.ndarray, model: Model, camera_to_world: np.ndarray, config: RefineConfig,
                   voxel: float):
    """``(motion, fitness, rmse, conditioned, start_rmse)``: the 4 x 4 camera-frame motion that brings the
    camera-frame ``source`` points onto the ``model``'s tangent planes, the camera at
    ``camera_to_world``: Gauss-Newton on the point-to-plane residuals of nearest-neighbour matches,
    in the camera's frame (so the rotation turns about the camera, well conditioned anywhere)."""
    distance, huber = config.distance_voxels * voxel, config.huber_voxels * voxel
    residual_sigma = config.residual_voxels * voxel
    prior = np.diag([*[(residual_sigma / math.radians(config.tracking_deg)) ** 2] * 3,
                     *[(residual_sigma / config.tracking_m) ** 2] * 3])  # in the data's units
    rotation, centre = camera_to_world[:3, :3], camera_to_world[:3, 3]
    motion = np.eye(4)
    fitness, rmse, start_rmse = 0.0, math.inf, None
    for _ in range(config.iterations):
        moved = source @ motion[:3, :3].T + motion[:3, 3]
        gap, nearest = model.tree.query(moved @ rotation.T + centre, distance_upper_bound=distance)
        matched = np.isfinite(gap)
        points = moved[matched]
        target = (model.points[nearest[matched]] - centre) @ rotation
        normals = model.normals[nearest[matched]] @ rotation
        residual = np.einsum("ij,ij->i", points - target, normals)
        fitness = len(residual) / max(len(source), 1)
        rmse = float(np.sqrt(np.mean(residual ** 2))) if len(residual) else math.inf
        start_rmse = rmse if start_rmse is None else start_rmse
        if len(residual) < 6:
            return motion, fitness, rmse, False, start_rmse
        weight = np.minimum(1.0, huber / np.maximum(np.abs(residual), 1e-12))
        jacobian = np.hstack([np.cross(points, normals), normals])
        hessian = jacobian.T @ (jacobian * weight[:, None])
        if np.linalg.cond(hessian) > MAX_CONDITION:
            return motion, fitness, rmse, False, start_rmse
        so_far = np.concatenate([rotation_vector(motion[:3, :3]), motion[:3, 3]])
        step = -np.linalg.solve(hessian + prior, jacobian.T @ (weight * residual) + prior @ so_far)
        update = np.eye(4)
        update[:3, :3], update[:3, 3] = rotation_from_vector(step[:3]), step[3:]
        motion = update @ motion
        if np.linalg.norm(step) < 1e-7:  # converged: metres and radians alike
            break
    return motion, fitness, rmse, True, start_rmse


def align_frame(model: Model | None, depth: np.ndarray, k: Intrinsics, predicted: np.ndarray, voxel: float,
                config: RefineConfig) -> Alignment:
    """Frame ``depth`` (metres, 0: none) aligned to ``model`` starting at the ``predicted``
    camera-to-world pose: the refined pose, or the predicted one with the reason the refinement
    was refused."""
    if model is None:
        return Alignment(predicted, 0.0, math.inf, False, "no surface fused yet")
    source = backproject(depth, k, sample_pixels(depth, config.points))
    motion, fitness, rmse, conditioned, start_rmse = point_to_plane(source, model, predicted, config, voxel)
    if not conditioned:
        return Alignment(predicted, fitness, rmse, False, "too few matches, or a motion the model does not constrain")
    if fitness < config.min_fitness:
        return Alignment(predicted, fitness, rmse, False, f"fitness {fitness:.2f} < {config.min_fitness:g}")
    if rmse > config.rmse_voxels * voxel:
        return Alignment(predicted, fitness, rmse, False,
                         f"RMSE {1000 * rmse:.1f} mm > {1000 * config.rmse_voxels * voxel:g} mm")
    if rmse > (1.0 - config.min_gain) * start_rmse:
        return Alignment(predicted, fitness, rmse, False, f"RMSE {1000 * start_rmse:.2f} -> {1000 * rmse:.2f} mm, "
                                                          f"a gain under {100 * config.min_gain:g} %")
    return Alignment(predicted @ motion, fitness, rmse, True)


def rotation_vector(rotation: np.ndarray) -> np.ndarray:
    """The rotation vector (radians) of a rotation matrix (small and moderate angles)."""
    angle = math.acos(float(np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0)))
    axis = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1]])
    return axis * (0.5 if angle < 1e-9 else angle / (2.0 * math.sin(angle)))


def correction_size(delta: np.ndarray, reported: np.ndarray) -> tuple[float, float]:
    """``(mm, degrees)`` of a correction ``delta`` (world frame: corrected = delta @ reported):
    how far the camera's centre moved, and the angle it turned."""
    moved = delta[:3, :3] @ reported[:3, 3] + delta[:3, 3] - reported[:3, 3]
    cosine = np.clip((np.trace(delta[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return 1000.0 * float(np.linalg.norm(moved)), math.degrees(math.acos(cosine))
