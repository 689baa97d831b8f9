"""The sensor's configuration (``sensor``), light: the camera's intrinsics and no kernel."""

from __future__ import annotations

from dataclasses import dataclass, field

from tpvp.errors import ConfigError
from tpvp.sensor.camera import D435, Intrinsics

MODELS = ("reference", "pixel")
ROW_RANGE = 2.0  # m, sensor range of the greenhouse-row setting (the rooms' view spaces, the oracle, the sweeps)


@dataclass(frozen=True)
class SensorConfig:
    """Measurement model and its parameters (defaults: single-plant setting of the paper)."""

    model: str = "reference"
    max_range: float = 1.0  # m; ROW_RANGE in greenhouse rows
    pixel_stride: int = 1  # pixel model only
    intrinsics: Intrinsics = field(default=D435)
    # The sensor's errors: a profile of tpvp.sensor.noise.NOISE_PROFILES (checked when a configuration
    # is made: tpvp.config_loading); "ideal" is the exact sensor.
    noise: str = "ideal"

    def __post_init__(self):
        if self.model not in MODELS:
            raise ConfigError(f"unknown sensor model {self.model!r}; choose one of {', '.join(MODELS)}")
        if not (self.max_range > 0):
            raise ConfigError(f"max_range must be > 0 m, got {self.max_range!r}")
        if int(self.pixel_stride) < 1:
            raise ConfigError(f"pixel_stride must be a positive integer, got {self.pixel_stride!r}")
        if not isinstance(self.noise, str) or not self.noise:
            raise ConfigError(f"noise must be the name of a noise profile, got {self.noise!r}")
