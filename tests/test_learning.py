"""The learned baselines: input grid, labels, sampling, networks, training, weight files, methods."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import torch
from scipy import sparse

from tpvp.errors import ConfigError, InputFileError
from tpvp.learning import dataset as ds
from tpvp.learning.grid import (L_HIT, L_MAX, L_MIN, L_MISS, GridGeometry, log_odds_grid, occupancy_grid,
                                scan_cells)
from tpvp.learning.models import GainNet, ViewSetNet
from tpvp.learning.training import TrainConfig, evaluate, gain_metrics, train, view_set_metrics
from tpvp.learning.weights import load_weights, save_weights, shipped_path


def _probability(log_odds):
    return 1 / (1 + math.exp(-log_odds))


# --------------------------------------------------------------------------------------------------
# the input grid
# --------------------------------------------------------------------------------------------------


def test_grid_hand_built_example():
    # a 4-cell line along x: the camera at x = -2 sees a point in cell 2
    geometry = GridGeometry(np.zeros(3), 1.0)
    camera, point = np.array([[-2.0, 0.5, 0.5]]), [np.array([[2.5, 0.5, 0.5]])]
    once = log_odds_grid(geometry, camera, point, cells=4)
    expected = np.zeros((4, 4, 4))
    expected[0, 0, 0] = expected[1, 0, 0] = L_MISS
    expected[2, 0, 0] = L_HIT
    np.testing.assert_array_equal(once, expected)
    twice = log_odds_grid(geometry, np.repeat(camera, 2, 0), point * 2, cells=4)
    assert _probability(twice[0, 0, 0]) == pytest.approx(0.3077, abs=1e-4)  # OctoMap's values
    assert _probability(twice[2, 0, 0]) == pytest.approx(0.8448, abs=1e-4)
    assert twice[3, 0, 0] == 0 and twice[0, 1, 0] == 0  # unknown stays at log-odds 0
    # clamping: many misses stop at 0.1192, many hits at 0.971
    many = log_odds_grid(geometry, np.repeat(camera, 12, 0), point * 12, cells=4)
    assert many[0, 0, 0] == pytest.approx(L_MIN) and many[2, 0, 0] == pytest.approx(L_MAX)


def test_occupancy_grid_values_and_layout():
    # camera above a point: the column above it is free, its cell occupied, everything else 0.5
    point = np.array([[0.05, 0.02, 0.03]])
    grid = occupancy_grid(np.zeros(3), [[0.05, 0.02, 5.0]], [point])
    assert grid.dtype == np.float32 and grid.shape == (32, 32, 32)
    values = {round(float(v), 4) for v in np.unique(grid)}
    assert values == {0.4, 0.5, 0.7}
    occupied = np.argwhere(grid > 0.5)
    assert len(occupied) == 1
    x, y, z = occupied[0]
    assert (grid[x, y, z + 1:] == np.float32(0.4)).all() and (grid[x, y, :z] == 0.5).all()


def test_occupied_wins_over_free_within_a_scan():
    geometry = GridGeometry(np.zeros(3), 1.0)
    camera = np.array([-2.0, 0.5, 0.5])
    occupied, free = scan_cells(geometry, camera, np.array([[1.5, 0.5, 0.5], [3.5, 0.5, 0.5]]), cells=4)
    flat = np.ravel_multi_index
    assert set(occupied) == {flat((1, 0, 0), (4, 4, 4)), flat((3, 0, 0), (4, 4, 4))}
    assert set(free) == {flat((0, 0, 0), (4, 4, 4)), flat((2, 0, 0), (4, 4, 4))}


def test_ray_insertion_matches_dense_sampling():
    rng = np.random.default_rng(3)
    geometry = GridGeometry(np.zeros(3), 1.0)
    for _ in range(60):
        camera = rng.uniform(-6, 14, 3)
        end = rng.uniform(-1, 9, 3)
        occupied, free = scan_cells(geometry, camera, end[None], cells=8)
        t = np.linspace(0, 1, 400_001)[:, None]
        cells = np.floor(camera + t * (end - camera)).astype(int)
        cells = cells[((cells >= 0) & (cells < 8)).all(axis=1)]
        crossed = set(np.ravel_multi_index(cells.T, (8, 8, 8))) if len(cells) else set()
        end_cell = np.floor(end).astype(int)
        inside = ((end_cell >= 0) & (end_cell < 8)).all()
        end_id = {int(np.ravel_multi_index(end_cell, (8, 8, 8)))} if inside else set()
        assert set(occupied) == end_id
        assert set(free) == crossed - end_id


# --------------------------------------------------------------------------------------------------
# labels and sampling
# --------------------------------------------------------------------------------------------------


def _brute_force_cover_size(seen: np.ndarray, state) -> int:
    remaining = ~seen[list(state)].any(axis=0)
    free_views = [v for v in range(len(seen)) if v not in state]
    for k in range(len(free_views) + 1):
        for subset in itertools.combinations(free_views, k):
            if not remaining.any() or seen[list(subset)].any(axis=0)[remaining].all():
                return k
    raise AssertionError("not coverable")


@pytest.mark.parametrize("seed", range(6))
def test_cover_label_is_a_minimum_set_cover(seed):
    rng = np.random.default_rng(seed)
    seen = rng.random((9, 40)) < 0.2
    seen[rng.integers(0, 9, 40), np.arange(40)] = True  # every voxel visible from some view
    state = sorted(rng.choice(9, size=int(rng.integers(1, 3)), replace=False).tolist())
    label, optimal = ds.cover_label(sparse.csr_matrix(seen), state)
    assert optimal
    assert not label[state].any()
    assert (seen[state].any(axis=0) | seen[label].any(axis=0)).all()
    assert label.sum() == _brute_force_cover_size(seen, state)


def test_greedy_and_gains_on_a_hand_example():
    seen = np.array([[1, 1, 0, 0, 0], [0, 1, 1, 1, 0], [0, 0, 0, 1, 1], [1, 0, 0, 0, 0]], bool)
    trajectories = ds.greedy_trajectories(seen)
    assert trajectories[0] == [0, 1, 2]  # view 1 adds 2, then view 2 adds 1
    assert trajectories[3] == [3, 1, 2]
    np.testing.assert_allclose(ds.coverage_gains(seen, [0]), [0, 0.4, 0.4, 0])
    d = ds.mean_gains(seen, trajectories)
    assert d[0] == pytest.approx(np.mean(seen.sum(1)) / 5)


def test_long_tail_states_follow_the_rule():
    rng = np.random.default_rng(0)
    seen = rng.random((32, 400)) < 0.12
    trajectories = ds.greedy_trajectories(seen)
    d = ds.mean_gains(seen, trajectories)
    states = ds.long_tail_states(seen, 4, np.random.default_rng(1))
    assert states == ds.long_tail_states(seen, 4, np.random.default_rng(1))  # deterministic
    prefixes = {frozenset(t[:m]) for t in trajectories for m in range(1, len(t))}
    assert all(frozenset(s) in prefixes for s in states)
    assert len({frozenset(s) for s in states}) == len(states)
    sizes = np.bincount([len(s) for s in states], minlength=32)
    for m in range(1, 32):
        available = len({frozenset(t[:m]) for t in trajectories if len(t) > m})
        assert sizes[m] == min(math.ceil(4 * d[m] / d[1] - 1e-12), available)


def test_dataset_config_keeps_splits_disjoint():
    with pytest.raises(ConfigError, match="overlap"):
        ds.DatasetConfig(validation_seed=1000)
    with pytest.raises(ConfigError, match="Table I"):
        ds.DatasetConfig(train_seed=0)


# --------------------------------------------------------------------------------------------------
# a tiny generated dataset, training, weights
# --------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    folder = tmp_path_factory.mktemp("learning") / "data"
    config = ds.DatasetConfig(train_plants=2, validation_plants=1, test_plants=1, rotations=2, held_out_rotations=1)
    manifest = ds.generate_dataset(folder, config, workers=1, progress=False)
    return ds.load_dataset(folder), manifest


def test_generated_dataset_is_consistent(tiny_dataset):
    data, manifest = tiny_dataset
    index = data.index
    assert manifest["states"] == len(index) and set(index["split"]) == set(ds.SPLITS)
    assert index["label_optimal"].all()
    labels, states, gains = np.asarray(data["labels"]), np.asarray(data["states"]), np.asarray(data["gains"])
    assert not (labels & states).any() and (gains[states] == 0).all()
    assert (labels.sum(1) == index["label_size"]).all() and (states.sum(1) == index["size"]).all()
    # a view the minimum cover needs adds something
    assert (gains[labels] > 0).all()
    grids = np.asarray(data["grids"], dtype=np.float32)
    assert grids.min() >= 0.1192 - 1e-3 and grids.max() <= 0.971 + 1e-3 and (grids == 0.5).any()


def test_dataset_generation_is_deterministic(tiny_dataset, tmp_path):
    data, manifest = tiny_dataset
    config = ds.DatasetConfig(**manifest["config"] | {"species": tuple(manifest["config"]["species"])})
    plant = config.plants("train")[0]
    again = ds.plant_samples(plant, "train", config)[0]
    rows = np.flatnonzero((data.index["species"] == plant[0]) & (data.index["seed"] == plant[1])
                          & (data.index["rotation_deg"] == 0) & (data.index["split"] == "train"))
    assert len(rows) == len(again["index"])
    for name in ("grids", "labels", "gains", "clouds", "states"):
        np.testing.assert_array_equal(np.asarray(data[name][rows]), again[name])


def test_incomplete_dataset_is_refused(tmp_path):
    with pytest.raises(InputFileError, match="manifest"):
        ds.load_dataset(tmp_path)


@pytest.mark.slow
def test_training_two_epochs_lowers_the_loss(tiny_dataset):
    data, _ = tiny_dataset
    rows = data.split("train")
    for kind in ("ma-scvp", "pc-nbv"):
        config = TrainConfig(batch_size=8, states_per_round=len(rows), max_rounds=2, patience=5, threads=1)
        result = train(kind, data, config, progress=False)
        assert list(result.history["epochs"]) == [1.0, 2.0]
        # the objective being minimised (train mode, penalty included), epoch 2 against epoch 1
        assert result.history["train_loss"].iat[1] < result.history["train_loss"].iat[0], kind
    torch.manual_seed(0)  # train() seeds the same way: the same initial network
    from tpvp.learning.models import build_model

    before = evaluate("ma-scvp", build_model("ma-scvp"), data, rows, config)["loss"]
    after = evaluate("ma-scvp", train("ma-scvp", data, config, progress=False).model, data, rows, config)["loss"]
    assert after < before


def test_training_is_deterministic_given_the_seed(tiny_dataset):
    data, _ = tiny_dataset
    config = TrainConfig(batch_size=8, states_per_round=16, max_rounds=2, patience=5, threads=1)
    for kind in ("ma-scvp", "pc-nbv"):
        first, second = (train(kind, data, config, progress=False) for _ in range(2))
        pd_first, pd_second = first.model.state_dict(), second.model.state_dict()
        assert all(torch.equal(pd_first[k], pd_second[k]) for k in pd_first), kind
        assert first.history["validation_loss"].tolist() == second.history["validation_loss"].tolist()


def test_metrics_on_hand_examples():
    probabilities = np.array([[0.9, 0.6, 0.1, 0.7]])
    labels = np.array([[1, 0, 1, 0]], bool)
    states = np.array([[0, 0, 0, 1]], bool)  # view 3 taken: its score is ignored
    m = view_set_metrics(probabilities, labels, states)
    assert m["recall"] == 0.5 and m["precision"] == 0.5
    g = gain_metrics(np.array([[0.3, 0.2, 0.1, 9.0]]), np.array([[0.1, 0.2, 0.3, 0.0]]), states)
    assert g["spearman"] == pytest.approx(-1.0) and g["chosen_rank"] == 3


@pytest.mark.parametrize("kind", ["ma-scvp", "pc-nbv"])
def test_shipped_weights_load_and_are_deterministic(kind):
    model, metadata = load_weights(shipped_path(kind), kind)
    assert shipped_path(kind).stat().st_size < 10e6
    torch.manual_seed(1)
    first = torch.rand(2, 32, 32, 32) if kind == "ma-scvp" else torch.rand(2, 512, 3)
    state = torch.zeros(2, 32)
    state[:, 17] = 1
    with torch.no_grad():
        a, b = model(first, state), model(first, state)
    assert a.shape == (2, 32) and torch.equal(a, b)
    assert {"summary", "test", "train_config", "dataset", "history"} <= set(metadata)


def test_weight_files_with_faults_give_one_clear_error(tmp_path):
    path = tmp_path / "ma-scvp.pt"
    save_weights(path, ViewSetNet(), "ma-scvp", {"note": "test"})
    model, metadata = load_weights(path, "ma-scvp")
    assert metadata == {"note": "test"}
    with pytest.raises(InputFileError, match="pc-nbv"):
        load_weights(path, "pc-nbv")
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(InputFileError, match="truncated.pt"):
        load_weights(truncated, "ma-scvp")
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a weight file at all")
    with pytest.raises(InputFileError, match="garbage.pt"):
        load_weights(garbage, "ma-scvp")
    with pytest.raises(InputFileError, match="no such weight file"):
        load_weights(tmp_path / "missing.pt", "ma-scvp")
    # a tensor of the wrong shape: the architecture the file names does not match its tensors
    payload = torch.load(path, weights_only=True)
    payload["spec"]["head"] = [128, 64, 32]
    wrong = tmp_path / "wrong.pt"
    torch.save(payload, wrong)
    with pytest.raises(InputFileError, match="wrong.pt.*shape"):
        load_weights(wrong, "ma-scvp")


def test_view_state_injection_follows_ma_scvp():
    # cell p of the 16^3 state map holds state[p mod 32]
    state = torch.arange(32, dtype=torch.float32)[None]
    tiled = state.repeat(1, 16 ** 3 // 32).reshape(1, 1, 16, 16, 16).flatten()
    assert torch.equal(tiled, torch.arange(4096, dtype=torch.float32) % 32)
    assert ViewSetNet()(torch.rand(1, 32, 32, 32), torch.zeros(1, 32)).shape == (1, 32)
    assert GainNet().eval()(torch.rand(1, 100, 3), torch.zeros(1, 32)).shape == (1, 32)


# --------------------------------------------------------------------------------------------------
# the stage methods
# --------------------------------------------------------------------------------------------------


def test_learned_methods_run_on_both_view_spaces():
    from tpvp.config_loading import make_config
    from tpvp.experiments.plants import default_cases, run_task

    for case in default_cases(quick=True)[::2]:  # one hemisphere and one sphere case
        for method in ("ma-scvp", "ma-scvp-oracle"):
            row = run_task(case, method, make_config("plant")).iloc[0]
            assert 0 < row["coverage"] <= 1 and row["views"] >= row["warm_up_views"] == 2
            assert row["coverage"] >= row["coverage_after_warm_up"]


def test_pc_nbv_never_repeats_or_leaves_the_hemisphere():
    from tpvp.config_loading import make_config
    from tpvp.experiments.baselines import nbv_curve
    from tpvp.experiments.plants import _scene, default_cases
    from dataclasses import replace

    case = [c for c in default_cases(quick=True) if c.view_space == "sphere"][0]
    config = make_config("plant", {"view_space": "sphere", "nbv.method": "pc-nbv"})
    scene = _scene(replace(case, initial_view=0), replace(case.config(config), initial_view=0))
    curve = nbv_curve(scene, case.config(config), max_views=8)
    assert curve["view"].is_unique and (curve["view"] < 32).all()
    assert curve["coverage"].is_monotonic_increasing


def test_cli_names_a_missing_dataset(tmp_path, capsys):
    from tpvp.learning.__main__ import main

    assert main(["train", "--data", str(tmp_path / "nowhere"), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    assert "nowhere: no manifest.json" in capsys.readouterr().err


def test_cli_evaluates_the_states_of_a_given_size(tiny_dataset, tmp_path, capsys):
    """``evaluate --executed 2`` adds a row per split for the two-view states, the same numbers as
    evaluating those rows directly."""
    import pandas as pd

    from tpvp.learning.__main__ import main
    from tpvp.learning.training import evaluate
    from tpvp.learning.weights import load_weights, shipped_path

    data, _ = tiny_dataset
    assert main(["evaluate", "--data", str(data.folder), "--kinds", "ma-scvp", "--executed", "2",
                 "--out", str(tmp_path)]) == 0
    table = pd.read_csv(tmp_path / "evaluation.csv")
    assert table["executed"].astype(str).tolist() == ["all", "2", "all", "2"]
    test = data.split("test")
    two = test[np.asarray(data["states"])[test].sum(axis=1) == 2]
    model, _ = load_weights(shipped_path("ma-scvp"), "ma-scvp")
    row = table[(table["split"] == "test") & (table["executed"].astype(str) == "2")].iloc[0]
    assert row["states"] == len(two) > 0
    assert row["recall"] == pytest.approx(evaluate("ma-scvp", model, data, two)["recall"])
    assert main(["evaluate", "--data", str(data.folder), "--kinds", "ma-scvp", "--executed", "40",
                 "--out", str(tmp_path)]) == 2
    assert "no validation state has 40 views executed" in capsys.readouterr().err
