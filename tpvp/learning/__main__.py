"""``python -m tpvp.learning``: generate the training data, train both networks, evaluate them.

    python -m tpvp.learning generate --data ~/.cache/tpvp/learning/plants   # ~20 min on 2 cores
    python -m tpvp.learning train --data ~/.cache/tpvp/learning/plants --out outputs/learning
    python -m tpvp.learning evaluate --data ~/.cache/tpvp/learning/plants   # the shipped weights
    python -m tpvp.learning evaluate --executed 2   # also the two-view states (Table I's MA-SCVP)
    python -m tpvp.learning all --out outputs/learning                       # generate + train
    python -m tpvp.learning all --quick --out /tmp/learning                  # a 1-minute smoke run

``train`` writes ``<kind>.pt``, ``<kind>_history.csv``, ``training_curves.png`` and
``metrics.csv`` (test-split metrics beside the shipped weights' ones) to ``--out``; pass
``--out tpvp/data/learning`` to replace the shipped weights.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict
from pathlib import Path

from tpvp.errors import TpvpError
from tpvp.io.atomic import atomic_path
from tpvp.learning import training
from tpvp.learning.dataset import DatasetConfig, generate_dataset, load_dataset
from tpvp.learning.weights import load_weights, save_weights, shipped_path
from tpvp.viz.learning import plot_training_curves

DEFAULT_DATA = Path.home() / ".cache" / "tpvp" / "learning" / "plants"
QUICK_DATASET = dict(train_plants=4, validation_plants=2, test_plants=2, rotations=2, held_out_rotations=1)
QUICK_TRAINING = dict(states_per_round=64, max_rounds=2, patience=2)
# (states per round, rounds at most) of the shipped run: about 10 (early stop) and 24 minutes on 2 CPU cores; a
# round count, not a clock, ends training so that a retraining repeats it exactly
SCHEDULE = {"ma-scvp": (8192, 32), "pc-nbv": (4096, 18)}


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m tpvp.learning", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name in ("generate", "train", "evaluate", "all"):
        p = sub.add_parser(name)
        p.add_argument("--data", type=Path, default=None, help=f"dataset folder (default {DEFAULT_DATA}; "
                                                               f"--quick: <out>/dataset)")
        p.add_argument("--quick", action="store_true", help="a few plants and training rounds (a smoke run)")
        p.add_argument("--seed", type=int, default=0, help="dataset sampling and training seed")
        p.add_argument("--workers", type=int, default=2, help="processes for the dataset")
        p.add_argument("--kinds", nargs="+", default=["ma-scvp", "pc-nbv"], choices=["ma-scvp", "pc-nbv"])
        p.add_argument("--out", type=Path, default=Path("outputs") / "learning",
                       help="weights, curves and metrics (train/all/evaluate)")
        p.add_argument("--weights", type=Path, default=None, help="evaluate: a folder of <kind>.pt (default: shipped)")
        p.add_argument("--executed", nargs="+", type=int, default=None, metavar="N",
                       help="evaluate: also the states with N views executed, one row per N (2: the state "
                            "MA-SCVP sees in Table I, after the initial view and one NBV)")
        p.add_argument("--device", default="cpu", help="torch device for training, e.g. cuda (default cpu)")
        p.add_argument("--no-progress", action="store_true")
    return parser


def _data_folder(args) -> Path:
    if args.data is not None:
        return args.data
    return args.out / "dataset" if args.quick else DEFAULT_DATA


def generate(args) -> dict:
    config = DatasetConfig(seed=args.seed, **(QUICK_DATASET if args.quick else {}))
    manifest = generate_dataset(_data_folder(args), config, workers=args.workers, progress=not args.no_progress)
    print(f"dataset {_data_folder(args)}: {manifest['states']} states {manifest['states_per_split']} "
          f"from {manifest['plants_per_split']} plants in {manifest['seconds']:.0f} s")
    return manifest


def train(args) -> None:
    import pandas as pd

    dataset = load_dataset(_data_folder(args))
    args.out.mkdir(parents=True, exist_ok=True)
    histories, rows = {}, []
    for kind in args.kinds:
        states_per_round, rounds = SCHEDULE[kind]
        schedule = QUICK_TRAINING if args.quick else {"states_per_round": states_per_round, "max_rounds": rounds}
        config = training.TrainConfig(seed=args.seed, max_minutes=60.0, device=args.device, **schedule)
        result = training.train(kind, dataset, config, progress=not args.no_progress)
        test = training.evaluate(kind, result.model, dataset, dataset.split("test"), config)
        summary = result.summary()
        metadata = {"summary": summary, "test": test, "train_config": asdict(config),
                    "dataset": {k: dataset.manifest[k] for k in ("config", "states", "states_per_split",
                                                                 "plants_per_split", "seconds")},
                    "cloud_points": int(dataset.manifest["config"]["cloud_points"]),
                    "history": result.history.to_dict(orient="list")}
        save_weights(args.out / f"{kind}.pt", result.model, kind, metadata)
        with atomic_path(args.out / f"{kind}_history.csv") as tmp:
            result.history.to_csv(tmp, index=False)
        histories[kind] = result.history
        rows.append({"kind": kind, "weights": "trained now", **{f"test_{k}": v for k, v in test.items()},
                     "parameters": summary["parameters"], "rounds": summary["rounds"],
                     "epochs": float(result.history["epochs"].max()), "seconds": summary["seconds"]})
        if shipped_path(kind).is_file() and shipped_path(kind).resolve() != (args.out / f"{kind}.pt").resolve():
            model, _ = load_weights(shipped_path(kind), kind)
            shipped = training.evaluate(kind, model, dataset, dataset.split("test"), config)
            rows.append({"kind": kind, "weights": "shipped", **{f"test_{k}": v for k, v in shipped.items()}})
    plot_training_curves(args.out / "training_curves.png", histories)
    table = pd.DataFrame(rows)
    with atomic_path(args.out / "metrics.csv") as tmp:
        table.to_csv(tmp, index=False)
    print(table.to_string(index=False))


def evaluate(args) -> None:
    import numpy as np
    import pandas as pd

    dataset = load_dataset(_data_folder(args))
    rows = []
    for kind in args.kinds:
        path = args.weights / f"{kind}.pt" if args.weights else shipped_path(kind)
        model, _ = load_weights(path, kind)
        for split in ("validation", "test"):
            states = dataset.split(split)
            executed = dataset["states"][states].sum(axis=1)
            for count in [None, *(args.executed or [])]:
                chosen = states if count is None else states[executed == count]
                if len(chosen) == 0:
                    raise TpvpError(f"{dataset.folder}: no {split} state has {count} views executed "
                                    f"(it has {', '.join(map(str, np.unique(executed)))})")
                rows.append({"kind": kind, "weights": str(path), "split": split,
                             "executed": "all" if count is None else count, "states": len(chosen),
                             **training.evaluate(kind, model, dataset, chosen)})
    table = pd.DataFrame(rows)
    args.out.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out / "evaluation.csv") as tmp:
        table.to_csv(tmp, index=False)
    print(table.to_string(index=False))


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    try:
        t0 = time.perf_counter()
        if args.command in ("generate", "all"):
            generate(args)
        if args.command in ("train", "all"):
            train(args)
        if args.command == "evaluate":
            evaluate(args)
        print(f"done in {time.perf_counter() - t0:.0f} s")
    except TpvpError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
