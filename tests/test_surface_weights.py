"""Class weights of the planning surface (tpvp.inflation.weights) against brute force, and the
weighted coverage target of the set-cover selection against exhaustive search."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import sparse
from test_partial_cover import brute_fewest

from tpvp.config import PlantConfig
from tpvp.config_loading import make_config
from tpvp.setcover.config import CALIBRATED_MISS_RATIO, SelectionConfig
from tpvp.errors import ConfigError
from tpvp.pipeline.plan import PlanningSurface, selection_problem
from tpvp.inflation.weights import (SURFACE_CLASSES, SurfaceWeightsConfig, surface_area, surface_classes,
                                   surface_weights)
from tpvp.scene import voxels
from tpvp.setcover.methods import SelectionProblem, set_cover


def brute_classes(keys, resolution, warped, coarse, near):
    """Per voxel, by looping over every point: the class the docstring of surface_classes defines."""
    out = []
    for key in keys:
        def holds(cloud):
            return any(all(int(np.floor(p[i] / resolution)) == key[i] for i in range(3)) for p in cloud)
        centre = (np.asarray(key) + 0.5) * resolution
        if holds(coarse):
            out.append(0)
        elif holds(warped):
            nearest = min(float(np.sqrt(((centre - q) ** 2).sum())) for q in coarse)
            out.append(1 if nearest <= near else 2)
        else:
            out.append(3)
    return np.array(out)


@pytest.mark.parametrize("seed", range(5))
def test_surface_classes_equal_brute_force(seed):
    rng = np.random.default_rng(seed)
    resolution = 0.004
    coarse = rng.uniform(0.0, 0.02, (15, 3))
    warped = np.concatenate([coarse[:5] + rng.normal(0, 0.001, (5, 3)), rng.uniform(0.0, 0.06, (25, 3))])
    inflation = rng.uniform(0.0, 0.04, (20, 3))
    keys = voxels.voxelise(np.concatenate([warped, coarse, inflation]), resolution)
    near = 0.008
    classes = surface_classes(keys, resolution, warped, coarse, near)
    expected = brute_classes(keys, resolution, warped, coarse, near)
    assert classes.dtype == np.int8 and np.array_equal(classes, expected)
    assert len(np.unique(expected)) >= 3  # the draw exercises most classes, not one


def test_surface_classes_hand_built():
    """One voxel of each class on a 1 cm grid: Q at voxel (0,0,0); P~ at (0,0,0) (observed wins),
    (1,0,0) (centre 1 cm from Q: near for 1.5 cm) and (5,0,0) (far); I alone at (0,1,0)."""
    r = 0.01
    coarse = np.array([[0.005, 0.005, 0.005]])
    warped = np.array([[0.004, 0.004, 0.004], [0.015, 0.005, 0.005], [0.055, 0.005, 0.005]])
    keys = np.array([[0, 0, 0], [1, 0, 0], [5, 0, 0], [0, 1, 0]])
    assert surface_classes(keys, r, warped, coarse, 0.015).tolist() == [0, 1, 2, 3]
    assert surface_classes(keys, r, warped, coarse, 0.005).tolist() == [0, 2, 2, 3]  # 1 cm > 0.5 cm: far
    assert surface_classes(keys, r, np.zeros((0, 3)), coarse, 0.015).tolist() == [0, 3, 3, 3]
    weights = surface_weights([0, 1, 2, 3], SurfaceWeightsConfig(enabled=True, observed=0.25, transferred_near=1.0,
                                                                 transferred_far=2.0, inflation=0.5))
    assert weights.tolist() == [0.25, 1.0, 2.0, 0.5]
    assert surface_weights([0, 3], SurfaceWeightsConfig(enabled=False)) is None
    assert len(SURFACE_CLASSES) == len(SurfaceWeightsConfig().class_weights) == 4


@pytest.mark.parametrize("seed", range(3))
def test_surface_area_equals_brute_force(seed):
    """Distinct sub-voxels (half the resolution) of the cloud inside each planning voxel, by looping."""
    rng = np.random.default_rng(seed)
    resolution = 0.004
    cloud = np.concatenate([rng.uniform(-0.02, 0.02, (200, 3)), rng.normal(0.0, 0.003, (200, 3))])
    keys = voxels.voxelise(cloud, resolution)
    area = surface_area(keys, resolution, cloud)
    expected = [len({tuple(np.floor(p / (resolution / 2)).astype(int)) for p in cloud
                     if tuple(np.floor(p / resolution).astype(int)) == tuple(k)}) for k in keys]
    assert np.array_equal(area, expected) and area.max() > 1  # dense points fill several sub-voxels
    # a planning voxel the cloud does not reach still counts 1; four subdivisions (nested) count at least as many
    assert surface_area(np.array([[100, 100, 100]]), resolution, cloud).tolist() == [1]
    fine = surface_area(keys, resolution, cloud, subdivisions=4)
    assert np.all(fine >= area)


def test_area_multiplies_the_class_weights():
    config = SurfaceWeightsConfig(enabled=True, area=True, observed=1.0, transferred_near=0.5)
    assert surface_weights([0, 1, 1], config, np.array([3, 1, 4])).tolist() == [3.0, 0.5, 2.0]
    with pytest.raises(ConfigError, match="area"):
        surface_weights([0, 1], config)
    with pytest.raises(ConfigError, match="surface_weights.area"):
        SurfaceWeightsConfig(area="yes")
    with pytest.raises(ConfigError, match="subdivisions"):
        surface_area([[0, 0, 0]], 0.004, np.zeros((1, 3)), subdivisions=0)


@pytest.mark.parametrize("field", ["observed", "transferred_near", "transferred_far", "inflation", "near_voxels"])
@pytest.mark.parametrize("value", [0.0, -1.0, float("nan"), float("inf"), "a", True])
def test_bad_weights_name_the_field(field, value):
    with pytest.raises(ConfigError, match=f"surface_weights.{field}"):
        SurfaceWeightsConfig(**{field: value})


def test_bad_weight_inputs():
    with pytest.raises(ConfigError, match="surface_weights.enabled"):
        SurfaceWeightsConfig(enabled=1)
    with pytest.raises(ConfigError, match="surface_weights.observed"):
        make_config("plant", {"surface_weights.observed": 0})
    with pytest.raises(ConfigError, match="0..3"):
        surface_weights([0, 4], SurfaceWeightsConfig(enabled=True))
    with pytest.raises(ConfigError, match="near"):
        surface_classes([[0, 0, 0]], 0.004, np.zeros((1, 3)), np.zeros((1, 3)), 0.0)
    with pytest.raises(ConfigError, match="SurfaceWeightsConfig"):
        surface_weights([0], SelectionConfig())


@pytest.mark.parametrize("seed", range(4))
def test_weighted_target_of_the_selection_equals_exhaustive_search(seed):
    """set_cover with voxel weights below a target of 1: the fewest views that see the target's
    share of the *coverable* weight (voxels no view sees do not count), executed views included."""
    rng = np.random.default_rng(seed)
    a = rng.random((9, 30)) < 0.2
    a[:, :3] = False  # uncoverable voxels carry weight that the target must ignore
    classes = rng.integers(0, 4, 30)
    weights = surface_weights(classes, SurfaceWeightsConfig(enabled=True, observed=0.25, transferred_far=2.0, inflation=0.5))
    executed = (1,)
    config = SelectionConfig(coverage_target=0.9)
    for target in (0.7, 0.9, 0.97):
        problem = SelectionProblem(sparse.csr_matrix(a), executed, None, np.zeros((30, 3)), target, weights)
        selection = set_cover(problem, config)
        coverable = a.any(axis=0)
        required = target * weights[coverable].sum()
        union = a[list(executed) + list(selection.selected)].any(axis=0)
        assert weights[union].sum() >= required - 1e-9
        assert len(selection.selected) == brute_fewest(a, required, executed, weights) and selection.optimal
        assert 1 not in selection.selected


def test_selection_problem_weights_only_below_a_target_of_one():
    """At the paper's target 1.0 the problem carries no weights (the full set cover is unchanged);
    below it, with the weights enabled, the class weights; unweighted by default."""
    classes = np.array([0, 1, 2, 3, 0], dtype=np.int8)
    area = np.array([1, 2, 3, 4, 1])
    surface = PlanningSurface(None, None, SimpleNamespace(centres=np.zeros((5, 3))), sparse.csr_matrix((4, 5)), {},
                              classes=classes, area=area)
    transferred = SimpleNamespace(executed=[0], nbv=None)
    scene = SimpleNamespace(view_space=None)
    full = selection_problem(scene, PlantConfig(), transferred, surface)
    assert full.voxel_weights is None and full.planning_target == 1.0
    asked = make_config("plant", {"selection.coverage_target": 0.98, "view_space": "sphere",
                                  "surface_weights.enabled": True})
    weighted = selection_problem(scene, asked, transferred, surface)
    expected = asked.surface_weights.class_weights[classes] * (area if asked.surface_weights.area else 1)
    assert np.array_equal(weighted.voxel_weights, expected)
    assert weighted.planning_target == pytest.approx(1 - CALIBRATED_MISS_RATIO["sphere"] * 0.02)
    plain = selection_problem(scene, make_config("plant", {"selection.coverage_target": 0.98, "view_space": "sphere"}),
                              transferred, surface)
    assert plain.voxel_weights is None
    assert plain.planning_target == pytest.approx(1 - CALIBRATED_MISS_RATIO["sphere"] * 0.02)
