import pytest

from tpvp.scene.grid import plant_grid
from tpvp.scene.normalise import normalise_plant
from tpvp.viewspace.single_plant import load_view_space


@pytest.fixture(scope="session")
def tomato_points():
    """The bundled real tomato (03-06) in metres, normalised to a 0.24 m largest side."""
    from tpvp.scene.samples import load_sample

    return normalise_plant(load_sample("tomato_0306"), table=True)


@pytest.fixture(scope="session")
def tomato_scene(tomato_points):
    """Ground-truth grid (2 mm, with the supporting table) and the 32 hemisphere views."""
    grid = plant_grid(tomato_points.points, tomato_points.table_points, 0.002)
    return grid, load_view_space("hemisphere")


@pytest.fixture(scope="session")
def raw_standin(tmp_path_factory):
    """Three generated room1 sessions written as raw captures with landmark files
    (data_tools.greenhouse_standin); read-only for the tests that share it."""
    from data_tools.greenhouse_standin import write_raw_standin

    return write_raw_standin(tmp_path_factory.mktemp("raw_standin"), n_sessions=3)


@pytest.fixture(scope="session")
def executed_notebooks(tmp_path_factory):
    """One folder per test worker that the reader's-mode notebook executions publish into
    (tests/test_notebooks.py). The runner gives their kernels an empty experiment cache and no
    published results, as on a fresh clone."""
    return tmp_path_factory.mktemp("notebooks") / "executed"


def pytest_collection_modifyitems(items):
    """The longest tests first, so that `make test`'s two workers finish together (pytest-xdist
    hands tests out in this order): the notebooks, then the other `slow` tests, then the site,
    which copies the notebooks' kept executions (run earlier, they need not be executed twice)."""
    def rank(item):
        if item.path.name == "test_site.py":
            return 2
        if item.path.name == "test_notebooks.py":
            return 0
        return 1 if item.get_closest_marker("slow") else 3

    items.sort(key=rank)  # stable: each group keeps its collection order
