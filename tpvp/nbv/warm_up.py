"""The warm-up of a simulated session: the initial view and the configured number of NBVs, each
executed in the simulator (:mod:`tpvp.scene.simulator`)."""

from __future__ import annotations

import numpy as np

from tpvp.nbv.methods import NbvContext, make_nbv
from tpvp.scene.simulator import observation


def warm_up(scene, config):
    """The initial view and ``config.nbv.warm_up_views`` NBVs executed: the NBV method, holding
    the executed views and their observations."""
    space = scene.view_space
    initial = space.view_index(config.initial_view)
    nbv = make_nbv(NbvContext(space, np.zeros(3), scene.sensor, config.nbv, prior=scene.previous))
    nbv.integrate(initial, observation(scene, initial))
    for _ in range(config.nbv.warm_up_views):
        choice = nbv.next_view()
        nbv.integrate(choice.view, observation(scene, choice.view))
    return nbv
