"""The learned planners as stage methods: ``pc-nbv`` (NBV) and ``ma-scvp`` (view selection).

A plugin of :mod:`tpvp.registry`: a stage registry imports this module the first time it is asked
for a name it does not hold, so the stages never import the learning package. This module is light;
torch and the networks load on the first call of a method (:mod:`tpvp.learning.planners`).
"""

from __future__ import annotations

from tpvp.nbv.methods import NBV_METHODS, NbvContext
from tpvp.setcover.methods import SELECTION_METHODS, Selection, SelectionProblem


@NBV_METHODS.register("pc-nbv", "PC-NBV-style learned NBV on the 32 hemisphere views (tpvp.learning)")
def pc_nbv(context: NbvContext):
    from tpvp.learning.planners import PcNbv  # torch behind it: loaded when the method is used

    return PcNbv(context)


@SELECTION_METHODS.register("ma-scvp")
def ma_scvp(problem: SelectionProblem, config) -> Selection:
    """MA-SCVP-style learned view set from what the executed views observed (tpvp.learning; ignores
    the planning surface)."""
    from tpvp.learning.planners import ma_scvp_selection  # torch behind it: loaded when the method is used

    return ma_scvp_selection(problem, config)


def learned_one_shot(scene, config, labels: str = "network") -> dict:
    """:func:`tpvp.learning.planners.learned_one_shot`, with torch loaded on the first call."""
    from tpvp.learning.planners import learned_one_shot as run  # torch behind it

    return run(scene, config, labels)
