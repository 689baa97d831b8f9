"""Set-cover view selection: the fewest candidate views that see every planning-surface voxel."""

from tpvp.setcover.ilp import SetCoverConfig, SetCoverResult, solve_set_cover  # noqa: F401
