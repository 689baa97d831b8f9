"""The per-case miss model's calibration figure (:mod:`tpvp.setcover.miss_model`): per case, the
true coverage against the coverage the plan predicted, with the predicted lower bound."""

from __future__ import annotations

import numpy as np

from tpvp.viz.figures import _save, plt


def plot_predicted_coverage(path, rows, asked: float = 0.98, tolerance: float = 0.01, title: str = ""):
    """``rows``: one per plan with ``view_space``, ``predicted``, ``lower`` and ``coverage`` (true),
    fractions, and optionally the ``rule`` that set its planning target. One panel per view space
    (columns) and rule (rows): each case a dot at (predicted, true) with a bar down to its
    lower bound; the diagonal, the asked coverage and ``asked - tolerance`` as lines; cases below
    their bound in red."""
    rules = list(dict.fromkeys(rows["rule"])) if "rule" in rows else [None]
    spaces = list(dict.fromkeys(rows["view_space"]))
    fig, axes = plt.subplots(len(rules), len(spaces), figsize=(4.8 * len(spaces), 4.4 * len(rules)), squeeze=False)
    values = 100 * np.concatenate([rows[c].to_numpy(float) for c in ("predicted", "lower", "coverage")])
    low, high = np.nanmin(values) - 0.3, min(np.nanmax(values) + 0.3, 100.2)
    for (rule, space), ax in zip([(r, s) for r in rules for s in spaces], axes.ravel()):
        chosen = rows["view_space"] == space
        if rule is not None:
            chosen &= rows["rule"] == rule
        cases = rows[chosen]
        predicted, lower, true = (100 * cases[c].to_numpy(float) for c in ("predicted", "lower", "coverage"))
        below = true < lower
        ax.vlines(predicted, lower, predicted, colors="0.75", linewidth=1, label="predicted lower bound")
        ax.scatter(predicted[~below], true[~below], s=14, color="tab:blue", label="case: true above its bound")
        ax.scatter(predicted[below], true[below], s=18, color="tab:red", label="case: true below its bound")
        ax.plot([low, high], [low, high], color="0.4", linewidth=0.8, label="true = predicted")
        ax.axhline(100 * asked, color="tab:green", linewidth=0.8, linestyle="--", label=f"asked {100 * asked:g} %")
        ax.axhline(100 * (asked - tolerance), color="tab:orange", linewidth=0.8, linestyle=":",
                   label=f"{100 * (asked - tolerance):g} %")
        ax.set_xlim(low, high)
        ax.set_ylim(low, high)
        ax.set_xlabel("predicted true coverage (%)")
        ax.set_ylabel("true coverage (%)")
        name = space if rule is None else f"{space}, {rule} rule"
        ax.set_title(f"{name}: {len(cases)} cases, {int(below.sum())} below their bound", fontsize=10)
    axes[0][0].legend(fontsize=7, loc="lower right")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)
