"""Conservative inflation: the planning geometry P~+ = P~ u Q u I."""

from tpvp.inflation.inflate import (
    InflationConfig,
    InflationResult,
    candidate_grid,
    inflate,
    inflate_voxels,
)

__all__ = ["InflationConfig", "InflationResult", "candidate_grid", "inflate", "inflate_voxels"]
