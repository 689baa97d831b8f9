"""Figures (matplotlib, offscreen PNG) and rerun recordings of plans and results. Import the
module you need (``tpvp.viz.figures``, ``tpvp.viz.recording``, ...): the package itself loads
nothing, so that a planner can name its drawings (``tpvp.viz.background``) without loading matplotlib."""
