"""The references of a generated row (tpvp.synthetic.scan): the emulated handheld phone capture,
the candidate-filtered scan and the complete row."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tpvp.errors import ConfigError
from tpvp.simulate.row_cases import RowCase, default_row_cases
from tpvp.scene import voxels
from tpvp.scene.boxes import room_config
from tpvp.scene.grid import build_grid
from tpvp.sensor.bruteforce import pixel_observation
from tpvp.sensor.camera import Intrinsics
from tpvp.synthetic.greenhouse import generate_row
from tpvp.synthetic.scan import (HandheldCapture, candidate_scan, handheld_scan, handheld_trajectory,
                                 reference_points)


def _wall_and_hidden_patch(room):
    """A wall on the row's mid-plane facing the aisle, and a small patch behind its middle."""
    box = room.plant_box
    aisle = np.sign(box.to_local(room.view_box.center)[1])
    u, v = np.meshgrid(np.arange(-1.0, 1.0, 0.005), np.arange(-0.6, 0.6, 0.005))
    wall = np.c_[u.ravel(), np.zeros(u.size), v.ravel()]
    a, b = np.meshgrid(np.arange(-0.1, 0.1, 0.01), np.arange(-0.1, 0.1, 0.01))
    hidden = np.c_[a.ravel(), np.full(a.size, -aisle * 0.2), b.ravel()]
    return wall, hidden, box.to_world(np.concatenate([wall, hidden]))


@pytest.mark.parametrize("scan", [handheld_scan, candidate_scan], ids=["handheld", "candidates"])
def test_scan_keeps_what_the_aisle_sees_and_drops_what_is_hidden(scan):
    room = room_config("room1")
    wall, hidden, points = _wall_and_hidden_patch(room)
    kept = scan(points, room)
    # every 10 cm patch of the wall keeps points (a voxelised slanted plane is partly two voxels
    # thick, and the back voxel of such a pair is hidden, as in a scan)
    patches = np.unique(np.floor(wall[kept[: len(wall)]][:, [0, 2]] / 0.1), axis=0)
    assert len(patches) == 20 * 12
    assert not kept[len(wall):].any()  # what hides behind it is not


def test_handheld_capture_walks_the_aisle_at_hand_heights():
    capture = HandheldCapture()
    for name in ("room1", "room4"):
        room = room_config(name)
        box = room.plant_box
        positions, look_ats = (box.to_local(a) for a in handheld_trajectory(room, capture))
        half = box.half_extent
        walk = 2 * (half[0] + capture.margin)
        assert len(positions) == int(np.floor(walk / capture.speed * capture.frame_rate + 1e-9)) + 1
        assert np.allclose(np.diff(positions[:, 0]), capture.speed / capture.frame_rate)
        # on the aisle side (the view box's), standoff in front of the row's face
        aisle = np.sign(box.to_local(room.view_box.center)[1])
        assert np.allclose(positions[:, 1], aisle * (half[1] + capture.standoff))
        height = positions[:, 2] + half[2]
        assert height.min() >= capture.reach[0] - 1e-9 and height.max() <= capture.reach[1] + 1e-9
        # the gaze: on the mid-plane, straight across, over the asked share of the row's height
        assert np.allclose(look_ats[:, 1], 0) and np.allclose(look_ats[:, 0], positions[:, 0])
        gaze = (look_ats[:, 2] + half[2]) / box.extent[2]
        step = 2 * (capture.gaze[1] - capture.gaze[0]) / (capture.sweep_period * capture.frame_rate)
        assert gaze.min() >= capture.gaze[0] - 1e-9 and gaze.max() <= capture.gaze[1] + 1e-9
        assert gaze.min() < capture.gaze[0] + step and gaze.max() > capture.gaze[1] - step


@pytest.mark.slow
def test_handheld_scan_ignores_the_candidates():
    room = room_config("room4")
    row = generate_row("room4", 0, 1, point_spacing=0.01).points
    moved = replace(room, candidate_positions=room.candidate_positions[::-1] + 0.3,
                    rand_look_at_points=room.rand_look_at_points + 0.3)
    # a coarse camera at one frame a second: what the scan reads of the room does not depend on its pixels
    capture = HandheldCapture(frame_rate=1.0, intrinsics=Intrinsics(fx=42.0, fy=42.0, cx=19.5, cy=25.5, width=39,
                                                                    height=51))
    kept = handheld_scan(row, room, capture)
    assert kept.any() and not kept.all()
    assert np.array_equal(kept, handheld_scan(row, moved, capture))
    assert not np.array_equal(candidate_scan(row, room, resolution=0.05), candidate_scan(row, moved, resolution=0.05))


def test_handheld_scan_counts_frames_like_brute_force():
    """Frames per voxel against the brute-force ray marcher, on a small camera and a short walk."""
    room = room_config("room1")
    capture = HandheldCapture(frame_rate=1.0, min_frames=2, resolution=0.02,
                              intrinsics=Intrinsics(fx=21.0, fy=21.0, cx=9.5, cy=12.5, width=19, height=25))
    row = generate_row("room1", 0, 1, point_spacing=0.02).points
    kept = handheld_scan(row, room, capture)
    grid = build_grid(voxels.voxelise(row, capture.resolution), capture.resolution)
    frames = np.zeros(grid.size, int)
    for position, look_at in zip(*handheld_trajectory(room, capture)):
        frames[pixel_observation(grid, position, look_at, capture.max_range, capture.intrinsics)] += 1
    expected = frames[grid.ids_of(voxels.voxel_keys(row, capture.resolution))] >= capture.min_frames
    assert expected.any() and not expected.all()
    assert np.array_equal(kept, expected)


def test_references_of_a_generated_row():
    room = room_config("room1")
    row = generate_row("room1", 0, 1, point_spacing=0.01).points
    assert len(reference_points(row, room, "complete")) == len(row)
    handheld = handheld_scan(row, room).mean()
    candidates = candidate_scan(row, room).mean()
    # a scan from the aisle misses the inside of the canopy; the handheld walk is one line of
    # keyframes where the candidates fill the workspace
    assert 0.3 < handheld < candidates < 0.95
    with pytest.raises(ConfigError, match="unknown reference 'lidar'"):
        reference_points(row, room, "lidar")


def test_row_cases_per_reference():
    cases = default_row_cases(references=("complete", "handheld"))
    assert len(cases) == 16 and {c.reference for c in cases} == {"complete", "handheld"}
    assert [c.reference for c in default_row_cases(quick=True, references=("complete", "candidates"))] == \
        ["complete", "candidates"]
    assert RowCase("room1", 0).labels()["reference"] == "handheld"


@pytest.mark.parametrize("field, value", [("speed", 0.0), ("min_frames", 0), ("gaze", (0.9, 0.1)),
                                          ("margin", -1.0)])
def test_handheld_capture_refuses_bad_values(field, value):
    with pytest.raises(ConfigError, match=field):
        HandheldCapture(**{field: value})
