"""Reading and writing point clouds and small text tables; atomic file writes."""

from tpvp.io.atomic import atomic_path, atomic_write_bytes, atomic_write_text
from tpvp.io.files import cloud_extension
from tpvp.io.readers import GZIP_READ_EXTENSIONS, READ_EXTENSIONS, read_point_cloud
from tpvp.io.text import read_text_table
from tpvp.io.units import UnitChoice, detect_units, to_metres, unit_choice
from tpvp.io.writers import WRITE_EXTENSIONS, write_point_cloud

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
