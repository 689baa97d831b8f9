"""The greenhouse planner's look-at targets (``targets``), light: no view space is imported with it."""

from __future__ import annotations

from dataclasses import dataclass

from tpvp.configuration_checks import check_integer


@dataclass(frozen=True)
class RowTargetsConfig:
    """Look-at targets of the greenhouse planner: ``count`` by farthest-point sampling, then each
    target takes its nearest unused candidate position, ``rounds`` times (docs/greenhouse.md)."""

    count: int = 100
    rounds: int = 8

    def __post_init__(self):
        check_integer(self, "count", minimum=1)
        check_integer(self, "rounds", minimum=1)
