"""Offscreen matplotlib figures: the plan in 3D and the covered / uncovered surface."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: figures are only ever written to files
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from tpvp.io.atomic import atomic_path  # noqa: E402

_MAX_POINTS = 30000  # matplotlib 3D scatter gets slow beyond this; subsample deterministically


def _subsample(points, *arrays, limit=_MAX_POINTS):
    points = np.asarray(points)
    if len(points) <= limit:
        return (points, *arrays)
    keep = np.random.default_rng(0).choice(len(points), limit, replace=False)
    return (points[keep], *(np.asarray(a)[keep] for a in arrays))


def _equal_axes(ax, points):
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        setter(c - half, c + half)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")


def _save(fig, path) -> Path:
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=130, bbox_inches="tight", format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    return path


def plot_plan(path, plant_points, candidates, executed, selected, path_polyline, title="") -> Path:
    """Plant, candidate views (grey), executed warm-up views (black), selected views (numbered in
    execution order) and the global path (purple)."""
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    (plant,) = _subsample(plant_points)
    ax.scatter(*plant.T, s=0.3, c=plant[:, 2], cmap="viridis", alpha=0.5, linewidths=0)
    candidates = np.asarray(candidates).reshape(-1, 3)
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
    _equal_axes(ax, np.concatenate([candidates, plant]))
    ax.legend(loc="upper left", fontsize=7)
    ax.set_title(title, fontsize=9)
    return _save(fig, path)


def plot_coverage(path, voxel_centres, covered, observable, title="") -> Path:
    """Ground-truth voxels: covered (blue), observable but missed (red), never observable (grey)."""
    voxel_centres, covered, observable = _subsample(voxel_centres, covered, observable)
    fig = plt.figure(figsize=(11, 5))
    for k, (elev, azim) in enumerate(((20, -60), (-25, 120))):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        for mask, colour, label in ((~observable, "lightgrey", "not observable"),
                                    (covered & observable, "tab:blue", "covered"),
                                    (~covered & observable, "tab:red", "missed")):
            if mask.any():
                ax.scatter(*voxel_centres[mask].T, s=1.5 if colour != "tab:red" else 4, c=colour,
                           label=f"{label} ({mask.sum()})", linewidths=0)
        _equal_axes(ax, voxel_centres)
        ax.view_init(elev=elev, azim=azim)
        if k == 0:
            ax.legend(loc="upper left", fontsize=7, markerscale=4)
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
