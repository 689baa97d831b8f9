"""Prior-guided NBV: the previous session tells where the surface is (docs/sensor.md#prior-guided-nbv).

Between two sessions the plant stands in the same place and grows a little (a few mm to ~2 cm), so
the previous session's model, already in the planning frame, predicts what each candidate view
would see today; on the benchmark it ranks views far better than the information gain on an
occupancy map of the few views executed so far. The method:

1. voxelises the prior (``NbvContext.prior``) at ``resolution`` (default: its largest side /
   ``voxels_across``, ~2 mm for the paper's plants); voxels that hold a candidate camera are left
   out (a camera cannot stand in the geometry);
2. computes, once, which prior voxels every candidate view observes with the library's exact
   sensor (:func:`tpvp.visibility.visibility_matrix`: the configured model, range and intrinsics;
   the prior occludes itself);
3. a prior voxel is *explained* when an executed view observes it in that model;
4. the gain of a view is the number of unexplained prior voxels it observes; the next view is the
   non-executed view of largest gain (ties: the lowest index).

After step 2 a call is one sparse matrix-vector product. The executed views' observed points are
kept (``observations``, and the occupancy map built from them on demand) but do not enter the
gain: on ``benchmarks/nbv_rank.py``, counting prior voxels near observed points as explained
ranked the truly best views lower (likely: a leaf seen from one side still has an unseen side),
and letting the observed voxels occlude was worse on the protocol's plants and mixed on held-out
ones.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from tpvp.errors import ConfigError, PointCloudError, checked_cloud
from tpvp.nbv.methods import NBV_METHODS, GeometricNbv, NbvChoice, NbvContext
from tpvp.scene import voxels
from tpvp.scene.grid import OccupancyGrid, build_grid
from tpvp.visibility import visibility_matrix

VOXELS_ACROSS = 100  # prior voxel = largest side of the prior's bounding box / VOXELS_ACROSS


def prior_grid(points, resolution: float, cameras=None) -> OccupancyGrid:
    """The prior's occupied voxels at ``resolution`` as a grid (every voxel countable), without the
    voxels that hold one of the ``cameras`` positions ``(V, 3)``."""
    keys = voxels.voxelise(checked_cloud(points, "prior (previous session)"), resolution)
    if cameras is not None and len(cameras):
        keys = voxels.difference_keys(keys, voxels.voxelise(cameras, resolution))
    if not len(keys):
        raise PointCloudError("prior (previous session): every voxel holds a candidate camera")
    return build_grid(keys, resolution)


def prior_gains(visibility, executed=()) -> np.ndarray:
    """Per view (rows of the ``(V, N)`` prior visibility matrix): the prior voxels it observes that
    no ``executed`` view observes (``(V,)`` int64)."""
    visibility = sparse.csr_matrix(visibility)
    unexplained = np.ones(visibility.shape[1], dtype=np.int64)
    done = np.asarray(list(executed), dtype=np.int64).reshape(-1)
    if done.size:
        rows = visibility[done]
        unexplained[rows.indices] = 0
    return np.asarray(visibility.astype(np.int64) @ unexplained).ravel()


@NBV_METHODS.register("prior", "prior-guided gain: unexplained voxels of the previous session each view would "
                               "observe (needs the previous session)")
class PriorNbv(GeometricNbv):
    """Prior-guided gain: the voxels of the previous session's model that a view observes and no
    executed view does (module docstring). Needs ``context.prior``.

    ``resolution``: the prior's voxel (m); None: the prior's largest side / ``voxels_across``.
    The executed views and their observations are kept as :class:`GeometricNbv` keeps them, so
    ``view_state`` and the occupancy map of what was observed (``occupancy``, built only when
    read, e.g. by a view-selection method) are there as well.
    """

    def __init__(self, context: NbvContext, resolution: float | None = None,
                 voxels_across: int = VOXELS_ACROSS):
        if context.prior is None:
            raise ConfigError(f"NBV method {context.config.method!r} needs the previous session's model "
                              f"(NbvContext.prior); it got none - use nbv.method=geometric without a "
                              f"previous session")
        self.prior = checked_cloud(context.prior, "prior (previous session)")
        if resolution is None:
            side = float(np.ptp(self.prior, axis=0).max())
            if not side > 0:
                raise PointCloudError("prior (previous session): all points coincide; give a resolution")
            resolution = side / int(voxels_across)
        if not (np.isfinite(resolution) and resolution > 0):
            raise ConfigError(f"prior voxel resolution must be a positive number of metres, got {resolution!r}")
        self.resolution = float(resolution)
        super().__init__(context)
        self._grid: OccupancyGrid | None = None
        self._visibility: sparse.csr_matrix | None = None

    def integrate(self, view: int, points: np.ndarray) -> None:
        if not 0 <= int(view) < len(self.context.view_space):
            raise ConfigError(f"view {view} out of range for {len(self.context.view_space)} views")
        super().integrate(view, points)

    @property
    def grid(self) -> OccupancyGrid:
        """The prior's voxels (computed on first use)."""
        if self._grid is None:
            self._grid = prior_grid(self.prior, self.resolution, self.context.view_space.positions)
        return self._grid

    @property
    def visibility(self) -> sparse.csr_matrix:
        """``(V, N)``: which prior voxels each candidate view observes (computed once, on first use)."""
        if self._visibility is None:
            space = self.context.view_space
            self._visibility = sparse.csr_matrix(
                visibility_matrix(self.grid, space.positions, space.look_ats, self.context.sensor))
        return self._visibility

    def gains(self) -> np.ndarray:
        """Every view's gain (executed views included: theirs is 0)."""
        return prior_gains(self.visibility, self.executed)

    def next_view(self) -> NbvChoice:
        gains = self.gains()
        candidates = ~self.view_state
        if not candidates.any():
            raise ConfigError(f"no candidate view left: all {len(gains)} views are executed")
        return NbvChoice(int(np.argmax(np.where(candidates, gains, -1))), gains)
