import numpy as np
import pytest

from tpvp.errors import ConfigError, InputFileError
from tpvp.scene.boxes import (
    OrientedBox,
    candidate_look_ats,
    read_bbx_config,
    room_config,
)


def _rot_z(deg):
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])


@pytest.fixture
def box():
    return OrientedBox(center=[1.0, -2.0, 0.5], rotation=_rot_z(35.0), extent=[3.0, 0.8, 2.0])


def test_local_world_round_trip(box):
    rng = np.random.default_rng(0)
    p = rng.normal(size=(100, 3))
    np.testing.assert_allclose(box.to_world(box.to_local(p)), p, atol=1e-12)
    np.testing.assert_allclose(box.to_local(box.center[None]), 0.0, atol=1e-12)
    # the local x axis is the first column of the rotation
    np.testing.assert_allclose(box.to_world([[1.0, 0, 0]])[0] - box.center, box.rotation[:, 0], atol=1e-12)


def test_contains_corners_and_bounds(box):
    c = box.corners()
    assert c.shape == (8, 3)
    assert box.contains(c, tol=1e-9).all()
    assert not box.contains(box.center + 1.02 * (c - box.center)).any()
    assert box.contains(box.center[None]).all()
    lo, hi = box.axis_aligned_bounds()
    np.testing.assert_allclose(lo, c.min(0))
    np.testing.assert_allclose(hi, c.max(0))
    # corner order: x slowest (the authors' C++ order)
    q = box.to_local(c)
    assert np.all(q[:4, 0] < 0) and np.all(q[4:, 0] > 0)
    np.testing.assert_allclose(np.abs(q), np.broadcast_to(box.half_extent, (8, 3)))


def test_sample_uniform(box):
    pts = box.sample_uniform(2000, rng=1)
    assert pts.shape == (2000, 3) and box.contains(pts).all()
    np.testing.assert_array_equal(pts, box.sample_uniform(2000, np.random.default_rng(1)))
    q = box.to_local(pts)
    assert np.all(q.max(0) - q.min(0) > 0.9 * box.extent)


def test_grid(box):
    shape = box.grid_shape(0.1)
    assert shape == (31, 9, 21)
    g = box.grid(0.1)
    assert g.shape == (31 * 9 * 21, 3)
    assert box.contains(g, tol=1e-9).all()
    q = box.to_local(g).reshape(*shape, 3)
    np.testing.assert_allclose(np.diff(q[:, 0, 0, 0]), 0.1, atol=1e-12)
    np.testing.assert_allclose(np.diff(q[0, :, 0, 1]), 0.1, atol=1e-12)
    np.testing.assert_allclose(np.diff(q[0, 0, :, 2]), 0.1, atol=1e-12)
    np.testing.assert_allclose(q.reshape(-1, 3).mean(0), 0.0, atol=1e-12)  # centred
    assert box.grid([0.5, 0.4, 1.0]).shape == (7 * 3 * 3, 3)
    with pytest.raises(ConfigError, match="spacing"):
        box.grid(0.0)


def test_box_validation():
    with pytest.raises(ConfigError, match="extent"):
        OrientedBox([0, 0, 0], np.eye(3), [1, -1, 1])
    with pytest.raises(ConfigError, match="not a rotation"):
        OrientedBox([0, 0, 0], np.eye(3) * 1.1, [1, 1, 1])
    with pytest.raises(ConfigError, match="reflection"):
        OrientedBox([0, 0, 0], np.diag([1.0, 1.0, -1.0]), [1, 1, 1])
    b = OrientedBox([0, 0, 0], _rot_z(10) + 1e-9, [1, 1, 1])  # float noise is snapped away
    np.testing.assert_allclose(b.rotation.T @ b.rotation, np.eye(3), atol=1e-14)
    assert not b.center.flags.writeable


GOOD = """%YAML:1.0
plant_box:
  center:
   - 1.0
   - 2.0
   - 0.5
  R_flat: [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
  extent:
   - 3.5
   - 0.8
   - 2.3
view_box:
  center: [1.7, 2.0, 0.5]
  R_flat: [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
  extent: [3.9, 0.6, 2.5]
"""


def test_read_bbx_config(tmp_path):
    path = tmp_path / "good.yaml"
    path.write_text(GOOD)
    boxes = read_bbx_config(path)
    assert set(boxes) == {"plant_box", "view_box"}
    pb = boxes["plant_box"]
    np.testing.assert_allclose(pb.center, [1.0, 2.0, 0.5])
    np.testing.assert_allclose(pb.rotation, [[0, -1, 0], [1, 0, 0], [0, 0, 1]])  # row-major
    np.testing.assert_allclose(pb.extent, [3.5, 0.8, 2.3])


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda t: t.replace("view_box:", "other_box:"), "missing key 'view_box'"),
        (lambda t: t.replace("  extent: [3.9, 0.6, 2.5]\n", ""), "missing key 'view_box.extent'"),
        (lambda t: t.replace("[1.7, 2.0, 0.5]", "[1.7, 2.0]"), "'view_box.center' must have 3 values"),
        (lambda t: t.replace("  R_flat: [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]\n  extent: [3.9",
                             "  R_flat: [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]\n  extent: [3.9"),
         "'view_box.R_flat' must have 9 values"),
        (lambda t: t.replace("  R_flat: [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]\n  extent: [3.9",
                             "  R_flat: [1.0, 0.5, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n  extent: [3.9"),
         "not a rotation"),
        (lambda t: t.replace("[3.9, 0.6, 2.5]", "[3.9, abc, 2.5]"), "numbers"),
        (lambda t: t.replace("[3.9, 0.6, 2.5]", "[3.9, 0.0, 2.5]"), "positive"),
    ],
)
def test_read_bbx_config_errors_name_the_file(tmp_path, edit, message):
    path = tmp_path / "bad_config.yaml"
    path.write_text(edit(GOOD))
    with pytest.raises(ConfigError) as err:
        read_bbx_config(path)
    assert "bad_config.yaml" in str(err.value)
    assert message in str(err.value)


def test_read_bbx_config_file_errors(tmp_path):
    with pytest.raises(InputFileError, match="missing.yaml: file not found"):
        read_bbx_config(tmp_path / "missing.yaml")
    bad = tmp_path / "broken.yaml"
    bad.write_text("%YAML:1.0\nplant_box: [1, 2\n")
    with pytest.raises(InputFileError, match="broken.yaml: not valid YAML"):
        read_bbx_config(bad)
    scalar = tmp_path / "scalar.yaml"
    scalar.write_text("%YAML:1.0\n42\n")
    with pytest.raises(ConfigError, match="scalar.yaml"):
        read_bbx_config(scalar)


@pytest.mark.parametrize("room", ["room1", "room4"])
def test_bundled_room_config(room):
    cfg = room_config(room)
    assert cfg.candidate_positions.shape == (1000, 3)
    assert cfg.initial_views.shape == (15, 6)
    assert cfg.initial_positions.shape == cfg.initial_look_ats.shape == (15, 3)
    assert cfg.rand_look_at_points.shape == (100, 3)
    assert 2.5 < cfg.passive_cost < 2.7
    assert cfg.view_box.contains(cfg.candidate_positions, tol=1e-6).all()
    assert cfg.plant_box.contains(cfg.rand_look_at_points, tol=1e-6).all()
    # row axis = local x (about 3.6 m), width y, height z; both boxes share the orientation
    assert 3.5 < cfg.plant_box.extent[0] < 3.7 and 0.6 < cfg.plant_box.extent[1] < 0.8
    np.testing.assert_allclose(cfg.plant_box.rotation, cfg.view_box.rotation)
    assert not cfg.candidate_positions.flags.writeable
    assert room_config(room) is cfg  # cached


def test_room_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="room must be one of room1, room4"):
        room_config("room2")
    with pytest.raises(InputFileError, match="not found"):
        room_config("room1", data_dir=tmp_path / "nowhere")
    (tmp_path / "room1_bbx_config.yaml").write_text(GOOD)
    (tmp_path / "room1_candidate_views.txt").write_text("1 2\n3 4\n")
    with pytest.raises(InputFileError, match="room1_candidate_views.txt: expected 3 columns"):
        room_config("room1", data_dir=tmp_path)


def test_candidate_look_ats():
    la = candidate_look_ats("room1", "20250918", "PriorTemporal")
    assert la.shape == (1000, 3)
    used = np.abs(la).sum(1) > 0
    assert used.sum() == 800  # 100 targets x 8 rounds
    assert room_config("room1").plant_box.contains(la[used], tol=0.05).mean() > 0.95
    with pytest.raises(ConfigError, match="prior must be one of"):
        candidate_look_ats("room1", "20250918", "PriorFoo")
    with pytest.raises(InputFileError, match="dates available for room4: 20250918, 20250922, 20250925, 20250929"):
        candidate_look_ats("room4", "20250915", "PriorBBX")
