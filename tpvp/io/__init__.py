"""Reading and writing point clouds and small text tables; atomic file writes."""

from tpvp.io.atomic import atomic_path, atomic_write_bytes, atomic_write_text
from tpvp.io.pointcloud import (
    GZIP_READ_EXTENSIONS,
    READ_EXTENSIONS,
    WRITE_EXTENSIONS,
    UnitChoice,
    cloud_extension,
    detect_units,
    read_point_cloud,
    read_text_table,
    to_metres,
    unit_choice,
    write_point_cloud,
)

__all__ = [
    "GZIP_READ_EXTENSIONS",
    "READ_EXTENSIONS",
    "WRITE_EXTENSIONS",
    "UnitChoice",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "cloud_extension",
    "detect_units",
    "read_point_cloud",
    "read_text_table",
    "to_metres",
    "unit_choice",
    "write_point_cloud",
]
