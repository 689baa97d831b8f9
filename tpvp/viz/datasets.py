"""Figures and tables of prepared datasets (notebook ``09_prepare_datasets``), and a way to show a
command line with its output in a notebook.

The figures are drawn offscreen (Agg) and written as PNG, like every ``plot_*`` function of
:mod:`tpvp.viz.figures`; they take point arrays and tables, not dataset folders, so they work on
any prepared data (``python -m data_tools pheno4d prepare`` / ``greenhouse clean`` /
``prepare-session``). Nothing here imports :mod:`data_tools`.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.viz.figures import _save, _subsample, plt
from tpvp.errors import TpvpError
from tpvp.metrics.geometry import nearest_distances

__all__ = [
    "CLEANING_STEPS",
    "CommandResult",
    "alignment_residuals",
    "error_row",
    "plot_alignment_residuals",
    "plot_cleaning_steps",
    "plot_prepared_pair",
    "plot_session_preparation",
    "run_cli",
    "show_command",
]

#: Manifest columns of ``greenhouse clean`` / ``prepare-session``: points left after each step.
CLEANING_STEPS = (("points_raw", "raw"), ("points_cropped", "cropped to the plant box"),
                  ("points_supports_removed", "supports removed"),
                  ("points_outliers_removed", "outliers removed"),
                  ("points_downsampled", "downsampled (5 mm)"), ("points", "fragments removed"))


# --------------------------------------------------------------------------------------------------
# figures
# --------------------------------------------------------------------------------------------------


def _scatter(ax, points, axes=(0, 2), colour=None, size=0.3, label=None, limit=15000, **style):
    (points,) = _subsample(np.asarray(points, float).reshape(-1, 3), limit=limit)
    if colour is None:
        ax.scatter(points[:, axes[0]], points[:, axes[1]], s=size, c=points[:, 2], cmap="viridis",
                   linewidths=0, label=label, **style)
    else:
        ax.scatter(points[:, axes[0]], points[:, axes[1]], s=size, color=colour, linewidths=0, label=label, **style)


def _legend(ax):
    legend = ax.legend(loc="upper right", fontsize=7, markerscale=12, frameon=True)
    for handle in legend.legend_handles:
        handle.set_alpha(1.0)


def plot_prepared_pair(path, previous, current, normalised, ground_truth, names=("previous", "current"),
                       resolution: float | None = None, title: str = "") -> Path:
    """A prepared single-plant pair in three columns, side view (x-z) above, top view (x-y) below:
    both sessions in their shared scanner frame (previous grey, current green; metres), today's
    normalised plant (largest side fixed, centred) and its ground-truth voxel centres (colour =
    height). ``resolution``: the ground-truth voxel size (m), shown in the title."""
    previous, current, normalised, ground_truth = (np.asarray(a, float).reshape(-1, 3)
                                                   for a in (previous, current, normalised, ground_truth))
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.4), gridspec_kw={"height_ratios": [1.2, 1]})
    vox = f" ({1000 * resolution:g} mm)" if resolution else ""
    columns = (f"scanner frame: {names[0]} (grey) and {names[1]} (green)",
               f"{names[1]}, normalised ({np.ptp(normalised, axis=0).max():.2f} m largest side)",
               f"{names[1]}, ground-truth voxels{vox}: {len(ground_truth):,}")
    for row, (axes_pair, labels) in enumerate((((0, 2), ("x (m)", "z (m)")), ((0, 1), ("x (m)", "y (m)")))):
        ax = axes[row, 0]
        _scatter(ax, previous, axes_pair, colour="0.6", label=f"{names[0]} ({len(previous):,} points)")
        _scatter(ax, current, axes_pair, colour="tab:green", label=f"{names[1]} ({len(current):,} points)", alpha=0.6)
        _scatter(axes[row, 1], normalised, axes_pair)
        _scatter(axes[row, 2], ground_truth, axes_pair, size=1.2)
        for k, ax in enumerate(axes[row]):
            ax.set_aspect("equal", adjustable="datalim")
            ax.set_xlabel(labels[0], fontsize=8)
            ax.set_ylabel(labels[1], fontsize=8)
            ax.tick_params(labelsize=7)
            if row == 0:
                ax.set_title(columns[k], fontsize=8)
        if row == 0:
            _legend(axes[0, 0])
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def plot_capture_frame(path, colour, depth, positions, points, frame: int, title: str = "") -> Path:
    """One frame of a phone capture and where it was taken: its colour image, its depth image
    (metres; white: none) and the camera path seen from above over the scene's points, the frame's
    camera marked."""
    positions, points = np.asarray(positions, float).reshape(-1, 3), np.asarray(points, float).reshape(-1, 3)
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), gridspec_kw={"width_ratios": [1.3, 1.3, 1]})
    axes[0].imshow(colour)
    axes[0].set_title(f"frame {frame}: colour ({colour.shape[1]} x {colour.shape[0]})", fontsize=8)
    shown = axes[1].imshow(np.where(np.isfinite(depth), depth, np.nan), cmap="viridis")
    fig.colorbar(shown, ax=axes[1], fraction=0.04, label="depth (m)")
    axes[1].set_title(f"depth ({depth.shape[1]} x {depth.shape[0]}, {np.isfinite(depth).mean():.0%} of the "
                      f"pixels measured)", fontsize=8)
    for ax in axes[:2]:
        ax.set_xticks([])
        ax.set_yticks([])
    _scatter(axes[2], points, (0, 1), colour="tab:green", size=0.2)
    axes[2].plot(positions[:, 0], positions[:, 1], ".-", color="0.5", ms=2, lw=0.5, label=f"{len(positions)} frames")
    axes[2].plot(*positions[frame, :2], "o", color="tab:red", ms=6, label=f"frame {frame}")
    axes[2].set_aspect("equal", adjustable="datalim")
    axes[2].set_xlabel("x (m)", fontsize=8)
    axes[2].set_ylabel("y (m)", fontsize=8)
    axes[2].tick_params(labelsize=7)
    axes[2].set_title("the camera path from above", fontsize=8)
    _legend(axes[2])
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def plot_fused_capture(path, fused, colours, truth, title: str = "") -> Path:
    """A fused capture against the truth: the fused points in their colours over the truth (grey)
    from the side and from above, and the distances of each to the other (mm)."""
    fused, truth = np.asarray(fused, float).reshape(-1, 3), np.asarray(truth, float).reshape(-1, 3)
    there, back = 1000 * nearest_distances(fused, truth), 1000 * nearest_distances(truth, fused)
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    for ax, axes_pair, labels in ((axes[0], (0, 2), ("x (m)", "z (m)")), (axes[1], (0, 1), ("x (m)", "y (m)"))):
        _scatter(ax, truth, axes_pair, colour="0.75", size=0.2, label=f"truth ({len(truth):,} points)")
        keep = np.random.default_rng(0).permutation(len(fused))[:15000]
        ax.scatter(fused[keep, axes_pair[0]], fused[keep, axes_pair[1]], c=np.asarray(colours)[keep] / 255.0, s=1.0,
                   linewidths=0, label=f"fused ({len(fused):,} points)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel(labels[0], fontsize=8)
        ax.set_ylabel(labels[1], fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0].set_title("from the side", fontsize=8)
    axes[1].set_title("from above", fontsize=8)
    _legend(axes[0])
    bins = np.linspace(0, max(np.percentile(np.concatenate([there, back]), 99), 1.0), 40)
    axes[2].hist(there, bins, alpha=0.6, color="tab:blue", label=f"fused -> truth: mean {there.mean():.2f} mm")
    axes[2].hist(back, bins, alpha=0.6, color="tab:orange", label=f"truth -> fused: mean {back.mean():.2f} mm")
    axes[2].set_xlabel("distance to the nearest point of the other (mm)", fontsize=8)
    axes[2].set_ylabel("points", fontsize=8)
    axes[2].tick_params(labelsize=7)
    axes[2].set_title(f"Chamfer distance {0.5 * (there.mean() + back.mean()):.2f} mm", fontsize=8)
    axes[2].legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def _grouped_bars(ax, groups, series, ylabel: str, ncols: int, values_on_bars: bool = False) -> None:
    """One group of bars per entry of ``groups``, one bar per ``(values, label, colour)`` of
    ``series`` (NaN values draw no bar), the legend above the axes."""
    width = 0.8 / max(len(series), 1)
    x = np.arange(len(groups))
    for k, (values, label, colour) in enumerate(series):
        bars = ax.bar(x + (k - (len(series) - 1) / 2) * width, np.nan_to_num(values), width, color=colour, label=label)
        if values_on_bars:
            ax.bar_label(bars, labels=["" if np.isnan(v) else f"{v:.2f}" for v in values], fontsize=6, padding=1)
    ax.set_xticks(x, groups, fontsize=8)
    ax.set_ylabel(ylabel, fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, ncols=ncols, loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    ax.grid(axis="y", alpha=0.3)


def plot_cleaning_steps(path, manifest: pd.DataFrame, title: str = "") -> Path:
    """Points left after each cleaning step (:data:`CLEANING_STEPS`), one group of bars per session
    of a ``greenhouse clean`` / ``prepare-session`` manifest, labelled ``<site> <date>``."""
    steps = [(column, label) for column, label in CLEANING_STEPS if column in manifest]
    sessions = [f"{s} {d}" for s, d in zip(manifest["site"], manifest["date"])]
    fig, ax = plt.subplots(figsize=(max(6.0, 1.9 * len(sessions) + 2.5), 3.6))
    colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.9, len(steps)))
    _grouped_bars(ax, sessions, [(manifest[column].to_numpy(float) / 1000.0, label, colour)
                                 for (column, label), colour in zip(steps, colours)],
                  "points (thousands)", ncols=3)
    if title:
        fig.suptitle(title, fontsize=10, y=1.12)
    return _save(fig, path)


def plot_session_preparation(path, reference, scan, transform, cleaned, box=None, title: str = "") -> Path:
    """What ``prepare-session`` did to one scan, in three panels: the raw capture in its own frame
    over the reference day (top view, grey), the same capture after the alignment ``transform``
    (4x4, capture -> reference), and the cleaned model (colour = height) over the aligned capture
    (side view along the row). With ``box`` (the plant box) the aligned views are drawn in the
    plant-box frame and the box is outlined."""
    reference, scan, cleaned = (np.asarray(a, float).reshape(-1, 3) for a in (reference, scan, cleaned))
    transform = np.asarray(transform, float)
    aligned = scan @ transform[:3, :3].T + transform[:3, 3]
    local = box.to_local if box is not None else (lambda p: p)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), gridspec_kw={"width_ratios": [1, 1, 1.15]})
    panels = ((axes[0], scan, "as captured (own frame)", "tab:red"),
              (axes[1], aligned, "aligned to the reference day", "tab:blue"))
    for ax, cloud, label, colour in panels:
        _scatter(ax, local(reference), (0, 1), colour="0.7", label="reference day")
        _scatter(ax, local(cloud), (0, 1), colour=colour, label=label, alpha=0.5)
        ax.set_title(f"top view: {label}", fontsize=8)
        ax.set_ylabel("y (m)", fontsize=8)
        _legend(ax)
    ax = axes[2]
    _scatter(ax, local(aligned), (0, 2), colour="0.8", label=f"aligned capture ({len(scan):,} points)")
    _scatter(ax, local(cleaned), (0, 2), size=0.6, label=f"cleaned ({len(cleaned):,} points)")
    ax.set_title("side view: the cleaned model (colour = height) in the aligned capture", fontsize=8)
    ax.set_ylabel("z (m)", fontsize=8)
    _legend(ax)
    if box is not None:
        hx, hy, hz = box.half_extent
        axes[1].plot([-hx, hx, hx, -hx, -hx], [-hy, -hy, hy, hy, -hy], color="k", lw=0.8)
        axes[2].plot([-hx, hx, hx, -hx, -hx], [-hz, -hz, hz, hz, -hz], color="k", lw=0.8)
    frame = "plant-box frame" if box is not None else "reference frame"
    for ax in axes:
        ax.set_aspect("equal")
        ax.set_xlabel(f"x (m, {frame})" if ax is not axes[0] else "x (m, capture frame)", fontsize=8)
        ax.tick_params(labelsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def plot_alignment_residuals(path, residuals: pd.DataFrame, title: str = "") -> Path:
    """Bars of the alignment residuals (mm) of every aligned session of an
    :func:`alignment_residuals` table: the landmark fit alone, the landmarks under the final
    transform, ICP's inlier RMSE on the static structure and, when the truth is known, the error
    at the plant-box corners."""
    columns = [c for c in ("landmark fit RMSE (mm)", "landmarks after ICP RMSE (mm)", "ICP inlier RMSE (mm)",
                           "true error at box corners (mm)") if c in residuals and residuals[c].notna().any()]
    table = residuals[residuals["alignment"] != "reference day"]
    fig, ax = plt.subplots(figsize=(max(5.5, 1.8 * len(table) + 2.5), 3.4))
    colours = plt.get_cmap("tab10")(np.arange(len(columns)))
    _grouped_bars(ax, list(table["session"]), [(table[column].to_numpy(float), column.replace(" (mm)", ""), colour)
                                               for column, colour in zip(columns, colours)],
                  "mm", ncols=2, values_on_bars=True)
    if title:
        fig.suptitle(title, fontsize=10, y=1.1)
    return _save(fig, path)


# --------------------------------------------------------------------------------------------------
# tables
# --------------------------------------------------------------------------------------------------


def _date_key(date) -> str:
    return str(date).replace("-", "")


def alignment_residuals(dataset, manifest: pd.DataFrame, landmarks: dict | None = None, truth: dict | None = None,
                        box=None) -> pd.DataFrame:
    """How well every session of a greenhouse dataset is aligned to its reference day.

    ``dataset``: the folder (its ``transform_file`` of each manifest row is read). ``landmarks``:
    ``{date: (source (K, 3), target (K, 3))}`` picked pairs of the sessions that have them (e.g.
    from ``data_tools.alignment.read_landmarks``); their RMS residual under the final transform is
    reported. ``truth``: ``{date: (4, 4) reference -> capture offset}`` when the true offsets are
    known (the generated stand-in's), giving the error of the recovered transform at the corners
    of ``box`` (max over the 8, mm) and its rotation error (deg). Dates as ``YYYY-MM-DD`` or
    ``YYYYMMDD``. One row per session: alignment method, ICP fitness and inlier RMSE, the landmark
    fit's RMSE, and the residuals above (empty where not applicable).
    """
    dataset = Path(dataset)
    landmarks = {_date_key(k): v for k, v in (landmarks or {}).items() if v is not None}
    truth = {_date_key(k): np.asarray(v, float) for k, v in (truth or {}).items()}
    rows = []
    for record in manifest.to_dict("records"):
        key = _date_key(record["date"])
        transform = np.loadtxt(dataset / record["transform_file"]).reshape(4, 4)
        row = {"session": f"{record['site']} {record['date']}", "alignment": record["alignment"],
               "ICP fitness": float(record["fitness"]), "ICP inlier RMSE (mm)": 1000 * float(record["inlier_rmse_m"]),
               "landmark fit RMSE (mm)": 1000 * float(record["landmark_rmse_m"])
               if pd.notna(record.get("landmark_rmse_m")) else np.nan,
               "rotation (deg)": float(record["rotation_deg"]), "translation (m)": float(record["translation_m"])}
        if key in landmarks:
            source, target = (np.asarray(a, float) for a in landmarks[key])
            moved = source @ transform[:3, :3].T + transform[:3, 3]
            row["landmarks after ICP RMSE (mm)"] = 1000 * float(np.sqrt(((moved - target) ** 2).sum(axis=1).mean()))
        else:
            row["landmarks after ICP RMSE (mm)"] = np.nan
        if truth and box is not None:
            if key in truth:
                true = np.linalg.inv(truth[key])  # capture -> reference
                corners = box.corners()
                apply = lambda t: corners @ t[:3, :3].T + t[:3, 3]  # noqa: E731
                row["true error at box corners (mm)"] = 1000 * float(np.linalg.norm(apply(transform) - apply(true),
                                                                                       axis=1).max())
                delta = transform[:3, :3] @ true[:3, :3].T
                row["true rotation error (deg)"] = float(np.degrees(np.arccos(np.clip((np.trace(delta) - 1) / 2, -1, 1))))
            else:
                row["true error at box corners (mm)"] = row["true rotation error (deg)"] = np.nan
        rows.append(row)
    return pd.DataFrame(rows)


def error_row(situation: str, call, *args, **kwargs) -> dict:
    """Call ``call(*args, **kwargs)`` expecting one of tpvp's user errors (:class:`tpvp.errors.TpvpError`,
    which the data tools' errors all are); returns ``{"situation", "error", "message"}`` with the
    error's class name and its one-line message ("(no error)" when the call succeeded). Other
    exceptions propagate: they are bugs, not messages for a user."""
    try:
        call(*args, **kwargs)
    except TpvpError as exc:
        return {"situation": situation, "error": type(exc).__name__, "message": str(exc)}
    return {"situation": situation, "error": "(no error)", "message": ""}


# --------------------------------------------------------------------------------------------------
# command lines in a notebook
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CommandResult:
    """A command that ran: its words as shown, exit status, output and wall time."""

    shown: str  # the command line as a user types it
    cwd: str | None  # the folder it ran in (None: the current one)
    returncode: int
    stdout: str
    stderr: str
    seconds: float

    @property
    def last_line(self) -> str:
        """The last non-empty line of stderr, else of stdout (a failed command's one-line error)."""
        for text in (self.stderr, self.stdout):
            lines = [line for line in text.splitlines() if line.strip()]
            if lines:
                return lines[-1]
        return ""


def run_cli(module: str, *args, cwd=None, env: dict | None = None, timeout: float | None = None) -> CommandResult:
    """Run ``python -m <module> <args>`` (this interpreter) in ``cwd`` and capture its output;
    ``env`` entries are added to (``None`` values removed from) the current environment. Never
    raises for a non-zero exit status: the result carries it."""
    environment = dict(os.environ)
    for key, value in (env or {}).items():
        if value is None:
            environment.pop(key, None)
        else:
            environment[key] = str(value)
    words = [str(a) for a in args]
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", module, *words], cwd=cwd, env=environment, capture_output=True,
                          text=True, timeout=timeout)
    return CommandResult(shown=shlex.join(["python", "-m", module, *words]),
                         cwd=str(Path(cwd).resolve()) if cwd is not None else None, returncode=done.returncode,
                         stdout=done.stdout, stderr=done.stderr, seconds=time.perf_counter() - start)


_PROGRESS = re.compile(r"^[^|]*:\s*\d+%\|")  # a tqdm progress line ("oracle:  40%|####  | 2/5 ...")


def show_command(result: CommandResult, max_lines: int = 40) -> None:
    """Display a command and what it printed as a console block (stdout, then stderr; progress-bar
    lines dropped, at most ``max_lines`` lines; the folder it ran in written as ``.``), with its
    exit status and wall time."""
    import html

    from IPython.display import HTML, display

    lines = []
    for text in (result.stdout, result.stderr):
        lines += [line for line in (raw.split("\r")[-1] for raw in text.splitlines())
                  if line.strip() and not _PROGRESS.match(line)]
    if len(lines) > max_lines:
        lines = lines[: max_lines - 1] + [f"... ({len(lines) - max_lines + 1} more lines)"]
    body = "\n".join([f"$ {result.shown}", *lines])
    if result.cwd:
        body = body.replace(result.cwd + os.sep, "").replace(result.cwd, ".")
    display(HTML(f"<pre style=\"white-space: pre-wrap; font-family: monospace; font-size: 0.85em; background: #f6f6f6; padding: .6em; border-radius: 4px\">"
                 f"{html.escape(body)}</pre><p><em>exit status {result.returncode}, {result.seconds:.1f} s</em></p>"))
