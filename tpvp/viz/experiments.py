"""Figures of the experiments (offscreen PNG): the coverage-effort trade-off, per-species bars and
the comparison of GMC, Ours and the exact optimum on one case."""

from __future__ import annotations

import numpy as np
import pandas as pd

from matplotlib.ticker import MaxNLocator

from tpvp.viz.figures import _equal_axes, _save, _subsample, plt

_STYLE = {"ours": ("tab:red", "o"), "ours-no-inflation": ("tab:orange", "s"), "initial-view-only": ("tab:brown", "v"),
          "initial-view-only-no-inflation": ("tab:pink", "^"), "one-shot-no-prior": ("tab:gray", "D"),
          "ma-scvp": ("tab:green", "P"), "ma-scvp-oracle": ("tab:olive", "X"), "ours-pc-nbv": ("tab:purple", "h"),
          "optimum": ("black", "*")}


def plot_coverage_effort(path, raw: pd.DataFrame, title: str = ""):
    """Coverage vs number of views and vs path length, one row of panels per view space: the GMC
    curve (mean over cases, band = std), each one-shot method's cases and mean, the exact optimum."""
    spaces = list(dict.fromkeys(raw["view_space"]))
    fig, axes = plt.subplots(len(spaces), 2, figsize=(11, 4.2 * len(spaces)), squeeze=False)
    for row, space in zip(axes, spaces):
        frame = raw[(raw["view_space"] == space) & raw["views"].notna()]
        for ax, x in zip(row, ("views", "path_length_m")):
            gmc = frame[frame["method"] == "gmc"]
            if len(gmc):
                curve = gmc.groupby("views")[["coverage", "path_length_m"]].agg(["mean", "std"])
                xs = curve.index.to_numpy(float) if x == "views" else curve[(x, "mean")].to_numpy()
                mean, std = 100 * curve[("coverage", "mean")], 100 * curve[("coverage", "std")].fillna(0)
                ax.plot(xs, mean, color="tab:blue", label="GMC (sequential NBV), mean")
                ax.fill_between(xs, mean - std, mean + std, color="tab:blue", alpha=0.15)
            groups = [(m, frame[frame["method"] == m], m) for m in _STYLE if m != "optimum"]
            if "target" in frame:
                optimum = frame[frame["method"] == "optimum"]
                groups += [("optimum", optimum[optimum["target"] == t], f"exact optimum for {100 * t:g} %")
                           for t in sorted(optimum["target"].dropna().unique(), reverse=True)]
            for method, points, label in groups:
                if points.empty:
                    continue
                colour, marker = _STYLE[method]
                if method == "optimum" and "98" in label:
                    colour = "dimgray"
                ax.scatter(points[x], 100 * points["coverage"], s=14, color=colour, marker=marker, alpha=0.35)
                ax.scatter(points[x].mean(), 100 * points["coverage"].mean(), s=90, color=colour, marker=marker,
                           edgecolor="black", label=f"{label} (mean of {len(points)})")
            ax.set_xlabel("views (initial and warm-up included)" if x == "views" else "path length (m)")
            ax.set_ylabel("coverage of the oracle set (%)")
            ax.set_title(f"{space}: coverage vs {'views' if x == 'views' else 'path length'}")
            ax.grid(alpha=0.3)
            low = np.nanpercentile(100 * frame["coverage"], 5) if len(frame) else 80
            ax.set_ylim(max(0.0, min(low, 95.0) - 2), 100.5)
        row[0].legend(fontsize=7, loc="lower right")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path, vector=True)


def plot_species_bars(path, table: pd.DataFrame, value: str = "views", title: str = ""):
    """Bars of ``<value>_mean`` (± std) per species and view space (Table II)."""
    fig, ax = plt.subplots(figsize=(6, 4))
    labels = [f"{r.species}\n{r.view_space}" for r in table.itertuples()]
    ax.bar(labels, table[f"{value}_mean"], yerr=table[f"{value}_std"], color="tab:red", alpha=0.7, capsize=4)
    ax.set_ylabel(value.replace("_", " "))
    ax.set_title(title or f"Ours: {value} per species and view space")
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return _save(fig, path, vector=True)


_COMPARISON_LABELS = {"gmc": "GMC (sequential NBV)", "ma-scvp": "MA-SCVP (learned one-shot)", "ours": "Ours (one-shot)",
                      "optimum": "exact optimum"}


def plot_method_comparison(path, scene, plans, title: str = ""):
    """The paper's comparison figure: one column per plan (``ComparedPlan``: GMC, MA-SCVP, Ours,
    optimum). Top: the plant, the candidate views (grey), the executed views numbered in
    execution order and the path. Bottom: the plant's ground-truth voxels seen from below, covered
    (blue) and observable but missed (red, drawn larger and on top)."""
    space = scene.view_space
    plant = scene.grid.countable
    centres = scene.grid.centres[plant]
    observable = np.zeros(scene.grid.size, dtype=bool)
    observable[scene.oracle] = True
    fig = plt.figure(figsize=(5.2 * len(plans), 10))
    (shown,) = _subsample(scene.current, limit=8000)
    for column, plan in enumerate(plans):
        ax = fig.add_subplot(2, len(plans), column + 1, projection="3d")
        ax.scatter(*shown.T, s=0.3, c="tab:green", alpha=0.4, linewidths=0)
        ax.scatter(*space.positions.T, s=6, c="lightgrey")
        executed = space.positions[plan.order]
        ax.scatter(*executed.T, s=36, c="tab:red", marker="^", depthshade=False)
        for i, p in enumerate(executed, start=1):
            ax.text(*p, f" {i}", fontsize=7)
        ax.plot(*plan.polyline.T, c="purple", lw=1.3)
        _equal_axes(ax, np.concatenate([space.positions, shown]))
        ax.set_title(f"{_COMPARISON_LABELS.get(plan.method, plan.method)}\n{len(plan.order)} views, "
                     f"{100 * plan.coverage:.2f} % coverage, {plan.path_length:.2f} m path\n{plan.note}", fontsize=9)
        ax.tick_params(labelsize=6)

        ax = fig.add_subplot(2, len(plans), len(plans) + column + 1, projection="3d")
        ax.computed_zorder = False
        hit = plan.covered[plant] & observable[plant]
        missed = ~plan.covered[plant] & observable[plant]
        (blue,) = _subsample(centres[hit], limit=15000)
        ax.scatter(*blue.T, s=1.5, c="tab:blue", alpha=0.45, linewidths=0, depthshade=False, zorder=1,
                   label=f"covered ({int(hit.sum())})")
        ax.scatter(*centres[missed].T, s=14, c="red", edgecolors="darkred", linewidths=0.4, depthshade=False,
                   zorder=2, label=f"missed ({int(missed.sum())})")
        _equal_axes(ax, centres)
        ax.view_init(elev=-55, azim=120)
        ax.legend(loc="upper left", fontsize=7, markerscale=2)
        ax.text2D(0.5, -0.08, "ground-truth voxels from below (elevation -55 deg)", transform=ax.transAxes,
                  ha="center", va="top", fontsize=8)
        ax.tick_params(labelsize=6)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def plot_frontier(path, frontier: pd.DataFrame, title: str = ""):
    """The coverage-effort frontier of one case (``tpvp.simulate.frontier.coverage_frontier``):
    true coverage vs views and vs path length for each planning target (labelled), beside the
    exact optimum for the same target with perfect knowledge."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, (x, x_optimum, label) in zip(axes, (("views", "optimum_views", "views (initial and warm-up included)"),
                                                ("path_length_m", "optimum_path_length_m", "path length (m)"))):
        ax.plot(frontier[x], 100 * frontier["coverage"], "o-", color="tab:red", label="Ours at a planning target")
        # targets that give the same plan share one label ("90-95"), so labels never overprint
        for (x_value, coverage), group in frontier.groupby([x, "coverage"], sort=False):
            targets = [f"{100 * t:g}" for t in group["target"]]
            text = targets[0] if len(targets) == 1 else f"{targets[0]}-{targets[-1]}"
            ax.annotate(text, (x_value, 100 * coverage), fontsize=7, textcoords="offset points", xytext=(4, -10))
        ax.plot(frontier[x_optimum], 100 * frontier["optimum_coverage"], "*--", color="black",
                label="exact optimum (perfect knowledge)")
        ax.set_xlabel(label)
        ax.set_ylabel("true coverage of the oracle set (%)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="lower right")
    fig.suptitle(f"{title}: coverage-effort frontier (labels: planning target, %)" if title
                 else "Coverage-effort frontier (labels: planning target, %)")
    fig.tight_layout()
    return _save(fig, path, vector=True)


#: What the season figure draws per session: (column of the per-session table, axis label).
SEASON_PANELS = (("coverage", "true coverage (%)"), ("views", "views"), ("chamfer_fused_mm", "fused model to truth (mm)"),
                 ("prior_missing", "today's plant the prior missed (share)"))


def plot_season(path, per_session: pd.DataFrame, title: str = ""):
    """A season session by session (``tpvp.experiments.season.tables``' per-session means): one row
    of panels (:data:`SEASON_PANELS`) per view space or room, one line per arm, dotted where the
    plans were re-planned from their captures."""
    spaces = list(dict.fromkeys(per_session["view_space"])) if "view_space" in per_session else [None]
    fig, axes = plt.subplots(len(spaces), len(SEASON_PANELS), figsize=(4 * len(SEASON_PANELS), 3.4 * len(spaces)),
                             squeeze=False)
    styles = {"truth": ("tab:blue", "o"), "own": ("tab:red", "s")}
    for row, space in zip(axes, spaces):
        frame = per_session if space is None else per_session[per_session["view_space"] == space]
        replans = frame["replan_after"] if "replan_after" in frame else pd.Series(0, index=frame.index)
        for (arm, replanned), rows in frame.assign(replan_after=replans).groupby(["arm", "replan_after"], sort=False):
            colour, marker = styles.get(arm, ("tab:grey", "^"))
            if arm == "none" and replanned:  # the none arm makes no plan: the same line twice
                continue
            label = arm + (f", re-planned every {replanned}" if replanned else "")
            for ax, (column, _) in zip(row, SEASON_PANELS):
                ax.plot(rows["session"], rows[f"{column}_mean"], marker + (":" if replanned else "-"), color=colour,
                        alpha=0.55 if replanned else 1.0, label=label)
        for ax, (_, label) in zip(row, SEASON_PANELS):
            ax.set_xlabel("session")
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
        if space is not None:
            row[0].set_title(space, loc="left", fontsize=10, fontweight="bold")
        row[0].legend(fontsize=7)
    fig.suptitle(title or "A season: each session planned from the truth or from its own last reconstruction")
    fig.tight_layout()
    return _save(fig, path, vector=True)


_MISSED = (("unseeable", "whitesmoke", "no candidate view sees it"), ("seen", "lightgrey", "seen"),
           ("missed_in_prior", "tab:red", "missed, the prior held it"),
           ("missed_not_in_prior", "tab:orange", "missed, the prior held nothing near"))


def plot_season_sessions(path, sessions, title: str = ""):
    """One plant's season, one column per session (side view, planning frame): above, the prior
    the session planned from (registered) over today's plant; below, today's plant by what became
    of it (``sessions``: (label, :meth:`tpvp.experiments.season.SeasonSession.missed`, registered
    prior) triples)."""
    fig, axes = plt.subplots(2, len(sessions), figsize=(3.2 * len(sessions), 6.4), squeeze=False)
    for column, (label, missed, prior) in enumerate(sessions):
        top, bottom = axes[0, column], axes[1, column]
        today = np.concatenate([missed[k] for k, _, _ in _MISSED])
        (shown,) = _subsample(today, limit=20000)
        top.scatter(shown[:, 0], shown[:, 2], s=0.3, color="lightgrey", label="today's plant")
        if prior is not None and len(prior):
            (shown,) = _subsample(prior, limit=20000)
            top.scatter(shown[:, 0], shown[:, 2], s=0.3, color="tab:blue", alpha=0.5, label="prior (registered)")
        top.set_title(label, fontsize=9)
        for key, colour, text in _MISSED:
            (points,) = _subsample(missed[key], limit=20000)
            size = 2.0 if key.startswith("missed") else 0.3
            bottom.scatter(points[:, 0], points[:, 2], s=size, color=colour,
                           label=f"{text} ({len(missed[key]):,})")
        bottom.legend(fontsize=6, markerscale=4, loc="upper right")
        for ax in (top, bottom):
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
    axes[0, 0].legend(fontsize=6, markerscale=8, loc="upper right")
    fig.suptitle(title or "A season session by session: what the prior held, what the plan missed")
    fig.tight_layout()
    return _save(fig, path)
