"""Non-rigid registration of the previous session onto the current coarse reconstruction."""

from tpvp.registration.embedded_deformation import (
    EDConfig,
    RegistrationResult,
    register_embedded_deformation,
)

__all__ = ["EDConfig", "RegistrationResult", "register_embedded_deformation"]
