"""Organ classes of a plant's points: one code per class, and each data source's labels as codes.

A point cloud's integer labels mean what its source says: Pheno4D's annotations (0 soil, 1 stem,
2+ one per leaf), the generated plants' parts, the generated rows' classes, Helios' organs. The
planner reports coverage per organ class (:data:`ORGANS`), so every source's labels are turned
into these codes once, when read (:func:`organ_codes`). ``unknown`` is what a voxel without a
labelled point holds (the inflation's growth voxels, a capture).
"""

from __future__ import annotations

import numpy as np

from tpvp.errors import ConfigError
from tpvp.scene import voxels
from tpvp.scene.config import ORGANS

CODE = {name: code for code, name in enumerate(ORGANS)}
#: What a source's labels mean -> its label -> organ class (``None``: a rule, see :func:`organ_codes`).
LABEL_KINDS = {
    "organ": None,  # the labels are organ codes already (a Helios dataset, tpvp's own files)
    "pheno4d": None,  # 0 soil, 1 stem, 2+ a leaf each
    "generated-row": {0: "stem", 1: "leaf", 2: "fruit", 3: "petiole"},  # tpvp.synthetic.greenhouse
}


def organ_codes(labels, kind: str) -> np.ndarray:
    """The organ code of every label of a source of ``kind`` (:data:`LABEL_KINDS`); labels it
    does not name are ``unknown``."""
    labels = np.asarray(labels, dtype=np.int64)
    if kind not in LABEL_KINDS:
        raise ConfigError(f"unknown label kind {kind!r}; choose one of {', '.join(LABEL_KINDS)}")
    if kind == "organ":
        return np.where((labels >= 0) & (labels < len(ORGANS)), labels, CODE["unknown"])
    if kind == "pheno4d":
        return np.select([labels == 1, labels >= 2], [CODE["stem"], CODE["leaf"]], CODE["unknown"])
    codes = np.full(len(labels), CODE["unknown"], dtype=np.int64)
    for label, organ in LABEL_KINDS[kind].items():
        codes[labels == label] = CODE[organ]
    return codes


def part_organ_codes(part_kinds, parts) -> np.ndarray:
    """A generated plant's points (:class:`tpvp.synthetic.plants.PlantSample`: the kind of every
    part, ``stem`` / ``petiole`` / ``blade``, and each point's part) as organ codes."""
    by_kind = {"stem": CODE["stem"], "petiole": CODE["petiole"], "blade": CODE["leaf"]}
    return np.array([by_kind[kind] for kind in part_kinds], dtype=np.int64)[np.asarray(parts)]


def voxel_organs(keys, resolution: float, points, organs) -> np.ndarray:
    """The organ code of each voxel ``keys`` (``(n, 3)`` at ``resolution``): the most frequent
    among the labelled ``points`` in it (the lowest code on ties), ``unknown`` where none lies."""
    keys = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
    result = np.full(len(keys), CODE["unknown"], dtype=np.int64)
    if len(keys) == 0 or len(points) == 0:
        return result
    codes = voxels.encode_keys(keys)
    order = np.argsort(codes)
    point_codes = voxels.encode_keys(voxels.voxel_keys(points, resolution))
    slot = np.searchsorted(codes[order], point_codes)
    inside = slot < len(codes)
    inside[inside] = codes[order][slot[inside]] == point_codes[inside]
    votes = np.zeros((len(keys), len(ORGANS)), dtype=np.int64)
    np.add.at(votes, (order[slot[inside]], np.asarray(organs, dtype=np.int64)[inside]), 1)
    labelled = votes.sum(axis=1) > 0
    result[labelled] = np.argmax(votes[labelled], axis=1)
    return result


def organ_shares(covered, ids, organs) -> dict:
    """Organ -> the share of its voxels among ``ids`` (voxel ids: those some view can see) that are
    in ``covered`` (voxel ids); ``organs``: the organ code of every voxel id."""
    seen = np.isin(ids, covered)
    codes = np.asarray(organs)[ids]
    return {ORGANS[code]: float(seen[codes == code].mean()) for code in np.unique(codes)}


def reduced_organs(reduced, points, organs, resolution: float):
    """The organ codes of ``reduced``, the voxel centroids at ``resolution`` of the labelled
    ``points`` (a scan reduced before planning): each centroid takes its voxel's majority; the
    codes as they are when nothing was reduced, None without codes."""
    if organs is None or len(reduced) == len(points):
        return organs
    return voxel_organs(voxels.voxel_keys(reduced, resolution), resolution, points, organs)


def check_organ_targets(targets: dict, organs, name: str) -> None:
    """Refuse per-organ ``targets`` (organ -> share) naming an organ that no point of the labelled
    previous model ``name`` holds (``organs``: its points' codes; None, no labels, is the planner's
    own error): a share of nothing is met by any plan, so the target is a typo or the wrong scan."""
    if not targets or organs is None:
        return
    counts = np.bincount(np.asarray(organs, dtype=np.int64).ravel(), minlength=len(ORGANS))
    absent = [organ for organ in targets if counts[CODE[organ]] == 0]
    if absent:
        asked = ",".join(f"{organ}={targets[organ]:g}" for organ in absent)
        has = ", ".join(f"{ORGANS[code]} {counts[code]:,} points" for code in np.flatnonzero(counts))
        raise ConfigError(f"organ targets {asked}: {name} has no {' or '.join(absent)} point (its organs: {has}); "
                          f"target an organ it has, or check the scan and its --labels")
