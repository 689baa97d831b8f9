"""GMC before / after the authors' map voxel and tie rule (issue 27, item 4): coverage, path and
the picks decided by a tie at 5 / 10 / 15 / 20 views.

Run from the repository root::

    python benchmarks/gmc_gain.py                 # the quick cases of `tpvp experiments plants --quick`
    python benchmarks/gmc_gain.py --with-real     # ... plus the bundled real tomato pair
    python benchmarks/gmc_gain.py --out benchmarks/results/gmc_gain.md

Cases: :func:`tpvp.experiments.plants.default_cases` with ``quick=True`` (generated tomato and maize,
seed 0, rotation 0, initial view 17, hemisphere and sphere): the protocol of Table I on its quick
case set. Each case runs :func:`tpvp.experiments.baselines.nbv_curve` (what ``tpvp experiments
plants`` runs for ``gmc``) twice on the same scene:

* before: ``gmc.map_resolution = None`` (the warm-up's map, 32 voxels across the plant) and
  ``gmc.tie_break = lowest-index``;
* 4 mm: the authors' GMC voxel (2 x gt_resolution) in this three-state map, ties by the shortest move;
* after: the defaults (the ground-truth voxel, 1 x gt_resolution = 2 mm, ties by the shortest move).

``ties`` is the number of picks (views 2..n) at which several candidates shared the largest gain,
so the tie rule chose. Paper: Table I (tpvp/data/paper/individual_plant.csv).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

if importlib.util.find_spec("tpvp") is None:  # not installed: run from a checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
import pandas as pd

from tpvp.config_loading import make_config, with_overrides
from tpvp.experiments import plants
from tpvp.experiments.baselines import nbv_curve

BUDGETS = plants.GMC_BUDGETS
RULES = {"before": {"gmc.map_resolution": None, "gmc.tie_break": "lowest-index"},
         "4 mm": {"gmc.map_resolution": 0.004},
         "after": {}}


def run(cases, base) -> pd.DataFrame:
    rows = []
    for case in cases:
        scene = plants.case_scene(case, case.config(base))
        for rule, overrides in RULES.items():
            config = case.config(with_overrides(base, overrides))
            t = time.perf_counter()
            curve = nbv_curve(scene, config, max_views=max(BUDGETS))
            seconds = time.perf_counter() - t
            ties = np.cumsum(curve["tied"].to_numpy() > 1)
            for budget in BUDGETS:
                row = curve.iloc[budget - 1]
                rows.append({**case.labels(), "rule": rule, "budget": budget,
                             "coverage": 100 * row["coverage"], "path_m": row["path_length"],
                             "ties": int(ties[budget - 1]), "seconds": seconds,
                             "views": " ".join(str(v) for v in curve["view"][:budget])})
            print(f"{case.instance.name} {case.view_space} {rule}: {seconds:.1f} s, views "
                  f"{' '.join(str(v) for v in curve['view'])}", file=sys.stderr, flush=True)
    return pd.DataFrame(rows)


def _cell(frame, column, digits) -> str:
    return " / ".join(f"{frame.loc[frame['budget'] == b, column].mean():.{digits}f}" for b in BUDGETS)


def markdown(table: pd.DataFrame, command: str) -> str:
    paper = plants.paper_values()
    paper = paper[paper["method"] == "gmc"]
    lines = [f"Command: `{command}`", "",
             "Per case: coverage (%) / path (m) / picks decided by a tie, at 5 / 10 / 15 / 20 views.", "",
             "| view space | case | rule | coverage % | path m | tie picks |", "|---|---|---|---|---|---|"]
    for (space, name), group in table.groupby(["view_space", "instance"], sort=False):
        for rule in RULES:
            g = group[group["rule"] == rule]
            lines.append(f"| {space} | {name} | {rule} | {_cell(g, 'coverage', 2)} | {_cell(g, 'path_m', 2)} | "
                         f"{_cell(g, 'ties', 0)} |")
    lines += ["", "Mean over the cases of each view space, and the paper's Table I (GMC):", "",
              "| view space | rule | cases | coverage % | path m | tie picks |", "|---|---|---|---|---|---|"]
    for space, group in table.groupby("view_space", sort=False):
        for rule in RULES:
            g = group[group["rule"] == rule]
            lines.append(f"| {space} | {rule} | {g['instance'].nunique()} | {_cell(g, 'coverage', 2)} | "
                         f"{_cell(g, 'path_m', 2)} | {_cell(g, 'ties', 1)} |")
        p = paper[(paper["table"] == "I") & (paper["view_space"] == space)]
        if len(p):
            cov = " / ".join(f"{p.loc[p['budget'] == b, 'coverage_mean'].iloc[0]:.2f}" for b in BUDGETS)
            path = " / ".join(f"{p.loc[p['budget'] == b, 'path_mean'].iloc[0]:.2f}" for b in BUDGETS)
            lines.append(f"| {space} | paper | 12 | {cov} | {path} | – |")
    lines += ["", "Views chosen (first 20):", ""]
    last = table[table["budget"] == max(BUDGETS)]
    for row in last.itertuples():
        lines.append(f"- {row.view_space} {row.instance} {row.rule}: `{row.views}`")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--with-real", action="store_true", help="add the bundled real tomato pair")
    parser.add_argument("--out", type=Path, help="also write the markdown table here")
    args = parser.parse_args(argv)
    base = make_config("plant")
    cases = plants.default_cases(quick=True)
    if args.with_real:
        cases += plants.case_list([plants.bundled_instance()], initial_views=(17,), rotations=(0.0,))
    table = run(cases, base)
    command = "python benchmarks/gmc_gain.py" + (" --with-real" if args.with_real else "") + \
        (f" --out {args.out}" if args.out else "")
    text = markdown(table, command)
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("# GMC: the authors' map voxel and tie rule (issue 27, item 4)\n\n" + text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
