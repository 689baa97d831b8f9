"""Figures of the learned planners (offscreen PNG): training curves and the dataset's make-up."""

from __future__ import annotations

import pandas as pd

from tpvp.viz.figures import _save, plt

_METRIC = {"ma-scvp": (("validation_recall", "recall"), ("validation_precision", "precision")),
           "pc-nbv": (("validation_spearman", "Spearman rho"), ("validation_chosen_best", "chosen view is a best one"))}


def plot_training_curves(path, histories: dict, title: str = ""):
    """Per network: train and validation loss per state over the states seen (left axis) and its
    validation metrics (right panel). ``histories``: kind -> history table of
    :func:`tpvp.learning.training.train`."""
    fig, axes = plt.subplots(len(histories), 2, figsize=(11, 3.6 * len(histories)), squeeze=False)
    for (kind, history), (loss_ax, metric_ax) in zip(histories.items(), axes):
        history = pd.DataFrame(history)
        epochs = history["epochs"]
        loss_ax.plot(epochs, history["train_loss"], marker=".", label="train (penalty included)")
        loss_ax.plot(epochs, history["validation_loss"], marker=".", label="validation")
        best = history.loc[history["validation_loss"].idxmin()]
        loss_ax.axvline(best["epochs"], color="grey", linestyle=":", label=f"kept: round {int(best['round'])}")
        loss_ax.set(xlabel="epochs (training states seen / training states)", ylabel="loss per state", title=kind)
        loss_ax.grid(alpha=0.3)
        loss_ax.legend(fontsize=8)
        for column, label in _METRIC.get(kind, ()):
            if column in history:
                metric_ax.plot(epochs, history[column], marker=".", label=label)
        metric_ax.set(xlabel="epochs", ylabel="validation metric", title=f"{kind}: validation metrics", ylim=(0, 1))
        metric_ax.grid(alpha=0.3)
        metric_ax.legend(fontsize=8)
    fig.suptitle(title or "Learned planners: training curves")
    fig.tight_layout()
    return _save(fig, path)


def plot_dataset(path, index: pd.DataFrame, title: str = ""):
    """States per state size and split, and the label-set size against the state size."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    counts = index.groupby(["size", "split"]).size().unstack(fill_value=0)
    counts.plot.bar(ax=axes[0], width=0.8)
    axes[0].set(xlabel="views in the state", ylabel="states", title="long-tail sample: states per size")
    axes[0].set_yscale("log")
    mean = index.groupby("size")["label_size"].agg(["mean", "min", "max"])
    axes[1].plot(mean.index, mean["mean"], marker="o", label="mean")
    axes[1].fill_between(mean.index, mean["min"], mean["max"], alpha=0.2, label="min-max")
    axes[1].set(xlabel="views in the state", ylabel="views in the exact minimum set cover",
                title="MA-SCVP labels")
    axes[1].grid(alpha=0.3)
    axes[1].legend(fontsize=8)
    fig.suptitle(title or "Learned planners: the generated training data")
    fig.tight_layout()
    return _save(fig, path)
