"""The plant-complexity computations (tpvp.experiments.species) against brute force on small
hand-made visibility matrices: exact equality."""

import itertools

import numpy as np
import pytest
from scipy import sparse

from tpvp.experiments import species

# 4 views x 7 voxels; voxel 5 is seen by no view (not in the oracle set), voxel 6 only by view 3.
SEES = {0: {0, 1, 2}, 1: {2, 3}, 2: {0, 3, 4}, 3: {4, 6}}
N_VOXELS = 7


def matrix(sees=SEES, n_voxels=N_VOXELS, fmt="csr"):
    dense = np.zeros((len(sees), n_voxels), dtype=np.uint8)
    for view, voxels in sees.items():
        dense[view, sorted(voxels)] = 1
    return sparse.csr_matrix(dense).asformat(fmt)


def oracle(sees=SEES):
    return np.array(sorted(set().union(*sees.values())))


def random_case(seed, views=6, voxels=25, density=0.25):
    rng = np.random.default_rng(seed)
    dense = rng.random((views, voxels)) < density
    sees = {v: set(np.flatnonzero(dense[v]).tolist()) for v in range(views)}
    return sees, voxels


@pytest.mark.parametrize("fmt", ["csr", "csc", "coo"])
def test_views_per_voxel_counts_the_views_that_see_each_voxel(fmt):
    counts = species.views_per_voxel(matrix(fmt=fmt))
    assert counts.tolist() == [2, 1, 2, 2, 2, 0, 1]
    assert species.views_per_voxel(matrix(fmt=fmt), [6, 0, 5]).tolist() == [1, 2, 0]


def test_explicit_zeros_are_not_views():
    m = matrix().tolil()
    m[1, 5] = 1
    m = m.tocsr()
    m.data[m.indptr[1]:m.indptr[2]][list(m.indices[m.indptr[1]:m.indptr[2]]).index(5)] = 0  # stored zero
    assert species.views_per_voxel(m).tolist() == [2, 1, 2, 2, 2, 0, 1]


def test_coverage_curve_by_hand():
    curve = species.coverage_curve(matrix(), oracle(), [3, 0, 1, 2])
    assert curve.to_dict("list") == {"step": [1, 2, 3, 4], "view": [3, 0, 1, 2], "new_voxels": [2, 3, 1, 0],
                                     "covered": [2, 5, 6, 6], "coverage": [2 / 6, 5 / 6, 1.0, 1.0]}


@pytest.mark.parametrize("seed", range(8))
def test_coverage_curve_against_set_unions(seed):
    sees, n = random_case(seed)
    omega = oracle(sees)
    order = list(np.random.default_rng(100 + seed).permutation(len(sees))[:4])
    curve = species.coverage_curve(matrix(sees, n), omega, order)
    seen = set()
    for row, view in zip(curve.itertuples(), order):
        new = (sees[view] & set(omega.tolist())) - seen
        seen |= new
        assert (row.view, row.new_voxels, row.covered) == (view, len(new), len(seen))
        assert row.coverage == len(seen) / len(omega)


def test_coverage_curve_only_counts_the_given_oracle_voxels():
    curve = species.coverage_curve(matrix(), np.array([0, 4]), [0, 3])
    assert curve["new_voxels"].tolist() == [1, 1] and curve["coverage"].tolist() == [0.5, 1.0]


@pytest.mark.parametrize("seed", range(8))
def test_first_seen_step_against_brute_force(seed):
    sees, n = random_case(seed)
    order = list(np.random.default_rng(200 + seed).permutation(len(sees))[:4])
    step = species.first_seen_step(matrix(sees, n), order)
    for voxel in range(n):
        expected = next((k for k, view in enumerate(order, start=1) if voxel in sees[view]), 0)
        assert step[voxel] == expected
    assert species.first_seen_step(matrix(sees, n), order, [3, 1]).tolist() == [step[3], step[1]]


def test_first_seen_step_by_hand():
    assert species.first_seen_step(matrix(), [2, 0]).tolist() == [1, 2, 2, 1, 1, 0, 0]


def test_forced_views_by_hand():
    # voxel 1 only by view 0, voxel 6 only by view 3
    assert species.forced_views(matrix(), oracle()).tolist() == [0, 3]
    assert species.forced_views(matrix(), np.array([0, 2, 3])).tolist() == []


@pytest.mark.parametrize("seed", range(8))
def test_forced_views_are_in_every_full_cover(seed):
    sees, n = random_case(seed, views=5, voxels=15, density=0.3)
    omega = set(oracle(sees).tolist())
    forced = species.forced_views(matrix(sees, n), oracle(sees))
    expected = sorted({next(v for v in sees if j in sees[v]) for j in omega
                       if sum(j in sees[v] for v in sees) == 1})
    assert forced.tolist() == expected
    covers = [set(c) for r in range(len(sees) + 1) for c in itertools.combinations(sees, r)
              if set().union(*(sees[v] for v in c)) >= omega]
    assert set(forced.tolist()) == set.intersection(*covers)


def test_share_seen_by_at_most():
    counts = np.array([1, 1, 2, 3, 5, 0])
    assert species.share_seen_by_at_most(counts, 4).tolist() == [3 / 6, 4 / 6, 5 / 6, 5 / 6]
    assert species.share_seen_by_at_most(np.array([], dtype=int), 2).tolist() == [0.0, 0.0]


def test_occlusion_summary_by_hand():
    summary = species.occlusion_summary(matrix(), oracle())
    # oracle voxels 0, 1, 2, 3, 4, 6 seen by 2, 1, 2, 2, 2, 1 views
    assert summary == {"oracle_voxels": 6, "only_1_view_pct": 100 * 2 / 6, "at_most_2_views_pct": 100.0,
                       "median_views": 2.0, "forced_views": 2}


def test_on_a_generated_plant_the_curve_ends_at_the_plan_coverage():
    from tpvp.experiments import plants

    case = next(c for c in plants.default_cases(quick=True) if c.instance.species == "maize")
    item = species.showcase(case)
    result, scene = item.result, item.scene
    curve = species.coverage_curve(scene.truth_visibility, scene.oracle, item.order)
    assert curve["view"].tolist() == result.executed_views + result.planned_views
    assert curve["coverage"].iloc[-1] == pytest.approx(result.coverage, abs=1e-15)
    assert curve["coverage"].iloc[len(result.executed_views) - 1] == pytest.approx(result.coverage_captured, abs=1e-15)
    assert curve["new_voxels"].sum() == curve["covered"].iloc[-1]
    row = species.plan_row(item)
    assert row["ours_views"] == result.n_views == len(curve)
    # every view that is the only view of some oracle voxel is in any 100 % plan, the optimum included
    assert row["forced_views"] <= row["optimum_views_100pct"]
    step = species.first_seen_step(scene.truth_visibility, item.order, scene.oracle)
    assert np.bincount(step, minlength=len(curve) + 1)[1:].tolist() == curve["new_voxels"].tolist()
