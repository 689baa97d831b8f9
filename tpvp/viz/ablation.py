"""Figures of the ablations of Tables III and IV (offscreen PNG, see
:mod:`tpvp.experiments.ablation`): the planning surface by origin, the views and voxels in which
the plans with and without inflation differ, the transferred model on today's plant after
registration on the initial view only and after the warm-up NBV, the protocol's cases paired, and
an interactive view of the planning surface's layers."""

from __future__ import annotations

import numpy as np
import pandas as pd

from tpvp.inflation.inflate import SURFACE_LAYERS
from tpvp.viz.figures import _equal_axes, _save, _subsample, plt
from tpvp.viz.interactive import scene_3d

#: Colours of the planning surface's layers (the paper's figures: previous red, coarse blue,
#: inflation green) and of the views / voxels only one plan has.
ORIGIN_COLOURS = ("tab:red", "tab:blue", "limegreen")
ONLY_WITH, ONLY_WITHOUT = "tab:green", "darkorange"
_PANELS = ((25, -60, "from above"), (5, 30, "side"), (-55, 120, "from below"))


def _panel_name(ax, name, elev):
    ax.text2D(0.5, -0.12, f"{name} (elevation {elev:+d} deg)", transform=ax.transAxes, ha="center", va="top",
              fontsize=8, fontweight="bold")
    ax.tick_params(labelsize=6)


def _legend(ax, **keywords):
    legend = ax.legend(fontsize=7, markerscale=2, **keywords)
    for handle in legend.legend_handles:
        handle.set_alpha(1.0)


def plot_planning_surface(path, centres, origin, labels=("transferred P~", "coarse Q", "inflation I"),
                          title: str = ""):
    """The planning surface's voxels coloured by origin (``origin[i]`` indexes ``labels``), from
    above, the side and below. Layers after the first (what inflation adds) are drawn larger and
    on top; the voxel counts are in the legend."""
    centres = np.asarray(centres, float).reshape(-1, 3)
    origin = np.asarray(origin).reshape(-1)
    fig = plt.figure(figsize=(15, 5.4))
    for k, (elev, azim, name) in enumerate(_PANELS):
        ax = fig.add_subplot(1, len(_PANELS), k + 1, projection="3d")
        ax.computed_zorder = False
        for index, (label, colour) in enumerate(zip(labels, ORIGIN_COLOURS)):
            points = centres[origin == index]
            style = dict(s=2, alpha=0.3) if index == 0 else \
                dict(s=12 if index == 1 else 40, alpha=1.0, edgecolors="black", linewidths=0.3)
            (shown,) = _subsample(points)
            ax.scatter(*shown.T, c=colour, depthshade=False, zorder=index + 1,
                       label=f"{label} ({len(points)} voxels)", **style) if len(shown) else \
                ax.scatter([], [], [], c=colour, label=f"{label} (0 voxels)", **style)
        if len(centres):
            _equal_axes(ax, centres)
        ax.view_init(elev=elev, azim=azim)
        ax.set_box_aspect((1, 1, 1), zoom=1.1)
        _panel_name(ax, name, elev)
        if k == 0:
            _legend(ax, loc="upper left")
    fig.suptitle(title or "The planning surface by origin", fontsize=10)
    return _save(fig, path, vector=True)


def plot_plan_difference(path, scene, ablation, title: str = ""):
    """Left: the candidate views (grey), the executed views (black), the views both plans select
    (dark grey), only the plan with inflation selects (green) and only the one without (orange),
    around the plant. Middle and right: today's plant (ground-truth voxels, grey) with the oracle
    voxels only the plan with inflation covers (green) and only the one without covers (orange),
    from the side and from below."""
    space = scene.view_space
    positions = space.positions
    executed = list(ablation.with_inflation.executed_views)
    both = [v for v in ablation.with_inflation.planned_views if v not in ablation.only_with]
    plant = scene.grid.countable
    centres = scene.grid.centres
    fig = plt.figure(figsize=(16, 5.6))
    ax = fig.add_subplot(1, 3, 1, projection="3d")
    ax.computed_zorder = False
    (shown,) = _subsample(centres[plant], limit=6000)
    ax.scatter(*shown.T, s=0.5, c="0.55", alpha=0.4, linewidths=0, zorder=1)
    groups = ((range(len(positions)), "lightgrey", "o", 8, "candidate views"),
              (executed, "black", "^", 50, "executed (initial, warm-up)"),
              (both, "dimgray", "o", 40, "selected by both plans"),
              (ablation.only_with, ONLY_WITH, "D", 70, "only with inflation"),
              (ablation.only_without, ONLY_WITHOUT, "s", 70, "only without inflation"))
    for z, (views, colour, marker, size, label) in enumerate(groups, start=2):
        views = list(views)
        if views:
            ax.scatter(*positions[views].T, s=size, c=colour, marker=marker, depthshade=False, zorder=z,
                       edgecolors="black" if size > 40 else "none", linewidths=0.4, label=f"{label} ({len(views)})")
    for view in [*executed, *ablation.only_with, *ablation.only_without]:
        ax.text(*positions[view], f" {view}", fontsize=7, zorder=10)
    _equal_axes(ax, positions)
    ax.set_box_aspect((1, 1, 1), zoom=1.05)
    ax.tick_params(labelsize=6)
    _legend(ax, loc="upper left")
    ax.set_title("the views of the two plans", fontsize=9)
    for k, (elev, azim, name) in enumerate(_PANELS[1:]):
        ax = fig.add_subplot(1, 3, k + 2, projection="3d")
        ax.computed_zorder = False
        (grey,) = _subsample(centres[plant], limit=20000)
        ax.scatter(*grey.T, s=2, c="0.45", alpha=0.35, linewidths=0, zorder=1, label="today's plant (2 mm voxels)")
        for z, (ids, colour, label) in enumerate(((ablation.seen_only_with, ONLY_WITH, "covered only with inflation"),
                                                  (ablation.seen_only_without, ONLY_WITHOUT,
                                                   "covered only without inflation")), start=2):
            points = centres[np.asarray(ids, dtype=np.int64)]
            ax.scatter(*points.T, s=18, c=colour, edgecolors="black", linewidths=0.3, depthshade=False, zorder=z,
                       label=f"{label} ({len(points)} voxels)")
        _equal_axes(ax, centres[plant])
        ax.view_init(elev=elev, azim=azim)
        ax.set_box_aspect((1, 1, 1), zoom=1.1)
        _panel_name(ax, name, elev)
        if k == 0:
            _legend(ax, loc="upper left")
    w, wo = ablation.with_inflation, ablation.without_inflation
    fig.suptitle(title or (f"with inflation: {w.n_views} views, {100 * w.coverage:.2f} % coverage; "
                           f"without: {wo.n_views} views, {100 * wo.coverage:.2f} % coverage"), fontsize=10)
    return _save(fig, path, vector=True)


def plot_registration(path, scene, settings, title: str = "", vmax_mm: float | None = None):
    """One column per warm-up setting (:class:`tpvp.experiments.ablation.RegistrationSetting`).
    Top: today's plant (grey) and the coarse reconstruction Q the registration fits (blue), with
    the executed views' directions. Bottom: the transferred model P~ on today's plant, each point
    coloured by its distance to today's plant (mm, one colour scale for all columns)."""
    (plant,) = _subsample(scene.current, limit=12000)
    errors = np.concatenate([1e3 * s.error for s in settings])
    vmax = vmax_mm or max(1.0, float(np.percentile(errors, 99)))
    fig = plt.figure(figsize=(6.2 * len(settings), 11))
    mappable = None
    for column, s in enumerate(settings):
        alignment = s.transfer.alignment
        ax = fig.add_subplot(2, len(settings), column + 1, projection="3d")
        ax.computed_zorder = False
        ax.scatter(*plant.T, s=0.4, c="0.6", alpha=0.35, linewidths=0, zorder=1, label="today's plant")
        (coarse,) = _subsample(s.coarse, limit=12000)
        ax.scatter(*coarse.T, s=1.5, c="tab:blue", alpha=0.8, linewidths=0, zorder=2,
                   label=f"coarse reconstruction Q ({len(s.coarse)} points)")
        centre = scene.current.mean(axis=0)
        reach = 0.6 * np.ptp(scene.current, axis=0).max()
        for i, view in enumerate(s.transfer.executed):
            direction = scene.view_space.positions[view] - centre
            tip = centre + reach * direction / np.linalg.norm(direction)
            ax.plot(*np.stack([tip, centre + 0.55 * (tip - centre)]).T, c="black", lw=2, zorder=3)
            ax.text(*tip, f" view {view}" + (" (initial)" if i == 0 else " (NBV)"), fontsize=7, zorder=4)
        _equal_axes(ax, np.concatenate([plant, centre + reach * np.eye(3), centre - reach * np.eye(3)]))
        ax.view_init(elev=20, azim=-60)
        ax.tick_params(labelsize=6)
        _legend(ax, loc="upper left")
        ax.set_title(f"{s.label}: Q from {len(s.transfer.executed)} view(s)\n"
                     f"Chamfer P~-Q after registration {1e3 * alignment.chamfer_after:.2f} mm", fontsize=9)

        ax = fig.add_subplot(2, len(settings), len(settings) + column + 1, projection="3d")
        ax.computed_zorder = False
        ax.scatter(*plant.T, s=0.4, c="0.75", alpha=0.25, linewidths=0, zorder=1)
        warped, error = _subsample(s.warped, 1e3 * s.error, limit=20000)
        order = np.argsort(error)  # the largest errors last, on top
        mappable = ax.scatter(*warped[order].T, s=1.2, c=error[order], cmap="magma_r", vmin=0, vmax=vmax,
                              linewidths=0, zorder=2)
        _equal_axes(ax, np.concatenate([plant, centre + reach * np.eye(3), centre - reach * np.eye(3)]))
        ax.view_init(elev=20, azim=-60)
        ax.tick_params(labelsize=6)
        ax.set_title(f"transferred model P~ on today's plant\nChamfer P~-truth "
                     f"{1e3 * s.chamfer_truth:.2f} mm, mean point error "
                     f"{1e3 * s.error.mean():.2f} mm", fontsize=9)
    if mappable is not None:
        fig.subplots_adjust(right=0.88)
        bar = fig.colorbar(mappable, cax=fig.add_axes([0.91, 0.12, 0.015, 0.3]))
        bar.set_label("distance of a transferred point to today's plant (mm)")
    fig.suptitle(title or "Registration on the initial view only vs after the warm-up NBV", fontsize=11)
    return _save(fig, path, vector=True)


def paired_cases(raw: pd.DataFrame, method_a: str, method_b: str, value: str) -> pd.DataFrame:
    """``value`` of two methods side by side per case (columns ``method_a`` and ``method_b``),
    one row per case both ran."""
    keys = [k for k in ("source", "instance", "species", "view_space", "rotation_deg", "initial_view") if k in raw]
    rows = raw[raw["method"].isin([method_a, method_b])]
    table = rows.pivot_table(index=keys, columns="method", values=value, aggfunc="first").reset_index()
    return table.dropna(subset=[m for m in (method_a, method_b) if m in table])


def plot_paired_cases(path, raw: pd.DataFrame, title: str = ""):
    """Every case of the protocol as one point per panel: coverage and views with inflation vs
    without (Table III) and the Chamfer distance of the transferred model to today's plant after
    the warm-up NBV vs on the initial view only (Table IV); the diagonal marks no change. Colour:
    species (the bundled real pair in purple); marker: view space."""
    panels = (("ours-no-inflation", "ours", "coverage", 100, "coverage (%)", "Table III: coverage"),
              ("ours-no-inflation", "ours", "views", 1, "views", "Table III: views"),
              ("initial-view-only", "ours", "chamfer_truth_mm", 1, "Chamfer P~-truth (mm)",
               "Table IV: registration error"))
    names = {"ours": "Ours", "ours-no-inflation": "Ours w/o inflation", "initial-view-only": "initial view only"}
    colours = {"tomato": "tab:red", "maize": "goldenrod"}
    markers = {"hemisphere": "o", "sphere": "s"}
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.8))
    for ax, (x_method, y_method, value, factor, unit, name) in zip(axes, panels):
        pairs = paired_cases(raw, x_method, y_method, value) if value in raw else pd.DataFrame()
        if pairs.empty or x_method not in pairs or y_method not in pairs:
            ax.text(0.5, 0.5, "no paired cases", ha="center", va="center", transform=ax.transAxes)
            ax.set_title(name)
            continue
        x, y = factor * pairs[x_method].to_numpy(float), factor * pairs[y_method].to_numpy(float)
        better = int((y < x).sum() if value == "chamfer_truth_mm" else (y > x).sum())
        if value == "views":  # integers: a little jitter keeps equal pairs apart
            rng = np.random.default_rng(0)
            x, y = x + rng.uniform(-0.12, 0.12, len(x)), y + rng.uniform(-0.12, 0.12, len(y))
        for (source, species, space), rows in pairs.reset_index(drop=True).groupby(["source", "species", "view_space"]):
            real = source == "bundled"  # the real tomato pair, apart from the generated ones
            ax.scatter(x[rows.index], y[rows.index], c="tab:purple" if real else colours.get(species, "gray"),
                       marker=markers.get(space, "o"), s=30, alpha=0.75, edgecolors="black", linewidths=0.3,
                       label=f"{species}{' (real pair)' if real else ''}, {space}")
        lo, hi = float(min(x.min(), y.min())), float(max(x.max(), y.max()))
        pad = 0.05 * (hi - lo) or 0.5
        ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], c="0.4", lw=1, ls="--")
        ax.set_xlim(lo - pad, hi + pad)
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_xlabel(f"{names[x_method]}: {unit}")
        ax.set_ylabel(f"{names[y_method]}: {unit}")
        word = {"coverage": "higher with inflation", "views": "more views with inflation",
                "chamfer_truth_mm": "lower after the warm-up NBV"}[value]
        ax.set_title(f"{name}\n{better} of {len(pairs)} cases {word}", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path, vector=True)


def planning_surface_3d(scene, ablation, title: str = ""):
    """An interactive (plotly) view of the inflated planning surface by layer, the plan with
    inflation (views numbered in execution order), the views only one plan selects (large green /
    orange) and the oracle voxels only one plan covers."""
    import plotly.graph_objects as go

    centres, origin = ablation.surface_centres, ablation.surface_origin
    truth = scene.grid.centres
    from matplotlib.colors import to_hex

    clouds = {f"{label} ({int((origin == i).sum())} voxels)": (centres[origin == i], to_hex(colour))
              for i, (label, colour) in enumerate(zip(SURFACE_LAYERS, ORIGIN_COLOURS))}
    clouds |= {"today's plant: covered only with inflation": (truth[ablation.seen_only_with], to_hex(ONLY_WITH)),
               "today's plant: covered only without inflation": (truth[ablation.seen_only_without],
                                                                 to_hex(ONLY_WITHOUT))}
    space = scene.view_space
    result = ablation.with_inflation
    figure = scene_3d(clouds, candidates=space.positions, executed=space.positions[result.executed_views],
                      selected=space.positions[result.planned_views],
                      title=title or "The planning surface P~ ∪ Q ∪ I by layer and the plan with inflation")
    for views, colour, symbol, name in ((ablation.only_with, ONLY_WITH, "diamond", "views only with inflation"),
                                        (ablation.only_without, ONLY_WITHOUT, "square", "views only without inflation")):
        if views:
            points = space.positions[list(views)]
            figure.add_trace(go.Scatter3d(x=points[:, 0], y=points[:, 1], z=points[:, 2], mode="markers+text",
                                          name=name, text=[f"view {v}" for v in views],
                                          marker={"size": 8, "color": to_hex(colour), "symbol": symbol,
                                                  "line": {"color": "black", "width": 1}}))
    sizes = {label: 1.5 if label.startswith(SURFACE_LAYERS[0]) else 4 for label in clouds}
    for trace in figure.data:  # what inflation adds and what the plans differ in: larger markers
        if trace.name in sizes and sizes[trace.name] > 1.5:
            trace.marker.size = sizes[trace.name]
    return figure
