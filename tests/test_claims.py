"""Sentences that compare (tpvp.experiments.claims): each one says what its table holds, and says
the opposite when the table does."""

import numpy as np
import pandas as pd

from tpvp.experiments.claims import compare, longest_stages, ordering, ours_against_gmc


def _table1(ours_coverage: float) -> pd.DataFrame:
    gmc = [{"source": "generated", "view_space": "sphere", "method": "gmc", "budget": b, "views_mean": b,
            "coverage_mean": c, "path_length_m_mean": p} for b, c, p in ((5, 95.0, 2.0), (10, 99.1, 6.0), (15, 99.7, 8.0))]
    ours = {"source": "generated", "view_space": "sphere", "method": "ours", "budget": None, "views_mean": 9.44,
            "coverage_mean": ours_coverage, "path_length_m_mean": 3.0}
    return pd.DataFrame([*gmc, ours])


def test_gmc_is_named_at_its_first_budget_that_reaches_ours_or_not_at_all():
    said = ours_against_gmc(_table1(99.0))
    assert "Ours sees 99.00 % with 9.4 views and 3.00 m of path" in said
    assert "GMC's first budget that reaches it is 10 views (99.10 %), with 6.00 m of path (2.0x Ours')" in said
    assert "is 15 views (99.70 %), with 8.00 m of path (2.7x Ours')" in ours_against_gmc(_table1(99.5))
    assert "GMC does not reach that within its budgets (99.70 % with 15 views)" in ours_against_gmc(_table1(99.9))


def test_an_ordering_is_reproduced_only_with_the_papers_sign():
    said = ordering({"a": 0.4, "b": -1.0, "c": 0.0}, {"a": 2.0, "b": 0.5, "c": 1.0}, {"a": "A", "b": "B", "c": "C"})
    assert said == ("A: ours +0.40, the paper +2.00 (the same sign: reproduced); B: ours -1.00, the paper +0.50 "
                    "(the other sign: not reproduced); C: ours +0.00, the paper +1.00 (the other sign: not reproduced).")


def test_the_longest_stage_is_found_per_covering_voxel_with_the_shared_stages():
    stages = pd.DataFrame([("registration", np.nan, 0.85), ("inflation", np.nan, 0.1), ("visibility", 10.0, 0.08),
                           ("visibility", 5.0, 0.55), ("selection", 10.0, 0.2), ("selection", 5.0, 0.9)],
                          columns=["stage", "cover_resolution_cm", "seconds"])
    assert longest_stages(stages) == ("At 5 cm the longest stage is selection (0.90 s); at 10 cm the longest stage is "
                                      "registration (0.85 s). Across them: visibility 0.08-0.55 s, selection 0.20-0.90 s.")


def test_a_comparison_takes_its_word_from_the_values():
    assert compare("Ours", 9.44, "GMC", 10.0, "views") == "Ours 9.44 views, 0.56 fewer than GMC (10.00)"
    assert compare("Ours", 10.5, "GMC", 10.0, "views", digits=1) == "Ours 10.5 views, 0.5 more than GMC (10.0)"
    assert (compare("one-shot", 98.7, "Ours", 99.0, "coverage", " %", words=("higher", "lower"), same=0.4)
            == "one-shot 98.70 % coverage, within 0.4 % of Ours (99.00 %)")
    assert "lower than" in compare("one-shot", 98.5, "Ours", 99.0, "coverage", " %", words=("higher", "lower"), same=0.4)


def test_compare_gives_a_gap_between_percentages_in_points():
    assert (compare("Ours", 98.9, "GMC", 100.0, "coverage", " %", words=("higher", "lower"), gap_unit=" points")
            == "Ours 98.90 % coverage, 1.10 points lower than GMC (100.00 %)")
    assert (compare("Ours", 99.8, "GMC", 100.0, "coverage", " %", same=0.5, gap_unit=" points")
            == "Ours 99.80 % coverage, within 0.5 points of GMC (100.00 %)")
    assert compare("Ours", 9.0, "GMC", 10.0, "views", gap_unit=None) == compare("Ours", 9.0, "GMC", 10.0, "views")
