"""Candidate camera positions: the bundled single-plant view spaces and a Tammes-style generator."""

from tpvp.viewspace.single_plant import (  # noqa: F401
    INITIAL_VIEW_INDICES,
    load_view_space,
)
from tpvp.viewspace.tammes import generate_view_space, min_angle_deg  # noqa: F401,E402
