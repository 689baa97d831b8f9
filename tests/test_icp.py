"""Deterministic rigid ICP (tpvp.registration.icp): brute-force references, determinism, Open3D agreement."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tpvp.config import PoseNoiseConfig
from tpvp.experiments import pose_noise as pn
from tpvp.registration import icp


def _rotation(axis, degrees):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = math.radians(degrees)
    return np.eye(3) + math.sin(a) * k + (1 - math.cos(a)) * k @ k


def _rigid(degrees, axis, translation, centre):
    t = np.eye(4)
    t[:3, :3] = _rotation(axis, degrees)
    t[:3, 3] = centre - t[:3, :3] @ centre + np.asarray(translation)
    return t


def _corner(seed=0, spacing=0.02, jitter=0.002):
    """Three jittered orthogonal walls (a room corner): well-posed for both ICP variants."""
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.arange(0, 0.4, spacing), np.arange(0, 0.4, spacing))
    u, v, z = u.ravel(), v.ravel(), np.zeros(u.size)
    walls = np.concatenate([np.stack([u, v, z], 1), np.stack([u, z, v], 1), np.stack([z, u, v], 1)])
    walls = np.unique(walls, axis=0)
    return walls + rng.uniform(-jitter, jitter, walls.shape) * np.array([1, 1, 1])


def _sphere(n, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, 3))
    return 0.2 * x / np.linalg.norm(x, axis=1, keepdims=True)


# ------------------------------------------------------------------------ brute-force references
def test_correspondences_match_an_all_pairs_search():
    rng = np.random.default_rng(1)
    target_points, source = rng.random((300, 3)) * 0.2, rng.random((120, 3)) * 0.2
    target = icp.prepare_target(target_points)
    for max_distance in (0.005, 0.01, 0.03, 1.0):
        got = icp.correspondences(source, target, max_distance)
        d2 = ((source[:, None] - target_points[None]) ** 2).sum(axis=2)
        nearest = d2.argmin(axis=1)
        keep = np.flatnonzero(d2[np.arange(len(source)), nearest] < max_distance**2)
        np.testing.assert_array_equal(got.source, keep)
        np.testing.assert_array_equal(got.target, nearest[keep])
        np.testing.assert_allclose(got.distance2, d2[keep, nearest[keep]], rtol=1e-12)
        fitness, rmse = icp.fitness_and_rmse(got, len(source))
        assert fitness == len(keep) / len(source)
        assert rmse == pytest.approx(math.sqrt(d2[keep, nearest[keep]].mean()) if len(keep) else 0.0, rel=1e-12)


def test_voxel_downsample_is_the_sorted_mean_per_voxel():
    rng = np.random.default_rng(2)
    points = rng.random((500, 3)) * 0.1
    got = icp.voxel_downsample(points, 0.02)
    keys = np.floor((points - (points.min(axis=0) - 0.01)) / 0.02).astype(int)
    expected = [points[(keys == k).all(axis=1)].mean(axis=0) for k in np.unique(keys, axis=0)]  # lexicographic
    np.testing.assert_allclose(got, np.array(expected), rtol=0, atol=1e-15)


def test_normals_are_the_smallest_eigenvector_of_the_neighbourhood():
    points = _sphere(400, seed=3)
    normals = icp.estimate_normals(points, radius=0.05, max_nn=12)
    for i in range(0, 400, 37):
        d = np.linalg.norm(points - points[i], axis=1)
        nb = np.argsort(d)[:12]
        nb = nb[d[nb] < 0.05]
        w, v = np.linalg.eigh(np.cov(points[nb].T, bias=True))
        assert abs(v[:, 0] @ normals[i]) == pytest.approx(1.0, abs=1e-9)
        # on a sphere the PCA normal is near the radial direction
        assert abs(normals[i] @ points[i] / 0.2) > 0.95
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)


def test_smallest_eigenvectors_match_numpy_also_when_repeated():
    rng = np.random.default_rng(4)
    m = rng.normal(size=(200, 3, 3))
    cov = m @ m.transpose(0, 2, 1)
    got = icp.smallest_eigenvectors(cov)
    _, v = np.linalg.eigh(cov)
    np.testing.assert_allclose(np.abs((got * v[:, :, 0]).sum(axis=1)), 1.0, atol=1e-9)
    line = np.diag([2.0, 0.0, 0.0])[None]  # collinear neighbours: any vector of the y-z plane is right
    e = icp.smallest_eigenvectors(line)[0]
    assert abs(e[0]) < 1e-12 and np.linalg.norm(e) == pytest.approx(1.0)
    np.testing.assert_array_equal(icp.smallest_eigenvectors(np.zeros((1, 3, 3))), [[0.0, 0.0, 1.0]])


def test_point_to_plane_step_solves_the_normal_equations():
    target_points = _corner(seed=5)
    target = icp.prepare_target(target_points, normal_radius=0.05, normal_max_nn=20)
    source = icp.transform_points(_rigid(1.0, [1, 2, 3], [0.003, -0.002, 0.004], target_points.mean(0)),
                                  target_points)
    corr = icp.correspondences(source, target, 0.05)
    s, t, n = source[corr.source], target.points[corr.target], target.normals[corr.target]
    jac = np.concatenate([np.cross(s, n), n], axis=1)
    x = np.linalg.lstsq(jac, -((s - t) * n).sum(axis=1), rcond=None)[0]
    expected = np.eye(4)
    expected[:3, :3] = _rotation([0, 0, 1], math.degrees(x[2])) @ _rotation([0, 1, 0], math.degrees(x[1])) \
        @ _rotation([1, 0, 0], math.degrees(x[0]))
    expected[:3, 3] = x[3:]
    np.testing.assert_allclose(icp.estimate_point_to_plane(source, target, corr), expected, atol=1e-12)


@pytest.mark.parametrize("method", icp.METHODS)
def test_a_known_rigid_motion_is_recovered_on_clean_data(method):
    target_points = _corner(seed=6)
    target = icp.prepare_target(target_points, normal_radius=0.05, normal_max_nn=20)
    motion = _rigid(1.0, [0.3, -1.0, 0.5], [0.003, -0.002, 0.002], target_points.mean(axis=0))
    source = icp.transform_points(np.linalg.inv(motion), target_points)  # target = motion(source)
    result = icp.icp(source, target, (0.02, 0.01), method=method, max_iteration=50)
    np.testing.assert_allclose(result.transformation, motion, atol=1e-9)
    assert result.fitness == 1.0 and result.inlier_rmse < 1e-9


# ------------------------------------------------------------------------------ determinism
def test_repeated_calls_are_bit_identical():
    target_points = _corner(seed=7, jitter=0.004)
    motion = _rigid(2.0, [1, 1, 0], [0.006, 0.0, -0.004], target_points.mean(axis=0))
    source = icp.transform_points(motion, target_points[::2]) + np.random.default_rng(8).normal(0, 0.001, (1, 3))
    runs = []
    for _ in range(2):
        target = icp.prepare_target(target_points, voxel=0.01, normal_radius=0.03, normal_max_nn=30)
        runs.append((target, icp.icp(icp.voxel_downsample(source, 0.01), target, (0.05, 0.02, 0.01))))
    (t1, r1), (t2, r2) = runs
    np.testing.assert_array_equal(t1.points, t2.points)
    np.testing.assert_array_equal(t1.normals, t2.normals)
    np.testing.assert_array_equal(r1.transformation, r2.transformation)
    assert (r1.fitness, r1.inlier_rmse, r1.iterations) == (r2.fitness, r2.inlier_rmse, r2.iterations)


# ---------------------------------------------------------------------------- Open3D agreement
@pytest.mark.parametrize("method", icp.METHODS)
def test_agrees_with_open3d_registration_icp(method):
    """Same source order, same downsampled target: Open3D's ICP and this one agree to 1e-9 (m and
    rotation entries; observed ~1e-15) with equal fitness. Only rounding separates them here; on voxel
    lattices, ties in the k-nearest normal neighbourhoods can also differ (observed ~1e-5 m)."""
    o3d = pytest.importorskip("open3d")
    reg = o3d.pipelines.registration
    rng = np.random.default_rng(9)
    cloud = np.concatenate([_sphere(3000, seed=10), _corner(seed=11, spacing=0.01) - 0.1])
    motion = _rigid(3.0, [0.2, 1.0, -0.4], [0.01, -0.008, 0.006], cloud.mean(axis=0))
    view = icp.transform_points(motion, cloud[rng.random(len(cloud)) < 0.5])
    target = icp.prepare_target(cloud, voxel=0.01, normal_radius=0.03, normal_max_nn=30)
    source = icp.voxel_downsample(view, 0.01)
    np.testing.assert_allclose(  # Open3D's centroids, in another order
        np.sort(target.points, axis=0),
        np.sort(np.asarray(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud)).voxel_down_sample(0.01).points),
                axis=0), atol=1e-15, rtol=0)
    o3d_target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(target.points))
    o3d_target.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.03, max_nn=30))
    dots = np.abs((np.asarray(o3d_target.normals) * target.normals).sum(axis=1))
    assert dots.min() > 1 - 1e-9
    o3d_source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source))
    estimation = reg.TransformationEstimationPointToPlane() if method == "point_to_plane" else (
        reg.TransformationEstimationPointToPoint())
    transform = np.eye(4)
    for distance in (0.05, 0.02, 0.01):
        theirs = reg.registration_icp(o3d_source, o3d_target, distance, transform, estimation,
                                      reg.ICPConvergenceCriteria(max_iteration=10))
        transform = np.array(theirs.transformation)
    ours = icp.icp(source, target, (0.05, 0.02, 0.01), method=method, max_iteration=10)
    np.testing.assert_allclose(ours.transformation, transform, atol=1e-9)
    assert ours.fitness == pytest.approx(theirs.fitness, abs=1e-12)
    assert ours.inlier_rmse == pytest.approx(theirs.inlier_rmse, rel=1e-6)
    assert ours.fitness > 0.9


# ------------------------------------------------------------------------------- bad input
def test_too_few_points_give_identity_and_no_acceptance():
    target = icp.prepare_target(_corner(seed=12), normal_radius=0.05)
    for few in (np.zeros((0, 3)), np.zeros((1, 3)), np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]])):
        result = icp.icp(few, target, (0.05,))
        np.testing.assert_array_equal(result.transformation, np.eye(4))
        assert result.fitness == 0.0 and result.iterations == 0
        transform, fitness, accepted = pn.refine_icp(few, _corner(seed=12), PoseNoiseConfig(icp_voxel=0.02))
        np.testing.assert_array_equal(transform, np.eye(4))
        assert fitness == 0.0 and not accepted
    tiny_target = icp.prepare_target(np.zeros((2, 3)), normal_radius=0.05)
    assert icp.icp(_corner(seed=13), tiny_target, (0.05,)).fitness == 0.0
    with pytest.raises(ValueError):
        icp.icp(_corner(seed=13), target, (0.05,), method="plane")
