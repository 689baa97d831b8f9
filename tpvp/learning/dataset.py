"""Training data of the learned planners from generated plants (docs/learning.md#dataset).

Per plant and rotation about the vertical (8 x 45 deg for training plants): the plant is rendered
from the 32 hemisphere views in the simulator's measurement model (what each view sees of the
plant, the table occluding); oracle greedy trajectories run from every start view until all the
visible surface is seen; states are drawn from their prefixes by MA-SCVP's long-tail rule (for
state size m, ``ceil(n1 x d[m] / d[1])`` distinct states, where ``d[m]`` is the mean coverage
gain of the (m+1)-th greedy view). For each state:

* the input grid (:mod:`tpvp.learning.grid`) and the accumulated cloud (``cloud_points`` points),
* the MA-SCVP label: one exact minimum set of views that sees every visible voxel the state has
  not seen (ILP, HiGHS),
* the PC-NBV targets: each view's true coverage gain (0 for views in the state).

Plants of the three splits come from disjoint generator seeds, none of them the Table I seeds
(0-2). The dataset is a folder of ``.npy`` arrays, an ``index.parquet`` (one row per state) and a
``manifest.json`` written last: a folder without a manifest is incomplete and never loaded.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import sparse

from tpvp.config_loading import make_config
from tpvp.errors import ConfigError, InputFileError
from tpvp.io.atomic import atomic_path, atomic_write_text
from tpvp.learning.grid import CELLS, occupancy_grid
from tpvp.parallel import run_cases
from tpvp.scene.frame import planning_frame
from tpvp.scene.grid import plant_grid
from tpvp.setcover.ilp import SetCoverConfig, solve_set_cover
from tpvp.synthetic.plants import generate_session_pair
from tpvp.visibility import oracle_voxels, visibility_matrix

VIEWS = 32
SPLITS = ("train", "validation", "test")
ARRAYS = {"grids": np.float16, "states": np.bool_, "orders": np.int8, "labels": np.bool_, "gains": np.float32,
          "clouds": np.float32}
DATASET_VERSION = 1


@dataclass(frozen=True)
class DatasetConfig:
    """Which plants, how many states. Plant counts are totals over ``species`` (split evenly);
    generator seeds are ``<split>_seed + i``. ``rotations``: rotations per training plant (the
    held-out splits take ``held_out_rotations``). ``n1``: single-view states per plant and rotation
    (MA-SCVP's "Longtail N1"; 32 keeps all of them)."""

    species: tuple = ("tomato", "maize")
    train_plants: int = 300
    validation_plants: int = 30
    test_plants: int = 30
    train_seed: int = 1000
    validation_seed: int = 5000
    test_seed: int = 9000
    rotations: int = 8
    held_out_rotations: int = 2
    n1: int = 4
    cloud_points: int = 512
    seed: int = 0

    def __post_init__(self):
        for name in ("train_plants", "validation_plants", "test_plants", "rotations", "held_out_rotations", "n1",
                     "cloud_points"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < (0 if "plants" in name else 1):
                raise ConfigError(f"dataset {name} must be a positive integer, got {value!r}")
        if not self.species:
            raise ConfigError("dataset species must name at least one species")
        seeds = {s: self.seeds(s) for s in SPLITS}
        for a in SPLITS:
            for b in SPLITS:
                if a < b and set(seeds[a]) & set(seeds[b]):
                    raise ConfigError(f"dataset {a} and {b} seeds overlap: move {a}_seed or {b}_seed")
        if set(range(3)) & set(seeds["train"]):
            raise ConfigError("training seeds must not include the Table I plants (seeds 0-2)")

    def seeds(self, split: str) -> range:
        per_species = math.ceil(getattr(self, f"{split}_plants") / len(self.species))
        start = getattr(self, f"{split}_seed")
        return range(start, start + per_species)

    def plants(self, split: str) -> list[tuple]:
        """``(species, seed, rotations)`` of the split's plants."""
        rotations = self.rotations if split == "train" else self.held_out_rotations
        plants = [(species, seed, rotations) for seed in self.seeds(split) for species in self.species]
        return plants[:getattr(self, f"{split}_plants")]


# --------------------------------------------------------------------------------------------------
# one rendered plant: greedy trajectories, long-tail states, labels
# --------------------------------------------------------------------------------------------------


def greedy_trajectories(seen: np.ndarray) -> list[list[int]]:
    """From every start view, the oracle greedy order (most newly seen voxels next, ties to the lowest
    index) until everything any view sees is seen. ``seen``: bool (views, visible voxels)."""
    trajectories = []
    for start in range(len(seen)):
        order, covered = [start], seen[start].copy()
        while not covered.all():
            gains = (seen & ~covered).sum(axis=1)
            gains[order] = -1
            view = int(np.argmax(gains))
            if gains[view] <= 0:
                break
            order.append(view)
            covered |= seen[view]
        trajectories.append(order)
    return trajectories


def mean_gains(seen: np.ndarray, trajectories) -> np.ndarray:
    """``d[m]``: mean over the trajectories of the fraction of visible voxels that the (m+1)-th view adds."""
    n = seen.shape[1]
    d = np.zeros(len(seen))
    for order in trajectories:
        covered = np.zeros(n, dtype=bool)
        for m, view in enumerate(order):
            d[m] += (seen[view] & ~covered).sum() / n
            covered |= seen[view]
    return d / len(trajectories)


def long_tail_states(seen: np.ndarray, n1: int, rng) -> list[list[int]]:
    """MA-SCVP's long-tail sample of states (ordered view lists) from the greedy prefixes that do
    not yet see everything."""
    trajectories = greedy_trajectories(seen)
    d = mean_gains(seen, trajectories)
    states = []
    for size in range(1, len(seen)):
        if d[1] <= 0:
            break
        count = math.ceil(n1 * d[size] / d[1] - 1e-12)
        candidates = {}
        for order in trajectories:
            if len(order) > size:  # the prefix leaves something to see
                candidates.setdefault(frozenset(order[:size]), order[:size])
        if count <= 0 or not candidates:
            continue
        keys = sorted(candidates, key=sorted)
        chosen = rng.choice(len(keys), size=min(count, len(keys)), replace=False)
        states.extend(candidates[keys[i]] for i in sorted(chosen))
    return states


def cover_label(visible, state) -> tuple[np.ndarray, bool]:
    """An exact minimum set of views (bool per view) that sees every visible voxel not seen by
    ``state``; and whether the solver proved it optimal. ``visible``: sparse (views, visible voxels)."""
    result = solve_set_cover(visible, executed=list(state), config=SetCoverConfig(solver="highs", time_limit=10.0))
    label = np.zeros(visible.shape[0], dtype=bool)
    label[np.asarray(result.selected, dtype=int)] = True
    return label, bool(result.optimal)


def coverage_gains(seen: np.ndarray, state) -> np.ndarray:
    """Each view's true coverage gain: the fraction of visible voxels it sees that ``state`` did not."""
    covered = seen[list(state)].any(axis=0)
    gains = (seen & ~covered).sum(axis=1) / seen.shape[1]
    gains[list(state)] = 0.0
    return gains.astype(np.float32)


def sample_cloud(points: np.ndarray, count: int, rng) -> np.ndarray:
    """``count`` points drawn without replacement (with replacement when there are fewer)."""
    idx = rng.choice(len(points), size=count, replace=len(points) < count)
    return points[np.sort(idx)].astype(np.float32)


def rendered_views(points, rotation_deg: float):
    """One plant (hemisphere, paper configuration) rotated about the vertical, in the simulator's
    measurement model (its planning frame, ground-truth grid and visibility, as
    :func:`tpvp.simulate.world.build_scene` renders today's plant): (view positions, per-view
    observed plant points, bool (views, visible voxels): what each view sees)."""
    config = make_config("plant", {"view_space": "hemisphere", "scene.rotation_deg": float(rotation_deg)})
    frame = planning_frame(points, config, "current-session scan")
    space, plant = frame.view_space, frame.reference
    grid = plant_grid(plant.points, plant.table_points, config.gt_resolution)
    truth = visibility_matrix(grid, space.positions, space.look_ats, frame.sensor)
    observations = [grid.centres[truth[v].indices] for v in range(len(space))]
    return space.positions, observations, truth[:, oracle_voxels(truth)].toarray().astype(bool)


def state_sample(positions, observations, seen, states, cloud_points: int, rng) -> dict:
    """Inputs and targets of ``states`` (ordered view lists) of one rendered plant."""
    visible = sparse.csr_matrix(seen)
    n = len(states)
    out = {"grids": np.zeros((n, CELLS, CELLS, CELLS), np.float16), "states": np.zeros((n, VIEWS), bool),
           "orders": np.full((n, VIEWS), -1, np.int8), "labels": np.zeros((n, VIEWS), bool),
           "gains": np.zeros((n, VIEWS), np.float32), "clouds": np.zeros((n, cloud_points, 3), np.float32),
           "optimal": np.zeros(n, bool), "coverage": np.zeros(n)}
    for i, state in enumerate(states):
        out["grids"][i] = occupancy_grid(np.zeros(3), positions[state], [observations[v] for v in state])
        out["states"][i, state] = True
        out["orders"][i, :len(state)] = state
        out["labels"][i], out["optimal"][i] = cover_label(visible, state)
        out["gains"][i] = coverage_gains(seen, state)
        out["clouds"][i] = sample_cloud(np.concatenate([observations[v] for v in state]), cloud_points, rng)
        out["coverage"][i] = seen[state].any(axis=0).mean()
    return out


def plant_samples(plant: tuple, split: str, config: DatasetConfig) -> list[dict]:
    """Every sampled state of one plant over its rotations (a worker task)."""
    species, seed, rotations = plant
    points = generate_session_pair(species, seed, days=2.0).current.points
    parts = []
    for r in range(rotations):
        rotation = 360.0 * r / config.rotations
        rng = np.random.default_rng([config.seed, seed, r, config.species.index(species)])
        positions, observations, seen = rendered_views(points, rotation)
        states = long_tail_states(seen, config.n1, rng)
        sample = state_sample(positions, observations, seen, states, config.cloud_points, rng)
        sample["index"] = pd.DataFrame({"split": split, "species": species, "seed": seed, "rotation_deg": rotation,
                                        "size": [len(s) for s in states], "label_size": sample["labels"].sum(1),
                                        "label_optimal": sample.pop("optimal"),
                                        "coverage": sample.pop("coverage")})
        parts.append(sample)
    return parts


def _plant_task(job, config):
    number, split, plant = job
    return [(number, plant_samples(plant, split, config))]  # one entry per plant: the bar counts plants


# --------------------------------------------------------------------------------------------------
# writing and reading
# --------------------------------------------------------------------------------------------------


def generate_dataset(folder, config: DatasetConfig = DatasetConfig(), workers: int = 2, progress: bool = True) -> dict:
    """Render, sample and label every plant of ``config``; write the dataset to ``folder``.
    Returns the manifest. Deterministic given ``config`` (states, labels, clouds)."""
    folder = Path(folder)
    t0 = time.perf_counter()
    jobs = [(split, plant) for split in SPLITS for plant in config.plants(split)]
    if not any(split == "train" for split, _ in jobs):
        raise ConfigError("the dataset has no training plant: set train_plants >= 1")
    done = run_cases(_plant_task, [(i, *job) for i, job in enumerate(jobs)], (config,), 1, workers=workers,
                     progress=progress, desc="learning dataset")
    # split, seed, species name: the order of the shipped dataset
    done = sorted(done, key=lambda item: (SPLITS.index(jobs[item[0]][0]), jobs[item[0]][1][1], jobs[item[0]][1][0]))
    parts = [part for _, plant in done for part in plant]
    index = pd.concat([p["index"] for p in parts], ignore_index=True)
    seconds = time.perf_counter() - t0
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "manifest.json").unlink(missing_ok=True)  # the folder is incomplete until it is rewritten
    for name, dtype in ARRAYS.items():
        with atomic_path(folder / f"{name}.npy") as tmp:
            np.save(tmp, np.concatenate([p[name] for p in parts]).astype(dtype))
    with atomic_path(folder / "index.parquet") as tmp:
        index.to_parquet(tmp)
    manifest = {"version": DATASET_VERSION, "config": asdict(config), "states": len(index),
                "states_per_split": index["split"].value_counts().reindex(list(SPLITS), fill_value=0).to_dict(),
                "plants_per_split": {s: len(config.plants(s)) for s in SPLITS},
                "label_optimal_fraction": float(index["label_optimal"].mean()),
                "seconds": round(seconds, 1), "workers": workers}
    atomic_write_text(folder / "manifest.json", json.dumps(manifest, indent=2, default=str))
    return manifest


@dataclass(frozen=True, eq=False)
class Dataset:
    """A loaded dataset: the arrays (memory-mapped) and the per-state index."""

    folder: Path
    manifest: dict
    index: pd.DataFrame
    arrays: dict

    def split(self, name: str) -> np.ndarray:
        """Row numbers of one split."""
        return np.flatnonzero(self.index["split"].to_numpy() == name)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.arrays[name]


def load_dataset(folder) -> Dataset:
    """A dataset written by :func:`generate_dataset`; one clear error when it is incomplete or damaged."""
    folder = Path(folder)
    manifest_path = folder / "manifest.json"
    if not manifest_path.is_file():
        raise InputFileError(f"{folder}: no manifest.json - not a (complete) learning dataset; "
                             f"generate one with python -m tpvp.learning generate --out {folder}")
    try:
        manifest = json.loads(manifest_path.read_text())
        index = pd.read_parquet(folder / "index.parquet")
        arrays = {name: np.load(folder / f"{name}.npy", mmap_mode="r") for name in ARRAYS}
    except (OSError, ValueError, json.JSONDecodeError) as exc:
        raise InputFileError(f"{folder}: damaged learning dataset ({exc}); generate it again") from None
    for name, array in arrays.items():
        if len(array) != len(index) or len(index) != manifest.get("states"):
            raise InputFileError(f"{folder / (name + '.npy')}: {len(array)} states, the index has {len(index)} "
                                 f"and the manifest {manifest.get('states')}; generate the dataset again")
    return Dataset(folder, manifest, index, arrays)
