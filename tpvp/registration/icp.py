"""A small deterministic rigid ICP over numpy arrays (scipy's cKDTree, no Open3D).

Why not Open3D's ``registration_icp``: it sums its normal equations in OpenMP reductions, so the
same call repeated in one process can differ in the last digits (also with one thread), and the
shipped pose-noise rows (Table VII) could not be reproduced bit for bit. Here every reduction is a
fixed-order numpy sum and every KD-tree query runs on one thread: the same input gives the same
bits. The algorithm follows Open3D's so that results agree with it to rounding (and to ties in
nearest-neighbour searches): voxel centroids, hybrid-neighbourhood PCA normals, point-to-plane
(linearised) or point-to-point (Kabsch) estimation, correspondences strictly within the maximum
distance, and Open3D's convergence test (fitness and inlier RMSE change below 1e-6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

METHODS = ("point_to_plane", "point_to_point")


def _cloud(points) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))


def voxel_downsample(points, voxel: float) -> np.ndarray:
    """Mean of the points in every ``voxel`` cell, one point per occupied cell, ordered by cell key.

    The grid starts half a voxel below the cloud's minimum, as Open3D's ``voxel_down_sample``; sums
    run in point order (``np.bincount``), so the centroids are those of Open3D, and the fixed output
    order (Open3D's follows a hash map) makes everything downstream deterministic.
    """
    points = _cloud(points)
    if len(points) == 0:
        return points.copy()
    lower = points.min(axis=0) - 0.5 * voxel
    keys = np.floor((points - lower) / voxel).astype(np.int64)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    sums = np.stack([np.bincount(inverse, weights=points[:, i], minlength=len(counts)) for i in range(3)], axis=1)
    return sums / counts[:, None].astype(np.float64)


def _dot(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _unit_null_vector(a, value):
    """Open3D's ``ComputeEigenvector0``: the eigenvector of ``value``, as the largest cross product of
    two rows of ``A - value I`` (vectorised over the leading axis)."""
    rows = a - value[:, None, None] * np.eye(3)
    crosses = np.stack([np.cross(rows[:, 0], rows[:, 1]), np.cross(rows[:, 0], rows[:, 2]),
                        np.cross(rows[:, 1], rows[:, 2])], axis=1)
    d = _dot(crosses, crosses)
    pick = np.where(d[:, 1] > d[:, 0], 1, 0)
    pick = np.where(d[:, 2] > d[np.arange(len(d)), pick], 2, pick)
    rows_n = np.arange(len(d))
    return crosses[rows_n, pick] / np.sqrt(d[rows_n, pick])[:, None]


def _second_vector(a, evec0, value):
    """Open3D's ``ComputeEigenvector1``: the eigenvector of ``value`` orthogonal to ``evec0``."""
    e0, e1, e2 = evec0[:, 0], evec0[:, 1], evec0[:, 2]
    first = np.abs(e0) > np.abs(e1)
    inv = np.where(first, 1 / np.sqrt(e0 * e0 + e2 * e2), 1 / np.sqrt(e1 * e1 + e2 * e2))
    zero = np.zeros_like(e0)
    u = np.where(first[:, None], np.stack([-e2 * inv, zero, e0 * inv], axis=1),
                 np.stack([zero, e2 * inv, -e1 * inv], axis=1))
    v = np.cross(evec0, u)
    au = np.stack([_dot(a[:, i], u) for i in range(3)], axis=1)  # A is symmetric: row i = column i
    av = np.stack([_dot(a[:, i], v) for i in range(3)], axis=1)
    m00, m01, m11 = _dot(u, au) - value, _dot(u, av), _dot(v, av) - value
    a00, a01, a11 = np.abs(m00), np.abs(m01), np.abs(m11)
    left = a00 >= a11  # the larger diagonal entry and m01 give the direction
    big, other = np.where(left, m00, m11), m01
    by_big = np.where(left, a00, a11) >= a01
    ratio = np.where(by_big, other / big, big / other)
    scale = 1 / np.sqrt(1 + ratio * ratio)
    # by_big: m01' = ratio * scale, big' = scale; else big' = ratio * scale, m01' = scale
    m01n, bign = np.where(by_big, ratio * scale, scale), np.where(by_big, scale, ratio * scale)
    out = np.where(left[:, None], m01n[:, None] * u - bign[:, None] * v, bign[:, None] * u - m01n[:, None] * v)
    degenerate = np.maximum(np.where(left, a00, a11), a01) == 0
    return np.where(degenerate[:, None], u, out)


def smallest_eigenvectors(cov) -> np.ndarray:
    """Eigenvector of the smallest eigenvalue of each symmetric ``(n, 3, 3)`` matrix, by Open3D's
    ``FastEigen3x3`` (Geometric Tools' closed form), vectorised: the same choice as Open3D also where
    the smallest eigenvalue is repeated (collinear neighbours on a voxel lattice), where any solver
    is free to return any vector of the eigenspace. Zero matrices give ``(0, 0, 1)``."""
    cov = np.asarray(cov, dtype=np.float64).reshape(-1, 3, 3)
    n = len(cov)
    out = np.tile([0.0, 0.0, 1.0], (n, 1))
    max_coeff = cov.reshape(n, 9).max(axis=1)
    live = max_coeff != 0
    a = cov[live] / max_coeff[live, None, None]
    norm = a[:, 0, 1] * a[:, 0, 1] + a[:, 0, 2] * a[:, 0, 2] + a[:, 1, 2] * a[:, 1, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        q = (a[:, 0, 0] + a[:, 1, 1] + a[:, 2, 2]) / 3
        b00, b11, b22 = a[:, 0, 0] - q, a[:, 1, 1] - q, a[:, 2, 2] - q
        p = np.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + norm * 2) / 6)
        c00 = b11 * b22 - a[:, 1, 2] * a[:, 1, 2]
        c01 = a[:, 0, 1] * b22 - a[:, 1, 2] * a[:, 0, 2]
        c02 = a[:, 0, 1] * a[:, 1, 2] - b11 * a[:, 0, 2]
        det = (b00 * c00 - a[:, 0, 1] * c01 + a[:, 0, 2] * c02) / (p * p * p)
        half_det = np.minimum(np.maximum(det * 0.5, -1.0), 1.0)
        angle = np.arccos(half_det) / 3.0
        beta2 = np.cos(angle) * 2
        beta0 = np.cos(angle + 2.09439510239319549) * 2
        beta1 = -(beta0 + beta2)
        ev0, ev1, ev2 = q + p * beta0, q + p * beta1, q + p * beta2
        up = half_det >= 0  # Open3D starts from the eigenvalue farthest from the others
        first_value, others = np.where(up, ev2, ev0), np.where(up, ev0, ev2)
        first = _unit_null_vector(a, first_value)
        second = _second_vector(a, first, ev1)
        third = np.where(up[:, None], np.cross(second, first), np.cross(first, second))
        first_min = (first_value < others) & (first_value < ev1)
        second_min = (ev1 < ev0) & (ev1 < ev2)
        general = np.where(first_min[:, None], first, np.where(second_min[:, None], second, third))
    diag = cov[live][:, [0, 1, 2], [0, 1, 2]]
    axis = np.where((diag[:, 0] < diag[:, 1]) & (diag[:, 0] < diag[:, 2]), 0,
                    np.where((diag[:, 1] < diag[:, 0]) & (diag[:, 1] < diag[:, 2]), 1, 2))
    out[live] = np.where((norm > 0)[:, None], general, np.eye(3)[axis])
    bad = ~np.isfinite(out).all(axis=1)  # Open3D would keep a NaN here; it would poison the ICP
    out[bad] = [0.0, 0.0, 1.0]
    return out


def estimate_normals(points, radius: float, max_nn: int, tree: cKDTree | None = None) -> np.ndarray:
    """Unit normals from each point's neighbourhood: its ``max_nn`` nearest points within
    ``radius`` (itself included), like Open3D's ``KDTreeSearchParamHybrid``; covariance from
    sequentially summed moments and the eigenvector of its smallest eigenvalue as Open3D computes
    them (:func:`smallest_eigenvectors`). The sign is arbitrary (point-to-plane ICP does not depend
    on it). Fewer than 3 neighbours: ``(0, 0, 1)``, as Open3D."""
    points = _cloud(points)
    normals = np.zeros_like(points)
    normals[:, 2] = 1.0
    if len(points) == 0:
        return normals
    tree = cKDTree(points) if tree is None else tree
    k = min(int(max_nn), len(points))
    _, idx = tree.query(points, k=k, distance_upper_bound=radius * (1 + 1e-9), workers=1)
    idx = idx.reshape(len(points), k)
    valid = idx < len(points)
    safe = np.where(valid, idx, 0)
    valid &= ((points[safe] - points[:, None, :]) ** 2).sum(axis=2) < radius * radius  # Open3D: d^2 < r^2
    count = valid.sum(axis=1)
    ok = count >= 3
    if not ok.any():
        return normals
    safe, valid, n = safe[ok], valid[ok], count[ok].astype(np.float64)
    moments = np.zeros((len(safe), 9))  # x, y, z, xx, xy, xz, yy, yz, zz, summed in neighbour order
    for j in range(k):
        x = points[safe[:, j]]
        terms = np.stack([x[:, 0], x[:, 1], x[:, 2], x[:, 0] * x[:, 0], x[:, 0] * x[:, 1], x[:, 0] * x[:, 2],
                          x[:, 1] * x[:, 1], x[:, 1] * x[:, 2], x[:, 2] * x[:, 2]], axis=1)
        moments += np.where(valid[:, j, None], terms, 0.0)
    m = moments / n[:, None]
    cov = np.empty((len(m), 3, 3))
    for (r, c), e in zip(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)), (3, 4, 5, 6, 7, 8)):
        cov[:, r, c] = cov[:, c, r] = m[:, e] - m[:, r] * m[:, c]
    normals[ok] = smallest_eigenvectors(cov)
    return normals


@dataclass(frozen=True)
class Target:
    """A registration target prepared once for many sources: points, normals (or None) and KD-tree."""

    points: np.ndarray
    normals: np.ndarray | None
    tree: cKDTree


def prepare_target(points, voxel: float | None = None, normal_radius: float | None = None,
                   normal_max_nn: int = 30) -> Target:
    """Downsample ``points`` at ``voxel`` (None: as given), estimate normals when ``normal_radius``
    is given (point-to-plane needs them) and build the KD-tree once."""
    points = _cloud(points) if voxel is None else voxel_downsample(points, voxel)
    tree = cKDTree(points)
    normals = None if normal_radius is None else estimate_normals(points, normal_radius, normal_max_nn, tree)
    return Target(points, normals, tree)


@dataclass(frozen=True)
class Correspondences:
    source: np.ndarray  # indices into the source points
    target: np.ndarray  # indices into the target points
    distance2: np.ndarray  # squared distances


def correspondences(source, target: Target, max_distance: float) -> Correspondences:
    """Nearest target point of every source point, kept when strictly closer than ``max_distance``
    (Open3D's hybrid search with one neighbour)."""
    source = _cloud(source)
    _, idx = target.tree.query(source, k=1, distance_upper_bound=max_distance * (1 + 1e-9),
                               workers=1)
    found = np.flatnonzero(idx < len(target.points))
    d2 = ((source[found] - target.points[idx[found]]) ** 2).sum(axis=1)
    keep = d2 < max_distance * max_distance
    return Correspondences(found[keep], idx[found[keep]], d2[keep])


def fitness_and_rmse(corr: Correspondences, n_source: int) -> tuple[float, float]:
    """Open3D's result measures: inlier correspondences per source point, RMSE of their distances."""
    n = len(corr.source)
    if n == 0 or n_source == 0:
        return 0.0, 0.0
    return n / n_source, float(np.sqrt(corr.distance2.sum() / n))


def _euler_to_matrix(x: np.ndarray) -> np.ndarray:
    """Open3D's ``TransformVector6dToMatrix4d``: ``Rz(gamma) Ry(beta) Rx(alpha)``, translation ``x[3:]``."""
    a, b, g = x[:3]
    ca, sa, cb, sb, cg, sg = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(g), np.sin(g)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
    ry = np.array([[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]])
    rz = np.array([[cg, -sg, 0.0], [sg, cg, 0.0], [0.0, 0.0, 1.0]])
    out = np.eye(4)
    out[:3, :3] = rz @ ry @ rx
    out[:3, 3] = x[3:]
    return out


def point_to_plane_system(source, target: Target, corr: Correspondences) -> tuple[np.ndarray, np.ndarray]:
    """``(J^T J, J^T r)`` of the linearised point-to-plane residuals ``(s - t) . n``, with rows
    ``J = [s x n, n]`` (small-angle rotation, then translation); summed in a fixed order."""
    s = _cloud(source)[corr.source]
    t, n = target.points[corr.target], target.normals[corr.target]
    r = ((s - t) * n).sum(axis=1)
    jac = np.empty((len(s), 6))
    jac[:, 0] = s[:, 1] * n[:, 2] - s[:, 2] * n[:, 1]  # s x n, written out (np.cross is slow on small arrays)
    jac[:, 1] = s[:, 2] * n[:, 0] - s[:, 0] * n[:, 2]
    jac[:, 2] = s[:, 0] * n[:, 1] - s[:, 1] * n[:, 0]
    jac[:, 3:] = n
    jtj = (jac[:, :, None] * jac[:, None, :]).sum(axis=0)
    jtr = (jac * r[:, None]).sum(axis=0)
    return jtj, jtr


def estimate_point_to_plane(source, target: Target, corr: Correspondences) -> np.ndarray:
    """One Gauss-Newton step of point-to-plane ICP (Open3D's ``TransformationEstimationPointToPlane``):
    solve ``J^T J x = -J^T r``; identity without correspondences or when ``|det J^T J| < 1e-6``
    (Open3D's singularity test)."""
    if len(corr.source) == 0 or target.normals is None:
        return np.eye(4)
    jtj, jtr = point_to_plane_system(source, target, corr)
    det = np.linalg.det(jtj)
    if not np.isfinite(det) or abs(det) < 1e-6:
        return np.eye(4)
    return _euler_to_matrix(np.linalg.solve(jtj, -jtr))


def estimate_point_to_point(source, target: Target, corr: Correspondences) -> np.ndarray:
    """Least-squares rigid motion of the matched pairs (Kabsch / Umeyama without scale, as Open3D's
    ``TransformationEstimationPointToPoint``); identity without correspondences."""
    if len(corr.source) == 0:
        return np.eye(4)
    s, t = _cloud(source)[corr.source], target.points[corr.target]
    sm, tm = s.mean(axis=0), t.mean(axis=0)
    cov = ((t - tm)[:, :, None] * (s - sm)[:, None, :]).sum(axis=0) / len(s)
    u, _, vt = np.linalg.svd(cov)
    d = np.ones(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        d[2] = -1.0
    out = np.eye(4)
    out[:3, :3] = (u * d) @ vt
    out[:3, 3] = tm - out[:3, :3] @ sm
    return out


def transform_points(transform, points) -> np.ndarray:
    transform = np.asarray(transform, dtype=np.float64)
    return _cloud(points) @ transform[:3, :3].T + transform[:3, 3]


@dataclass(frozen=True)
class IcpResult:
    transformation: np.ndarray  # 4x4, maps the source onto the target
    fitness: float  # inlier correspondences / source points (last stage's distance)
    inlier_rmse: float
    iterations: int  # over all stages


def icp(source, target: Target, max_distances, init=None, method: str = "point_to_plane",
        max_iteration: int = 30, relative_fitness: float = 1e-6, relative_rmse: float = 1e-6) -> IcpResult:
    """Rigid ICP of ``source`` points onto a :func:`prepare_target` target, one stage per maximum
    correspondence distance (coarse to fine), each started from the previous one's result.

    Every stage is Open3D's ``registration_icp`` loop: estimate, apply the update to the moving
    points, re-match, and stop after ``max_iteration`` updates or when fitness and inlier RMSE both
    changed by less than the relative thresholds. Fewer than 3 source or target points: ``init``
    (identity by default) and fitness 0, as there is nothing to register.
    """
    if method not in METHODS:
        raise ValueError(f"unknown ICP method {method!r}; choose one of {', '.join(METHODS)}")
    source = _cloud(source)
    transform = np.eye(4) if init is None else np.array(init, dtype=np.float64).reshape(4, 4)
    distances = tuple(float(d) for d in np.atleast_1d(max_distances))
    if len(source) < 3 or len(target.points) < 3 or not distances:
        return IcpResult(np.eye(4) if init is None else transform, 0.0, 0.0, 0)
    if method == "point_to_plane" and target.normals is None:
        raise ValueError("point-to-plane ICP needs target normals (prepare_target with normal_radius)")
    estimate = estimate_point_to_plane if method == "point_to_plane" else estimate_point_to_point
    iterations = 0
    for distance in distances:
        moving = source if np.array_equal(transform, np.eye(4)) else transform_points(transform, source)
        corr = correspondences(moving, target, distance)
        fitness, rmse = fitness_and_rmse(corr, len(source))
        for _ in range(int(max_iteration)):
            update = estimate(moving, target, corr)
            transform = update @ transform
            moving = transform_points(update, moving)
            iterations += 1
            previous = (fitness, rmse)
            corr = correspondences(moving, target, distance)
            fitness, rmse = fitness_and_rmse(corr, len(source))
            if abs(previous[0] - fitness) < relative_fitness and abs(previous[1] - rmse) < relative_rmse:
                break
    return IcpResult(transform, float(fitness), float(rmse), iterations)
