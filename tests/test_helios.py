"""data_tools.helios: Helios-grown plants written in the prepared Pheno4D layout with organ labels,
the same bytes from the same seed, sessions that are one plant growing, read by the experiments,
the surface sampler against known areas and textures, and bad input refused with one line."""

from __future__ import annotations

import importlib.util
import itertools
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from data_tools import cli
from data_tools.helios import SOWN, HeliosConfig, Surface, grow, helios_seed, prepare_helios, sample_surface
from data_tools.prepared import MANIFEST_COLUMNS, PAIR_COLUMNS
from helpers import tree_digest
from tpvp.experiments.plants import dataset_instances
from tpvp.experiments.season import dataset_season_cases
from tpvp.io import read_point_cloud
from tpvp.metrics.geometry import nearest_distances
from tpvp.scene.normalise import normalise_plant
from tpvp.scene.organs import CODE, ORGANS
from tpvp.scene.voxels import voxel_centres

needs_helios = pytest.mark.skipif(importlib.util.find_spec("pyhelios") is None,
                                  reason="pyhelios3d is not installed (environment.txt lists it)")
SPECIES = ("tomato", "sugarbeet")
AGES = (30, 36)
CONFIG = HeliosConfig(spacing=0.005, plants=2, seed=0)  # ~8,000-11,000 points a session: fast


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    folder = tmp_path_factory.mktemp("helios") / "dataset"
    prepare_helios(folder, SPECIES, AGES, CONFIG, progress=False)
    return folder


@needs_helios
def test_the_dataset_has_the_pheno4d_layout_with_organ_labels(dataset):
    manifest = pd.read_csv(dataset / "manifest.csv")
    assert tuple(manifest.columns) == MANIFEST_COLUMNS
    pd.testing.assert_frame_equal(pd.read_parquet(dataset / "manifest.parquet"), manifest, check_dtype=False)
    plants = ["Tomato01", "Tomato02", "Sugarbeet01", "Sugarbeet02"]
    assert list(manifest.plant) == [p for p in plants for _ in AGES]
    assert list(manifest.date) == ["2025-01-31", "2025-02-06"] * 4  # sown 2025-01-01, + 30 / + 36 days
    assert manifest.labelled.all() and set(manifest.label_kind) == {"organ"}
    assert (manifest.points == manifest.plant_points).all()
    assert "NOTICE.md" in {p.name for p in dataset.iterdir()}

    for row in manifest.itertuples():
        points, labels = read_point_cloud(dataset / row.file, units="m", return_labels=True)
        assert row.file == f"{row.plant}/{row.plant}_{row.date[5:7]}{row.date[8:]}.ply" and len(points) == row.points
        assert set(np.unique(labels)) <= set(range(len(ORGANS)))
        assert {CODE["leaf"], CODE["stem"]} <= set(np.unique(labels))
        # metres, z up, the base at the origin: the lowest stem point is the base, the plant stands above it
        stem = points[labels == CODE["stem"]]
        np.testing.assert_allclose(stem[np.argmin(stem[:, 2])], 0, atol=0.01)
        assert 0.2 < np.ptp(points[:, 2]) < 1.5 and points[:, 2].min() > -0.05
        np.testing.assert_allclose(np.ptp(points, axis=0), [row.extent_x, row.extent_y, row.extent_z])
        # the normalised copy and the ground truth exactly as pheno4d prepare makes them
        scene = normalise_plant(points, largest_side=0.24)
        normalised, normalised_labels = read_point_cloud(dataset / row.normalised_file, units="m",
                                                         return_labels=True)
        np.testing.assert_array_equal(normalised, scene.points)
        np.testing.assert_array_equal(normalised_labels, labels)
        np.testing.assert_array_equal(read_point_cloud(dataset / row.gt_file, units="m"),
                                      voxel_centres(scene.points, 0.002))

    pairs = pd.read_csv(dataset / "pairs.csv")
    assert tuple(pairs.columns) == PAIR_COLUMNS
    assert sorted(pairs.plant) == sorted(plants) and (pairs.days_apart == 6).all()
    assert list(pairs.previous_file) == [f"{p}/{p}_0131.ply" for p in pairs.plant]


@needs_helios
def test_the_same_seed_gives_the_same_bytes_and_another_seed_another_plant(dataset, tmp_path):
    again = tmp_path / "again"
    prepare_helios(again, SPECIES, AGES, CONFIG, progress=False)
    mine, theirs = tree_digest(dataset), tree_digest(again)
    for digest in (mine, theirs):
        digest.pop(".tpvp-run.json")  # it holds the time of writing
    assert mine == theirs

    first = read_point_cloud(dataset / "Tomato01" / "Tomato01_0131.ply", units="m")
    second = read_point_cloud(dataset / "Tomato02" / "Tomato02_0131.ply", units="m")
    assert len(first) != len(second) or not np.array_equal(first, second)
    other = prepare_helios(tmp_path / "other", ["tomato"], [30], HeliosConfig(spacing=0.005, seed=1),
                           progress=False)
    reseeded = read_point_cloud(tmp_path / "other" / other.file[0], units="m")
    assert len(reseeded) != len(first) or not np.array_equal(reseeded, first)


def test_the_seed_the_species_and_the_plant_each_change_helios_seed():
    """Every pair of (seed, species, plant) gets its own Helios seed, the same one each time."""
    keys = [(0, "tomato", 1), (1, "tomato", 1), (0, "sugarbeet", 1), (0, "tomato", 2), (1, "sugarbeet", 2)]
    seeds = {key: helios_seed(*key) for key in keys}
    assert [(a, b) for a, b in itertools.combinations(keys, 2) if seeds[a] == seeds[b]] == []
    assert all(0 <= seed < 2 ** 32 and seed == helios_seed(*key) for key, seed in seeds.items())


@needs_helios
def test_the_sessions_are_one_plant_growing(dataset):
    manifest = pd.read_csv(dataset / "manifest.csv")
    for plant, rows in manifest.groupby("plant"):
        early, late = (read_point_cloud(dataset / f, units="m", return_labels=True) for f in rows.file)
        leaves = [(labels == CODE["leaf"]).sum() for _, labels in (early, late)]
        assert leaves[1] > 1.05 * leaves[0], plant  # 6 days later: more leaf area, at one point per 25 mm²
        assert rows.source.str.extract(r"Helios seed (\d+)")[0].nunique() == 1
        # the same plant six days on lies far closer to its younger self than its sibling does
        sibling = plant[:-1] + ("2" if plant.endswith("1") else "1")
        other = read_point_cloud(dataset / f"{sibling}/{sibling}_0206.ply", units="m")
        assert nearest_distances(early[0], late[0]).mean() < 0.3 * nearest_distances(early[0], other).mean()


@needs_helios
def test_the_experiments_read_the_dataset(dataset):
    instances = dataset_instances(dataset)
    assert sorted(i.name for i in instances) == sorted(
        f"{p}-2025-01-31-2025-02-06" for p in ("Tomato01", "Tomato02", "Sugarbeet01", "Sugarbeet02"))
    assert {i.species for i in instances} == set(SPECIES) and {i.source for i in instances} == {"dataset"}
    previous, current = instances[0].load()
    assert len(previous) > 1000 and len(current) > len(previous)
    cases = dataset_season_cases(dataset, view_spaces=("hemisphere",), replan_after=(0,))
    assert len(cases) == 4 and all(len(case.files) == len(AGES) for case in cases)


@needs_helios
def test_the_sampled_area_is_helios_own_leaf_area():
    """Leaves are textured meshes: a point on a transparent texel is not leaf. The sampled area of
    every organ matches the area Helios itself gives its triangles (their solid fractions)."""
    from pyhelios import Context, PlantArchitecture
    from pyhelios.types import vec3

    seed, spacing = helios_seed(0, "tomato", 1), 0.002
    (_, surface), = grow("tomato", [30], seed)
    points, organs = sample_surface(surface, spacing, np.random.default_rng(0))
    with Context() as context, PlantArchitecture(context) as plants:
        context.seedRandomGenerator(seed)
        plants.disableMessages()
        plants.loadPlantModelFromLibrary("tomato")
        plants.buildPlantInstanceFromLibrary(vec3(0, 0, 0), 30.0)
        leaf = float(np.sum(context.getPrimitiveArea(plants.getAllLeafUUIDs())))
        stem = float(np.sum(context.getPrimitiveArea(plants.getAllInternodeUUIDs())))
    assert (organs == CODE["leaf"]).sum() * spacing ** 2 == pytest.approx(leaf, rel=0.01)
    assert (organs == CODE["stem"]).sum() * spacing ** 2 == pytest.approx(stem, rel=0.03)


def test_the_sampler_is_uniform_by_area_and_leaves_transparent_texels_out():
    # two triangles of 0.5 and 2 m² in z = 0 and z = 1; the second textured: opaque top half only
    vertices = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 1], [2, 0, 1], [0, 2, 1]]], dtype=float)
    uv = np.array([[[0, 0], [0, 0], [0, 0]], [[0, 0], [1, 0], [0, 1]]], dtype=float)
    mask = np.zeros((100, 100), dtype=bool)
    mask[:50] = True  # row 0 is the top of the image: v = 1
    surface = Surface(vertices, np.array([CODE["stem"], CODE["leaf"]]), uv, np.array([-1, 0]), (mask,))
    spacing = 0.01
    points, organs = sample_surface(surface, spacing, np.random.default_rng(0))
    assert set(points[organs == CODE["stem"], 2]) == {0.0} and set(points[organs == CODE["leaf"], 2]) == {1.0}
    stem, leaf = points[organs == CODE["stem"]], points[organs == CODE["leaf"]]
    assert (stem[:, :2].sum(axis=1) <= 1 + 1e-12).all() and (stem[:, :2] >= 0).all()
    assert len(stem) == pytest.approx(0.5 / spacing ** 2, rel=0.03)
    # v = y / 2 on the textured triangle: only v > 1/2 is opaque, y > 1, the triangle's top corner (0.5 m²)
    assert (leaf[:, 1] >= 1 - 0.02).all()
    assert len(leaf) == pytest.approx(0.5 / spacing ** 2, rel=0.03)
    again, _ = sample_surface(surface, spacing, np.random.default_rng(0))
    np.testing.assert_array_equal(again, points)


def _no_pyhelios(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyhelios", None)  # import pyhelios raises ImportError


def _broken_library(monkeypatch):
    import pyhelios

    def fails():
        raise OSError("libhelios.so: cannot open shared object file: No such file or directory")
    monkeypatch.setattr(pyhelios, "Context", fails)


HELIOS = importlib.util.find_spec("pyhelios") is not None
# case -> (options replacing the good ones, what breaks Helios, the message, whether it needs Helios)
BAD = {
    "unknown-species": ({"--species": ["tomatoe"]}, None, "unknown species 'tomatoe'; Helios 0.1.38 offers", True),
    "ages-not-increasing": ({"--ages": ["33", "30"]}, None, "ages must be positive days in strictly increasing order",
                            False),
    "ages-repeated": ({"--ages": ["30", "30"]}, None, "strictly increasing order (each session after the previous",
                      False),
    "age-zero": ({"--ages": ["0", "3"]}, None, "ages must be positive days", False),
    "no-plants": ({"--plants": ["0"]}, None, "plants must be an integer of at least 1, got 0", False),
    "no-pyhelios": ({}, _no_pyhelios, "Helios is not installed", False),
    "broken-library": ({}, _broken_library, "Helios cannot load (libhelios.so: cannot open shared object file", True),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_input_is_one_line_and_writes_nothing(case, tmp_path, capsys, monkeypatch):
    options, damage, expected, needs = BAD[case]
    if needs and not HELIOS:
        pytest.skip("pyhelios3d is not installed (environment.txt lists it)")
    if damage is not None:
        damage(monkeypatch)
    arguments = {"--species": ["tomato"], "--ages": ["30", "33"], **options, "--output": [str(tmp_path / "out")]}
    code = cli.main(["helios", *(x for flag, values in arguments.items() for x in (flag, *values))])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert err.startswith("data_tools helios: error: ") and expected in err and "Traceback" not in err
    if damage is not None:  # how to get a working Helios
        assert "pip install pyhelios3d==0.1.38" in err and "make test" in err
    if case == "unknown-species":
        assert ", tomato, " in err and ", maize, " in err  # the list comes from Helios
    assert list(tmp_path.iterdir()) == []  # no dataset, no lock, no staging folder


@needs_helios
def test_an_existing_dataset_needs_force(tmp_path, capsys):
    argv = ["helios", "--species", "tomato", "--ages", "30", "--spacing", "0.01", "--output", str(tmp_path / "d")]
    assert cli.main(argv) == 0
    assert "grew 1 plant(s) of 1 species through 1 session(s) each" in capsys.readouterr().out
    before = tree_digest(tmp_path / "d")
    assert cli.main(argv) == 2
    assert "manifest.csv exists" in capsys.readouterr().err and tree_digest(tmp_path / "d") == before
    assert cli.main([*argv, "--force"]) == 0
    assert pd.read_csv(tmp_path / "d" / "manifest.csv").date.tolist() == [str(SOWN.replace(day=31))]


def test_the_data_tools_load_without_pyhelios():
    """pyhelios is imported only when the helios command runs."""
    code = ("import sys; import data_tools.cli, data_tools.helios, data_tools.pheno4d; "
            "data_tools.cli.build_parser(); print('pyhelios' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and result.stdout.strip() == "False", result.stderr
