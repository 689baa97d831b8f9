"""The experiments' results: the aggregated tables' helpers and the one writer of an experiment's
results folder (its raw rows, the tables its :class:`~tpvp.experiments.runner.Experiment` makes,
the paper's values, its figures, the configuration and provenance)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from tpvp.config_loading import config_yaml
from tpvp.io import atomic_write_text
from tpvp.io.publish import staged_folder
from tpvp.provenance import provenance


def mean_std(frame: pd.DataFrame, by: list, columns=("views", "coverage", "path_length_m")) -> pd.DataFrame:
    frame = frame.copy()
    for column in {"coverage", *columns}:  # coverages in percent: the whole plant's and each organ's
        if column in frame and column.startswith("coverage"):
            frame[column] = 100 * frame[column]
    grouped = frame.groupby(by, sort=False, dropna=False)
    out = grouped.size().rename("cases").to_frame()
    for column in columns:
        if column in frame:
            out[f"{column}_mean"] = grouped[column].mean()
            out[f"{column}_std"] = grouped[column].std(ddof=0)
    return out.reset_index()


def markdown(table: pd.DataFrame) -> str:
    """A Markdown table with mean ± std columns merged (in the mean column's place)."""
    if table.empty:
        return "(no rows: the methods this table needs were not run)\n"
    table = table.copy()
    for column in [c for c in table.columns if c.endswith("_mean")]:
        base = column[: -len("_mean")]
        std = table.get(f"{base}_std")
        merged = [f"{m:.2f} ± {s:.2f}" if pd.notna(m) else "" for m, s in
                  zip(table[column], std if std is not None else [np.nan] * len(table))]
        table.insert(table.columns.get_loc(column), f"{base} ", merged)  # a placeholder name while both exist
        table = table.drop(columns=[column] + ([f"{base}_std"] if std is not None else []))
        table = table.rename(columns={f"{base} ": base})
    header = "| " + " | ".join(map(str, table.columns)) + " |"
    rule = "|" + "|".join("---" for _ in table.columns) + "|"
    body = ["| " + " | ".join("" if (isinstance(v, float) and np.isnan(v)) else str(v) for v in row) + " |"
            for row in table.itertuples(index=False)]
    return "\n".join([header, rule, *body]) + "\n"



def write_results(experiment, folder, raw: pd.DataFrame, config, **options) -> dict:
    """The raw per-case table, the experiment's aggregated tables (CSV + Markdown), the paper's
    values, its figures (``options`` go to its figures hook) and the base configuration with its
    provenance, as one published folder (whole or not at all). Returns the tables by name."""
    written = {}
    with staged_folder(folder) as stage:
        atomic_write_text(stage.folder / "raw_cases.csv", raw.to_csv(index=False))
        for name, values in experiment.paper.items():
            atomic_write_text(stage.folder / f"{name}.csv", values().to_csv(index=False))
        for name, table in experiment.tables(raw).items():
            atomic_write_text(stage.folder / f"{name}.csv", table.to_csv(index=False))
            atomic_write_text(stage.folder / f"{name}.md", markdown(table))
            written[name] = table
        if experiment.figures is not None:
            experiment.figures(stage.folder, raw, written, config, **options)
        atomic_write_text(stage.folder / "config.yaml", config_yaml(config, f"base configuration of the {experiment.name}"))
        atomic_write_text(stage.folder / "provenance.json", json.dumps(provenance(config), indent=2) + "\n")
    return written
