"""Reading and writing point clouds and small text tables; atomic file writes."""

from tpvp.io.atomic import atomic_path, atomic_write_bytes, atomic_write_text
from tpvp.io.pointcloud import (
    READ_EXTENSIONS,
    WRITE_EXTENSIONS,
    detect_units,
    read_point_cloud,
    read_text_table,
    to_metres,
    write_point_cloud,
)

__all__ = [
    "READ_EXTENSIONS",
    "WRITE_EXTENSIONS",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "detect_units",
    "read_point_cloud",
    "read_text_table",
    "to_metres",
    "write_point_cloud",
]
