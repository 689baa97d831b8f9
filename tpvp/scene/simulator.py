"""The simulated session pair: both scans in the planning frame, the current session's ground truth
and what every candidate view observes of it (the simulator the experiments execute plans in).

``config`` is a :class:`tpvp.config.PlantConfig` (the scene, sensor and view-space sections are read).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from tpvp.errors import ConfigError, PointCloudError, checked_cloud
from tpvp.scene import voxels
from tpvp.scene.organs import reduced_organs, voxel_organs
from tpvp.scene.grid import plant_grid
from tpvp.scene.normalise import check_session_pair, normalise_plant, up_rotation
from tpvp.viewspace import get_view_space
from tpvp.visibility import oracle_voxels, visibility_matrix

NATIVE_RADIUS = 0.4  # m around the real plant when scale = native and no radius is given


@dataclass(frozen=True, eq=False)
class Scene:
    """Both sessions in the planning frame, the current ground truth and what each view sees.

    The planning frame is the normalised plant frame (docs/single_plant.md#normalisation);
    ``plant_from_scan`` (4x4, scale included) maps the scan's metric frame into it. ``view_space``
    and ``sensor`` are those of the planning frame (scaled when planning at the plant's true size).
    """

    previous: np.ndarray
    current: np.ndarray
    grid: object  # OccupancyGrid of the current ground truth (plant + table)
    view_space: object  # tpvp.viewspace.ViewSpace
    sensor: object  # SensorConfig in the planning frame
    truth_visibility: object  # csr (V, voxels): what each view observes on the ground truth
    oracle: np.ndarray
    plant_from_scan: np.ndarray
    table_points: np.ndarray
    names: tuple = ("previous-session scan", "current-session scan")
    reduction: dict | None = None  # points in and used per scan, reduction voxel
    previous_organs: np.ndarray | None = None  # organ code of each point of ``previous`` (tpvp.scene.organs)
    voxel_organs: np.ndarray | None = None  # organ code of each ground-truth voxel of ``grid``

    @property
    def views(self) -> np.ndarray:
        return self.view_space.positions

    @property
    def scan_scale(self) -> float:
        """Planning-frame metres per scan metre."""
        return float(np.cbrt(np.linalg.det(self.plant_from_scan[:3, :3])))


@dataclass(frozen=True, eq=False)
class PlanningFrame:
    """The planning frame of a session pair, fixed by one scan (``scene.frame``): that scan
    normalised (scale, rotation, centre, supporting table), the up-axis turn before it, and the
    candidate views and sensor in that frame (scaled with the plant at ``scene.scale = native``)."""

    reference: object  # tpvp.scene.normalise.PlantScene of the reference scan
    up: np.ndarray  # (3, 3) scan axes -> +Z up
    view_space: object  # tpvp.viewspace.ViewSpace in the planning frame
    sensor: object  # SensorConfig in the planning frame

    @property
    def plant_from_scan(self) -> np.ndarray:
        """4x4, scale included: ``p_planning = M[:3, :3] @ p_scan + M[:3, 3]``."""
        matrix = self.reference.matrix
        matrix[:3, :3] = matrix[:3, :3] @ self.up
        return matrix

    def to_planning(self, scan_points) -> np.ndarray:
        """Points of the scan's own frame in the planning frame."""
        points = np.asarray(scan_points, dtype=np.float64)
        return self.reference.transform(points if np.array_equal(self.up, np.eye(3)) else points @ self.up.T)


def scan_points(plant_from_scan: np.ndarray, points) -> np.ndarray:
    """Planning-frame ``points`` back in the scan's own frame (the inverse of ``plant_from_scan``)."""
    matrix = np.asarray(plant_from_scan, dtype=np.float64)
    return (np.asarray(points, dtype=np.float64) - matrix[:3, 3]) @ np.linalg.inv(matrix[:3, :3]).T


def planning_frame(reference_scan, config, name: str = "reference scan") -> PlanningFrame:
    """The planning frame that ``reference_scan`` (its own frame, metres) defines under ``config``."""
    up = up_rotation(config.scene.up_axis)
    scan = checked_cloud(reference_scan, name)
    if config.scene.up_axis != "+z":
        scan = scan @ up.T
    reference = normalise_plant(scan, config.scene.largest_side, config.scene.rotation_deg,
                                centre=config.scene.centre, table=config.uses_table, name=name,
                                table_size=config.scene.table_size, table_resolution=config.scene.table_resolution)
    space, sensor = get_view_space(config.view_space), config.sensor
    if config.scene.scale == "native":
        # The plant keeps its size: the view sphere and the sensor range are real metres, so in the
        # planning frame they scale with the plant like every resolution does.
        space = space.with_radius((config.scene.radius or NATIVE_RADIUS) * reference.scale)
        sensor = replace(sensor, max_range=sensor.max_range * reference.scale)
    elif config.scene.radius is not None:
        space = space.with_radius(config.scene.radius)
    return PlanningFrame(reference, up, space, sensor)


def build_scene(previous_points, current_points, config,
                names=("previous-session scan", "current-session scan"), organs=(None, None)) -> Scene:
    """Bring both sessions into the planning frame (defined by the current session, or by the
    previous one with ``scene.frame = previous``; the plant stays in place between sessions) and
    render the ground truth from every candidate view.

    ``names`` (e.g. the files) name the scans in errors. Scans of more than
    ``scene.reduce_above`` points are reduced to voxel centroids at ``scene.reduce_resolution``;
    the ground truth is built from every point of the current scan, so it does not change.
    ``organs``: the organ codes (:mod:`tpvp.scene.organs`) of the previous and of the current
    scan's points, or None; they label the (reduced) previous points and the ground-truth voxels."""
    up = up_rotation(config.scene.up_axis)
    current_scan, previous_scan = (checked_cloud(points, name) for points, name in
                                   ((current_points, names[1]), (previous_points, names[0])))
    if config.scene.up_axis != "+z":
        check_session_pair(previous_scan @ up.T, current_scan @ up.T, names)
    else:
        check_session_pair(previous_scan, current_scan, names)
    by_previous = config.scene.frame == "previous"
    frame = planning_frame(previous_scan if by_previous else current_scan, config, names[0 if by_previous else 1])
    space, sensor, current = frame.view_space, frame.sensor, frame.reference
    current_points = frame.to_planning(current_scan) if by_previous else current.points
    grid = plant_grid(current_points, current.table_points, config.gt_resolution)
    current_labelled = current_points
    previous = current.points if by_previous else frame.to_planning(previous_scan)
    labelled_previous = previous
    del previous_scan, current_scan
    reduction = {"resolution_m": config.scene.reduce_resolution, "previous_points": len(previous),
                 "current_points": len(current_points)}
    # Centroids lie in their points' voxels, so the reduction keeps the ground-truth voxel sets.
    previous, current_points = (voxels.voxel_centroids(p, config.scene.reduce_resolution)
                                if len(p) > config.scene.reduce_above else p
                                for p in (previous, current_points))
    reduction.update(previous_points_used=len(previous), current_points_used=len(current_points))
    previous_organs, grid_organs = _organs(organs, previous, labelled_previous, grid, current_labelled, config, names)
    for name, points, count in ((names[0], previous, None), (names[1], current_points, int(grid.countable.sum()))):
        count = len(voxels.voxelise(points, config.gt_resolution)) if count is None else count
        if count < config.scene.min_plant_voxels:
            raise PointCloudError(
                f"{name}: only {count} occupied {1e3 * config.gt_resolution:g} mm voxels once the plant is "
                f"scaled to a {config.scene.largest_side:g} m largest side ({len(points)} points); a plant scan "
                f"has at least {config.scene.min_plant_voxels} - is this the right file?")
    truth = visibility_matrix(grid, space.positions, space.look_ats, sensor)
    oracle = oracle_voxels(truth)
    if len(oracle) == 0:
        raise ConfigError(_unseen(config, space, sensor, current.scale if config.scene.scale == "native" else 1.0))
    return Scene(previous, current_points, grid, space, sensor, truth, oracle, frame.plant_from_scan,
                 current.table_points, names, reduction, previous_organs, grid_organs)


def _organs(organs, previous, labelled_previous, grid, labelled_current, config, names):
    """(organ code of each used previous point, of each ground-truth voxel), each None without its
    labels: a reduced point takes its voxel's majority, a ground-truth voxel its points'."""
    previous_codes, current_codes = organs
    for codes, points, which in ((previous_codes, labelled_previous, 0), (current_codes, labelled_current, 1)):
        if codes is not None and len(codes) != len(points):
            raise ConfigError(f"{names[which]}: {len(codes)} organ labels for its {len(points)} points")
    previous_codes = reduced_organs(previous, labelled_previous, previous_codes, config.scene.reduce_resolution)
    if current_codes is not None:
        current_codes = voxel_organs(grid.keys, config.gt_resolution, labelled_current, current_codes)
    return previous_codes, current_codes


def _unseen(config, space, sensor, per_metre: float) -> str:
    """Why no candidate view sees the plant, in the user's terms: the views' distance from the
    plant and the sensor's range, in the view space's metres (``per_metre``: planning-frame units
    per metre of the view space, the plant's scale with ``--scale native``, else 1)."""
    distance = np.linalg.norm(space.positions, axis=1) / per_metre
    if config.scene.scale == "native":
        frame = "--scale native: the plant at its true size"
        fix = ("check the scans' units (--units) and the view sphere's radius (--radius M: metres around the "
               "real plant)")
    else:
        frame = (f"--scale normalised: the plant scaled to a {config.scene.largest_side:g} m largest side "
                 f"at the origin")
        fix = ("check the view space's radius and units (positions in metres), or move the views onto a "
               "sphere around the plant with --radius (e.g. --radius 0.4)")
    near, far = distance.min(), distance.max()
    span = f"{near:.3g} m" if far - near <= 0.01 * far else f"{near:.3g}-{far:.3g} m"
    return (f"view space {config.view_space!r}: no candidate view sees the plant: its {len(space)} views are "
            f"{span} from the centre of a plant {config.scene.largest_side / per_metre:.3g} m across, the sensor "
            f"sees {sensor.max_range / per_metre:.3g} m far ({frame}); {fix}")


def observation(scene: Scene, view: int) -> np.ndarray:
    """What ``view`` observes of the current plant: the centres of the ground-truth voxels it sees."""
    return scene.grid.centres[scene.truth_visibility[view].indices]
