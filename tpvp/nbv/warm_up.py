"""The warm-up of a simulated session: the initial view and the configured number of NBVs, each
executed in the simulator (``scene.observe``: :class:`tpvp.simulate.world.Scene`, or any scene that
renders what a view observes)."""

from __future__ import annotations

import numpy as np

from tpvp.errors import ConfigError
from tpvp.nbv.methods import start_nbv


def warm_up(scene, config):
    """The initial view and ``config.nbv.warm_up_views`` NBVs executed: the NBV method, holding
    the executed views and their observations."""
    initial = scene.view_space.view_index(config.initial_view)
    nbv = start_nbv(scene, config)
    seen = scene.observe(initial)
    if len(seen) == 0:
        raise ConfigError(_initial_sees_nothing(scene, initial, config))
    nbv.integrate(initial, seen)
    for _ in range(config.nbv.warm_up_views):
        choice = nbv.next_view()
        nbv.integrate(choice.view, scene.observe(choice.view, len(nbv.executed)))  # its place among the captures
    return nbv


def _initial_sees_nothing(scene, initial: int, config) -> str:
    """The initial view sees no voxel of the plant (other views do: :func:`build_scene` refuses a
    view space where none does): say so and list views that would do."""
    seeing = np.flatnonzero(np.diff(scene.truth_visibility.indptr) > 0)
    shown = ", ".join(map(str, seeing[:10])) + (", ..." if len(seeing) > 10 else "")
    per_metre = scene.scan_scale if config.scene.scale == "native" else 1.0  # as build_scene words it
    return (f"initial view {initial} of view space {config.view_space!r} sees nothing of the plant (it is "
            f"{np.linalg.norm(scene.view_space.positions[initial]) / per_metre:.3g} m from the plant's centre, "
            f"the sensor sees {scene.sensor.max_range / per_metre:.3g} m far); choose an --initial-view that does: "
            f"{shown} ({len(seeing)} of {len(scene.view_space)} views see it)")
