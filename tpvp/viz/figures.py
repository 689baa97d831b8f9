"""Offscreen matplotlib figures: the plan in 3D and the covered / uncovered surface."""

from __future__ import annotations

import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: figures are only ever written to files
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tpvp.errors import ConfigError  # noqa: E402
from tpvp.io.atomic import atomic_path  # noqa: E402

_MAX_POINTS = 30000  # matplotlib 3D scatter gets slow beyond this; subsample deterministically


def _subsample(points, *arrays, limit=_MAX_POINTS):
    points = np.asarray(points)
    if len(points) <= limit:
        return (points, *arrays)
    keep = np.random.default_rng(0).choice(len(points), limit, replace=False)
    return (points[keep], *(np.asarray(a)[keep] for a in arrays))


def _equal_axes(ax, points, unit: str = "m"):
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        setter(c - half, c + half)
    ax.set_xlabel(f"x ({unit})")
    ax.set_ylabel(f"y ({unit})")
    ax.set_zlabel(f"z ({unit})")


RASTER_POINTS = 2000


def _save(fig, path, vector: bool = False) -> Path:
    """Write ``fig`` to ``path`` (PNG) and, for the paper's figures (``vector=True``), a PDF beside it.
    In the PDF, point clouds (collections of more than :data:`RASTER_POINTS` marks) are drawn as
    images and the rest as vectors: tens of thousands of vector marks make a PDF of tens of MB
    that takes seconds to write and to open."""
    path = Path(path)
    for ax in fig.axes:
        for collection in ax.collections:
            if len(collection.get_offsets()) > RASTER_POINTS:
                with warnings.catch_warnings():
                    # mplot3d's collections warn that they ignore it, but their base class's draw honours it
                    warnings.filterwarnings("ignore", message="Rasterization of")
                    collection.set_rasterized(True)
    for target in (path, path.with_suffix(".pdf")) if vector else (path,):
        with atomic_path(target) as tmp:
            fig.savefig(tmp, dpi=130, bbox_inches="tight", format=target.suffix.lstrip(".") or "png")
    plt.close(fig)
    return path


def _sphere_wireframe(ax, centre, radius, **style):
    u = np.linspace(0.0, 2.0 * np.pi, 25)
    v = np.linspace(0.0, np.pi, 13)
    x = centre[0] + radius * np.outer(np.cos(u), np.sin(v))
    y = centre[1] + radius * np.outer(np.sin(u), np.sin(v))
    z = centre[2] + radius * np.outer(np.ones_like(u), np.cos(v))
    return ax.plot_wireframe(x, y, z, **style)


def plot_plan(path, plant_points, candidates, executed, selected, path_polyline, title="", *,
              obstacle=None, table_points=None, unit: str = "m") -> Path:
    """Plant, candidate views (grey), executed warm-up views (black), selected views (numbered in
    execution order) and the global path (purple).

    ``obstacle=(centre, radius)`` adds the obstacle sphere the path goes around (wireframe, radius
    in the legend); ``table_points`` ((M, 3), e.g. the table voxel centres) adds the supporting
    table (light brown). Both default to None (not drawn). ``unit``: of the coordinates (a real
    session plans in a scaled planning frame, not in metres).
    """
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    extent = [np.asarray(candidates, dtype=np.float64).reshape(-1, 3)]
    if table_points is not None and len(np.asarray(table_points).reshape(-1, 3)):
        (table,) = _subsample(np.asarray(table_points, dtype=np.float64).reshape(-1, 3), limit=4000)
        ax.scatter(*table.T, s=2, c="sienna", alpha=0.35, linewidths=0, label="table")
        extent.append(table)
    (plant,) = _subsample(plant_points)
    ax.scatter(*plant.T, s=0.3, c=plant[:, 2], cmap="viridis", alpha=0.5, linewidths=0)
    if obstacle is not None:
        centre, radius = obstacle
        centre = np.asarray(centre, dtype=np.float64).reshape(3)
        radius = float(radius)
        _sphere_wireframe(ax, centre, radius, color="tab:orange", lw=0.4, alpha=0.45,
                          label=f"obstacle sphere (r = {radius:.3f} {unit})")
        ax.scatter(*centre, s=25, c="tab:orange", marker="+")
        extent.append(np.array([centre - radius, centre + radius]))
    candidates = extent[0]
    ax.scatter(*candidates.T, s=8, c="lightgrey", label="candidate views")
    executed = np.asarray(executed).reshape(-1, 3)
    ax.scatter(*executed.T, s=40, c="black", marker="s", label="warm-up views")
    selected = np.asarray(selected).reshape(-1, 3)
    ax.scatter(*selected.T, s=40, c="tab:red", marker="^", label="planned views")
    for i, p in enumerate(selected, start=1):
        ax.text(*p, f" {i}", fontsize=7)
    polyline = np.asarray(path_polyline).reshape(-1, 3)
    if len(polyline):
        ax.plot(*polyline.T, c="purple", lw=1.5, label="global path")
    _equal_axes(ax, np.concatenate([*extent, plant]), unit)
    legend = ax.legend(loc="upper left", fontsize=7)
    for handle in legend.legend_handles:
        handle.set_alpha(1.0)
    ax.set_title(title, fontsize=9)
    return _save(fig, path)


#: Views of the coverage figure: (elevation, azimuth, panel title).
_COVERAGE_VIEWS = ((25, -60, "from above"), (5, 30, "side"), (-55, 120, "from below"))


def plot_coverage(path, voxel_centres, covered, observable, title="") -> Path:
    """Ground-truth voxels: covered (blue), observable but missed (red), never observable (grey).

    Three panels (from above, side, from below). Missed and never-observable voxels are drawn
    larger and on top of the covered ones (they are the point of the figure, and few); only the
    covered ones are subsampled for speed. Counts are in the legend and the title.
    """
    voxel_centres = np.asarray(voxel_centres, dtype=np.float64).reshape(-1, 3)
    covered = np.asarray(covered, dtype=bool).reshape(-1)
    observable = np.asarray(observable, dtype=bool).reshape(-1)
    hit = covered & observable
    missed = ~covered & observable
    never = ~observable
    n_hit, n_missed, n_never = int(hit.sum()), int(missed.sum()), int(never.sum())
    (blue,) = _subsample(voxel_centres[hit])
    (grey,) = _subsample(voxel_centres[never], limit=_MAX_POINTS // 3)
    (red,) = _subsample(voxel_centres[missed], limit=_MAX_POINTS // 3)
    layers = (  # drawn in this order, later on top
        (blue, dict(s=1.5, c="tab:blue", alpha=0.45, linewidths=0), f"covered ({n_hit})"),
        (grey, dict(s=3, c="0.3", alpha=0.55, linewidths=0), f"never observable ({n_never})"),
        (red, dict(s=16, c="red", edgecolors="darkred", linewidths=0.4), f"missed ({n_missed})"),
    )
    fig = plt.figure(figsize=(15, 5.2))
    for k, (elev, azim, name) in enumerate(_COVERAGE_VIEWS):
        ax = fig.add_subplot(1, len(_COVERAGE_VIEWS), k + 1, projection="3d")
        ax.computed_zorder = False  # keep the drawing order: mpl would sort whole layers by depth
        for z, (points, style, label) in enumerate(layers):
            if len(points):
                ax.scatter(*points.T, depthshade=False, zorder=z + 1, label=label, **style)
            elif k == 0:  # keep the count in the legend even when there is nothing to draw
                ax.scatter([], [], [], label=label, **style)
        if len(voxel_centres):
            _equal_axes(ax, voxel_centres)
        ax.view_init(elev=elev, azim=azim)
        ax.set_box_aspect((1, 1, 1), zoom=1.1)
        # Panel name under the panel: a title would collide with the axes of the view from below.
        ax.text2D(0.5, -0.1, f"{name} (elevation {elev:+d} deg)", transform=ax.transAxes,
                  ha="center", va="top", fontsize=8, fontweight="bold")
        ax.tick_params(labelsize=6)
        if k == 0:
            legend = ax.legend(loc="upper left", fontsize=7, markerscale=2)
            for handle in legend.legend_handles:
                handle.set_alpha(1.0)
    n_obs = n_hit + n_missed
    share = f"{100 * n_hit / n_obs:.2f} %" if n_obs else "n/a"
    counts = (f"covered {n_hit} of {n_obs} observable voxels ({share}), missed {n_missed} (red), "
              f"never observable {n_never} (grey)")
    fig.suptitle(f"{title}\n{counts}" if title else counts, fontsize=10)
    return _save(fig, path)


def plot_depth_images(path, depths, labels, title="", *, cmap="viridis") -> Path:
    """Depth images side by side (at most 3 per row), colour-mapped in metres with one shared
    colour bar; pixels without a surface (``inf`` / NaN) are white. ``labels``: one per image."""
    depths = [np.asarray(d, dtype=np.float64) for d in depths]
    if not depths:
        raise ConfigError("no depth images to plot")
    finite = np.concatenate([d[np.isfinite(d)] for d in depths])
    lo, hi = (float(finite.min()), float(finite.max())) if len(finite) else (0.0, 1.0)
    if hi <= lo:
        hi = lo + 1e-3
    ncol = min(3, len(depths))
    nrow = -(-len(depths) // ncol)
    h, w = depths[0].shape
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol + 1.0, nrow * (4.2 * h / w + 0.45) + 0.5),
                             squeeze=False, layout="constrained")
    colours = plt.get_cmap(cmap).with_extremes(bad="white")
    image = None
    for ax, depth, label in zip(axes.flat, depths, labels):
        image = ax.imshow(np.ma.masked_invalid(depth), cmap=colours, vmin=lo, vmax=hi,
                          interpolation="nearest")
        seen = np.isfinite(depth)
        ax.set_title(f"{label}: {100 * seen.mean():.1f} % of pixels hit", fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
        for side in ax.spines.values():
            side.set_color("0.6")
    for ax in axes.flat[len(depths):]:
        ax.set_visible(False)
    bar = fig.colorbar(image, ax=axes.ravel().tolist(), shrink=0.9, aspect=30)
    bar.set_label("depth (m, along the camera axis)", fontsize=8)
    bar.ax.tick_params(labelsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def plot_row_sessions(path, sessions, titles, box=None, title="") -> Path:
    """Side view (along the row, x-z) and top view (x-y) of every session of a row, one column per
    session, in the plant-box frame when ``box`` is given; colour = height."""
    sessions = [np.asarray(s).reshape(-1, 3) for s in sessions]
    local = [box.to_local(s) if box is not None else s for s in sessions]
    allpts = np.concatenate(local)
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    span = np.maximum(hi - lo, 0.2)
    inch_per_m = 3.2 / span[0]  # each column is 3.2 inches wide; keep the views to scale
    fig, axes = plt.subplots(2, len(local), figsize=(3.2 * len(local), inch_per_m * (span[2] + span[1]) + 1.6),
                             squeeze=False, gridspec_kw={"height_ratios": [span[2], span[1]]})
    for k, (points, label) in enumerate(zip(local, titles)):
        (points,) = _subsample(points, limit=20000)
        for row, (j, name) in enumerate(((2, "z"), (1, "y"))):
            ax = axes[row, k]
            ax.scatter(points[:, 0], points[:, j], s=0.2, c=points[:, 2], cmap="viridis",
                       vmin=lo[2], vmax=hi[2], linewidths=0)
            ax.set_xlim(lo[0], hi[0])
            ax.set_ylim(lo[j], hi[j])
            ax.set_aspect("equal")
            ax.tick_params(labelsize=6)
            if row == 1:
                ax.set_xlabel("x along the row (m)", fontsize=7)
            if k == 0:
                ax.set_ylabel(f"{name} (m)", fontsize=7)
        axes[0, k].set_title(label, fontsize=7)
    fig.suptitle(title, fontsize=9)
    return _save(fig, path)
