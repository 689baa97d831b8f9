"""Procedural multi-session greenhouse tomato rows (stand-ins for the authors' row dataset).

The real dataset (five sessions of two rows, "room1" and "room4", Sep. 15-29 2025) is not
redistributable; this module generates realistic substitutes, deterministic by seed:

* a row of 8-12 high-wire tomato plants that fills the room's real plant box (row axis = box local x,
  width = local y, height = local z; every point lies inside the box), in metres, in the room's world
  frame - the same frame as the bundled candidate views, so the generated rows plug into the
  simulator directly;
* each plant has a tubular main stem (radius 5.5-7.5 mm) from near the floor to the top of the box,
  slightly leaning along the row and zig-zagging at the nodes; a compound leaf at every node (every
  0.13-0.18 m of stem, alternating towards both aisles), 0.34-0.5 m long (less in narrow boxes),
  drooping with age, with 3-5 pairs of broad leaflets, small intercalary leaflets and a terminal
  leaflet; a fruit truss every third node (a hanging peduncle carrying 4-7 spheres of radius
  2-3.5 cm) in the lower-middle height; foliage dense enough that about a third of the 1 cm surface
  voxels cannot be seen from the 15 passive views;
* five sessions at the real dates (3-4 days apart). Between sessions stems extend at the top
  (1.2-1.8 cm/day) and new leaves unfold, young leaves elongate and droop, fruits swell and the
  trusses sag, the stems sway a few centimetres; growers remove the lowest leaves (de-leafing,
  continuously) and pick the lowest ripe truss of half of the plants on 20250922 and 20250929.
* organs that would reach a face of the box are bent smoothly inwards (a squeeze in the last
  0.1-0.18 m), so the row fills the box like the real data, which defined it.

Every session is evaluated from the same parametric surface samples (stem: arc length x angle;
leaflet: a regular grid on the flat blade; fruit: a Fibonacci sphere; ...) with per-session growth
parameters, so a sample that survives from one session to the next is the same material point:
``RowSession.sample_id`` identifies it, and :func:`row_correspondences` pairs them up. Removed and
new organs have no correspondences.

Surfaces are single layers of points sampled on a grid of ``point_spacing`` metres at the organ's
largest (final) size, so younger organs are sampled more densely; the default 0.004 m (0.4 x the
1 cm ground-truth voxel of the greenhouse setting) gives closed surfaces when voxelised at 1 cm.
"""

from __future__ import annotations

import datetime as _dt
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tpvp.errors import ConfigError, InputFileError
from tpvp.io import atomic_write_text, write_point_cloud
from tpvp.scene.boxes import OrientedBox, room_config
from tpvp.scene.voxels import voxelise

GENERATOR_VERSION = "1.0"
DATES = ("20250915", "20250918", "20250922", "20250925", "20250929")
HARVEST_SESSIONS = (2, 4)  # trusses are picked on 20250922 and 20250929

# point labels (RowSession.labels)
STEM, LEAF, FRUIT, PETIOLE = 0, 1, 2, 3
LABEL_NAMES = {STEM: "stem", LEAF: "leaf", FRUIT: "fruit", PETIOLE: "petiole/rachis/peduncle"}

# organ ids (RowSession.organ_id) = kind * ORGAN_STRIDE + index of the organ in its kind
ORGAN_STRIDE = 100_000
KIND_STEM, KIND_LEAF, KIND_TRUSS, KIND_FRUIT = 0, 1, 2, 3

_DAYS = np.array(
    [(_dt.date.fromisoformat(f"{d[:4]}-{d[4:6]}-{d[6:]}") - _dt.date(2025, 9, 15)).days for d in DATES],
    dtype=np.float64,
)
_MARGIN = 0.01  # all points stay at least this far inside the plant box
_SOFT_ZONE = np.array([0.12, 0.18, 0.10])  # width of the smooth squeeze band along the box faces (x, y, z)
_EMERGE = 0.03  # a node's leaf appears once the stem has grown this far past it (m)


# ============================================================================ public types
@dataclass(frozen=True, eq=False)
class RowSession:
    """One monitoring session of a generated row.

    ``points`` (N, 3) world coordinates in metres; ``labels`` (N,) point class (0 stem, 1 leaf blade,
    2 fruit, 3 petiole / leaf rachis / truss peduncle); ``plant_id`` (N,) plant index along the row;
    ``organ_id`` (N,) organ instance, ``kind * 100000 + index`` with kind 0 stem, 1 leaf (rachis and
    leaflets), 2 truss peduncle, 3 fruit - stable across sessions; ``sample_id`` (N,) material-point
    id, stable across sessions (see :func:`row_correspondences`). Arrays are read-only.
    """

    points: np.ndarray
    labels: np.ndarray
    plant_id: np.ndarray
    organ_id: np.ndarray
    sample_id: np.ndarray
    room: str
    date: str
    session: int
    seed: int
    point_spacing: float
    plant_box: OrientedBox

    def __post_init__(self):
        for name in ("points", "labels", "plant_id", "organ_id", "sample_id"):
            getattr(self, name).setflags(write=False)

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    def _count(self, kind: int) -> int:
        ids = np.unique(self.organ_id)
        return int(np.count_nonzero(ids // ORGAN_STRIDE == kind))

    @property
    def n_plants(self) -> int:
        return self._count(KIND_STEM)

    @property
    def n_leaves(self) -> int:
        """Compound leaves present."""
        return self._count(KIND_LEAF)

    @property
    def n_trusses(self) -> int:
        return self._count(KIND_TRUSS)

    @property
    def n_fruits(self) -> int:
        return self._count(KIND_FRUIT)

    def local_points(self) -> np.ndarray:
        """Points in the plant-box frame (x along the row, y across, z up; origin at the box centre)."""
        return self.plant_box.to_local(self.points)

    @property
    def name(self) -> str:
        """The real dataset's processed-model stem name, ``room<k>_<YYYYMMDD>``."""
        return f"{self.room}_{self.date}"


def row_correspondences(previous: RowSession, current: RowSession) -> tuple[np.ndarray, np.ndarray]:
    """Ground-truth correspondences between two sessions of the same generated row.

    Returns index arrays ``(i_prev, i_curr)`` such that ``previous.points[i_prev]`` and
    ``current.points[i_curr]`` are the same material points (surviving organs only; removed and new
    organs have none). Works for any two sessions of one ``(room, seed, point_spacing)``.
    """
    if (previous.room, previous.seed, previous.point_spacing) != (current.room, current.seed, current.point_spacing):
        raise ConfigError(
            "row_correspondences: sessions come from different rows "
            f"({previous.room}/seed {previous.seed}/spacing {previous.point_spacing} vs "
            f"{current.room}/seed {current.seed}/spacing {current.point_spacing})"
        )
    _, i_prev, i_curr = np.intersect1d(previous.sample_id, current.sample_id, assume_unique=True, return_indices=True)
    return i_prev.astype(np.int64), i_curr.astype(np.int64)


# ============================================================================ small helpers
def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _fib_sphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _grid_rows(counts_a: np.ndarray, counts_b: np.ndarray):
    """For organs with an (na x nb) parameter grid: organ index, ia, ib of every grid cell."""
    sizes = counts_a * counts_b
    owner = np.repeat(np.arange(sizes.size), sizes)
    local = np.arange(owner.size) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    nb = counts_b[owner]
    return owner, local // nb, local % nb


def _leaflet_shape(a: np.ndarray) -> np.ndarray:
    """Half-width profile of a tomato leaflet (ovate, widest at ~40 %, pointed tip), in [0, 1]."""
    return np.clip(np.sin(np.pi * np.clip(a, 0.0, 1.0) ** 0.75), 0.0, 1.0) ** 0.8


def _growth(age_days: np.ndarray) -> np.ndarray:
    """Relative size of a leaf of a given age (logistic expansion over ~3 weeks)."""
    return 1.0 / (1.0 + np.exp(-(age_days - 9.0) / 3.5))


def _soft_clamp(q: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Squeeze local coordinates smoothly into ``|q| < half - margin`` (identity in the interior)."""
    bound = half - _MARGIN
    knee = bound - _SOFT_ZONE
    a = np.abs(q)
    over = a > knee
    if not np.any(over):
        return q
    out = q.copy()
    kb = np.broadcast_to(knee, q.shape)[over]
    zone = np.broadcast_to(bound - knee, q.shape)[over]
    out[over] = np.sign(q[over]) * (kb + zone * np.tanh((a[over] - kb) / zone))
    return out


def _check_spacing(point_spacing) -> float:
    try:
        s = float(point_spacing)
    except (TypeError, ValueError):
        raise ConfigError(f"point_spacing must be a number of metres, got {point_spacing!r}") from None
    if not np.isfinite(s) or not (0.001 <= s <= 0.05):
        raise ConfigError(f"point_spacing must be between 0.001 and 0.05 m, got {point_spacing!r}")
    return s


def _check_session(session) -> int:
    if isinstance(session, (bool, np.bool_)) or not isinstance(session, (int, np.integer)):
        raise ConfigError(f"session must be an integer 0..{len(DATES) - 1}, got {session!r}")
    if not 0 <= int(session) < len(DATES):
        raise ConfigError(f"session must be in 0..{len(DATES) - 1} (dates {', '.join(DATES)}), got {session}")
    return int(session)


def _check_seed(seed) -> int:
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or int(seed) < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


# ============================================================================ the row model
class _Row:
    """All parameters of one row (drawn from the seed) and the parametric surface samples."""

    def __init__(self, room: str, box: OrientedBox, seed: int, spacing: float):
        self.room, self.box, self.seed, self.spacing = room, box, seed, spacing
        rng = np.random.default_rng(seed)
        L, W, H = (float(v) for v in box.extent)
        self.half = box.extent / 2.0
        zf = -H / 2.0 + _MARGIN  # floor
        top = H / 2.0 - _MARGIN
        n_s = len(DATES)

        # ---------------------------------------------------------------- plants / stems
        P = int(rng.integers(8, 13))
        self.P = P
        lean_sign = rng.choice([-1.0, 1.0])
        lam = np.radians(rng.uniform(3.0, 10.0, P))
        lean_az = np.where(lean_sign > 0, 0.0, np.pi) + rng.normal(0.0, 0.2, P)
        self.cos_lam = np.cos(lam)
        self.u_lean = np.stack([np.sin(lam) * np.cos(lean_az), np.sin(lam) * np.sin(lean_az), np.cos(lam)], 1)
        self.rate = rng.uniform(0.012, 0.018, P)  # stem extension, m/day
        tip_final = top - rng.uniform(0.0, 0.08, P)
        base_z = zf + rng.uniform(0.005, 0.05, P)
        self.S_final = (tip_final - base_z) / self.cos_lam
        self.S = self.S_final[None, :] - self.rate[None, :] * (_DAYS[-1] - _DAYS[:, None])  # (sessions, P)
        end = min(0.2, 0.45 * L / P)
        x_mid = np.linspace(-L / 2 + end, L / 2 - end, P) + rng.normal(0.0, 0.015, P)
        base_xy = np.stack([x_mid, np.clip(rng.normal(0.0, 0.025, P), -0.06, 0.06)], 1)
        base_xy -= self.u_lean[:, :2] * (self.S_final[:, None] / 2.0)  # mid-height on the plant's slot
        self.base = np.column_stack([base_xy, base_z])
        self.internode = rng.uniform(0.13, 0.18, P)
        self.r_stem = rng.uniform(0.0055, 0.0075, P)
        # lateral wobble (2 sinusoids) + zig-zag at the nodes, all horizontal
        self.wob_amp = rng.uniform(0.004, 0.014, (P, 2))
        self.wob_len = rng.uniform(1.0, 2.2, (P, 2))
        self.wob_ph = rng.uniform(0, 2 * np.pi, (P, 2))
        wob_az = rng.uniform(0, 2 * np.pi, (P, 2))
        self.wob_dir = np.stack([np.cos(wob_az), np.sin(wob_az), np.zeros_like(wob_az)], -1)
        self.zz_amp = rng.uniform(0.004, 0.01, P)
        self.zz_ph = rng.uniform(0, 2 * np.pi, P)
        sway_az = rng.uniform(0, 2 * np.pi, (n_s, P))
        sway_amp = rng.uniform(0.0, 0.035, (n_s, P))
        self.sway = np.stack([np.cos(sway_az), np.sin(sway_az), np.zeros_like(sway_az)], -1) * sway_amp[..., None]

        # grower operations (heights above the local box centre, per session and plant)
        self.deleaf = zf + H * rng.uniform(0.18, 0.26, P)[None, :] + 0.018 * _DAYS[:, None]
        harvest0 = zf + H * rng.uniform(0.14, 0.2, P)
        jumps = np.zeros((n_s, P))
        truss_step = 3 * self.internode * self.cos_lam  # height between successive trusses
        for k in HARVEST_SESSIONS:  # half of the plants have their lowest (ripe) truss picked
            picked = np.zeros(P, bool)
            picked[rng.permutation(P)[: (P + 1) // 2]] = True
            jumps[k] = np.where(picked, truss_step * rng.uniform(0.95, 1.1, P), rng.uniform(0.0, 0.05, P))
        self.harvest = harvest0[None, :] + np.cumsum(jumps, axis=0)
        self.fruit_set = (
            zf + H * rng.uniform(0.52, 0.6, P)[None, :] + (self.rate * self.cos_lam)[None, :] * _DAYS[:, None]
        )

        # ---------------------------------------------------------------- nodes, leaves, trusses
        leaf_scale = float(np.clip((W / 2 - 0.03) / 0.37, 0.75, 1.1))
        node_plant, node_s, node_idx = [], [], []
        for p in range(P):
            s = rng.uniform(0.06, 0.16)
            j = 0
            while s < self.S_final[p] - _EMERGE:
                node_plant.append(p)
                node_s.append(s)
                node_idx.append(j)
                s += self.internode[p] * rng.uniform(0.85, 1.15)
                j += 1
        node_plant = np.array(node_plant)
        node_s = np.array(node_s)
        node_idx = np.array(node_idx)
        nL = node_s.size
        self.leaf_plant, self.leaf_s = node_plant, node_s
        self.leaf_z = self.base[node_plant, 2] + node_s * self.cos_lam[node_plant]
        side0 = rng.choice([-1.0, 1.0], P)
        side = side0[node_plant] * np.where(node_idx % 2 == 0, 1.0, -1.0)
        self.leaf_az = side * np.pi / 2 + rng.normal(0.0, 0.6, nL)
        self.leaf_az_jit = rng.normal(0.0, 0.04, (n_s, nL))
        self.leaf_len = leaf_scale * rng.uniform(0.34, 0.5, nL)
        self.leaf_alpha_j = np.radians(rng.normal(0.0, 7.0, nL))
        self.leaf_droop = rng.uniform(0.8, 1.3, nL)
        self.r_rachis = rng.uniform(0.0025, 0.0035, nL)

        # leaflets: (leaf, u on rachis, side, angle to rachis, max length, max width, roll, cup, droop, tilt)
        lf_leaf, lf_u, lf_side, lf_beta, lf_len, lf_wid = [], [], [], [], [], []
        for i in range(nL):
            npairs = int(rng.integers(3, 6))
            us = np.linspace(0.22, 0.8, npairs) + rng.normal(0.0, 0.02, npairs)
            for u in us:
                for sd in (-1.0, 1.0):
                    lf_leaf.append(i)
                    lf_u.append(u + 0.015 * sd)
                    lf_side.append(sd)
                    lf_beta.append(np.radians(rng.uniform(45, 75)))
                    lf_len.append(self.leaf_len[i] * rng.uniform(0.3, 0.38) * (0.8 + 0.3 * u))
                    lf_wid.append(rng.uniform(0.55, 0.7))
            for u in 0.5 * (us[1:] + us[:-1]):  # small intercalary leaflets
                for sd in (-1.0, 1.0):
                    lf_leaf.append(i)
                    lf_u.append(u)
                    lf_side.append(sd)
                    lf_beta.append(np.radians(rng.uniform(60, 85)))
                    lf_len.append(self.leaf_len[i] * rng.uniform(0.08, 0.13))
                    lf_wid.append(rng.uniform(0.45, 0.55))
            lf_leaf.append(i)  # terminal leaflet
            lf_u.append(1.0)
            lf_side.append(0.0)
            lf_beta.append(rng.normal(0.0, 0.1))
            lf_len.append(self.leaf_len[i] * rng.uniform(0.3, 0.38))
            lf_wid.append(rng.uniform(0.55, 0.7))
        self.lf_leaf = np.array(lf_leaf)
        nF = self.lf_leaf.size
        self.lf_u = np.array(lf_u)
        self.lf_side = np.array(lf_side)
        self.lf_beta = np.array(lf_beta)
        self.lf_len = np.array(lf_len)
        self.lf_wid = np.array(lf_wid) * self.lf_len
        self.lf_roll = self.lf_side * rng.uniform(0.3, 1.0, nF) + rng.normal(0.0, 0.4, nF)
        self.lf_cup = rng.uniform(-0.1, 0.45, nF)
        self.lf_droop = rng.uniform(0.05, 0.3, nF)
        self.lf_tilt = np.radians(rng.uniform(0.0, 25.0, nF))
        self.lf_wave = rng.uniform(0, 2 * np.pi, nF)

        # trusses on every third node, between this leaf and the next one, on the other side
        offset = rng.integers(0, 3, P)
        is_truss = (node_idx % 3) == offset[node_plant]
        tn = np.flatnonzero(is_truss)
        nT = tn.size
        self.tr_plant = node_plant[tn]
        self.tr_s = node_s[tn] + 0.4 * self.internode[self.tr_plant]
        self.tr_z = self.base[self.tr_plant, 2] + self.tr_s * self.cos_lam[self.tr_plant]
        self.tr_az = self.leaf_az[tn] + np.pi + rng.normal(0.0, 0.5, nT)
        self.tr_reach = rng.uniform(0.08, 0.14, nT)
        self.tr_side = rng.normal(0.0, 0.03, nT)
        self.tr_r = rng.uniform(0.02, 0.035, nT)  # full-grown fruit radius
        tr_nfruit = rng.integers(4, 8, nT)
        self.tr_drop = 0.06 + tr_nfruit * self.tr_r * rng.uniform(0.8, 1.0, nT)
        self.fr_truss = np.repeat(np.arange(nT), tr_nfruit)
        nR = self.fr_truss.size
        k_in = np.arange(nR) - np.repeat(np.cumsum(tr_nfruit) - tr_nfruit, tr_nfruit)
        self.fr_u = 0.42 + 0.58 * (k_in + 0.5) / tr_nfruit[self.fr_truss]
        self.fr_gamma = k_in * 2.4 + rng.normal(0.0, 0.3, nR)
        self.fr_r = self.tr_r[self.fr_truss] * rng.uniform(0.85, 1.0, nR)
        self.n_leaves_total, self.n_trusses_total, self.n_fruits_total = nL, nT, nR

        self._build_samples()

    # ------------------------------------------------------------------ sample tables
    def _build_samples(self):
        sp = self.spacing
        offset = 0
        # stems: arc length x angle
        n_theta = max(3, int(np.ceil(2 * np.pi * self.r_stem.max() / sp)))
        n_sa = np.ceil(self.S_final / sp).astype(np.int64)
        owner, ia, ib = _grid_rows(n_sa, np.full(self.P, n_theta))
        self.st = dict(
            own=owner, s=(ia + 0.5) * sp, th=(ib + 0.5) * 2 * np.pi / n_theta, sid=offset + np.arange(owner.size)
        )
        offset += owner.size
        # leaf rachis: u x angle
        n_th_r = max(3, int(np.ceil(2 * np.pi * 0.0035 / sp)))
        n_u = np.ceil(self.leaf_len / sp).astype(np.int64) + 1
        owner, ia, ib = _grid_rows(n_u, np.full(n_u.size, n_th_r))
        self.ra = dict(
            own=owner, u=(ia + 0.5) / n_u[owner], th=(ib + 0.5) * 2 * np.pi / n_th_r, sid=offset + np.arange(owner.size)
        )
        offset += owner.size
        # leaflets: regular grid on the flat blade, kept inside the leaflet outline
        na = np.maximum(2, np.ceil(self.lf_len / sp).astype(np.int64))
        nb = np.maximum(2, np.ceil(self.lf_wid / sp).astype(np.int64))
        owner, ia, ib = _grid_rows(na, nb)
        a = (ia + 0.5) / na[owner]
        b = -1.0 + (2 * ib + 1.0) / nb[owner]
        keep = np.abs(b) <= _leaflet_shape(a) + 1e-9
        gid = np.arange(owner.size)[keep]
        self.lf = dict(own=owner[keep], a=a[keep], b=b[keep], sid=offset + gid)
        offset += owner.size
        # truss peduncles: u x angle
        n_th_p = max(3, int(np.ceil(2 * np.pi * 0.003 / sp)))
        n_up = np.ceil((self.tr_reach + self.tr_drop + 0.05) / sp).astype(np.int64) + 1
        owner, ia, ib = _grid_rows(n_up, np.full(n_up.size, n_th_p))
        self.pe = dict(
            own=owner, u=(ia + 0.5) / n_up[owner], th=(ib + 0.5) * 2 * np.pi / n_th_p, sid=offset + np.arange(owner.size)
        )
        offset += owner.size
        # fruits: Fibonacci spheres
        n_dir = np.maximum(12, np.ceil(4 * np.pi * self.fr_r**2 / sp**2).astype(np.int64))
        owner = np.repeat(np.arange(n_dir.size), n_dir)
        dirs = np.concatenate([_fib_sphere(int(n)) for n in n_dir]) if n_dir.size else np.zeros((0, 3))
        self.fr = dict(own=owner, d=dirs, sid=offset + np.arange(owner.size))
        offset += owner.size
        self.n_samples = offset

    # ------------------------------------------------------------------ geometry
    def centre(self, p: np.ndarray, s: np.ndarray, k: int) -> np.ndarray:
        """Stem centre line of plants ``p`` at arc lengths ``s`` in session ``k`` (local frame)."""
        c = self.base[p] + s[:, None] * self.u_lean[p]
        for m in range(2):
            wave = self.wob_amp[p, m] * np.sin(2 * np.pi * s / self.wob_len[p, m] + self.wob_ph[p, m])
            c += wave[:, None] * self.wob_dir[p, m]
        c[:, 1] += self.zz_amp[p] * np.sin(np.pi * s / self.internode[p] + self.zz_ph[p])
        c += ((s / self.S_final[p]) ** 2)[:, None] * self.sway[k, p]
        return c

    def stem_radius(self, p, s, k):
        return self.r_stem[p] * (0.55 + 0.45 * np.clip((self.S[k, p] - s) / 0.4, 0.0, 1.0))

    def _stems(self, k):
        t = self.st
        keep = t["s"] <= self.S[k, t["own"]]
        p, s, th = t["own"][keep], t["s"][keep], t["th"][keep]
        c = self.centre(p, s, k)
        tan = _unit(self.centre(p, s + 1e-3, k) - self.centre(p, s - 1e-3, k))
        e1 = _unit(np.cross(tan, np.array([1.0, 0.0, 0.0])))
        e2 = np.cross(tan, e1)
        r = self.stem_radius(p, s, k)[:, None]
        pts = c + r * (np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2)
        return pts, np.full(p.size, STEM), p, KIND_STEM * ORGAN_STRIDE + p, t["sid"][keep]

    def _leaf_state(self, k):
        """Per-leaf geometry of session k for the leaves present."""
        p = self.leaf_plant
        present = (self.S[k, p] >= self.leaf_s + _EMERGE) & (self.leaf_z > self.deleaf[k, p])
        age = (self.S[k, p] - self.leaf_s) / self.rate[p]
        g = _growth(age)
        alpha0 = np.radians(20.0) + np.radians(50.0) * np.exp(-age / 12.0) + self.leaf_alpha_j
        delta = -(np.radians(25.0) + np.radians(65.0) * (1.0 - np.exp(-age / 20.0))) * self.leaf_droop
        az = self.leaf_az + self.leaf_az_jit[k]
        d = np.stack([np.cos(az), np.sin(az), np.zeros_like(az)], 1)
        e = np.stack([-np.sin(az), np.cos(az), np.zeros_like(az)], 1)
        node = self.centre(p, self.leaf_s, k)
        base = node + self.stem_radius(p, self.leaf_s, k)[:, None] * d
        return dict(present=present, g=g, L=self.leaf_len * g, a0=alpha0, da=delta, d=d, e=e, base=base)

    @staticmethod
    def _rachis_at(st, i, u):
        """Position and unit tangent of leaf ``i``'s rachis at parameter ``u`` (exact arc-length curve)."""
        a0, da, L = st["a0"][i], st["da"][i], st["L"][i]
        au = a0 + da * u
        h = (np.sin(au) - np.sin(a0)) / da
        v = (np.cos(a0) - np.cos(au)) / da
        z = np.array([0.0, 0.0, 1.0])
        pos = st["base"][i] + (L * h)[:, None] * st["d"][i] + (L * v)[:, None] * z
        tan = np.cos(au)[:, None] * st["d"][i] + np.sin(au)[:, None] * z
        return pos, tan

    def _rachises(self, k, st):
        t = self.ra
        keep = st["present"][t["own"]]
        i, u, th = t["own"][keep], t["u"][keep], t["th"][keep]
        pos, tan = self._rachis_at(st, i, u)
        e = st["e"][i]
        n2 = np.cross(tan, e)
        r = (self.r_rachis[i] * (1.0 - 0.5 * u) * np.sqrt(np.maximum(st["g"][i], 0.3)))[:, None]
        pts = pos + r * (np.cos(th)[:, None] * e + np.sin(th)[:, None] * n2)
        return pts, np.full(i.size, PETIOLE), self.leaf_plant[i], KIND_LEAF * ORGAN_STRIDE + i, t["sid"][keep]

    def _leaflets(self, k, st):
        # per-leaflet frames
        li = self.lf_leaf
        att, tan = self._rachis_at(st, li, self.lf_u)
        e = st["e"][li]
        nb = _unit(np.cross(tan, e))  # "up" for a horizontal rachis
        sd, beta = self.lf_side, self.lf_beta
        m = _unit(np.cos(beta)[:, None] * tan + (sd * np.sin(beta))[:, None] * e)
        m = _unit(m - np.tan(self.lf_tilt)[:, None] * nb)
        l0 = _unit(np.cross(nb, m))
        n0 = np.cross(m, l0)
        cr, sr = np.cos(self.lf_roll)[:, None], np.sin(self.lf_roll)[:, None]
        lat = cr * l0 + sr * n0
        nor = -sr * l0 + cr * n0
        g = st["g"][li]
        ln, wd = self.lf_len * g, self.lf_wid * g
        att = att + (0.006 * g * sd)[:, None] * e  # short petiolule
        # samples
        t = self.lf
        keep = st["present"][li[t["own"]]]
        j, a, b = t["own"][keep], t["a"][keep], t["b"][keep]
        along = a * ln[j]
        across = b * wd[j] / 2
        bend = (
            -self.lf_cup[j] * (wd[j] / 2) * b**2
            - self.lf_droop[j] * ln[j] * a**2
            + 0.0015 * np.sin(2 * np.pi * (3 * a + b) + self.lf_wave[j]) * np.abs(b)
        )
        pts = att[j] + along[:, None] * m[j] + across[:, None] * lat[j] + bend[:, None] * nor[j]
        leaf = li[j]
        return pts, np.full(j.size, LEAF), self.leaf_plant[leaf], KIND_LEAF * ORGAN_STRIDE + leaf, t["sid"][keep]

    def _truss_state(self, k):
        p = self.tr_plant
        present = (
            (self.S[k, p] >= self.tr_s + 0.05) & (self.tr_z > self.harvest[k, p]) & (self.tr_z < self.fruit_set[k, p])
        )
        size = np.clip(0.3 + 0.7 * (self.fruit_set[k, p] - self.tr_z) / 0.5, 0.3, 1.0)
        az = self.tr_az
        d = np.stack([np.cos(az), np.sin(az), np.zeros_like(az)], 1)
        e = np.stack([-np.sin(az), np.cos(az), np.zeros_like(az)], 1)
        z = np.array([0.0, 0.0, 1.0])
        p0 = self.centre(p, self.tr_s, k) + self.stem_radius(p, self.tr_s, k)[:, None] * d
        reach = self.tr_reach[:, None]
        drop = (self.tr_drop * (0.85 + 0.25 * size))[:, None]
        ctrl = np.stack(
            [
                p0,
                p0 + 0.6 * reach * d + 0.03 * z,
                p0 + reach * d + self.tr_side[:, None] * e - 0.3 * drop * z,
                p0 + 1.1 * reach * d + 1.5 * self.tr_side[:, None] * e - drop * z,
            ],
            1,
        )
        return dict(present=present, size=size, ctrl=ctrl, e=e)

    @staticmethod
    def _bezier(ctrl, u):
        u = u[:, None]
        w = [(1 - u) ** 3, 3 * u * (1 - u) ** 2, 3 * u**2 * (1 - u), u**3]
        dw = [-3 * (1 - u) ** 2, 3 * (1 - u) ** 2 - 6 * u * (1 - u), 6 * u * (1 - u) - 3 * u**2, 3 * u**2]
        pos = sum(w[i] * ctrl[:, i] for i in range(4))
        tan = _unit(sum(dw[i] * ctrl[:, i] for i in range(4)))
        return pos, tan

    def _peduncles(self, k, ts):
        t = self.pe
        keep = ts["present"][t["own"]]
        i, u, th = t["own"][keep], t["u"][keep], t["th"][keep]
        pos, tan = self._bezier(ts["ctrl"][i], u)
        e1 = _unit(np.cross(tan, ts["e"][i]))
        e2 = np.cross(tan, e1)
        r = (0.003 * (1.0 - 0.4 * u))[:, None]
        pts = pos + r * (np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2)
        return pts, np.full(i.size, PETIOLE), self.tr_plant[i], KIND_TRUSS * ORGAN_STRIDE + i, t["sid"][keep]

    def _fruits(self, k, ts):
        tr = self.fr_truss
        pos, tan = self._bezier(ts["ctrl"][tr], self.fr_u)
        e1 = _unit(np.cross(tan, ts["e"][tr]))
        e2 = np.cross(tan, e1)
        o = np.cos(self.fr_gamma)[:, None] * e1 + np.sin(self.fr_gamma)[:, None] * e2
        rad = self.fr_r * ts["size"][tr]
        centre = pos + (rad + 0.006)[:, None] * o
        t = self.fr
        keep = ts["present"][tr[t["own"]]]
        f, dirs = t["own"][keep], t["d"][keep]
        pts = centre[f] + rad[f, None] * dirs
        # drop the parts of a fruit hidden inside its neighbours on the same truss
        if f.size:
            tf = tr[f]
            order = np.argsort(tr, kind="stable")
            first = np.searchsorted(tr[order], np.arange(self.n_trusses_total))
            counts = np.bincount(tr, minlength=self.n_trusses_total)
            inside = np.zeros(f.size, bool)
            for q in range(int(counts.max())):
                other = order[np.minimum(first[tf] + q, order.size - 1)]
                valid = (q < counts[tf]) & (other != f)
                dist = np.linalg.norm(pts - centre[other], axis=1)
                inside |= valid & (dist < rad[other] - 1e-9)
            keep_f = ~inside
            pts, f = pts[keep_f], f[keep_f]
            sid = t["sid"][keep][keep_f]
        else:
            sid = t["sid"][keep]
        return pts, np.full(f.size, FRUIT), self.tr_plant[tr[f]], KIND_FRUIT * ORGAN_STRIDE + f, sid

    def session(self, k: int, noise: float = 0.0) -> RowSession:
        st = self._leaf_state(k)
        ts = self._truss_state(k)
        parts = [self._stems(k), self._rachises(k, st), self._leaflets(k, st), self._peduncles(k, ts), self._fruits(k, ts)]
        local = np.concatenate([q[0] for q in parts])
        if noise > 0:
            local = local + np.random.default_rng([self.seed, k, 7]).normal(0.0, noise, local.shape)
        local = _soft_clamp(local, self.half)
        points = self.box.to_world(local)
        return RowSession(
            points=points,
            labels=np.concatenate([q[1] for q in parts]).astype(np.int8),
            plant_id=np.concatenate([q[2] for q in parts]).astype(np.int16),
            organ_id=np.concatenate([q[3] for q in parts]).astype(np.int32),
            sample_id=np.concatenate([q[4] for q in parts]).astype(np.int64),
            room=self.room,
            date=DATES[k],
            session=k,
            seed=self.seed,
            point_spacing=self.spacing,
            plant_box=self.box,
        )


def _make_row(room, seed, point_spacing, plant_box) -> _Row:
    seed = _check_seed(seed)
    spacing = _check_spacing(point_spacing)
    if plant_box is None:
        box = room_config(room).plant_box
    elif isinstance(plant_box, OrientedBox):
        box = plant_box
        if not (2.0 <= box.extent[0] <= 10.0 and 0.4 <= box.extent[1] <= 1.5 and 1.5 <= box.extent[2] <= 4.0):
            raise ConfigError(
                f"plant_box extent {np.round(box.extent, 3).tolist()} m is not a crop row "
                "(expected about 2-10 m x 0.4-1.5 m x 1.5-4 m along local x, y, z)"
            )
    else:
        raise ConfigError(f"plant_box must be an OrientedBox or None, got {type(plant_box).__name__}")
    return _Row(str(room), box, seed, spacing)


def _check_noise(noise) -> float:
    noise = float(noise)
    if not np.isfinite(noise) or not 0.0 <= noise <= 0.05:
        raise ConfigError(f"noise must be a standard deviation between 0 and 0.05 m, got {noise!r}")
    return noise


def generate_row(
    room: str = "room1",
    seed: int = 0,
    session: int = 0,
    point_spacing: float = 0.004,
    *,
    noise: float = 0.0,
    plant_box: OrientedBox | None = None,
) -> RowSession:
    """Generate session ``session`` (0..4 = dates 20250915..20250929) of a tomato row.

    The row fills ``room``'s real plant box ("room1" or "room4"; or a custom ``plant_box``). Same
    ``(room, seed, point_spacing)`` -> same row; ``noise`` adds Gaussian jitter (std, metres) to
    every point (still clamped into the box). Equal to ``generate_row_sessions(...)[session]``.
    """
    session = _check_session(session)
    noise = _check_noise(noise)
    return _make_row(room, seed, point_spacing, plant_box).session(session, noise)


def generate_row_sessions(
    room: str = "room1",
    seed: int = 0,
    n_sessions: int = 5,
    point_spacing: float = 0.004,
    *,
    noise: float = 0.0,
    plant_box: OrientedBox | None = None,
) -> list[RowSession]:
    """The first ``n_sessions`` (1..5) sessions of a row; pair them with :func:`row_correspondences`."""
    if isinstance(n_sessions, bool) or not isinstance(n_sessions, (int, np.integer)) or not 1 <= n_sessions <= len(DATES):
        raise ConfigError(f"n_sessions must be an integer 1..{len(DATES)}, got {n_sessions!r}")
    noise = _check_noise(noise)
    row = _make_row(room, seed, point_spacing, plant_box)
    return [row.session(k, noise) for k in range(int(n_sessions))]


# ============================================================================ saving
def save_row_sessions(sessions, folder) -> Path:
    """Write sessions as the dataset's processed models ``<folder>/room<k>_<YYYYMMDD>.pcd``.

    Binary PCD (x y z float32, metres, world frame) plus ``manifest.json`` (room, dates, files, point
    counts, seed, generator version, units). Every file is written to a temporary file in ``folder``
    and moved into place, so readers never see a partial file. Returns the manifest path.
    """
    sessions = list(sessions)
    if not sessions or not all(isinstance(s, RowSession) for s in sessions):
        raise ConfigError("save_row_sessions: expected a non-empty list of RowSession")
    rows = {(s.room, s.seed, s.point_spacing) for s in sessions}
    if len(rows) != 1:
        raise ConfigError(f"save_row_sessions: sessions come from different rows: {sorted(rows)}")
    names = [s.name for s in sessions]
    if len(set(names)) != len(names):
        raise ConfigError(f"save_row_sessions: duplicate sessions {names}")
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputFileError(f"{folder}: cannot create output folder ({exc})") from None
    if not folder.is_dir():
        raise InputFileError(f"{folder}: not a folder")
    files = []
    for s in sessions:
        path = folder / f"{s.name}.pcd"
        write_point_cloud(path, s.points, binary=True, dtype=np.float32)
        files.append(path.name)
    first = sessions[0]
    manifest = {
        "room": first.room,
        "dates": [s.date for s in sessions],
        "sessions": [s.session for s in sessions],
        "files": files,
        "point_counts": [s.n_points for s in sessions],
        "seed": first.seed,
        "point_spacing": first.point_spacing,
        "generator": "tpvp.synthetic.greenhouse",
        "generator_version": GENERATOR_VERSION,
        "units": "m",
        "frame": f"{first.room} world frame (plant box of the bundled configuration)",
        "plant_box": {
            "center": first.plant_box.center.tolist(),
            "R_flat": first.plant_box.rotation.reshape(-1).tolist(),
            "extent": first.plant_box.extent.tolist(),
        },
        "labels": {str(k): v for k, v in LABEL_NAMES.items()},
        "counts": [
            {"date": s.date, "plants": s.n_plants, "leaves": s.n_leaves, "trusses": s.n_trusses, "fruits": s.n_fruits}
            for s in sessions
        ],
    }
    path = folder / "manifest.json"
    atomic_write_text(path, json.dumps(manifest, indent=2) + "\n")
    return path


def row_summary(session: RowSession, voxel: float = 0.01) -> dict:
    """Realism figures of one session: points, occupied voxels, plant-box-frame extent, organ counts."""
    q = session.local_points()
    return {
        "room": session.room,
        "date": session.date,
        "points": session.n_points,
        "voxels": int(voxelise(session.points, voxel).shape[0]),
        "extent": (q.max(axis=0) - q.min(axis=0)).tolist(),
        "plants": session.n_plants,
        "leaves": session.n_leaves,
        "trusses": session.n_trusses,
        "fruits": session.n_fruits,
    }


__all__ = [
    "DATES",
    "FRUIT",
    "GENERATOR_VERSION",
    "LEAF",
    "LABEL_NAMES",
    "PETIOLE",
    "RowSession",
    "STEM",
    "generate_row",
    "generate_row_sessions",
    "row_correspondences",
    "row_summary",
    "save_row_sessions",
]
