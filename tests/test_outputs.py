"""Tests of what the user gets to see: figures (coverage, plan, depth images), ``tpvp render``'s
scene and images, and the one-line message of ``python -m tpvp`` run without the dependencies."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tpvp.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) of a PNG, checking the signature and the IHDR chunk."""
    data = Path(path).read_bytes()
    assert data[:8] == PNG_SIGNATURE, f"{path} is not a PNG"
    assert data[12:16] == b"IHDR"
    assert data[-12:-4] == b"\x00\x00\x00\x00IEND", f"{path} is truncated"
    return struct.unpack(">II", data[16:24])


# ---------------------------------------------------------------------------------------------
# figures


def test_plot_coverage_draws_all_classes(tmp_path):
    from tpvp.viz.figures import plot_coverage

    rng = np.random.default_rng(0)
    centres = rng.uniform(-0.1, 0.1, (600, 3))
    observable = rng.random(600) > 0.1
    covered = observable & (rng.random(600) > 0.05)
    out = plot_coverage(tmp_path / "coverage.png", centres, covered, observable, "test")
    assert out == tmp_path / "coverage.png"
    width, height = png_size(out)
    assert width > 2 * height  # three panels side by side
    # Nothing missed, nothing hidden: still draws (empty classes keep their count in the legend).
    plot_coverage(tmp_path / "all.png", centres, np.ones(600, bool), np.ones(600, bool))
    assert png_size(tmp_path / "all.png")[0] > 0
    assert not list(tmp_path.glob(".*tmp*"))  # atomic writes leave no temporary files


def test_a_paper_figure_draws_its_point_clouds_as_images_in_the_pdf(tmp_path):
    import matplotlib.pyplot as plt

    from tpvp.viz.figures import RASTER_POINTS, _save

    fig = plt.figure()
    ax = fig.add_subplot(projection="3d")
    cloud = ax.scatter(*np.random.default_rng(0).random((RASTER_POINTS + 1, 3)).T, s=1)
    marks = ax.scatter([0, 1], [0, 1], [0, 1], s=30)
    _save(fig, tmp_path / "f.png", vector=True)
    assert cloud.get_rasterized() and not marks.get_rasterized()
    pdf = (tmp_path / "f.pdf").read_bytes()
    assert pdf.startswith(b"%PDF") and b"/Image" in pdf  # the cloud, embedded as one image
    assert (tmp_path / "f.png").read_bytes().startswith(PNG_SIGNATURE)


def test_plot_plan_old_and_new_keywords(tmp_path):
    from tpvp.viz.figures import plot_plan

    rng = np.random.default_rng(1)
    plant = rng.uniform(-0.1, 0.1, (500, 3))
    views = rng.normal(size=(20, 3))
    views *= 0.4 / np.linalg.norm(views, axis=1, keepdims=True)
    polyline = views[[0, 3, 5]]
    old = plot_plan(tmp_path / "old.png", plant, views, views[:1], views[3:6], polyline, "old call")
    gx, gy = np.meshgrid(np.linspace(-0.2, 0.2, 41), np.linspace(-0.2, 0.2, 41))
    table = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, -0.07)])
    new = plot_plan(tmp_path / "new.png", plant, views, views[:1], views[3:6], polyline, "new call",
                    obstacle=(np.zeros(3), 0.2), table_points=table)
    for path in (old, new):
        assert path.stat().st_size > 1000
        png_size(path)
    assert old.read_bytes() != new.read_bytes()
    empty = plot_plan(tmp_path / "empty_table.png", plant, views, views[:1], views[3:6], polyline,
                      obstacle=([0.0, 0.0, 0.0], 0.25), table_points=np.zeros((0, 3)))
    png_size(empty)


def test_plot_depth_images(tmp_path):
    from tpvp.viz.figures import plot_depth_images

    depth = np.full((36, 64), np.inf)
    depth[10:20, 20:40] = np.linspace(0.3, 0.5, 20)
    out = plot_depth_images(tmp_path / "d.png", [depth, depth[::-1]], ["a", "b"], title="t")
    png_size(out)
    with pytest.raises(ConfigError):
        plot_depth_images(tmp_path / "none.png", [], [])


# ---------------------------------------------------------------------------------------------
# tpvp render: the scene of each view space, depth images


@pytest.mark.parametrize("view_space,has_table", [("sphere", False), ("hemisphere", True)])
def test_render_demo_table_only_for_hemisphere(tmp_path, view_space, has_table):
    from tpvp.simulate.render_demo import RenderDemoConfig, run_render_demo

    # Depth images only for one of the two (each figure costs about a second).
    out = tmp_path / view_space if has_table else None
    table, summary = run_render_demo(RenderDemoConfig(view_space=view_space), output=out)
    assert (summary["table_voxels"] > 0) == has_table
    if has_table:
        assert summary["table_voxels"] == 40401
    assert summary["views"] == len(table) == (32 if view_space == "hemisphere" else 63)
    assert table["coverage"].iloc[-1] == pytest.approx(1.0)
    if out is None:
        assert "depth_images" not in summary
        return
    written = [Path(p) for p in summary["depth_images"]]
    assert written == [out / "depth_views.png"]
    for path in written:
        width, height = png_size(path)
        assert width > height > 200


def test_render_demo_explicit_table_and_no_output():
    from tpvp.simulate.render_demo import RenderDemoConfig

    assert RenderDemoConfig().uses_table
    assert not RenderDemoConfig(view_space="sphere").uses_table
    assert RenderDemoConfig(view_space="sphere", table=True).uses_table
    assert not RenderDemoConfig(table=False).uses_table


def test_render_depth_images(tmp_path, tomato_scene):
    from tpvp.simulate.render_demo import default_depth_views, render_depth_images
    from tpvp.sensor.sensor import SensorConfig

    grid, views = tomato_scene
    assert default_depth_views(views) == [17, 8, 21, 0, 12, 28]
    below = np.vstack([views, [[0.0, 0.05, -0.4]]])
    assert default_depth_views(below)[3] == len(views)  # a view from below comes fourth
    written = render_depth_images(tmp_path / "imgs", grid, views, [17, 21, 999],
                                  sensor=SensorConfig(model="reference", pixel_stride=4))
    assert written == [tmp_path / "imgs" / "depth_views.png"]
    png_size(written[0])
    with pytest.raises(ConfigError):
        render_depth_images(tmp_path, grid, views, [999])


# ---------------------------------------------------------------------------------------------
# python -m tpvp / python -m data_tools without the dependencies


@pytest.mark.parametrize("module", ["tpvp", "data_tools"])
def test_missing_package_message(module):
    # -S: no site-packages (so no numpy), -E: ignore PYTHON* variables; the project comes from the
    # working directory, which ``-m`` puts on sys.path.
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    proc = subprocess.run([sys.executable, "-S", "-E", "-m", module, "--help"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"{module}: missing package 'numpy'")
    assert ".venv/bin/activate" in lines[0]
    assert "Traceback" not in proc.stderr


def test_missing_package_at_import_time(monkeypatch, capsys):
    import tpvp.__main__ as entry

    monkeypatch.setattr(entry, "missing_packages", lambda: [])

    def load():
        raise ModuleNotFoundError("No module named 'rerun'", name="rerun")

    assert entry.run_checked("tpvp", load) == 2
    err = capsys.readouterr().err
    assert err.startswith("tpvp: missing package 'rerun' (pip: rerun-sdk)") and err.count("\n") == 1

    def broken():
        raise ModuleNotFoundError("No module named 'tpvp.nothing'", name="tpvp.nothing")

    with pytest.raises(ModuleNotFoundError):  # the project's own bug: a traceback, not the hint
        entry.run_checked("tpvp", broken)
    assert entry.run_checked("tpvp", lambda: (lambda: 0)) == 0
