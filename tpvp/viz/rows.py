"""Figures of the greenhouse-row experiments (offscreen PNG): the coverage-path frontier of every
method, a plan's path from the top and the side, the passive sweep's fields of view and the
candidate views of the three look-at priors. Rows are drawn in the plant box's own frame (x along the row, z up)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.collections import LineCollection

from tpvp.sensor.camera import look_at_rotations
from tpvp.viz.figures import _save, _subsample, plt

_METHOD_STYLE = {"coarse": ("black", "s"), "blockwise-nbv": ("tab:blue", "^"), "prior-obb-random": ("tab:gray", "v"),
                 "prior-passive-random": ("tab:olive", "D"), "prior-transfer-random": ("tab:orange", "P"),
                 "ours": ("tab:red", "o")}


def plot_row_frontier(path, table6: pd.DataFrame, title: str = ""):
    """Coverage vs path length (and vs views) of every method of Table VI, ours and the paper's."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    for ax, (x, paper_x, label) in zip(axes, (("path_length_m_mean", "paper_path_length_m", "path length (m)"),
                                              ("views_mean", "paper_views", "views (passive included)"))):
        for method, rows in table6.groupby("method", sort=False):
            colour, marker = _METHOD_STYLE.get(method, ("tab:purple", "x"))
            rows = rows.sort_values(x)
            ax.plot(rows[x], rows["coverage_mean"], marker=marker, color=colour, label=f"{method} (ours)")
            if paper_x in rows and rows[paper_x].notna().any():
                ax.plot(rows[paper_x], rows["paper_coverage"], marker=marker, color=colour, linestyle=":",
                        markerfacecolor="none", label=f"{method} (paper)")
        ax.set_xlabel(label)
        ax.set_ylabel("coverage of the oracle set (%)")
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7, loc="lower right", ncol=2)
    fig.suptitle(title or "Greenhouse rows: coverage-effort frontier (solid: ours, dotted: the paper)")
    fig.tight_layout()
    return _save(fig, path, vector=True)


def plot_blockwise_prefix(path, curve: pd.DataFrame, table6: pd.DataFrame, paper: pd.DataFrame, title: str = ""):
    """Block-wise NBV: the coverage after every prefix of its longest run (a line per reference)
    beside the runs of their own budget (markers) and the paper's (open markers)."""
    fig, ax = plt.subplots(figsize=(7, 4.6))
    runs = table6[table6["method"] == "blockwise-nbv"]
    for colour, ((source, reference), rows) in zip(plt.rcParams["axes.prop_cycle"].by_key()["color"],
                                                  curve.groupby(["source", "reference"], sort=False)):
        label = reference if source == "generated" else source
        ax.plot(rows["views"], rows["coverage_mean"], color=colour, label=f"prefixes of one run ({label})")
        own = runs[(runs["source"] == source) & (runs["reference"] == reference)]
        ax.plot(own["views_mean"], own["coverage_mean"], "o", color=colour, label=f"one run per budget ({label})")
    published = paper[(paper["table"] == "VI") & (paper["method"] == "blockwise-nbv")]
    ax.plot(published["views_mean"], published["coverage_mean"], "s", color="black", markerfacecolor="none",
            label="paper")
    ax.set_xlabel("views")
    ax.set_ylabel("coverage of the oracle set (%)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(title or "Block-wise NBV: prefixes of one run vs a run per budget")
    fig.tight_layout()
    return _save(fig, path)


def plot_row_paths(path, box, row_points, plans: dict, title: str = ""):
    """Each plan's path from the top and the side, in the plant box frame. ``plans``: label ->
    ``(positions in execution order (n, 3), subtitle)``."""
    row_local = box.to_local(_subsample(row_points, limit=40_000)[0])
    fig, axes = plt.subplots(2, len(plans), figsize=(6.5 * len(plans), 7.5), squeeze=False)
    for column, (label, (positions, subtitle)) in enumerate(plans.items()):
        local = box.to_local(np.asarray(positions).reshape(-1, 3))
        for row, (a, b, name) in enumerate(((0, 1, "top"), (0, 2, "side"))):
            ax = axes[row, column]
            ax.scatter(row_local[:, a], row_local[:, b], s=0.2, color="tab:green", alpha=0.3)
            ax.plot(local[:, a], local[:, b], "-", color="tab:purple", linewidth=0.6)
            ax.scatter(local[:, a], local[:, b], s=4, color="tab:red", zorder=3)
            ax.set_aspect("equal")
            ax.set_xlabel("along the row (m)")
            ax.set_ylabel("across (m)" if b == 1 else "height (m)")
            ax.set_title(f"{label}, {name} view" + (f"\n{subtitle}" if row == 0 and subtitle else ""), fontsize=9)
    fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def field_of_view_footprints(room, intrinsics) -> np.ndarray:
    """Where each passive view's field of view meets the row's mid-plane (the plane through the
    plant box centre across which the row is thin): ``(views, 4, 3)`` corners in the plant box
    frame, NaN for a corner ray that never reaches the plane."""
    box = room.plant_box
    corners = np.array([[u, v] for u, v in ((0, 0), (intrinsics.width, 0), (intrinsics.width, intrinsics.height),
                                            (0, intrinsics.height))], dtype=float)
    rays = np.column_stack([(corners[:, 0] - intrinsics.cx) / intrinsics.fx,
                            (corners[:, 1] - intrinsics.cy) / intrinsics.fy, np.ones(4)])
    rotations = look_at_rotations(room.initial_positions, room.initial_look_ats)
    origins = box.to_local(room.initial_positions)
    directions = np.einsum("ij,vjk,ck->vci", box.rotation.T, rotations, rays)  # box frame, (views, 4, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = -origins[:, None, 1] / directions[..., 1]
    depth[~(depth > 0)] = np.nan
    return origins[:, None, :] + depth[..., None] * directions


def plot_passive_sweep(path, room, row_points, intrinsics, title: str = ""):
    """The passive warm start (the paper's passive-sweep figure), in the plant box frame: the plant
    box (red), the view box the cameras move in (blue), the passive views (black) and their fields
    of view (green). Top: from the aisle, each field of view where it meets the row's mid-plane.
    Bottom: from above, each field of view's horizontal extent down to that plane."""
    box, view_box = room.plant_box, room.view_box
    row_local = box.to_local(_subsample(row_points, limit=40_000)[0])
    cameras = box.to_local(room.initial_positions)
    footprints = field_of_view_footprints(room, intrinsics)
    view_corners = box.to_local(view_box.corners())
    fig, axes = plt.subplots(2, 1, figsize=(11, 10), gridspec_kw={"height_ratios": [2.6, 1.4]})
    for ax, (a, b, name) in zip(axes, ((0, 2, "from the aisle"), (0, 1, "from above"))):
        ax.scatter(row_local[:, a], row_local[:, b], s=0.2, color="tab:green", alpha=0.25)
        for corners, colour, label in ((box.to_local(box.corners()), "tab:red", "plant box"),
                                       (view_corners, "tab:blue", "view box (camera workspace)")):
            outline = _outline(corners[:, [a, b]])
            ax.fill(outline[:, 0], outline[:, 1], facecolor="none", edgecolor=colour, linewidth=1.6, label=label)
        for camera, footprint in zip(cameras, footprints):
            if b == 2:  # the footprint on the mid-plane
                ax.fill(footprint[:, 0], footprint[:, 2], color="limegreen", alpha=0.12)
                ax.plot(*np.vstack([footprint, footprint[:1]])[:, [0, 2]].T, color="forestgreen", linewidth=0.6)
            else:  # the horizontal extent: the camera to its footprint's left and right edges
                edge = footprint[:, [a, b]]
                for corner in (edge[np.nanargmin(edge[:, 0])], edge[np.nanargmax(edge[:, 0])]):
                    ax.plot([camera[a], corner[0]], [camera[b], corner[1]], color="forestgreen", linewidth=0.6)
        ax.scatter(cameras[:, a], cameras[:, b], s=30, marker="v" if b == 2 else "o", color="black", zorder=3,
                   label=f"{len(cameras)} passive views")
        ax.set_aspect("equal")
        ax.set_xlabel("along the row (m)")
        ax.set_ylabel("height (m)" if b == 2 else "across (m)")
        ax.set_title(f"{name}" + (": fields of view on the row's mid-plane" if b == 2 else ""), fontsize=10)
    axes[0].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.suptitle(title or "The passive sweep's fields of view")
    fig.tight_layout()
    return _save(fig, path, vector=True)


def _outline(points) -> np.ndarray:
    """The convex outline of 2D points, closed (a box's corners seen along an axis)."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(points)
    return points[np.append(hull.vertices, hull.vertices[0])]


def plot_prior_candidates(path, box, row_points, candidate_sets: dict, title: str = ""):
    """The look-at targets and candidate positions of each prior (side view, plant box frame);
    a line joins each candidate position to its target."""
    row_local = box.to_local(_subsample(row_points, limit=40_000)[0])
    fig, axes = plt.subplots(1, len(candidate_sets), figsize=(6 * len(candidate_sets), 3.8), squeeze=False)
    for ax, (label, candidates) in zip(axes[0], candidate_sets.items()):
        positions, look_ats = box.to_local(candidates.positions), box.to_local(candidates.look_ats)
        targets = box.to_local(candidates.targets)
        ax.scatter(row_local[:, 0], row_local[:, 2], s=0.2, color="tab:green", alpha=0.3)
        segments = np.stack([positions[:, [0, 2]], look_ats[:, [0, 2]]], axis=1)
        ax.add_collection(LineCollection(segments, colors="tab:blue", linewidths=0.2, alpha=0.3))
        ax.scatter(positions[:, 0], positions[:, 2], s=2, color="tab:blue", label="candidate positions")
        ax.scatter(targets[:, 0], targets[:, 2], s=10, color="tab:red", marker="x", label="look-at targets")
        ax.set_aspect("equal")
        ax.set_xlabel("along the row (m)")
        ax.set_ylabel("height (m)")
        ax.set_title(f"{label}: {len(targets)} targets, {len(positions)} views", fontsize=9)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_fused_clouds(path, box, truth_points, clouds: dict, slab: float = 0.4, title: str = ""):
    """Side views of fused reconstructions (e.g. noise-free, noisy without ICP, noisy with ICP)
    over the ground truth, in a ``slab`` (m) along the row at the plant box centre."""
    def cut(points):
        local = box.to_local(np.asarray(points).reshape(-1, 3))
        return local[np.abs(local[:, 0]) <= slab / 2]

    truth = cut(truth_points)
    fig, axes = plt.subplots(1, len(clouds), figsize=(4.2 * len(clouds), 5), squeeze=False)
    for ax, (label, points) in zip(axes[0], clouds.items()):
        local = cut(points)
        ax.scatter(truth[:, 0], truth[:, 2], s=0.3, color="lightgray", label="ground truth")
        ax.scatter(local[:, 0], local[:, 2], s=0.3, color="tab:red", alpha=0.5, label="fused")
        ax.set_aspect("equal")
        ax.set_xlabel("along the row (m)")
        ax.set_ylabel("height (m)")
        ax.set_title(label, fontsize=9)
    axes[0, 0].legend(fontsize=7, markerscale=10, loc="upper right")
    fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_row_scene(path, box, centres, oracle_ids, passive_ids, passive_positions, title: str = ""):
    """The ground truth of a row from the side (plant box frame): voxels no view-box position sees
    (grey), the oracle set Ω (green), the part of it the passive sweep observed (blue), and the
    passive views (black triangles). ``centres``: ground-truth voxel centres; ``oracle_ids`` and
    ``passive_ids``: indices into them."""
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    layers = np.zeros(len(centres), dtype=np.int8)
    layers[np.asarray(oracle_ids, dtype=np.int64)] = 1
    layers[np.intersect1d(np.asarray(passive_ids, dtype=np.int64), np.asarray(oracle_ids, dtype=np.int64))] = 2
    local = box.to_local(centres)
    cameras = box.to_local(np.asarray(passive_positions, dtype=float).reshape(-1, 3))
    fig, ax = plt.subplots(figsize=(12, 3.8))
    for layer, colour, label in ((0, "lightgray", "not visible from the view box"),
                                 (1, "tab:green", "oracle set Ω, missed by the passive sweep"),
                                 (2, "tab:blue", "oracle set Ω, seen by the passive sweep (Q)")):
        points = _subsample(local[layers == layer], limit=40_000)[0]
        ax.scatter(points[:, 0], points[:, 2], s=0.3, color=colour, label=f"{label}: {int((layers == layer).sum()):,}")
    ax.scatter(cameras[:, 0], cameras[:, 2], s=30, marker="v", color="black", label="passive views")
    ax.set_aspect("equal")
    ax.set_xlabel("along the row (m)")
    ax.set_ylabel("height (m)")
    legend = ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    for handle in legend.legend_handles:
        handle.set_sizes([25])
    ax.set_title(title or "The row's ground-truth voxels", fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def plot_stage_breakdown(path, stages: pd.DataFrame, paper: pd.DataFrame | None = None, title: str = ""):
    """Seconds of each planning stage of one case (horizontal bars, log scale), one bar per stage
    and covering voxel where the stage depends on it, with the paper's range (14 cores) beside it.
    ``stages``: rows ``stage``, ``cover_resolution_cm`` (NaN for stages before the covering voxel)
    and ``seconds``; ``paper``: :func:`tpvp.experiments.rows.paper_timing` (``stage``,
    ``cover_resolution_cm``, ``paper_seconds_low``/``_high``; a row without a covering voxel
    applies to every one)."""
    stages = stages.reset_index(drop=True)
    labels = [stage if pd.isna(cm) else f"{stage} @ {cm:g} cm" for stage, cm in zip(stages["stage"],
                                                                                      stages["cover_resolution_cm"])]
    y = np.arange(len(stages))[::-1]
    colours = plt.get_cmap("tab10")
    order = {stage: i for i, stage in enumerate(dict.fromkeys(stages["stage"]))}
    fig, ax = plt.subplots(figsize=(8.5, 0.42 * len(stages) + 1.4))
    ax.barh(y + 0.12, stages["seconds"].clip(lower=1e-3), 0.5,
            color=[colours(order[s] % 10) for s in stages["stage"]], label="ours (this machine)")
    for yy, seconds in zip(y, stages["seconds"]):
        ax.text(max(seconds, 1e-3) * 1.1, yy + 0.12, f"{seconds:.2f} s", va="center", fontsize=7)
    if paper is not None:
        shown = False
        for yy, stage, cm in zip(y, stages["stage"], stages["cover_resolution_cm"]):
            rows = paper[(paper["stage"] == stage) & (paper["cover_resolution_cm"].isna()
                                                      | np.isclose(paper["cover_resolution_cm"], cm))]
            if len(rows):
                low, high = float(rows["paper_seconds_low"].iloc[0]), float(rows["paper_seconds_high"].iloc[0])
                ax.plot([low, high], [yy - 0.28] * 2, color="black", linewidth=2.5, solid_capstyle="butt",
                        marker="D" if low == high else "|", markersize=5 if low == high else 9,
                        label=None if shown else "the paper (14 cores)")
                ax.text(high * 1.15, yy - 0.28, f"{low:g} s" if low == high else f"{low:g}-{high:g} s",
                        va="center", fontsize=7)
                shown = True
    ax.set_yticks(y, labels)
    ax.set_xscale("log")
    ax.set_xlabel("seconds (log scale)")
    ax.grid(alpha=0.3, axis="x")
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(title or "Where the planning time goes", fontsize=10)
    fig.tight_layout()
    return _save(fig, path, vector=True)


def plot_protocol_stages(path, timing: pd.DataFrame, paper: pd.DataFrame | None = None, title: str = ""):
    """:func:`plot_stage_breakdown` of the experiment runner's rows of Ours (one case): ``timing``
    has ``cover_resolution_cm`` and ``seconds_<stage>`` columns, one row per covering voxel. The
    stages before the covering voxel (registration, inflation, targets) are drawn once (their mean
    over the rows), visibility, selection and path once per covering voxel."""
    before = [s for s in ("registration", "inflation", "targets") if f"seconds_{s}" in timing]
    after = [s for s in ("visibility", "selection", "path") if f"seconds_{s}" in timing]
    once = [{"stage": s, "cover_resolution_cm": np.nan, "seconds": float(timing[f"seconds_{s}"].mean())}
            for s in before]
    each = [{"stage": s, "cover_resolution_cm": float(cm), "seconds": float(seconds)}
            for s in after for cm, seconds in zip(timing["cover_resolution_cm"], timing[f"seconds_{s}"])]
    stages = pd.DataFrame(once + each)
    return plot_stage_breakdown(path, stages, paper, title)
