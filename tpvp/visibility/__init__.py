"""Which surface voxels each candidate view sees: sparse visibility matrices and oracles."""

from tpvp.visibility.matrix import (  # noqa: F401
    coverage_ratio,
    covered_voxels,
    oracle_voxels,
    safe_visibility,
    visibility_matrix,
)
