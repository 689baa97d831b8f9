"""The plant-experiment runner: every method on tiny cases, the cache, the tables, bad input."""

import pandas as pd
import pytest

from tpvp.cli import main
from tpvp.config_loading import make_config
from tpvp.errors import ConfigError, InputFileError
from tpvp import parallel
from tpvp.experiments import plants, runner
from tpvp.experiments.comparison import compare_methods
from tpvp.experiments.results import markdown, write_results

CONFIG = make_config("plant", {"registration.embedded_deformation.iterations": 20})


@pytest.fixture(scope="module")
def tiny_cases():
    instances = plants.generated_instances(seeds=(0,), species=("maize",))
    return plants.case_list(instances, view_spaces=("tammes-hemisphere:12",), rotations=(0.0,), initial_views=(0, 5))


@pytest.fixture(scope="module")
def raw(tiny_cases, tmp_path_factory):
    cache = tmp_path_factory.mktemp("cache")
    table = plants.run_experiments(tiny_cases, list(plants.PLANT_METHODS.defaults()), CONFIG, cache_dir=cache, progress=False)
    return table, cache


def test_every_method_gives_rows_for_every_case(raw, tiny_cases):
    table, _ = raw
    for method in plants.PLANT_METHODS.defaults():
        rows = table[table["method"] == method]
        assert rows["initial_view"].nunique() == len(tiny_cases), method
    for method in ("ma-scvp", "ma-scvp-oracle"):  # a 12-view space: the learned planners say they do not apply
        assert (table[table["method"] == method]["status"] == plants.NOT_APPLICABLE).all()
    gmc = table[table["method"] == "gmc"]
    for case_rows in gmc.groupby("initial_view"):
        views = case_rows[1]["views"].to_numpy()
        assert list(views) == list(range(1, len(views) + 1))  # row k executed exactly k views
    ours = table[table["method"] == "ours"]
    assert (ours["coverage"] > 0.8).all() and (ours["views"] >= 2).all()
    optimum = table[table["method"] == "optimum"]
    assert set(optimum["target"]) == {1.0, 0.98}
    one_shot = table[table["optimum_views_same_coverage"].notna()]
    assert set(one_shot["method"]) == {"ours", "ours-no-inflation", "initial-view-only",
                                       "initial-view-only-no-inflation", "one-shot-no-prior"}
    # nothing sees as much with fewer views than the optimum; the full optimum bounds it from above
    assert (one_shot["optimum_views_same_coverage"] <= one_shot["views"]).all()
    full = optimum[optimum["target"] == 1.0].set_index("initial_view")["views"]
    assert (one_shot["optimum_views_same_coverage"] <= one_shot["initial_view"].map(full)).all()


def test_tables_hold_every_method_row(raw):
    table, _ = raw
    out = plants.tables(table)
    methods = set(out["table1_coverage_effort"]["method"])
    assert methods == set(plants.PLANT_METHODS.defaults())
    assert set(out["table3_inflation"]["method"]) == {"ours", "ours-no-inflation"}
    assert set(out["table4_registration"]["method"]) == {"ours", "initial-view-only"}
    assert plants.NOT_APPLICABLE in set(out["table1_coverage_effort"]["status"].dropna())
    assert "| ours |" in markdown(out["table1_coverage_effort"])


def test_results_folder_holds_tables_figures_and_the_comparison(raw, tiny_cases, tmp_path):
    table, _ = raw
    case = plants.comparison_case(tiny_cases)
    write_results(plants.PLANT_EXPERIMENTS, tmp_path / "out", table, CONFIG, comparison=case)
    out = tmp_path / "out"
    for name in ("raw_cases.csv", "table1_coverage_effort.md", "figures/coverage_effort_generated.png",
                 "figures/views_per_species_generated.png", "comparison/comparison.png", "comparison/comparison.rrd"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    compared = pd.read_csv(out / "comparison" / "comparison.csv")
    assert list(compared["method"]) == ["gmc", "ours", "optimum"]  # 12 views: no MA-SCVP
    assert compared["views"].nunique() == 1  # a matched view count
    for row in compared.itertuples():
        assert int(row.order.split()[0]) == case.initial_view  # the same initial view
    # nothing with that many views sees more than the optimum
    assert compared["coverage"].max() == pytest.approx(compared.set_index("method").loc["optimum", "coverage"])
    # the oracle voxels each plan missed: coverage = 1 - missed / |oracle| for every plan alike
    oracle = len(plants.case_scene(case, case.config(CONFIG)).oracle)
    assert compared["coverage"].tolist() == pytest.approx((1 - compared["missed_voxels"] / oracle).tolist())


def test_the_comparison_shows_ma_scvp_on_its_32_views():
    case = plants.case_list(plants.generated_instances(seeds=(0,), species=("maize",)), view_spaces=("sphere",),
                            rotations=(0.0,), initial_views=(17,))[0]
    config = case.config(CONFIG)
    plans = {p.method: p for p in compare_methods(plants.case_scene(case, config), config)}
    assert list(plans) == ["gmc", "ma-scvp", "ours", "optimum"]
    learned = plans["ma-scvp"]
    assert learned.order[0] == 17 and all(0 <= v < 32 for v in learned.order)  # the sphere's first 32 views only
    assert len(set(learned.order)) == len(learned.order) and 0 < learned.coverage <= 1
    assert len({len(p.order) for m, p in plans.items() if m != "ma-scvp"}) == 1  # matched: Ours' count
    # nothing with as many views sees more than the optimum
    optimum = plans["optimum"]
    assert max(p.coverage for p in plans.values() if len(p.order) <= len(optimum.order)) == pytest.approx(optimum.coverage)


def test_the_cache_is_reused_and_an_interrupted_run_resumes(raw, tiny_cases, monkeypatch):
    table, cache = raw
    files = sorted(cache.glob("*.parquet"))
    assert len(files) == len(tiny_cases) * len(plants.PLANT_METHODS.defaults())
    files[0].unlink()  # as if the run had been interrupted before this task
    calls = []
    original = plants.PLANT_METHODS.get("ours")

    def counting(scene, config):
        calls.append(1)
        return original(scene, config)

    monkeypatch.setitem(plants.PLANT_METHODS._entries, "ours", counting)
    again = plants.run_experiments(tiny_cases, list(plants.PLANT_METHODS.defaults()), CONFIG, cache_dir=cache, progress=False)
    assert len(sorted(cache.glob("*.parquet"))) == len(files)
    assert len(calls) <= 1  # only the missing task ran (if it was an "ours" task)
    timings = [c for c in table.columns if c.startswith("seconds")]
    pd.testing.assert_frame_equal(again.drop(columns=timings), table.drop(columns=timings), check_dtype=False)
    # a changed configuration never reuses rows
    changed = make_config("plant", {"registration.embedded_deformation.iterations": 21})
    assert runner.task_key(tiny_cases[0], "ours", changed) != runner.task_key(tiny_cases[0], "ours", CONFIG)


def test_methods_sharing_a_registration_give_the_rows_of_separate_runs(raw, tiny_cases, monkeypatch):
    """Ours and Ours w/o inflation share one warm-up + registration per process; run apart (a fresh
    transfer each) they give the same rows."""
    table, _ = raw
    timings = [c for c in table.columns if c.startswith("seconds")]
    case = tiny_cases[1]
    for method in ("ours-no-inflation", "initial-view-only-no-inflation"):
        runner.clear_shared()
        alone = plants.run_task(case, method, CONFIG).drop(columns=["seconds_task"])
        shared = table[(table["method"] == method) & (table["initial_view"] == case.initial_view)]
        columns = [c for c in alone.columns if c not in timings]
        pd.testing.assert_frame_equal(alone[columns].reset_index(drop=True),
                                      shared[columns].reset_index(drop=True), check_dtype=False)
    before = runner.task_key(case, "ours", CONFIG)
    monkeypatch.setattr(runner, "RESULTS_VERSION", runner.RESULTS_VERSION + 1)
    assert runner.task_key(case, "ours", CONFIG) != before  # a change of results never reuses rows
    before = runner.task_key(case, "ours", CONFIG)
    monkeypatch.setattr(runner, "code_digest", lambda: "0" * 64)  # any change to the code
    assert runner.task_key(case, "ours", CONFIG) != before  # a row of other code is never read back


def test_the_code_digest_names_the_code(tmp_path):
    from tpvp.provenance import code_digest, code_files

    for folder in ("tpvp/data/results", "tpvp/__pycache__", "data_tools"):
        (tmp_path / folder).mkdir(parents=True)
    (tmp_path / "tpvp/stage.py").write_text("a = 1\n")
    (tmp_path / "data_tools/grow.py").write_text("b = 2\n")
    first = code_digest(tmp_path)
    (tmp_path / "tpvp/data/results/table1.parquet").write_bytes(b"rows")  # results and byte code are not code
    (tmp_path / "tpvp/__pycache__/stage.cpython-311.pyc").write_bytes(b"compiled")
    code_digest.cache_clear()
    assert code_digest(tmp_path) == first
    assert [p.name for p in code_files(tmp_path)] == ["grow.py", "stage.py"]
    (tmp_path / "tpvp/stage.py").write_text("a = 2\n")
    code_digest.cache_clear()
    assert code_digest(tmp_path) != first
    code_digest.cache_clear()


def test_bad_input_is_one_line(tmp_path, capsys):
    with pytest.raises(InputFileError, match="no pairs.csv"):
        plants.dataset_instances(tmp_path)
    (tmp_path / "pairs.csv").write_text("plant,species\nTomato01,tomato\n")
    with pytest.raises(InputFileError, match="missing columns"):
        plants.dataset_instances(tmp_path)
    with pytest.raises(ConfigError, match="unknown plant experiment method 'magic'"):
        plants.run_experiments(plants.default_cases(quick=True), ["magic"])
    with pytest.raises(ConfigError, match="case list is empty"):
        plants.case_list([], ("hemisphere",))
    assert main(["experiments", "plants", "--quick", "--methods", "magic", "--output", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "magic" in err[0]


def test_a_prepared_dataset_becomes_instances(tmp_path):
    from tpvp.io import write_point_cloud
    from tpvp.synthetic.plants import generate_session_pair

    pair = generate_session_pair("tomato", 1)
    for name, points in (("T01_a.ply", pair.previous.points), ("T01_b.ply", pair.current.points)):
        write_point_cloud(tmp_path / name, points)
    (tmp_path / "pairs.csv").write_text("plant,species,previous_date,current_date,days_apart,previous_file,current_file\n"
                                        "Tomato01,tomato,2020-03-05,2020-03-06,1,T01_a.ply,T01_b.ply\n"
                                        "Tomato04,tomato,2020-03-05,2020-03-06,1,T01_a.ply,T01_b.ply\n")
    assert [i.name for i in plants.dataset_instances(tmp_path, paper_subset=True)] == ["Tomato01-2020-03-05-2020-03-06"]
    (instance,) = plants.dataset_instances(tmp_path, plants=["Tomato04"])
    previous, current = instance.load()
    assert len(previous) == len(pair.previous.points)
    with pytest.raises(ConfigError, match="selects no pair"):
        plants.dataset_instances(tmp_path, plants=["Maize09"])


def test_the_same_rows_on_a_dask_cluster(tiny_cases, tmp_path, monkeypatch):
    from distributed import Client, LocalCluster

    monkeypatch.setattr(parallel, "SCHEDULER_TIMEOUT_S", 2)
    methods = ["one-shot-no-prior", "ma-scvp"]
    local = plants.run_experiments(tiny_cases, methods, CONFIG, cache_dir=tmp_path / "local", progress=False)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        by_address = plants.run_experiments(tiny_cases, methods, CONFIG, cache_dir=tmp_path / "cluster",
                                            progress=False, scheduler=cluster.scheduler_address)
        with Client(cluster) as client:
            by_client = plants.run_experiments(tiny_cases, methods, CONFIG, cache_dir=None, progress=False,
                                               scheduler=client)
    timings = [c for c in local.columns if c.startswith("seconds")]
    for remote in (by_address, by_client):
        pd.testing.assert_frame_equal(remote.drop(columns=timings), local.drop(columns=timings), check_dtype=False)
    with pytest.raises(ConfigError, match="cannot reach the Dask scheduler"):
        plants.run_experiments(tiny_cases[:1], ["ma-scvp"], CONFIG, progress=False, scheduler="tcp://127.0.0.1:1")


def test_a_new_one_shot_method_is_one_registration(tiny_cases, tmp_path, capsys):
    """A Table I method added through the public hook runs in the protocol by default and is listed
    in the command's help; nothing else names it."""
    plants.register_one_shot("toy-no-warm-up", {"nbv.warm_up_views": 0, "inflation.enabled": False},
                             "a toy variant for this test")
    try:
        assert plants.PLANT_METHODS.defaults()[-1] == "toy-no-warm-up"
        table = plants.run_experiments(tiny_cases[:1], ["toy-no-warm-up", "initial-view-only-no-inflation"], CONFIG,
                                       cache_dir=tmp_path, progress=False)
        toy, same = (table[table["method"] == m].drop(columns=["method"]).filter(regex="^(?!seconds)")
                     for m in ("toy-no-warm-up", "initial-view-only-no-inflation"))
        assert len(toy) == 1 and toy.reset_index(drop=True).equals(same.reset_index(drop=True))  # the same overrides
        with pytest.raises(SystemExit):
            main(["experiments", "plants", "--help"])
        assert "toy-no-warm-up" in capsys.readouterr().out.replace("\n", " ")
    finally:
        plants.PLANT_METHODS.unregister("toy-no-warm-up")
        plants.ONE_SHOT_METHODS.pop("toy-no-warm-up")
