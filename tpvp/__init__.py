"""tpvp: one-shot view planning guided by the previous-session reconstruction."""

__version__ = "0.1.0"

import os as _os

# numba would try TBB first and warn that the installed TBB is too old; OpenMP is what we use.
_os.environ.setdefault("NUMBA_THREADING_LAYER", "omp")
