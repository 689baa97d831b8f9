import json

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tpvp.errors import ConfigError, InputFileError
from tpvp.scene.boxes import OrientedBox, room_config
from tpvp.synthetic.greenhouse import (
    DATES,
    FRUIT,
    LEAF,
    ORGAN_STRIDE,
    PETIOLE,
    STEM,
    generate_row,
    generate_row_sessions,
    row_correspondences,
    row_summary,
    save_row_sessions,
)
from tpvp.scene.voxels import voxelise

SPACING = 0.01  # coarse sampling keeps the tests fast


@pytest.fixture(scope="module", params=["room1", "room4"])
def sessions(request):
    return generate_row_sessions(request.param, seed=3, point_spacing=SPACING)


def _organs(session, kind):
    ids = np.unique(session.organ_id)
    return set(ids[ids // ORGAN_STRIDE == kind].tolist())


def test_row_inside_box_with_realistic_extent(sessions):
    box = room_config(sessions[0].room).plant_box
    for s in sessions:
        assert s.points.shape == (s.n_points, 3) and s.n_points > 10_000
        assert np.isfinite(s.points).all()
        assert box.contains(s.points).all()
        q = s.local_points()
        extent = q.max(0) - q.min(0)
        # the row fills the real plant box: ~3.6 m long, 0.7-0.8 m wide (0.68 m box in room4), 2.0-2.5 m tall
        assert 0.95 * box.extent[0] < extent[0] <= box.extent[0]
        assert 0.9 * box.extent[1] < extent[1] <= box.extent[1]
        assert 0.85 * box.extent[2] < extent[2] <= box.extent[2]
        assert 3.3 < extent[0] < 3.7 and 0.6 < extent[1] < 0.8 and 2.0 < extent[2] < 2.5
        assert 8 <= s.n_plants <= 12
        assert set(np.unique(s.labels)) == {STEM, LEAF, FRUIT, PETIOLE}
        assert s.n_leaves >= 6 * s.n_plants and s.n_fruits >= 20
        assert s.date == DATES[s.session]
    # the stems start near the floor
    q = sessions[0].local_points()[sessions[0].labels == STEM]
    assert q[:, 2].min() < -box.extent[2] / 2 + 0.08


def test_fruits_lower_middle_and_sizes(sessions):
    s = sessions[0]
    box = room_config(s.room).plant_box
    z = s.local_points()[s.labels == FRUIT, 2] + box.extent[2] / 2  # height above the box floor
    assert 0.1 < np.median(z) / box.extent[2] < 0.6
    for fid in list(_organs(s, 3))[:20]:
        p = s.points[s.organ_id == fid]
        radius = np.linalg.norm(p - p.mean(0), axis=1).max()
        assert 0.004 < radius < 0.04


def test_deterministic_by_seed():
    a = generate_row("room1", seed=5, session=2, point_spacing=SPACING)
    b = generate_row("room1", seed=5, session=2, point_spacing=SPACING)
    c = generate_row("room1", seed=6, session=2, point_spacing=SPACING)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.sample_id, b.sample_id)
    assert a.points.shape != c.points.shape or not np.array_equal(a.points, c.points)
    # one session on its own equals the same session of the sequence
    seq = generate_row_sessions("room1", seed=5, n_sessions=3, point_spacing=SPACING)
    assert len(seq) == 3
    np.testing.assert_array_equal(seq[2].points, a.points)
    np.testing.assert_array_equal(seq[2].labels, a.labels)
    assert not a.points.flags.writeable


def test_geometry_independent_of_spacing():
    """The row's structure comes from the seed alone; point_spacing only changes the sampling."""
    coarse = generate_row("room4", seed=1, session=1, point_spacing=0.02)
    fine = generate_row("room4", seed=1, session=1, point_spacing=SPACING)
    assert (coarse.n_plants, coarse.n_leaves, coarse.n_fruits) == (fine.n_plants, fine.n_leaves, fine.n_fruits)
    assert fine.n_points > 3 * coarse.n_points
    np.testing.assert_allclose(coarse.points.min(0), fine.points.min(0), atol=0.05)
    np.testing.assert_allclose(coarse.points.max(0), fine.points.max(0), atol=0.05)


def test_sessions_change_like_a_crop(sessions):
    fruits = [s.n_fruits for s in sessions]
    # harvest on 20250922 and 20250929 (sessions 2 and 4)
    assert fruits[2] < fruits[1] and fruits[4] < fruits[3]
    # the top grows in every interval
    tops = [s.local_points()[s.labels == STEM, 2].max() for s in sessions]
    assert np.all(np.diff(tops) > 0.01)
    new_leaves = 0
    for prev, curr in zip(sessions[:-1], sessions[1:]):
        lp, lc = _organs(prev, 1), _organs(curr, 1)
        removed, added = lp - lc, lc - lp
        new_leaves += len(added)
        zp = prev.local_points()[:, 2]
        lowest = {}
        for oid in lp:  # de-leafing removes the lowest leaves of a plant (by the height of the node)
            m = np.flatnonzero(prev.organ_id == oid)
            plant = int(prev.plant_id[m[0]])
            stem = prev.points[(prev.labels == STEM) & (prev.plant_id == plant)]
            dist, _ = cKDTree(stem).query(prev.points[m])
            lowest.setdefault(plant, []).append((zp[m[np.argmin(dist)]], oid in removed))
        for plant, leaves in lowest.items():
            flags = [r for _, r in sorted(leaves, key=lambda t: t[0])]
            # removed leaves come first when ordered by the height of their node
            assert flags == sorted(flags, reverse=True), f"plant {plant}: a leaf above a kept one was removed"
        # new leaves appear at the top of their plant
        zc = curr.local_points()[:, 2]
        for oid in added:
            m = curr.organ_id == oid
            plant = curr.plant_id[m][0]
            stem_top = zc[(curr.labels == STEM) & (curr.plant_id == plant)].max()
            assert zc[m].min() > stem_top - 0.4
        # harvested trusses were the lowest ones
        tp, tc = _organs(prev, 2), _organs(curr, 2)
        for oid in tp - tc:
            m = prev.organ_id == oid
            plant = prev.plant_id[m][0]
            others = [zp[prev.organ_id == o].max() for o in tp & tc if prev.plant_id[prev.organ_id == o][0] == plant]
            assert not others or zp[m].max() < min(others)
    assert new_leaves > 0
    assert sum(len(_organs(a, 1) - _organs(b, 1)) for a, b in zip(sessions[:-1], sessions[1:])) > 0


def test_correspondences(sessions):
    for prev, curr in zip(sessions[:-1], sessions[1:]):
        i, j = row_correspondences(prev, curr)
        assert i.size > 0.7 * min(prev.n_points, curr.n_points)
        np.testing.assert_array_equal(prev.sample_id[i], curr.sample_id[j])
        np.testing.assert_array_equal(prev.organ_id[i], curr.organ_id[j])
        np.testing.assert_array_equal(prev.labels[i], curr.labels[j])
        np.testing.assert_array_equal(prev.plant_id[i], curr.plant_id[j])
        d = np.linalg.norm(prev.points[i] - curr.points[j], axis=1)
        assert np.median(d) < 0.05 and d.max() < 0.6
        assert np.percentile(d, 99) > 1e-3  # growth / sway: the row is not static
        # organs removed or added have no correspondences
        gone = np.isin(prev.organ_id, list(set(np.unique(prev.organ_id)) - set(np.unique(curr.organ_id))))
        assert not np.isin(np.flatnonzero(gone), i).any()
    # sample ids are unique inside a session
    assert np.unique(sessions[0].sample_id).size == sessions[0].n_points
    other = generate_row("room1" if sessions[0].room == "room4" else "room4", seed=3, session=1, point_spacing=SPACING)
    with pytest.raises(ConfigError, match="different rows"):
        row_correspondences(sessions[0], other)


def test_one_cm_voxels_close_surfaces():
    """At the default spacing, voxelising at 1 cm misses (almost) no voxel of a denser sampling."""
    a = generate_row("room4", seed=0, session=0, point_spacing=0.004)
    b = generate_row("room4", seed=0, session=0, point_spacing=0.003)
    ka, kb = voxelise(a.points, 0.01), voxelise(b.points, 0.01)
    assert ka.shape[0] > 0.9 * kb.shape[0]
    summary = row_summary(a)
    assert summary["voxels"] == ka.shape[0] and summary["plants"] == a.n_plants


def _read_pcd(path):
    raw = path.read_bytes()
    end = raw.index(b"DATA binary\n") + len(b"DATA binary\n")
    header = raw[:end].decode("ascii").splitlines()
    fields = dict(line.split(" ", 1) for line in header if not line.startswith("#"))
    n = int(fields["POINTS"])
    assert fields["FIELDS"] == "x y z" and fields["TYPE"] == "F F F" and fields["SIZE"] == "4 4 4"
    assert int(fields["WIDTH"]) == n and fields["HEIGHT"] == "1"
    assert header[0].startswith("# .PCD v0.7")
    data = np.frombuffer(raw[end:], dtype="<f4")
    assert data.size == 3 * n
    return data.reshape(n, 3)


def test_save_row_sessions_round_trip(tmp_path):
    seq = generate_row_sessions("room4", seed=2, n_sessions=2, point_spacing=0.02)
    out = tmp_path / "Processed_3D_Model"
    manifest_path = save_row_sessions(seq, out)
    assert manifest_path == out / "manifest.json"
    names = sorted(p.name for p in out.iterdir())
    assert names == ["manifest.json", "room4_20250915.pcd", "room4_20250918.pcd"]  # no temp files left
    for s in seq:
        pts = _read_pcd(out / f"{s.name}.pcd")
        np.testing.assert_allclose(pts, s.points, atol=1e-6)
    manifest = json.loads(manifest_path.read_text())
    assert manifest["room"] == "room4" and manifest["units"] == "m" and manifest["seed"] == 2
    assert manifest["dates"] == ["20250915", "20250918"]
    assert manifest["files"] == ["room4_20250915.pcd", "room4_20250918.pcd"]
    assert manifest["point_counts"] == [s.n_points for s in seq]
    assert manifest["generator_version"]
    # overwriting is atomic too and leaves nothing behind
    save_row_sessions(seq[:1], out)
    assert sorted(p.name for p in out.iterdir()) == names


def test_save_failure_leaves_no_temp_file(tmp_path, monkeypatch):
    import tpvp.io.atomic as atomic

    seq = generate_row_sessions("room1", seed=0, n_sessions=1, point_spacing=0.03)

    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(atomic.os, "replace", boom)
    with pytest.raises(InputFileError, match="disk full"):
        save_row_sessions(seq, tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_argument_errors():
    with pytest.raises(ConfigError, match="room must be one of"):
        generate_row("room7")
    with pytest.raises(ConfigError, match="session must be in 0..4"):
        generate_row(session=5)
    with pytest.raises(ConfigError, match="point_spacing"):
        generate_row(point_spacing=0.0)
    with pytest.raises(ConfigError, match="seed"):
        generate_row(seed=-1)
    with pytest.raises(ConfigError, match="n_sessions"):
        generate_row_sessions(n_sessions=6)
    with pytest.raises(ConfigError, match="non-empty list"):
        save_row_sessions([], "unused")
    with pytest.raises(ConfigError, match="plant_box extent"):
        generate_row(plant_box=OrientedBox([0, 0, 0], np.eye(3), [1.0, 1.0, 1.0]))


def test_custom_box_and_noise():
    box = OrientedBox([5.0, 1.0, 1.2], np.eye(3), [4.0, 0.9, 2.4])
    s = generate_row(seed=1, session=3, point_spacing=0.02, plant_box=box, noise=0.003)
    assert box.contains(s.points).all()
    clean = generate_row(seed=1, session=3, point_spacing=0.02, plant_box=box)
    d = np.linalg.norm(s.points - clean.points, axis=1)
    assert 0.001 < np.median(d) < 0.01
