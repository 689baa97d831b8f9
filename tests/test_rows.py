"""Greenhouse rows end to end: look-at targets and round robin, the look-at prior registry, the
cached oracle, one case of Ours and its baselines, the row experiment runner, the CLI and its bad
inputs."""

from __future__ import annotations

import itertools
import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from tpvp.cli import main
from tpvp.errors import ConfigError, InputFileError, PointCloudError
from tpvp.experiments import rows
from tpvp.experiments.results import write_results
from tpvp.config_loading import make_config
from tpvp.scene.boxes import ROOMS, candidate_look_ats, room_config
from tpvp.sensor.sensor import ROW_RANGE
from tpvp.simulate import greenhouse, row_cases
from tpvp.synthetic.greenhouse import generate_row
from tpvp.viewspace.space import get_view_space
from tpvp.viewspace.lookat import (farthest_point_sampling, free_space_keys, round_robin_views,
                                   surface_frontiers)
from tpvp.viewspace.priors import AUTHORS_PRIORS, LOOK_AT_PRIORS
from tpvp.visibility.oracle_cache import cached_oracle

QUICK = row_cases.quick_config({"registration.method": "none"})


# ----------------------------------------------------------------------------- look-at candidates


def _brute_round_robin(targets, positions, rounds, seed):
    rng = np.random.default_rng(seed)
    used, pairs = set(), []
    for _ in range(rounds):
        for t in rng.permutation(len(targets)):
            if len(used) == len(positions):
                break
            d = [(np.sum((targets[t] - p) ** 2), i) for i, p in enumerate(positions) if i not in used]
            i = min(d)[1]
            used.add(i)
            pairs.append((i, t))
    return pairs


def test_round_robin_gives_every_target_k_views_and_each_position_at_most_once():
    rng = np.random.default_rng(3)
    targets, positions = rng.uniform(0, 1, (7, 3)), rng.uniform(0, 1, (60, 3))
    views = round_robin_views(targets, positions, rounds=8, seed=5)
    assert len(views) == 56
    assert np.bincount(views.target_ids, minlength=7).tolist() == [8] * 7
    assert len(np.unique(views.position_ids)) == len(views.position_ids)
    assert np.array_equal(views.look_ats, targets[views.target_ids])
    assert list(zip(views.position_ids.tolist(), views.target_ids.tolist())) == _brute_round_robin(targets, positions, 8, 5)
    # fewer positions than targets x rounds: each position once, every target its share
    short = round_robin_views(targets, positions[:30], rounds=8, seed=5)
    assert len(short) == 30 and set(np.bincount(short.target_ids).tolist()) <= {4, 5}


def test_farthest_point_sampling_matches_brute_force():
    rng = np.random.default_rng(1)
    points = rng.normal(size=(200, 3))
    chosen = farthest_point_sampling(points, 12, seed=4)
    expected = [int(np.random.default_rng(4).integers(200))]
    for _ in range(11):
        d = np.array([min(np.sum((p - points[c]) ** 2) for c in expected) for p in points])
        expected.append(int(np.argmax(d)))
    assert chosen.tolist() == expected
    assert farthest_point_sampling(points[:5], 12).tolist() == list(range(5))


def test_surface_frontiers_match_brute_force():
    rng = np.random.default_rng(2)
    occupied = np.unique(rng.integers(0, 6, (40, 3)), axis=0)
    free = np.unique(rng.integers(0, 6, (60, 3)), axis=0)
    free = free[~(free[:, None, :] == occupied[None]).all(-1).any(1)]
    got = {tuple(k) for k in surface_frontiers(occupied, free)}
    occ, fre = {tuple(k) for k in occupied}, {tuple(k) for k in free}
    faces = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    expected = set()
    for key in itertools.product(range(-1, 8), repeat=3):
        if key in occ or key in fre:
            continue
        nb = [tuple(np.add(key, f)) for f in faces]
        if any(n in occ for n in nb) and any(n in fre for n in nb):
            expected.add(key)
    assert got == expected


def test_free_space_stops_short_of_the_observed_voxel():
    keys = free_space_keys(np.zeros(3), np.array([[0.105, 0.005, 0.005]]), 0.01)
    assert keys[:, 0].min() == 0 and keys[:, 0].max() == 9 and np.all(keys[:, 1:] == 0)


# ----------------------------------------------------------------------------- one case


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    previous = generate_row("room1", 0, 0, point_spacing=0.008).points
    current = generate_row("room1", 0, 1, point_spacing=0.008).points
    return greenhouse.build_row_scene(previous, current, QUICK, cache_dir=tmp_path_factory.mktemp("oracle"))


@pytest.mark.slow
def test_oracle_is_cached_on_disk_by_scene_and_configuration(scene, tmp_path):
    grid, viewpoints = scene.grid, scene.room.view_box.grid(QUICK.oracle_grid)
    ids, cached = cached_oracle(grid, viewpoints, ROW_RANGE, tmp_path)
    assert not cached and np.array_equal(ids, scene.oracle)
    again, cached = cached_oracle(grid, viewpoints, ROW_RANGE, tmp_path)
    assert cached and np.array_equal(again, ids)
    other, cached = cached_oracle(grid, viewpoints, 1.5, tmp_path)  # another range: another entry
    assert not cached and len(other) < len(ids)
    for entry in (tmp_path / "oracle").iterdir():  # a damaged entry is recomputed
        entry.write_bytes(b"not an array")
    repaired, cached = cached_oracle(grid, viewpoints, ROW_RANGE, tmp_path)
    assert not cached and np.array_equal(repaired, ids)


def test_ours_plans_executes_and_beats_random_selection_at_equal_views(scene):
    result = greenhouse.run_row_case(scene, QUICK)
    assert result.n_views == 15 + len(result.planned_views) and result.selection.optimal
    assert result.coverage_captured < result.coverage <= 1.0
    assert result.path_length == pytest.approx(result.path.length + scene.room.passive_cost)
    assert result.path.gap <= QUICK.path.band_gap + 1e-9
    # the executed views are the path's order of the selected candidates, each candidate once
    assert len(np.unique(result.planned_views)) == len(result.planned_views)
    candidates = greenhouse.row_candidates(scene, "transfer", QUICK, result.transfer)
    truth = greenhouse.candidate_truth(scene, candidates)
    random = [greenhouse.random_selection(scene, candidates, truth, len(result.planned_views), r, QUICK)
              for r in range(3)]
    assert result.coverage > max(r["coverage"] for r in random)
    assert greenhouse.upper_limit(scene, truth) >= greenhouse.row_coverage(scene, greenhouse.execute(
        scene, result.positions, result.look_ats), with_passive=False) - 1e-12


def test_priors_give_800_candidate_views_each(scene):
    transfer = greenhouse.row_transfer(scene, QUICK)
    box = scene.room.plant_box
    for prior in ("obb", "passive", "transfer"):
        candidates = greenhouse.row_candidates(scene, prior, QUICK, transfer)
        assert len(candidates) == 800 and len(candidates.targets) == 100
        assert box.contains(candidates.targets, tol=0.05).mean() > 0.95
        assert np.isin(candidates.position_ids, np.arange(1000)).all()
    with pytest.raises(ConfigError, match="unknown look-at prior"):
        greenhouse.row_candidates(scene, "magic", QUICK)
    with pytest.raises(ConfigError, match="date"):
        greenhouse.row_candidates(scene, "authors-transfer", QUICK)
    with pytest.raises(ConfigError, match="registered previous session"):
        greenhouse.row_candidates(scene, "transfer", QUICK)


def test_look_at_priors_are_a_registry_of_the_ladder_and_the_authors_files():
    assert LOOK_AT_PRIORS.names() == sorted(rows.PRIORS + tuple(f"authors-{p}" for p in rows.PRIORS))
    assert set(AUTHORS_PRIORS) == set(rows.PRIORS)


def test_the_authors_look_at_files_as_candidates(scene):
    dated = replace(scene, known=replace(scene.known, date="20250918"))
    for prior, name in AUTHORS_PRIORS.items():
        table = candidate_look_ats("room1", "20250918", name)
        candidates = greenhouse.row_candidates(dated, f"authors-{prior}", QUICK)
        used = np.flatnonzero(np.any(table != 0, axis=1))
        assert np.array_equal(candidates.position_ids, used)
        assert np.array_equal(candidates.look_ats, table[used])
        assert np.array_equal(candidates.targets[candidates.target_ids], candidates.look_ats)


# ----------------------------------------------------------------------------- bad input


def test_row_outside_its_rooms_boxes_is_one_clear_error():
    points = generate_row("room1", 0, 0, point_spacing=0.02).points
    with pytest.raises(PointCloudError, match="outside its room's boxes"):
        greenhouse.build_row_scene(points, points + [5.0, 0.0, 0.0], QUICK, cache_dir=False)
    room4 = generate_row("room4", 0, 0, point_spacing=0.02).points  # the scene's room is config.view_space
    with pytest.raises(PointCloudError, match="room1's plant box"):
        greenhouse.build_row_scene(room4, room4, QUICK, cache_dir=False)


def test_each_room_is_defined_once_and_its_view_space_made_from_it():
    for room in ROOMS:
        space, config = get_view_space(room), room_config(room)
        assert np.array_equal(space.positions, config.candidate_positions) and space.name == room
        assert np.array_equal(space.passive_views, config.initial_views) and space.passive_cost == config.passive_cost
        assert space.max_range == ROW_RANGE == make_config("row", view_space=room).sensor.max_range


def test_empty_passive_scan_is_one_clear_error():
    points = generate_row("room1", 0, 0, point_spacing=0.02).points
    blind = row_cases.quick_config({"sensor.max_range": 0.05, "registration.method": "none"})
    with pytest.raises(PointCloudError, match="empty passive scan"):
        greenhouse.build_row_scene(points, points, blind, cache_dir=False)


def test_dataset_folder_without_sessions_is_one_clear_error(tmp_path, capsys):
    with pytest.raises(InputFileError, match="no Processed_3D_Model"):
        row_cases.dataset_cases(tmp_path)
    (tmp_path / "Processed_3D_Model").mkdir()
    (tmp_path / "Processed_3D_Model" / "room1_20250915.pcd").write_bytes(b"")
    assert main(["greenhouse", "--dataset", str(tmp_path), "--output", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no two sessions of one room" in err[0]


# ----------------------------------------------------------------------------- runner and CLI


@pytest.mark.slow
def test_row_experiments_cache_and_tables(tmp_path):
    config = row_cases.quick_config({"registration.method": "none", "protocol.cover_resolutions": (0.10,),
                                "protocol.budgets": (50,), "protocol.repetitions": 2})
    case = row_cases.RowCase("room1", 0, point_spacing=0.008)
    methods = ["coarse", "ours", "prior-obb-random", "upper-limit"]
    raw = rows.run_row_experiments([case], methods, config, cache_dir=tmp_path / "cache", progress=False)
    assert sorted(raw["method"].unique()) == sorted(methods)
    assert len(raw[raw["method"] == "prior-obb-random"]) == 2 and len(raw[raw["method"] == "upper-limit"]) == 3
    again = rows.run_row_experiments([case], methods, config, cache_dir=tmp_path / "cache", progress=False)
    pd.testing.assert_frame_equal(raw, again)  # read back from the cache, identical
    written = write_results(rows.ROW_EXPERIMENTS, tmp_path / "out", raw, config)
    table6 = written["table6_coverage_effort"]
    coarse = table6[table6["method"] == "coarse"].iloc[0]
    assert coarse["views_mean"] == 15 and coarse["paper_coverage"] == pytest.approx(44.48)
    assert (tmp_path / "out" / "figures" / "coverage_path_frontier.png").stat().st_size > 0
    assert set(written["table5_upper_limit"]["prior"]) == {"obb", "passive", "transfer"}
    with pytest.raises(ConfigError, match="unknown row experiment method"):
        rows.run_row_experiments([case], ["magic"], config)


@pytest.mark.slow
def test_standin_clean_then_tpvp_greenhouse_on_the_dataset(tmp_path, capsys):
    from data_tools.cli import main as data_main

    raw, dataset = tmp_path / "raw", tmp_path / "dataset"
    assert data_main(["greenhouse", "standin", "--output", str(raw), "--sessions", "2"]) == 0
    assert data_main(["greenhouse", "clean", str(raw), "--landmarks", str(raw / "landmarks"),
                      "--output", str(dataset)]) == 0
    capsys.readouterr()
    out = tmp_path / "plan"
    assert main(["greenhouse", "--dataset", str(dataset), "--quick", "--output", str(out),
                 "--cache", str(tmp_path / "cache")]) == 0
    printed = capsys.readouterr().out
    assert "coverage of the oracle set" in printed
    summary = json.loads((out / "results.json").read_text())
    assert summary["room"] == "room1" and summary["views"] > 15 and 0.4 < summary["coverage"] <= 1.0
    plan = pd.read_csv(out / "plan.csv", comment="#")
    assert (plan["role"] == "passive").sum() == 15 and len(plan) == summary["views"]
    for name in ("plan.json", "plan.png", "recording.rrd", "config.yaml", "provenance.json"):
        assert (out / name).stat().st_size > 0


@pytest.mark.slow
def test_blockwise_nbv_and_pose_noise_rows(tmp_path):
    config = row_cases.quick_config({"registration.method": "none", "protocol.nbv_budgets": (10, 20)})
    assert config.pose_noise.draws == 1 and config.pose_noise.cover_resolution == 0.10
    case = row_cases.RowCase("room1", 0, point_spacing=0.008)
    raw = rows.run_row_experiments([case], ["blockwise-nbv", "pose-noise"], config, progress=False)
    nbv = raw[(raw["method"] == "blockwise-nbv") & raw["prefix_of"].isna()]
    assert nbv["views"].tolist() == [10, 20]
    assert nbv["coverage"].is_monotonic_increasing and nbv["path_length_m"].is_monotonic_increasing
    # the prefix curve of the longest run (every 10 views) ends on that run's own row
    curve = raw[raw["prefix_of"] == 20]
    assert curve["views"].tolist() == [10, 20]
    assert curve["coverage"].iloc[-1] == nbv["coverage"].iloc[-1]
    assert curve["path_length_m"].iloc[-1] == nbv["path_length_m"].iloc[-1]
    assert rows.tables(raw)["blockwise_prefix_curve"]["views"].tolist() == [10, 20]
    table7 = rows.tables(raw)["table7_pose_noise"]
    assert len(table7) == 3  # noise-free, noisy without ICP, noisy with ICP
    free, off, on = (table7.iloc[i] for i in range(3))
    # every fused point is a 2 cm voxel centre, at most half a voxel diagonal (1.73 cm) from the
    # centroid of the surface points in its voxel
    assert free["precision_20mm_mean"] == pytest.approx(1.0)
    assert off["precision_10mm_mean"] < free["precision_10mm_mean"] and on["chamfer_mm_mean"] < off["chamfer_mm_mean"]


def test_experiments_rows_cli_quick(tmp_path, capsys):
    out = tmp_path / "tables"
    assert main(["experiments", "rows", "--quick", "--methods", "coarse", "--rooms", "room4", "--workers", "1",
                 "--cache", str(tmp_path / "cache"), "--output", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "1 cases x 1 methods" in printed and "| generated | handheld | coarse |" in printed
    raw = pd.read_csv(out / "raw_cases.csv")
    assert raw["room"].tolist() == ["room4"] and raw["views"].tolist() == [15]
    for name in ("table6_coverage_effort.md", "paper_values.csv", "paper_pose_noise.csv", "config.yaml"):
        assert (out / name).stat().st_size > 0


def test_config_command_prints_every_row_setting(capsys):
    assert main(["config", "--config", "paper-row", "--derived"]) == 0
    printed = capsys.readouterr().out
    for section in ("protocol:", "pose_noise:", "blockwise:", "pose_noise.seed = seed"):
        assert section in printed


def test_passive_fields_of_view_meet_the_mid_plane_where_the_pinhole_puts_them(tmp_path):
    from types import SimpleNamespace

    from tpvp.scene.boxes import OrientedBox
    from tpvp.sensor.camera import D435
    from tpvp.viz.rows import field_of_view_footprints, plot_passive_sweep

    box = OrientedBox(np.zeros(3), np.eye(3), np.array([2.0, 0.6, 2.0]))
    room = SimpleNamespace(plant_box=box, view_box=OrientedBox(np.array([0.0, -1.0, 0.0]), np.eye(3), np.ones(3)),
                           initial_positions=np.array([[0.3, -1.5, 0.2], [0.0, -1.0, 0.0]]),
                           initial_look_ats=np.array([[0.3, 0.0, 0.2], [0.0, 0.0, 5.0]]))
    footprints = field_of_view_footprints(room, D435)
    # looking straight across from 1.5 m: image corner (u, v) lands at depth 1.5 along x right, y down
    expected = [[0.3 + 1.5 * (u - D435.cx) / D435.fx, 0.0, 0.2 - 1.5 * (v - D435.cy) / D435.fy]
                for u, v in ((0, 0), (D435.width, 0), (D435.width, D435.height), (0, D435.height))]
    np.testing.assert_allclose(footprints[0], expected, atol=1e-12)
    # a camera looking steeply up: the rays of its lower image corners still reach the plane
    assert np.isfinite(footprints[1][2:]).all() and (footprints[1][2:, 1] == pytest.approx(0.0))
    room.initial_positions, room.initial_look_ats = room.initial_positions[:1], room.initial_look_ats[:1]
    assert plot_passive_sweep(tmp_path / "sweep.png", room, np.random.default_rng(0).random((50, 3)) - 0.5,
                              D435).stat().st_size > 0


def test_a_new_candidate_source_and_route_are_one_registration_each(scene):
    """A row candidate source (a look-at prior) and a route added through the public hooks are
    chosen by name in the configuration; the pipeline needs nothing else."""
    from tpvp.config_loading import with_overrides
    from tpvp.path.route import ROW_ROUTES
    from tpvp.path.tsp import band_path

    @LOOK_AT_PRIORS.register("toy-centre", "every view looks at the plant box's centre")
    def toy_centre(context, targets, seed):
        centre = np.asarray(context.room.plant_box.center, dtype=np.float64)
        return round_robin_views(np.repeat(centre[None], 4, axis=0), context.room.candidate_positions,
                                 targets.rounds, seed, "toy-centre")

    @ROW_ROUTES.register("toy-lower-first", "the band path, lower band first")
    def lower_first(positions, split_height, start_position, config):
        return band_path(positions, split_height=split_height, start_position=start_position, first="lower",
                         config=config)

    try:
        config = with_overrides(QUICK, {"candidates": "toy-centre", "route": "toy-lower-first"})
        result = greenhouse.run_row_case(scene, config)
        assert np.allclose(result.candidates.look_ats, scene.room.plant_box.center)
        assert len(result.candidates) == 4 * QUICK.targets.rounds
        split = scene.room.view_box.center[2]
        heights = result.positions[:, 2]
        if (heights < split).any():
            assert heights[0] < split  # the toy route visits the lower band first
        assert result.coverage_captured < result.coverage <= 1.0
        with pytest.raises(ConfigError, match="unknown row route 'nowhere'; choose one of band, open, toy-lower-first"):
            with_overrides(QUICK, {"route": "nowhere"})
    finally:
        LOOK_AT_PRIORS.unregister("toy-centre")
        ROW_ROUTES.unregister("toy-lower-first")


def test_the_open_route_is_one_band(scene):
    from tpvp.path.route import row_path

    positions = scene.room.candidate_positions[::40]
    band, _ = row_path(scene.room, positions, QUICK.path)
    one, length = row_path(scene.room, positions, QUICK.path, route="open")
    assert len(one.bands[1]) == 0 and sorted(one.order) == sorted(band.order) == list(range(len(positions)))
    assert length == pytest.approx(one.length + scene.room.passive_cost)
