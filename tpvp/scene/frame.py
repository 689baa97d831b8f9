"""The planning frame of a session pair, and what the robot knows of the previous session in it
(a row's frame is its room's: :func:`check_row` refuses a row that is not where its room expects it).

Shared by the simulator (:mod:`tpvp.simulate.world`) and a real session (:mod:`tpvp.session.plant`):
both fix the frame with :func:`planning_frame` and reduce the previous scan with
:func:`known_from_previous`, so a session plans on the very points the simulator's plan uses.

``config`` is a :class:`tpvp.config.PlantConfig` (the scene, sensor and view-space sections are read).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from tpvp.errors import ConfigError, PointCloudError, checked_cloud
from tpvp.scene import voxels
from tpvp.scene.normalise import normalise_plant, up_rotation
from tpvp.scene.organs import reduced_organs

NATIVE_RADIUS = 0.4  # m around the real plant when scale = native and no radius is given
MIN_INSIDE_PLANT_BOX = 0.5  # a row whose points lie mostly outside its room's plant box is in another frame
BOX_TOLERANCE = 0.10  # m: leaves may overhang the plant box a little


@dataclass(frozen=True, eq=False)
class PlanningFrame:
    """The planning frame of a session pair, fixed by one scan (``scene.frame``): that scan
    normalised (scale, rotation, centre, supporting table), the up-axis turn before it, and the
    candidate views and sensor in that frame (scaled with the plant at ``scene.scale = native``)."""

    reference: object  # tpvp.scene.normalise.PlantScene of the reference scan
    up: np.ndarray  # (3, 3) scan axes -> +Z up
    view_space: object  # tpvp.viewspace.space.ViewSpace in the planning frame
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
    space, sensor = config.space, config.sensor
    if config.scene.scale == "native":
        # The plant keeps its size: the view sphere and the sensor range are real metres, so in the
        # planning frame they scale with the plant like every resolution does.
        space = space.with_radius((config.scene.radius or NATIVE_RADIUS) * reference.scale)
        sensor = replace(sensor, max_range=sensor.max_range * reference.scale)
    elif config.scene.radius is not None:
        space = space.with_radius(config.scene.radius)
    return PlanningFrame(reference, up, space, sensor)


def known_from_previous(previous, config, name: str, organs=None) -> tuple[np.ndarray, np.ndarray | None, dict]:
    """What the planner knows of the previous session: ``previous`` (its scan in the planning
    frame, every point) reduced to voxel centroids at ``scene.reduce_resolution`` when it has more
    than ``scene.reduce_above`` points. Returns (the points used, their organ codes: a centroid takes
    its voxel's majority, None without ``organs``, the code of each scan point, :mod:`tpvp.scene.organs`;
    ``{"previous_points", "previous_points_used"}``). ``name`` (e.g. the file) names the scan in errors:
    labels that do not match its points, or a scan of fewer than ``scene.min_plant_voxels`` occupied
    ground-truth voxels."""
    if organs is not None and len(organs) != len(previous):
        raise ConfigError(f"{name}: {len(organs)} organ labels for its {len(previous)} points")
    resolution = config.scene.reduce_resolution
    # Centroids lie in their points' voxels, so the reduction keeps the ground-truth voxel sets.
    used = voxels.voxel_centroids(previous, resolution) if len(previous) > config.scene.reduce_above else previous
    check_plant_voxels(name, used, len(voxels.voxelise(used, config.gt_resolution)), config)
    return used, reduced_organs(used, previous, organs, resolution), {"previous_points": len(previous),
                                                                       "previous_points_used": len(used)}


def check_plant_voxels(name: str, points, count: int, config) -> None:
    """Refuse a scan (``points`` in the planning frame) with fewer than ``scene.min_plant_voxels``
    occupied ground-truth voxels (``count``): the wrong file, or the wrong units."""
    if count < config.scene.min_plant_voxels:
        raise PointCloudError(
            f"{name}: only {count} occupied {1e3 * config.gt_resolution:g} mm voxels once the plant is "
            f"scaled to a {config.scene.largest_side:g} m largest side ({len(points)} points); a plant scan "
            f"has at least {config.scene.min_plant_voxels} - is this the right file?")


def check_row(points, name: str, room) -> None:
    """Refuse a row that is not where its room expects it (outside the plant box, or in the view box)."""
    inside = room.plant_box.contains(points, tol=BOX_TOLERANCE)
    if inside.mean() < MIN_INSIDE_PLANT_BOX:
        raise PointCloudError(
            f"{name}: only {100 * inside.mean():.1f} % of its points lie in {room.room}'s plant box "
            f"(centre {np.round(room.plant_box.center, 3).tolist()} m): the row is outside its room's boxes "
            f"- is it in the room's frame (metres, aligned to the first capture day)?")
    in_view_box = room.view_box.contains(points).mean()
    if in_view_box > 0.05:
        raise PointCloudError(f"{name}: {100 * in_view_box:.1f} % of its points lie in {room.room}'s view box, "
                              f"where the camera moves: the row is not where its room expects it")
