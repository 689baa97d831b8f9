"""Candidate views: view spaces as objects (positions, look-ats, table, initial views, range)."""

from tpvp.viewspace.single_plant import load_view_space  # noqa: F401
from tpvp.viewspace.space import (  # noqa: F401
    INITIAL_VIEW_INDICES,
    VIEW_SPACES,
    ViewSpace,
    get_view_space,
    read_view_space_file,
    view_space_choices,
)
from tpvp.viewspace.tammes import generate_view_space, min_angle_deg  # noqa: F401,E402
