"""The ablations of Tables III and IV on one case: what inflation adds to the planning surface and
which views it buys, and how the warm-up NBV changes the registration of the previous session.

Table III plans on the inflated surface :math:`\\tilde P^+ = \\tilde P \\cup Q \\cup I` and, without
inflation, on the transferred previous session :math:`\\tilde P` alone (``inflation.enabled =
False``: no :math:`I`, no :math:`Q`). Table IV registers the previous session onto the coarse
reconstruction :math:`Q` of the initial view only (``nbv.warm_up_views = 0``) or of the initial view
plus one warm-up NBV. The functions below take one scene apart along these two switches, with the
same configuration overrides as the experiment registry (``plants.method_config``); the tables of
the whole protocol come from :func:`tpvp.experiments.plants.tables`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import sparse

from tpvp.config_loading import with_overrides
from tpvp.experiments.plants import default_cases, method_config
from tpvp.experiments.results import mean_std
from tpvp.simulate.single_plant import known, run_case, transfer
from tpvp.pipeline.surface import planning_visibility
from tpvp.inflation.inflate import SURFACE_LAYERS as ORIGINS
from tpvp.metrics.geometry import chamfer_distance, nearest_distances
from tpvp.scene import voxels
from tpvp.visibility import covered_voxels
from tpvp.viz.ablation import paired_cases  # noqa: F401 (Tables III and IV per case)

#: The four methods of Tables III and IV (their overrides: ``plants.ONE_SHOT_METHODS``).
ABLATION_METHODS = ["ours", "ours-no-inflation", "initial-view-only", "initial-view-only-no-inflation"]

#: Origin labels of a planning-surface voxel, in the order of precedence (a voxel occupied by
#: several layers takes the first one's label).


def example_case(species: str = "maize", view_space: str = "sphere"):
    """The reduced protocol's case (``plants.default_cases(quick=True)``) of ``species`` in
    ``view_space``: generated pair seed 0, rotation 0, initial view 17."""
    for case in default_cases(quick=True):
        if case.instance.species == species and case.view_space == view_space:
            return case
    raise KeyError(f"no quick case of {species!r} in the {view_space!r} view space")


# --------------------------------------------------------------------------------------------------
# small exact computations
# --------------------------------------------------------------------------------------------------


def surface_origins(layers, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """The voxels at ``resolution`` occupied by any cloud of ``layers`` (a sequence of ``(N, 3)``
    clouds, e.g. ``(P~, Q, I)``) in code order - the order :func:`tpvp.scene.grid.build_grid`
    gives the planning grid - and per voxel the index of the first layer that occupies it.
    Returns ``(keys (M, 3) int64, origin (M,) int64)``."""
    codes = [voxels.encode_keys(voxels.voxelise(layer, resolution)) if len(layer) else np.zeros(0, np.int64)
             for layer in layers]
    every = np.unique(np.concatenate(codes)) if codes else np.zeros(0, np.int64)
    origin = np.full(len(every), -1, dtype=np.int64)
    for index in reversed(range(len(codes))):  # the first layer is written last: it wins
        origin[np.isin(every, codes[index])] = index
    return voxels.decode_keys(every), origin


def covered_mask(visibility, views, size: int | None = None) -> np.ndarray:
    """Boolean mask over the columns of ``visibility`` (views x voxels): seen by any of ``views``."""
    matrix = sparse.csr_matrix(visibility)
    mask = np.zeros(matrix.shape[1] if size is None else size, dtype=bool)
    mask[covered_voxels(matrix, list(views))] = True
    return mask


def only_covered_by(visibility, views, other_views, among=None) -> np.ndarray:
    """Ids of the voxels that ``views`` see and none of ``other_views`` sees (restricted to the ids
    ``among``, e.g. the oracle set, when given), ascending."""
    ids = np.flatnonzero(covered_mask(visibility, views) & ~covered_mask(visibility, other_views))
    return ids if among is None else np.intersect1d(ids, np.asarray(among, dtype=np.int64))


def sole_cover(visibility, views) -> dict:
    """Per view of ``views``: the ids of the voxels it sees and no other view of ``views`` sees
    (its own contribution to the plan; in a minimal set cover every chosen view has some)."""
    matrix = sparse.csr_matrix(visibility)
    views = list(dict.fromkeys(int(v) for v in views))
    if not views:
        return {}
    counts = np.asarray(matrix[views].astype(np.int64).sum(axis=0)).ravel()
    out = {}
    for view in views:
        seen = matrix.indices[matrix.indptr[view]:matrix.indptr[view + 1]]
        out[view] = np.sort(seen[counts[seen] == 1])
    return out


# --------------------------------------------------------------------------------------------------
# Table III on one case: with and without inflation
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class InflationAblation:
    """One case planned with inflation (``with_inflation``) and without (``without_inflation``),
    sharing one warm-up and registration.

    ``surface_keys`` / ``surface_origin``: the voxels of the inflated planning surface (the planning
    grid's voxels, same order) and the index in :data:`ORIGINS` of the first layer occupying each;
    the surface without inflation is exactly the voxels of origin 0. ``visibility_with`` /
    ``visibility_without``: what each candidate view sees of either surface. ``only_with`` /
    ``only_without``: views only that plan selects; ``seen_only_with`` / ``seen_only_without``:
    ground-truth (oracle) voxel ids that plan's views see and the other plan's views miss.
    """
    with_inflation: object  # PlanResult
    without_inflation: object
    resolution: float
    surface_keys: np.ndarray
    surface_origin: np.ndarray
    visibility_with: object
    visibility_without: object
    only_with: list
    only_without: list
    seen_only_with: np.ndarray
    seen_only_without: np.ndarray

    @property
    def surface_centres(self) -> np.ndarray:
        return voxels.key_centres(self.surface_keys, self.resolution)


def inflation_ablation(scene, config, transferred=None) -> InflationAblation:
    """Plan ``scene`` with ``config`` (inflation on) and with inflation off, from one shared warm-up
    and registration (``transferred``, computed when not given), and compare the two plans."""
    config = with_overrides(config, {"inflation.enabled": True})
    transferred = transferred or transfer(scene, config)
    with_inflation = run_case(scene, config, transferred=transferred)
    without = run_case(scene, method_config(config, "ours-no-inflation"), transferred=transferred)
    resolution = config.selection.cover_resolution
    clouds = with_inflation.clouds
    keys, origin = surface_origins((clouds["warped"], clouds["coarse"], clouds["inflation"]), resolution)
    space, sensor = scene.view_space, known(scene).sensor
    grid_with, visibility_with = planning_visibility(clouds["planning"], resolution, space.positions, space.look_ats,
                                                     sensor)
    if not np.array_equal(grid_with.keys, keys):  # both are the code order of the same voxel set
        raise AssertionError("the planning grid and the labelled surface disagree")
    _, visibility_without = planning_visibility(without.clouds["planning"], resolution, space.positions,
                                                space.look_ats, sensor)
    views_with, views_without = with_inflation.order, without.order
    return InflationAblation(
        with_inflation=with_inflation, without_inflation=without, resolution=resolution,
        surface_keys=keys, surface_origin=origin, visibility_with=visibility_with,
        visibility_without=visibility_without,
        only_with=[v for v in with_inflation.planned_views if v not in views_without],
        only_without=[v for v in without.planned_views if v not in views_with],
        seen_only_with=only_covered_by(scene.truth_visibility, views_with, views_without, scene.oracle),
        seen_only_without=only_covered_by(scene.truth_visibility, views_without, views_with, scene.oracle))


def inflation_table(ablation: InflationAblation) -> pd.DataFrame:
    """One row per plan: its planning surface (voxels by origin), views, coverage (%), path, the
    views only it selects and the ground-truth voxels only it covers."""
    counts = np.bincount(ablation.surface_origin, minlength=len(ORIGINS))
    rows = []
    for name, result, surface, only, seen in (
            ("without inflation: P~", ablation.without_inflation, (counts[0], 0, 0), ablation.only_without,
             ablation.seen_only_without),
            ("with inflation: P~ ∪ Q ∪ I", ablation.with_inflation, tuple(counts), ablation.only_with,
             ablation.seen_only_with)):
        rows.append({"plan": name, "planning voxels": int(sum(surface)), "from P~": int(surface[0]),
                     "added by Q": int(surface[1]), "added by I": int(surface[2]), "views": result.n_views,
                     "coverage (%)": 100 * result.coverage, "path (m)": result.path_length,
                     "views only this plan selects": ", ".join(map(str, only)) or "-",
                     "oracle voxels only this plan covers": len(seen)})
    return pd.DataFrame(rows)


def exclusive_views_table(scene, ablation: InflationAblation) -> pd.DataFrame:
    """Per view that only one plan selects: which plan, where it stands (elevation, azimuth), the
    ground-truth voxels it sees that the other plan's views all miss, the voxels inflation adds (Q
    or I) it sees on the inflated surface, and the planning voxels only it covers within its own
    plan, by origin (why the set cover needed it)."""
    space = scene.view_space
    inflated = sparse.csr_matrix(ablation.visibility_with)
    truth = sparse.csr_matrix(scene.truth_visibility)
    oracle = np.zeros(truth.shape[1], dtype=bool)
    oracle[scene.oracle] = True
    rows = []
    for name, result, only, visibility, other in (
            ("with inflation", ablation.with_inflation, ablation.only_with, ablation.visibility_with,
             ablation.without_inflation),
            ("without inflation", ablation.without_inflation, ablation.only_without, ablation.visibility_without,
             ablation.with_inflation)):
        sole = sole_cover(visibility, result.order)
        misses = ~covered_mask(truth, other.order)
        for view in only:
            seen = truth.indices[truth.indptr[view]:truth.indptr[view + 1]]
            # the surface without inflation is the P~ voxels alone: its voxel ids follow another grid
            origin = ablation.surface_origin[sole[view]] if visibility is ablation.visibility_with \
                else np.zeros(len(sole[view]), dtype=np.int64)
            by_origin = np.bincount(origin, minlength=len(ORIGINS))
            added = ablation.surface_origin[inflated.indices[inflated.indptr[view]:inflated.indptr[view + 1]]] > 0
            offset = space.positions[view] - space.look_ats[view]
            rows.append({"plan": name, "view": int(view),
                         "elevation (deg)": float(np.degrees(np.arcsin(offset[2] / np.linalg.norm(offset)))),
                         "azimuth (deg)": float(np.degrees(np.arctan2(offset[1], offset[0]))),
                         "oracle voxels it sees": int(oracle[seen].sum()),
                         "... that the other plan misses": int((oracle[seen] & misses[seen]).sum()),
                         "added voxels (Q, I) it sees": int(added.sum()),
                         "planning voxels only it covers": int(len(sole[view])),
                         "of which P~": int(by_origin[0]), "of which Q": int(by_origin[1]),
                         "of which I": int(by_origin[2])})
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------------------------------
# Table IV on one case: registration on the initial view only vs after the warm-up NBV
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class RegistrationSetting:
    """One warm-up setting: its transfer (executed views, coarse reconstruction, alignment), the
    distance of every transferred point to today's plant (m) and its plans with and without
    inflation."""
    label: str
    warm_up_views: int
    transfer: object  # tpvp.simulate.single_plant.Transfer
    error: np.ndarray  # (N,) nearest distance of each warped point to today's plant
    chamfer_truth: float  # symmetric Chamfer distance of the warped model to today's plant (m, Table IV)
    plans: dict  # "with inflation" / "without inflation" -> PlanResult

    @property
    def coarse(self) -> np.ndarray:
        return np.unique(self.transfer.coarse, axis=0)

    @property
    def warped(self) -> np.ndarray:
        return self.transfer.alignment.warped


def registration_ablation(scene, config, transfers: dict | None = None) -> list:
    """The initial view only and the initial view + ``config.nbv.warm_up_views`` (at least one)
    warm-up NBVs: register, measure against today's plant, plan with and without inflation.
    ``transfers``: already computed transfers by number of warm-up views (e.g. ``{1: transferred}``).
    Returns two :class:`RegistrationSetting`."""
    transfers = dict(transfers or {})
    warm_ups = max(1, config.nbv.warm_up_views)
    settings = []
    for count, label, (with_method, without_method) in (
            (0, "initial view only", ("initial-view-only", "initial-view-only-no-inflation")),
            (warm_ups, f"initial view + {warm_ups} warm-up NBV", ("ours", "ours-no-inflation"))):
        base = with_overrides(config, {"nbv.warm_up_views": count})
        with_config, without_config = (method_config(base, m) for m in (with_method, without_method))
        transferred = transfers.get(count) or transfer(scene, with_config)
        warped = transferred.alignment.warped
        plans = {"with inflation": run_case(scene, with_config, transferred=transferred),
                 "without inflation": run_case(scene, without_config, transferred=transferred)}
        settings.append(RegistrationSetting(label, count, transferred, nearest_distances(warped, scene.current),
                                            chamfer_distance(warped, scene.current), plans))
    return settings


def registration_table(scene, settings) -> pd.DataFrame:
    """One row per warm-up setting: the executed views, the coarse reconstruction's points, the
    Chamfer distances (mm) of the previous session to Q before registration and of the transferred
    model to Q and to today's plant after it (Table IV's measure), the share of transferred points
    within 2 mm (the ground-truth voxel size) of today's plant, and the plans' views and coverage."""
    unregistered = 1e3 * chamfer_distance(scene.previous, scene.current)
    rows = []
    for s in settings:
        alignment = s.transfer.alignment
        rows.append({
            "registration on": s.label, "executed views": ", ".join(map(str, s.transfer.executed)),
            "Q points": len(s.coarse),
            "Chamfer P-Q before (mm)": 1e3 * alignment.chamfer_before,
            "Chamfer P~-Q after (mm)": 1e3 * alignment.chamfer_after,
            "Chamfer P-truth unregistered (mm)": unregistered,
            "Chamfer P~-truth (mm)": 1e3 * s.chamfer_truth,
            "P~ points within 2 mm of today's plant (%)": 100 * (s.error <= 0.002).mean(),
            **{f"{k}: views": p.n_views for k, p in s.plans.items()},
            **{f"{k}: coverage (%)": 100 * p.coverage for k, p in s.plans.items()}})
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------------------------------
# the protocol's tables
# --------------------------------------------------------------------------------------------------


def pooled_table(raw: pd.DataFrame, methods=ABLATION_METHODS) -> pd.DataFrame:
    """Views, coverage (%), path length and Chamfer to today's plant (mm) per source and method,
    pooled over species and view spaces (the paper's text reports the initial-view-only variant
    without inflation this way), mean and std over the cases; sources in the order they come,
    methods in the order of ``methods``."""
    rows = raw[raw["method"].isin(list(methods)) & raw["views"].notna()]
    order = {m: i for i, m in enumerate(methods)}
    table = mean_std(rows, ["source", "method"],
                      columns=("views", "coverage", "path_length_m", "chamfer_truth_mm"))
    sources = {source: i for i, source in enumerate(dict.fromkeys(rows["source"]))}  # as they come
    return table.sort_values(["source", "method"], key=lambda c: c.map(order if c.name == "method" else sources),
                             kind="stable").reset_index(drop=True)


# --------------------------------------------------------------------------------------------------
# what a case shows, in words (numbers computed, never typed)
# --------------------------------------------------------------------------------------------------


def describe_inflation(ablation: InflationAblation) -> str:
    """A Markdown paragraph with the case's numbers: what inflation adds to the planning surface,
    the two plans, and what the views only one plan selects see that the other misses."""
    counts = np.bincount(ablation.surface_origin, minlength=len(ORIGINS))
    w, wo = ablation.with_inflation, ablation.without_inflation
    views = lambda vs: ", ".join(map(str, vs)) or "none"  # noqa: E731
    return (f"Inflation adds **{counts[1]}** voxels that only the coarse reconstruction $Q$ occupies and "
            f"**{counts[2]}** that only the inflation set $I$ occupies to the **{counts[0]}** voxels of "
            f"$\\tilde P$ ({1e3 * ablation.resolution:g} mm voxels). With inflation the plan has **{w.n_views}** "
            f"views and covers **{100 * w.coverage:.2f} %** of the oracle set; without, **{wo.n_views}** views "
            f"and **{100 * wo.coverage:.2f} %**. Views only the inflated plan selects: {views(ablation.only_with)}; "
            f"only the plan without inflation: {views(ablation.only_without)}. The inflated plan covers "
            f"**{len(ablation.seen_only_with)}** oracle voxels the other plan misses, which covers "
            f"**{len(ablation.seen_only_without)}** that the inflated plan misses.")


def describe_registration(settings) -> str:
    """A Markdown paragraph with the Chamfer distances of both warm-up settings."""
    parts = []
    for s in settings:
        alignment = s.transfer.alignment
        parts.append(f"*{s.label}* ($Q$ from view(s) {', '.join(map(str, s.transfer.executed))}, {len(s.coarse)} "
                     f"points): Chamfer to $Q$ **{1e3 * alignment.chamfer_after:.2f} mm**, to today's plant "
                     f"**{1e3 * s.chamfer_truth:.2f} mm**")
    return "; ".join(parts) + "."

