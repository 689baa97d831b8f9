"""Figures (matplotlib, offscreen PNG) and rerun recordings of plans and results."""

from tpvp.viz.figures import plot_coverage, plot_depth_images, plot_plan, plot_row_sessions  # noqa: F401
from tpvp.viz.recording import write_recording  # noqa: F401
