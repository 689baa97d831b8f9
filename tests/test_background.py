"""Drawings beside the computation (tpvp.viz.background): the same files as drawn here, one line
for a failed drawing, and a pool left early leaves no process behind."""

import multiprocessing

import numpy as np
import pytest

from tpvp.errors import TpvpError
from tpvp.registry import load_reference
from tpvp.viz.background import draw, drawing_pool


class _Unpicklable(Exception):
    def __init__(self):
        super().__init__("held a lambda")
        self.held = lambda: None


def unpicklable_failure():
    raise _Unpicklable


def _calls(folder):
    points = np.random.default_rng(0).random((500, 3))
    views = points[:6] + 1.0
    return [("tpvp.viz.figures:plot_plan", (folder / "plan.png", points, views, views[:1], views[1:], views), {}),
            ("tpvp.viz.figures:plot_coverage", (folder / "coverage.png", points, points[:, 0] > 0.1,
                                                 np.ones(len(points), bool)), {"title": "t"}),
            ("tpvp.viz.recording:write_recording", (folder / "r.rrd",), {"clouds": {"p": (points, (1, 2, 3))}})]


def test_the_pool_draws_the_files_drawn_here(tmp_path):
    here, there = tmp_path / "here", tmp_path / "there"
    here.mkdir(), there.mkdir()
    serial = draw(_calls(here))
    with drawing_pool() as pool:
        assert pool is not None
        pooled = draw(_calls(there), pool)
    assert [p.name for p in serial] == [p.name for p in pooled] == ["plan.png", "coverage.png", "r.rrd"]
    for name in ("plan.png", "coverage.png"):
        assert (here / name).read_bytes() == (there / name).read_bytes(), name
    assert (there / "r.rrd").stat().st_size > 0
    assert multiprocessing.active_children() == []


def test_a_failed_drawing_raises_its_error_here_and_the_pool_ends(tmp_path):
    with drawing_pool() as pool:
        with pytest.raises(AttributeError, match="no_such_figure"):
            draw([("tpvp.viz.figures:no_such_figure", (tmp_path / "p.png",), {})], pool)
        with pytest.raises((TpvpError, AttributeError), match="pickle"):  # an error, not a hang
            draw([(f"{__name__}:unpicklable_failure", (), {})], pool)
        assert draw([("tpvp.viz.figures:plot_coverage", (tmp_path / "c.png", np.zeros((2, 3)), [True, False],
                                                          [True, True]), {})], pool) == [tmp_path / "c.png"]
    assert multiprocessing.active_children() == []


def test_an_interrupted_caller_waits_for_the_drawing_then_ends_it(tmp_path):
    with pytest.raises(KeyboardInterrupt):
        with drawing_pool():
            raise KeyboardInterrupt
    assert multiprocessing.active_children() == []


def test_every_drawing_the_outputs_name_exists():
    import ast
    from pathlib import Path

    import tpvp

    names = set()
    for path in Path(tpvp.__file__).parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.startswith("tpvp.viz.") \
                    and ":" in node.value:
                names.add(node.value)
    assert len(names) >= 5, names
    for name in names:
        assert callable(load_reference(name)), name


def test_a_drawing_process_killed_from_outside_is_one_line(tmp_path):
    import os
    import signal

    with drawing_pool() as pool:
        os.kill(pool._process.pid, signal.SIGKILL)
        pool._process.join()
        with pytest.raises(TpvpError, match="the drawing process ended"):
            draw(_calls(tmp_path), pool)
    assert multiprocessing.active_children() == []
