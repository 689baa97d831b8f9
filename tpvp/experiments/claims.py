"""Sentences that compare, written from the data they compare (the notebooks' prose, issue 51): each
function evaluates the comparison on the table it is given and returns the sentence the data
support, never a fixed one."""

from __future__ import annotations

import math

import pandas as pd


def ours_against_gmc(table1: pd.DataFrame, source: str = "generated") -> str:
    """Table I (``plants.tables(...)["table1_coverage_effort"]``): per view space, Ours' mean views,
    coverage and path against GMC's first budget whose mean coverage reaches Ours' (GMC picks views
    one by one, so a budget is a prefix of its run)."""
    rows = table1[table1["source"] == source]
    parts = []
    for space in dict.fromkeys(rows["view_space"]):
        ours = rows[(rows["view_space"] == space) & (rows["method"] == "ours")].iloc[0]
        gmc = rows[(rows["view_space"] == space) & (rows["method"] == "gmc")].sort_values("budget")
        reached = gmc[gmc["coverage_mean"] >= ours["coverage_mean"]]
        said = (f"on the {space} Ours sees {ours['coverage_mean']:.2f} % with {ours['views_mean']:.1f} views and "
                f"{ours['path_length_m_mean']:.2f} m of path; ")
        if reached.empty:
            best = gmc.iloc[-1]
            said += (f"GMC does not reach that within its budgets ({best['coverage_mean']:.2f} % with "
                     f"{int(best['budget'])} views)")
        else:
            first = reached.iloc[0]
            said += (f"GMC's first budget that reaches it is {int(first['budget'])} views "
                     f"({first['coverage_mean']:.2f} %), with {first['path_length_m_mean']:.2f} m of path "
                     f"({first['path_length_m_mean'] / ours['path_length_m_mean']:.1f}x Ours')")
        parts.append(said)
    return f"{source.capitalize()} pairs: " + "; ".join(parts) + "."


def ordering(ours: dict, paper: dict, what: dict) -> str:
    """Whether each difference of ``ours`` has the sign of the ``paper``'s (keys shared), in words:
    ``what[key]`` names the difference."""
    said = []
    for key, name in what.items():
        same = math.copysign(1.0, ours[key]) == math.copysign(1.0, paper[key]) and ours[key] != 0
        said.append(f"{name}: ours {ours[key]:+.2f}, the paper {paper[key]:+.2f} "
                    f"({'the same sign: reproduced' if same else 'the other sign: not reproduced'})")
    return "; ".join(said) + "."


def longest_stage(stages: pd.DataFrame, per: str = "cover_resolution_cm") -> dict:
    """Per value of ``per`` (ascending): the stage that took longest, with the stages shared by
    every value (``per`` NaN), and its seconds."""
    shared = stages[stages[per].isna()]
    longest = {}
    for value in sorted(stages[per].dropna().unique()):
        own = pd.concat([shared, stages[stages[per] == value]])
        row = own.loc[own["seconds"].idxmax()]
        longest[value] = (row["stage"], row["seconds"])
    return longest


def longest_stages(stages: pd.DataFrame, per: str = "cover_resolution_cm") -> str:
    """``stages``: ``stage``, ``per`` (NaN for a stage shared by every value of ``per``) and
    ``seconds``. Per value of ``per``: the stage that took longest, then how the per-value stages
    range."""
    said = [f"at {value:g} {per.rsplit('_', 1)[-1]} the longest stage is {stage} ({seconds:.2f} s)"
            for value, (stage, seconds) in longest_stage(stages, per).items()]
    ranges = [f"{stage} {group['seconds'].min():.2f}-{group['seconds'].max():.2f} s"
              for stage, group in stages.dropna(subset=[per]).groupby("stage", sort=False)]
    said = "; ".join(said)
    return said[:1].upper() + said[1:] + ". Across them: " + ", ".join(ranges) + "."


def compare(first: str, a: float, second: str, b: float, quantity: str, unit: str = "", digits: int = 2,
            words: tuple = ("more", "fewer"), same: float = 0.0, gap_unit: str | None = None) -> str:
    """``first`` against ``second`` on one quantity, in the word the values support: "Ours 9.44
    views, 0.56 fewer than GMC (10.00)"; within ``same`` of each other: "within 0.5 of". The gap
    is in ``gap_unit`` (None: the values' ``unit``), e.g. ``" points"`` between two values in %."""
    gap, gap_unit = a - b, unit if gap_unit is None else gap_unit
    relation = (f"within {same:g}{gap_unit} of" if abs(gap) <= same
                else f"{abs(gap):.{digits}f}{gap_unit} {words[0] if gap > 0 else words[1]} than")
    return f"{first} {a:.{digits}f}{unit} {quantity}, {relation} {second} ({b:.{digits}f}{unit})"
