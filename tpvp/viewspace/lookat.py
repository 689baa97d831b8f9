"""Look-at targets and 6D candidate views of a greenhouse row (docs/greenhouse.md#look-at-candidates).

A row's candidate positions are fixed (1,000 per room); the planner chooses where they look. The
three priors of the paper's ladder give 100 targets each:

* PriorOBB (:func:`box_targets`): spread evenly in the plant box, no observation at all;
* PriorPassive (:func:`passive_targets`): farthest-point samples on the surface frontiers of the
  passive reconstruction (unknown voxels next to both free space and a surface);
* PriorTransfer (:func:`transfer_targets`): farthest-point samples on the transferred and inflated
  previous session where the passive reconstruction did not see it.

:func:`round_robin_views` turns targets into views: ``rounds`` times, each target in turn (in a
shuffled order) takes its nearest still unused candidate position (k-NN with balanced round-robin
allocation), so every target gets ``rounds`` views and no position serves twice.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tpvp.errors import ConfigError, PointCloudError
from tpvp.scene import voxels

PRIORS = ("obb", "passive", "transfer")
_FACE_OFFSETS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.int64)


@dataclass(frozen=True, eq=False)
class CandidateViews:
    """6D candidate views: ``positions``/``look_ats`` (V, 3); ``position_ids`` index the room's
    candidate positions, ``target_ids`` the ``targets`` (T, 3) each view looks at."""

    prior: str
    targets: np.ndarray
    positions: np.ndarray
    look_ats: np.ndarray
    position_ids: np.ndarray
    target_ids: np.ndarray

    def __len__(self) -> int:
        return len(self.positions)


def _count(count) -> int:
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ConfigError(f"target count must be a positive integer, got {count!r}")
    return int(count)


def farthest_point_sampling(points, count: int, seed: int = 0) -> np.ndarray:
    """Indices of ``count`` points chosen greedily farthest from those already chosen, starting
    from a random point (``seed``); all points when there are at most ``count``."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    count = _count(count)
    if len(points) == 0:
        raise PointCloudError("farthest-point sampling: no points to sample from")
    if len(points) <= count:
        return np.arange(len(points))
    chosen = np.empty(count, dtype=np.int64)
    chosen[0] = np.random.default_rng(seed).integers(len(points))
    nearest = ((points - points[chosen[0]]) ** 2).sum(axis=1)
    for i in range(1, count):  # one vectorised distance update per target, not per point
        chosen[i] = int(np.argmax(nearest))
        np.minimum(nearest, ((points - points[chosen[i]]) ** 2).sum(axis=1), out=nearest)
    return chosen


def box_targets(box, count: int = 100, seed: int = 0, samples_per_target: int = 64) -> np.ndarray:
    """PriorOBB: ``count`` targets spread evenly in an oriented box (farthest-point samples of a
    uniform sample, a Poisson-disk-like spread). The bundled rooms hold the authors' own 100
    (``RoomConfig.rand_look_at_points``)."""
    count = _count(count)
    rng = np.random.default_rng(seed)
    sample = box.sample_uniform(count * int(samples_per_target), rng)
    return sample[farthest_point_sampling(sample, count, seed)]


def free_space_keys(cameras, points, voxel: float) -> np.ndarray:
    """Keys of the voxels crossed by the rays from each camera to its observed point, the point's
    own voxel excluded (sampled every half voxel). ``cameras`` (N, 3) or (3,), ``points`` (N, 3)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    cameras = np.broadcast_to(np.asarray(cameras, dtype=np.float64).reshape(-1, 3), points.shape)
    if len(points) == 0:
        return np.zeros((0, 3), dtype=np.int64)
    step = 0.5 * voxel
    offsets = points - cameras
    lengths = np.linalg.norm(offsets, axis=1)
    directions = offsets / np.maximum(lengths, 1e-12)[:, None]
    keys = []
    n_steps = int(np.ceil(lengths.max() / step))
    chunk = max(1, 2_000_000 // max(n_steps, 1))
    t = np.arange(n_steps) * step
    for start in range(0, len(points), chunk):
        stop = start + chunk
        inside = t[None, :] < (lengths[start:stop, None] - voxel)  # stop a voxel short of the surface
        samples = cameras[start:stop, None, :] + directions[start:stop, None, :] * t[None, :, None]
        keys.append(voxels.unique_keys(voxels.voxel_keys(samples[inside], voxel)))
    return voxels.unique_keys(np.concatenate(keys))


def surface_frontiers(occupied_keys, free_keys) -> np.ndarray:
    """Keys of the unknown voxels (neither occupied nor free) with a free and an occupied face
    neighbour: where a surface continues into space no view has seen."""
    occupied_keys = np.asarray(occupied_keys, dtype=np.int64).reshape(-1, 3)
    free_keys = np.asarray(free_keys, dtype=np.int64).reshape(-1, 3)
    if len(occupied_keys) == 0:
        return np.zeros((0, 3), dtype=np.int64)
    near_surface = voxels.unique_keys((occupied_keys[:, None, :] + _FACE_OFFSETS[None]).reshape(-1, 3))
    unknown = voxels.difference_keys(voxels.difference_keys(near_surface, occupied_keys), free_keys)
    if len(unknown) == 0 or len(free_keys) == 0:
        return unknown[:0]
    neighbours = (unknown[:, None, :] + _FACE_OFFSETS[None]).reshape(-1, 3)
    touches_free = voxels.contains_keys(free_keys, neighbours).reshape(-1, 6).any(axis=1)
    return unknown[touches_free]


def passive_targets(cameras, points, voxel: float, count: int = 100, seed: int = 0, box=None) -> np.ndarray:
    """PriorPassive: farthest-point samples on the surface frontiers of the passive reconstruction
    (``points`` observed from ``cameras``, one camera per point), at voxel ``voxel``; only frontiers
    inside ``box`` (the plant box) when given."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0:
        raise PointCloudError("the passive reconstruction is empty: no surface frontier to look at")
    occupied = voxels.voxelise(points, voxel)
    frontier = voxels.key_centres(surface_frontiers(occupied, free_space_keys(cameras, points, voxel)), voxel)
    if box is not None:
        frontier = frontier[box.contains(frontier)]
    if len(frontier) == 0:
        raise PointCloudError("the passive reconstruction has no surface frontier inside the plant box")
    return frontier[farthest_point_sampling(frontier, count, seed)]


def transfer_targets(warped, coarse, inflation_points, voxel: float, count: int = 100, seed: int = 0) -> np.ndarray:
    """PriorTransfer: farthest-point samples on the voxel centres of the aligned previous session
    not seen in the coarse reconstruction, plus the inflation voxels: ``(H \\ C) u A``."""
    seen = voxels.voxelise(np.asarray(coarse, dtype=np.float64).reshape(-1, 3), voxel)
    transferred = voxels.difference_keys(voxels.voxelise(np.asarray(warped, dtype=np.float64).reshape(-1, 3), voxel), seen)
    surface = np.concatenate([voxels.key_centres(transferred, voxel), np.asarray(inflation_points).reshape(-1, 3)])
    if len(surface) == 0:
        raise PointCloudError("the transferred previous session adds nothing to the coarse reconstruction: "
                              "no look-at target to sample")
    return surface[farthest_point_sampling(surface, count, seed)]


def round_robin_views(targets, positions, rounds: int = 8, seed: int = 0, prior: str = "") -> CandidateViews:
    """``rounds`` rounds; in each, every target in a shuffled order takes its nearest unused
    position. Stops early when the positions run out (each target then has ``rounds`` or
    ``rounds - 1`` views)."""
    targets = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(targets) == 0 or len(positions) == 0:
        raise ConfigError(f"round robin needs targets and positions, got {len(targets)} and {len(positions)}")
    rng = np.random.default_rng(seed)
    by_distance = np.argsort(((targets[:, None, :] - positions[None, :, :]) ** 2).sum(axis=-1), axis=1, kind="stable")
    cursor = np.zeros(len(targets), dtype=np.int64)  # first entry of a target's list not yet known used
    used = np.zeros(len(positions), dtype=bool)
    chosen_positions, chosen_targets = [], []
    for _ in range(int(rounds)):
        for target in rng.permutation(len(targets)):
            if len(chosen_positions) == len(positions):
                break
            row = by_distance[target]
            while used[row[cursor[target]]]:
                cursor[target] += 1
            position = row[cursor[target]]
            used[position] = True
            chosen_positions.append(position)
            chosen_targets.append(target)
    position_ids = np.asarray(chosen_positions, dtype=np.int64)
    target_ids = np.asarray(chosen_targets, dtype=np.int64)
    return CandidateViews(prior, targets, positions[position_ids], targets[target_ids], position_ids, target_ids)


def assigned_views(positions, look_ats, prior: str = "") -> CandidateViews:
    """Candidate views from a per-position look-at table (``(P, 3)``, an all-zero row marks an
    unused position), e.g. the authors' ``gap_1`` files (:func:`tpvp.scene.boxes.candidate_look_ats`)."""
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    look_ats = np.asarray(look_ats, dtype=np.float64).reshape(-1, 3)
    if len(positions) != len(look_ats):
        raise ConfigError(f"{len(look_ats)} look-ats for {len(positions)} positions")
    used = np.flatnonzero(np.any(look_ats != 0, axis=1))
    targets, target_ids = np.unique(look_ats[used], axis=0, return_inverse=True)
    return CandidateViews(prior, targets, positions[used], look_ats[used], used, target_ids.reshape(-1))
