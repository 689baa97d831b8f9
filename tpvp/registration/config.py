"""Registration's configuration (``registration`` and each method's section), light: no solver or
kernel is imported with it; the method name is checked against
:data:`tpvp.registration.methods.REGISTRATION_METHODS` when a configuration is loaded."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tpvp.configuration_checks import check_positive
from tpvp.errors import ConfigError

SOLVERS = ("lu-cg", "cg", "direct")
CORRESPONDENCES = ("previous-to-coarse", "coarse-to-previous", "both")


@dataclass(frozen=True)
class EDConfig:
    """Parameters of :func:`register_embedded_deformation` (defaults: the paper / authors' code).

    node_coverage: graph voxel size r_graph (m). k_edges: graph neighbours per node.
    k_anchors: nodes blended per point. anchor_sigma_factor: sigma = factor * node_coverage.
    chamfer_samples: points drawn from P~ and from Q per iteration (also the Laplacian subset).
    chamfer_truncation: squared distance (m^2) from which a Chamfer term is zeroed.
    stop_loss: stop when the total loss falls below this. max_nodes: refuse larger graphs (units).
    threads: torch CPU threads of the torch-autograd reference
        (:mod:`tpvp.registration.autograd_reference`; None: leave torch's setting; 2 threads were
        up to 5x slower than 1 on a 2-core machine). The registration itself runs numpy and serial
        numba kernels and never imports torch.
    """

    node_coverage: float = 0.004
    k_edges: int = 8
    k_anchors: int = 4
    anchor_sigma_factor: float = 1.5
    iterations: int = 300
    lr: float = 1e-3
    lr_decay: float = 0.999
    w_arap: float = 1.0
    w_chamfer: float = 0.1
    w_laplacian: float = 0.01
    laplacian_in_gradient: bool = False
    laplacian_k: int = 8
    chamfer_samples: int = 1000
    chamfer_truncation: float = 0.3
    stop_loss: float = 1e-7
    max_nodes: int = 100_000
    seed: int = 0
    threads: int | None = 1

    def __post_init__(self):
        for name in ("node_coverage", "anchor_sigma_factor", "lr", "chamfer_truncation"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise ConfigError(f"EDConfig.{name} must be a positive number, got {v!r}")
        for name in ("k_edges", "k_anchors", "chamfer_samples", "laplacian_k", "max_nodes"):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1):
                raise ConfigError(f"EDConfig.{name} must be an integer >= 1, got {v!r}")
        if not (isinstance(self.iterations, (int, np.integer)) and not isinstance(self.iterations, bool)
                and self.iterations >= 0):
            raise ConfigError(f"EDConfig.iterations must be an integer >= 0, got {self.iterations!r}")
        if not (np.isfinite(self.lr_decay) and 0 < self.lr_decay <= 1):
            raise ConfigError(f"EDConfig.lr_decay must be in (0, 1], got {self.lr_decay!r}")
        for name in ("w_arap", "w_chamfer", "w_laplacian", "stop_loss"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
                raise ConfigError(f"EDConfig.{name} must be a number >= 0, got {v!r}")
        if self.threads is not None and not (isinstance(self.threads, int) and self.threads >= 1):
            raise ConfigError(f"EDConfig.threads must be an integer >= 1 or None, got {self.threads!r}")
        if not isinstance(self.seed, (int, np.integer)):
            raise ConfigError(f"EDConfig.seed must be an integer, got {self.seed!r}")

    @property
    def anchor_sigma(self) -> float:
        return self.anchor_sigma_factor * self.node_coverage


@dataclass(frozen=True)
class WarpFieldConfig:
    """Parameters of :func:`register_warp_field`; defaults = the values hard-coded in the authors'
    ``cilantro_nicp/src/core/Registration.cpp``.

    node_spacing: grid cell of the control nodes (m). anchors: nodes blended per point, Gaussian
    sigma = anchor_sigma_factor x node_spacing (0.075 m). regularisation_neighbours: k of the node
    graph *including the node itself* (k - 1 arcs per node), sigma = regularisation_sigma_factor x
    node_spacing (0.45 m). stiffness: regularisation weight; huber: Huber boundary on each parameter
    difference. max_correspondence: pairs this far apart or farther are ignored (m).
    correspondences: the search direction, ``previous-to-coarse`` (every point of the previous
    session P to its nearest point of the coarse cloud Q: the authors' setup, cilantro's default)
    or ``coarse-to-previous`` (every point of Q to its nearest warped point of P: the unseen parts
    of P get no data term, so a partial Q no longer pulls them onto what was seen; an unchanged row
    stays put) or ``both``.
    normal_neighbours: k of the target normals. icp_* / gn_* / cg_*: iteration limits and stop
    tolerances (see the module docstring). solver: ``lu-cg`` (CG preconditioned by a reused LU),
    ``cg`` (Eigen's Jacobi CG, as cilantro) or ``direct`` (an LU per system).
    voxel: both clouds reduced to voxel centroids at this size first (m; None: as given).
    centre: rotate about the source centroid instead of the world origin (not the reference).
    max_nodes: refuse larger graphs (units). workers: KD-tree query threads (-1: all cores).
    """

    node_spacing: float = 0.15
    anchors: int = 4
    anchor_sigma_factor: float = 0.5
    regularisation_neighbours: int = 8
    regularisation_sigma_factor: float = 3.0
    stiffness: float = 2000.0
    huber: float = 0.01
    max_correspondence: float = 0.5
    normal_neighbours: int = 30
    icp_iterations: int = 15
    icp_tolerance: float = 2.5e-3
    gn_iterations: int = 10
    gn_tolerance: float = 5e-4
    correspondences: str = "previous-to-coarse"
    solver: str = "lu-cg"
    cg_iterations: int = 500
    cg_tolerance: float = 1e-5
    voxel: float | None = 0.01
    centre: bool = False
    max_nodes: int = 100_000
    workers: int = -1

    def __post_init__(self):
        positive = ("node_spacing", "anchor_sigma_factor", "regularisation_sigma_factor", "huber",
                    "max_correspondence", "icp_tolerance", "gn_tolerance", "cg_tolerance")
        for name in positive + (("voxel",) if self.voxel is not None else ()):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (0 < v < float("inf")):
                raise ConfigError(f"WarpFieldConfig.{name} must be a positive number, got {v!r}")
        if isinstance(self.stiffness, bool) or not isinstance(self.stiffness, (int, float)) \
                or not (0 <= self.stiffness < float("inf")):
            raise ConfigError(f"WarpFieldConfig.stiffness must be a number >= 0, got {self.stiffness!r}")
        for name, low in (("anchors", 1), ("regularisation_neighbours", 1), ("normal_neighbours", 3),
                          ("icp_iterations", 0), ("gn_iterations", 1), ("cg_iterations", 1), ("max_nodes", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low:
                raise ConfigError(f"WarpFieldConfig.{name} must be an integer >= {low}, got {v!r}")
        if self.correspondences not in CORRESPONDENCES:
            raise ConfigError(f"WarpFieldConfig.correspondences must be one of {', '.join(CORRESPONDENCES)}, "
                              f"got {self.correspondences!r}")
        if self.solver not in SOLVERS:
            raise ConfigError(f"WarpFieldConfig.solver must be one of {', '.join(SOLVERS)}, got {self.solver!r}")
        if not isinstance(self.centre, bool):
            raise ConfigError(f"WarpFieldConfig.centre must be true or false, got {self.centre!r}")
        w = self.workers
        if isinstance(w, bool) or not isinstance(w, int) or not (w >= 1 or w == -1):
            raise ConfigError(f"WarpFieldConfig.workers must be an integer >= 1 or -1 (all cores), got {w!r}")

    @property
    def anchor_sigma(self) -> float:
        return self.anchor_sigma_factor * self.node_spacing

    @property
    def regularisation_sigma(self) -> float:
        return self.regularisation_sigma_factor * self.node_spacing


@dataclass(frozen=True)
class RegistrationConfig:
    """Alignment of the previous session onto the coarse reconstruction. method: a name of
    :data:`tpvp.registration.methods.REGISTRATION_METHODS`; each method reads its own section.
    warn_chamfer_fraction: warn when the aligned previous session stays farther than this fraction
    of the plant's size from the coarse scan (Chamfer): a matching pair ends near 0.5 %."""

    method: str = "embedded-deformation"
    embedded_deformation: EDConfig = field(default_factory=EDConfig)
    warp_field: WarpFieldConfig = field(default_factory=WarpFieldConfig)
    warn_chamfer_fraction: float = 0.03

    def __post_init__(self):
        check_positive(self, "warn_chamfer_fraction")
