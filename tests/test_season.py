"""A season of one plant (tpvp.experiments.season): the chained sessions against a loop written
out by hand with the pipeline's public stages and measured by brute force, a row's sessions against
their plans executed by hand, and the growth series it runs on."""

from collections import Counter

import numpy as np
import pytest
from scipy import sparse
from scipy.spatial import cKDTree

from tpvp.config_loading import load_config
from tpvp.errors import ConfigError
from tpvp.experiments.season import SEASON_COLUMNS, prior_missing, run_season
from tpvp.nbv.warm_up import warm_up
from tpvp.pipeline.plan import Known, plan, transfer
from tpvp.simulate.depth_captures import fused_captures
from tpvp.simulate.world import build_scene
from tpvp.synthetic.plants import generate_growth_series, generate_plant

CONFIG = load_config("paper", {"selection.coverage_target": 0.98})


@pytest.fixture(scope="module")
def series():
    return [sample.points for sample in generate_growth_series("tomato", 0, sessions=3)]


def test_a_growth_series_is_the_plant_growing(series):
    assert len(series) == 3
    extents = [np.ptp(points, axis=0).max() for points in series]
    assert extents[0] < extents[1] < extents[2]  # it grows
    first = generate_growth_series("tomato", 0, sessions=1)[0]
    assert np.array_equal(first.points, generate_plant("tomato", 0).points)  # day 1 is the plant at stage 1
    for bad in (0, 2.5, True):
        with pytest.raises(ConfigError, match="sessions"):
            generate_growth_series("tomato", 0, sessions=bad)
    with pytest.raises(ConfigError, match="days"):
        generate_growth_series("tomato", 0, days=0)


def brute_chamfer(a, b) -> float:
    """Mean of both directed mean nearest-neighbour distances, by k-d trees."""
    return 0.5 * (cKDTree(b).query(a)[0].mean() + cKDTree(a).query(b)[0].mean())


def brute_prior_missing(plant, prior, voxel) -> float:
    """The share of the plant's voxels with no prior point in them or in one of their 26 neighbours."""
    held = set(map(tuple, np.floor(prior / voxel).astype(np.int64)))
    near = [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)]
    keys = np.floor(plant / voxel).astype(np.int64)
    counts = Counter(any((x + i, y + j, z + k) in held for i, j, k in near) for x, y, z in keys)
    return counts[False] / len(keys)


@pytest.mark.slow
def test_a_season_equals_its_sessions_chained_by_hand(series):
    """run_season against the sessions chained here, with nothing of run_case or of the season's
    chaining: each day the simulator renders today's truth and executes the warm-up, the planner's
    public stages (transfer, plan) plan from what the robot knows, written out; the session is
    measured by brute force on the truth, and the ``own`` arm's next prior is the model fused from
    its captures' depth images (scan frame)."""
    assert CONFIG.selection.replan_after == 0  # each session plans once
    table = run_season(series, CONFIG, arms=("truth", "own"), name="tomato 0")
    assert tuple(table.columns) == SEASON_COLUMNS
    assert table[["session", "arm"]].values.tolist() == [[2, "truth"], [2, "own"], [3, "truth"], [3, "own"]]
    own = series[0]
    for day in (1, 2):
        for arm in ("truth", "own"):
            prior = series[day - 1] if arm == "truth" else own
            scene = build_scene(prior, series[day], CONFIG)
            nbv = warm_up(scene, CONFIG)
            robot = Known(scene.previous, scene.sensor, scene.names, scene.view_space, scene.plant_from_scan,
                          scene.table_points, scene.reduction or {}, scene.previous_organs)
            result = plan(robot, CONFIG, transfer(robot, CONFIG, nbv))
            order = [*nbv.executed, *result.planned_views]
            truth = sparse.csr_matrix(scene.truth_visibility)
            seeable = set(truth.indices.tolist())
            seen = sorted({int(i) for view in order for i in truth.indices[truth.indptr[view]:truth.indptr[view + 1]]})
            fused = fused_captures(scene, order)  # the captures' depth images fused (tests/test_depth_captures.py)
            matrix = scene.plant_from_scan
            per_mm = 1e3 / np.cbrt(np.linalg.det(matrix[:3, :3]))  # planning-frame metres -> scan millimetres
            row = table[(table["session"] == day + 1) & (table["arm"] == arm)].iloc[0]
            assert (row["views"], row["coverage"], row["path_length_m"]) == \
                (len(order), len(seen) / len(seeable), result.path_length), (day, arm)
            assert row["prior_points"] == len(prior)
            planning = fused @ matrix[:3, :3].T + matrix[:3, 3]
            assert row["chamfer_fused_mm"] == pytest.approx(per_mm * brute_chamfer(planning, scene.current))
            assert row["registration_chamfer_mm"] == pytest.approx(per_mm * result.chamfer_after)
            plant = scene.grid.centres[scene.grid.countable]
            assert row["prior_missing"] == pytest.approx(
                brute_prior_missing(plant, result.clouds["warped"], CONFIG.gt_resolution))
            if arm == "own":
                next_own = fused
        own = next_own
    # session 2 starts both arms from day 1's full scan
    first = table[table["session"] == 2]
    assert first.iloc[0].drop("arm").equals(first.iloc[1].drop("arm"))


@pytest.mark.slow
def test_the_arm_without_prior_is_the_geometric_nbv_until_the_target(series):
    from tpvp.config_loading import with_overrides
    from tpvp.experiments.baselines import nbv_curve
    from tpvp.experiments.season import NONE_MAX_VIEWS

    row = run_season(series[:2], CONFIG, arms=("none",)).iloc[0]
    scene = build_scene(series[0], series[1], CONFIG)
    curve = nbv_curve(scene, with_overrides(CONFIG, {"nbv.method": "geometric"}), NONE_MAX_VIEWS)
    first = next(r for r in curve.itertuples() if r.coverage >= 0.98)  # brute force: the first step there
    assert (row["views"], row["coverage"], row["path_length_m"]) == (first.views, first.coverage, first.path_length)
    assert np.isnan(row["registration_chamfer_mm"]) and np.isnan(row["prior_missing"]) and row["prior_points"] == 0


def test_a_carried_prior_keeps_the_registered_prior_where_the_views_did_not_look(series):
    from tpvp.experiments.season import season_sessions
    from tpvp.scene.frame import scan_points

    first, second = season_sessions(series, CONFIG, arms=("own",), carry_unseen=True)
    voxel = CONFIG.gt_resolution
    held = {tuple(k) for k in np.floor(first.fused / voxel).astype(np.int64)}
    near = [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)]
    unseen = np.array([not any((x + i, y + j, z + k) in held for i, j, k in near)
                       for x, y, z in np.floor(first.warped / voxel).astype(np.int64)])
    assert 0 < unseen.sum() < len(unseen)
    expected = scan_points(first.scene.plant_from_scan, np.concatenate([first.fused, first.warped[unseen]]))
    assert np.allclose(second.prior, expected)


def test_prior_missing_counts_the_plant_the_prior_holds_nothing_near():
    scene = build_scene(generate_plant("tomato", 0).points, generate_plant("tomato", 0).points, CONFIG)
    plant = scene.grid.centres[scene.grid.countable]
    voxel = CONFIG.gt_resolution
    assert prior_missing(scene, plant, voxel) == 0.0
    half = plant[plant[:, 2] < np.median(plant[:, 2])]
    missing = prior_missing(scene, half, voxel)
    # brute force: a plant voxel is held when a prior point lies within one voxel in every axis
    keys, held = np.floor(plant / voxel), np.floor(half / voxel)
    expected = np.mean([not (np.abs(held - key) <= 1).all(axis=1).any() for key in keys])
    assert missing == pytest.approx(expected) and 0.2 < missing < 0.8


def test_a_season_needs_two_scans_and_known_arms(series):
    with pytest.raises(ConfigError, match="at least 2 scans"):
        run_season(series[:1], CONFIG)
    with pytest.raises(ConfigError, match="unknown season arm 'oracle'"):
        run_season(series, CONFIG, arms=("oracle",))


@pytest.mark.slow
def test_the_season_command_writes_its_tables_and_figure_and_resumes(tmp_path, capsys):
    import pandas as pd

    from tpvp.cli import main

    argv = ["experiments", "season", "--quick", "--view-spaces", "hemisphere", "--replan-after", "0", "--workers", "1",
            "--output", str(tmp_path / "out"), "--cache", str(tmp_path / "cache")]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "1 plant(s) x 3 arm(s), 3 sessions each, coverage target 0.98" in out
    totals = pd.read_csv(tmp_path / "out" / "season_totals.csv")
    assert totals["arm"].tolist() == ["truth", "own", "none"] and (totals["sessions"] == 2).all()
    assert (totals["replan_after"] == 0).all()
    assert (tmp_path / "out" / "figures" / "season.png").stat().st_size > 0
    cached = sorted((tmp_path / "cache").glob("*.parquet"))
    assert len(cached) == 3  # one per (plant, arm): a second run reads them
    assert main(argv[:-4] + ["--output", str(tmp_path / "again"), "--cache", str(tmp_path / "cache")]) == 0
    assert pd.read_csv(tmp_path / "again" / "raw_cases.csv").drop(columns=["seconds_task"]).equals(
        pd.read_csv(tmp_path / "out" / "raw_cases.csv").drop(columns=["seconds_task"]))


@pytest.mark.slow
def test_a_row_season_chains_its_sessions_from_its_own_reconstruction(tmp_path):
    from tpvp.config_loading import make_config
    from tpvp.experiments import season
    from tpvp.simulate.row_cases import QUICK
    from tpvp.pipeline.plan import plan as plan_row
    from tpvp.visibility import safe_visibility

    case = season.RowSeasonCase("room1", 0, sessions=3)
    config = case.config(make_config("row", QUICK))
    series = season._row_series(case, config, tmp_path)
    sessions = list(season.row_season_sessions(series.scans, config, ("truth", "own"), cache_dir=series.cache_dir))
    assert [(s.row["session"], s.row["arm"]) for s in sessions] == [(2, "truth"), (2, "own"), (3, "truth"), (3, "own")]
    # session 2 starts both arms from day 1's full scan; session 3's own prior is what session 2 saw
    assert sessions[0].row == {**sessions[1].row, "arm": "truth"}
    assert np.array_equal(sessions[3].prior, sessions[1].fused)
    assert len(sessions[1].fused) < len(series.scans[1])
    for s in sessions[1:]:
        # the planner on what the passive sweep saw, its views executed on the truth here
        scene, planned = s.scene, plan_row(s.scene.known, config)
        executed = safe_visibility(scene.grid, planned.positions, planned.look_ats, config.sensor)
        seen = set(scene.passive_seen.tolist()) | set(executed.indices.tolist())
        oracle = set(scene.oracle.tolist())
        assert (s.row["views"], s.row["path_length_m"]) == (planned.n_views, planned.path_length)
        assert planned.n_views == len(scene.room.initial_positions) + len(planned.planned_views)
        assert s.row["coverage"] == len(seen & oracle) / len(oracle)
        # what it fused is one point in each voxel it saw, the passive sweep's included
        fused_ids = scene.grid.ids_of(np.floor(s.fused / scene.grid.resolution).astype(np.int64))
        assert len(fused_ids) == len(seen) and set(fused_ids.tolist()) == seen
        assert s.row["prior_points"] == len(s.prior)


def test_what_a_session_missed_partitions_todays_plant(series):
    from tpvp.experiments.season import season_sessions

    session = next(season_sessions(series[:2], CONFIG, arms=("own",)))
    missed = session.missed(CONFIG.gt_resolution)
    counts = {k: len(v) for k, v in missed.items()}
    assert sum(counts.values()) == session.scene.grid.countable.sum()
    seeable = counts["seen"] + counts["missed_in_prior"] + counts["missed_not_in_prior"]
    assert seeable == len(session.scene.oracle)
    assert counts["seen"] / seeable == pytest.approx(session.row["coverage"])


def test_a_dataset_season_is_each_plants_scans_in_date_order(tmp_path, series, capsys):
    from pathlib import Path

    from tpvp.cli import main
    from tpvp.experiments.season import dataset_season_cases
    from tpvp.io import write_point_cloud

    dates = ["2020-03-05", "2020-03-06", "2020-03-07"]
    for date, points in zip(dates, series):
        write_point_cloud(tmp_path / f"T01_{date}.ply", points)
    rows = [f"Tomato01,tomato,{a},{b},1,T01_{a}.ply,T01_{b}.ply" for a, b in zip(dates, dates[1:])]
    (tmp_path / "pairs.csv").write_text("plant,species,previous_date,current_date,days_apart,previous_file,"
                                        "current_file\n" + "\n".join(reversed(rows)) + "\n")
    (case,) = dataset_season_cases(tmp_path, view_spaces=("hemisphere",), replan_after=(0,))
    assert [Path(f).name for f in case.files] == [f"T01_{d}.ply" for d in dates]
    assert case.labels()["plant"] == "Tomato01" and case.species == "tomato"
    with pytest.raises(ConfigError, match="no plant named Maize09"):
        dataset_season_cases(tmp_path, plants=["Maize09"])
    argv = ["experiments", "season", "--dataset", str(tmp_path), "--view-spaces", "hemisphere", "--replan-after", "0",
            "--arms", "truth", "--workers", "1", "--output", str(tmp_path / "out"), "--cache", str(tmp_path / "cache")]
    assert main(argv) == 0
    import pandas as pd
    from tpvp.io import read_point_cloud

    raw = pd.read_csv(tmp_path / "out" / "raw_cases.csv")
    expected = run_season([read_point_cloud(f, units="m") for f in case.files], case.config(CONFIG), arms=("truth",))
    assert raw["views"].tolist() == expected["views"].tolist() and raw["plant"].eq("Tomato01").all()
    # pairs that do not chain day by day are refused
    (tmp_path / "pairs.csv").write_text("plant,species,previous_date,current_date,days_apart,previous_file,"
                                        "current_file\n" + rows[0] + "\n" + rows[1].replace("03-06,", "03-04,", 1) + "\n")
    assert main(argv) == 2
    assert "do not chain day by day" in capsys.readouterr().err


def test_the_season_plans_in_the_known_frame_under_one_sensor():
    """Every case plans in ``scene.frame = previous`` unless --frame says otherwise; --noise sets
    every arm's sensor; a configuration's frame or sensor that the options contradict is refused."""
    from tpvp.cli import EVERY, build_parser
    from tpvp.commands.experiments import season_setup

    def configs(*argv):
        config, cases = season_setup(build_parser(EVERY).parse_args(["experiments", "season", "--quick", *argv]))
        return [case.config(config) for case in cases]

    assert {(c.scene.frame, c.sensor.noise) for c in configs()} == {("previous", "ideal")}
    assert {(c.scene.frame, c.sensor.noise) for c in configs("--frame", "current", "--noise", "phone-lidar")} == \
        {("current", "phone-lidar")}
    assert {(c.scene.frame, c.sensor.noise) for c in configs("--config", "realistic")} == {("previous", "arm-rgbd")}
    with pytest.raises(ConfigError, match="scene.frame='previous'.*--frame"):
        configs("--config", "realistic", "--frame", "current")
    with pytest.raises(ConfigError, match="--noise phone-lidar and sensor.noise='arm-rgbd'"):
        configs("--noise", "phone-lidar", "--set", "sensor.noise=arm-rgbd")
    with pytest.raises(ConfigError, match="--noise applies to the plants' season"):
        configs("--rows", "--noise", "phone-lidar")
