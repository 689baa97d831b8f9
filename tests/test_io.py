"""Tests of tpvp.io: point-cloud readers/writers, units, text tables and atomic writes.

All test files are generated into pytest's tmp_path; the real Pheno4D samples under
../shared are used only when present.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from tpvp.errors import ConfigError, InputFileError, PointCloudError, TpvpError
from tpvp.io import (
    atomic_path,
    atomic_write_bytes,
    atomic_write_text,
    detect_units,
    read_point_cloud,
    read_text_table,
    to_metres,
    write_point_cloud,
)

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
if not SHARED.exists():
    SHARED = Path("/work/shared")
PHENO = SHARED / "data" / "pheno4d_samples"
CONFIG = SHARED / "data" / "tpvp_config"
PACKAGE_DATA = Path(__file__).resolve().parents[1] / "tpvp" / "data" / "greenhouse_row"


def need(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} not available (../shared is optional)")
    return path


@pytest.fixture
def cloud():
    """A plant-sized cloud in metres with integer labels."""
    rng = np.random.default_rng(0)
    pts = rng.uniform([-0.2, -0.2, 0.0], [0.2, 0.2, 0.6], size=(500, 3))
    labels = rng.integers(0, 5, size=500)
    return pts, labels


def raises_naming(exc_type, path, func, *args, match=None, **kwargs):
    """Assert ``func`` raises ``exc_type`` with a one-line message naming ``path``."""
    with pytest.raises(exc_type) as info:
        func(*args, **kwargs)
    msg = str(info.value)
    assert str(path) in msg, msg
    assert "\n" not in msg, msg
    if match is not None:
        assert match in msg, msg
    return msg


# ---------------------------------------------------------------------------------------------
# hand-made PLY files (independent of the writer under test)

FACES = np.array([[0, 1, 2], [2, 3, 0]])


def make_ply(path, fmt, pts, *, coord="float", extra=True, labels=None, faces_before=False,
             faces_after=False, comment=True):
    """Write a PLY by hand: x y z [nx ny nz red green blue] [label], optional face elements."""
    endian = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "<"}[fmt]
    ctype = {"float": "f4", "double": "f8", "int": "i4", "short": "i2"}[coord]
    fields = [(c, endian + ctype) for c in "xyz"]
    props = [f"property {coord} {c}" for c in "xyz"]
    if extra:
        fields += [(c, endian + "f4") for c in ("nx", "ny", "nz")]
        fields += [(c, "u1") for c in ("red", "green", "blue")]
        props += [f"property float {c}" for c in ("nx", "ny", "nz")]
        props += [f"property uchar {c}" for c in ("red", "green", "blue")]
    if labels is not None:
        fields.append(("label", endian + "i4"))
        props.append("property int label")
    rec = np.zeros(len(pts), dtype=fields)
    for j, c in enumerate("xyz"):
        rec[c] = pts[:, j]
    if extra:
        rec["nz"] = 1.0
        rec["red"] = 200
    if labels is not None:
        rec["label"] = labels
    face_hdr = ["element face 2", "property list uchar int vertex_indices"]
    hdr = ["ply", f"format {fmt} 1.0"] + (["comment hand made"] if comment else [])
    if faces_before:
        hdr += face_hdr
    hdr += [f"element vertex {len(pts)}"] + props
    if faces_after:
        hdr += face_hdr
    hdr.append("end_header")
    head = ("\n".join(hdr) + "\n").encode()
    frec = np.zeros(2, dtype=[("n", "u1"), ("i", endian + "i4", (3,))])
    frec["n"], frec["i"] = 3, FACES
    if fmt == "ascii":
        rows = "\n".join(" ".join(repr(v.item()) if isinstance(v, np.generic) else str(v)
                                  for v in r) for r in rec.tolist())
        vbody = (rows + "\n").encode()
        fbody = b"3 0 1 2\n3 2 3 0\n"
    else:
        vbody, fbody = rec.tobytes(), frec.tobytes()
    body = (fbody if faces_before else b"") + vbody + (fbody if faces_after else b"")
    Path(path).write_bytes(head + body)
    return rec


# ---------------------------------------------------------------------------------------------
# PLY


@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_ply_roundtrip(tmp_path, cloud, binary, dtype):
    pts, labels = cloud
    path = write_point_cloud(tmp_path / "c.ply", pts, labels, binary=binary, dtype=dtype)
    got, got_labels = read_point_cloud(path, units="m", return_labels=True)
    assert got.dtype == np.float64 and got.shape == pts.shape
    if dtype == "float64":
        np.testing.assert_array_equal(got, pts)
    else:
        np.testing.assert_array_equal(got, pts.astype(np.float32).astype(np.float64))
    np.testing.assert_array_equal(got_labels, labels)
    assert read_point_cloud(path, return_labels=True)[1] is not None
    assert (b"binary_little_endian" in path.read_bytes()[:100]) == binary


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("coord", ["float", "double", "int"])
@pytest.mark.parametrize("faces", ["none", "before", "after"])
def test_ply_hand_made_variants(tmp_path, cloud, fmt, coord, faces):
    pts, labels = cloud
    pts_mm = np.round(pts * 1000) if coord == "int" else pts * 1000
    path = tmp_path / "v.PLY"  # extension is case-insensitive
    rec = make_ply(path, fmt, pts_mm, coord=coord, labels=labels,
                   faces_before=faces == "before", faces_after=faces == "after")
    got, got_labels = read_point_cloud(path, units="mm", return_labels=True)
    expect = np.column_stack([rec["x"], rec["y"], rec["z"]]).astype(np.float64) * 1e-3
    np.testing.assert_allclose(got, expect, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(got_labels, labels)


def test_ply_without_labels_returns_none(tmp_path, cloud):
    path = tmp_path / "n.ply"
    make_ply(path, "binary_little_endian", cloud[0], extra=True)
    pts, labels = read_point_cloud(path, return_labels=True)
    assert labels is None and pts.shape == (500, 3)


def test_ply_mixed_faces_before_vertices(tmp_path, cloud):
    pts = cloud[0]
    # A triangle then a quad: variable-length lists before the vertex element.
    face = np.array([3], "u1").tobytes() + np.array([0, 1, 2], "<i4").tobytes() \
        + np.array([4], "u1").tobytes() + np.array([0, 1, 2, 3], "<i4").tobytes()
    head = ("ply\nformat binary_little_endian 1.0\nelement face 2\n"
            "property list uchar int vertex_indices\n"
            f"element vertex {len(pts)}\nproperty double x\nproperty double y\nproperty double z\n"
            "end_header\n").encode()
    path = tmp_path / "mixed.ply"
    path.write_bytes(head + face + pts.astype("<f8").tobytes())
    np.testing.assert_array_equal(read_point_cloud(path, units="m"), pts)


def test_ply_empty_list_element(tmp_path, cloud):
    pts = cloud[0]
    head = ("ply\nformat binary_big_endian 1.0\nelement face 0\n"
            "property list uchar int vertex_indices\n"
            f"element vertex {len(pts)}\nproperty double x\nproperty double y\nproperty double z\n"
            "element face2 0\nproperty list uchar int vertex_indices\nend_header\n").encode()
    path = tmp_path / "empty_faces.ply"
    path.write_bytes(head + pts.astype(">f8").tobytes())
    np.testing.assert_array_equal(read_point_cloud(path, units="m"), pts)


def test_ply_vertex_list_property(tmp_path, cloud):
    pts = cloud[0][:10]
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n"
            "property list uchar float feat\nproperty float y\nproperty float z\nend_header\n")
    rec = np.zeros(10, dtype=[("x", "<f4"), ("n", "u1"), ("f", "<f4", (2,)), ("y", "<f4"),
                              ("z", "<f4")])
    rec["x"], rec["y"], rec["z"], rec["n"] = pts[:, 0], pts[:, 1], pts[:, 2], 2
    path = tmp_path / "list.ply"
    path.write_bytes(head.encode() + rec.tobytes())
    np.testing.assert_allclose(read_point_cloud(path, units="m"), pts, atol=1e-7)
    # Same in ASCII.
    rows = "\n".join(f"{x} 2 0.5 0.5 {y} {z}" for x, y, z in pts.tolist())
    path_a = tmp_path / "list_a.ply"
    path_a.write_text(head.replace("binary_little_endian", "ascii") + rows + "\n")
    np.testing.assert_allclose(read_point_cloud(path_a, units="m"), pts, atol=1e-12)
    # Varying lengths inside the vertex element are rejected clearly.
    rec["n"][3] = 1
    path.write_bytes(head.encode() + rec.tobytes())
    raises_naming(InputFileError, path, read_point_cloud, path, match="varying")


# ---------------------------------------------------------------------------------------------
# PCD


@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_pcd_roundtrip(tmp_path, cloud, binary, dtype):
    pts, labels = cloud
    path = write_point_cloud(tmp_path / "c.pcd", pts, labels - 1, binary=binary, dtype=dtype)
    got, got_labels = read_point_cloud(path, return_labels=True)
    np.testing.assert_array_equal(got, pts.astype(dtype).astype(np.float64))
    np.testing.assert_array_equal(got_labels, labels - 1)


def test_pcd_padding_and_multi_count_fields(tmp_path, cloud):
    pts = cloud[0][:50]
    rec = np.zeros(50, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("_", "u1", (4,)),
                              ("rgb", "<f4"), ("hist", "<f4", (3,)), ("_2", "u1", (4,)),
                              ("label", "<u4")])
    rec["x"], rec["y"], rec["z"], rec["label"] = pts[:, 0], pts[:, 1], pts[:, 2], 7
    head = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z _ rgb hist _ label\nSIZE 4 4 4 1 4 4 1 4\n"
            "TYPE F F F U F F U U\nCOUNT 1 1 1 4 1 3 4 1\nWIDTH 50\nHEIGHT 1\n"
            "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 50\nDATA binary\n")
    path = tmp_path / "pad.pcd"
    path.write_bytes(head.encode() + rec.tobytes())
    got, labels = read_point_cloud(path, return_labels=True)
    np.testing.assert_array_equal(got, pts.astype(np.float32).astype(np.float64))
    assert (labels == 7).all()


def lzf_literals(raw: bytes) -> bytes:
    """A valid LZF stream made of literal runs only (32 bytes each)."""
    out = bytearray()
    for i in range(0, len(raw), 32):
        chunk = raw[i:i + 32]
        out.append(len(chunk) - 1)
        out += chunk
    return bytes(out)


def test_pcd_binary_compressed_literal(tmp_path, cloud):
    pts = cloud[0][:40].astype(np.float32)
    raw = b"".join(np.ascontiguousarray(pts[:, j]).tobytes() for j in range(3))
    comp = lzf_literals(raw)
    head = ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 40\n"
            "HEIGHT 1\nPOINTS 40\nDATA binary_compressed\n").encode()
    path = tmp_path / "lit.pcd"
    path.write_bytes(head + np.array([len(comp), len(raw)], "<u4").tobytes() + comp)
    np.testing.assert_array_equal(read_point_cloud(path), pts.astype(np.float64))
    # A corrupt stream is reported, not crashed on.
    path.write_bytes(head + np.array([len(comp), len(raw)], "<u4").tobytes() + b"\xff" * len(comp))
    raises_naming(InputFileError, path, read_point_cloud, path, match="LZF")


def test_pcd_binary_compressed_open3d(tmp_path):
    o3d = pytest.importorskip("open3d")
    rng = np.random.default_rng(1)
    # Repetitive values so that LZF emits back references.
    pts = np.round(rng.uniform(-0.5, 0.5, size=(3000, 3)), 2)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    path = tmp_path / "o3d.pcd"
    assert o3d.io.write_point_cloud(str(path), pcd, compressed=True)
    assert b"binary_compressed" in path.read_bytes()[:400]
    got = read_point_cloud(path)
    np.testing.assert_array_equal(got, np.asarray(o3d.io.read_point_cloud(str(path)).points))


def test_open3d_reads_our_files(tmp_path, cloud):
    o3d = pytest.importorskip("open3d")
    pts = cloud[0]
    for name, binary in [("a.ply", True), ("b.ply", False), ("c.pcd", True), ("d.pcd", False)]:
        path = write_point_cloud(tmp_path / name, pts, binary=binary)  # PCD: float32 default
        expect = read_point_cloud(path)
        assert np.abs(expect - pts).max() < (1e-7 if name.endswith(".pcd") else 1e-15)
        # open3d parses ASCII floats as doubles, we round them to the declared float32.
        np.testing.assert_allclose(np.asarray(o3d.io.read_point_cloud(str(path)).points),
                                   expect, rtol=0, atol=1e-9)


# ---------------------------------------------------------------------------------------------
# text


@pytest.mark.parametrize("ext", [".xyz", ".txt", ".pts", ".csv"])
@pytest.mark.parametrize("with_labels", [False, True])
def test_text_roundtrip(tmp_path, cloud, ext, with_labels):
    pts, labels = cloud
    lab = labels if with_labels else None
    path = write_point_cloud(tmp_path / f"c{ext}", pts, lab)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # 3 or 4 columns: nothing is ignored
        got, got_labels = read_point_cloud(path, return_labels=True)
    np.testing.assert_array_equal(got, pts)
    if with_labels:
        np.testing.assert_array_equal(got_labels, labels)
    else:
        assert got_labels is None


def test_text_pheno4d_layouts(tmp_path, cloud):
    pts, labels = cloud
    mm = pts * 1000 - [70, 750, 0]
    # Annotated Pheno4D with two more label columns (leaf collar / tip): 6 columns.
    table = np.column_stack([mm, labels, labels * 2, labels * 3])
    path = tmp_path / "M01_0313_a.txt"
    np.savetxt(path, table, fmt="%.8f")
    with pytest.warns(UserWarning, match=r"ignored column\(s\) 5, 6") as rec:
        got, got_labels = read_point_cloud(path, return_labels=True)
    assert str(path) in str(rec[0].message)
    np.testing.assert_allclose(got, mm / 1000, atol=1e-12)
    np.testing.assert_array_equal(got_labels, labels)
    # A non-integer 4th column (e.g. intensity) is not taken as labels.
    np.savetxt(path, np.column_stack([mm, np.linspace(0, 1, len(mm))]))
    with pytest.warns(UserWarning, match=r"ignored column\(s\) 4"):
        assert read_point_cloud(path, return_labels=True)[1] is None


def test_text_csv_with_header_and_comments(tmp_path, cloud):
    pts, labels = cloud
    path = tmp_path / "h.csv"
    rows = "\n".join(f"{l},{z!r},{x!r},{y!r}" for (x, y, z), l in zip(pts.tolist(), labels))
    path.write_text("# exported\nlabel,z,x,y\n" + rows + "\n")
    got, got_labels = read_point_cloud(path, return_labels=True)
    np.testing.assert_array_equal(got, pts)
    np.testing.assert_array_equal(got_labels, labels)
    cc = tmp_path / "cc.txt"  # CloudCompare style header, tab separated, CRLF
    cc.write_bytes(("//X\tY\tZ\r\n" + "\r\n".join("\t".join(map(repr, p)) for p in pts.tolist())
                    + "\r\n").encode())
    np.testing.assert_array_equal(read_point_cloud(cc), pts)


# ---------------------------------------------------------------------------------------------
# meshes


@pytest.mark.parametrize("ext", [".obj", ".stl", ".off", ".glb"])
def test_mesh_sampling(tmp_path, ext):
    trimesh = pytest.importorskip("trimesh")
    box = trimesh.creation.box(extents=[0.2, 0.3, 0.5])
    path = tmp_path / f"box{ext}"
    box.export(path)
    a = read_point_cloud(path, mesh_samples=2000)
    b = read_point_cloud(path, mesh_samples=2000)
    assert a.shape == (2000, 3)
    np.testing.assert_array_equal(a, b)  # seeded
    assert not np.array_equal(a, read_point_cloud(path, mesh_samples=2000, seed=1))
    # Every sample lies on the box surface.
    half = np.array([0.1, 0.15, 0.25])
    assert np.isclose(np.abs(a), half, atol=1e-7).any(axis=1).all()  # STL/GLB store float32
    assert (np.abs(a) <= half + 1e-7).all()


def test_mesh_bad_file(tmp_path):
    path = tmp_path / "bad.stl"
    path.write_bytes(b"solid x\n this is not an stl\n")
    with pytest.raises(TpvpError) as info:
        read_point_cloud(path)
    assert str(path) in str(info.value)


# ---------------------------------------------------------------------------------------------
# real Pheno4D samples


@pytest.mark.parametrize("name,count", [("tomato_0305.xyz", 24795), ("tomato_0306.xyz", 50000),
                                        ("maize_0313.ply", 338874)])
def test_pheno4d_samples(name, count):
    path = need(PHENO / name)
    pts = read_point_cloud(path)
    assert pts.shape == (count, 3) and pts.dtype == np.float64
    side = (pts.max(0) - pts.min(0)).max()
    assert 0.02 < side < 1.0  # a plant, in metres
    assert -0.8 < pts[:, 1].min() < -0.7  # the scanner frame puts y near -750 mm
    assert detect_units(read_point_cloud(path, units="mm") * 1000) == "mm"


def test_maize_matches_open3d():
    o3d = pytest.importorskip("open3d")
    path = need(PHENO / "maize_0313.ply")
    ref = np.asarray(o3d.io.read_point_cloud(str(path)).points)
    ours = read_point_cloud(path)
    assert ours.shape == ref.shape
    np.testing.assert_array_equal(ours, ref * 1e-3)


def test_shared_config_tables():
    hemi = read_text_table(need(CONFIG / "single_plant" / "view_space_hemisphere32.txt"), columns=3)
    assert hemi.shape == (32, 3)
    np.testing.assert_allclose(np.linalg.norm(hemi, axis=1), 0.4, atol=1e-3)
    assert read_text_table(CONFIG / "single_plant" / "view_space_sphere63.txt").shape == (63, 3)


def test_package_config_tables():
    root = PACKAGE_DATA if PACKAGE_DATA.exists() else need(CONFIG / "greenhouse_row")
    assert read_text_table(root / "room1_initial_views.txt", columns=6).shape == (15, 6)
    assert read_text_table(root / "room1_candidate_views.txt", columns=3).shape == (1000, 3)
    cost = read_text_table(root / "room1_passive_cost.txt")
    assert cost.shape == (1, 1) and 2.5 < cost.item() < 2.7
    look = read_text_table(root / "gap_1" / "room1_20250918_candidate_look_ats_PriorBBX.txt",
                           columns=3)
    assert look.shape == (1000, 3)


# ---------------------------------------------------------------------------------------------
# read_text_table


def test_text_table_count_header(tmp_path):
    path = tmp_path / "views.txt"
    path.write_text("3\n0 0 1\n0 1 0\n1 0 0\n")
    assert read_text_table(path).shape == (3, 3)
    assert read_text_table(path, count_header=True).shape == (3, 3)
    path.write_text("4\n0 0 1\n0 1 0\n1 0 0\n")
    raises_naming(InputFileError, path, read_text_table, path, match="declares 4 rows")
    raises_naming(InputFileError, path, read_text_table, path, columns=6, count_header=True,
                  match="declares 4")
    path.write_text("0 0 1\n0 1 0\n")
    raises_naming(InputFileError, path, read_text_table, path, count_header=True,
                  match="row count")
    raises_naming(InputFileError, path, read_text_table, path, columns=6, match="expected 6")
    # One column with a matching count line, and without one.
    path.write_text("3\n1.5\n2.5\n3.5\n")
    np.testing.assert_array_equal(read_text_table(path)[:, 0], [1.5, 2.5, 3.5])
    path.write_text("3\n1\n2\n")
    assert read_text_table(path).shape == (3, 1)
    assert read_text_table(path, count_header=False).shape == (3, 1)
    path.write_text("  # a comment\n\n2.59 # metres\n")
    assert read_text_table(path).item() == 2.59


def test_text_table_bad_input(tmp_path):
    path = tmp_path / "t.txt"
    path.write_text("1 2 3\n4 five 6\n")
    raises_naming(InputFileError, path, read_text_table, path, match="line 2")
    path.write_text("1 2 3\n4 5\n")
    raises_naming(InputFileError, path, read_text_table, path, match="line 2 has 2 columns")
    path.write_text("1 2 nan\n")
    raises_naming(InputFileError, path, read_text_table, path, match="NaN")
    path.write_text("\n\n# nothing\n")
    raises_naming(InputFileError, path, read_text_table, path, match="no data")
    with pytest.raises(ConfigError, match="count_header"):
        read_text_table(path, count_header="yes")
    with pytest.raises(ConfigError, match="columns"):
        read_text_table(path, columns=0)


# ---------------------------------------------------------------------------------------------
# units


def test_detect_units_both_ways():
    rng = np.random.default_rng(2)
    plant_mm = rng.uniform([-75, -760, 0], [-30, -720, 90], size=(100, 3))  # Pheno4D-like
    assert detect_units(plant_mm) == "mm"
    row_m = rng.uniform([0, -0.5, 0], [3.6, 0.5, 1.8], size=(100, 3))  # greenhouse row
    assert detect_units(row_m) == "m"
    # A 3.6 m row far from the origin stays metres (the reference |c| >= 10 rule would
    # convert it) and the ambiguity is reported.
    with pytest.warns(UserWarning, match="taken as metres"):
        assert detect_units(row_m + [8.0, 20.0, 0.0]) == "m"
    np.testing.assert_allclose(to_metres(plant_mm), plant_mm / 1000)
    np.testing.assert_array_equal(to_metres(row_m), row_m)
    np.testing.assert_allclose(to_metres(row_m * 1000, "mm"), row_m)


def test_implausible_units(tmp_path):
    rng = np.random.default_rng(3)
    big = rng.uniform(0, 700_000, size=(50, 3))  # 700 m even as millimetres
    big[0], big[1] = 0.0, 700_000.0
    path = tmp_path / "huge.xyz"
    np.savetxt(path, big)
    raises_naming(PointCloudError, path, read_point_cloud, path, match="wrong units")
    raises_naming(PointCloudError, path, read_point_cloud, path, units="mm", match="700 m")
    span700 = tmp_path / "plant_mm.xyz"
    np.savetxt(span700, np.vstack([rng.uniform(0, 700, size=(50, 3)), [0, 0, 0], [700, 0, 0]]))
    raises_naming(PointCloudError, span700, read_point_cloud, span700, units="m",
                  match="a 700 m plant")
    assert read_point_cloud(span700).max() < 0.71  # auto: millimetres
    metric = tmp_path / "metric.xyz"
    np.savetxt(metric, rng.uniform(0, 0.5, size=(50, 3)))
    raises_naming(PointCloudError, metric, read_point_cloud, metric, units="mm",
                  match="wrong units")
    with pytest.raises(ConfigError, match="units"):
        read_point_cloud(metric, units="cm")
    with pytest.raises(ConfigError, match="units"):
        to_metres(big, "inch")
    with pytest.raises(PointCloudError, match="wrong units"):
        to_metres(big, "m")


# ---------------------------------------------------------------------------------------------
# bad input files


def test_missing_unknown_empty(tmp_path):
    missing = tmp_path / "nope.ply"
    raises_naming(InputFileError, missing, read_point_cloud, missing, match="not found")
    raises_naming(InputFileError, missing, read_text_table, missing, match="not found")
    las = tmp_path / "scan.las"
    las.write_bytes(b"LASF")
    raises_naming(InputFileError, las, read_point_cloud, las, match="unknown point-cloud extension")
    for ext in (".ply", ".pcd", ".xyz", ".obj"):
        empty = tmp_path / f"empty{ext}"
        empty.write_bytes(b"")
        raises_naming(InputFileError, empty, read_point_cloud, empty, match="empty file")
    raises_naming(InputFileError, tmp_path, read_point_cloud, tmp_path / "")
    with pytest.raises(ConfigError):
        read_point_cloud(None)


def test_truncated_binary_ply(tmp_path, cloud):
    path = tmp_path / "t.ply"
    make_ply(path, "binary_little_endian", cloud[0], extra=False)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 12 * 100 - 5])
    raises_naming(InputFileError, path, read_point_cloud, path,
                  match="truncated: header declares 500 vertices, file holds 399")
    # Truncated inside a face element that precedes the vertices.
    make_ply(path, "binary_big_endian", cloud[0], extra=False, faces_before=True)
    head = path.read_bytes().split(b"end_header\n")[0] + b"end_header\n"
    path.write_bytes(head + b"\x03\x00\x00")
    raises_naming(InputFileError, path, read_point_cloud, path, match="truncated")


def test_truncated_ascii_ply(tmp_path, cloud):
    path = tmp_path / "t.ply"
    make_ply(path, "ascii", cloud[0], extra=False)
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:-10]))
    raises_naming(InputFileError, path, read_point_cloud, path,
                  match="header declares 500 vertices, file holds 490")
    # A partially written last line.
    path.write_text("".join(lines[:-1]) + lines[-1].split()[0] + "\n")
    raises_naming(InputFileError, path, read_point_cloud, path, match="columns")


def test_ply_header_errors(tmp_path, cloud):
    path = tmp_path / "h.ply"
    make_ply(path, "binary_little_endian", cloud[0], extra=False)
    data = path.read_bytes()
    path.write_bytes(data.replace(b"end_header\n", b""))
    raises_naming(InputFileError, path, read_point_cloud, path, match="end_header")
    make_ply(path, "ascii", cloud[0], extra=False)
    path.write_text(path.read_text().replace("end_header\n", ""))
    raises_naming(InputFileError, path, read_point_cloud, path, match="end_header")
    path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n")
    raises_naming(InputFileError, path, read_point_cloud, path, match="end_header")
    make_ply(path, "binary_little_endian", cloud[0], extra=False)
    path.write_bytes(data.replace(b"property float y", b"property float33 y"))
    raises_naming(InputFileError, path, read_point_cloud, path, match="unknown PLY property type")
    path.write_bytes(data.replace(b"binary_little_endian", b"binary_middle_endian"))
    raises_naming(InputFileError, path, read_point_cloud, path, match="format")
    path.write_bytes(data.replace(b"property float z", b"property float w"))
    raises_naming(InputFileError, path, read_point_cloud, path, match="no 'z' property")
    path.write_bytes(b"PK\x03\x04 not a ply")
    raises_naming(InputFileError, path, read_point_cloud, path, match="not a PLY")
    path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                     b"property float y\nproperty float z\nend_header\n")
    raises_naming(PointCloudError, path, read_point_cloud, path, match="no points")


def test_nan_coordinates(tmp_path, cloud):
    pts, labels = cloud
    bad = pts.copy()
    bad[[3, 10], 1] = np.nan
    bad[20, 2] = np.inf
    for name in ("n.ply", "n.pcd", "n.xyz"):
        path = tmp_path / name
        if name.endswith(".ply"):
            make_ply(path, "binary_little_endian", bad, coord="double", extra=False, labels=labels)
        elif name.endswith(".pcd"):
            path.write_bytes(b"VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\n"
                             b"WIDTH 500\nHEIGHT 1\nPOINTS 500\nDATA binary\n"
                             + bad.astype("<f8").tobytes())
        else:
            np.savetxt(path, np.column_stack([bad, labels]))
        msg = raises_naming(PointCloudError, path, read_point_cloud, path,
                            match="3 of 500 points have NaN/inf")
        assert "first at point 4" in msg and "--drop-invalid" in msg and "drop_invalid=True" in msg
        with pytest.warns(UserWarning, match="dropped 3 of 500"):
            got, got_labels = read_point_cloud(path, drop_invalid=True, return_labels=True)
        keep = np.ones(500, bool)
        keep[[3, 10, 20]] = False
        np.testing.assert_array_equal(got, pts[keep])
        if got_labels is not None:
            np.testing.assert_array_equal(got_labels, labels[keep])
    allnan = tmp_path / "allnan.xyz"
    allnan.write_text("nan nan nan\n")
    with pytest.warns(UserWarning, match="dropped 1 of 1"):
        raises_naming(PointCloudError, allnan, read_point_cloud, allnan, drop_invalid=True,
                      match="no points")


def test_non_numeric_text(tmp_path):
    path = tmp_path / "bad.xyz"
    path.write_text("1 2 3\n4 5 6\n7 abc 9\n")
    raises_naming(InputFileError, path, read_point_cloud, path, match="line 3: non-numeric value 'abc'")
    path.write_text("1 2\n3 4\n")
    raises_naming(InputFileError, path, read_point_cloud, path, match="needs 3")
    path.write_bytes(b"\x00\x01\x02binary junk")
    raises_naming(InputFileError, path, read_point_cloud, path, match="binary data")
    csv = tmp_path / "bad.csv"
    csv.write_text("1,2,3\n1,,3\n")
    raises_naming(InputFileError, csv, read_point_cloud, csv, match="line 2")
    path.write_text("   \n# only a comment\n")
    raises_naming(InputFileError, path, read_point_cloud, path, match="no data")


def test_pcd_errors(tmp_path, cloud):
    pts = cloud[0]
    path = write_point_cloud(tmp_path / "e.pcd", pts, binary=True, dtype="float32")
    data = path.read_bytes()
    path.write_bytes(data[:-100])
    raises_naming(InputFileError, path, read_point_cloud, path,
                  match="truncated: header declares 500 points")
    path.write_bytes(data.replace(b"DATA binary\n", b""))
    raises_naming(InputFileError, path, read_point_cloud, path, match="DATA")
    path.write_bytes(data.replace(b"TYPE F F F", b"TYPE F Q F"))
    raises_naming(InputFileError, path, read_point_cloud, path, match="unknown PCD type")
    path.write_bytes(data.replace(b"WIDTH 500", b"WIDTH 499"))
    raises_naming(InputFileError, path, read_point_cloud, path, match="WIDTH")
    path.write_bytes(data.replace(b"DATA binary", b"DATA zipped"))
    raises_naming(InputFileError, path, read_point_cloud, path, match="DATA mode")
    text = write_point_cloud(tmp_path / "a.pcd", pts, binary=False)
    lines = text.read_text().splitlines(keepends=True)
    text.write_text("".join(lines[:-5]))
    raises_naming(InputFileError, text, read_point_cloud, text, match="file holds 495")


# ---------------------------------------------------------------------------------------------
# writer arguments


def test_write_errors(tmp_path, cloud):
    pts, labels = cloud
    with pytest.raises(ConfigError, match="extension"):
        write_point_cloud(tmp_path / "c.las", pts)
    with pytest.raises(ConfigError, match="dtype"):
        write_point_cloud(tmp_path / "c.ply", pts, dtype="int32")
    with pytest.raises(ConfigError, match=r"\(N, 3\)"):
        write_point_cloud(tmp_path / "c.ply", pts[:, :2])
    with pytest.raises(ConfigError, match="labels"):
        write_point_cloud(tmp_path / "c.ply", pts, labels[:-1])
    with pytest.raises(ConfigError, match="labels"):
        write_point_cloud(tmp_path / "c.ply", pts, labels + 0.5)
    bad = pts.copy()
    bad[0, 0] = np.nan
    msg = raises_naming(PointCloudError, tmp_path / "c.ply", write_point_cloud,
                        tmp_path / "c.ply", bad)
    assert "NaN" in msg
    with pytest.raises(PointCloudError, match="empty"):
        write_point_cloud(tmp_path / "c.ply", np.empty((0, 3)))
    assert not list(tmp_path.iterdir())  # nothing written by failed calls


def test_write_creates_parents_and_is_atomic(tmp_path, cloud, monkeypatch):
    pts = cloud[0]
    path = write_point_cloud(tmp_path / "a" / "b" / "c.ply", pts)
    assert path.exists()
    old = path.read_bytes()

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    # A failure while serialising leaves the old file and no temporary behind.
    monkeypatch.setattr("tpvp.io.writers._packed", boom)
    with pytest.raises(RuntimeError):
        write_point_cloud(path, pts * 2)
    assert path.read_bytes() == old
    assert os.listdir(path.parent) == ["c.ply"]


# ---------------------------------------------------------------------------------------------
# atomic writes


def test_atomic_path_success_and_failure(tmp_path):
    dest = tmp_path / "sub" / "out.ply"
    atomic_write_text(dest, "old")
    with pytest.raises(ValueError, match="mid-write"):
        with atomic_path(dest) as tmp:
            assert tmp.parent == dest.parent and tmp.suffix == ".ply" and tmp != dest
            tmp.write_text("half of the new con")
            raise ValueError("mid-write")
    assert dest.read_text() == "old"
    assert sorted(os.listdir(dest.parent)) == ["out.ply"]
    with atomic_path(dest) as tmp:
        tmp.write_text("new")
        assert dest.read_text() == "old"  # not visible until the block ends
    assert dest.read_text() == "new"
    assert sorted(os.listdir(dest.parent)) == ["out.ply"]


def test_atomic_write_bytes(tmp_path):
    dest = tmp_path / "x" / "y" / "data.bin"
    assert atomic_write_bytes(dest, b"\x00\x01") == dest
    assert dest.read_bytes() == b"\x00\x01"
    dest.chmod(0o640)
    atomic_write_bytes(dest, b"2")
    assert dest.read_bytes() == b"2" and (dest.stat().st_mode & 0o777) == 0o640
    assert os.listdir(dest.parent) == ["data.bin"]
    with pytest.raises(TypeError):
        atomic_write_bytes(dest, "not bytes")
    assert dest.read_bytes() == b"2" and os.listdir(dest.parent) == ["data.bin"]
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(InputFileError) as info:
        atomic_write_bytes(blocker / "child.txt", b"")
    assert str(blocker) in str(info.value)


# ---------------------------------------------------------------------------------------------
# gzip-compressed files and the units report


def _gzip_copy(path: Path, name: str | None = None) -> Path:
    import gzip

    target = path.with_name(name or path.name + ".gz")
    target.write_bytes(gzip.compress(path.read_bytes(), mtime=0))
    return target


@pytest.mark.parametrize("ext,binary", [(".ply", True), (".ply", False), (".pcd", True), (".pcd", False),
                                        (".xyz", None), (".txt", None), (".pts", None), (".csv", None)])
def test_gzip_equals_plain(tmp_path, cloud, ext, binary):
    pts, labels = cloud
    plain = write_point_cloud(tmp_path / f"c{ext}", pts, labels, binary=bool(binary))
    packed = _gzip_copy(plain)
    a, la = read_point_cloud(plain, return_labels=True)
    b, lb = read_point_cloud(packed, return_labels=True)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(la, lb)
    # Upper-case names work too.
    np.testing.assert_array_equal(read_point_cloud(_gzip_copy(plain, f"C{ext.upper()}.GZ")), a)


@pytest.mark.parametrize("fmt", ["binary_big_endian", "binary_little_endian", "ascii"])
def test_gzip_hand_made_ply(tmp_path, cloud, fmt):
    pts, labels = cloud
    plain = tmp_path / "h.ply"
    make_ply(plain, fmt, pts, labels=labels, faces_before=True)
    a, la = read_point_cloud(plain, return_labels=True)
    b, lb = read_point_cloud(_gzip_copy(plain), return_labels=True)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(la, lb)


def test_gzip_compressed_pcd(tmp_path):
    o3d = pytest.importorskip("open3d")
    pts = np.random.default_rng(3).uniform(-0.1, 0.1, (300, 3))
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    plain = tmp_path / "lzf.pcd"
    o3d.io.write_point_cloud(str(plain), pcd, compressed=True)
    assert b"binary_compressed" in plain.read_bytes()[:400]
    np.testing.assert_array_equal(read_point_cloud(_gzip_copy(plain)), read_point_cloud(plain))


@pytest.mark.parametrize("ext", [".obj", ".stl", ".off", ".glb"])
def test_gzip_mesh(tmp_path, ext):
    trimesh = pytest.importorskip("trimesh")
    plain = tmp_path / f"box{ext}"
    trimesh.creation.box(extents=[0.2, 0.3, 0.5]).export(plain)
    a = read_point_cloud(plain, mesh_samples=500)
    np.testing.assert_array_equal(read_point_cloud(_gzip_copy(plain), mesh_samples=500), a)


def test_gzip_bundled_sample():
    from tpvp.scene.samples import DATA, load_sample

    packed = DATA / "tomato_0306.xyz.gz"
    np.testing.assert_array_equal(read_point_cloud(packed, units="mm"), load_sample("tomato_0306"))


def test_gzip_text_table(tmp_path):
    plain = tmp_path / "t.txt"
    plain.write_text("3\n1 2\n3 4\n5 6\n")
    np.testing.assert_array_equal(read_text_table(_gzip_copy(plain)), read_text_table(plain))


def test_gzip_errors(tmp_path, cloud):
    import gzip

    pts, _ = cloud
    plain = write_point_cloud(tmp_path / "c.ply", pts)
    data = gzip.compress(plain.read_bytes())
    for cut in (5, 30, len(data) // 2):  # inside the trailer, the deflate stream, the middle
        bad = tmp_path / f"cut{cut}.ply.gz"
        bad.write_bytes(data[:-cut])
        raises_naming(InputFileError, bad, read_point_cloud, bad, match="truncated gzip file")
    fake = tmp_path / "fake.ply.gz"
    fake.write_bytes(plain.read_bytes())  # not compressed at all
    raises_naming(InputFileError, fake, read_point_cloud, fake, match="not a valid gzip file")
    empty = tmp_path / "empty.xyz.gz"
    empty.write_bytes(gzip.compress(b""))
    raises_naming(InputFileError, empty, read_point_cloud, empty, match="empty file")
    bare = tmp_path / "bare.gz"
    bare.write_bytes(data)
    raises_naming(InputFileError, bare, read_point_cloud, bare, match="unknown point-cloud extension")
    # An error inside the decompressed file still names the .gz file.
    short = tmp_path / "short.ply.gz"
    short.write_bytes(gzip.compress(plain.read_bytes()[:-100]))
    raises_naming(InputFileError, short, read_point_cloud, short, match="truncated")


def test_cloud_extension():
    from tpvp.io import GZIP_READ_EXTENSIONS, READ_EXTENSIONS, cloud_extension

    assert cloud_extension("a/scan.PLY.gz") == (".ply", True)
    assert cloud_extension("scan.xyz") == (".xyz", False)
    assert cloud_extension("scan.gz") == ("", True)
    assert ".pcd.gz" in GZIP_READ_EXTENSIONS and ".gz" not in READ_EXTENSIONS


def test_units_report(tmp_path, cloud):
    from tpvp.io import UnitChoice, unit_choice

    pts, labels = cloud  # 0.6 m tall
    mm = write_point_cloud(tmp_path / "mm.xyz", pts * 1000, labels)
    got, choice = read_point_cloud(mm, return_units=True)
    np.testing.assert_allclose(got, pts, rtol=1e-12, atol=1e-12)
    assert isinstance(choice, UnitChoice)
    assert choice.requested == "auto" and choice.used == "mm"
    side = float(np.ptp(pts * 1000, axis=0).max())
    assert choice.largest_side == pytest.approx(side)
    assert choice.largest_side_m == pytest.approx(side / 1000)
    assert str(choice) == f"auto -> mm (largest extent {side:.3g} mm)"
    got, lab, choice = read_point_cloud(_gzip_copy(mm), return_labels=True, return_units=True)
    np.testing.assert_array_equal(lab, labels)
    assert choice.used == "mm"
    metres = write_point_cloud(tmp_path / "m.ply", pts)
    _, choice = read_point_cloud(metres, return_units=True)
    assert str(choice).startswith("auto -> m (largest extent 0.")
    _, choice = read_point_cloud(metres, units="m", return_units=True)
    assert choice.requested == choice.used == "m"
    assert unit_choice(pts * 1000) == UnitChoice("auto", "mm", pytest.approx(side))
    with pytest.raises(ConfigError):
        unit_choice(pts, "cm")


def test_a_new_point_cloud_format_is_one_registration_each_way(tmp_path):
    """A reader and a writer added through the public hooks (READERS, WRITERS) serve
    read_point_cloud and write_point_cloud like the built-in formats."""
    from tpvp.io.readers import READERS
    from tpvp.io.writers import WRITERS

    WRITERS.register(".toy", "toy: one point per line, z y x")(
        lambda pts, labels, binary, fmt: "".join(f"{z!r} {y!r} {x!r}\n" for x, y, z in pts.tolist()).encode())
    READERS.register(".toy", "toy")(
        lambda path, return_labels, mesh_samples, seed: (np.loadtxt(path, ndmin=2)[:, ::-1], None))
    try:
        points = np.random.default_rng(0).random((20, 3))
        written = write_point_cloud(tmp_path / "cloud.toy", points)
        assert written.read_text().splitlines()[0] == " ".join(repr(c) for c in points[0, ::-1].tolist())
        assert np.array_equal(read_point_cloud(written, units="m"), points)
    finally:
        WRITERS.unregister(".toy")
        READERS.unregister(".toy")
    with pytest.raises(ConfigError, match="cannot write extension '.toy'"):
        write_point_cloud(tmp_path / "again.toy", points)
