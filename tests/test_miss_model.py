"""The per-case miss model (tpvp.setcover.miss_model): its fit and conformal bound against brute
force, the planning target it asks, its file's errors, and the planner's use of it."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from tpvp.errors import ConfigError
from tpvp.setcover.config import SelectionConfig
from tpvp.setcover.miss_model import (MODEL_FILE, MissModel, _least_squares, fit_miss_model, load_miss_model,
                                      plan_summary, targets_missed)

FEATURES = ("unexplained", "fit")


def _rows(noise=0.0, seed=0, instances=12):
    """Cases of known truth: miss = 0.004 + 0.6 planned + 0.2 planned sphere + 0.002 sphere
    + 0.3 unexplained - 0.5 fit (+ noise), five planning targets each."""
    rng = np.random.default_rng(seed)
    rows = []
    for instance in range(instances):
        unexplained, fit, sphere = rng.uniform(0, 0.05), rng.uniform(0.003, 0.008), float(instance % 2)
        for target in (0.95, 0.97, 0.98, 0.99, 1.0):
            planned = 1 - target
            miss = 0.004 + 0.6 * planned + 0.2 * planned * sphere + 0.002 * sphere + 0.3 * unexplained - 0.5 * fit
            rows.append({"instance": f"i{instance}", "planned_miss": planned, "sphere": sphere,
                         "unexplained": unexplained, "fit": fit, "coverage": 1 - miss + noise * rng.normal()})
    return pd.DataFrame(rows)


def test_the_fit_recovers_a_linear_truth_and_its_bound_is_zero_without_noise():
    rows = _rows()
    model = fit_miss_model(rows, FEATURES, rows["instance"], rows["instance"])
    assert (model.intercept, model.planned, model.sphere_planned, model.sphere) == pytest.approx(
        (0.004, 0.6, 0.2, 0.002), abs=1e-12)
    assert model.coefficients == pytest.approx((0.3, -0.5), abs=1e-12)
    assert model.lower == pytest.approx(0.0, abs=1e-12)


def test_the_conformal_bound_is_that_of_the_held_out_plans_by_brute_force():
    rows = _rows(noise=0.004, seed=3, instances=30)
    rows["case"] = rows["instance"]
    rows["group"] = "g" + (rows["instance"].str[1:].astype(int) // 3).astype(str)  # three cases a group
    model = fit_miss_model(rows, FEATURES, rows["group"], rows["case"], asked=0.98, alpha=0.1)

    def design(t):
        return np.column_stack([np.ones(len(t)), t.planned_miss, t.planned_miss * t.sphere, t.sphere,
                                t.unexplained, t.fit])

    residuals = []
    for group in rows["group"].unique():  # each group's cases planned by a fit without it, by hand
        train = rows[rows["group"] != group]
        beta = np.linalg.lstsq(design(train), 1 - train.coverage, rcond=None)[0]
        for _, case in rows[rows["group"] == group].groupby("case"):
            predicted = 1 - design(case) @ beta  # per planning target, ascending planned miss
            targets = 1 - case.planned_miss.to_numpy()
            fine = np.linspace(0.95, 1.0, 50001)  # the model's target: the first that predicts 98.1 %
            first = case.iloc[[0] * len(fine)].assign(planned_miss=1 - fine)
            curve = 1 - design(first) @ beta
            wanted = fine[np.argmax(curve >= 0.981 - 1e-12)] if (curve >= 0.981 - 1e-12).any() else 1.0
            pick = np.flatnonzero(targets >= wanted - 2e-6)[np.argmin(targets[targets >= wanted - 2e-6])]
            residuals.append(predicted[pick] - case.coverage.to_numpy()[pick])
    n = len(residuals)
    k = math.ceil((n + 1) * 0.9)  # the conformal rank: the k-th smallest of predicted - true
    assert model.lower == pytest.approx(-sorted(residuals)[k - 1], abs=1e-12)
    full = _least_squares(rows, FEATURES)
    assert (model.intercept, model.planned, model.coefficients) == (full.intercept, full.planned, full.coefficients)


def test_the_planning_target_is_the_smallest_that_predicts_the_request_by_brute_force():
    model = MissModel(("unexplained",), (0.3,), 0.004, 0.6, 0.2, 0.002, lower=-0.012, lowest_target=0.9)
    grid = np.linspace(0.9, 1.0, 1001)
    for unexplained in (0.0, 0.01, 0.03, 0.2):
        for sphere in (0.0, 1.0):
            features = {"unexplained": unexplained, "sphere": sphere}
            point = np.array([model.predicted_coverage(features, t)[0] for t in grid])
            ok = grid[point >= 0.981 - 1e-12]
            expected = ok.min() if len(ok) else 1.0
            assert model.planning_target_for(features, 0.98) == pytest.approx(expected, abs=1e-4)
            assert model.predicted_coverage(features, 0.99)[1] == pytest.approx(
                model.predicted_coverage(features, 0.99)[0] - 0.012)
    # the full cover is all a bad prediction can ask, and never less than the calibrated range
    assert model.planning_target_for({"unexplained": 0.2, "sphere": 0.0}, 0.98) == 1.0
    assert model.planning_target_for({"unexplained": 0.0, "sphere": 0.0}, 0.5) == 0.9


def test_a_model_file_that_cannot_be_read_is_one_clear_error(tmp_path):
    good = MissModel(("unexplained",), (0.3,), 0.0, 0.6, 0.0, 0.0, -0.01).to_dict()
    assert MissModel.from_dict(good) == MissModel(("unexplained",), (0.3,), 0.0, 0.6, 0.0, 0.0, -0.01)
    for broken, words in (({**good, "version": 99}, "version 99"), ({**good, "features": ["height"]}, "height"),
                          ({**good, "lower": float("nan")}, "finite")):
        with pytest.raises(ConfigError, match=words):
            MissModel.from_dict(broken)
    missing = tmp_path / "none.json"
    with pytest.raises(ConfigError, match="selection.miss_model=constant"):
        load_miss_model(str(missing))
    (tmp_path / "bad.json").write_text("{ not json")
    with pytest.raises(ConfigError, match="bad.json: not a miss model"):
        load_miss_model(str(tmp_path / "bad.json"))


def test_the_shipped_model_is_the_fit_of_its_calibration_rows_and_they_hold_no_evaluation_plant():
    import sys
    from pathlib import Path

    from tpvp.experiments.species import HELIOS_SEEDS

    benchmarks = Path(__file__).resolve().parents[1] / "benchmarks"
    sys.path.insert(0, str(benchmarks))
    try:
        import miss_model as benchmark
    finally:
        sys.path.remove(str(benchmarks))
    rows = pd.read_csv(benchmark.ROWS)
    assert set(rows["split"]) == {"calibration"}
    generated = rows[rows["source"].isin(["generated", "series"])]
    assert generated["seed"].min() >= 10  # the evaluation seeds are 0-2
    assert set(rows.loc[rows["source"] == "dataset", "seed"]) == {HELIOS_SEEDS["calibration"]}
    assert set(rows["source"]) == {"generated", "series", "dataset"}
    model = load_miss_model()
    again = fit_miss_model(rows, model.features, benchmark.plant_key(rows), benchmark._case_key(rows), benchmark.ASKED)
    assert again.to_dict() | {"calibration": ""} == model.to_dict() | {"calibration": ""}
    assert json.loads(MODEL_FILE.read_text())["calibration"].endswith("miss_model_rows.csv")


def test_a_plan_summary_counts_each_group_by_brute_force():
    rng = np.random.default_rng(3)
    plans = pd.DataFrame({"view_space": rng.choice(["hemisphere", "sphere"], 40), "views": rng.integers(8, 14, 40),
                          "optimum_views": rng.integers(7, 11, 40), "coverage": rng.uniform(0.955, 0.995, 40),
                          "predicted": rng.uniform(0.97, 0.99, 40), "lower": rng.uniform(0.955, 0.975, 40)})
    summary = plan_summary(plans).set_index("view_space")
    for space in ("hemisphere", "sphere"):
        rows = [r for r in plans.to_dict("records") if r["view_space"] == space]
        n = len(rows)
        assert summary.loc[space, "cases"] == n
        assert summary.loc[space, "views_per_optimum"] == pytest.approx(sum(r["views"] / r["optimum_views"] for r in rows) / n)
        assert summary.loc[space, "coverage_mean"] == pytest.approx(sum(r["coverage"] for r in rows) / n)
        assert summary.loc[space, "coverage_min"] == min(r["coverage"] for r in rows)
        assert summary.loc[space, "below_97"] == sum(r["coverage"] < 0.97 for r in rows) / n
        assert summary.loc[space, "below_96"] == sum(r["coverage"] < 0.96 for r in rows) / n
        assert summary.loc[space, "below_bound"] == sum(r["coverage"] < r["lower"] for r in rows) / n
        assert summary.loc[space, "mean_abs_error"] == pytest.approx(
            sum(abs(r["predicted"] - r["coverage"]) for r in rows) / n)
    assert "below_bound" not in plan_summary(plans.drop(columns=["lower"]))
    without = plan_summary(plans.drop(columns=["optimum_views"]))
    assert "views_per_optimum" not in without and without.drop(columns="view_space").equals(
        summary.reset_index().drop(columns=["view_space", "views_per_optimum"]))


def test_the_targets_missed_are_named_at_their_thresholds():
    passing = dict(views_per_optimum=1.10, coverage_mean=0.98, below_97=0.05, below_96=0.0, below_bound=0.07,
                   mean_abs_error=0.005)
    failing = dict(views_per_optimum=1.1001, coverage_mean=0.9799, below_97=0.0501, below_96=0.01, below_bound=0.0299,
                   mean_abs_error=0.0051)
    summary = pd.DataFrame([passing, failing, {k: v for k, v in failing.items() if k != "below_bound"}])
    missed = targets_missed(summary, 0.05)
    assert missed[0] == []
    assert missed[1] == ["views <= 1.10x the optimum", "mean true coverage >= 98 %", "<= 5 % of cases below 97 %",
                         "no case below 96 %", "share below the bound within 2 points of the stated share",
                         "mean |predicted - true| <= 0.5 point"]
    assert missed[2] == [m for m in missed[1] if "bound" not in m]


def test_an_unknown_miss_model_is_refused():
    with pytest.raises(ConfigError, match="selection.miss_model must be one of constant, per-case"):
        SelectionConfig(coverage_target=0.98, miss_model="magic")


def test_the_planner_asks_the_models_target_and_says_how_sure_it_is():
    from dataclasses import replace

    from tpvp.config_loading import make_config
    from tpvp.pipeline.plan import plan, planning_surface
    from tpvp.scene.samples import load_sample
    from tpvp.setcover.miss_model import planning_features
    from tpvp.simulate.single_plant import build_scene, known, transfer

    config = make_config("plant", {"selection.coverage_target": 0.98, "selection.miss_model": "per-case"})
    scene = build_scene(load_sample("tomato_0305"), load_sample("tomato_0306"), config)
    transferred = transfer(scene, config)
    surface = planning_surface(known(scene), config, transferred)
    model, features = load_miss_model(), planning_features(config, transferred, surface)
    result = plan(known(scene), config, transferred, surface=surface)
    assert result.planning_target == model.planning_target_for(features, 0.98) != 0.99
    assert (result.predicted_coverage, result.predicted_coverage_lower) == model.predicted_coverage(
        features, result.planning_target)
    assert result.predicted_coverage_lower < result.predicted_coverage
    assert result.summary()["predicted_coverage"] == result.predicted_coverage
    # the constant rule (the default) and a given ratio set the target; the model still predicts
    for other, target in (({"miss_model": "constant"}, 0.99), ({"planning_miss_ratio": 0.25}, 0.995)):
        again = plan(known(scene), replace(config, selection=replace(config.selection, **other)), transferred,
                     surface=surface)
        assert again.planning_target == pytest.approx(target)
        assert again.predicted_coverage == model.predicted_coverage(features, again.planning_target)[0]
    assert make_config("plant").selection.miss_model == "constant"
    full = plan(known(scene), replace(config, selection=replace(config.selection, coverage_target=1.0)), transferred,
                surface=surface)
    assert full.planning_target == 1.0
    assert math.isnan(full.predicted_coverage) and "predicted_coverage" not in full.summary()


def test_the_calibration_figure_has_a_panel_per_rule_and_view_space_counting_cases_below_their_bound(monkeypatch, tmp_path):
    import tpvp.viz.miss_model as figure

    shown = {}
    monkeypatch.setattr(figure, "_save", lambda fig, path: shown.setdefault("titles", [a.get_title() for a in fig.axes]))
    rng = np.random.default_rng(1)
    rows = pd.DataFrame({"view_space": np.tile(["hemisphere", "sphere"], 10), "rule": np.repeat(["constant", "per-case"], 10),
                         "predicted": rng.uniform(0.975, 0.99, 20), "lower": rng.uniform(0.965, 0.975, 20),
                         "coverage": rng.uniform(0.96, 0.995, 20)})
    figure.plot_predicted_coverage(tmp_path / "f.png", rows)
    expected = [f"{space}, {rule} rule: 5 cases, "
                f"{int(sum(r['coverage'] < r['lower'] for r in rows.to_dict('records') if (r['rule'], r['view_space']) == (rule, space)))}"
                f" below their bound" for rule in ("constant", "per-case") for space in ("hemisphere", "sphere")]
    assert shown["titles"] == expected
