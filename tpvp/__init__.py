"""tpvp: one-shot view planning guided by the previous-session reconstruction."""

__version__ = "0.1.0"

import os as _os

# numba would try TBB first and warn that the installed TBB is too old; OpenMP is what we use.
_os.environ.setdefault("NUMBA_THREADING_LAYER", "omp")
# open3d's web visualiser (and its start-up lines in every notebook) is never used: figures are files.
_os.environ.setdefault("OPEN3D_DISABLE_WEB_VISUALIZER", "true")
