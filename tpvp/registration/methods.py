"""Registration methods, chosen by name (``registration.method``) from :data:`REGISTRATION_METHODS`.

Signature of a method: ``register(previous (N, 3), coarse (M, 3), config: RegistrationConfig)
-> Alignment``, both clouds in metres in one frame. Each method reads its own section of the
configuration (``config.embedded_deformation`` for ``embedded-deformation``, ``config.warp_field``
for ``warp-field``). A new method is one function plus one ``@REGISTRATION_METHODS.register`` line.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tpvp.errors import GraphTooLargeError

from tpvp.registration.embedded_deformation import register_embedded_deformation
from tpvp.registration.warp_field import register_warp_field
from tpvp.registry import Registry
from tpvp.metrics.geometry import chamfer_distance

REGISTRATION_METHODS = Registry("registration method")


@dataclass(frozen=True, eq=False)
class Alignment:
    """The previous session moved onto the current coarse reconstruction.

    warped: (N, 3) the previous session's points after alignment (``warp-field`` first reduces
    both clouds to 1 cm voxel centroids, as the reference does, and returns the reduced session).
    chamfer_before/after (m): the symmetric Chamfer distance to the coarse reconstruction (for
    ``warp-field``, between the reduced clouds). details: the method's own result (e.g.
    ``RegistrationResult`` of embedded deformation or ``WarpFieldResult``, with its graph and ``warp``).
    """

    warped: np.ndarray
    chamfer_before: float
    chamfer_after: float
    seconds: float
    details: object = field(default=None)


@REGISTRATION_METHODS.register("embedded-deformation")
def embedded_deformation(previous, coarse, config) -> Alignment:
    """Embedded deformation optimised with Adam (the authors' single-plant registration)."""
    result = register_embedded_deformation(previous, coarse, config.embedded_deformation)
    return Alignment(result.warped, result.chamfer_before, result.chamfer_after, result.seconds, result)


@REGISTRATION_METHODS.register("warp-field")
def warp_field(previous, coarse, config) -> Alignment:
    """Sparse locally rigid warp-field ICP (the authors' greenhouse-row registration, cilantro)."""
    result = register_warp_field(previous, coarse, config.warp_field)
    return Alignment(result.warped, result.chamfer_before, result.chamfer_after, result.seconds, result)


@REGISTRATION_METHODS.register("none")
def no_registration(previous, coarse, config) -> Alignment:
    """The previous session as it is (an ablation: no alignment)."""
    previous = np.asarray(previous, dtype=np.float64)
    chamfer = chamfer_distance(previous, coarse)
    return Alignment(previous, chamfer, chamfer, 0.0)


@REGISTRATION_METHODS.register("no-prior")
def no_prior(previous, coarse, config) -> Alignment:
    """No previous session: the coarse reconstruction stands in for it (one-shot planning without a prior)."""
    coarse = np.unique(np.asarray(coarse, dtype=np.float64), axis=0)
    return Alignment(coarse, 0.0, 0.0, 0.0)


def register(previous, coarse, config, name: str | None = None) -> Alignment:
    """Run the registration method named by ``config.method``; ``name`` (the previous session's
    file) starts the message of a graph over its node limit (the method knows arrays only)."""
    try:
        return REGISTRATION_METHODS.get(config.method)(previous, coarse, config)
    except GraphTooLargeError as exc:
        if name is None:
            raise
        raise GraphTooLargeError(f"{name}: {exc}") from None
