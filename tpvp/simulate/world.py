"""The simulated world of a session pair: both scans in the planning frame, the current session's
ground truth and what every candidate view observes of it (the simulator ``tpvp plan``, ``demo`` and
the experiments execute plans in). The planning frame and what the robot knows of the previous
scan are shared with a real session (:mod:`tpvp.scene.frame`).

``config`` is a :class:`tpvp.config.PlantConfig` (the scene, sensor and view-space sections are read).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tpvp.errors import ConfigError, checked_cloud
from tpvp.scene import voxels
from tpvp.scene.frame import check_plant_voxels, known_from_previous, planning_frame
from tpvp.scene.grid import plant_grid
from tpvp.scene.normalise import check_session_pair, up_rotation
from tpvp.scene.organs import voxel_organs
from tpvp.sensor.noise import apply_noise, noise_profile
from tpvp.visibility import oracle_voxels, visibility_matrix


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
    view_space: object  # tpvp.viewspace.space.ViewSpace
    sensor: object  # SensorConfig in the planning frame
    truth_visibility: object  # csr (V, voxels): what each view observes on the ground truth
    oracle: np.ndarray
    plant_from_scan: np.ndarray
    table_points: np.ndarray
    names: tuple = ("previous-session scan", "current-session scan")
    reduction: dict | None = None  # points in and used per scan, reduction voxel
    previous_organs: np.ndarray | None = None  # organ code of each point of ``previous`` (tpvp.scene.organs)
    voxel_organs: np.ndarray | None = None  # organ code of each ground-truth voxel of ``grid``
    seed: int = 0  # the configuration's seed: the captures' noise (``sensor.noise``) is drawn from it
    per_metre: float = 1.0  # planning-frame units per metre of the sensor's world (the noise's figures)

    @property
    def views(self) -> np.ndarray:
        return self.view_space.positions

    @property
    def scan_scale(self) -> float:
        """Planning-frame metres per scan metre."""
        return float(np.cbrt(np.linalg.det(self.plant_from_scan[:3, :3])))

    def observe(self, view: int, capture: int = 0) -> np.ndarray:
        """What ``view`` observes of the current plant: the centres of the ground-truth voxels it
        sees, as the configured sensor (``sensor.noise``, :mod:`tpvp.sensor.noise`) reports them.
        ``capture``: the view's place in the session's order of captures (0 first); the pose drift
        grows with it over a sequence as long as the view space. The noise is drawn from
        ``default_rng([seed, view, capture])``; the ``ideal`` sensor returns the exact centres.
        Only the observation is noisy: ``truth_visibility`` and the coverage stay exact."""
        exact = self.grid.centres[self.truth_visibility[view].indices]
        profile = noise_profile(getattr(self.sensor, "noise", "ideal"))
        if profile.ideal:
            return exact
        rng = np.random.default_rng([int(self.seed), int(view), int(capture)])
        return apply_noise(profile, exact, self.view_space.positions[view], int(capture), len(self.view_space), rng,
                           self.per_metre, drift_seed=int(self.seed))


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
    current_codes = organs[1]
    if current_codes is not None and len(current_codes) != len(current_points):
        raise ConfigError(f"{names[1]}: {len(current_codes)} organ labels for its {len(current_points)} points")
    previous = current.points if by_previous else frame.to_planning(previous_scan)
    del previous_scan, current_scan
    previous, previous_organs, known = known_from_previous(previous, config, names[0], organs[0])
    grid_organs = None if current_codes is None else voxel_organs(grid.keys, config.gt_resolution, current_points,
                                                                   current_codes)
    reduction = {"resolution_m": config.scene.reduce_resolution, "previous_points": known["previous_points"],
                 "current_points": len(current_points)}
    if len(current_points) > config.scene.reduce_above:  # as known_from_previous reduces the previous scan
        current_points = voxels.voxel_centroids(current_points, config.scene.reduce_resolution)
    reduction.update(previous_points_used=known["previous_points_used"], current_points_used=len(current_points))
    check_plant_voxels(names[1], current_points, int(grid.countable.sum()), config)
    truth = visibility_matrix(grid, space.positions, space.look_ats, sensor)
    oracle = oracle_voxels(truth)
    if len(oracle) == 0:
        raise ConfigError(_unseen(config, space, sensor, current.scale if config.scene.scale == "native" else 1.0))
    return Scene(previous, current_points, grid, space, sensor, truth, oracle, frame.plant_from_scan,
                 current.table_points, names, reduction, previous_organs, grid_organs, config.seed,
                 current.scale if config.scene.scale == "native" else 1.0)


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

