"""Cleaning one greenhouse-row scan (already in the reference frame), the paper's post-processing.

Steps, each reported as a point count so a user can see what every step removed:

1. crop to the plant box (everything outside - floor, aisles, neighbouring rows - is background);
2. remove horizontal supports in the bottom band of the box (substrate slabs, gutters, benches):
   RANSAC planes restricted to near-horizontal normals, accepted only when the inliers form a
   filled flat patch (a plane cut through foliage is a scatter of leaf crossings and is kept);
3. statistical outlier removal (open3d);
4. voxel downsampling (open3d);
5. removal of small disconnected fragments (floating debris, cut-off strings): connected components
   of the occupied voxels at ``fragment_radius``.

Thin supports that touch the plants (strings, clips, wires along stems) cannot be told apart from
stems by geometry alone and stay.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse
from scipy.sparse.csgraph import connected_components

from data_tools.errors import ConfigError, PointCloudError
from tpvp.errors import checked_cloud
from tpvp.scene import voxels


@dataclass(frozen=True)
class CleanConfig:
    """Cleaning settings (metres). Defaults suit a Polycam/LiDAR greenhouse row."""

    crop_margin: float = 0.0  # grow the plant box by this before cropping
    support_band: float = 0.4  # height of the bottom band of the box searched for supports
    max_supports: int = 3  # horizontal support planes removed at most
    plane_distance: float = 0.01  # RANSAC inlier distance
    max_plane_tilt_deg: float = 15.0  # a support plane's normal is this close to vertical
    min_plane_area: float = 0.05  # m^2 of filled patch for a support
    min_plane_fill: float = 0.5  # share of the patch's bounding rectangle that must be covered
    fill_cell: float = 0.02  # cell size of that coverage test
    ransac_trials: int = 400
    sor_neighbours: int = 20  # statistical outlier removal: neighbours
    sor_std_ratio: float = 2.0  # and the cut in standard deviations of the mean distance
    voxel_size: float = 0.005  # downsampling voxel (the ground truth is voxelised at 0.01 m)
    fragment_radius: float = 0.03  # points closer than this (voxel adjacency) are connected
    min_fragment_share: float = 0.002  # components with fewer points than this share are removed
    seed: int = 0

    def __post_init__(self):
        for name in ("support_band", "plane_distance", "min_plane_area", "fill_cell", "sor_std_ratio",
                     "voxel_size", "fragment_radius"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ConfigError(f"CleanConfig.{name} must be > 0, got {value!r}")
        if not 0 <= self.min_plane_fill <= 1 or not 0 <= self.min_fragment_share < 1:
            raise ConfigError("CleanConfig: min_plane_fill must be in [0, 1], min_fragment_share in [0, 1)")


@dataclass(frozen=True)
class CleanResult:
    points: np.ndarray
    counts: dict  # points after each step: raw, cropped, supports_removed, outliers_removed, downsampled, fragments_removed


def crop_to_box(points: np.ndarray, box, margin: float = 0.0) -> np.ndarray:
    """Points inside the oriented ``box`` grown by ``margin``."""
    return points[box.contains(points, tol=margin)]


def _fit_plane(points: np.ndarray) -> tuple[np.ndarray, float]:
    centre = points.mean(axis=0)
    normal = np.linalg.svd(points - centre, full_matrices=False)[2][2]
    return normal, -float(normal @ centre)


def _patch_fill(points: np.ndarray, cell: float) -> tuple[float, float]:
    """(filled area m^2, share of the bounding rectangle filled) of plane inliers, measured on
    ``cell``-sized squares in the plane along the inliers' principal axes."""
    axes = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)[2][:2]
    cells = np.unique(np.floor(points @ axes.T / cell).astype(np.int64), axis=0)
    span = cells.max(axis=0) - cells.min(axis=0) + 1
    return len(cells) * cell ** 2, len(cells) / float(np.prod(span))


def find_support_planes(points: np.ndarray, box, config: CleanConfig = CleanConfig()) -> np.ndarray:
    """Mask of the points on horizontal support planes in the bottom band of ``box``."""
    local_z = box.to_local(points)[:, 2]
    candidates = np.flatnonzero(local_z <= -box.half_extent[2] + config.support_band)
    removed = np.zeros(len(points), dtype=bool)
    rng = np.random.default_rng(config.seed)
    up = box.rotation[:, 2]
    min_cos = np.cos(np.radians(config.max_plane_tilt_deg))
    for _ in range(config.max_supports):
        pool = candidates[~removed[candidates]]
        if len(pool) < 3:
            break
        sample = points[pool if len(pool) <= 20_000 else rng.choice(pool, 20_000, replace=False)]
        triples = sample[rng.integers(0, len(sample), (config.ransac_trials, 3))]
        normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
        length = np.linalg.norm(normals, axis=1)
        ok = length > 1e-12
        normals[ok] /= length[ok, None]
        ok &= np.abs(normals @ up) >= min_cos  # only near-horizontal planes are supports
        if not ok.any():
            break
        normals, offsets = normals[ok], -np.einsum("ij,ij->i", normals[ok], triples[ok, 0])
        inliers = np.abs(sample @ normals.T + offsets) <= config.plane_distance
        best = int(inliers.sum(axis=0).argmax())
        # Refine on every pool point near the best hypothesis, then judge the patch.
        near = pool[np.abs(points[pool] @ normals[best] + offsets[best]) <= config.plane_distance]
        if len(near) < 3:
            break
        normal, offset = _fit_plane(points[near])
        on_plane = pool[np.abs(points[pool] @ normal + offset) <= config.plane_distance]
        if abs(normal @ up) < min_cos or len(on_plane) < 3:
            break
        area, fill = _patch_fill(points[on_plane], config.fill_cell)
        if area < config.min_plane_area or fill < config.min_plane_fill:
            break  # the best remaining plane is foliage, not a support
        removed[on_plane] = True
    return removed


def remove_statistical_outliers(points: np.ndarray, neighbours: int = 20, std_ratio: float = 2.0) -> np.ndarray:
    """Mask of the points kept by open3d's statistical outlier removal."""
    import open3d as o3d

    if len(points) <= neighbours:
        return np.ones(len(points), dtype=bool)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    _, kept = cloud.remove_statistical_outlier(nb_neighbors=neighbours, std_ratio=std_ratio)
    mask = np.zeros(len(points), dtype=bool)
    mask[np.asarray(kept, dtype=np.int64)] = True
    return mask


def voxel_downsample(points: np.ndarray, voxel_size: float) -> np.ndarray:
    """open3d voxel downsampling: one point (the mean) per occupied voxel, in a stable order."""
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    out = np.asarray(cloud.voxel_down_sample(voxel_size).points)
    return out[np.lexsort(out.T[::-1])]  # sorted, so runs compare equal file to file


def fragment_mask(points: np.ndarray, radius: float, min_share: float) -> np.ndarray:
    """Mask of the points in connected components (26-neighbour voxels of size ``radius``) holding
    at least ``min_share`` of all points."""
    keys = voxels.voxel_keys(points, radius)
    cells, inverse = np.unique(voxels.encode_keys(keys), return_inverse=True)
    cell_keys = voxels.decode_keys(cells)
    rows, cols = [], []
    # Half of the 26 neighbour offsets suffice: the graph is undirected.
    offsets = [o for o in np.ndindex(3, 3, 3) if o > (1, 1, 1)]
    for off in offsets:
        codes = voxels.encode_keys(cell_keys + (np.array(off) - 1))
        pos = np.searchsorted(cells, codes).clip(max=len(cells) - 1)
        hit = cells[pos] == codes
        rows.append(np.flatnonzero(hit))
        cols.append(pos[hit])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    graph = scipy.sparse.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(cells), len(cells)))
    _, component = connected_components(graph, directed=False)
    sizes = np.bincount(component[inverse])
    return sizes[component[inverse]] >= min_share * len(points)


def clean_scan(points: np.ndarray, box=None, config: CleanConfig = CleanConfig()) -> CleanResult:
    """Run the cleaning steps on ``points`` (reference frame, metres); without a ``box`` the crop
    and support steps are skipped."""
    points = checked_cloud(points, "scan")
    counts = {"raw": len(points)}
    if box is not None:
        points = crop_to_box(points, box, config.crop_margin)
        if len(points) == 0:
            raise PointCloudError("no point of the scan lies in the plant box: is the scan aligned "
                                  "to the site's reference frame (landmarks) and in metres?")
        counts["cropped"] = len(points)
        points = points[~find_support_planes(points, box, config)]
        counts["supports_removed"] = len(points)
    points = points[remove_statistical_outliers(points, config.sor_neighbours, config.sor_std_ratio)]
    counts["outliers_removed"] = len(points)
    points = voxel_downsample(points, config.voxel_size)
    counts["downsampled"] = len(points)
    points = points[fragment_mask(points, config.fragment_radius, config.min_fragment_share)]
    counts["fragments_removed"] = len(points)
    if len(points) == 0:
        raise PointCloudError("cleaning removed every point")
    return CleanResult(points=points, counts=counts)
