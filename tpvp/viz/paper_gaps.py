"""Where our numbers are far from the paper's, and why (issue 51): the rows of a paper table whose
value differs from the paper's by more than :data:`RELATIVE_GAP` of it, each with the explanation
registered for it (:data:`EXPLANATIONS`, one sentence and a link into docs/), or said to have none
yet. The notebooks print these lines under each paper table (:func:`tpvp.viz.notebook.show_paper_table`)
and sum them up in their conclusion (:func:`agreement`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

#: A value is far from the paper's when |ours - paper| exceeds this share of |paper|.
RELATIVE_GAP = 0.10
SHOWN = 4  # far values listed per explanation


@dataclass(frozen=True)
class Explanation:
    """Why rows of paper ``tables`` differ: those whose key columns hold one of ``match``'s values
    (every key named; an empty ``match`` takes every row), for the ``values`` named (empty: any)."""

    tables: tuple
    sentence: str
    link: str
    match: dict = field(default_factory=dict)
    values: tuple = ()
    short: str = ""  # a few words for a conclusion's count


    def explains(self, table: str, row: pd.Series, value: str) -> bool:
        return (table in self.tables and (not self.values or value in self.values)
                and all(str(row.get(k)) in map(str, v) for k, v in self.match.items()))


DEVIATIONS = "../docs/deviations.md"
EXPLANATIONS = (
    Explanation(("I",), "our GMC scores views on a three-state map at the 2 mm ground-truth voxel by the unknown "
                "voxels they reach, the authors' on a 4 mm probabilistic OctoMap by entropy and frontier proximity",
                DEVIATIONS, {"method": ("gmc",)}, ("coverage",), "GMC's map and score"),
    Explanation(("I", "II"), "MA-SCVP and PC-NBV are retrained here on generated plants, with networks 23x and 30x "
                "smaller than the authors'", DEVIATIONS, {"method": ("ma-scvp", "ma-scvp-oracle")},
                short="the networks retrained here"),
    Explanation(("I", "II", "III", "IV", "text"), "these rows are generated plants, not the paper's real Pheno4D "
                "scans (a difference not measured apart from the others)", DEVIATIONS, {"source": ("generated",)},
                short="generated plants"),
    Explanation(("V", "VI"), "the paper's rows are real handheld scans; ours are generated rows, "
                "measured against what a reference of them holds (the reference column)", DEVIATIONS,
                short="generated rows and their references"),
    Explanation(("VII",), "the pose-noise study's protocol (noise model, fusion, ICP settings) is not in the paper "
                "or the authors' code; ours is stated in greenhouse.md", DEVIATIONS, short="our noise protocol"),
)


def large_gaps(wide: pd.DataFrame, keys: list, values: dict) -> pd.DataFrame:
    """One row per (table row, value) whose ours (``<column>_mean``) and the paper's
    (``paper_<paper column>``) differ by more than :data:`RELATIVE_GAP`: the keys, ``value`` (the
    header), ``ours``, ``paper``."""
    found = []
    for column, (theirs, header) in values.items():
        if f"{column}_mean" not in wide or f"paper_{theirs}" not in wide:
            continue
        for _, row in wide.iterrows():
            ours, paper = row[f"{column}_mean"], row[f"paper_{theirs}"]
            if pd.notna(ours) and pd.notna(paper) and paper != 0 and abs(ours - paper) > RELATIVE_GAP * abs(paper):
                found.append({**{k: row[k] for k in keys if k in wide}, "value": header, "column": column,
                              "ours": float(ours), "paper": float(paper)})
    return pd.DataFrame(found)


def _explanation(table: str, gap: pd.Series) -> int:
    """The index of the first explanation of a far value, len(EXPLANATIONS) when none explains it."""
    return next((i for i, e in enumerate(EXPLANATIONS) if e.explains(table, gap, gap["column"])), len(EXPLANATIONS))


def gap_lines(wide: pd.DataFrame, table: str, keys: list, values: dict) -> list[str]:
    """Markdown lines: the far values grouped by their explanation (the first that explains them),
    then those without one."""
    gaps = large_gaps(wide, keys, values)
    if gaps.empty:
        return []
    groups: dict = {}  # index of the explanation (len(EXPLANATIONS): none) -> the values it explains
    for _, gap in gaps.iterrows():
        where = ", ".join(f"{gap[k]:g}" if isinstance(gap[k], float) else str(gap[k])
                          for k in keys if k != "cases" and k in gap and pd.notna(gap[k]) and str(gap[k]) != "")
        groups.setdefault(_explanation(table, gap), []).append(f"{where} {gap['value']} {gap['ours']:.2f} / "
                                                                f"{gap['paper']:.2f}")
    lines = [f"Values more than {100 * RELATIVE_GAP:g} % from the paper's (ours / paper):"]
    for why in sorted(groups):
        said = "; ".join(groups[why][:SHOWN]) + (f" and {len(groups[why]) - SHOWN} more (the CSV)"
                                                 if len(groups[why]) > SHOWN else "")
        explanation = EXPLANATIONS[why] if why < len(EXPLANATIONS) else None
        lines.append(f"- {said}: " + (f"{explanation.sentence} ([why]({explanation.link}))." if explanation
                                      else "not explained yet."))
    return lines


def agreement(wide: pd.DataFrame, table: str, keys: list, values: dict) -> str:
    """One sentence for a conclusion: how many of the values the paper reports are within
    :data:`RELATIVE_GAP` of the paper's, and how many of the others each explanation covers."""
    compared = sum(int((wide[f"{column}_mean"].notna() & wide[f"paper_{theirs}"].notna()).sum())
                   for column, (theirs, _) in values.items() if f"{column}_mean" in wide and f"paper_{theirs}" in wide)
    if compared == 0:
        return f"Table {table}: the paper reports none of these values."
    gaps = large_gaps(wide, keys, values)
    said = f"Table {table}: {compared - len(gaps)} of {compared} values within {100 * RELATIVE_GAP:g} % of the paper's"
    if gaps.empty:
        return said + "."
    counts = gaps.apply(lambda gap: _explanation(table, gap), axis=1).value_counts().sort_index()
    parts = [f"{n} explained by {EXPLANATIONS[why].short}" if why < len(EXPLANATIONS) else f"{n} not explained yet"
             for why, n in counts.items()]
    links = {EXPLANATIONS[why].link for why in counts.index if why < len(EXPLANATIONS)}
    return (said + f"; of the other {len(gaps)}, " + ", ".join(parts)
            + "".join(f" ([why]({link}))" for link in sorted(links)) + ".")
