"""Figures of the plant-complexity tutorial (notebook 03, Table II): two plants side by side, the
views Ours picks for each, what each view adds, the coverage curves and how many candidate views
see each voxel (offscreen PNG). The computations are in :mod:`tpvp.experiments.species`."""

from __future__ import annotations

import numpy as np

from tpvp.metrics.views import first_seen_step, share_seen_by_at_most, views_per_voxel
from tpvp.viz.figures import _equal_axes, _save, _subsample, plt
from tpvp.viz.geometry import plan_geometry

_SPECIES_COLOURS = {"tomato": "tab:red", "maize": "tab:olive"}


def _colour(label: str, index: int) -> str:
    for species, colour in _SPECIES_COLOURS.items():
        if str(label).startswith(species):
            return colour
    return f"C{index}"


def _plant_voxels(scene):
    """The plant's ground-truth voxel centres (the table left out)."""
    return scene.grid.centres[scene.grid.countable]


def plot_plants(path, panels, title: str = ""):
    """The plants side by side (``panels``: a list of ``(title, scene)``), each from the side
    (elevation 10 deg) and from above (elevation 80 deg): the ground-truth voxels (2 mm) coloured by
    height, in the same metric scale."""
    fig = plt.figure(figsize=(4.6 * len(panels), 8.4))
    clouds = [_plant_voxels(scene) for _, scene in panels]
    everything = np.concatenate(clouds)
    for column, ((name, _), cloud) in enumerate(zip(panels, clouds)):
        for row, (elevation, what) in enumerate(((10, "from the side"), (80, "from above"))):
            ax = fig.add_subplot(2, len(panels), row * len(panels) + column + 1, projection="3d")
            ax.scatter(*cloud.T, s=1.2, c=cloud[:, 2], cmap="viridis", linewidths=0, alpha=0.8,
                       vmin=everything[:, 2].min(), vmax=everything[:, 2].max())
            _equal_axes(ax, everything)
            ax.view_init(elev=elevation, azim=-60)
            ax.set_box_aspect(None, zoom=1.1)
            ax.set_title(f"{name}: {what}\n{len(cloud):,} plant voxels", fontsize=9)
            ax.tick_params(labelsize=6)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_plans(path, items, title: str = ""):
    """Ours' plan for each showcase (``items``: :class:`tpvp.experiments.species.Showcase`) side by
    side: the plant, the candidate views (grey), the initial and warm-up views (black triangles),
    the planned views numbered in execution order (red) and the path around the obstacle sphere."""

    fig = plt.figure(figsize=(5.4 * len(items), 5.6))
    for column, item in enumerate(items):
        scene, result = item.scene, item.result
        geometry = plan_geometry(scene, result)
        space = scene.view_space
        ax = fig.add_subplot(1, len(items), column + 1, projection="3d")
        (plant,) = _subsample(_plant_voxels(scene), limit=6000)
        ax.scatter(*plant.T, s=1.0, c="darkgreen", alpha=0.6, linewidths=0)
        ax.scatter(*space.positions.T, s=8, c="lightgrey")
        executed = space.positions[result.executed_views]
        ax.scatter(*executed.T, s=40, c="black", marker="^", depthshade=False, label="initial + warm-up views")
        planned = space.positions[result.planned_views]
        ax.scatter(*planned.T, s=34, c="tab:red", marker="o", depthshade=False, label="planned views")
        for i, p in enumerate(geometry["positions"], start=1):
            ax.text(*p, f" {i}", fontsize=7)
        ax.plot(*geometry["polyline"].T, c="purple", lw=1.2, label="path")
        _equal_axes(ax, np.concatenate([space.positions, plant]))
        ax.view_init(elev=25, azim=-60)
        ax.set_title(f"{item.label}: {result.n_views} views\n{100 * result.coverage:.2f} % coverage, "
                     f"{result.path_length:.2f} m path", fontsize=10)
        ax.tick_params(labelsize=6)
        if column == 0:
            ax.legend(loc="upper left", fontsize=7)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_view_gains(path, items, curves, title: str = ""):
    """What each executed view adds, per showcase (``items``) with its coverage curve (``curves``,
    the matching :func:`tpvp.experiments.species.coverage_curve` tables). Top: the plant's oracle
    voxels coloured by the step that first saw them (one colour per step, shared by both rows;
    light grey: never seen by the plan). Bottom: the oracle voxels each step sees first (log
    scale), labelled with the view's index."""
    from matplotlib.colors import BoundaryNorm

    steps = max(len(c) for c in curves)
    cmap = plt.get_cmap("viridis_r", steps)
    norm = BoundaryNorm(np.arange(0.5, steps + 1.5), cmap.N)
    fig = plt.figure(figsize=(6.4 * len(items), 10.5))
    grid = fig.add_gridspec(2, len(items), height_ratios=[1.5, 1.0])
    for column, (item, curve) in enumerate(zip(items, curves)):
        scene = item.scene
        oracle = np.asarray(scene.oracle)
        centres = scene.grid.centres[oracle]
        step = first_seen_step(scene.truth_visibility, item.order, oracle)
        ax = fig.add_subplot(grid[0, column], projection="3d")
        ax.computed_zorder = False
        seen = step > 0
        ax.scatter(*centres[~seen].T, s=2, c="lightgrey", linewidths=0, zorder=0)
        early = seen & (step <= 2)
        ax.scatter(*centres[early].T, s=1.2, c=step[early], cmap=cmap, norm=norm, linewidths=0, alpha=0.5, zorder=1)
        late = seen & (step > 2)  # drawn larger and on top: the voxels the initial and warm-up views missed
        points = ax.scatter(*centres[late].T, s=6, c=step[late], cmap=cmap, norm=norm, linewidths=0, zorder=2)
        _equal_axes(ax, centres)
        ax.view_init(elev=15, azim=-60)
        ax.set_box_aspect(None, zoom=1.15)
        ax.set_title(f"{item.label}: oracle voxels by the step that first saw them\n"
                     f"steps 1-2 small (initial, warm-up), later steps large", fontsize=9)
        ax.tick_params(labelsize=6)
        fig.colorbar(points, ax=ax, shrink=0.6, pad=0.14, label="step (execution order)",
                     ticks=range(1, steps + 1, max(1, steps // 8)))

        ax = fig.add_subplot(grid[1, column])
        x = curve["step"].to_numpy()
        new = curve["new_voxels"].to_numpy()
        ax.bar(x, np.maximum(new, 0.8), color=cmap(norm(x)), edgecolor="black", linewidth=0.4)
        for xi, n in zip(x, new):
            ax.text(xi, max(n, 0.8) * 1.1, str(n), ha="center", va="bottom", fontsize=6.5)
        ax.set_yscale("log")
        ax.set_ylim(0.7, max(new.max(), 1) * 3)
        ax.set_xticks(x, [f"{s}\n#{v}" for s, v in zip(x, curve["view"])], fontsize=7)
        ax.set_xlabel("step (view index); steps 1-2: initial and warm-up views")
        ax.set_ylabel("oracle voxels seen first (log)")
        ax.set_title(f"{item.label}: what each view adds", fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_coverage_curves(path, curves: dict, title: str = ""):
    """Coverage of the oracle set vs the number of executed views, in execution order, one line
    per entry of ``curves`` (``{label: coverage_curve table}``), all on one axis (left); the oracle
    voxels still unseen, log scale (right), where the long tail of a plan shows. A label starting
    with a species name gets that species' colour; one containing "sphere)" but not "hemisphere"
    is dashed."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for i, (label, curve) in enumerate(curves.items()):
        colour = _colour(label, i)
        style = "o--" if "sphere)" in label and "hemisphere" not in label else "o-"
        x = curve["step"].to_numpy()
        axes[0].plot(x, 100 * curve["coverage"], style, color=colour, label=f"{label}: {len(curve)} views, "
                     f"{100 * curve['coverage'].iloc[-1]:.2f} %")
        total = curve["covered"].iloc[-1] / max(curve["coverage"].iloc[-1], 1e-12)
        unseen = np.rint(total - curve["covered"].to_numpy())
        axes[1].plot(x, np.maximum(unseen, 0.8), style, color=colour, label=label)
    for level in (98, 99):
        axes[0].axhline(level, color="grey", lw=0.7, ls=":")
    axes[0].set_ylabel("coverage of the oracle set (%)")
    axes[0].set_ylim(min(60, axes[0].get_ylim()[0]), 100.5)
    axes[1].set_yscale("log")
    axes[1].set_ylabel("oracle voxels not yet seen (log)")
    for ax in axes:
        ax.set_xlabel("views executed (initial and warm-up included)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="lower right" if ax is axes[0] else "upper right")
    axes[0].set_title("coverage in execution order (dotted: 98 % and 99 %)")
    axes[1].set_title("what is left to see")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_views_per_voxel(path, counts: dict, k_max: int = 8, title: str = ""):
    """How many candidate views see each oracle voxel: ``counts`` ``{(species, view_space):
    views_per_voxel array}``; one panel per view space with, per species, the share of the oracle
    voxels seen by at most k views, k = 1 .. ``k_max`` (grouped bars)."""

    spaces = list(dict.fromkeys(space for _, space in counts))
    species = list(dict.fromkeys(sp for sp, _ in counts))
    fig, axes = plt.subplots(1, len(spaces), figsize=(5.6 * len(spaces), 4.2), squeeze=False, sharey=True)
    width = 0.8 / len(species)
    k = np.arange(1, k_max + 1)
    for ax, space in zip(axes[0], spaces):
        for i, sp in enumerate(species):
            if (sp, space) not in counts:
                continue
            share = 100 * share_seen_by_at_most(counts[(sp, space)], k_max)
            bars = ax.bar(k + (i - (len(species) - 1) / 2) * width, share, width, color=_colour(sp, i),
                          label=f"{sp} (median {np.median(counts[(sp, space)]):.0f} views per voxel)")
            for bar, value in zip(bars[:3], share[:3]):
                ax.text(bar.get_x() + bar.get_width() / 2, value + 0.3, f"{value:.1f}", ha="center", va="bottom",
                        fontsize=6.5)
        ax.set_xticks(k)
        ax.set_xlabel("k (candidate views)")
        ax.set_title(f"{space} view space", fontsize=10)
        ax.grid(axis="y", alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
    axes[0][0].set_ylabel("oracle voxels seen by at most k views (%)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_hard_voxels(path, panels, few: int = 2, title: str = ""):
    """Where the hard voxels are (``panels``: a list of ``(title, scene)``): the oracle voxels seen
    by at most ``few`` candidate views (red, large, on top) among the others (light blue), from the
    side (elevation 15 deg) and from below (elevation -40 deg)."""

    fig = plt.figure(figsize=(4.8 * len(panels), 8.6))
    for column, (name, scene) in enumerate(panels):
        oracle = np.asarray(scene.oracle)
        centres = scene.grid.centres[oracle]
        counts = views_per_voxel(scene.truth_visibility, oracle)
        hard = counts <= few
        for row, (elevation, what) in enumerate(((15, "from the side"), (-40, "from below"))):
            ax = fig.add_subplot(2, len(panels), row * len(panels) + column + 1, projection="3d")
            ax.computed_zorder = False
            ax.scatter(*centres[~hard].T, s=1.5, c="steelblue", alpha=0.25, linewidths=0, zorder=1)
            ax.scatter(*centres[hard].T, s=7, c="red", edgecolors="darkred", linewidths=0.2, zorder=2,
                       label=f"seen by <= {few} views: {int(hard.sum())} ({100 * hard.mean():.1f} %)")
            _equal_axes(ax, centres)
            ax.view_init(elev=elevation, azim=-60)
            ax.set_title(f"{name}: {what}", fontsize=9, pad=24 if elevation < 0 else 6)
            ax.tick_params(labelsize=6)
            if row == 0:
                ax.legend(loc="upper left", fontsize=7, markerscale=1.5)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_species_optimum(path, per_species, title: str = ""):
    """Per species (rows of :func:`tpvp.experiments.species.species_tables`' ``per_species``), one
    panel per view space: the plan's views for 98 % beside the exact optimum's, the ratio above,
    the species in the order of the hemisphere's ratio."""
    spaces = list(dict.fromkeys(per_species["view_space"]))
    order = (per_species[per_species["view_space"] == spaces[0]].sort_values("views_per_optimum")["species"].tolist())
    fig, axes = plt.subplots(1, len(spaces), figsize=(6.5 * len(spaces), 4.6), squeeze=False, sharey=True)
    for ax, space in zip(axes[0], spaces):
        table = per_species[per_species["view_space"] == space].set_index("species").reindex(order)
        x = np.arange(len(order))
        ax.bar(x - 0.2, table["views"], 0.4, color="tab:blue", label="plan for 98 %")
        ax.bar(x + 0.2, table["optimum"], 0.4, color="0.6", label="exact optimum for 98 %")
        for i, (views, ratio) in enumerate(zip(table["views"], table["views_per_optimum"])):
            ax.text(i - 0.2, views, f"{ratio:.2f}x", ha="center", va="bottom", fontsize=7)
        ax.set_xticks(x, [s.replace(" ", "\n", 1) for s in order], fontsize=7)
        ax.set_title(space, fontsize=9)
        ax.grid(axis="y", alpha=0.3)
    axes[0, 0].set_ylabel("views (mean over the cases)")
    axes[0, 0].legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def plot_organ_targets(path, organ_targets, title: str = ""):
    """Per fruiting species and view space (``organ_targets`` of
    :func:`tpvp.experiments.species.species_tables`): the views of the full cover beside those of the
    organ targets, the true fruit coverage (mean) above the organ targets' bar."""
    labels = [f"{r.species.replace('helios ', '')}\n{r.view_space}" for r in organ_targets.itertuples()]
    x = np.arange(len(labels))
    fig, ax = plt.subplots(figsize=(max(6.0, 0.75 * len(labels)), 4.2))
    ax.bar(x - 0.2, organ_targets["full_cover_views"], 0.4, color="0.6", label="--coverage-target 1.0")
    ax.bar(x + 0.2, organ_targets["organ_target_views"], 0.4, color="tab:orange", label="fruit=1.0, leaf=0.95")
    for i, (views, fruit) in enumerate(zip(organ_targets["organ_target_views"], organ_targets["fruit_mean"])):
        ax.text(i + 0.2, views, f"fruit\n{100 * fruit:.1f} %", ha="center", va="bottom", fontsize=6.5)
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("views (mean over the cases)")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)
