"""Training and evaluation of the two networks on a generated dataset (docs/learning.md#training).

Losses as published: MA-SCVP's per-element binary cross-entropy summed over the batch and the 32
views, label-1 elements weighted by ``positive_weight``; PC-NBV's summed squared error of the gains
plus ``l2`` x the sum of squares of every parameter. Adam. Training runs in *rounds* of
``states_per_round`` states drawn without replacement from the training split (an epoch when it
equals the split's size); after each round the loss on the validation split decides: the best
round's weights are kept and training stops after ``patience`` rounds without improvement (or at
``max_rounds`` / ``max_minutes``). Deterministic given ``seed`` and ``threads``.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd
import torch
from scipy import stats
from tqdm.auto import tqdm

from tpvp.errors import ConfigError
from tpvp.learning.models import build_model, parameter_count

KINDS = ("ma-scvp", "pc-nbv")
THRESHOLD = 0.5


@dataclass(frozen=True)
class TrainConfig:
    """Optimiser, loss weights and the stopping rule (defaults: the values the shipped weights used)."""

    batch_size: int = 32
    learning_rate: float = 1e-3
    positive_weight: float = 2.0  # MA-SCVP's lambda (the released checkpoint's value)
    l2: float = 1e-4  # PC-NBV's weight penalty
    states_per_round: int = 8192
    max_rounds: int = 40
    patience: int = 3
    max_minutes: float = 30.0
    seed: int = 0
    threads: int = 2
    device: str = "cpu"  # "cuda" for a bigger run on a GPU; nothing needs one

    def __post_init__(self):
        for name in ("batch_size", "states_per_round", "max_rounds", "patience", "threads"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"training {name} must be a positive integer, got {value!r}")
        for name in ("learning_rate", "positive_weight", "max_minutes"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"training {name} must be > 0, got {getattr(self, name)!r}")
        try:
            torch.device(self.device)
        except (RuntimeError, TypeError):
            raise ConfigError(f"training device must be a torch device such as cpu or cuda, got {self.device!r}") \
                from None


@dataclass(frozen=True, eq=False)
class TrainingResult:
    kind: str
    model: torch.nn.Module
    history: pd.DataFrame  # one row per round: train and validation loss and metrics
    best_round: int
    seconds: float
    config: TrainConfig

    def summary(self) -> dict:
        best = self.history.loc[self.history["round"] == self.best_round].iloc[0].to_dict()
        return {"kind": self.kind, "parameters": parameter_count(self.model), "rounds": int(self.history["round"].max()),
                "best_round": self.best_round, "seconds": round(self.seconds, 1),
                "states_seen": int(self.history["states_seen"].max()),
                **{k: float(v) for k, v in best.items() if k.startswith("validation_")}}


def inputs(kind: str, dataset, rows) -> tuple[torch.Tensor, torch.Tensor]:
    """Network inputs of dataset rows: (grids as stored, float16, or clouds; view state)."""
    rows = np.sort(np.asarray(rows))
    first = dataset["grids"] if kind == "ma-scvp" else dataset["clouds"]
    return (torch.from_numpy(np.asarray(first[rows])),
            torch.from_numpy(np.asarray(dataset["states"][rows], dtype=np.float32)))


def targets(kind: str, dataset, rows) -> torch.Tensor:
    rows = np.sort(np.asarray(rows))
    name = "labels" if kind == "ma-scvp" else "gains"
    return torch.from_numpy(np.asarray(dataset[name][rows], dtype=np.float32))


def loss_sum(kind: str, model, output: torch.Tensor, target: torch.Tensor, config: TrainConfig,
             with_penalty: bool = True) -> torch.Tensor:
    """The published loss, summed over the batch."""
    if kind == "ma-scvp":
        weight = 1.0 + (config.positive_weight - 1.0) * target
        return torch.nn.functional.binary_cross_entropy_with_logits(output, target, weight=weight, reduction="sum")
    loss = ((output - target) ** 2).sum()
    if with_penalty and config.l2:
        loss = loss + config.l2 * sum((p ** 2).sum() for p in model.parameters())
    return loss


def predict(kind: str, model, first: torch.Tensor, state: torch.Tensor, batch_size: int = 64) -> np.ndarray:
    """Scores (B, 32): MA-SCVP probabilities, PC-NBV gains; the model in eval mode."""
    model.eval()
    device = next(model.parameters()).device
    out = []
    with torch.no_grad():
        for start in range(0, len(first), batch_size):
            batch = slice(start, start + batch_size)
            raw = model(first[batch].to(device).float(), state[batch].to(device))
            out.append((torch.sigmoid(raw) if kind == "ma-scvp" else raw).cpu())
    return torch.cat(out).numpy() if out else np.zeros((0, state.shape[1]), np.float32)


def view_set_metrics(probabilities: np.ndarray, labels: np.ndarray, states: np.ndarray) -> dict:
    """Recall and precision of the label sets at threshold 0.5 (executed views left out), and how
    often the predicted set equals the label exactly."""
    free = ~states.astype(bool)
    predicted = (probabilities >= THRESHOLD) & free
    labels = labels.astype(bool) & free
    hits = (predicted & labels).sum()
    return {"recall": float(hits / max(labels.sum(), 1)), "precision": float(hits / max(predicted.sum(), 1)),
            "exact_sets": float((predicted == labels).all(axis=1).mean()),
            "mean_predicted_size": float(predicted.sum(axis=1).mean()), "mean_label_size": float(labels.sum(axis=1).mean())}


def gain_metrics(predicted: np.ndarray, gains: np.ndarray, states: np.ndarray) -> dict:
    """Mean Spearman rank correlation with the true gains over the views not taken, and the true-gain
    rank (1 = best) of the view the network would choose."""
    rhos, ranks = [], []
    for p, g, s in zip(predicted, gains, states.astype(bool)):
        free = ~s
        if free.sum() < 2:
            continue
        rho = stats.spearmanr(p[free], g[free]).statistic
        rhos.append(0.0 if np.isnan(rho) else rho)
        chosen = np.flatnonzero(free)[np.argmax(p[free])]
        ranks.append(1 + int((g[free] > g[chosen]).sum()))
    ranks = np.asarray(ranks)
    return {"spearman": float(np.mean(rhos)) if rhos else float("nan"),
            "chosen_rank": float(ranks.mean()) if len(ranks) else float("nan"),
            "chosen_best": float((ranks == 1).mean()) if len(ranks) else float("nan")}


def evaluate(kind: str, model, dataset, rows, config: TrainConfig = TrainConfig()) -> dict:
    """Loss per state and the metrics of ``kind`` on dataset rows."""
    first, state = inputs(kind, dataset, rows)
    target = targets(kind, dataset, rows)
    scores = predict(kind, model, first, state)
    if kind == "ma-scvp":
        logits = torch.logit(torch.from_numpy(scores).clamp(1e-7, 1 - 1e-7))
        loss = float(loss_sum(kind, model, logits, target, config)) / max(len(rows), 1)
        return {"loss": loss, **view_set_metrics(scores, target.numpy(), state.numpy())}
    loss = float(((torch.from_numpy(scores) - target) ** 2).sum()) / max(len(rows), 1)
    return {"loss": loss, **gain_metrics(scores, target.numpy(), state.numpy())}


def train(kind: str, dataset, config: TrainConfig = TrainConfig(), spec: dict | None = None,
          progress: bool = True) -> TrainingResult:
    """Train a fresh ``kind`` network on the dataset's training split, stopping on its validation split."""
    if kind not in KINDS:
        raise ConfigError(f"unknown network {kind!r}; choose one of {', '.join(KINDS)}")
    train_rows, validation_rows = dataset.split("train"), dataset.split("validation")
    if len(train_rows) == 0 or len(validation_rows) == 0:
        raise ConfigError(f"{dataset.folder}: training needs states in both the train and the validation split")
    torch.set_num_threads(config.threads)
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    device = torch.device(config.device)
    model = build_model(kind, spec).to(device)
    optimiser = torch.optim.Adam(model.parameters(), lr=config.learning_rate)
    # Held in memory once: rounds draw from it without touching the disk.
    first, state = inputs(kind, dataset, train_rows)
    target = targets(kind, dataset, train_rows)
    history, best, best_loss, best_round, stale = [], None, np.inf, 0, 0
    t0 = time.perf_counter()
    order, cursor, seen = rng.permutation(len(train_rows)), 0, 0
    bar = tqdm(total=config.max_rounds, desc=f"training {kind}", unit="round", disable=not progress)
    for round_number in range(1, config.max_rounds + 1):
        model.train()
        total, count = 0.0, 0
        while count < config.states_per_round:
            if cursor >= len(order):
                order, cursor = rng.permutation(len(train_rows)), 0
            batch = order[cursor:cursor + min(config.batch_size, config.states_per_round - count)]
            cursor += len(batch)
            optimiser.zero_grad()
            output = model(first[batch].to(device).float(), state[batch].to(device))
            loss = loss_sum(kind, model, output, target[batch].to(device), config)
            loss.backward()
            optimiser.step()
            total += float(loss.detach())
            count += len(batch)
        seen += count
        validation = evaluate(kind, model, dataset, validation_rows, config)
        history.append({"round": round_number, "states_seen": seen, "epochs": seen / len(train_rows),
                        "train_loss": total / count, **{f"validation_{k}": v for k, v in validation.items()},
                        "seconds": time.perf_counter() - t0})
        bar.update(1)
        bar.set_postfix(train=f"{total / count:.3f}", validation=f"{validation['loss']:.3f}")
        if validation["loss"] < best_loss:
            best, best_loss, best_round, stale = copy.deepcopy(model.state_dict()), validation["loss"], round_number, 0
        else:
            stale += 1
        if stale >= config.patience or time.perf_counter() - t0 > 60 * config.max_minutes:
            break
    bar.close()
    model.load_state_dict(best)
    model.cpu().eval()
    return TrainingResult(kind, model, pd.DataFrame(history), best_round, time.perf_counter() - t0, config)
