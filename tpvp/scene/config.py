"""The scene's configuration (``scene``), light: no stage code is imported with it."""

from __future__ import annotations

from dataclasses import dataclass

from tpvp.configuration_checks import check_integer, check_positive
from tpvp.errors import ConfigError

SCALES = ("normalised", "native")
UP_AXES = ("+z", "-z", "+y", "-y", "+x", "-x")
FRAMES = ("current", "previous")  # the scan that defines the planning frame
#: The organ classes, their codes being their positions (:data:`tpvp.scene.organs.CODE`).
ORGANS = ("unknown", "stem", "leaf", "petiole", "peduncle", "flower", "fruit")


@dataclass(frozen=True)
class SceneConfig:
    """How a scan becomes the simulator's scene (docs/single_plant.md#normalisation).

    scale: ``normalised`` (the paper's protocol: the plant scaled to ``largest_side``) or
    ``native`` (the plant keeps its size; ``radius`` is the view-sphere radius in the scan's metres
    and every resolution scales with the plant, see docs/configuration.md#native-scale).
    radius: view-sphere radius; None keeps the view space's own (0.4 m) in normalised mode and means
    0.4 m around the real plant in native mode. table: None = the view space's choice.
    up_axis: the scan axis that points up; the plant is turned so that it becomes +Z.
    frame: the scan that defines the planning frame (scale, centre, table): ``current`` (the
    paper's protocol: today's full scan) or ``previous`` (the previous session's model: all a real
    session has before planning, see ``tpvp session``).
    reduce_above / reduce_resolution: scans with more points are reduced to voxel centroids at
    ``reduce_resolution`` (planning frame; half the ground-truth voxel, so the ground truth
    is unchanged) before anything else. min_plant_voxels: fewer occupied ground-truth voxels than
    this is not a plant scan (the bundled tomato has 3,890).
    """

    largest_side: float = 0.24
    rotation_deg: float = 0.0
    centre: str = "bbox"
    table: bool | None = None
    table_size: float = 0.4
    table_resolution: float = 0.002
    scale: str = "normalised"
    radius: float | None = None
    up_axis: str = "+z"
    frame: str = "current"
    reduce_above: int = 1_000_000
    reduce_resolution: float = 0.001
    min_plant_voxels: int = 100

    def __post_init__(self):
        check_positive(self, "largest_side", "table_size", "table_resolution", "reduce_resolution")
        check_integer(self, "reduce_above", minimum=1)
        check_integer(self, "min_plant_voxels", minimum=1)
        if self.radius is not None:
            check_positive(self, "radius")
        if self.centre not in ("bbox", "centroid"):
            raise ConfigError(f"scene.centre must be 'bbox' or 'centroid', got {self.centre!r}")
        if self.scale not in SCALES:
            raise ConfigError(f"scene.scale must be one of {', '.join(SCALES)}, got {self.scale!r}")
        if self.up_axis not in UP_AXES:
            raise ConfigError(f"scene.up_axis must be one of {', '.join(UP_AXES)}, got {self.up_axis!r}")
        if self.frame not in FRAMES:
            raise ConfigError(f"scene.frame must be one of {', '.join(FRAMES)}, got {self.frame!r}")
