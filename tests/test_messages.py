"""The lines users see on bad input (docs/messages.md), one test per row of its table.

Each row of docs/messages.md's table names a test id; :data:`ROWS` holds, for each id, the real
command that shows the line (``tpvp.cli.main`` / ``data_tools.cli.main`` in this process, or the
installed CLI in a subprocess), its exit status and the line's key content. A table row without a
test here, or a test without a row, fails :func:`test_every_row_of_the_table_has_a_test`.
"""

from __future__ import annotations

import gzip
import importlib.util
import json
import os
import re
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from data_tools import cli as data_cli
from helpers import benchmark_module, plan_folder
from tpvp.cli import main
from tpvp.errors import install_warning_format
from tpvp.scene.samples import sample_path

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "messages.md"
ROWS = {}
DATA_TOOLS_ROWS = ("kaggle-credentials", "data-tools-output-inside-input", "capture-unknown-layout",
                   "capture-depth-units", "capture-depth-units-one-frame", "capture-empty-depth-image",
                   "capture-one-frame", "capture-pose-not-finite", "capture-frame-name",
                   "helios-unknown-species")  # python -m data_tools, not tpvp


def row(test_id: str, exit_status: int, *expected: str, stream: str = "err"):
    """Register a row: the function (its arguments: fixtures by name) runs the command and returns
    ``(exit status, stdout, stderr)``; the last line of ``stream`` that holds ``expected[0]`` must
    hold every ``expected`` string (a regular expression when it starts with ``re:``)."""
    def register(func):
        ROWS[test_id] = (func, exit_status, expected, stream)
        return func
    return register


def run_cli(argv, capsys, entry=main):
    """``entry(argv)`` in this process: (exit status, stdout, stderr); argparse errors included."""
    try:
        code = entry([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def run_subprocess(argv, cwd, env=None):
    env = dict(os.environ, **(env or {}), PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    result = subprocess.run([sys.executable, "-m", "tpvp", *map(str, argv)], capture_output=True, text=True,
                            cwd=cwd, env=env, timeout=300)
    return result.returncode, result.stdout, result.stderr


@pytest.fixture(scope="module")
def scans(tmp_path_factory):
    """The bundled real tomato pair (mm), every 4th point, as plain xyz files: day1.xyz, day2.xyz."""
    folder = tmp_path_factory.mktemp("scans")
    for name, sample in (("day1.xyz", "tomato_0305"), ("day2.xyz", "tomato_0306")):
        rows = np.loadtxt(gzip.decompress(sample_path(sample).read_bytes()).decode().splitlines())[::4, :3]
        np.savetxt(folder / name, rows, fmt="%.4f")
    return folder


@pytest.fixture(scope="module")
def metres_run(scans):
    """One whole `tpvp plan` of the millimetre pair read with --units m (a quick registration)."""
    return run_subprocess(["plan", "--previous", scans / "day1.xyz", "--current", scans / "day2.xyz", "--units", "m",
                           "--set", "registration.embedded_deformation.iterations=5", "--output",
                           scans.parent / "metres_run"], cwd=scans)


def points(scans) -> np.ndarray:
    return np.loadtxt(scans / "day1.xyz")


def ply_bytes(pts, comment: bytes = b"") -> bytes:
    head = (b"ply\nformat binary_little_endian 1.0\n" + comment + b"element vertex %d\nproperty float x\n"
            b"property float y\nproperty float z\nend_header\n" % len(pts))
    return head + np.asarray(pts, dtype="<f4").tobytes()


def plan(previous, current, *more, output=None):
    return ["plan", "--previous", previous, "--current", current, *more,
            "--output", output or Path(previous).parent / "out"]


# --------------------------------------------------------------------------------------------------
# reading the scans


@row("missing-file", 2, "day0.ply: file not found")
def _(tmp, scans, capsys):
    return run_cli(plan(tmp / "day0.ply", scans / "day2.xyz"), capsys)


@row("truncated-ply", 2, "day1.ply: truncated: header declares 6199 vertices, file holds 6186")
def _(tmp, scans, capsys):
    (tmp / "day1.ply").write_bytes(ply_bytes(points(scans))[:-150])
    return run_cli(plan(tmp / "day1.ply", scans / "day2.xyz"), capsys)


@row("empty-cloud", 2, "day1.ply: holds no points (element vertex 0)")
def _(tmp, scans, capsys):
    (tmp / "day1.ply").write_bytes(ply_bytes(np.zeros((0, 3))))
    return run_cli(plan(tmp / "day1.ply", scans / "day2.xyz"), capsys)


@row("nan-cloud", 2, "day1.xyz: 1 of 6,199 points has NaN/inf coordinates (first at point 4)", "--drop-invalid")
def _(tmp, scans, capsys):
    pts = points(scans)
    pts[3, 1] = np.nan
    np.savetxt(tmp / "day1.xyz", pts)
    return run_cli(plan(tmp / "day1.xyz", scans / "day2.xyz"), capsys)


@row("ply-header-not-ascii", 2, "day1.ply: line 3 of the PLY header is not ASCII text",
     "byte 0xe9 at column 24", "'comment scanned by Andr\\xe9'", "must be plain ASCII")
def _(tmp, scans, capsys):
    (tmp / "day1.ply").write_bytes(ply_bytes(points(scans), b"comment scanned by Andr\xe9\n"))
    return run_cli(plan(tmp / "day1.ply", scans / "day2.xyz"), capsys)


@row("pcd-header-not-ascii", 2, "day1.pcd: line 2 of the PCD header is not ASCII text", "byte 0xc3 at column 18",
     "'# scanned by André'", "must be plain ASCII")
def _(tmp, scans, capsys):
    pts = points(scans)
    head = ("# .PCD v0.7\n# scanned by André\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
            f"WIDTH {len(pts)}\nHEIGHT 1\nPOINTS {len(pts)}\nDATA binary\n")
    (tmp / "day1.pcd").write_bytes(head.encode() + pts.astype("<f4").tobytes())
    return run_cli(plan(tmp / "day1.pcd", scans / "day2.xyz"), capsys)


@row("no-end-header", 2, "day1.ply: PLY header has no 'end_header' line (binary data at line 7)")
def _(tmp, scans, capsys):
    data = ply_bytes(points(scans))
    (tmp / "day1.ply").write_bytes(data.replace(b"end_header\n", b"\xff\xfe"))  # binary data right after
    return run_cli(plan(tmp / "day1.ply", scans / "day2.xyz"), capsys)


# --------------------------------------------------------------------------------------------------
# units and coordinates


@row("wrong-units", 2, "day1.xyz: wrong units? --units m makes it a 700 m plant (limit 100 m)",
     "it looks like millimetres: use --units mm or --units auto")
def _(tmp, scans, capsys):
    pts = np.random.default_rng(0).uniform(0, 700, size=(500, 3))
    pts[:2] = [[0, 0, 0], [700, 0, 0]]
    np.savetxt(tmp / "day1.xyz", pts)
    return run_cli(plan(tmp / "day1.xyz", scans / "day2.xyz", "--units", "m"), capsys)


@row("units-differ-given", 2, "day1.xyz spans 46.2 m and ", "day2.xyz 0.0479 m, a factor 964 apart",
     "--units m applies to both: try --units auto")
def _(tmp, scans, capsys):
    np.savetxt(tmp / "day2.xyz", np.loadtxt(scans / "day2.xyz") / 1000)
    return run_cli(plan(scans / "day1.xyz", tmp / "day2.xyz", "--units", "m"), capsys)


@row("units-differ-auto", 2, "day1.xyz spans 46.2 mm and ", "day2.xyz 4.79 m, a factor 104 apart",
     "--units auto read one as mm, the other as m", "give --units m or --units mm")
def _(tmp, scans, capsys):
    np.savetxt(tmp / "day2.xyz", np.loadtxt(scans / "day2.xyz") / 10)  # centimetres
    return run_cli(plan(scans / "day1.xyz", tmp / "day2.xyz"), capsys)


@row("plant-over-5-m", 0, "day1.xyz: read as metres (--units m) the plant spans 46.2 m", "tpvp: warning: ",
     "give --units mm")
def _(tmp, scans, metres_run):
    return metres_run


@row("absurd-coordinates", 2, "day1.xyz: 1 of 6,199 points has absurd coordinates",
     "(first: x = 1e+30 at point index 5, counting from 0)", "beyond 1e+10 in metres or millimetres")
def _(tmp, scans, capsys):
    pts = points(scans)
    pts[5, 0] = 1e30
    np.savetxt(tmp / "day1.xyz", pts)
    return run_cli(plan(tmp / "day1.xyz", scans / "day2.xyz"), capsys)


@row("absurd-coordinates-1e308", 2, "day1.ply: all 6,199 points have absurd coordinates",
     "re:\\(first: x = -?1e\\+308 at point index 0")
def _(tmp, scans, capsys):
    pts = np.where(points(scans) > 0, 1e308, -1e308)  # max - min overflows: no RuntimeWarning either
    head = (b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty double x\nproperty double y\n"
            b"property double z\nend_header\n" % len(pts))
    (tmp / "day1.ply").write_bytes(head + pts.astype("<f8").tobytes())
    return run_cli(plan(tmp / "day1.ply", scans / "day2.xyz"), capsys)


@row("stray-point", 2, "day1.xyz: 1 of 6,199 points lies far from all the others",
     "(y = 3e+07 at point index 7, counting from 0)", "with it the scan spans 3e+07 mm, without it 46.2 mm")
def _(tmp, scans, capsys):
    pts = points(scans)
    pts[7, 1] = 3e7
    np.savetxt(tmp / "day1.xyz", pts)
    return run_cli(plan(tmp / "day1.xyz", scans / "day2.xyz"), capsys)


@row("python-warning", 2, "shifted.xyz: coordinates reach |c| = 100", "tpvp: warning: ", "taken as metres",
     "give --units mm")
def _(tmp, scans, capsys):
    plant = np.random.default_rng(1).normal(size=(3000, 3)) * 0.02
    np.savetxt(tmp / "shifted.xyz", plant + [100.0, 0, 0])
    np.savetxt(tmp / "day2.xyz", plant)
    return run_subprocess(plan(tmp / "shifted.xyz", tmp / "day2.xyz"), cwd=tmp)  # the real CLI's warnings


# --------------------------------------------------------------------------------------------------
# view spaces


@row("view-space-bad-row", 2, "views.txt: line 3 is not a view: '0 0.4 abc'",
     "each row must be 3 numbers 'x y z'", "or 6 numbers 'x y z lx ly lz'")
def _(tmp, scans, capsys):
    (tmp / "views.txt").write_text("3\n0.4 0 0\n0 0.4 abc\n0 0 0.4\n")
    return run_cli(plan(scans / "day1.xyz", scans / "day2.xyz", "--view-space", tmp / "views.txt"), capsys)


@row("view-space-own-position", 2, "views.txt: line 2 (view 1, counting from 0) looks at its own position",
     "give it a look-at point elsewhere")
def _(tmp, scans, capsys):
    (tmp / "views.txt").write_text("0.4 0 0 0 0 0\n0 0.4 0 0 0.4 0\n")
    return run_cli(plan(scans / "day1.xyz", scans / "day2.xyz", "--view-space", tmp / "views.txt"), capsys)


def _hemisphere(scale: float, far_view: int | None = None) -> np.ndarray:
    views = np.loadtxt(ROOT / "tpvp" / "data" / "view_spaces" / "view_space_hemisphere32.txt", skiprows=1)
    if far_view is None:
        return views * scale
    views[far_view] *= scale
    return views


@row("view-space-out-of-range", 2, "no candidate view sees the plant: its 32 views are 5 m from the centre of a "
     "plant 0.24 m across, the sensor sees 1 m far", "check the view space's radius and units", "--radius")
def _(tmp, scans, capsys):
    np.savetxt(tmp / "far.txt", _hemisphere(12.5))
    return run_cli(plan(scans / "day1.xyz", scans / "day2.xyz", "--view-space", tmp / "far.txt"), capsys)


@row("initial-view-blind", 2, "initial view 17 of view space", "sees nothing of the plant (it is 5 m from",
     "choose an --initial-view that does: 0, 1, 2", "(31 of 32 views see it)")
def _(tmp, scans, capsys):
    np.savetxt(tmp / "far17.txt", _hemisphere(12.5, far_view=17))
    return run_cli(plan(scans / "day1.xyz", scans / "day2.xyz", "--view-space", tmp / "far17.txt"), capsys)


# --------------------------------------------------------------------------------------------------
# the pipeline


@row("registration-node-limit", 2, "day1.xyz: the previous session's scan gives ",
     "deformation-graph nodes at a 4 mm node spacing (planning frame), more than the limit of 10",
     "--set registration.embedded_deformation.max_nodes=", "--set registration.embedded_deformation.node_coverage=")
def _(tmp, scans, capsys):
    return run_cli(plan(scans / "day1.xyz", scans / "day2.xyz", "--set",
                        "registration.embedded_deformation.max_nodes=10"), capsys)


@row("unreachable-voxels", 0, "view selection", "re:\\d+ views, optimal=True, \\d+ unreachable voxels dropped",
     stream="out")
def _(tmp, scans, metres_run):
    return metres_run


@row("kaggle-credentials", 2, "data_tools greenhouse download: error: no Kaggle credentials found",
     "https://www.kaggle.com/settings/api", "KAGGLE_API_TOKEN")
def _(tmp, scans, capsys, monkeypatch):
    for var in ("KAGGLE_API_TOKEN", "KAGGLE_USERNAME", "KAGGLE_KEY", "KAGGLE_CONFIG_DIR", "XDG_CONFIG_HOME"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("HOME", str(tmp / "home"))
    return run_cli(["greenhouse", "download", "--output", tmp / "out"], capsys, entry=data_cli.main)


# --------------------------------------------------------------------------------------------------
# the output folder, the disk and signals


@row("output-busy", 3, "output folder", "is being written by another run", "wait for it to finish or choose another folder")
def _(tmp, scans, capsys):
    import fcntl

    with open(tmp / ".out.tpvp-lock", "w") as lock:  # what a running `tpvp plan --output out` holds
        fcntl.flock(lock, fcntl.LOCK_EX)
        return run_cli(plan(scans / "day1.xyz", scans / "day2.xyz", output=tmp / "out"), capsys)


@row("disk-full", 4, "cannot write", "plan.csv: No space left on device; nothing was published", "is as it was")
def _(tmp, scans, capsys):
    from tpvp.io import faults

    with faults.inject("enospc", 1):  # the first file write fails as on a full disk
        return run_cli(plan(scans / "day1.xyz", scans / "day2.xyz", output=tmp / "out"), capsys)


@row("read-only-file-system", 4, "is on a read-only file system; choose a folder on a writable disk")
def _(tmp, scans, capsys):
    real_faults = benchmark_module("real_faults")

    try:
        with real_faults.mounted_tmpfs(1 << 20, read_only=True) as disk:
            return run_cli(plan(scans / "day1.xyz", scans / "day2.xyz", output=disk / "out"), capsys)
    except real_faults.Unavailable as exc:
        pytest.skip(str(exc))


@row("output-is-input", 2, "tpvp export: error: output file", "is the input", "inputs are only read")
def _(tmp, capsys):
    run = plan_folder(tmp)
    return run_cli(["export", "moveit", run, "--output", run / "plan.csv", "--force"], capsys)


@row("output-file-exists", 2, "tpvp export: error: output file", "exists: choose a new one, or --force to replace it")
def _(tmp, capsys):
    run = plan_folder(tmp)
    (tmp / "goals.yaml").write_text("mine\n")
    return run_cli(["export", "moveit", run, "--output", tmp / "goals.yaml"], capsys)


@row("output-file-busy", 3, "output file", "is being written by another run", "wait for it to finish")
def _(tmp, capsys):
    import fcntl

    run = plan_folder(tmp)
    with open(tmp / ".goals.yaml.tpvp-lock", "w") as lock:  # what a running export to goals.yaml holds
        fcntl.flock(lock, fcntl.LOCK_EX)
        return run_cli(["export", "moveit", run, "--output", tmp / "goals.yaml"], capsys)


@row("output-file-unwritable", 4, "tpvp export: error: cannot create", "nothing was written",
     "choose a place you can write (--output)")
def _(tmp, capsys):
    run = plan_folder(tmp)
    (tmp / "notes.txt").write_text("a file, not a folder\n")
    return run_cli(["export", "moveit", run, "--output", tmp / "notes.txt" / "goals.yaml"], capsys)


@row("output-file-disk-full", 4, "tpvp export: error: cannot write", "goals.yaml: No space left on device",
     "nothing was written", "was not created")
def _(tmp, capsys):
    from tpvp.io import faults

    run = plan_folder(tmp)
    with faults.inject("enospc", 1):
        return run_cli(["export", "moveit", run, "--output", tmp / "goals.yaml"], capsys)


@row("interrupted-while-starting", 130, "tpvp: interrupted while starting; nothing was written")
def _(tmp, scans):
    real_faults = benchmark_module("real_faults")

    command = real_faults.tpvp(*plan(scans / "day1.xyz", scans / "day2.xyz", output=tmp / "out"))
    result = real_faults.start_up_try(command, 0.3, signal.SIGINT)
    return result["rc"], "", "\n".join(result["stderr"])


@row("interrupted-while-running", 130, "tpvp plan: interrupted; nothing was written", "was not created")
def _(tmp, scans, capsys):
    from tpvp.io import faults

    # SIGINT raises KeyboardInterrupt, as in a terminal: a test runner's worker may ignore it.
    saved = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with faults.inject("interrupt", 1):  # Ctrl-C as the first file is written
            return run_cli(plan(scans / "day1.xyz", scans / "day2.xyz", output=tmp / "out"), capsys)
    finally:
        signal.signal(signal.SIGINT, saved)


@row("data-tools-output-inside-input", 2, "data_tools greenhouse clean: error: dataset", "lies inside the input",
     "inputs are only read: choose another dataset outside")
def _(tmp, capsys):
    (tmp / "raw").mkdir()
    return run_cli(["greenhouse", "clean", tmp / "raw", "--output", tmp / "raw" / "clean"], capsys,
                   entry=data_cli.main)


@row("reference-with-dataset", 2, "tpvp greenhouse: error: --reference applies to generated rows",
     "are used as they are")
def _(tmp, capsys):
    return run_cli(["greenhouse", "--dataset", tmp / "data", "--reference", "complete", "--output", tmp / "out"],
                   capsys)


@row("option-for-other-setting", 2, "tpvp config: error: --scale applies to individual plants",
     "configuration 'paper-row' plans greenhouse rows")
def _(tmp, capsys):
    return run_cli(["config", "--config", "paper-row", "--scale", "native"], capsys)


@row("organ-targets-on-rows", 2, "tpvp greenhouse: error: configuration: selection.organ_targets='fruit=1.0': "
     "organ targets need a plant's organ labels; a row has none")
def _(tmp, capsys):
    return run_cli(["greenhouse", "--set", "selection.organ_targets=fruit=1.0", "--output", tmp / "out"], capsys)


@row("season-key-per-case", 2, "tpvp experiments: error: selection.replan_after=1 (--config or --set): the season "
     "sets it per case from --replan-after")
def _(tmp, capsys):
    return run_cli(["experiments", "season", "--set", "selection.replan_after=1", "--output", tmp / "out"], capsys)


@row("season-option-other-season", 2, "tpvp experiments: error: --view-spaces applies to the plants' season",
     "--rows runs the greenhouse rows' season")
def _(tmp, capsys):
    return run_cli(["experiments", "season", "--rows", "--view-spaces", "sphere", "--output", tmp / "out"], capsys)


# --------------------------------------------------------------------------------------------------
# phone captures, exports, organs and Helios (data_tools capture / helios, tpvp export, --organ-targets)


@row("capture-unknown-layout", 2, "data_tools capture fuse: error:", "cannot tell the capture's format",
     "name it with --format nerfstudio|polycam|depth")
def _(tmp, capsys):
    (tmp / "export").mkdir()
    (tmp / "export" / "readme.txt").write_text("not a capture")
    return run_cli(["capture", "fuse", tmp / "export", "--output", tmp / "cloud.ply"], capsys, entry=data_cli.main)


@row("capture-depth-units", 2, "data_tools capture fuse: error:", "1000000.png: frame 1000000's depth lies",
     "read at 1 m per unit", "all 12 frames do: are the units wrong? try --depth-scale 0.001")
def _(tmp, capsys):
    from data_tools.capture.phone_standin import plant_scene, write_standin  # only these rows render a capture

    folder = write_standin(tmp / "phone", "polycam", plant_scene("tomato", 0, size=0.4, frames=12), progress=False)
    return run_cli(["capture", "fuse", folder, "--output", tmp / "cloud.ply", "--depth-scale", "1"], capsys,
                   entry=data_cli.main)


def depth_capture(folder: Path, names=("000000", "000001", "000002"), depth_mm=500) -> Path:
    """A small hand-written depth-folder capture: 32 x 24 depth planes ``depth_mm`` away (16-bit
    PNG), poses 5 cm apart; the rows below fail before any fusion, so no rendered scene is needed."""
    from PIL import Image

    for sub in ("depth", "poses"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    (folder / "intrinsics.yaml").write_text("fx: 30\nfy: 30\ncx: 15.5\ncy: 11.5\nwidth: 32\nheight: 24\n")
    for i, name in enumerate(names):
        Image.fromarray(np.full((24, 32), depth_mm, dtype=np.uint16)).save(folder / "depth" / f"{name}.png")
        pose = np.eye(4)
        pose[0, 3] = 0.05 * i
        np.savetxt(folder / "poses" / f"{name}.txt", pose)
    return folder


def fuse_cli(folder: Path, tmp: Path, capsys, *more):
    return run_cli(["capture", "fuse", folder, "--output", tmp / "cloud.ply", *more], capsys, entry=data_cli.main)


@row("capture-depth-units-one-frame", 2, "data_tools capture fuse: error:", "000001.png: frame 000001's depth lies "
     "5 m away (its nearest tenth) read at 0.001 m per unit, outside the 0.1-1.5 m these settings fuse",
     "while 2 of the 3 frames lie within", "0.0001 m per unit would fit it", "remove the frame")
def _(tmp, capsys):
    from PIL import Image

    folder = depth_capture(tmp / "capture")
    Image.fromarray(np.full((24, 32), 5000, dtype=np.uint16)).save(folder / "depth" / "000001.png")  # 10x: 0.1 mm
    return fuse_cli(folder, tmp, capsys)


@row("capture-empty-depth-image", 2, "data_tools capture fuse: error:", "000002.npy: frame 000002's depth image is "
     "0 x 0 pixels (empty)", "export the frame again, or remove it")
def _(tmp, capsys):
    folder = depth_capture(tmp / "capture")
    (folder / "depth" / "000002.png").unlink()
    np.save(folder / "depth" / "000002.npy", np.zeros((0, 0)))
    return fuse_cli(folder, tmp, capsys)


@row("capture-one-frame", 2, "data_tools capture fuse: error:", "the capture holds 1 frame, and a surface is kept "
     "only where more than 1 frame saw it", "fusion needs at least 2 frames that overlap")
def _(tmp, capsys):
    return fuse_cli(depth_capture(tmp / "capture", names=("000000",)), tmp, capsys)


@row("capture-pose-not-finite", 2, "data_tools capture fuse: error:", "poses/000001.txt: frame 000001: line 2, "
     "number 4 is nan (its translation's y)", "a pose must be finite numbers")
def _(tmp, capsys):
    folder = depth_capture(tmp / "capture")
    pose = np.eye(4)
    pose[1, 3] = np.nan
    np.savetxt(folder / "poses" / "000001.txt", pose)
    return fuse_cli(folder, tmp, capsys)


@row("capture-frame-name", 2, "data_tools capture fuse: error:", "depth/frame 1.png: the frame name 'frame 1' holds "
     "a space", "a frame name is letters, digits, '.', '-' and '_'", "(no spaces or slashes); rename the frame's files")
def _(tmp, capsys):
    return fuse_cli(depth_capture(tmp / "capture", names=("000000", "frame 1")), tmp, capsys)


@row("export-not-rigid", 2, "tpvp export: error:", "base.json", "not a rigid transform")
def _(tmp, capsys):
    plan_folder(tmp)
    (tmp / "base.json").write_text(json.dumps(np.diag([2.0, 2.0, 2.0, 1.0]).tolist()))
    return run_cli(["export", "ros2", tmp / "run", "--base-from-scan", tmp / "base.json", "--output", tmp / "bag"],
                   capsys)


@row("organ-targets-malformed", 2, "tpvp plan: error: selection.organ_targets: 'fruit=1.5' is not ORGAN=SHARE",
     "SHARE in [0, 1]")
def _(tmp, scans, capsys):
    return run_cli(plan(scans / "day1.xyz", scans / "day2.xyz", "--organ-targets", "fruit=1.5", output=tmp / "out"),
                   capsys)


@row("organ-targets-without-labels", 2, "tpvp plan: error: organ targets (fruit, leaf) need the previous model's "
     "organ labels", "day1.xyz has none", "--labels organ|pheno4d")
def _(tmp, scans, capsys):
    return run_cli(plan(scans / "day1.xyz", scans / "day2.xyz", "--organ-targets", "fruit=1.0,leaf=0.95",
                        output=tmp / "out"), capsys)


@row("helios-unknown-species", 2, "data_tools helios: error: unknown species 'tomatoe'", "offers", "tomato")
def _(tmp, capsys):
    if importlib.util.find_spec("pyhelios") is None:
        pytest.skip("pyhelios3d is not installed (environment.txt)")
    return run_cli(["helios", "--species", "tomatoe", "--ages", "30", "--output", tmp / "helios"], capsys,
                   entry=data_cli.main)


# --------------------------------------------------------------------------------------------------
# a real session (tpvp session ...)


def session(tmp, scans, capsys, *more) -> Path:
    """A session started on day1.xyz (millimetres) in ``tmp/session``."""
    folder = tmp / "session"
    assert run_cli(["session", "start", "--previous", scans / "day1.xyz", *more, "--output", folder], capsys)[0] == 0
    return folder


def capture_with_nan(tmp, scans) -> Path:
    """Today's scan as a capture (millimetres, the world frame) with 3 NaN rows, as a camera writes them."""
    pts = np.loadtxt(scans / "day2.xyz")
    pts[[0, 5, 9]] = np.nan
    np.savetxt(tmp / "capture.xyz", pts)
    return tmp / "capture.xyz"


@row("session-nan-capture", 2, "capture.xyz: 3 of 12,500 points have NaN/inf coordinates (first at point 1)",
     "tpvp session add: error: ", "pass --drop-invalid (tpvp plan, tpvp session start/add)")
def _(tmp, scans, capsys):
    folder = session(tmp, scans, capsys)
    return run_cli(["session", "add", folder, "--cloud", capture_with_nan(tmp, scans)], capsys)


@row("session-drop-invalid", 0, "tpvp: warning: ", "capture.xyz: dropped 3 of 12,500 points with NaN/inf coordinates")
def _(tmp, scans, capsys):
    folder = session(tmp, scans, capsys)
    return run_cli(["session", "add", folder, "--cloud", capture_with_nan(tmp, scans), "--drop-invalid"], capsys)


@row("session-plant-over-5-m", 0, "tpvp: warning: ", "day1.xyz: read as metres (--units m) the plant spans 46.2 m",
     "give --units mm")
def _(tmp, scans, capsys):
    return run_cli(["session", "start", "--previous", scans / "day1.xyz", "--units", "m", "--output",
                    tmp / "session"], capsys)


@row("depth-png-8-bit", 2, "depth.png: an 8-bit PNG cannot hold depth (256 levels)",
     "depth must be a 16-bit PNG in millimetres, or a .npy in metres")
def _(tmp, scans, capsys):
    from PIL import Image

    folder = session(tmp, scans, capsys)
    Image.fromarray(np.full((720, 1280), 200, dtype=np.uint8)).save(tmp / "depth.png")
    return run_cli(["session", "add", folder, "--depth", tmp / "depth.png"], capsys)


@row("depth-complex", 2, "depth.npy: the depth image holds complex numbers (complex128)", "depth must be real numbers")
def _(tmp, scans, capsys):
    folder = session(tmp, scans, capsys)
    np.save(tmp / "depth.npy", np.full((720, 1280), 0.4 + 0.1j))
    return run_cli(["session", "add", folder, "--depth", tmp / "depth.npy"], capsys)


@row("intrinsics-not-finite", 2, "intrinsics.json: fx = NaN, cy = inf: the intrinsics must be finite numbers")
def _(tmp, scans, capsys):
    folder = session(tmp, scans, capsys)
    np.save(tmp / "depth.npy", np.full((720, 1280), 0.4))
    (tmp / "intrinsics.json").write_text('{"fx": NaN, "fy": 640, "cx": 640, "cy": "inf", "width": 1280, '
                                         '"height": 720}')
    return run_cli(["session", "add", folder, "--depth", tmp / "depth.npy", "--intrinsics", tmp / "intrinsics.json"],
                   capsys)


@row("pose-file-missing", 2, "--pose poses/view3.json: no such file", "a pose file, or a candidate view's index or name")
def _(tmp, scans, capsys):
    folder = session(tmp, scans, capsys)
    return run_cli(["session", "add", folder, "--cloud", scans / "day2.xyz", "--pose", "poses/view3.json"], capsys)


@row("session-busy", 3, "tpvp session add: error: session folder", "is being written by another run",
     "run this command again when that one has finished (--wait SECONDS waits longer)")
def _(tmp, scans, capsys):
    import fcntl

    folder = session(tmp, scans, capsys)
    with open(tmp / ".session.tpvp-lock", "w") as lock:  # what another running `tpvp session` step holds
        fcntl.flock(lock, fcntl.LOCK_EX)
        return run_cli(["session", "add", folder, "--cloud", scans / "day2.xyz", "--wait", "0"], capsys)


@row("session-damaged", 2, "tpvp session add: error: ", "captures/000.npy (capture 1, view 17) is missing (deleted?)",
     "`tpvp session check", "--repair` will drop capture 1 (view 17)")
def _(tmp, scans, capsys):
    folder = session(tmp, scans, capsys)
    assert run_cli(["session", "add", folder, "--cloud", scans / "day2.xyz"], capsys)[0] == 0
    (folder / "captures" / "000.npy").unlink()
    return run_cli(["session", "add", folder, "--cloud", scans / "day2.xyz", "--pose", "3"], capsys)


@row("session-prediction-damaged", 2, "tpvp session plan: error: ", "plan/prediction.npz is damaged (truncated?",
     "`tpvp session check", "--repair` will drop the plan (run `tpvp session plan` again)")
def _(tmp, scans, capsys):
    # the audit's case: a planned view captured, then the prediction its re-plan reads damaged
    folder = session(tmp, scans, capsys)
    for _ in range(2):  # the initial view and the warm-up NBV
        assert run_cli(["session", "add", folder, "--cloud", scans / "day2.xyz"], capsys)[0] == 0
    assert run_cli(["session", "plan", folder], capsys)[0] == 0
    assert run_cli(["session", "add", folder, "--cloud", scans / "day2.xyz"], capsys)[0] == 0
    prediction = folder / "plan" / "prediction.npz"
    prediction.write_bytes(prediction.read_bytes()[:100])
    code, out, err = run_cli(["session", "check", folder], capsys)
    assert code == 2 and "problem: " in out and "prediction.npz is damaged" in out, (out, err)
    return run_cli(["session", "plan", folder], capsys)


@row("plan-csv-not-a-number", 2, "tpvp export: error: ", "plan.csv: line 4, column 'qx': '0.12.3' is not a number",
     "correct it, or write the plan again")
def _(tmp, capsys):
    plan = plan_folder(tmp) / "plan.csv"
    lines = plan.read_text().splitlines()
    lines[3] = ",".join("0.12.3" if i == 8 else value for i, value in enumerate(lines[3].split(",")))
    plan.write_text("\n".join(lines) + "\n")
    return run_cli(["export", "moveit", plan.parent, "--output", tmp / "goals.yaml"], capsys)


@row("organ-targets-twice", 2, "tpvp plan: error: selection.organ_targets: 'fruit' is given twice (fruit=1.0, "
     "fruit=0.9)", "give each organ one share")
def _(tmp, scans, capsys):
    return run_cli(plan(scans / "day1.xyz", scans / "day2.xyz", "--organ-targets", "fruit=1.0,fruit=0.9",
                        output=tmp / "out"), capsys)


@row("organ-targets-absent-organ", 2, "tpvp session plan: error: organ targets flower=1: ",
     "labelled.xyz has no flower point (its organs: stem ", " points, leaf ", "target an organ it has")
def _(tmp, scans, capsys):
    pts = points(scans)
    labels = np.where(pts[:, 2] < np.percentile(pts[:, 2], 20), 1, 2)  # Pheno4D's: 1 stem, 2+ leaves
    np.savetxt(tmp / "labelled.xyz", np.column_stack([pts, labels]), fmt="%.4f %.4f %.4f %d")
    folder = tmp / "session"
    assert run_cli(["session", "start", "--previous", tmp / "labelled.xyz", "--labels", "pheno4d", "--output", folder],
                   capsys)[0] == 0
    return run_cli(["session", "plan", folder, "--organ-targets", "flower=1.0"], capsys)


@row("session-interrupted-after-commit", 0, "tpvp session add: SIGINT received after capture 1 was recorded; the "
     "step is complete")
def _(tmp, scans, capsys):
    folder = session(tmp, scans, capsys)
    steps = 6  # the capture's two files and the state, the commit's two renames, the moment after it
    env = {"TPVP_FAULT": f"interrupt@{steps}"}
    code, out, err = run_subprocess(["session", "add", folder, "--cloud", scans / "day2.xyz"], cwd=tmp, env=env)
    assert "capture 1: view 17" in out and len(json.loads((folder / "session.json").read_text())["captures"]) == 1
    return code, out, err


# --------------------------------------------------------------------------------------------------


def _line_with(text: str, first: str) -> str:
    lines = [line for line in text.splitlines() if first in line]
    assert lines, f"no line holds {first!r}:\n{text}"
    return lines[-1]


@pytest.mark.parametrize("test_id", sorted(ROWS))
def test_message(test_id, tmp_path, scans, capsys, monkeypatch, request):
    func, exit_status, expected, stream = ROWS[test_id]
    wanted = {"tmp": tmp_path, "scans": scans, "capsys": capsys, "monkeypatch": monkeypatch}
    names = func.__code__.co_varnames[:func.__code__.co_argcount]
    if "metres_run" in names:
        wanted["metres_run"] = request.getfixturevalue("metres_run")
    code, out, err = func(**{name: wanted[name] for name in names})
    text = out if stream == "out" else err
    assert code == exit_status, f"exit status {code}, not {exit_status}:\n{out}\n{err}"
    # stderr: one-line warnings, then (on failure) exactly one error line; argparse puts its usage first.
    lines = err.strip().splitlines()
    if lines and lines[0].startswith("usage:"):
        lines = [line for line in lines if not line.startswith(("usage:", " "))]
    prog = "data_tools" if test_id in DATA_TOOLS_ROWS else "tpvp"
    assert all(line.startswith((f"{prog}: warning: ", f"{prog} ", f"{prog}: interrupted")) for line in lines), err
    assert sum(": error: " in line for line in lines) == (exit_status in (1, 2, 3, 4)), err
    assert sum(": interrupted" in line for line in lines) == (exit_status == 130), err
    assert "Traceback" not in err and "Warning:" not in err and ".py:" not in err, err
    line = _line_with(text, expected[0])
    for part in expected:
        if part.startswith("re:"):
            assert re.search(part[3:], line), f"{part[3:]!r} does not match {line!r}"
        else:
            assert part in line, f"{part!r} not in {line!r}"


def test_every_row_of_the_table_has_a_test():
    ids = re.findall(r"^\|.*\|\s*`([a-z0-9-]+)`\s*\|\s*$", DOC.read_text(encoding="utf-8"), flags=re.M)
    assert ids, "no table rows with a test id in docs/messages.md"
    assert len(ids) == len(set(ids)), sorted(i for i in ids if ids.count(i) > 1)
    assert set(ids) == set(ROWS), f"rows without a test: {sorted(set(ids) - set(ROWS))}; " \
                                  f"tests without a row: {sorted(set(ROWS) - set(ids))}"


def test_a_python_warning_is_one_line_naming_the_program(capsys):
    with warnings.catch_warnings():  # restores warnings.showwarning and the filters afterwards
        warnings.simplefilter("always")
        install_warning_format("prog")
        warnings.warn("first line\nsecond line", RuntimeWarning)
    assert capsys.readouterr().err == "prog: warning: first line second line\n"


@pytest.mark.parametrize("units", ["auto", "m", "mm"])
def test_absurd_coordinates_are_refused_without_a_numpy_warning(units):
    from tpvp.errors import PointCloudError
    from tpvp.io.units import to_metres

    pts = np.random.default_rng(2).normal(size=(200, 3)) * 50
    pts[[3, 4]] = [[1e308, 0, 0], [-1e308, 0, 0]]  # max - min overflows float64
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning (overflow) would fail here
        with pytest.raises(PointCloudError, match=r"2 of 200 points have absurd coordinates \(first: x = 1e\+308 "
                                                  r"at point index 3"):
            to_metres(pts, units, source="scan.xyz")
        pts[[3, 4]] = [[0, 3e6, 0], [0, 0, 0]]  # in range, but 3 km away in mm: a stray point
        with pytest.raises(PointCloudError, match=r"scan.xyz: 1 of 200 points lies far from all the others "
                                                  r"\(y = 3e\+06 at point index 3"):
            to_metres(pts, "mm", source="scan.xyz")
