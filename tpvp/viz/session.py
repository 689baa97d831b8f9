"""Figures of a real session (``tpvp session``, notebook ``10_real_session``): its state after each
step, today's model against a reference scan, and the workflow diagram of docs/session.md.

Plain functions over point arrays (world frame, metres), drawn offscreen (Agg) and written as PNG
like every ``plot_*`` function of :mod:`tpvp.viz.figures`. :func:`session_state` gathers the arrays
from a :class:`tpvp.session.Session`; nothing here writes into a session folder.

``python -m tpvp.viz.session [PNG]`` redraws the workflow diagram (default:
``docs/images/session_workflow.png``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from tpvp.viz.figures import _equal_axes, _save, _subsample, plt

__all__ = ["model_agreement", "plot_model_comparison", "plot_session_state", "plot_session_workflow",
           "request_row", "session_state"]

_CAPTURE_COLOURS = plt.get_cmap("tab10").colors


def session_state(session) -> dict:
    """What :func:`plot_session_state` draws of ``session``, in the world frame (the previous
    model's, metres): ``previous`` (N, 3), ``candidates`` (V, 3) camera positions, ``captures`` (one
    (M, 3) array of voxel centres per capture, in order) and ``capture_views`` (their views)."""
    scene = session.scene
    return {"previous": np.asarray(session.previous_scan, dtype=np.float64),
            "candidates": scene.to_scan(scene.view_space.positions),
            "captures": [scene.to_scan(points) for _, points in session.observations()],
            "capture_views": [int(view) for view, _ in session.observations()]}


def request_row(request) -> dict:
    """A :class:`tpvp.session.Request` as a table row: view, role, position, look-at point and
    quaternion (camera-to-world, x y z w, OpenCV camera axes), world frame, metres."""
    row = {"view": request.view, "role": request.role}
    if request.view is None:
        return row
    for name, values, axes in (("", request.position, "xyz"), ("look_", request.look_at, "xyz"),
                               ("q", request.quaternion, "xyzw")):
        row.update({f"{name}{axis}": float(value) for axis, value in zip(axes, values)})
    return row


def _legend(ax, **keywords):
    legend = ax.legend(fontsize=7, markerscale=1.5, **keywords)
    for handle in legend.legend_handles:
        handle.set_alpha(1.0)


def plot_session_state(path, previous, candidates, captures=(), capture_views=(), requested=None,
                       requested_label: str = "requested view", title: str = "") -> Path:
    """A session after a step, two 3D panels in the world frame. Left, the whole set-up: the
    previous model (grey), the candidate camera positions (numbered), the views captured so far
    (coloured squares, one colour per capture) and the requested pose (red star and its viewing
    ray to the look-at point). Right, the plant close up: the previous model (light grey) and every
    capture fused so far (voxel centres, same colours).

    ``requested``: None or ``(position, look_at)`` (3-vectors); ``capture_views``: the candidate
    index of each capture (``captures``: one (M, 3) array each). A voxel centre is coloured by the
    first capture that holds it (the legend counts each capture's voxels and the new ones)."""
    previous = np.asarray(previous, dtype=np.float64).reshape(-1, 3)
    candidates = np.asarray(candidates, dtype=np.float64).reshape(-1, 3)
    captures = [np.asarray(c, dtype=np.float64).reshape(-1, 3) for c in captures]
    capture_views = [int(v) for v in capture_views]
    if len(capture_views) != len(captures):
        raise ValueError(f"{len(captures)} captures but {len(capture_views)} capture views")
    fig = plt.figure(figsize=(13, 6))
    whole = fig.add_subplot(1, 2, 1, projection="3d")
    close = fig.add_subplot(1, 2, 2, projection="3d")
    (shown,) = _subsample(previous, limit=8000)
    whole.scatter(*shown.T, s=0.5, c="0.45", alpha=0.6, linewidths=0, label=f"previous model ({len(previous):,} points)")
    whole.scatter(*candidates.T, s=10, c="lightgrey", edgecolors="0.5", linewidths=0.3, label="candidate views")
    for index, position in enumerate(candidates):
        whole.text(*position, f" {index}", fontsize=6, color="0.4")
    extent = [candidates, previous]
    (faint,) = _subsample(previous, limit=15000)
    close.scatter(*faint.T, s=0.4, c="0.75", alpha=0.35, linewidths=0, label="previous model")
    seen = set()
    for number, (points, view) in enumerate(zip(captures, capture_views), start=1):
        colour = _CAPTURE_COLOURS[(number - 1) % len(_CAPTURE_COLOURS)]
        rows = [tuple(p) for p in points]
        new = np.array([row not in seen for row in rows], dtype=bool)
        seen.update(rows)
        label = f"capture {number}: view {view} ({len(points):,} voxels, {int(new.sum()):,} new)"
        whole.scatter(*candidates[view], s=45, color=colour, marker="s", edgecolors="black", linewidths=0.5, label=label)
        (shown,) = _subsample(points[new], limit=10000)
        close.scatter(*shown.T, s=2.0, color=colour, alpha=0.85, linewidths=0, depthshade=False, label=label)
    if requested is not None:
        position, look_at = (np.asarray(p, dtype=np.float64).reshape(3) for p in requested)
        whole.scatter(*position, s=160, c="red", marker="*", edgecolors="darkred", linewidths=0.5, label=requested_label)
        whole.plot(*np.stack([position, look_at]).T, c="red", lw=1.2, ls="--")
        extent.append(position[None])
    _equal_axes(whole, np.concatenate(extent))
    _equal_axes(close, np.concatenate([previous, *captures]) if len(previous) or captures else candidates)
    for ax in (whole, close):
        ax.tick_params(labelsize=6)
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.label.set_size(7)
    whole.set_title("the set-up: candidate views 0.4 m around the plant", fontsize=9)
    close.set_title(f"the plant: {len(captures)} capture(s) fused" if captures else "the plant: nothing captured yet",
                    fontsize=9)
    _legend(whole, loc="upper left")
    if captures:
        _legend(close, loc="upper left")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def model_agreement(model, reference, tolerance: float) -> dict:
    """How well ``model`` (e.g. today's exported voxel centres) matches ``reference`` (e.g.
    today's full scan), both (N, 3) in the same frame: ``completeness`` (the share of reference
    points within ``tolerance`` of the model), ``accuracy`` (the share of model points within
    ``tolerance`` of the reference) and the median nearest distances both ways (in millimetres:
    the points are in metres)."""
    from scipy.spatial import cKDTree

    model = np.asarray(model, dtype=np.float64).reshape(-1, 3)
    reference = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    to_model, _ = cKDTree(model).query(reference)
    to_reference, _ = cKDTree(reference).query(model)
    return {"model points": len(model), "reference points": len(reference), "tolerance (mm)": 1e3 * float(tolerance),
            "completeness": float(np.mean(to_model <= tolerance)),
            "accuracy": float(np.mean(to_reference <= tolerance)),
            "median reference -> model (mm)": 1e3 * float(np.median(to_model)),
            "median model -> reference (mm)": 1e3 * float(np.median(to_reference))}


def plot_model_comparison(path, model, reference, previous=None, tolerance: float | None = None,
                          names=("today's model", "today's scan", "previous model"), title: str = "") -> Path:
    """Today's model against a reference scan, side view (x-z) above and top view (x-y) below:
    the previous model (when given), the reference, and the model over the reference (grey) with
    the reference points farther than ``tolerance`` from the model in red (what the model misses)."""
    model = np.asarray(model, dtype=np.float64).reshape(-1, 3)
    reference = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    panels = [] if previous is None else [(np.asarray(previous, dtype=np.float64).reshape(-1, 3), names[2])]
    panels += [(reference, names[1]), (model, names[0])]
    missed = np.zeros(len(reference), dtype=bool)
    if tolerance is not None:
        from scipy.spatial import cKDTree

        missed = cKDTree(model).query(reference)[0] > tolerance
    fig, axes = plt.subplots(2, len(panels), figsize=(4.2 * len(panels), 6.4), squeeze=False,
                             gridspec_kw={"height_ratios": [1.2, 1]})
    for row, (pair, labels) in enumerate((((0, 2), ("x (m)", "z (m)")), ((0, 1), ("x (m)", "y (m)")))):
        for column, (points, name) in enumerate(panels):
            ax = axes[row, column]
            last = column == len(panels) - 1
            if last:
                (grey,) = _subsample(reference, limit=15000)
                ax.scatter(grey[:, pair[0]], grey[:, pair[1]], s=0.3, color="0.8", linewidths=0, label=names[1])
            (shown,) = _subsample(points, limit=15000)
            ax.scatter(shown[:, pair[0]], shown[:, pair[1]], s=0.6 if last else 0.3, c=shown[:, 2], cmap="viridis",
                       linewidths=0, label=f"{name} ({len(points):,} points)" if last else None)
            if last and missed.any():
                (red,) = _subsample(reference[missed], limit=5000)
                ax.scatter(red[:, pair[0]], red[:, pair[1]], s=1.0, color="red", linewidths=0,
                           label=f"{names[1]} farther than {1000 * tolerance:.2g} mm ({int(missed.sum()):,})")
            ax.set_aspect("equal", adjustable="datalim")
            ax.set_xlabel(labels[0], fontsize=8)
            ax.set_ylabel(labels[1], fontsize=8)
            ax.tick_params(labelsize=7)
            if row == 0:
                ax.set_title(f"{name}: {len(points):,} points" if not last else f"{name} over {names[1]}", fontsize=8)
        if row == 0:
            legend = axes[0, -1].legend(loc="upper right", fontsize=6, markerscale=8)
            for handle in legend.legend_handles:
                handle.set_alpha(1.0)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


#: The workflow's steps: (command, what it does, what it writes).
WORKFLOW = (
    ("tpvp session start\n--previous model.ply", "world frame = the previous\nmodel's; candidate views",
     "session.json, config.yaml,\nprevious.npy"),
    ("tpvp session add\n(initial view)", "a cloud or a depth image\nat the requested pose", "captures/000.npy"),
    ("tpvp session add\n(warm-up NBV)", "the view that sees the\nmost unknown space", "captures/001.npy"),
    ("tpvp session plan", "registration, inflation,\nset cover, shortest path", "plan/ (plan.csv in the\nworld frame)"),
    ("tpvp session add\n(planned views)", "one capture per planned\nview, in the path's order", "captures/002.npy ..."),
    ("tpvp session export\n--model today.ply", "today's fused model\n(world frame)", "today.ply"),
)


def plot_session_workflow(path, title: str = "A real session, step by step") -> Path:
    """The session workflow as a diagram: start, add (initial view, warm-up NBV), plan, add (the
    planned views), export, and the exported model as the next session's ``--previous``. Each box
    names the command, what it does and what it writes."""
    from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

    fig, ax = plt.subplots(figsize=(13.5, 4.8))
    ax.set_xlim(0, 13.5)
    ax.set_ylim(0, 4.8)
    ax.axis("off")
    width, height, gap, top = 1.85, 1.55, 0.4, 2.45
    colours = ("#dbe9f6", "#e6f4e1", "#e6f4e1", "#fde9d2", "#e6f4e1", "#efe3f4")
    centres = []
    for k, ((command, does, writes), colour) in enumerate(zip(WORKFLOW, colours)):
        x = 0.25 + k * (width + gap)
        ax.add_patch(FancyBboxPatch((x, top), width, height, boxstyle="round,pad=0.04,rounding_size=0.12",
                                    facecolor=colour, edgecolor="0.3", linewidth=1))
        ax.text(x + width / 2, top + height - 0.12, command, ha="center", va="top", fontsize=8.2,
                fontweight="bold", family="monospace")
        ax.text(x + width / 2, top + 0.52, does, ha="center", va="center", fontsize=7.6)
        ax.text(x + width / 2, top - 0.14, writes, ha="center", va="top", fontsize=7, color="0.3", style="italic")
        centres.append((x, x + width))
        if k:
            ax.add_patch(FancyArrowPatch((centres[k - 1][1] + 0.02, top + height / 2), (x - 0.02, top + height / 2),
                                         arrowstyle="-|>", mutation_scale=12, color="0.2", lw=1.2))
    # the session asks for each pose: 'add' repeats until the warm-up / the plan is done
    for k in (2, 4):
        x0, x1 = centres[k]
        ax.add_patch(FancyArrowPatch((x1 - 0.35, top + height + 0.05), (x0 + 0.35, top + height + 0.05),
                                     connectionstyle="arc3,rad=0.45", arrowstyle="-|>", mutation_scale=10,
                                     color="tab:green", lw=1))
    ax.text(centres[2][0] + width / 2, top + height + 0.42, "until the warm-up is done", ha="center", fontsize=7,
            color="tab:green")
    ax.text(centres[4][0] + width / 2, top + height + 0.42, "until every planned view is captured", ha="center",
            fontsize=7, color="tab:green")
    # the loop: today's model is the next session's previous model
    y = 0.55
    start, end = centres[-1][0] + width / 2, centres[0][0] + width / 2
    ax.add_patch(FancyArrowPatch((start, top - 0.62), (start, y), arrowstyle="-", color="tab:purple", lw=1.4))
    ax.add_patch(FancyArrowPatch((start, y), (end, y), arrowstyle="-", color="tab:purple", lw=1.4))
    ax.add_patch(FancyArrowPatch((end, y), (end, top - 0.62), arrowstyle="-|>", mutation_scale=12,
                                 color="tab:purple", lw=1.4))
    ax.text((start + end) / 2, y + 0.12, "days later: the next session starts with --previous today.ply "
            "(the same world frame)", ha="center", va="bottom", fontsize=8.5, color="tab:purple")
    ax.text(6.75, 0.12, "every step publishes the session folder whole: a crash or Ctrl-C leaves it as the last "
            "finished step left it", ha="center", fontsize=7.5, color="0.35")
    if title:
        ax.text(6.75, 4.75, title, ha="center", va="top", fontsize=11, fontweight="bold")
    return _save(fig, path)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    target = Path(argv[0]) if argv else Path(__file__).resolve().parents[2] / "docs" / "images" / "session_workflow.png"
    plot_session_workflow(target)
    return 0


if __name__ == "__main__":
    sys.exit(main())
