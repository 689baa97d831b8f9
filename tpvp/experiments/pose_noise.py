"""Pre-deployment pose-noise robustness (the paper's Table VII, "Ours at 4 cm").

The executed *active* views are perturbed with zero-mean Gaussian pose noise; every view is rendered
from its perturbed (true) pose and fused at its nominal (planned) pose, so the error shows up as
misaligned points. Optionally each active view is then refined by a light rigid ICP against the
passive map, and the fused cloud is compared with the ground-truth surface (symmetric Chamfer
distance, F-score at 1 and 2 cm).

Protocol decisions (the paper leaves them open; all are fields of :class:`tpvp.config.PoseNoiseConfig`,
the ``pose_noise`` section of the row configuration):

* **Noise model.** Per view, the position gets ``N(0, sigma_t^2)`` per axis; the orientation is
  turned about a uniformly random axis by an angle ``theta ~ N(0, sigma_r^2)`` (the paper's
  "zero-mean Gaussian, standard deviation sigma_r"; a negative angle is the opposite turn, so
  ``|theta|`` is half-normal: RMS ``sigma_r``, mean ``sigma_r * sqrt(2 / pi)`` = 0.8 sigma_r). The
  turn is applied in the camera frame, ``R_true = R_nominal @ Rot(axis, theta)``; as the axis is
  isotropic, the world-frame convention has the same distribution. A level with ``sigma = 0`` returns
  the nominal poses unchanged (bit for bit).
* **Seeds.** Draw ``d`` of every level uses ``numpy.random.default_rng([seed, d])``: the levels share
  the same standard-normal draws, scaled by their sigmas (common random numbers, so the trend
  across levels is not masked by draw-to-draw scatter). The noise-free level is evaluated once
  (it is deterministic) and reported as one row.
* **What is measured.** With the authors' voxel-driven sensor (``SensorConfig.model ==
  "reference"``, the default here with the rows' range, ``ROW_SENSOR``), a view measures the centres of the
  ground-truth voxels it observes, as the OctoMap simulator does (so the noise-free precision at
  tau = 1 cm is exactly 100 %, as in Table VII). With the ``pixel`` model it measures the back-
  projected depth image: one surface point per (strided) pixel, on the face of the voxel hit.
* **Fusion.** The reconstruction is the passive map (the 15 passive views, kept noise-free as in
  the paper's protocol: the platform's fixed sweep) plus every active view at its nominal pose,
  de-duplicated on a ``fusion_voxel`` grid (0.002 m; the first point of each voxel is kept, points
  are never averaged, so misaligned copies stay visible as ghosts - averaging would hide part of
  the error that the study measures).
* **ICP.** Point-to-plane ICP (``icp_method``; :mod:`tpvp.registration.icp`, Open3D's algorithm,
  deterministic) of each active view against the passive map,
  both downsampled at ``icp_voxel`` (0.01 m, the ground-truth voxel; voxel centroids), target
  normals from a hybrid search (radius 3 voxels, 30 neighbours). Coarse to fine, starting at the
  nominal pose: ``icp_max_iterations`` (10) iterations at each maximum correspondence distance of
  ``icp_max_correspondence`` (0.05, 0.02, 0.01 m; the first admits the 2-3 cm displacement of the
  largest level, the last stops the lattice of voxel centres from sliding). A refinement is
  accepted only when its final fitness (share of source points with a correspondence within the
  last distance) is at least ``icp_min_fitness`` (0.3); otherwise the view is fused unrefined. On
  generated room1 rows the rejected views are those that diverged (fitness <= 0.24, errors of
  6-330 mm after ICP), while the accepted ones end within 3 mm (1-1.3 mm on average); a single stage at 5 cm
  left 5-11 mm of mean drift. The target is the passive map only (not the other active views), as
  the paper motivates ICP by the passive warm-start map.
* **Metrics.** Against the ground-truth surface points: Chamfer = mean of the two directed mean
  nearest-neighbour distances (mm); precision = share of fused points within tau of the truth,
  recall = share of truth points within tau of the fusion, F1 their harmonic mean (fractions in the
  rows, percent in :func:`summarise`'s formatted table). ``drift_mm`` is a diagnostic: the mean
  distance between an active point's fused position and where it really is (0 without noise).
"""

from __future__ import annotations

import math
import time
import weakref

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from tpvp.config import PoseNoiseConfig
from tpvp.errors import ConfigError, checked_cloud
from tpvp.metrics import geometry
from tpvp.registration import icp
from tpvp.scene import voxels
from tpvp.scene.grid import OccupancyGrid
from tpvp.sensor import kernels
from tpvp.sensor.sensor import ROW_SENSOR, SensorConfig, check_camera, observe_poses, view_poses

_NORMAL_RADIUS_VOXELS = 3.0
_NORMAL_NEIGHBOURS = 30


# ============================================================================ noise
def _axis_angle_matrices(axes: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Rodrigues: ``(V, 3, 3)`` rotations by ``angles`` (rad) about unit ``axes``."""
    k = np.zeros((len(axes), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axes[:, 2], axes[:, 1], -axes[:, 0]
    k[:, 1, 0], k[:, 2, 0], k[:, 2, 1] = axes[:, 2], -axes[:, 1], axes[:, 0]
    s, c = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def perturb_poses(positions, rotations, sigma_t: float, sigma_r_deg: float, rng):
    """Noisy copies of ``(V, 3)`` camera positions and ``(V, 3, 3)`` camera-to-world rotations.

    Position + ``N(0, sigma_t^2)`` per axis; rotation turned about a uniformly random axis by
    ``N(0, sigma_r^2)`` degrees, in the camera frame. A zero sigma leaves that part unchanged (the
    arrays are copied, not recomputed), and then draws nothing from ``rng``.
    """
    positions = np.array(positions, dtype=np.float64).reshape(-1, 3)
    rotations = np.array(rotations, dtype=np.float64).reshape(-1, 3, 3)
    if len(rotations) != len(positions):
        raise ConfigError(f"{len(positions)} positions but {len(rotations)} rotations")
    sigma_t, sigma_r = float(sigma_t), float(sigma_r_deg)
    if not (math.isfinite(sigma_t) and math.isfinite(sigma_r) and sigma_t >= 0 and sigma_r >= 0):
        raise ConfigError(f"noise levels must be non-negative and finite, got sigma_t={sigma_t} m, "
                          f"sigma_r={sigma_r} deg")
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    n = len(positions)
    if sigma_t > 0:
        positions = positions + rng.normal(0.0, sigma_t, size=(n, 3))
    if sigma_r > 0:
        axes = rng.normal(size=(n, 3))
        axes /= np.linalg.norm(axes, axis=1, keepdims=True)
        angles = rng.normal(0.0, math.radians(sigma_r), size=n)
        rotations = rotations @ _axis_angle_matrices(axes, angles)
    return positions, rotations


# ============================================================================ rendering
_PIXEL_CACHE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _pixel_arrays(grid: OccupancyGrid) -> dict:
    if grid not in _PIXEL_CACHE:
        keys = np.ascontiguousarray(grid.keys)
        lo = np.ascontiguousarray(grid.origin_key)
        _PIXEL_CACHE[grid] = {"keys": keys, "centres": np.ascontiguousarray(grid.centres),
                              "exposed": kernels.exposed_faces(keys, grid.index, lo)}
    return _PIXEL_CACHE[grid]


def _pixel_world_points(grid: OccupancyGrid, position, rotation, sensor: SensorConfig) -> np.ndarray:
    """World surface points of one view's depth image (pixel model), one per pixel that hits a
    countable voxel within range (the range test of :func:`tpvp.sensor.sensor.depth_image`)."""
    arrays = _pixel_arrays(grid)
    k, stride = sensor.intrinsics, int(sensor.pixel_stride)
    r0, r1, c0, c1 = kernels.pixel_window(position, rotation, k.fx, k.fy, k.cx, k.cy, k.width, k.height,
                                          stride, arrays["centres"], grid.resolution)
    if r1 < r0 or c1 < c0:
        return np.zeros((0, 3))
    depth = np.empty((r1 - r0 + 1, c1 - c0 + 1))
    hit = np.empty(depth.shape, dtype=np.int64)
    kernels.pixel_view(position, rotation, k.fx, k.fy, k.cx, k.cy, stride, arrays["keys"], arrays["exposed"],
                       grid.resolution, r0, c0, depth, hit)
    rows, cols = np.nonzero(hit >= 0)
    ids = hit[rows, cols]
    offset = arrays["centres"][ids] - position
    keep = grid.countable[ids] & ((offset**2).sum(axis=1) <= float(sensor.max_range) ** 2)
    rows, cols, t = rows[keep], cols[keep], depth[rows[keep], cols[keep]]
    xn = ((cols + c0) * stride - k.cx) / k.fx
    yn = ((rows + r0) * stride - k.cy) / k.fy
    # the kernel's ray: position + t * rotation @ (xn, yn, 1), element-wise as there
    return np.stack([position[i] + t * (rotation[i, 0] * xn + rotation[i, 1] * yn + rotation[i, 2])
                     for i in range(3)], axis=1)


def render_views(grid: OccupancyGrid, positions, rotations, sensor: SensorConfig = ROW_SENSOR) -> list:
    """World points measured by each view given as a pose (``(V, 3)``, ``(V, 3, 3)``): observed
    voxel centres (``reference`` model, all views at once) or back-projected depth (``pixel``)."""
    positions = np.array(positions, dtype=np.float64, order="C").reshape(-1, 3)
    rotations = np.array(rotations, dtype=np.float64, order="C").reshape(-1, 3, 3)
    for p in positions:
        check_camera(grid, p)
    if sensor.model == "reference":
        seen = observe_poses(grid, positions, rotations, sensor)
        centres = grid.centres
        return [centres[np.flatnonzero(row)] for row in seen]
    return [_pixel_world_points(grid, p, r, sensor) for p, r in zip(positions, rotations)]


def render_view_points(grid: OccupancyGrid, position, rotation, sensor: SensorConfig = ROW_SENSOR) -> np.ndarray:
    """``(N, 3)`` points one view measures, in its camera frame (OpenCV: +z optical axis, +x right,
    +y down; ``rotation`` is camera-to-world, as :func:`tpvp.sensor.camera.look_at_rotation`)."""
    position = np.asarray(position, dtype=np.float64).reshape(3)
    rotation = np.asarray(rotation, dtype=np.float64).reshape(3, 3)
    world = render_views(grid, position[None], rotation[None], sensor)[0]
    return (world - position) @ rotation


def _relative_transforms(nominal_positions, nominal_rotations, true_positions, true_rotations):
    """``(R, t)`` per view mapping a true world point to where it is fused: ``R x + t`` with
    ``R = R_nom R_true^T``, ``t = p_nom - R p_true``; ``None`` where the poses are identical."""
    out = []
    for p_nom, r_nom, p_true, r_true in zip(nominal_positions, nominal_rotations, true_positions, true_rotations):
        if np.array_equal(p_nom, p_true) and np.array_equal(r_nom, r_true):
            out.append(None)
        else:
            r = r_nom @ r_true.T
            out.append((r, p_nom - r @ p_true))
    return out


def measure_views(grid: OccupancyGrid, nominal_positions, nominal_rotations, true_positions=None,
                  true_rotations=None, sensor: SensorConfig = ROW_SENSOR) -> list:
    """Per active view, its points rendered from the true pose and expressed at the nominal pose
    (world frame). Views whose true pose equals the nominal one are returned as rendered."""
    nominal_positions = np.asarray(nominal_positions, dtype=np.float64).reshape(-1, 3)
    nominal_rotations = np.asarray(nominal_rotations, dtype=np.float64).reshape(-1, 3, 3)
    true_positions = nominal_positions if true_positions is None else (
        np.asarray(true_positions, dtype=np.float64).reshape(-1, 3))
    true_rotations = nominal_rotations if true_rotations is None else (
        np.asarray(true_rotations, dtype=np.float64).reshape(-1, 3, 3))
    if not (len(nominal_positions) == len(nominal_rotations) == len(true_positions) == len(true_rotations)):
        raise ConfigError("nominal and true poses must describe the same number of views")
    return _measure(grid, nominal_positions, nominal_rotations, true_positions, true_rotations, sensor)[1]


def _measure(grid, nominal_positions, nominal_rotations, true_positions, true_rotations, sensor):
    """``(rendered, fused)`` per view: the points where they really are and where they are fused."""
    rendered = render_views(grid, true_positions, true_rotations, sensor)
    transforms = _relative_transforms(nominal_positions, nominal_rotations, true_positions, true_rotations)
    return rendered, [x if tr is None else x @ tr[0].T + tr[1] for x, tr in zip(rendered, transforms)]


def deduplicate(points, voxel: float) -> np.ndarray:
    """The first point of every ``voxel`` cell (world-aligned grid), in order of first appearance;
    points are kept as they are (never averaged)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0:
        return points.copy()
    _, first = np.unique(voxels.encode_keys(voxels.voxel_keys(points, voxel)), return_index=True)
    return points[np.sort(first)]


def fuse(grid: OccupancyGrid, nominal_positions, nominal_rotations, true_positions, true_rotations,
         sensor: SensorConfig = ROW_SENSOR, *, passive_points=None, voxel: float = 0.002) -> np.ndarray:
    """Fused cloud: ``passive_points`` (noise-free, first) plus every active view rendered from its
    true pose and fused at its nominal pose, de-duplicated on a ``voxel`` grid (:func:`deduplicate`)."""
    views = measure_views(grid, nominal_positions, nominal_rotations, true_positions, true_rotations, sensor)
    return _fuse_views(views, passive_points, voxel)


def _fuse_views(views, passive_points, voxel):
    parts = [] if passive_points is None else [np.asarray(passive_points, dtype=np.float64).reshape(-1, 3)]
    parts += list(views)
    return deduplicate(np.concatenate(parts) if parts else np.zeros((0, 3)), voxel)


def passive_map(grid: OccupancyGrid, positions, look_ats, sensor: SensorConfig = ROW_SENSOR,
                voxel: float = 0.002) -> np.ndarray:
    """Noise-free fused points of the passive views (position + look-at), the ICP target."""
    positions, rotations = view_poses(grid, positions, look_ats)
    return _fuse_views(render_views(grid, positions, rotations, sensor), None, voxel)


# ============================================================================ ICP
def prepare_icp_target(passive_points, config: PoseNoiseConfig = PoseNoiseConfig()) -> icp.Target:
    """The passive map downsampled at ``icp_voxel`` (voxel centroids), with normals for
    point-to-plane ICP and its KD-tree; pass it to :func:`refine_icp` to build it once for many views."""
    radius = _NORMAL_RADIUS_VOXELS * config.icp_voxel if config.icp_method == "point_to_plane" else None
    return icp.prepare_target(checked_cloud(passive_points, "passive map"), config.icp_voxel, radius,
                              _NORMAL_NEIGHBOURS)


def refine_icp(view_points_world, passive_points, config: PoseNoiseConfig = PoseNoiseConfig()):
    """Light rigid ICP of one view (world points at its nominal pose) against the passive map.

    ``passive_points``: an ``(N, 3)`` array or the target of :func:`prepare_icp_target`. Returns
    ``(transform, fitness, accepted)``: the 4x4 correction to apply to the view's points (identity
    unless accepted), the final fitness, and whether it reached ``icp_min_fitness``. The ICP is
    :func:`tpvp.registration.icp.icp` (deterministic: the same input gives the same bits).
    """
    target = passive_points if isinstance(passive_points, icp.Target) else prepare_icp_target(passive_points, config)
    view = np.asarray(view_points_world, dtype=np.float64).reshape(-1, 3)
    source = icp.voxel_downsample(view, config.icp_voxel)
    if len(source) < 3 or len(target.points) < 3:
        return np.eye(4), 0.0, False
    result = icp.icp(source, target, config.icp_max_correspondence, method=config.icp_method,
                     max_iteration=int(config.icp_max_iterations))
    fitness = result.fitness
    accepted = fitness >= config.icp_min_fitness and fitness > 0
    return (result.transformation if accepted else np.eye(4)), fitness, bool(accepted)


def _apply(transform, points):
    return points @ transform[:3, :3].T + transform[:3, 3]


# ============================================================================ metrics
def _tau_label(tau: float) -> str:
    return f"{tau * 1000:g}mm"


def geometry_metrics(points, truth, taus=(0.01, 0.02)) -> dict:
    """Chamfer (mm) and precision / recall / F1 (fractions) per tau of ``points`` against ``truth``
    (an ``(M, 3)`` array or a prebuilt ``scipy.spatial.cKDTree`` of it), by
    :mod:`tpvp.metrics.geometry` with one nearest-neighbour search each way."""
    truth_tree = truth if isinstance(truth, cKDTree) else cKDTree(checked_cloud(truth, "ground truth"))
    points = checked_cloud(points, "fused cloud")
    to_truth = geometry.nearest_distances(points, truth_tree)
    to_points = geometry.nearest_distances(truth_tree.data, points)
    out = {"chamfer_mm": 1000.0 * geometry.chamfer_from_distances(to_truth, to_points)}
    for tau in taus:
        score = geometry.f_score_from_distances(to_truth, to_points, tau)
        label = _tau_label(tau)
        out[f"precision_{label}"], out[f"recall_{label}"] = score.precision, score.recall
        out[f"f1_{label}"] = score.f1
    return out


# ============================================================================ study
def _drift_mm(views_fused, views_true) -> float:
    n = sum(len(v) for v in views_true)
    if n == 0:
        return 0.0
    return 1000.0 * sum(float(np.linalg.norm(f - t, axis=1).sum()) for f, t in zip(views_fused, views_true)) / n


def pose_noise_study(truth_points, grid: OccupancyGrid, passive_points, active_positions, active_look_ats,
                     config: PoseNoiseConfig = PoseNoiseConfig(), sensor: SensorConfig = ROW_SENSOR,
                     *, progress: bool = False) -> pd.DataFrame:
    """One row per (level, draw, ICP off/on): ``sigma_t_m, sigma_r_deg, draw, icp, n_points,
    chamfer_mm, precision_/recall_/f1_<tau>mm, icp_accepted, icp_fitness, drift_mm, seconds``.

    ``truth_points``: ground-truth surface cloud; ``grid``: the ground-truth occupancy grid the views
    are rendered from; ``passive_points``: the noise-free passive map (:func:`passive_map`), fused
    into every reconstruction and the ICP target; active views as positions + look-at targets.
    The noise-free level is evaluated once, without ICP (Table VII's "-").
    """
    from tqdm.auto import tqdm

    truth_tree = cKDTree(checked_cloud(truth_points, "ground truth"))
    passive_points = checked_cloud(passive_points, "passive map")
    positions, rotations = view_poses(grid, active_positions, active_look_ats)
    target = prepare_icp_target(passive_points, config) if True in config.icp else None

    tasks = [(t, r, d) for t, r in config.levels for d in range(1 if t == 0 and r == 0 else config.draws)]
    rows = []
    for sigma_t, sigma_r, draw in tqdm(tasks, desc="pose noise", unit="draw", disable=not progress):
        for with_icp, fused in noisy_reconstructions(grid, positions, rotations, passive_points, sigma_t, sigma_r, draw,
                                                config, sensor, target).items():
            row = {"sigma_t_m": sigma_t, "sigma_r_deg": sigma_r, "draw": draw, "icp": with_icp,
                   "n_points": len(fused["cloud"])}
            row.update(geometry_metrics(fused["cloud"], truth_tree, config.taus))
            row.update({k: fused[k] for k in ("icp_accepted", "icp_fitness", "drift_mm", "seconds")})
            rows.append(row)
    return pd.DataFrame(rows)


def noisy_reconstructions(grid: OccupancyGrid, positions, rotations, passive_points, sigma_t: float,
                          sigma_r_deg: float, draw: int, config: PoseNoiseConfig = PoseNoiseConfig(),
                          sensor: SensorConfig = ROW_SENSOR, icp_target=None) -> dict:
    """One draw of one noise level: ``{icp (False/True): {"cloud", "icp_accepted", "icp_fitness",
    "drift_mm", "seconds"}}`` for each ICP setting of ``config.icp`` (noise-free: ICP off only).
    ``icp_target``: :func:`prepare_icp_target` of the passive map (built here when needed)."""
    start = time.perf_counter()
    true_positions, true_rotations = perturb_poses(positions, rotations, sigma_t, sigma_r_deg,
                                                   np.random.default_rng([int(config.seed), int(draw)]))
    rendered, fused = _measure(grid, positions, rotations, true_positions, true_rotations, sensor)
    noisy = sigma_t > 0 or sigma_r_deg > 0
    base = time.perf_counter() - start
    out = {}
    for with_icp in (config.icp if noisy else (False,)):
        t0 = time.perf_counter()
        views, accepted, fitness = fused, 0, float("nan")
        if with_icp:
            icp_target = icp_target if icp_target is not None else prepare_icp_target(passive_points, config)
            results = [refine_icp(v, icp_target, config) for v in fused]
            views = [_apply(T, v) if ok else v for v, (T, _, ok) in zip(fused, results)]
            accepted = sum(ok for _, _, ok in results)
            fitness = float(np.mean([f for _, f, _ in results])) if results else float("nan")
        out[with_icp] = {"cloud": _fuse_views(views, passive_points, config.fusion_voxel), "icp_accepted": accepted,
                    "icp_fitness": fitness, "drift_mm": _drift_mm(views, rendered),
                    "seconds": base + time.perf_counter() - t0}
    return out


def summarise(df: pd.DataFrame, formatted: bool = False) -> pd.DataFrame:
    """Mean and standard deviation per (level, ICP) in Table VII's order: noise-free first, then the
    noisy levels without ICP, then with ICP. Numeric columns ``<metric>_mean`` / ``<metric>_std``
    (sample std; 0 for a single row); ``formatted=True`` gives the paper's table as strings
    ("5.44 ± 0.13", precision/recall/F1 in percent, ICP "-" / "OFF" / "ON")."""
    metrics = [c for c in df.columns if c == "chamfer_mm" or c.split("_")[0] in ("precision", "recall", "f1")]
    keys = ["sigma_t_m", "sigma_r_deg", "icp"]
    grouped = df.groupby(keys, sort=False)[metrics]
    mean, std = grouped.mean(), grouped.std().fillna(0.0)
    out = mean.add_suffix("_mean").join(std.add_suffix("_std")).reset_index()
    out["n"] = grouped.size().to_numpy()
    free = (out["sigma_t_m"] == 0) & (out["sigma_r_deg"] == 0)
    out["_block"] = np.where(free, 0, np.where(out["icp"], 2, 1))
    out = out.sort_values(["_block", "sigma_t_m", "sigma_r_deg"], kind="stable").drop(columns="_block")
    out = out.reset_index(drop=True)
    if not formatted:
        return out
    table = pd.DataFrame({"sigma_t (m)": out["sigma_t_m"].map(lambda v: f"{v:g}"),
                          "sigma_r (deg)": out["sigma_r_deg"].map(lambda v: f"{v:g}"),
                          "ICP": np.where((out["sigma_t_m"] == 0) & (out["sigma_r_deg"] == 0), "-",
                                          np.where(out["icp"], "ON", "OFF"))})
    for m in metrics:
        scale, digits = (1.0, 2) if m == "chamfer_mm" else (100.0, 1)
        name = "Chamfer (mm)" if m == "chamfer_mm" else m.replace("_", " @ ")
        table[name] = [f"{a * scale:.{digits}f} ± {b * scale:.{digits}f}"
                       for a, b in zip(out[f"{m}_mean"], out[f"{m}_std"])]
    return table


def in_paper_units(summary: pd.DataFrame) -> pd.DataFrame:
    """A :func:`summarise` table in the paper's units and labels, ready to stand beside
    :func:`tpvp.experiments.rows.paper_pose_noise`: precision, recall and F-score in percent, ICP
    as "-" (noise-free), "OFF" or "ON"."""
    out = summary.copy()
    free = (out["sigma_t_m"] == 0) & (out["sigma_r_deg"] == 0)
    out["icp"] = np.where(free, "-", np.where(out["icp"].astype(bool), "ON", "OFF"))
    for column in [c for c in out.columns if c.split("_")[0] in ("precision", "recall", "f1") and c != "n"]:
        out[column] = 100.0 * out[column]
    return out
