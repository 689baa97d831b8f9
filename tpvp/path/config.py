"""The open path's configuration (``path``), light: no solver or kernel is imported with it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tpvp.errors import ConfigError
from tpvp.solvers import check_solver_settings

METHODS = ("auto", "dp", "ilp", "heuristic")

# Largest node count the Held-Karp table may take (2^(n-2) x (n-2) doubles: 170 MB at 22).
_DP_HARD_LIMIT = 22


@dataclass(frozen=True)
class TspConfig:
    """How to solve the open path (see :mod:`tpvp.path.tsp`)."""

    method: str = "auto"
    dp_max_nodes: int = 15  # "auto": Held-Karp up to this many views (including start and end)
    ilp_max_nodes: int = 40  # "auto": exact ILP up to this many views, heuristic beyond
    solver: str = "cbc"  # ILP solver: "cbc" (PuLP's CBC) or "highs" (PuLP's HiGHS interface)
    time_limit: float = 60.0  # seconds for the ILP cutting loop (then the heuristic) or the heuristic
    threads: int = 1  # one thread keeps the result deterministic
    kicks: int = 50  # heuristic: random double-bridge restarts of the local search (fixed seed)
    bound_iterations: int = 2000  # band_path: Held-Karp subgradient iterations for heuristic bands (0: no bound)
    band_gap: float = 0.02  # band_path: keep improving a heuristic band's path until its gap to the bound is below
    band_seconds: float = 5.0  # band_path: ... or this many seconds have gone into the band

    def __post_init__(self):
        if self.method not in METHODS:
            raise ConfigError(f"method must be one of {METHODS}, got {self.method!r}")
        check_solver_settings(self.solver, self.time_limit, self.threads)
        if not (isinstance(self.dp_max_nodes, (int, np.integer)) and 1 <= self.dp_max_nodes <= _DP_HARD_LIMIT):
            raise ConfigError(f"dp_max_nodes must be an integer in [1, {_DP_HARD_LIMIT}], got {self.dp_max_nodes!r}")
        if not (isinstance(self.ilp_max_nodes, (int, np.integer)) and self.ilp_max_nodes >= 1):
            raise ConfigError(f"ilp_max_nodes must be an integer >= 1, got {self.ilp_max_nodes!r}")
        if not (isinstance(self.kicks, (int, np.integer)) and self.kicks >= 0):
            raise ConfigError(f"kicks must be an integer >= 0, got {self.kicks!r}")
        for name in ("band_gap", "band_seconds"):
            value = getattr(self, name)
            if isinstance(value, bool) or not (isinstance(value, (int, float)) and value >= 0):
                raise ConfigError(f"{name} must be a number >= 0, got {value!r}")
        if isinstance(self.bound_iterations, (bool, np.bool_)) or not (
                isinstance(self.bound_iterations, (int, np.integer)) and self.bound_iterations >= 0):
            raise ConfigError(f"bound_iterations must be an integer >= 0, got {self.bound_iterations!r}")
