"""Drawings beside the computation (tpvp.viz.background): the same files as drawn here (the
recording read back with rerun: what was logged, entity by entity), one line for a failed drawing,
and a pool left early leaves no process behind."""

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


POINTS = np.random.default_rng(0).random((500, 3))
VIEWS = POINTS[:6] + 1.0


def _calls(folder):
    points, views = POINTS, VIEWS
    return [("tpvp.viz.figures:plot_plan", (folder / "plan.png", points, views, views[:1], views[1:], views), {}),
            ("tpvp.viz.figures:plot_coverage", (folder / "coverage.png", points, points[:, 0] > 0.1,
                                                 np.ones(len(points), bool)), {"title": "t"}),
            ("tpvp.viz.recording:write_recording", (folder / "r.rrd",),
             {"clouds": {"p": (points, (1, 2, 3))}, "cameras": {"views": (views, np.zeros(3))},
              "paths": {"path": views}})]


def read_recording(path) -> dict:
    """Entity path -> {component column: its logged values} of every chunk of an ``.rrd`` (rerun's
    own reader: rerun.chunk.RrdReader), with the number of rows logged on each entity."""
    from rerun.chunk import RrdReader

    entities = {}
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        entity = entities.setdefault(chunk.entity_path, {"rows": 0, "static": True})
        entity["rows"] += chunk.num_rows
        entity["static"] &= chunk.is_static
        for name in batch.schema.names:
            if not name.startswith("rerun.controls"):
                entity[name] = batch.column(name).to_pylist()
    return entities


def check_recording(path):
    """The recording holds the cloud, the six cameras and the path that _calls logged, and nothing else."""
    from tpvp.sensor.camera import look_at_rotation

    recording = read_recording(path)
    cameras = [f"/world/views/{i:03d}" for i in range(len(VIEWS))]
    assert set(recording) == {"/__properties", "/world", "/world/p", "/world/path", *cameras}
    assert all(entity["static"] for entity in recording.values())
    cloud = recording["/world/p"]
    assert cloud["rows"] == 1
    np.testing.assert_array_equal(cloud["Points3D:positions"][0], POINTS.astype(np.float32))
    assert cloud["Points3D:colors"] == [[0x010203FF]]  # (1, 2, 3), opaque
    for i, entity in enumerate(cameras):  # a pose and a pinhole each, at its view looking at the origin
        camera = recording[entity]
        assert camera["rows"] == 2
        np.testing.assert_array_equal(camera["Transform3D:translation"][0], [VIEWS[i].astype(np.float32)])
        np.testing.assert_allclose(np.reshape(camera["Transform3D:mat3x3"][0], (3, 3)).T,  # column-major
                                   look_at_rotation(VIEWS[i], np.zeros(3)), atol=1e-6)
        assert camera["Pinhole:resolution"] == [[[1280.0, 720.0]]]
    (strip,) = recording["/world/path"]["LineStrips3D:strips"][0]
    np.testing.assert_array_equal(strip, VIEWS.astype(np.float32))


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
    for folder in (here, there):
        check_recording(folder / "r.rrd")
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


def test_a_drawing_process_ends_when_its_parent_is_killed(tmp_path):
    """The drawing process holds no copy of its parent's end of the pipe: a parent killed without
    closing the pool (SIGKILL, out of memory) leaves no drawing process behind."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    code = ("import os, signal\nfrom tpvp.viz.background import drawing_pool\n"
            "with drawing_pool() as pool:\n    print(pool._process.pid, flush=True)\n"
            "    os.kill(os.getpid(), signal.SIGKILL)\n")
    out = tmp_path / "out.txt"
    with out.open("w") as stream:  # a file, not a pipe: a drawing process left behind would hold a pipe open
        status = subprocess.run([sys.executable, "-c", code], stdout=stream, stderr=subprocess.STDOUT).returncode
    assert status == -signal.SIGKILL, out.read_text()
    pid = int(out.read_text().split()[0])
    deadline = time.monotonic() + 60  # it loads matplotlib and rerun first, then reads the pipe's end
    stat = Path(f"/proc/{pid}/stat")
    while time.monotonic() < deadline:
        try:
            if stat.read_text().rsplit(")", 1)[1].split()[0] == "Z":  # ended, not yet reaped
                return
        except (FileNotFoundError, ProcessLookupError):
            return
        time.sleep(0.1)
    os.kill(pid, signal.SIGKILL)
    raise AssertionError("the drawing process outlived its killed parent")
