"""The ablation helpers of Tables III and IV (tpvp.experiments.ablation): small hand-made cases
against brute-force references, exact; one end-to-end case on a generated pair."""

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from scipy import sparse

from tpvp.config_loading import flatten_keys, make_config, to_dict
from tpvp.experiments import ablation


def _random_visibility(seed, views=7, voxels=40, density=0.25):
    dense = np.random.default_rng(seed).random((views, voxels)) < density
    return dense, sparse.csr_matrix(dense)


# --------------------------------------------------------------------------------------------------
# voxel origins
# --------------------------------------------------------------------------------------------------


def _brute_origins(layers, resolution):
    first = {}
    for index, layer in enumerate(layers):
        for point in layer:
            key = tuple(int(k) for k in np.floor(point / resolution))
            first.setdefault(key, index)
    return first


@pytest.mark.parametrize("seed", range(5))
def test_surface_origins_against_brute_force(seed):
    rng = np.random.default_rng(seed)
    resolution = 0.004
    # overlapping layers (P~, Q, I) on a small box, negative coordinates included
    layers = [rng.uniform(-0.02, 0.02, (n, 3)) for n in (60, 40, 10)]
    layers[1] = np.concatenate([layers[1], layers[0][:5] + 1e-4])  # some Q points in P~'s voxels
    keys, origin = ablation.surface_origins(layers, resolution)
    expected = _brute_origins(layers, resolution)
    assert len(keys) == len(expected)
    assert {tuple(k): int(o) for k, o in zip(keys, origin)} == expected


def test_surface_origins_follow_the_planning_grid_order_and_skip_empty_layers():
    from tpvp.scene import voxels
    from tpvp.scene.grid import build_grid

    rng = np.random.default_rng(7)
    warped, coarse = rng.uniform(-0.05, 0.05, (300, 3)), rng.uniform(-0.05, 0.05, (100, 3))
    keys, origin = ablation.surface_origins((warped, coarse, np.zeros((0, 3))), 0.004)
    grid = build_grid(voxels.voxelise(np.concatenate([warped, coarse]), 0.004), 0.004)
    assert np.array_equal(keys, grid.keys)
    assert set(np.unique(origin)) <= {0, 1}
    # the voxels of origin 0 are exactly P~'s voxels
    assert np.array_equal(keys[origin == 0], voxels.voxelise(warped, 0.004))


def test_surface_origins_hand_made():
    keys, origin = ablation.surface_origins(
        (np.array([[0.5, 0.5, 0.5]]), np.array([[0.6, 0.5, 0.5], [1.5, 0.5, 0.5]]), np.array([[-0.5, 0.5, 0.5]])), 1.0)
    assert keys.tolist() == [[-1, 0, 0], [0, 0, 0], [1, 0, 0]]
    assert origin.tolist() == [2, 0, 1]


# --------------------------------------------------------------------------------------------------
# coverage set algebra
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(6))
def test_covered_only_and_sole_cover_against_brute_force(seed):
    dense, matrix = _random_visibility(seed)
    rng = np.random.default_rng(100 + seed)
    views = sorted(rng.choice(7, 3, replace=False).tolist())
    others = sorted(rng.choice(7, 3, replace=False).tolist())
    among = np.sort(rng.choice(40, 25, replace=False))

    covered = [any(dense[v, j] for v in views) for j in range(40)]
    assert ablation.covered_mask(matrix, views).tolist() == covered
    assert not ablation.covered_mask(matrix, []).any()

    only = [j for j in range(40) if covered[j] and not any(dense[v, j] for v in others)]
    assert ablation.only_covered_by(matrix, views, others).tolist() == only
    assert ablation.only_covered_by(matrix, views, others, among).tolist() == [j for j in only if j in among]

    sole = ablation.sole_cover(matrix, views + views[:1])  # a repeated view counts once
    assert list(sole) == views
    for v in views:
        assert sole[v].tolist() == [j for j in range(40) if dense[v, j] and sum(dense[u, j] for u in views) == 1]


def test_sole_cover_of_a_hand_made_plan():
    # view 0 sees voxels 0, 1; view 1 sees 1, 2; view 2 sees 3
    matrix = sparse.csr_matrix(np.array([[1, 1, 0, 0], [0, 1, 1, 0], [0, 0, 0, 1]], bool))
    assert {v: ids.tolist() for v, ids in ablation.sole_cover(matrix, [0, 1, 2]).items()} == {0: [0], 1: [2], 2: [3]}
    assert ablation.sole_cover(matrix, []) == {}


# --------------------------------------------------------------------------------------------------
# the registry's overrides
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ablation.ABLATION_METHODS)
def test_method_config_is_what_the_registry_runs(method, monkeypatch):
    """The registry's method hands run_case the same configuration as method_config."""
    from tpvp.experiments import plants

    class Captured(Exception):
        pass

    def capture(scene, config, transferred=None):
        raise Captured(config)

    monkeypatch.setattr(plants, "run_case", capture)
    monkeypatch.setattr(plants, "shared_transfer", lambda scene, config: None)
    base = make_config("plant", {"view_space": "sphere", "initial_view": 8})
    with pytest.raises(Captured) as caught:
        plants.PLANT_METHODS.get(method)(None, base)
    ran = flatten_keys(to_dict(caught.value.args[0]))
    assert ran == flatten_keys(to_dict(ablation.method_config(base, method)))
    assert ran["inflation.enabled"] == ("no-inflation" not in method)
    assert ran["nbv.warm_up_views"] == (0 if method.startswith("initial-view-only") else base.nbv.warm_up_views)


def test_unknown_method_and_case():
    with pytest.raises(KeyError, match="unknown one-shot method"):
        ablation.method_config(make_config("plant"), "gmc")
    with pytest.raises(KeyError, match="no quick case"):
        ablation.example_case("rose", "sphere")
    case = ablation.example_case("tomato", "hemisphere")
    assert (case.instance.species, case.view_space, case.rotation_deg, case.initial_view) == \
        ("tomato", "hemisphere", 0.0, 17)


# --------------------------------------------------------------------------------------------------
# the one-case tables on hand-made data
# --------------------------------------------------------------------------------------------------


def _plan(executed, planned, coverage=0.5):
    return SimpleNamespace(executed_views=executed, planned_views=planned, order=executed + planned,
                           n_views=len(executed) + len(planned), coverage=coverage, path_length=1.0)


def test_exclusive_views_table_hand_made():
    # 4 views on the unit circle looking at the origin; 5 ground-truth voxels, all in the oracle set but 4
    positions = np.array([[1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0], [0, 0, 1.0]])
    truth = sparse.csr_matrix(np.array([[1, 1, 0, 0, 0],    # view 0: executed
                                        [0, 1, 1, 0, 0],    # view 1: only with inflation
                                        [0, 0, 0, 1, 0],    # view 2: only without
                                        [0, 0, 1, 1, 1]], bool))  # view 3: both
    scene = SimpleNamespace(view_space=SimpleNamespace(positions=positions, look_ats=np.zeros((4, 3))),
                            truth_visibility=truth, oracle=np.array([0, 1, 2, 3]))
    # inflated surface: 4 voxels, origins P~, Q, I, P~; plain surface: 2 voxels (P~)
    with_vis = sparse.csr_matrix(np.array([[1, 0, 0, 0], [0, 1, 1, 1], [0, 0, 0, 0], [1, 0, 0, 1]], bool))
    without_vis = sparse.csr_matrix(np.array([[1, 0], [0, 0], [0, 1], [1, 1]], bool))
    study = ablation.InflationAblation(
        with_inflation=_plan([0], [1, 3], 0.75), without_inflation=_plan([0], [2, 3], 0.5), resolution=0.004,
        surface_keys=np.zeros((4, 3), np.int64), surface_origin=np.array([0, 1, 2, 0]),
        visibility_with=with_vis, visibility_without=without_vis, only_with=[1], only_without=[2],
        seen_only_with=np.array([]), seen_only_without=np.array([]))
    table = ablation.exclusive_views_table(scene, study).set_index("view")
    assert table.loc[1, "plan"] == "with inflation" and table.loc[2, "plan"] == "without inflation"
    assert table.loc[1, "oracle voxels it sees"] == 2  # voxels 1, 2
    assert table.loc[1, "... that the other plan misses"] == 0  # views 0, 2, 3 see 1 and 2
    assert table.loc[2, "... that the other plan misses"] == 0  # view 3 sees voxel 3
    assert table.loc[1, "added voxels (Q, I) it sees"] == 2  # surface voxels 1 (Q) and 2 (I)
    assert table.loc[2, "added voxels (Q, I) it sees"] == 0
    # within the inflated plan {0, 1, 3}: view 1 alone sees surface voxels 1, 2 (Q, I)
    assert table.loc[1, ["planning voxels only it covers", "of which P~", "of which Q", "of which I"]].tolist() == \
        [2, 0, 1, 1]
    # within the plan without inflation {0, 2, 3}: view 2's surface voxel 1 is also seen by view 3
    assert table.loc[2, "planning voxels only it covers"] == 0
    assert table.loc[1, "elevation (deg)"] == pytest.approx(0.0) and table.loc[1, "azimuth (deg)"] == pytest.approx(90.0)


def test_inflation_table_counts():
    study = ablation.InflationAblation(
        with_inflation=_plan([0], [1, 3], 0.75), without_inflation=_plan([0], [2], 0.5), resolution=0.004,
        surface_keys=np.zeros((6, 3), np.int64), surface_origin=np.array([0, 0, 0, 1, 1, 2]),
        visibility_with=None, visibility_without=None, only_with=[1, 3], only_without=[2],
        seen_only_with=np.array([4, 5, 6]), seen_only_without=np.array([7]))
    table = ablation.inflation_table(study)
    assert table["planning voxels"].tolist() == [3, 6]
    assert table[["from P~", "added by Q", "added by I"]].values.tolist() == [[3, 0, 0], [3, 2, 1]]
    assert table["views"].tolist() == [2, 3] and table["coverage (%)"].tolist() == [50.0, 75.0]
    assert table["views only this plan selects"].tolist() == ["2", "1, 3"]
    assert table["oracle voxels only this plan covers"].tolist() == [1, 3]
    assert "**1**" in ablation.describe_inflation(study)  # one inflation voxel, in words


def _brute_chamfer(a, b):
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
    return 0.5 * (d.min(axis=1).mean() + d.min(axis=0).mean())


def test_registration_table_hand_made():
    rng = np.random.default_rng(3)
    previous, current = rng.uniform(0, 0.1, (30, 3)), rng.uniform(0, 0.1, (25, 3))
    scene = SimpleNamespace(previous=previous, current=current)
    settings = []
    for count, shift in ((0, 0.003), (1, 0.001)):
        warped = previous + shift
        error = np.linalg.norm(warped[:, None] - current[None], axis=2).min(axis=1)
        transfer = SimpleNamespace(executed=[17] + [5] * count, coarse=np.repeat(current[:10 + count], 2, axis=0),
                                   alignment=SimpleNamespace(warped=warped, chamfer_before=0.004, chamfer_after=0.002))
        settings.append(ablation.RegistrationSetting(f"{count} NBV", count, transfer, error,
                                                     _brute_chamfer(warped, current),
                                                     {"with inflation": _plan([17], [1, 2], 0.9)}))
    table = ablation.registration_table(scene, settings)
    assert table["executed views"].tolist() == ["17", "17, 5"]
    assert table["Q points"].tolist() == [10, 11]  # duplicates of the coarse cloud counted once
    assert table["Chamfer P-truth unregistered (mm)"].tolist() == pytest.approx([1e3 * _brute_chamfer(previous, current)] * 2)
    assert table["Chamfer P~-truth (mm)"].tolist() == pytest.approx([1e3 * s.chamfer_truth for s in settings])
    assert table["P~ points within 2 mm of today's plant (%)"].tolist() == \
        pytest.approx([100 * (s.error <= 0.002).mean() for s in settings])
    assert table["with inflation: views"].tolist() == [3, 3]


# --------------------------------------------------------------------------------------------------
# the protocol's rows
# --------------------------------------------------------------------------------------------------


def _raw():
    rows = []
    for species, space, rotation in (("tomato", "sphere", 0.0), ("maize", "hemisphere", 45.0)):
        for method, views, coverage, chamfer in (("ours", 10, 0.99, 0.5), ("ours-no-inflation", 9, 0.97, 0.5),
                                                 ("initial-view-only", 8, 0.96, 1.5)):
            bump = 2 if species == "maize" else 0
            rows.append({"source": "generated", "instance": f"{species}-0", "species": species, "view_space": space,
                         "rotation_deg": rotation, "initial_view": 17, "method": method, "views": views + bump,
                         "coverage": coverage, "path_length_m": 3.0, "chamfer_truth_mm": chamfer + bump})
    rows.append({**rows[0], "method": "gmc", "views": np.nan})  # not one of the four
    return pd.DataFrame(rows)


def test_pooled_table_exact_means():
    table = ablation.pooled_table(_raw()).set_index("method")
    assert table.index.tolist() == ["ours", "ours-no-inflation", "initial-view-only"]
    assert table.loc["ours", "cases"] == 2
    assert table.loc["ours", "views_mean"] == 11 and table.loc["ours", "views_std"] == 1  # 10 and 12, ddof 0
    assert table.loc["ours-no-inflation", "coverage_mean"] == pytest.approx(97.0)  # per cent, as Table I-III
    assert table.loc["initial-view-only", "chamfer_truth_mm_mean"] == pytest.approx(2.5)


def test_paired_cases():
    pairs = ablation.paired_cases(_raw(), "initial-view-only", "ours", "chamfer_truth_mm")
    assert len(pairs) == 2
    assert (pairs["initial-view-only"] - pairs["ours"]).tolist() == [1.0, 1.0]
    assert set(pairs["species"]) == {"tomato", "maize"}


def test_paired_figure_writes_a_png(tmp_path):
    from tpvp.viz.ablation import plot_paired_cases

    path = plot_paired_cases(tmp_path / "paired.png", _raw(), "hand-made")
    assert path.is_file() and path.with_suffix(".pdf").is_file()


# --------------------------------------------------------------------------------------------------
# one generated case end to end
# --------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def maize_case():
    from tpvp.simulate.single_plant import build_scene
    from tpvp.synthetic.plants import generate_session_pair

    pair = generate_session_pair("maize", 2, days=2.0)
    config = make_config("plant", {"registration.embedded_deformation.iterations": 60})
    return build_scene(pair.previous.points, pair.current.points, config), config


def test_inflation_ablation_on_a_generated_pair(maize_case, tmp_path):
    from tpvp.scene import voxels
    from tpvp.visibility import covered_voxels

    scene, config = maize_case
    study = ablation.inflation_ablation(scene, config)
    plain = study.without_inflation
    # the surface without inflation is exactly the voxels labelled P~
    assert np.array_equal(voxels.voxelise(plain.clouds["planning"], study.resolution),
                          study.surface_keys[study.surface_origin == 0])
    assert study.visibility_with.shape == (len(scene.view_space), len(study.surface_keys))
    assert set(study.only_with).isdisjoint(plain.planned_views + plain.executed_views)
    views_with = study.with_inflation.executed_views + study.with_inflation.planned_views
    views_without = plain.executed_views + plain.planned_views
    seen_with = set(covered_voxels(scene.truth_visibility, views_with)) & set(scene.oracle)
    seen_without = set(covered_voxels(scene.truth_visibility, views_without)) & set(scene.oracle)
    assert set(study.seen_only_with) == seen_with - seen_without
    assert set(study.seen_only_without) == seen_without - seen_with
    # coverage difference = what only one plan sees, over the oracle set
    assert study.with_inflation.coverage - plain.coverage == pytest.approx(
        (len(study.seen_only_with) - len(study.seen_only_without)) / len(scene.oracle))

    settings = ablation.registration_ablation(scene, config)
    assert [s.warm_up_views for s in settings] == [0, 1]
    assert [len(s.transfer.executed) for s in settings] == [1, 2]
    assert settings[0].plans["with inflation"].executed_views == [config.initial_view]

    from tpvp.viz import ablation as figures

    for path in (figures.plot_planning_surface(tmp_path / "s.png", study.surface_centres, study.surface_origin),
                 figures.plot_plan_difference(tmp_path / "d.png", scene, study),
                 figures.plot_registration(tmp_path / "r.png", scene, settings)):
        assert path.is_file()
    figure = figures.planning_surface_3d(scene, study)
    assert any(trace.name.startswith("transferred P~") for trace in figure.data)
