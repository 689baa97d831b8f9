"""Procedural individual plants (tomato, maize) and their next monitoring session.

A plant is a small set of parametric organs evaluated at a plant *age* (days):

* stems are tubes around a gently leaning, slightly curved axis, one tube per internode;
* leaves are thin blades around a midrib curve that rises, droops toward the tip, curls sideways
  and twists; the cross-section folds (V along the midrib) and cups or rolls (a circular arc whose
  arc length equals the blade half-width, so the sampled area is honest);
* every surface is sampled as a *scanned layer*, not as a mathematical sheet (below);
* tomato: two cotyledons on the hypocotyl, rising from the node, arching down and banked (rolled
  about the midrib) to one side, then compound true leaves in a spiral (petiole/rachis tube, pairs
  of ovate leaflets and a terminal leaflet, each leaflet rolled about its midrib instead of lying
  in the rachis plane); maize: a pseudo-stem of sheaths and long strap leaves alternating on two
  opposite sides, the youngest one upright and rolled.

Every organ grows with its own age (``1 - exp(-(a/T)^2)``: a slow start, a fast middle, a plateau),
leaves flatten as they mature and move a little (a slow oscillation of their elevation, like the
nastic movements seen between scans), and the stem lean drifts. A session pair evaluates the *same*
material samples ``(s, t, w)`` of every organ at two ages, so the ground-truth correspondence is
exact and the deformation is smooth and non-rigid; leaves that emerge in between have no
correspondence.

Realism: as hard to see as the real scans. ``benchmarks/plant_realism.py`` renders the plants from
the 32 hemisphere views (table, 2 mm voxels, largest side 0.24 m) next to the bundled Pheno4D
scans. The real tomato (two sessions of one seedling) has an oracle share of 86.3-90.4 % and its
best single view sees 56.7-62.2 % of the oracle; the real maize 87.1 % and 44.4 %. The generator
used to give tomato 91-95 % and 71-78 % (maize 91-93 %, 45-50 %). The causes, measured on the scans:

* *Thickness.* A laser scan of a leaf is a layer, not a surface: in 0.5 mm patches the points
  spread 42-50 um (tomato) and 61 um (maize) about the local plane, stems about as much (leaf
  thickness and the scanner's depth noise), where the generator had one sample layer (< 5 um).
  After normalising (x3-5) that is 0.15-0.3 mm, so a blade crosses more voxel boundaries: the real
  tomato canopy fills 1.6-2.0 voxels per vertical column (the generator 1.3-1.5). A view sees the
  first voxel of each line of sight: 95-98 % of the canopy voxels the best (top) view misses lie
  under another occupied voxel, and the inner ones of a 3-voxel stack are hidden from every view
  (the oracle share). Now every sample has a depth ``w`` in a layer of thickness ``_LAYER`` (tomato
  0.105 mm, maize 0.19 mm; uniform across plus Gaussian noise of 0.15 of it) along the blade's
  normal or the tube's radius: the generated spread is ~34 um (tomato, a little below the scans;
  thicker layers push the oracle share under the real range) and ~60 um (maize).
* *Tomato posture.* The real cotyledons rise 10-35 degrees from the node and level off or hang
  (the middle of the blade pitched -20 to +6 degrees), and they are banked 7-27 degrees about the
  midrib; the blades' normals tilt 14-28 degrees (median) from vertical. The generator's cotyledons rose
  0-25 degrees, drooped gently and lay nearly flat (normals 10-15 degrees), so the top view saw
  almost all of them. Now: elevation 18-35, droop 27-55 degrees (fast, ``s ** 0.8``), bank 18-33
  degrees to a random side, leaflets rolled 30 +- 8 degrees, hypocotyl 18-25 mm (the scans: about
  21-23 mm); the normals now tilt 17-37 degrees (median). Development, leaf and leaflet counts and
  sizes and the growth between sessions are unchanged. The posture ranges are calibrated: with them
  the tomato mean over seeds 0-5 falls inside both real ranges (as do most single seeds); the
  maize, with only the layer, stays within about 2 points of its one real scan.

Units: metres in a plant-local frame (stem base at the origin, +Z up) at the real scale of the
Pheno4D seedlings (tomato ~5 cm across, maize ~9 cm tall); callers rescale (largest side 0.24 m,
docs/single_plant.md#normalisation). Samples are stratified (a jittered grid, one row per
``spacing`` of arc length, as many samples across a row as its width needs), so the density is
uniform per area and a 2 mm voxel grid at the normalised scale sees a closed layer. Deterministic:
the plant is a function of ``(species, seed, stage, params)``.

The organs' geometry (curves, tubes, blades, the growth curve) is :mod:`tpvp.synthetic.organs`;
this module holds the species, the sampling and the session pairs.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.special import erf as _erf

from tpvp.errors import ConfigError
from tpvp.io import atomic_write_text, write_point_cloud
from tpvp.scene.voxels import voxelise
from tpvp.synthetic.organs import (CURVE_NODES, Blade, Curve, Part, Tube, age_visible, beta_profile,
                                   relative_size, smoothstep)

SPECIES = ("tomato", "maize")
_SPECIES_CODE = {"tomato": 1, "maize": 2}
_DEG = np.pi / 180.0
_MAX_LEAVES = 24

# Default sample spacing: ``_DEFAULT_SPACING`` m for a plant whose skeleton spans ``_NOMINAL_EXTENT``
# m, proportionally more or less for larger or smaller plants, so that after normalising to a 0.24 m
# largest side the spacing is always ~0.4 mm (about 5 samples per 2 mm voxel edge).
_DEFAULT_SPACING = {"tomato": 0.9e-4, "maize": 1.3e-4}
_NOMINAL_EXTENT = {"tomato": 0.05, "maize": 0.09}
# Extra age (days) drawn per seed at stage 1: the variety of development stages.
_DEFAULT_DEVELOPMENT = {"tomato": (0.0, 8.0), "maize": (0.0, 4.0)}
_BASE_AGE = {"tomato": 10.0, "maize": 11.0}
# Plant-days (the generator's developmental clock) per calendar day between sessions: calibrated so
# that 1-3 days move the leaves by a few mm to ~2 cm at the real scale.
_CLOCK = {"tomato": 0.6, "maize": 0.35}
# The scanned layer (see the module docstring): thickness (m, at size 1) of the layer every surface
# is sampled in, and the scanner's depth noise as a fraction of it. Measured on the bundled Pheno4D
# scans (spread of the points about the local surface: ~0.04-0.06 mm at the real scale).
_LAYER = {"tomato": 0.105e-3, "maize": 0.19e-3}
_LAYER_NOISE = 0.15
# Tomato posture (degrees unless noted), calibrated on the bundled tomato scans (module docstring):
# hypocotyl length (m), cotyledon elevation at the node, droop toward the tip and bank (roll about
# the midrib, either side), leaflet bank (mean, sd).
_TOMATO_POSTURE = {"hypocotyl": (0.018, 0.025), "cot_elevation": (18.0, 35.0), "cot_droop": (27.0, 55.0),
                   "cot_droop_exp": 0.8, "cot_bank": (18.0, 33.0), "leaflet_bank": (30.0, 8.0)}


# --------------------------------------------------------------------------------------------------
# public data types
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PlantParams:
    """Knobs of the generator (defaults give Pheno4D-like seedlings).

    spacing: sample spacing in metres at the generated scale (None: proportional to the plant's
        size, ~0.1 mm for a Pheno4D-sized seedling, ~0.4 mm after normalising to 0.24 m).
    development: range (days) of the extra age drawn per seed at ``stage`` 1 (None: species
        default); wider ranges give more varied plants (more, larger true leaves).
    size: overall scale factor of the plant.
    growth_rate: speed of growth and movement between sessions (1 = calibrated default).
    leaf_motion: scale of the leaves' elevation oscillation and of the stem-lean drift.
    new_leaf: in a session pair, make sure at least one leaf emerges between the sessions.
    azimuth_deg: direction of the plant's main horizontal axis (the cotyledons of a tomato, the
        leaf plane of a maize), +-8 degrees per seed; None: uniformly random per seed.
    """

    spacing: float | None = None
    development: tuple[float, float] | None = None
    size: float = 1.0
    growth_rate: float = 1.0
    leaf_motion: float = 1.0
    new_leaf: bool = True
    azimuth_deg: float | None = 0.0

    def __post_init__(self):
        if self.spacing is not None and not (np.isfinite(self.spacing) and self.spacing > 0):
            raise ConfigError(f"PlantParams.spacing must be a positive length in metres, got {self.spacing!r}")
        if self.development is not None:
            dev = tuple(self.development)
            if len(dev) != 2 or not all(np.isfinite(dev)) or dev[0] < 0 or dev[1] < dev[0]:
                raise ConfigError(
                    f"PlantParams.development must be a (low, high) range of days with 0 <= low <= high, "
                    f"got {self.development!r}")
        for name in ("size", "growth_rate"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"PlantParams.{name} must be > 0, got {v!r}")
        if self.azimuth_deg is not None and not np.isfinite(self.azimuth_deg):
            raise ConfigError(f"PlantParams.azimuth_deg must be finite or None, got {self.azimuth_deg!r}")
        if not (np.isfinite(self.leaf_motion) and self.leaf_motion >= 0):
            raise ConfigError(f"PlantParams.leaf_motion must be >= 0, got {self.leaf_motion!r}")


@dataclass(frozen=True)
class PlantSample:
    """One plant at one moment.

    points: (N, 3) float64, metres, stem base at the origin, +Z up.
    organ: (N,) int32, 0 = stem, 1.. = leaf (bottom to top; tomato: 1-2 are the cotyledons).
    part: (N,) int32, index into ``part_kinds`` (each internode, petiole/rachis, blade or leaflet is
        one part; handy to pick a single leaflet).
    part_kinds: kind of every part: "stem", "petiole" or "blade".
    part_organs: organ of every part.
    age: plant age in days (what ``stage`` maps to for this seed).
    """

    points: np.ndarray
    organ: np.ndarray
    part: np.ndarray
    part_kinds: tuple[str, ...]
    part_organs: tuple[int, ...]
    species: str
    seed: int
    stage: float
    age: float
    leaf_count: int
    spacing: float
    params: PlantParams = field(default_factory=PlantParams)

    def __len__(self) -> int:
        return len(self.points)

    def organ_points(self, organ: int) -> np.ndarray:
        return self.points[self.organ == organ]


@dataclass(frozen=True)
class SessionPair:
    """Two sessions of one plant with ground-truth correspondences.

    ``previous.points[correspondence_previous_idx[k]]`` and ``current.points[correspondence_current_idx[k]]``
    are the same material point. Every previous point has a partner; current points on organs that
    emerged in between (``new_organs``) or on new internodes have none.
    """

    previous: PlantSample
    current: PlantSample
    correspondence_previous_idx: np.ndarray
    correspondence_current_idx: np.ndarray
    days: float
    new_organs: tuple[int, ...]

    @property
    def displacement(self) -> np.ndarray:
        """(K, 3) motion of every corresponded material point from previous to current (m)."""
        return (self.current.points[self.correspondence_current_idx]
                - self.previous.points[self.correspondence_previous_idx])


# --------------------------------------------------------------------------------------------------
# species
# --------------------------------------------------------------------------------------------------


def _check_species(species) -> str:
    if not isinstance(species, str) or species.lower() not in SPECIES:
        raise ConfigError(f"unknown species {species!r}; choose one of {', '.join(SPECIES)}")
    return species.lower()


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _check_stage(stage) -> float:
    try:
        stage = float(stage)
    except (TypeError, ValueError):
        raise ConfigError(f"stage must be a number, got {stage!r}") from None
    if not np.isfinite(stage) or not (0.3 <= stage <= 3.0):
        raise ConfigError(f"stage must lie in [0.3, 3] (1 = a Pheno4D-like seedling), got {stage!r}")
    return stage


class _Spec(dict):
    """Per-seed constants of one plant (attribute access)."""

    def __getattr__(self, name):
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None

    __setattr__ = dict.__setitem__


def _main_azimuth(rng, params: PlantParams) -> float:
    jitter = rng.normal(0, 8) * _DEG
    if params.azimuth_deg is None:
        return rng.uniform(0, 2 * np.pi) + jitter
    return params.azimuth_deg * _DEG + jitter


def _new_spec(species: str, seed: int, params: PlantParams):
    """The species' random stream (seeded by the plant's seed) and a spec with its age drawn first."""
    rng = np.random.default_rng([seed, _SPECIES_CODE[species]])
    sp = _Spec()
    sp.age1 = _BASE_AGE[species] + rng.uniform(*(params.development or _DEFAULT_DEVELOPMENT[species]))
    return rng, sp


def _tomato_spec(seed: int, params: PlantParams) -> _Spec:
    rng, sp = _new_spec("tomato", seed, params)
    u = rng.uniform
    n = _MAX_LEAVES
    # stem (hypocotyl, then one epicotyl internode under each true leaf)
    post = _TOMATO_POSTURE
    sp.hyp_len = u(*post["hypocotyl"])
    sp.r0 = u(0.00075, 0.00095)
    sp.beta0 = u(5, 18) * _DEG
    sp.beta1 = u(-8, 8) * _DEG
    sp.gamma0 = u(0, 2 * np.pi)
    sp.gamma1 = u(-20, 20) * _DEG
    sp.beta_amp, sp.beta_per, sp.beta_ph = u(1.5, 3.0) * _DEG, u(5, 9), u(0, 2 * np.pi)
    sp.int_len = u(0.0015, 0.003, n) * (1 + 0.15 * np.arange(n))
    # cotyledons
    phc = _main_azimuth(rng, params)
    sp.cot_phi = phc + np.array([0.0, np.pi]) + rng.normal(0, 0.1, 2)
    sp.cot_len = u(0.020, 0.025) * (1 + rng.normal(0, 0.04, 2))
    sp.cot_wr = u(0.34, 0.44, 2)
    sp.cot_theta = u(*post["cot_elevation"], 2) * _DEG  # rising from the node, then arching down
    sp.cot_droop = u(*post["cot_droop"], 2) * _DEG
    sp.cot_curl = rng.normal(0, 8, 2) * _DEG
    sp.cot_twist = rng.normal(0, 12, 2) * _DEG
    # banked (rolled about the midrib) by a uniform magnitude in post["cot_bank"] to either side; the
    # half-normal draw mapped onto it keeps the random stream (and every later draw) what it was
    z = rng.normal(0, 1, 2)
    lo, hi = post["cot_bank"]
    sp.cot_bank = np.sign(z) * (lo + (hi - lo) * _erf(np.abs(z) / np.sqrt(2))) * _DEG
    sp.cot_cup = rng.normal(0, 0.35, 2)
    sp.cot_osc = (u(3, 6, 2) * _DEG, u(4, 8, 2), u(0, 2 * np.pi, 2))
    # true leaves: emergence, spiral phyllotaxis, size, posture
    sp.leaf_T = 9.0
    sp.leaf_e = u(7.5, 9.0) + np.concatenate([[0.0], np.cumsum(u(2.4, 3.4, n - 1))])
    turn = 137.5 * _DEG * (1 if rng.uniform() < 0.5 else -1)
    sp.leaf_phi = phc + (np.pi / 2) * (1 if rng.uniform() < 0.5 else -1) + turn * np.arange(n) \
        + rng.normal(0, 12, n) * _DEG
    sp.rachis = u(0.030, 0.040, n) * np.minimum(1 + 0.25 * np.arange(n), 2.5)
    sp.rachis_r = u(0.00028, 0.00038)
    sp.theta_young = u(45, 60, n) * _DEG
    sp.theta_mature = u(10, 30, n) * _DEG
    sp.rachis_droop = u(25, 50, n) * _DEG
    sp.rachis_curl = rng.normal(0, 10, n) * _DEG
    sp.n_pairs = np.minimum(2 + (np.arange(n) >= 1) + (u(0, 1, n) < 0.4), 4).astype(int)
    sp.leaf_osc = (u(4, 8, n) * _DEG, u(4, 8, n), u(0, 2 * np.pi, n))
    m = 2 * n * 4 + n  # leaflet draws per plant (per leaf: up to 4 pairs x 2 sides + terminal)
    sp.lf_angle = u(50, 75, m) * _DEG
    sp.lf_tilt = u(-15, 5, m) * _DEG
    sp.lf_wr = u(0.55, 0.70, m)
    sp.lf_droop = u(10, 40, m) * _DEG
    sp.lf_curl = rng.normal(0, 10, m) * _DEG
    sp.lf_twist = rng.normal(0, 12, m) * _DEG
    sp.lf_cup = rng.normal(0.15, 0.3, m)
    sp.lf_scale = u(0.85, 1.15, m)
    # leaflets rolled about their midrib, the margin toward the leaf base lower (pairs mirror-symmetric),
    # instead of lying in the rachis plane
    sp.lf_bank = rng.normal(*post["leaflet_bank"], m) * _DEG
    return sp


def _tomato_parts(sp: _Spec, age: float, motion: float, size: float) -> list[Part]:
    parts: list[Part] = []
    T = sp.leaf_T
    ages = age - sp.leaf_e
    g = relative_size(ages, T)
    n_true = int(np.sum(ages > age_visible(T)))
    # ---- stem -------------------------------------------------------------------------------------
    internodes = [sp.hyp_len * (0.45 + 0.55 * float(relative_size(age, 5.0)))]
    internodes += [sp.int_len[i] * float(relative_size(ages[i] + 1.0, 7.0)) for i in range(n_true)]
    internodes = np.array(internodes) * size
    total = internodes.sum()
    sig = np.linspace(0, 1, CURVE_NODES) * total
    ref = 0.025 * size
    beta = sp.beta0 + motion * sp.beta_amp * np.sin(2 * np.pi * age / sp.beta_per + sp.beta_ph) \
        + sp.beta1 * sig / ref
    gamma = sp.gamma0 + sp.gamma1 * sig / ref
    stem = Curve(np.zeros(3), total, gamma, np.pi / 2 - beta)
    thick = 0.8 + 0.2 * float(relative_size(age, 8.0))

    def stem_r(s, total=total):
        return size * sp.r0 * thick * (1 - 0.3 * np.minimum(np.asarray(s) * total / (0.03 * size), 1.0))

    nodes = np.concatenate([[0.0], np.cumsum(internodes)]) / total
    for j in range(len(internodes)):
        parts.append(Part((0, j), 0, "stem", Tube(stem, nodes[j], nodes[j + 1], stem_r)))

    def base_point(s_node, phi):
        p = stem.point(s_node)[0]
        r = float(stem_r(np.array([s_node]))[0])
        return p + 0.8 * r * np.array([np.cos(phi), np.sin(phi), 0.0])

    # ---- cotyledons ---------------------------------------------------------------------------------
    cot_g = 0.35 + 0.65 * float(relative_size(age, 4.0))
    amp, per, ph = sp.cot_osc
    for k in range(2):
        L = sp.cot_len[k] * cot_g * size
        th0 = sp.cot_theta[k] + motion * amp[k] * np.sin(2 * np.pi * age / per[k] + ph[k])
        s = np.linspace(0, 1, CURVE_NODES)
        droop = sp.cot_droop[k] * s ** _TOMATO_POSTURE["cot_droop_exp"]
        curve = Curve(base_point(nodes[1], sp.cot_phi[k]), L, sp.cot_phi[k] + sp.cot_curl[k] * s,
                       th0 - droop, sp.cot_bank[k] + sp.cot_twist[k] * s)
        pet_hw = 0.0007 / (L * sp.cot_wr[k] / 2)

        def cot_profile(s, pet=pet_hw):
            u = np.clip((s - 0.12) / 0.88, 0, 1)
            blade = beta_profile(u, 0.75, 0.7)
            return np.maximum(blade, pet * (1 - smoothstep(0.1, 0.3, s)))

        cup = sp.cot_cup[k]
        parts.append(Part((1, k), k + 1, "blade",
                           Blade(curve, L * sp.cot_wr[k] / 2, cot_profile, roll=lambda s, c=cup: c + 0 * s)))
    # ---- compound true leaves -------------------------------------------------------------------------
    amp, per, ph = sp.leaf_osc
    for i in range(n_true):
        a, gi = ages[i], float(g[i])
        organ = 3 + i
        R = sp.rachis[i] * gi * size
        th0 = sp.theta_mature[i] + (sp.theta_young[i] - sp.theta_mature[i]) * np.exp(-a / 4.0) \
            + motion * amp[i] * np.sin(2 * np.pi * age / per[i] + ph[i])
        s = np.linspace(0, 1, CURVE_NODES)
        rachis = Curve(base_point(nodes[i + 2], sp.leaf_phi[i]), R, sp.leaf_phi[i] + sp.rachis_curl[i] * s,
                        th0 - sp.rachis_droop[i] * gi * s**1.5)
        rr = size * sp.rachis_r * (0.5 + 0.5 * gi)
        parts.append(Part((2, i, 0), organ, "petiole",
                           Tube(rachis, 0.0, 1.0, lambda s, rr=rr: rr * (1 - 0.4 * np.asarray(s)))))
        npair = int(sp.n_pairs[i])
        pos = [0.6] if npair == 1 else list(0.38 + 0.45 * np.arange(npair) / (npair - 1))
        leaflets = []  # (attach s, side, relative length)
        for j, sj in enumerate(pos):
            rel = 0.45 + 0.15 * j / max(npair - 1, 1)
            leaflets += [(sj, -1, rel), (sj, +1, rel)]
        leaflets.append((1.0, 0, 0.75))
        lat_g = gi ** 0.3  # lateral leaflets lag the terminal one a little
        for q, (sj, side, rel) in enumerate(leaflets):
            d = i * (2 * 4 + 1) + q
            p, Tr, Br, Nr = rachis.point(sj)
            if side == 0:
                d0 = Tr
                Ll = sp.rachis[i] * size * rel * sp.lf_scale[d] * gi
            else:
                d0 = np.cos(sp.lf_angle[d]) * Tr + side * np.sin(sp.lf_angle[d]) * Br
                d0 = d0 + np.tan(sp.lf_tilt[d]) * Nr
                Ll = sp.rachis[i] * size * rel * sp.lf_scale[d] * gi * lat_g
            d0 = d0 / np.linalg.norm(d0)
            phi0, th0l = np.arctan2(d0[1], d0[0]), np.arcsin(np.clip(d0[2], -1, 1))
            sd = side if side else 1
            curve = Curve(p, Ll, phi0 + sd * sp.lf_curl[d] * s, th0l - sp.lf_droop[d] * gi * s**1.4,
                           sd * (sp.lf_twist[d] * s - sp.lf_bank[d]))
            cup = sp.lf_cup[d]
            parts.append(Part((2, i, 1 + q), organ, "blade",
                               Blade(curve, Ll * sp.lf_wr[d] / 2, lambda s: beta_profile(s, 0.5, 0.9),
                                      roll=lambda s, c=cup: c + 0 * s)))
    return parts


def _maize_spec(seed: int, params: PlantParams) -> _Spec:
    rng, sp = _new_spec("maize", seed, params)
    u = rng.uniform
    n = _MAX_LEAVES
    idx = np.arange(n)
    sp.leaf_T = 5.5 + 0.8 * idx
    sp.leaf_e = np.concatenate([[0.0], np.cumsum(u(2.2, 3.0, n - 1))])
    sp.blade_len = u(0.032, 0.040) * (1 + 0.55 * idx) * u(0.9, 1.1, n)
    sp.width_ratio = np.where(idx == 0, u(0.24, 0.30), u(0.21, 0.27, n) * np.maximum(1 - 0.06 * (idx - 1), 0.7))
    sp.tip_exp = np.where(idx == 0, 4.0, 2.0)
    sp.sheath = u(0.013, 0.017) * (1 + 0.5 * idx) * u(0.9, 1.1, n)  # internode under each collar
    sp.r0 = u(0.0014, 0.0019)
    sp.beta0 = u(0, 6) * _DEG
    sp.beta1 = u(-4, 4) * _DEG
    sp.gamma0 = u(0, 2 * np.pi)
    sp.beta_amp, sp.beta_per, sp.beta_ph = u(1.0, 2.0) * _DEG, u(5, 9), u(0, 2 * np.pi)
    phi0 = _main_azimuth(rng, params)
    sp.leaf_phi = phi0 + np.pi * idx + rng.normal(0, 35, n) * _DEG
    sp.theta_mature = u(60, 78, n) * _DEG
    sp.theta_young = u(84, 89, n) * _DEG
    sp.droop = u(35, 100, n) * _DEG
    sp.droop_exp = u(1.4, 2.2, n)
    sp.curl = rng.normal(0, 35, n) * _DEG
    sp.twist = rng.normal(0, 25, n) * _DEG
    sp.fold = u(8, 22, n) * _DEG
    sp.wave = (u(0.0002, 0.0005, n), u(6, 12, n), u(0, 2 * np.pi, n))
    sp.leaf_osc = (u(3, 6, n) * _DEG, u(4, 8, n), u(0, 2 * np.pi, n))
    return sp


def _maize_parts(sp: _Spec, age: float, motion: float, size: float) -> list[Part]:
    parts: list[Part] = []
    ages = age - sp.leaf_e
    vis = ages > age_visible(sp.leaf_T)
    n = int(np.sum(vis))
    g = relative_size(ages, sp.leaf_T)
    # pseudo-stem: one internode (sheath segment) under each visible collar
    internodes = np.array([sp.sheath[i] * float(g[i]) ** 1.5 for i in range(n)]) * size
    internodes = np.maximum(internodes, 1e-5 * size)
    total = internodes.sum()
    sig = np.linspace(0, 1, CURVE_NODES) * total
    ref = 0.05 * size
    beta = sp.beta0 + motion * sp.beta_amp * np.sin(2 * np.pi * age / sp.beta_per + sp.beta_ph) \
        + sp.beta1 * sig / ref
    stem = Curve(np.zeros(3), total, sp.gamma0 + 0 * sig, np.pi / 2 - beta)
    thick = 0.6 + 0.4 * float(relative_size(age, 10.0))

    def stem_r(s, total=total):
        return size * sp.r0 * thick * (1 - 0.3 * np.asarray(s) * min(total / ref, 1.0))

    nodes = np.concatenate([[0.0], np.cumsum(internodes)]) / total
    for j in range(n):
        parts.append(Part((0, j), 0, "stem", Tube(stem, nodes[j], nodes[j + 1], stem_r)))
    amp, per, ph = sp.leaf_osc
    s = np.linspace(0, 1, CURVE_NODES)
    for i in range(n):
        a, gi = ages[i], float(g[i])
        L = sp.blade_len[i] * gi * size
        hw = sp.blade_len[i] * sp.width_ratio[i] / 2 * gi ** 0.8 * size
        young = np.exp(-a / 3.0)
        th0 = sp.theta_mature[i] + (sp.theta_young[i] - sp.theta_mature[i]) * young \
            + motion * amp[i] * np.sin(2 * np.pi * age / per[i] + ph[i])
        theta = th0 - sp.droop[i] * gi**2 * s ** sp.droop_exp[i]
        phi = sp.leaf_phi[i]
        sn = nodes[i + 1]
        r = float(stem_r(np.array([sn]))[0])
        base = stem.point(sn)[0] + 0.9 * r * np.array([np.cos(phi), np.sin(phi), 0.0])
        curve = Curve(base, L, phi + sp.curl[i] * s, theta, sp.twist[i] * s**1.5)
        tip = sp.tip_exp[i]

        def profile(s, tip=tip):
            return (0.55 + 0.45 * smoothstep(0.0, 0.3, s)) * np.clip(1 - s**tip, 0, 1) ** 0.6

        # a young leaf is rolled (almost a cone); every blade wraps round the stem at its base
        rolled = 2.3 * young
        wrap = min(np.pi * r / max(hw, 1e-9), 2.5)

        def roll(s, rolled=rolled, wrap=wrap):
            return rolled + wrap * np.exp(-np.asarray(s) / 0.05)

        fold = (sp.fold[i] * 1.2, sp.fold[i] * 0.4)
        wave = (sp.wave[0][i] * gi * size, sp.wave[1][i], sp.wave[2][i])
        parts.append(Part((1, i), i + 1, "blade", Blade(curve, hw, profile, fold, roll, wave)))
    return parts


_SPEC = {"tomato": _tomato_spec, "maize": _maize_spec}
_PARTS = {"tomato": _tomato_parts, "maize": _maize_parts}


def _plant_parts(species: str, sp: _Spec, age: float, motion: float, size: float) -> list[Part]:
    """The plant's parts at ``age``, every surface carrying the species' scanned layer."""
    parts = _PARTS[species](sp, age, motion, size)
    for p in parts:
        p.geom.layer = _LAYER[species] * size
    return parts


def _first_hidden_leaf(species: str, sp: _Spec, age: float) -> int | None:
    ages = age - sp.leaf_e
    hidden = np.nonzero(ages <= age_visible(sp.leaf_T))[0]
    return int(hidden[0]) if len(hidden) else None


# --------------------------------------------------------------------------------------------------
# sampling
# --------------------------------------------------------------------------------------------------


def _sample_uv(geoms, h: float, rng) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stratified samples (s, t, w) of one part, dense enough for every geometry in ``geoms``.

    Rows every ``h`` of arc length (largest length over the geometries), each with as many jittered
    samples as the widest geometry needs at that row. ``w`` is the sample's depth in the scanned
    layer, in layer thicknesses (uniform across the layer plus Gaussian scanner noise); it is drawn
    after (s, t), so the surface samples do not depend on it.
    """
    g0 = geoms[0]
    L = max(g.length for g in geoms)
    n_rows = max(int(np.ceil(L / h)), 2)
    s = (np.arange(n_rows) + 0.5 + rng.uniform(-0.4, 0.4, n_rows)) / n_rows
    if g0.kind == "tube":
        circ = 2 * np.pi * max(g.max_radius() for g in geoms)
        n_i = np.full(n_rows, max(int(np.ceil(circ / h)), 6))
    else:
        width = 2 * np.max([g.halfwidth(s) for g in geoms], axis=0)
        width = width * 1.05  # cupped / folded cross-sections are slightly longer than their chord
        n_i = np.maximum(np.ceil(width / h).astype(np.int64), 1)
    row = np.repeat(np.arange(n_rows), n_i)
    k = np.arange(row.size) - np.repeat(np.cumsum(n_i) - n_i, n_i)
    t = (k + 0.5 + rng.uniform(-0.4, 0.4, row.size)) / n_i[row]
    if g0.kind != "tube":  # tubes: angle fraction in [0, 1); blades: signed lateral fraction
        t = 2 * t - 1
    w = rng.uniform(-0.5, 0.5, row.size) + _LAYER_NOISE * rng.standard_normal(row.size)
    return s[row], t, w


def _part_rng(seed: int, species: str, key: tuple):
    return np.random.default_rng([seed, _SPECIES_CODE[species], 7919, *key])


def _assemble(species, seed, stage, age, params, spacing, parts, uv):
    pts, organ, part_ids, kinds, organs = [], [], [], [], []
    for pid, p in enumerate(parts):
        s, t, w = uv[p.key]
        pts.append(p.geom.eval(s, t, w))
        organ.append(np.full(len(s), p.organ, np.int32))
        part_ids.append(np.full(len(s), pid, np.int32))
        kinds.append(p.kind)
        organs.append(p.organ)
    leaf_count = len({p.organ for p in parts if p.organ > 0})
    return PlantSample(points=np.ascontiguousarray(np.concatenate(pts)), organ=np.concatenate(organ),
                       part=np.concatenate(part_ids), part_kinds=tuple(kinds), part_organs=tuple(organs),
                       species=species, seed=seed, stage=stage, age=float(age), leaf_count=leaf_count,
                       spacing=spacing, params=params)


def _setup(species, seed, stage, params):
    species = _check_species(species)
    seed = _check_seed(seed)
    stage = _check_stage(stage)
    if params is None:
        params = PlantParams()
    elif not isinstance(params, PlantParams):
        raise ConfigError(f"params must be a PlantParams, got {type(params).__name__}")
    sp = _SPEC[species](seed, params)
    return species, seed, stage, params, sp


def _spacing(species: str, params: PlantParams, parts: list[Part]) -> float:
    if params.spacing is not None:
        return float(params.spacing)
    nodes = np.concatenate([p.geom.curve.pos for p in parts])
    extent = max(float(np.ptp(nodes, axis=0).max()), 1e-3)
    return _DEFAULT_SPACING[species] * extent / _NOMINAL_EXTENT[species]


# --------------------------------------------------------------------------------------------------
# public functions
# --------------------------------------------------------------------------------------------------


def generate_plant(species: str, seed: int, stage: float = 1.0, params: PlantParams | None = None) -> PlantSample:
    """One procedural plant ("tomato" or "maize"), deterministic in ``(species, seed, stage, params)``.

    ``stage`` scales the plant's age (1 = a Pheno4D-like seedling; 0.3 to 3 allowed): older plants
    have more and larger leaves. Points are in metres, stem base at the origin, +Z up.
    """
    species, seed, stage, params, sp = _setup(species, seed, stage, params)
    age = stage * sp.age1
    parts = _plant_parts(species, sp, age, params.leaf_motion, params.size)
    spacing = _spacing(species, params, parts)
    uv = {p.key: _sample_uv([p.geom], spacing, _part_rng(seed, species, p.key)) for p in parts}
    return _assemble(species, seed, stage, age, params, spacing, parts, uv)


def generate_session_pair(species: str, seed: int, days: float = 2.0, stage: float = 1.0,
                          params: PlantParams | None = None) -> SessionPair:
    """The plant at ``stage`` (previous session) and ``days`` later (current session).

    Both sessions evaluate the same material samples of every organ, so the correspondences are
    exact; the current session is sampled densely enough for its (larger) organs, which makes the
    previous one slightly denser. Leaves that emerge in between (at least one unless
    ``params.new_leaf`` is False) and their internodes have no correspondence.
    """
    species, seed, stage, params, sp = _setup(species, seed, stage, params)
    days = _check_days(days)
    age_prev = stage * sp.age1
    age_cur = age_prev + days * params.growth_rate * _CLOCK[species]
    if params.new_leaf:
        k = _first_hidden_leaf(species, sp, age_prev)
        if k is not None:
            T = np.asarray(sp.leaf_T) * np.ones(len(sp.leaf_e))
            a_vis = age_visible(T[k])
            latest = age_prev - a_vis + 0.1 * (age_cur - age_prev)  # emerges just after the previous one
            shift = sp.leaf_e[k] - latest
            if shift > 0:
                sp = _Spec(sp)
                e = sp.leaf_e.copy()
                e[k:] -= shift
                sp.leaf_e = e
    prev_parts = _plant_parts(species, sp, age_prev, params.leaf_motion, params.size)
    cur_parts = _plant_parts(species, sp, age_cur, params.leaf_motion, params.size)
    prev_by_key = {p.key: p for p in prev_parts}
    spacing = _spacing(species, params, prev_parts + cur_parts)
    if any(p.key not in {q.key for q in cur_parts} for p in prev_parts):  # pragma: no cover
        raise AssertionError("an organ disappeared between sessions")
    uv = {}
    for p in cur_parts:
        geoms = [p.geom] + ([prev_by_key[p.key].geom] if p.key in prev_by_key else [])
        uv[p.key] = _sample_uv(geoms, spacing, _part_rng(seed, species, p.key))
    # the previous session lists its parts in the current session's order
    prev_parts = [prev_by_key[p.key] for p in cur_parts if p.key in prev_by_key]
    previous = _assemble(species, seed, stage, age_prev, params, spacing, prev_parts, uv)
    current = _assemble(species, seed, stage, age_cur, params, spacing, cur_parts, uv)
    # correspondences: shared parts, in order
    counts = {p.key: len(uv[p.key][0]) for p in cur_parts}
    cur_start, off = {}, 0
    for p in cur_parts:
        cur_start[p.key] = off
        off += counts[p.key]
    prev_idx, cur_idx, off = [], [], 0
    for p in prev_parts:
        n = counts[p.key]
        prev_idx.append(np.arange(off, off + n))
        cur_idx.append(np.arange(cur_start[p.key], cur_start[p.key] + n))
        off += n
    new_organs = tuple(sorted({p.organ for p in cur_parts if p.key not in prev_by_key and p.organ > 0}))
    return SessionPair(previous=previous, current=current,
                       correspondence_previous_idx=np.concatenate(prev_idx).astype(np.int64),
                       correspondence_current_idx=np.concatenate(cur_idx).astype(np.int64),
                       days=days, new_organs=new_organs)


def generate_growth_series(species: str, seed: int, sessions: int = 6, days: float = 2.0, stage: float = 1.0,
                           params: PlantParams | None = None) -> list[PlantSample]:
    """The plant of :func:`generate_plant` scanned ``sessions`` times, ``days`` apart, from ``stage``
    on (the age steps of :func:`generate_session_pair`): a season of one plant, each scan sampled
    on its own as a scanner's would be."""
    species, seed, stage, params, sp = _setup(species, seed, stage, params)
    if isinstance(sessions, bool) or not isinstance(sessions, (int, np.integer)) or sessions < 1:
        raise ConfigError(f"sessions must be an integer >= 1, got {sessions!r}")
    step = _check_days(days) * params.growth_rate * _CLOCK[species] / sp.age1
    return [generate_plant(species, seed, stage + k * step, params) for k in range(int(sessions))]


def _check_days(days) -> float:
    try:
        days = float(days)
    except (TypeError, ValueError):
        raise ConfigError(f"days must be a number, got {days!r}") from None
    if not np.isfinite(days) or days <= 0 or days > 7:
        raise ConfigError(f"days between sessions must be in (0, 7], got {days!r}")
    return days


def plant_summary(sample: PlantSample, largest_side: float = 0.24, voxel: float = 0.002) -> dict:
    """Points, occupied voxels and bounding-box extent after scaling to ``largest_side`` (m)."""
    pts = sample.points
    ext = np.ptp(pts, axis=0)
    scale = largest_side / ext.max()
    lo = pts.min(axis=0)
    scaled = (pts - 0.5 * (lo + pts.max(axis=0))) * scale
    return {"points": len(pts), "voxels": len(voxelise(scaled, voxel)), "extent": ext * scale,
            "raw_extent": ext, "leaves": sample.leaf_count}


__all__ = ["SPECIES", "PlantParams", "PlantSample", "SessionPair", "generate_plant", "generate_session_pair",
           "plant_summary"]


def save_session_pair(pair: SessionPair, folder, name: str | None = None) -> Path:
    """Write a pair as ``<name>_previous.ply``, ``<name>_current.ply`` (binary, metres, organ labels),
    ``<name>_correspondences.csv`` (previous index, current index) and ``<name>_manifest.json``.

    Every file is written atomically. Returns the manifest path.
    """

    name = name or f"{pair.current.species}_seed{pair.current.seed}"
    folder = Path(folder)
    files = {}
    for role, sample in (("previous", pair.previous), ("current", pair.current)):
        path = write_point_cloud(folder / f"{name}_{role}.ply", sample.points, labels=sample.organ)
        files[role] = path.name
    corr = np.stack([pair.correspondence_previous_idx, pair.correspondence_current_idx], axis=1)
    corr_path = folder / f"{name}_correspondences.csv"
    atomic_write_text(corr_path, "previous,current\n" + "\n".join(f"{a},{b}" for a, b in corr) + "\n")
    manifest = {
        "species": pair.current.species, "seed": pair.current.seed, "days": pair.days,
        "units": "m", "frame": "stem base at the origin, +Z up",
        "labels": "organ: 0 = stem, 1.. = leaves bottom to top",
        "files": {**files, "correspondences": corr_path.name},
        "points": {"previous": len(pair.previous), "current": len(pair.current)},
        "leaves": {"previous": pair.previous.leaf_count, "current": pair.current.leaf_count},
        "new_organs": list(pair.new_organs), "generator": "tpvp.synthetic.plants",
    }
    manifest_path = folder / f"{name}_manifest.json"
    atomic_write_text(manifest_path, json.dumps(manifest, indent=2) + "\n")
    return manifest_path
