"""Errors of the data tools (all :class:`tpvp.errors.TpvpError`, so the CLI prints one line)."""

from tpvp.errors import ConfigError, InputFileError, PointCloudError, TpvpError


class DownloadError(TpvpError, OSError):
    """A download failed: offline, server error, size or checksum mismatch."""


class CredentialsError(TpvpError):
    """Kaggle credentials are missing or unusable."""


class DatasetError(TpvpError, ValueError):
    """A dataset folder or manifest is inconsistent (missing columns, existing session, ...)."""


class PlantSimulatorError(TpvpError):
    """The plant simulator (Helios, the optional package pyhelios3d) cannot load, or failed to grow
    a plant."""


__all__ = ["ConfigError", "CredentialsError", "DatasetError", "DownloadError", "InputFileError",
           "PlantSimulatorError", "PointCloudError", "TpvpError"]
