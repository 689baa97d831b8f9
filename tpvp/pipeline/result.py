"""What every plan holds, plants and rows alike."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True, eq=False, kw_only=True)
class PlanResult:
    """The views, their true coverage, the path and the view selection of a plan, with the stage
    times and the warnings in the user's terms. The planner leaves the coverage NaN: it has no
    ground truth (the simulation measures it). A setting's result adds its own fields
    (:class:`tpvp.pipeline.plant.CaseResult`, :class:`tpvp.pipeline.row.RowCaseResult`)."""

    n_views: int  # the views executed before the plan included
    coverage: float
    path_length: float  # m (a plant's in the planning frame)
    selection: object  # tpvp.setcover.methods.Selection
    timings: dict
    warnings: list = field(default_factory=list)

    def headline(self) -> dict:
        """The summary's first columns, the same for every setting."""
        return {"views": self.n_views, "coverage": self.coverage, "path_length_m": self.path_length}

    def selection_summary(self) -> dict:
        return {"selection_optimal": bool(self.selection.optimal), "selection_status": self.selection.status}
