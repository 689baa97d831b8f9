"""What a reference scan of a generated row would have captured.

The paper's reference rows are not complete surfaces: each session was captured by a person walking
the aisle with a LiDAR phone (Polycam on an iPhone/iPad Pro: RGB, per-frame depth, estimated poses)
and reconstructed with Nerfstudio's depth-nerfacto, so a reference model holds only the surfaces a
phone in the aisle saw. A generated row holds every surface, leaves deep in the canopy included.
Three references of a generated row (:data:`REFERENCES`, ``RowCase.reference``):

* ``complete``: every point of the generated row;
* ``candidates``: the points the room's own candidate positions see (:func:`candidate_scan`; the
  planners choose from those positions, so the oracle is close to the reference by construction);
* ``handheld``: an emulated phone capture that knows nothing of the candidates
  (:func:`handheld_scan`, :class:`HandheldCapture`): a walk along the aisle at a person's hand
  heights with a phone-LiDAR-like depth camera, kept where enough frames saw a surface.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tpvp.errors import ConfigError, checked_cloud
from tpvp.scene import voxels
from tpvp.scene.grid import build_grid
from tpvp.sensor.camera import Intrinsics
from tpvp.sensor.sensor import ROW_RANGE, SensorConfig
from tpvp.visibility import safe_visibility

REFERENCES = ("complete", "candidates", "handheld")

# ARKit's LiDAR depth map (ARDepthData.depthMap) is 256 x 192 pixels, registered to the wide camera
# of the 1920 x 1440 stream (fx ~ 1,590 px on an iPad Pro, scaled by 256 / 1920 -> 212 px: about
# 62 x 49 degrees); held upright (portrait) as a person scans a tall row: 192 wide, 256 high.
PHONE_LIDAR = Intrinsics(fx=212.0, fy=212.0, cx=96.0, cy=128.0, width=192, height=256)


@dataclass(frozen=True)
class HandheldCapture:
    """A person walking the row's aisle with a LiDAR phone, and what the reconstruction keeps.

    The walk runs along the row, ``margin`` beyond each end, at ``speed`` (m/s), the phone
    ``standoff`` metres in front of the row's aisle face (the aisle side is the room's view box, the
    accessible workspace; no candidate position or look-at enters the capture). A keyframe is taken
    ``frame_rate`` times a second. The gaze sweeps up and down the row's mid-plane between the
    ``gaze`` shares of its height, once per ``sweep_period`` seconds (a triangle wave); the hand
    follows the gaze height within a person's ``reach`` above the row's base and tilts the phone
    where it cannot. The sensor: :data:`PHONE_LIDAR` out to ``max_range`` (Apple: "up to 5 m").
    The reconstruction keeps a point when its ``resolution`` voxel (1 cm: the order of the phone
    LiDAR's depth accuracy) is seen by at least ``min_frames`` keyframes (a NeRF places a surface
    from several views, not from one)."""

    standoff: float = 0.5
    margin: float = 0.3
    speed: float = 0.2
    frame_rate: float = 5.0
    sweep_period: float = 3.0
    gaze: tuple = (0.1, 0.9)
    reach: tuple = (0.5, 1.9)
    max_range: float = 5.0
    resolution: float = 0.01
    min_frames: int = 2
    intrinsics: Intrinsics = field(default=PHONE_LIDAR)

    def __post_init__(self):
        for name in ("standoff", "speed", "frame_rate", "sweep_period", "max_range", "resolution"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"handheld capture: {name} must be > 0, got {getattr(self, name)!r}")
        if self.margin < 0 or int(self.min_frames) < 1:
            raise ConfigError(f"handheld capture: margin must be >= 0 and min_frames >= 1, "
                              f"got {self.margin!r} and {self.min_frames!r}")
        for name in ("gaze", "reach"):
            low, high = getattr(self, name)
            if not 0 <= low <= high:
                raise ConfigError(f"handheld capture: {name} must be (low, high) with 0 <= low <= high, "
                                  f"got {getattr(self, name)!r}")


def handheld_trajectory(room, capture: HandheldCapture = HandheldCapture()) -> tuple[np.ndarray, np.ndarray]:
    """The keyframes of :class:`HandheldCapture` in ``room``: positions and look-ats ``(n, 3)``."""
    box = room.plant_box
    half = box.half_extent
    aisle = np.sign(box.to_local(room.view_box.center)[1]) or 1.0
    length = 2 * (half[0] + capture.margin)
    times = np.arange(0.0, length / capture.speed + 1e-9, 1.0 / capture.frame_rate)
    along = -half[0] - capture.margin + capture.speed * times
    phase = (times / capture.sweep_period) % 1.0
    wave = 1.0 - np.abs(2.0 * phase - 1.0)  # 0 -> 1 -> 0 once per sweep
    gaze = capture.gaze[0] + (capture.gaze[1] - capture.gaze[0]) * wave  # share of the row's height
    base = -half[2]
    gaze_height = base + gaze * box.extent[2]
    hand_height = np.clip(gaze_height, base + capture.reach[0], base + capture.reach[1])
    across = aisle * (half[1] + capture.standoff)
    positions = np.column_stack([along, np.full_like(along, across), hand_height])
    look_ats = np.column_stack([along, np.zeros_like(along), gaze_height])
    return box.to_world(positions), box.to_world(look_ats)


def handheld_scan(points, room, capture: HandheldCapture = HandheldCapture()) -> np.ndarray:
    """Boolean mask of the ``points`` (a row in ``room``'s frame) that the emulated phone capture
    keeps: their ``capture.resolution`` voxel is seen by at least ``capture.min_frames`` keyframes
    of :func:`handheld_trajectory` (one ray per depth pixel)."""
    positions, look_ats = handheld_trajectory(room, capture)
    sensor = SensorConfig(model="pixel", max_range=capture.max_range, intrinsics=capture.intrinsics)
    return _seen_by(points, capture.resolution, positions, look_ats, sensor, capture.min_frames)


def _seen_by(points, resolution: float, positions, look_ats, sensor: SensorConfig, views: int) -> np.ndarray:
    """Boolean mask of the ``points`` whose ``resolution`` voxel at least ``views`` of the views
    (``positions``, ``look_ats``) observe through ``sensor``."""
    points = checked_cloud(points, "row")
    grid = build_grid(voxels.voxelise(points, resolution), resolution)
    seeing = np.asarray(safe_visibility(grid, positions, look_ats, sensor).sum(axis=0)).ravel()
    return seeing[grid.ids_of(voxels.voxel_keys(points, resolution))] >= views


SCAN_OFFSETS = ((0.0, 0.0), (1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))  # (along, up) x offset


def candidate_scan(points, room, resolution: float = 0.02, offset: float = 0.3,
                   max_range: float = ROW_RANGE) -> np.ndarray:
    """Boolean mask of the ``points`` whose ``resolution`` voxel the room's candidate positions
    observe with the rows' reference sensor: from every candidate position, looking straight across
    the row and ``offset`` metres to the left, right, up and down of that point on the row's
    mid-plane. The planners choose from the same positions (the earlier default reference)."""
    box = room.plant_box
    local = box.to_local(room.candidate_positions)
    positions, look_ats = [], []
    for along, up in SCAN_OFFSETS:
        target = local.copy()
        target[:, 1] = 0.0  # the row's mid-plane
        target[:, 0] += along * offset
        target[:, 2] += up * offset
        positions.append(room.candidate_positions)
        look_ats.append(box.to_world(target))
    return _seen_by(points, resolution, np.concatenate(positions), np.concatenate(look_ats),
                    SensorConfig(max_range=max_range), 1)


def reference_points(points, room, reference: str = "handheld") -> np.ndarray:
    """The generated row ``points`` as the named reference (:data:`REFERENCES`) holds them."""
    if reference not in REFERENCES:
        raise ConfigError(f"unknown reference {reference!r}; choose one of {', '.join(REFERENCES)}")
    if reference == "complete":
        return np.asarray(points)
    scan = candidate_scan if reference == "candidates" else handheld_scan
    return points[scan(points, room)]
