"""Pose-noise study (Table VII): noise model, rendering at perturbed poses, fusion, ICP, metrics."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from tpvp.config import PoseNoiseConfig
from tpvp.errors import ConfigError
from tpvp.experiments import pose_noise as pn
from tpvp.scene.boxes import room_config
from tpvp.scene.grid import grid_from_points
from tpvp.sensor.camera import D435, look_at_rotation
from tpvp.sensor.sensor import ROW_RANGE, ROW_SENSOR, SensorConfig, observe_poses, view_poses
from tpvp.synthetic.greenhouse import generate_row

RES = 0.02  # truth grid of the small row (the paper's rows: 0.01 m)
PIXEL = SensorConfig(model="pixel", max_range=ROW_RANGE, pixel_stride=8)
# ICP scaled to the 2 cm truth grid (the defaults are for 1 cm)
SMALL_ICP = dict(icp_voxel=RES, icp_max_correspondence=(0.06, 0.04, 0.02))


@pytest.fixture(scope="module")
def scene():
    """A coarse generated room1 row (8 mm samples, 2 cm truth grid), its noise-free passive map
    and 8 active views aimed at voxels the passive views missed."""
    row = generate_row("room1", seed=0, session=1, point_spacing=0.008)
    truth = np.asarray(row.points)
    grid = grid_from_points(truth, RES)
    room = room_config("room1")
    passive = pn.passive_map(grid, room.initial_positions, room.initial_look_ats)
    rng = np.random.default_rng(1)
    seen = grid.ids_of(np.floor(passive / RES).astype(np.int64))
    missed = np.setdiff1d(np.arange(grid.size), seen[seen >= 0])
    targets = grid.centres[rng.choice(missed, 8, replace=False)]
    candidates = np.asarray(room.candidate_positions)
    order = np.argsort(np.linalg.norm(candidates[None] - targets[:, None], axis=2), axis=1)
    used, positions = set(), []
    for row_order in order:
        i = next(int(j) for j in row_order if int(j) not in used)
        used.add(i)
        positions.append(candidates[i])
    positions, rotations = view_poses(grid, np.array(positions), targets)
    return {"truth": truth, "grid": grid, "passive": passive, "positions": positions, "rotations": rotations,
            "look_ats": targets, "room": room}


# ------------------------------------------------------------------------------------- config
def test_config_defaults_are_the_paper_protocol():
    c = PoseNoiseConfig()
    assert c.levels == ((0.0, 0.0), (0.002, 0.5), (0.005, 1.0), (0.01, 2.0))
    assert c.draws == 5 and c.taus == (0.01, 0.02) and c.icp == (False, True)
    assert c.icp_max_correspondence == (0.05, 0.02, 0.01) and c.cover_resolution == 0.04


@pytest.mark.parametrize("bad", [dict(levels=((0.01, -1.0),)), dict(levels=()), dict(draws=0), dict(taus=(0.0,)),
                                 dict(fusion_voxel=0.0), dict(icp_method="plane"), dict(icp_min_fitness=1.5),
                                 dict(icp_max_correspondence=()), dict(icp=(True, True)),
                                 dict(levels=((0.01, 2.0), (0.01, 2.0)))])
def test_config_rejects_bad_values(bad):
    with pytest.raises(ConfigError):
        PoseNoiseConfig(**bad)


# -------------------------------------------------------------------------------------- noise
def test_zero_noise_returns_the_nominal_poses_bitwise(scene):
    p, r = scene["positions"], scene["rotations"]
    tp, tr = pn.perturb_poses(p, r, 0.0, 0.0, np.random.default_rng(0))
    assert np.array_equal(tp, p) and np.array_equal(tr, r)
    tp, tr = pn.perturb_poses(p, r, 0.01, 0.0, np.random.default_rng(0))
    assert np.array_equal(tr, r) and not np.array_equal(tp, p)


def test_perturbation_statistics():
    n = 20000
    rotation = look_at_rotation([0.3, -0.2, 1.0], [0.0, 0.5, 0.2])
    positions = np.tile([0.3, -0.2, 1.0], (n, 1))
    rotations = np.tile(rotation, (n, 1, 1))
    sigma_t, sigma_r = 0.005, 2.0
    tp, tr = pn.perturb_poses(positions, rotations, sigma_t, sigma_r, np.random.default_rng(7))
    dt = tp - positions
    np.testing.assert_allclose(dt.std(axis=0), sigma_t, rtol=0.03)
    np.testing.assert_allclose(dt.mean(axis=0), 0.0, atol=4 * sigma_t / math.sqrt(n))
    # proper rotations; the noise is R_nominal^T R_true (applied in the camera frame)
    np.testing.assert_allclose(tr @ tr.transpose(0, 2, 1), np.broadcast_to(np.eye(3), tr.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(tr), 1.0, atol=1e-12)
    noise = rotation.T @ tr
    angles = np.degrees(np.arccos(np.clip((np.trace(noise, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    # |theta| of theta ~ N(0, sigma_r): half-normal, RMS sigma_r, mean sigma_r sqrt(2 / pi)
    assert math.sqrt((angles**2).mean()) == pytest.approx(sigma_r, rel=0.03)
    assert angles.mean() == pytest.approx(sigma_r * math.sqrt(2 / math.pi), rel=0.03)
    assert stats.kstest(angles, stats.halfnorm(scale=sigma_r).cdf).pvalue > 1e-3
    # isotropic axes: the rotation vectors average to zero and have equal spread per axis
    axes = np.stack([noise[:, 2, 1] - noise[:, 1, 2], noise[:, 0, 2] - noise[:, 2, 0],
                     noise[:, 1, 0] - noise[:, 0, 1]], axis=1)
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    np.testing.assert_allclose(axes.mean(axis=0), 0.0, atol=0.03)
    np.testing.assert_allclose((axes**2).mean(axis=0), 1 / 3, atol=0.02)


# ---------------------------------------------------------------------------------- rendering
@pytest.mark.parametrize("sensor", [ROW_SENSOR, PIXEL], ids=["reference", "pixel"])
def test_view_rendered_at_its_own_pose_lies_on_the_truth(scene, sensor):
    from scipy.spatial import cKDTree

    grid = scene["grid"]
    half_diagonal = math.sqrt(3) / 2 * RES
    for p, r in zip(scene["positions"][:3], scene["rotations"][:3]):
        cam = pn.render_view_points(grid, p, r, sensor)
        assert len(cam) > 10
        # camera frame (OpenCV): in front of the camera; a pixel's point projects onto that pixel
        # (the reference model also observes voxels that block a ray, whose centres may fall
        # outside the image)
        assert np.all(cam[:, 2] > 0)
        u = D435.fx * cam[:, 0] / cam[:, 2] + D435.cx
        v = D435.fy * cam[:, 1] / cam[:, 2] + D435.cy
        if sensor.model == "pixel":
            stride = sensor.pixel_stride
            np.testing.assert_allclose(u / stride, np.round(u / stride), atol=1e-6)
            np.testing.assert_allclose(v / stride, np.round(v / stride), atol=1e-6)
            assert u.min() > -1e-6 and u.max() < D435.width and v.min() > -1e-6 and v.max() < D435.height
        world = p + cam @ r.T
        # every point lies in (reference: at the centre of; pixel: on a face of) an observed voxel
        to_voxel = cKDTree(grid.centres).query(world)[0]
        assert to_voxel.max() <= half_diagonal + 1e-9
        if sensor.model == "reference":  # voxel centres: within half a diagonal of the surface
            assert cKDTree(scene["truth"]).query(world)[0].max() <= half_diagonal + 1e-9
            ids = np.flatnonzero(observe_poses(grid, p[None], r[None], sensor)[0])
            np.testing.assert_allclose(world, grid.centres[ids], rtol=0, atol=1e-12)
        else:  # depth = camera z: the point is where the pixel ray enters its voxel
            assert to_voxel.max() >= 0.4 * RES


@pytest.mark.parametrize("sensor", [ROW_SENSOR, PIXEL], ids=["reference", "pixel"])
def test_zero_noise_fusion_is_the_noise_free_fusion_bitwise(scene, sensor):
    grid, p, r, passive = scene["grid"], scene["positions"], scene["rotations"], scene["passive"]
    noise_free = pn.fuse(grid, p, r, p, r, sensor, passive_points=passive)
    tp, tr = pn.perturb_poses(p, r, 0.0, 0.0, np.random.default_rng(3))
    zero_noise = pn.fuse(grid, p, r, tp, tr, sensor, passive_points=passive)
    assert zero_noise.tobytes() == noise_free.tobytes()
    # and it is what the views see, rendered directly (no pose round trip)
    direct = pn.deduplicate(np.concatenate([passive, *pn.render_views(grid, p, r, sensor)]), 0.002)
    assert noise_free.tobytes() == direct.tobytes()
    if sensor.model == "reference":  # = the centres of the union of observed voxels (+ passive)
        seen = observe_poses(grid, p, r, sensor).any(axis=0)
        expected = np.unique(np.concatenate([passive, grid.centres[seen]]), axis=0)
        np.testing.assert_array_equal(np.unique(noise_free, axis=0), expected)


def test_noisy_view_is_rendered_at_the_true_pose_and_fused_at_the_nominal_pose(scene):
    grid, p, r = scene["grid"], scene["positions"][:2], scene["rotations"][:2]
    tp, tr = pn.perturb_poses(p, r, 0.01, 2.0, np.random.default_rng(5))
    fused = pn.measure_views(grid, p, r, tp, tr)
    for i in range(2):
        cam = pn.render_view_points(grid, tp[i], tr[i])  # measured in the true camera frame
        np.testing.assert_allclose(fused[i], p[i] + cam @ r[i].T, atol=1e-12)
        assert not np.allclose(fused[i], tp[i] + cam @ tr[i].T, atol=1e-3)


def test_deduplicate_keeps_first_point_per_voxel_unchanged():
    pts = np.array([[0.0101, 0.0, 0.0], [0.0199, 0.001, 0.0], [0.03, 0.0, 0.0], [0.0105, 0.0, 0.0]])
    out = pn.deduplicate(pts, 0.01)
    np.testing.assert_array_equal(out, pts[[0, 2]])


# ------------------------------------------------------------------------------------- ICP
def _rigid(angle_deg, axis, translation, centre):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    rot = pn._axis_angle_matrices(axis[None], np.array([math.radians(angle_deg)]))[0]
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = centre - rot @ centre + np.asarray(translation)
    return t


def test_icp_recovers_a_known_small_rigid_offset(scene):
    grid, room, passive = scene["grid"], scene["room"], scene["passive"]
    config = PoseNoiseConfig(**SMALL_ICP)
    target = pn.prepare_icp_target(passive, config)
    for k in (1, 7):  # passive views: full overlap with the map
        pos, rot = view_poses(grid, room.initial_positions[k:k + 1], room.initial_look_ats[k:k + 1])
        view = pn.render_views(grid, pos, rot)[0]
        offset = _rigid(1.5, [0.3, -1.0, 0.5], [0.008, -0.006, 0.005], view.mean(axis=0))
        moved = pn._apply(offset, view)
        before = np.linalg.norm(moved - view, axis=1).mean()
        transform, fitness, accepted = pn.refine_icp(moved, target, config)
        assert accepted and fitness > 0.8
        after = np.linalg.norm(pn._apply(transform, moved) - view, axis=1).mean()
        assert before > 0.009 and after < 0.1 * before
        residual = transform @ offset
        angle = math.degrees(math.acos(np.clip((np.trace(residual[:3, :3]) - 1) / 2, -1, 1)))
        assert angle < 0.2
        # the same with the passive points given as an array: the ICP (tpvp.registration.icp) is
        # deterministic, so the repeat is bit for bit
        again = pn.refine_icp(moved, passive, config)
        np.testing.assert_array_equal(again[0], transform)
        assert again[1:] == (fitness, accepted)


def test_icp_is_rejected_below_the_fitness_threshold(scene):
    config = PoseNoiseConfig(**SMALL_ICP)
    view = pn.render_views(scene["grid"], scene["positions"][:1], scene["rotations"][:1])[0]
    transform, fitness, accepted = pn.refine_icp(view + [0.0, 0.0, 3.0], scene["passive"], config)
    assert not accepted and fitness == 0.0
    np.testing.assert_array_equal(transform, np.eye(4))
    half_away = np.concatenate([view, view + [0.0, 0.0, 3.0]])  # half the view has no counterpart
    strict = PoseNoiseConfig(**SMALL_ICP, icp_min_fitness=0.6)
    transform, fitness, accepted = pn.refine_icp(half_away, scene["passive"], strict)
    assert 0.3 < fitness < 0.6 and not accepted
    np.testing.assert_array_equal(transform, np.eye(4))
    assert pn.refine_icp(half_away, scene["passive"], PoseNoiseConfig(**SMALL_ICP))[2]  # 0.3 default


# ----------------------------------------------------------------------------------- metrics
def test_metrics_match_brute_force():
    rng = np.random.default_rng(11)
    truth = rng.random((300, 3)) * 0.1
    points = np.concatenate([truth[:150] + rng.normal(0, 0.004, (150, 3)), rng.random((40, 3)) * 0.1])
    d = np.linalg.norm(points[:, None] - truth[None], axis=2)
    to_truth, to_points = d.min(axis=1), d.min(axis=0)
    got = pn.geometry_metrics(points, truth, taus=(0.005, 0.01))
    assert got["chamfer_mm"] == pytest.approx(1000 * 0.5 * (to_truth.mean() + to_points.mean()), rel=1e-12)
    for tau, label in ((0.005, "5mm"), (0.01, "10mm")):
        p, r = (to_truth <= tau).mean(), (to_points <= tau).mean()
        assert got[f"precision_{label}"] == pytest.approx(p, abs=1e-15)
        assert got[f"recall_{label}"] == pytest.approx(r, abs=1e-15)
        assert got[f"f1_{label}"] == pytest.approx(2 * p * r / (p + r), rel=1e-12)
    from tpvp.metrics import chamfer_distance, f_score

    assert got["chamfer_mm"] == pytest.approx(1000 * chamfer_distance(points, truth), rel=1e-12)
    assert got["f1_10mm"] == pytest.approx(f_score(points, truth, 0.01).f1, rel=1e-12)


# ------------------------------------------------------------------------------------- study
@pytest.fixture(scope="module")
def study(scene):
    config = PoseNoiseConfig(levels=((0.0, 0.0), (0.002, 0.5), (0.01, 2.0)), draws=2, seed=4, **SMALL_ICP)
    args = (scene["truth"], scene["grid"], scene["passive"], scene["positions"], scene["look_ats"], config)
    return config, args, pn.pose_noise_study(*args)


def test_study_rows_and_noise_free_reference(scene, study):
    config, _, df = study
    assert len(df) == 1 + 2 * 2 * 2  # noise-free once without ICP; 2 levels x 2 draws x ICP off/on
    free = df[(df.sigma_t_m == 0) & (df.sigma_r_deg == 0)]
    assert len(free) == 1 and not free.icp.iloc[0] and free.drift_mm.iloc[0] == 0
    cloud = pn.fuse(scene["grid"], scene["positions"], scene["rotations"], scene["positions"], scene["rotations"],
                    passive_points=scene["passive"], voxel=config.fusion_voxel)
    expected = pn.geometry_metrics(cloud, scene["truth"], config.taus)
    for key, value in expected.items():
        assert free[key].iloc[0] == value
    assert free.n_points.iloc[0] == len(cloud)
    assert free["precision_20mm"].iloc[0] == 1.0  # voxel centres (2 cm) lie within 1.8 cm of the truth
    worst = df[(df.sigma_t_m == 0.01)]
    off, on = worst[~worst.icp], worst[worst.icp]
    assert (off.drift_mm > 5).all() and (on.drift_mm < 0.5 * off.drift_mm.to_numpy()).all()
    assert on.chamfer_mm.mean() < off.chamfer_mm.mean()
    assert (on.icp_accepted >= 1).all() and (off.icp_accepted == 0).all()


def test_study_is_deterministic_given_the_seed(scene, study):
    config, args, df = study
    again = pn.pose_noise_study(*args)
    cols = [c for c in df.columns if c != "seconds"]
    exact = ~df.icp
    pd.testing.assert_frame_equal(df.loc[exact, cols], again.loc[exact, cols])
    pd.testing.assert_frame_equal(df.loc[~exact, cols], again.loc[~exact, cols], rtol=1e-9)
    other = pn.pose_noise_study(*args[:-1], PoseNoiseConfig(levels=((0.01, 2.0),), draws=1, seed=5, icp=(False,)))
    first = df[(df.sigma_t_m == 0.01) & (df.draw == 0) & ~df.icp]
    assert other.chamfer_mm.iloc[0] != first.chamfer_mm.iloc[0]


def test_summarise_in_table_layout(study):
    _, _, df = study
    table = pn.summarise(df)
    assert list(zip(table.sigma_t_m, table.sigma_r_deg, table.icp)) == [
        (0.0, 0.0, False), (0.002, 0.5, False), (0.01, 2.0, False), (0.002, 0.5, True), (0.01, 2.0, True)]
    assert table.n.tolist() == [1, 2, 2, 2, 2]
    sub = df[(df.sigma_t_m == 0.01) & df.icp]
    assert table.loc[4, "chamfer_mm_mean"] == pytest.approx(sub.chamfer_mm.mean())
    assert table.loc[4, "chamfer_mm_std"] == pytest.approx(sub.chamfer_mm.std())
    assert table.loc[0, "f1_20mm_std"] == 0.0
    text = pn.summarise(df, formatted=True)
    assert text["ICP"].tolist() == ["-", "OFF", "OFF", "ON", "ON"]
    assert text.columns[:4].tolist() == ["sigma_t (m)", "sigma_r (deg)", "ICP", "Chamfer (mm)"]
    p = table.loc[1, "precision_10mm_mean"] * 100
    assert text.loc[1, "precision @ 10mm"].startswith(f"{p:.1f} ± ")


def test_summary_in_the_papers_units_stands_beside_table7():
    from tpvp.experiments.rows import paper_pose_noise
    from tpvp.viz.notebook import beside_paper

    rows = pd.DataFrame({"sigma_t_m": [0.0, 0.01, 0.01, 0.01], "sigma_r_deg": [0.0, 2.0, 2.0, 2.0],
                         "icp": [False, False, True, True], "chamfer_mm": [4.0, 9.0, 4.0, 4.2],
                         "precision_1cm": [1.0, 0.4, 0.99, 0.97]})
    table = pn.in_paper_units(pn.summarise(rows))
    assert table["icp"].tolist() == ["-", "OFF", "ON"]
    assert table["precision_1cm_mean"].tolist() == pytest.approx([100.0, 40.0, 98.0])
    assert table["chamfer_mm_mean"].tolist() == pytest.approx([4.0, 9.0, 4.1])
    beside = beside_paper(table, paper_pose_noise(), on=["sigma_t_m", "sigma_r_deg", "icp"],
                          values=("chamfer_mm", "precision_1cm"))
    assert beside["paper_chamfer_mm"].tolist() == [5.44, 13.87, 6.08]
    assert beside["paper_precision_1cm"].tolist() == [100.0, 27.3, 98.7]
