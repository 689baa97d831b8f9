import numpy as np
import pytest

from tpvp.scene import voxels
from tpvp.scene.normalise import normalise_plant
from tpvp.sensor.grid import build_grid
from tpvp.viewspace import load_view_space


@pytest.fixture(scope="session")
def tomato_points():
    """The bundled real tomato (03-06) in metres, normalised to a 0.24 m largest side."""
    from tpvp.scene.samples import load_sample

    return normalise_plant(load_sample("tomato_0306"), table=True)


@pytest.fixture(scope="session")
def tomato_scene(tomato_points):
    """Ground-truth grid (2 mm, with the supporting table) and the 32 hemisphere views."""
    res = 0.002
    plant = voxels.voxelise(tomato_points.points, res)
    table = voxels.voxelise(tomato_points.table_points, res)
    grid = build_grid(np.concatenate([plant, table]), res,
                      np.r_[np.ones(len(plant), bool), np.zeros(len(table), bool)])
    return grid, load_view_space("hemisphere")
