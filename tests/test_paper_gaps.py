"""Values far from the paper's, listed under each paper table with why (tpvp.viz.paper_gaps):
exactly those beyond the relative gap, each under the first explanation that covers it."""

import numpy as np
import pandas as pd

from tpvp.viz.paper_gaps import DEVIATIONS, EXPLANATIONS, RELATIVE_GAP, agreement, gap_lines, large_gaps

VALUES = {"views": ("views", "views"), "coverage": ("coverage", "coverage (%)")}


def _wide() -> pd.DataFrame:
    rng = np.random.default_rng(5)
    rows = []
    for source in ("generated", "bundled"):
        for method in ("gmc", "ours", "ma-scvp"):
            paper_views, paper_coverage = rng.uniform(5, 20), rng.uniform(80, 99)
            rows.append({"source": source, "method": method, "views_mean": paper_views * rng.uniform(0.8, 1.2),
                         "paper_views": paper_views, "coverage_mean": paper_coverage * rng.uniform(0.85, 1.15),
                         "paper_coverage": paper_coverage})
    return pd.DataFrame(rows)


def test_exactly_the_values_beyond_the_gap_are_listed():
    wide = _wide()
    gaps = large_gaps(wide, ["source", "method"], VALUES)
    expected = {(r["source"], r["method"], header) for r in wide.to_dict("records")
                for column, (theirs, header) in VALUES.items()
                if abs(r[f"{column}_mean"] - r[f"paper_{theirs}"]) > RELATIVE_GAP * abs(r[f"paper_{theirs}"])}
    assert 0 < len(expected) < 2 * len(wide)
    assert set(zip(gaps["source"], gaps["method"], gaps["value"])) == expected


def test_each_far_value_goes_under_the_first_explanation_that_covers_it():
    wide = pd.DataFrame([{"source": "bundled", "method": "gmc", "coverage_mean": 97.0, "paper_coverage": 81.9},
                         {"source": "bundled", "method": "ours", "coverage_mean": 50.0, "paper_coverage": 99.0},
                         {"source": "generated", "method": "ours", "coverage_mean": 60.0, "paper_coverage": 99.0},
                         {"source": "generated", "method": "ours", "coverage_mean": 98.0, "paper_coverage": 99.0}])
    lines = gap_lines(wide, "I", ["source", "method"], VALUES)
    gmc, generated = (next(e for e in EXPLANATIONS if e.explains("I", pd.Series(r), "coverage"))
                      for r in ({"method": "gmc", "source": "bundled"}, {"method": "ours", "source": "generated"}))
    assert lines[1] == f"- bundled, gmc coverage (%) 97.00 / 81.90: {gmc.sentence} ([why]({gmc.link}))."
    assert lines[2] == f"- generated, ours coverage (%) 60.00 / 99.00: {generated.sentence} ([why]({generated.link}))."
    assert lines[3] == "- bundled, ours coverage (%) 50.00 / 99.00: not explained yet."
    assert len(lines) == 4  # 98 against 99 is within the gap
    assert gap_lines(wide.iloc[3:], "I", ["source", "method"], VALUES) == []


def test_the_agreement_counts_the_values_near_the_papers_and_the_others_by_explanation():
    wide = pd.DataFrame([{"source": "bundled", "method": "gmc", "coverage_mean": 97.0, "paper_coverage": 81.9,
                          "views_mean": 10.0, "paper_views": np.nan},
                         {"source": "bundled", "method": "ours", "coverage_mean": 50.0, "paper_coverage": 99.0,
                          "views_mean": 10.0, "paper_views": 10.5},
                         {"source": "generated", "method": "ours", "coverage_mean": 60.0, "paper_coverage": 99.0,
                          "views_mean": np.nan, "paper_views": 9.0},
                         {"source": "generated", "method": "gmc", "coverage_mean": 98.0, "paper_coverage": 99.0,
                          "views_mean": 20.0, "paper_views": 10.0}])
    # compared: 4 coverages and 2 views (a value either side missing is not compared); far: 3 coverages, 1 views
    said = agreement(wide, "I", ["source", "method"], VALUES)
    assert said == ("Table I: 2 of 6 values within 10 % of the paper's; of the other 4, 1 explained by GMC's map "
                    f"and score, 2 explained by generated plants, 1 not explained yet ([why]({DEVIATIONS})).")
    assert agreement(wide.iloc[:0], "I", ["source", "method"], VALUES) == "Table I: the paper reports none of these values."
    assert agreement(wide.iloc[1:2].assign(coverage_mean=98.0), "I", ["source", "method"], VALUES) == \
        "Table I: 2 of 2 values within 10 % of the paper's."
