"""Hostile inputs for the point-cloud reader: every one must end in ONE clear error line.

Each case builds a bad file in tmp_path. ``read_point_cloud`` must raise the listed
:class:`~tpvp.errors.TpvpError` subclass with a one-line message that names the file (and says
what is wrong), without hanging or allocating gigabytes; ``tpvp plan --previous BAD --current
GOOD`` must exit with status 2 and one stderr line naming the file, no traceback.

Cases by class: non-regular files (directories, FIFOs, sockets, devices, also behind symlinks),
symlinks and path problems, PCD headers, PLY sizes (declared vs present), NaN/inf, and other
malformed files (truncated headers, garbage, UTF-16, huge declared counts, ...).
"""

from __future__ import annotations

import gzip
import os
import socket
import sys
import threading
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from tpvp.errors import InputFileError, PointCloudError, TpvpError
from tpvp.io import read_point_cloud

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux device files")
TIMEOUT = 20.0
#: A reader must notice a bad declared size before allocating this much (tracemalloc peak).
MEMORY_LIMIT = 200e6


# --------------------------------------------------------------------------------------------
# helpers


def call_with_timeout(func, *args, timeout=TIMEOUT, unblock=None, **kwargs):
    """Run ``func`` in a daemon thread; return ``(result, exception)``. A call that does not end
    within ``timeout`` fails the test (``unblock()`` is then called to free the blocked thread)."""
    box = {}

    def target():
        try:
            box["result"] = func(*args, **kwargs)
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            box["exc"] = exc

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    thread.join(timeout)
    if thread.is_alive():
        if unblock is not None:
            unblock()
        pytest.fail(f"{getattr(func, '__name__', func)} did not return within {timeout} s (blocked?)")
    return box.get("result"), box.get("exc")


def unblock_fifo(path: Path):
    """Open the write end of a FIFO (without blocking) and close it: a blocked reader sees EOF."""
    def unblock():
        try:
            fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
        except OSError:
            return
        os.close(fd)
    return unblock


def assert_one_line_error(exc, exc_type, path, match=None):
    assert exc is not None, f"{path}: no error raised (silently accepted)"
    assert isinstance(exc, exc_type), f"{type(exc).__name__}: {exc}"
    msg = str(exc)
    assert str(path) in msg, msg
    assert "\n" not in msg and "\r" not in msg, msg
    if match is not None:
        for m in [match] if isinstance(match, str) else match:
            assert m in msg, f"{m!r} not in {msg!r}"
    return msg


def pcd(fields="x y z", size="4 4 4", type_="F F F", count="1 1 1", width="3", height="1",
        points="3", data="ascii", body=b"0 0 0\n0.01 0 0\n0 0.01 0.02\n") -> bytes:
    """A PCD file; None leaves a header line out. FIELDS is line 3, SIZE 4, TYPE 5, COUNT 6."""
    lines = ["# .PCD v0.7 - Point Cloud Data file format", "VERSION 0.7"]
    for key, val in (("FIELDS", fields), ("SIZE", size), ("TYPE", type_), ("COUNT", count),
                     ("WIDTH", width), ("HEIGHT", height), ("VIEWPOINT", "0 0 0 1 0 0 0"),
                     ("POINTS", points), ("DATA", data)):
        if val is not None:
            lines.append(f"{key} {val}".rstrip())
    return ("\n".join(lines) + "\n").encode() + body


def ply_header(fmt, n, props=("float x", "float y", "float z"), before=(), after=()) -> bytes:
    hdr = ["ply", f"format {fmt} 1.0", *before, f"element vertex {n}",
           *(f"property {p}" for p in props), *after, "end_header"]
    return ("\n".join(hdr) + "\n").encode()


def small_points(n=50, seed=1):
    return np.random.default_rng(seed).uniform(0.0, 0.05, size=(n, 3))


def binary_ply(n_declared, pts, fmt="binary_little_endian", after=(), tail=b""):
    endian = "<" if fmt == "binary_little_endian" else ">"
    return ply_header(fmt, n_declared, after=after) + pts.astype(endian + "f4").tobytes() + tail


def ascii_ply(n_declared, pts, after=(), tail=""):
    rows = "".join(f"{x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in pts)
    return ply_header("ascii", n_declared, after=after) + (rows + tail).encode()


FACE_HEADER = ("element face 2", "property list uchar int vertex_indices")


def faces_binary(endian="<", rows=2):
    rec = np.zeros(rows, dtype=[("n", "u1"), ("i", endian + "i4", (3,))])
    rec["n"], rec["i"] = 3, [0, 1, 2]
    return rec.tobytes()


# --------------------------------------------------------------------------------------------
# the cases: builder(tmp_path) -> path of the bad file

CASES = []


def case(id, exc=InputFileError, match=None, *, cli=True, memory=False, marks=()):
    """Register a builder; ``match``: substring(s) the message must hold; ``memory``: also check
    that reading it does not allocate more than MEMORY_LIMIT."""
    def deco(build):
        CASES.append(pytest.param(build, exc, match, cli, memory, id=id, marks=marks))
        return build
    return deco


# ---- non-regular files


@case("dir", match="is a directory")
def _(tmp):
    p = tmp / "scan.ply"
    p.mkdir()
    return p


@case("dir-gz", match="is a directory")
def _(tmp):
    p = tmp / "scan.xyz.gz"
    p.mkdir()
    return p


@case("symlink-to-dir", match=["is a directory", "symlink"])
def _(tmp):
    (tmp / "folder").mkdir()
    p = tmp / "scan.pcd"
    p.symlink_to(tmp / "folder")
    return p


@case("socket", match="is a socket, not a file")
def _(tmp):
    p = tmp / "scan.pcd"
    cwd = os.getcwd()
    os.chdir(tmp)  # AF_UNIX names are limited to ~108 bytes; bind a relative name
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            s.bind(p.name)
    finally:
        os.chdir(cwd)
    return p


@case("dev-zero", match="is a character device, not a file", marks=linux_only)
def _(tmp):
    return Path("/dev/zero")


@case("devlink-zero-ply", match=["is a character device, not a file", "/dev/zero"],
      marks=linux_only)
def _(tmp):
    p = tmp / "zero.ply"
    p.symlink_to("/dev/zero")
    return p


@case("devlink-urandom-xyz", match=["is a character device", "/dev/urandom"], marks=linux_only)
def _(tmp):
    p = tmp / "noise.xyz"
    p.symlink_to("/dev/urandom")
    return p


@case("devlink-null-gz", match="is a character device", marks=linux_only)
def _(tmp):
    p = tmp / "null.ply.gz"
    p.symlink_to("/dev/null")
    return p


@case("devlink-zero-obj", match="is a character device", marks=linux_only)
def _(tmp):
    p = tmp / "zero.obj"
    p.symlink_to("/dev/zero")
    return p


# ---- symlinks and path problems


@case("symlink-loop", match="symlink loop")
def _(tmp):
    a, b = tmp / "a.ply", tmp / "b.ply"
    a.symlink_to(b)
    b.symlink_to(a)
    return a


@case("symlink-self-loop", match="symlink loop")
def _(tmp):
    a = tmp / "self.xyz"
    a.symlink_to(a)
    return a


@case("symlink-dangling", match=["broken symlink", "gone.ply"])
def _(tmp):
    a = tmp / "scan.ply"
    a.symlink_to(tmp / "gone.ply")
    return a


@case("symlink-dangling-chain", match="broken symlink")
def _(tmp):
    a, b = tmp / "scan.ply", tmp / "middle.ply"
    b.symlink_to(tmp / "gone.ply")
    a.symlink_to(b)
    return a


@case("missing-folder", match="not found")
def _(tmp):
    return tmp / "no_such_folder" / "scan.ply"


@case("file-as-folder", match=["not found", "not a folder"])
def _(tmp):
    (tmp / "plain.ply").write_bytes(b"ply\n")
    return tmp / "plain.ply" / "scan.ply"


@case("name-too-long", match="too long", cli=False)
def _(tmp):
    return tmp / ("a" * 300 + ".ply")


# ---- PCD headers: name the line that disagrees


@case("pcd-fields-4-others-3", match=["FIELDS", "line 3", "4", "SIZE", "TYPE", "COUNT"])
def _(tmp):
    p = tmp / "fields.pcd"
    p.write_bytes(pcd(fields="x y z w"))
    return p


@case("pcd-size-2", match=["SIZE (line 4) lists 2"])
def _(tmp):
    p = tmp / "size.pcd"
    p.write_bytes(pcd(size="4 4"))
    return p


@case("pcd-type-4", match=["TYPE (line 5) lists 4"])
def _(tmp):
    p = tmp / "type.pcd"
    p.write_bytes(pcd(type_="F F F F"))
    return p


@case("pcd-count-2", match=["COUNT (line 6) lists 2"])
def _(tmp):
    p = tmp / "count.pcd"
    p.write_bytes(pcd(count="1 1"))
    return p


@case("pcd-fields-4-no-count", match=["FIELDS (line 3) lists 4"])
def _(tmp):
    p = tmp / "fields_nocount.pcd"
    p.write_bytes(pcd(fields="x y z w", count=None))
    return p


@case("pcd-all-differ", match=["disagree", "FIELDS (line 3)", "SIZE (line 4)", "TYPE (line 5)"])
def _(tmp):
    p = tmp / "all.pcd"
    p.write_bytes(pcd(fields="x y z w", size="4 4", count=None))
    return p


@case("pcd-size-not-a-number", match=["line 4", "SIZE"])
def _(tmp):
    p = tmp / "sizeword.pcd"
    p.write_bytes(pcd(size="4 4 four"))
    return p


@case("pcd-fields-empty", match=["line 3", "FIELDS"])
def _(tmp):
    p = tmp / "nofields.pcd"
    p.write_bytes(pcd(fields=""))
    return p


@case("pcd-no-type", match="no TYPE line")
def _(tmp):
    p = tmp / "notype.pcd"
    p.write_bytes(pcd(type_=None))
    return p


@case("pcd-fields-twice", match=["FIELDS", "twice"])
def _(tmp):
    p = tmp / "twice.pcd"
    p.write_bytes(pcd().replace(b"SIZE", b"FIELDS x y z\nSIZE"))
    return p


@case("pcd-unknown-type", match=["unknown PCD type", "line 5"])
def _(tmp):
    p = tmp / "qtype.pcd"
    p.write_bytes(pcd(type_="F Q F"))
    return p


@case("pcd-huge-count-field", match="COUNT", memory=True)
def _(tmp):
    p = tmp / "hugecount.pcd"
    p.write_bytes(pcd(fields="x y z w", size="4 4 4 4", type_="F F F F",
                      count="1 1 1 99999999999", width="1", points="1", data="binary",
                      body=b"\0" * 16))
    return p


@case("pcd-width-word", match=["WIDTH", "line 7"])
def _(tmp):
    p = tmp / "width.pcd"
    p.write_bytes(pcd(width="three"))
    return p


@case("pcd-huge-points-binary", match="truncated", memory=True)
def _(tmp):
    p = tmp / "huge.pcd"
    p.write_bytes(pcd(width="99999999999", points="99999999999", data="binary",
                      body=b"\0" * 36))
    return p


@case("pcd-huge-points-ascii", match="truncated", memory=True)
def _(tmp):
    p = tmp / "hugea.pcd"
    p.write_bytes(pcd(width="99999999999", points="99999999999"))
    return p


@case("pcd-compressed-bomb", match="compressed", memory=True)
def _(tmp):
    # 300 million points (3.6 GB unpacked) claimed from a 10-byte LZF block
    n = 300_000_000
    body = np.array([10, 12 * n], "<u4").tobytes() + b"\0" * 10
    p = tmp / "bomb.pcd"
    p.write_bytes(pcd(width=str(n), points=str(n), data="binary_compressed", body=body))
    return p


@case("pcd-header-only", match="truncated")
def _(tmp):
    p = tmp / "hdronly.pcd"
    p.write_bytes(pcd(body=b""))
    return p


@case("pcd-extra-rows-binary", match=["declares 3 points", "more bytes"])
def _(tmp):
    p = tmp / "extra.pcd"
    p.write_bytes(pcd(data="binary", body=small_points(5).astype("<f4").tobytes()))
    return p


# ---- PLY: declared sizes vs what the file holds


@case("ply-ascii-extra-vertices", match=["declares 40 vertices", "50"])
def _(tmp):
    p = tmp / "extra_ascii.ply"
    p.write_bytes(ascii_ply(40, small_points(50)))
    return p


@case("ply-ascii-extra-after-faces", match=["declares", "2 more"])
def _(tmp):
    p = tmp / "extra_faces.ply"
    p.write_bytes(ascii_ply(50, small_points(50), after=FACE_HEADER,
                            tail="3 0 1 2\n3 2 3 0\n3 4 5 6\n3 7 8 9\n"))
    return p


@case("ply-ascii-truncated", match="truncated")
def _(tmp):
    p = tmp / "short_ascii.ply"
    p.write_bytes(ascii_ply(60, small_points(50)))
    return p


@case("ply-ascii-truncated-faces", match=["truncated", "face"])
def _(tmp):
    p = tmp / "short_faces.ply"
    p.write_bytes(ascii_ply(50, small_points(50), after=FACE_HEADER, tail="3 0 1 2\n"))
    return p


@case("ply-binary-extra-vertices", match=["declares 40 vertices", "480 bytes", "120 more bytes"])
def _(tmp):
    p = tmp / "extra_bin.ply"
    p.write_bytes(binary_ply(40, small_points(50)))
    return p


@case("ply-binary-trailing-garbage", match=["5 more bytes"])
def _(tmp):
    p = tmp / "garbage_tail.ply"
    p.write_bytes(binary_ply(50, small_points(50), tail=b"JUNK!"))
    return p


@case("ply-binary-extra-after-faces", match=["more bytes", "face"])
def _(tmp):
    p = tmp / "extra_bin_faces.ply"
    p.write_bytes(binary_ply(50, small_points(50), after=FACE_HEADER,
                             tail=faces_binary(rows=3)))
    return p


@case("ply-binary-big-endian-extra", match=["declares 40 vertices"])
def _(tmp):
    p = tmp / "extra_be.ply"
    p.write_bytes(binary_ply(40, small_points(50), fmt="binary_big_endian"))
    return p


@case("ply-binary-truncated", match="truncated")
def _(tmp):
    p = tmp / "short_bin.ply"
    p.write_bytes(binary_ply(60, small_points(50)))
    return p


@case("ply-binary-truncated-faces", match=["truncated", "face"])
def _(tmp):
    p = tmp / "short_bin_faces.ply"
    p.write_bytes(binary_ply(50, small_points(50), after=FACE_HEADER, tail=faces_binary()[:7]))
    return p


@case("ply-huge-vertex-count-binary", match="truncated", memory=True)
def _(tmp):
    p = tmp / "huge_bin.ply"
    p.write_bytes(binary_ply(99999999999, small_points(3)))
    return p


@case("ply-huge-vertex-count-ascii", match="truncated", memory=True)
def _(tmp):
    p = tmp / "huge_ascii.ply"
    p.write_bytes(ascii_ply(99999999999, small_points(3)))
    return p


@case("ply-huge-face-count-before", match="truncated", memory=True)
def _(tmp):
    p = tmp / "huge_faces.ply"
    p.write_bytes(ply_header("binary_little_endian", 3, before=(
        "element face 99999999999", "property list uchar int vertex_indices"))
        + faces_binary() + small_points(3).astype("<f4").tobytes())
    return p


@case("ply-huge-list-length", match="truncated", memory=True)
def _(tmp):
    # the first row's list claims 4 billion doubles
    p = tmp / "huge_list.ply"
    p.write_bytes(ply_header("binary_little_endian", 3,
                             props=("float x", "float y", "float z", "list uint double extra"))
                  + np.zeros(3, "<f4").tobytes() + np.array([4_000_000_000], "<u4").tobytes())
    return p


@case("ply-huge-list-length-faces-before", match="truncated", memory=True)
def _(tmp):
    p = tmp / "huge_list_faces.ply"
    p.write_bytes(ply_header("binary_little_endian", 3, before=(
        "element face 1", "property list uint double vertex_indices"))
        + np.array([4_000_000_000], "<u4").tobytes() + small_points(3).astype("<f4").tobytes())
    return p


# ---- NaN / inf


@case("nan-xyz", PointCloudError, match=["2 of 50 points", "NaN/inf", "first at point 5",
                                         "--drop-invalid", "drop_invalid=True"])
def _(tmp):
    pts = small_points(50)
    pts[4, 0] = np.nan
    pts[9, 2] = np.inf
    p = tmp / "nan.xyz"
    np.savetxt(p, pts)
    return p


@case("inf-ply", PointCloudError, match=["1 of 50 points", "--drop-invalid"])
def _(tmp):
    pts = small_points(50)
    pts[0, 1] = -np.inf
    p = tmp / "inf.ply"
    p.write_bytes(binary_ply(50, pts))
    return p


@case("nan-pcd-ascii", PointCloudError, match=["1 of 3 points", "--drop-invalid"])
def _(tmp):
    p = tmp / "nan.pcd"
    p.write_bytes(pcd(body=b"0 0 0\nnan 0 0\n0.01 0.02 0\n"))
    return p


@case("overflow-xyz", PointCloudError, match="NaN/inf")
def _(tmp):
    p = tmp / "overflow.xyz"
    p.write_text("0 0 0\n1e400 0 0\n0.01 0.02 0.03\n")
    return p


# ---- other malformed files


@case("empty-ply", match="empty file")
def _(tmp):
    p = tmp / "empty.ply"
    p.write_bytes(b"")
    return p


@case("zero-byte-gz", match="empty file")
def _(tmp):
    p = tmp / "empty.xyz.gz"
    p.write_bytes(b"")
    return p


@case("gz-of-nothing", match="empty file")
def _(tmp):
    p = tmp / "nothing.ply.gz"
    p.write_bytes(gzip.compress(b""))
    return p


@case("gz-garbage", match="not a valid gzip")
def _(tmp):
    p = tmp / "fake.pcd.gz"
    p.write_bytes(b"this is not gzip at all")
    return p


@case("gz-truncated", match="truncated gzip")
def _(tmp):
    p = tmp / "cut.xyz.gz"
    p.write_bytes(gzip.compress(b"0 0 0\n" * 1000)[:-20])
    return p


@case("binary-garbage-ply", match="not a PLY")
def _(tmp):
    p = tmp / "garbage.ply"
    p.write_bytes(np.random.default_rng(3).bytes(4096))
    return p


@case("ply-then-garbage", match="end_header")
def _(tmp):
    p = tmp / "ply_garbage.ply"
    p.write_bytes(b"ply\n" + np.random.default_rng(4).bytes(4096))
    return p


@case("ply-truncated-header", match="end_header")
def _(tmp):
    p = tmp / "cut_header.ply"
    p.write_bytes(b"ply\nformat ascii 1.0\nelement ver")
    return p


@case("ply-header-only", match="truncated")
def _(tmp):
    p = tmp / "header_only.ply"
    p.write_bytes(ply_header("binary_little_endian", 10))
    return p


@case("ply-bad-count", match="line 3")
def _(tmp):
    p = tmp / "badcount.ply"
    p.write_bytes(ply_header("ascii", "1e3") + b"0 0 0\n")
    return p


@case("pcd-binary-garbage", match="PCD")
def _(tmp):
    p = tmp / "garbage.pcd"
    p.write_bytes(np.random.default_rng(5).bytes(4096))
    return p


@case("utf16-xyz", match="UTF-16")
def _(tmp):
    p = tmp / "utf16.xyz"
    p.write_bytes("0 0 0\n0.01 0.02 0.03\n0.02 0 0.01\n".encode("utf-16"))
    return p


@case("utf16-xyz-no-bom", match="UTF-16")
def _(tmp):
    p = tmp / "utf16le.xyz"
    p.write_bytes("0 0 0\n0.01 0.02 0.03\n0.02 0 0.01\n".encode("utf-16-le"))
    return p


@case("utf16-ply", match="UTF-16")
def _(tmp):
    p = tmp / "utf16.ply"
    p.write_bytes(ascii_ply(3, small_points(3)).decode().encode("utf-16"))
    return p


@case("utf16-pcd", match="UTF-16")
def _(tmp):
    p = tmp / "utf16.pcd"
    p.write_bytes(pcd().decode().encode("utf-16"))
    return p


@case("xyz-2-columns", match="needs 3")
def _(tmp):
    p = tmp / "two.xyz"
    p.write_text("0 0\n0.01 0.02\n0.03 0.01\n")
    return p


@case("xyz-1-column-count", match="needs 3")
def _(tmp):
    p = tmp / "one.xyz"
    p.write_text("3\n0.1\n0.2\n0.3\n")
    return p


@case("xyz-ragged", match="line 3 has 2 columns")
def _(tmp):
    p = tmp / "ragged.xyz"
    p.write_text("0 0 0\n0.01 0.02 0.03\n0.02 0\n")
    return p


@case("xyz-huge-count-header", match="declares 99999999999 rows", memory=True)
def _(tmp):
    p = tmp / "count.pts"
    p.write_text("99999999999\n0 0 0\n0.01 0.02 0.03\n")
    return p


@case("xyz-names-only", PointCloudError, match="no points")
def _(tmp):
    p = tmp / "names.csv"
    p.write_text("x,y,z\n")
    return p


@case("xyz-binary", match="binary data")
def _(tmp):
    p = tmp / "bin.xyz"
    p.write_bytes(b"\x00\x01\x02\x03 junk")
    return p


@case("obj-garbage", match="cannot read mesh")
def _(tmp):
    p = tmp / "bad.obj"
    p.write_text("v 1 2\nf 1 2 3\nxx\n")
    return p


@case("off-huge-count", match="cannot read mesh", memory=True)
def _(tmp):
    p = tmp / "huge.off"
    p.write_text("OFF\n99999999999 1 0\n0 0 0\n")
    return p


@case("stl-garbage", (InputFileError, PointCloudError), match="mesh")
def _(tmp):
    p = tmp / "garbage.stl"
    p.write_bytes(np.random.default_rng(6).bytes(300))
    return p


@case("unknown-extension", match="unknown point-cloud extension")
def _(tmp):
    p = tmp / "scan.las"
    p.write_bytes(b"LASF")
    return p


# --------------------------------------------------------------------------------------------
# the tests


@pytest.mark.parametrize("build, exc_type, match, cli, memory", CASES)
def test_read_point_cloud_refuses(tmp_path, build, exc_type, match, cli, memory):
    path = build(tmp_path)
    if memory:
        tracemalloc.start()
    try:
        _, exc = call_with_timeout(read_point_cloud, path)
        peak = tracemalloc.get_traced_memory()[1] if memory else 0
    finally:
        if memory:
            tracemalloc.stop()
    assert_one_line_error(exc, exc_type, path, match)
    assert peak < MEMORY_LIMIT, f"{path}: allocated {peak / 1e6:.0f} MB before refusing"


@pytest.fixture
def good_cloud(tmp_path):
    """2,000 random points in a 5 cm cube, saved as .xyz."""
    path = tmp_path / "good" / "good.xyz"
    path.parent.mkdir()
    np.savetxt(path, np.random.default_rng(0).uniform(0.0, 0.05, size=(2000, 3)))
    return path


def run_plan(previous, current, output):
    from tpvp.cli import main

    return main(["plan", "--previous", str(previous), "--current", str(current),
                 "--output", str(output)])


def assert_cli_refuses(capsys, code, path):
    out, err = capsys.readouterr()
    assert code == 2, (code, err)
    assert "Traceback" not in err and "Traceback" not in out, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert str(path) in lines[0], err


@pytest.mark.parametrize("build, exc_type, match, cli, memory",
                         [c for c in CASES if c.values[3]])
def test_cli_plan_refuses(tmp_path, capsys, good_cloud, build, exc_type, match, cli, memory):
    bad = build(tmp_path)
    code, exc = call_with_timeout(run_plan, bad, good_cloud, tmp_path / "o")
    assert exc is None, f"{type(exc).__name__}: {exc}"
    assert_cli_refuses(capsys, code, bad)
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_cli_plan_refuses_bad_current(tmp_path, capsys, good_cloud):
    bad = tmp_path / "extra.ply"
    bad.write_bytes(binary_ply(40, small_points(50)))
    code, exc = call_with_timeout(run_plan, good_cloud, bad, tmp_path / "o")
    assert exc is None, exc
    assert_cli_refuses(capsys, code, bad)


# ---- FIFOs: must not block


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
@pytest.mark.parametrize("name", ["scan.ply", "scan.xyz.gz", "scan.pcd", "mesh.obj"])
def test_fifo_is_refused_without_blocking(tmp_path, name):
    fifo = tmp_path / name
    os.mkfifo(fifo)
    _, exc = call_with_timeout(read_point_cloud, fifo, unblock=unblock_fifo(fifo))
    assert_one_line_error(exc, InputFileError, fifo, "is a FIFO (named pipe), not a file")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_fifo_behind_symlink(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    link = tmp_path / "scan.xyz"
    link.symlink_to(fifo)
    _, exc = call_with_timeout(read_point_cloud, link, unblock=unblock_fifo(fifo))
    assert_one_line_error(exc, InputFileError, link, ["FIFO", str(fifo)])


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_fifo_cli(tmp_path, capsys, good_cloud):
    fifo = tmp_path / "scan.ply"
    os.mkfifo(fifo)
    code, exc = call_with_timeout(run_plan, fifo, good_cloud, tmp_path / "o",
                                  unblock=unblock_fifo(fifo))
    assert exc is None, exc
    assert_cli_refuses(capsys, code, fifo)


def test_fifo_text_table(tmp_path):
    from tpvp.io import read_text_table

    if not hasattr(os, "mkfifo"):
        pytest.skip("no FIFOs on this platform")
    fifo = tmp_path / "views.txt"
    os.mkfifo(fifo)
    _, exc = call_with_timeout(read_text_table, fifo, unblock=unblock_fifo(fifo))
    assert_one_line_error(exc, InputFileError, fifo, "FIFO")


# ---- permissions, NUL bytes


def test_permission_denied(tmp_path, monkeypatch, capsys, good_cloud):
    path = tmp_path / "secret.xyz"
    np.savetxt(path, small_points(20))
    if os.geteuid() != 0:
        path.chmod(0)
    else:  # root reads anything: simulate the refusal of the open call
        import tpvp.io.files as pc

        real_open = os.open

        def fake_open(p, flags, *args, **kwargs):
            if Path(p) == path:
                raise PermissionError(13, "Permission denied", str(p))
            return real_open(p, flags, *args, **kwargs)

        monkeypatch.setattr(pc.os, "open", fake_open)
    _, exc = call_with_timeout(read_point_cloud, path)
    assert_one_line_error(exc, InputFileError, path, "permission denied")
    code, exc = call_with_timeout(run_plan, path, good_cloud, tmp_path / "o")
    assert exc is None, exc
    assert_cli_refuses(capsys, code, path)


def test_nul_byte_in_path(tmp_path):
    _, exc = call_with_timeout(read_point_cloud, str(tmp_path / "a\0b.ply"))
    assert isinstance(exc, TpvpError), repr(exc)
    assert "NUL" in str(exc) and "\n" not in str(exc)


# ---- what must still be accepted


def test_trailing_newline_after_binary_ply_is_accepted(tmp_path):
    pts = small_points(50)
    path = tmp_path / "newline.ply"
    path.write_bytes(binary_ply(50, pts, tail=b"\n"))
    got = read_point_cloud(path, units="m")
    np.testing.assert_allclose(got, pts.astype("f4"))


def test_trailing_blank_lines_after_ascii_ply_are_accepted(tmp_path):
    pts = small_points(50)
    path = tmp_path / "blank.ply"
    path.write_bytes(ascii_ply(50, pts, tail="\n\n  \n"))
    np.testing.assert_allclose(read_point_cloud(path, units="m"), pts, atol=1e-6)


def test_faces_after_vertices_are_accepted(tmp_path):
    pts = small_points(50)
    for path, data in ((tmp_path / "fa.ply", ascii_ply(50, pts, after=FACE_HEADER,
                                                        tail="3 0 1 2\n4 2 3 0 1\n")),
                       (tmp_path / "fb.ply", binary_ply(50, pts, after=FACE_HEADER,
                                                         tail=faces_binary()))):
        path.write_bytes(data)
        assert read_point_cloud(path, units="m").shape == (50, 3)


def test_mixed_faces_after_vertices_binary(tmp_path):
    """Faces of varying length after the vertices are walked to check the file's size."""
    pts = small_points(50)
    rows = [np.array([3], "u1").tobytes() + np.array([0, 1, 2], "<i4").tobytes(),
            np.array([4], "u1").tobytes() + np.array([0, 1, 2, 3], "<i4").tobytes()] * 500
    header = ply_header("binary_little_endian", 50, after=("element face 1000",
                                                           "property list uchar int vertex_indices"))
    path = tmp_path / "mixed.ply"
    path.write_bytes(header + pts.astype("<f4").tobytes() + b"".join(rows))
    assert read_point_cloud(path, units="m").shape == (50, 3)
    path.write_bytes(header + pts.astype("<f4").tobytes() + b"".join(rows) + rows[0])
    _, exc = call_with_timeout(read_point_cloud, path)
    assert_one_line_error(exc, InputFileError, path, "more bytes")
    path.write_bytes(header + pts.astype("<f4").tobytes() + b"".join(rows[:-1]))
    _, exc = call_with_timeout(read_point_cloud, path)
    assert_one_line_error(exc, InputFileError, path, ["truncated", "face"])


def test_zero_size_element_is_accepted(tmp_path):
    """An element without properties takes no bytes: a huge count of it must not hang."""
    pts = small_points(5)
    path = tmp_path / "empty_element.ply"
    path.write_bytes(ply_header("binary_little_endian", 5, before=("element marker 99999999999",))
                     + pts.astype("<f4").tobytes())
    got, exc = call_with_timeout(read_point_cloud, path, units="m")
    assert exc is None, exc
    assert got.shape == (5, 3)


def test_utf8_bom_is_accepted(tmp_path):
    pts = small_points(5)
    for name, data in (("bom.ply", ascii_ply(5, pts)), ("bom.pcd", pcd()),
                       ("bom.xyz", "".join(f"{x} {y} {z}\n" for x, y, z in pts).encode())):
        path = tmp_path / name
        path.write_bytes(b"\xef\xbb\xbf" + data)
        assert read_point_cloud(path, units="m").shape[1] == 3


def test_symlink_to_good_file_is_accepted(tmp_path, good_cloud):
    link = tmp_path / "link.xyz"
    link.symlink_to(good_cloud)
    assert read_point_cloud(link).shape == (2000, 3)


def test_nan_can_be_dropped(tmp_path):
    path = tmp_path / "nan.xyz"
    pts = small_points(50)
    pts[4, 0] = np.nan
    np.savetxt(path, pts)
    with pytest.warns(UserWarning, match="dropped 1 of 50"):
        assert read_point_cloud(path, drop_invalid=True).shape == (49, 3)


def test_cases_cover_every_class():
    ids = [c.id for c in CASES]
    assert len(ids) == len(set(ids))
    for prefix in ("dir", "socket", "dev", "symlink", "pcd-", "ply-", "nan", "utf16", "gz"):
        assert any(i.startswith(prefix) for i in ids), prefix
    # FIFOs are tested apart, each call guarded by a timeout (a regression would block).
