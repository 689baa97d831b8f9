"""Conservative inflation of the transferred geometry (paper "Conservative Inflation",
P~+ = P~ u Q u I; docs/single_plant.md#inflation).

An inflation point is near the current coarse reconstruction Q but far from the warped previous
session P~: new growth that Q saw and P~ lacks.

* :func:`inflate` - single plant (docs/single_plant.md#inflation): candidates on a regular grid, KD-tree distances.
* :func:`inflate_voxels` - greenhouse rows (docs/greenhouse.md#inflation): voxel-set morphology.

Deviation from the single-plant reference: when no candidate survives, the authors' code plans on
P~ alone and drops Q as well; here Q is always part of the planning cloud (the paper's equation,
and Q is needed as an occluder for ray casting).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from tpvp.errors import ConfigError, checked_cloud
from tpvp.inflation.config import InflationConfig
from tpvp.scene import voxels

# Refuse candidate grids larger than this (a sign of wrong units or a wrong half_size).
# The planning surface's parts in the order that claims a voxel: the transferred previous session,
# the coarse reconstruction, the inflation layer.
SURFACE_LAYERS = ("transferred P~", "coarse Q", "inflation I")
_MAX_CANDIDATES = 50_000_000


@dataclass(frozen=True)
class InflationResult:
    """inflation: (K, 3) points I. planning: P~ u Q u I (in that order, duplicates kept).
    counts: candidates, near_current (survived the Q test), inflation, warped, current, planning."""

    inflation: np.ndarray
    planning: np.ndarray
    counts: dict = field(default_factory=dict)


def _vector3(value, name: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be 3 numbers, got {value!r}") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ConfigError(f"{name} must be 3 finite numbers, got {value!r}")
    return v


def _positive(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a positive number of metres, got {value!r}") from None
    if not (np.isfinite(v) and v > 0):
        raise ConfigError(f"{name} must be a positive number of metres, got {value!r}")
    return v


def candidate_grid(centre, half_size: float, step: float) -> np.ndarray:
    """Regular grid c - S + i*step, i = 0.. while < c + S (the end is exclusive), per axis."""
    centre = _vector3(centre, "centre")
    half_size = _positive(half_size, "half_size")
    step = _positive(step, "step")
    n = int(np.ceil(2 * half_size / step - 1e-9))  # np.arange's count, robust to rounding
    if n**3 > _MAX_CANDIDATES:
        raise ConfigError(f"half_size={half_size} m with step={step} m gives {n**3} candidates; "
                          f"are half_size and step in metres?")
    axis = np.arange(n) * step - half_size
    g = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    return g + centre


def inflate(P_warped, Q, centre, half_size: float, config: InflationConfig | None = None) -> InflationResult:
    """Single-plant inflation: grid candidates in the cube centre +- half_size (m) that lie within
    gamma_near of Q and beyond gamma_far of P~; returns I and the planning cloud P~ u Q u I."""
    config = InflationConfig() if config is None else config
    if not isinstance(config, InflationConfig):
        raise ConfigError(f"config must be an InflationConfig, got {type(config).__name__}")
    P_warped = checked_cloud(P_warped, "warped previous cloud P~")
    Q = checked_cloud(Q, "current cloud Q")
    if not config.enabled:
        counts = {"candidates": 0, "near_current": 0, "inflation": 0, "warped": len(P_warped),
                  "current": len(Q), "planning": len(P_warped)}
        return InflationResult(inflation=np.zeros((0, 3)), planning=P_warped, counts=counts)
    cand = candidate_grid(centre, half_size, config.step)
    n_cand = len(cand)
    inflation = np.zeros((0, 3))
    # Q first: only a thin shell around Q survives, so the P~ query runs on few points.
    # The upper bounds let the KD-tree prune; the strict tests decide.
    d_q = cKDTree(Q).query(cand, distance_upper_bound=2 * config.gamma_near)[0]
    cand = cand[d_q < config.gamma_near]
    near_count = len(cand)
    if near_count:
        d_p = cKDTree(P_warped).query(cand, distance_upper_bound=2 * config.gamma_far)[0]
        inflation = cand[d_p > config.gamma_far]  # inf (nothing within the bound) counts as far
    planning = np.concatenate([P_warped, Q, inflation])
    counts = {"candidates": n_cand, "near_current": near_count, "inflation": len(inflation),
              "warped": len(P_warped), "current": len(Q), "planning": len(planning)}
    return InflationResult(inflation=inflation, planning=planning, counts=counts)


def inflate_voxels(P_warped, Q, voxel: float = 0.01, gamma_near: float = 0.01, gamma_far: float = 0.01,
                   roi_centre=None, roi_half=None) -> InflationResult:
    """Greenhouse-row inflation by voxel morphology (docs/greenhouse.md#inflation).

    Keys floor(p / voxel); C = voxels of Q, H = voxels of P~; I = centres of
    dilate(C, gamma_near) minus dilate(H, gamma_far) minus C, the dilation by all integer offsets with
    |o| <= gamma / voxel. With a ROI (axis-aligned cube roi_centre +- roi_half, m) points outside it
    are dropped - from the planning cloud too - and dilation does not leave the keys it spans.
    Planning cloud = P~ u Q u I (Q always added, as in the reference for rows).
    """
    P_warped = checked_cloud(P_warped, "warped previous cloud P~")
    Q = checked_cloud(Q, "current cloud Q")
    voxel = _positive(voxel, "voxel")
    gamma_near = _positive(gamma_near, "gamma_near")
    gamma_far = _positive(gamma_far, "gamma_far")
    lo_key = hi_key = None
    if (roi_centre is None) != (roi_half is None):
        raise ConfigError("give both roi_centre and roi_half, or neither")
    if roi_centre is not None:
        c, h = _vector3(roi_centre, "roi_centre"), _positive(roi_half, "roi_half")
        P_warped = P_warped[np.all(np.abs(P_warped - c) <= h, axis=1)]
        Q = Q[np.all(np.abs(Q - c) <= h, axis=1)]
        # a key is inside the ROI iff some point of the cube falls in it
        lo_key = voxels.voxel_keys((c - h)[None], voxel)[0]
        hi_key = voxels.voxel_keys((c + h)[None], voxel)[0]
    C = voxels.voxelise(Q, voxel)
    H = voxels.voxelise(P_warped, voxel)
    near = voxels.dilate_keys(C, gamma_near / voxel) if len(C) else C
    if lo_key is not None and len(near):
        near = near[np.all((near >= lo_key) & (near <= hi_key), axis=1)]
    far = voxels.dilate_keys(H, gamma_far / voxel) if len(H) else H
    added = voxels.difference_keys(voxels.difference_keys(near, far), C) if len(near) else near
    inflation = voxels.key_centres(added, voxel)
    planning = np.concatenate([P_warped, Q, inflation])
    counts = {"candidates": len(near), "near_current": len(near), "inflation": len(inflation),
              "warped": len(P_warped), "current": len(Q), "planning": len(planning)}
    return InflationResult(inflation=inflation, planning=planning, counts=counts)
