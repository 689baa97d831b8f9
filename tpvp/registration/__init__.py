"""Non-rigid registration of the previous session onto the current coarse reconstruction."""

from tpvp.registration.embedded_deformation import (
    EDConfig,
    RegistrationResult,
    register_embedded_deformation,
)

from tpvp.registration.warp_field import WarpFieldConfig, WarpFieldResult, register_warp_field

__all__ = ["EDConfig", "RegistrationResult", "WarpFieldConfig", "WarpFieldResult", "register_embedded_deformation",
           "register_warp_field"]
