"""One greenhouse-row case of the paper, end to end in the simulator (docs/greenhouse.md).

The passive sweep (15 fixed views) is captured on the current session's ground truth through the
sensor (``sensor.noise``; Q is fused from the captures as a row session fuses them,
docs/sensor.md#sensor-noise); the planner (:mod:`tpvp.pipeline.plan`) plans from what the robot
knows (``scene.known``: the coarse reconstruction Q and the previous session, never the ground
truth); the plan is executed on the
ground truth, its coverage normalised by the FOV-free oracle (cached on disk). The baselines
of Tables V-VI (the prior ladder with random selection, each prior's upper limit) reuse the same
scene and candidates. The stages live in their packages (the oracle and its cache in
:mod:`tpvp.visibility`, the look-at priors in :mod:`tpvp.viewspace.priors`); this module calls them
in order, with the room and every setting taken from the one :class:`tpvp.config.RowConfig`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from tpvp.config import RowConfig
from tpvp.errors import PointCloudError, checked_cloud
from tpvp.path.route import row_path
from tpvp.pipeline.plan import Known, PlanResult, Transfer, inflated, plan, transfer
from tpvp.pipeline.timing import timed
from tpvp.scene import voxels
from tpvp.scene.boxes import room_config
from tpvp.scene.frame import check_row
from tpvp.scene.grid import build_grid
from tpvp.sensor.noise import apply_noise, noise_profile
from tpvp.viewspace.lookat import CandidateViews
from tpvp.viewspace.priors import candidate_views
from tpvp.visibility import coverage_ratio, covered_voxels, safe_visibility
from tpvp.visibility.oracle_cache import cached_oracle


@dataclass(frozen=True, eq=False)
class RowScene:
    """A simulated pair of sessions of one row in the room's (world) frame: what the robot knows
    (``known``: the room, the previous session, the coarse reconstruction Q of the passive sweep and
    its cameras, the sensor) and the current session's ground truth, its oracle and the voxel ids
    the passive sweep saw (``passive_seen``)."""

    known: Known
    current: np.ndarray
    grid: object  # OccupancyGrid of the current ground truth
    oracle: np.ndarray
    passive_visibility: object  # csr (15, voxels)
    passive_seen: np.ndarray
    oracle_cached: bool = False

    # What the simulation reads of what the robot knows (the room's boxes and sweep, the sensor).
    room = property(lambda self: self.known.room)
    sensor = property(lambda self: self.known.sensor)
    previous = property(lambda self: self.known.previous)
    coarse = property(lambda self: self.known.coarse)
    names = property(lambda self: self.known.names)
    timings = property(lambda self: self.known.timings)


def build_row_scene(previous_points, current_points, config: RowConfig = RowConfig(),
                    names=("previous session", "current session"), cache_dir=None, progress=None,
                    date: str | None = None) -> RowScene:
    """Both sessions in the room ``config.view_space``, the current ground truth at
    ``config.gt_resolution``, its oracle (cached on disk, see
    :func:`tpvp.visibility.oracle_cache.cached_oracle`) and the passive sweep's observation.
    ``date`` (YYYYMMDD of the current session) lets the authors' look-at files of that day be used
    as candidates."""
    room_cfg = room_config(config.view_space)
    timings = {}
    t = time.perf_counter()
    previous = checked_cloud(previous_points, names[0])
    current = checked_cloud(current_points, names[1])
    for points, name in ((previous, names[0]), (current, names[1])):
        check_row(points, name, room_cfg)
    resolution = config.gt_resolution
    grid = build_grid(voxels.voxelise(current, resolution), resolution)
    # The previous session feeds registration only: its voxel centroids keep its voxel set.
    previous = voxels.voxel_centroids(previous, resolution)
    timings["scene"] = time.perf_counter() - t

    t = time.perf_counter()
    oracle, from_cache = cached_oracle(grid, room_cfg.view_box.grid(config.oracle_grid), config.sensor.max_range,
                                       cache_dir, progress)
    timings["oracle"] = time.perf_counter() - t
    t = time.perf_counter()
    passive = safe_visibility(grid, room_cfg.initial_positions, room_cfg.initial_look_ats, config.sensor)
    seen = covered_voxels(passive, np.arange(passive.shape[0]))
    first_view = np.asarray(passive.tocsc().argmax(axis=0)).ravel()
    timings["passive"] = time.perf_counter() - t
    if passive.nnz == 0:
        raise PointCloudError(f"{names[1]}: the 15 passive views of {room_cfg.room} observe nothing of it "
                              f"(empty passive scan): is the row in {room_cfg.room}'s frame?")
    if len(oracle) == 0:
        raise PointCloudError(f"{names[1]}: no voxel of the row is visible from {room_cfg.room}'s view box")
    current = voxels.voxel_centroids(current, resolution)
    observed = observed_points(grid, current) if config.coarse == "centroids" else grid.centres
    profile = noise_profile(config.sensor.noise)
    if profile.ideal:
        coarse, cameras = observed[seen], room_cfg.initial_positions[first_view[seen]]
    else:  # each view's capture through the sensor, then the reduction a row session makes of its captures
        t = time.perf_counter()
        sweep = len(room_cfg.initial_positions)
        captures = [(view, noisy_capture(profile, observed[np.sort(passive[view].indices)],
                                         room_cfg.initial_positions[view], view, view, sweep, config.seed))
                    for view in range(passive.shape[0])]
        coarse, first = passive_reconstruction(captures, resolution, config.coarse)
        cameras = room_cfg.initial_positions[first]
        timings["passive"] += time.perf_counter() - t
    known = Known(previous, config.sensor, tuple(names), room=room_cfg, coarse=coarse,
                  passive_cameras=cameras, timings=timings, date=date)
    return RowScene(known, current, grid, oracle, passive, seen, from_cache)


def noisy_capture(profile, points, position, view: int, capture: int, captures: int, seed: int) -> np.ndarray:
    """``points`` (room frame, metres) seen from ``position`` as ``profile``'s sensor reports them:
    capture ``capture`` of a sequence of ``captures``, drawn from ``default_rng([seed, view,
    capture])``, the drift's direction from ``seed`` (as :meth:`tpvp.simulate.world.Scene.observe`)."""
    rng = np.random.default_rng([int(seed), int(view), int(capture)])
    return apply_noise(profile, points, position, int(capture), int(captures), rng, 1.0, drift_seed=int(seed))


def passive_reconstruction(captures, resolution: float, coarse: str = "centroids") -> tuple[np.ndarray, np.ndarray]:
    """Q and the view that gave each point, from the passive captures ``[(view, points), ...]`` as a
    row session fuses them (:meth:`tpvp.session.row.RowSession.known`, :func:`tpvp.scene.voxels.first_seen`):
    per voxel the centroid of the points the first view that saw it captured there (``coarse =
    centroids``) or the voxel centre (``centres``)."""
    reduced = [(view, *voxels.code_centroids(voxels.voxel_keys(points, resolution), points))
               for view, points in captures]
    return voxels.first_seen([(view, codes, centroids if coarse == "centroids" else None)
                              for view, codes, centroids in reduced], resolution)


def observed_points(grid, centroids) -> np.ndarray:
    """Per voxel of ``grid`` the centroid of the ground-truth points in it (``centroids``: the
    ground truth's :func:`tpvp.scene.voxels.voxel_centroids` at the grid's resolution, the grid's
    key order), the voxel centre where rounding puts a centroid in another voxel. What a view sees
    of a voxel is its points: the reference's coarse cloud is the observed points reduced to 1 cm
    voxel centroids, as the previous session is, so an unchanged row gives Q inside P
    (docs/greenhouse.md#registration); voxel centres would sit up to half a voxel diagonal off P."""
    centres = grid.centres
    if len(centroids) != len(centres):
        return centres
    same = np.all(voxels.voxel_keys(centroids, grid.resolution) == grid.keys, axis=1)
    return np.where(same[:, None], centroids, centres)


def row_transfer(scene: RowScene, config: RowConfig = RowConfig(), progress=None) -> Transfer:
    """The planner's registration (:func:`tpvp.pipeline.plan.transfer`) on what the simulated
    passive sweep saw."""
    return transfer(scene.known, config, progress)


def row_candidates(scene: RowScene, prior: str, config: RowConfig = RowConfig(),
                   transferred: Transfer | None = None) -> CandidateViews:
    """The candidate views of the look-at prior ``prior`` (a name of
    :data:`tpvp.viewspace.priors.LOOK_AT_PRIORS`: ``obb``, ``passive``, ``transfer``, which needs
    ``transferred``, or ``authors-<prior>``, which needs the scene's date), ``config.targets`` of
    them, surface voxel ``config.inflation.step`` (docs/greenhouse.md#look-at-candidates)."""
    known = scene.known
    context = (known.prior_context(config.inflation.step) if transferred is None else
               known.prior_context(config.inflation.step, transferred.alignment.warped,
                                   inflated(known, config, transferred).inflation))
    return candidate_views(prior, context, config.targets, config.seed)


def execute(scene: RowScene, positions, look_ats) -> np.ndarray:
    """Ground-truth voxel ids the views observe (the simulator's execution)."""
    return covered_voxels(safe_visibility(scene.grid, positions, look_ats, scene.sensor), np.arange(len(positions)))


def row_coverage(scene: RowScene, seen_ids, with_passive: bool = True) -> float:
    """Oracle-normalised coverage of what the views saw, the passive sweep's voxels added."""
    seen = np.union1d(seen_ids, scene.passive_seen) if with_passive else np.asarray(seen_ids)
    return coverage_ratio(seen, scene.oracle)


def run_row_case(scene: RowScene, config: RowConfig = RowConfig(), progress=None,
                 transferred: Transfer | None = None) -> PlanResult:
    """Ours on one row pair, one block per stage: transfer, the transfer prior's candidates, their
    visibility on the planning surface, set cover with the passive views as executed, band path from
    the end of the passive sweep, execution. ``transferred``: :func:`row_transfer` of this scene."""
    result = plan(scene.known, config, transferred, progress)
    timings = dict(result.timings)
    with timed(timings, "execution", progress or (lambda stage: None), "execution"):
        coverage = row_coverage(scene, execute(scene, result.positions, result.look_ats))
    return replace(result, coverage=coverage, coverage_captured=row_coverage(scene, []), timings=timings)


def candidate_truth(scene: RowScene, candidates: CandidateViews):
    """What each candidate view observes of the ground truth (csr, candidates x voxels)."""
    return safe_visibility(scene.grid, candidates.positions, candidates.look_ats, scene.sensor)


def upper_limit(scene: RowScene, truth) -> float:
    """Table V: the largest fraction of the oracle any subset of the candidates reaches (all of
    them together; the passive views not added)."""
    return row_coverage(scene, covered_voxels(truth, np.arange(truth.shape[0])), with_passive=False)


def random_selection(scene: RowScene, candidates: CandidateViews, truth, budget: int, repetition: int,
                     config: RowConfig = RowConfig(), with_passive: bool = True) -> dict:
    """A random one-shot baseline: ``budget`` of the candidates drawn uniformly (seeded by the
    configuration's seed and ``repetition``), the same route as Ours, executed. Views and path include
    the passive sweep when ``with_passive`` (PriorPassive/PriorTransfer use it; PriorOBB does not)."""
    rng = np.random.default_rng([config.seed, int(repetition), int(budget)])
    chosen = rng.choice(len(candidates), size=min(int(budget), len(candidates)), replace=False)
    t = time.perf_counter()
    path, length = row_path(scene.room, candidates.positions[chosen], config.path, with_passive, config.route)
    seconds = time.perf_counter() - t
    coverage = row_coverage(scene, covered_voxels(truth, chosen), with_passive)
    n_passive = len(scene.room.initial_positions) if with_passive else 0
    return {"budget": int(budget), "repetition": int(repetition), "views": n_passive + len(chosen),
            "coverage": coverage, "path_length_m": length, "path_gap": path.gap, "seconds_path": seconds}
