"""Every number docs/results.md and README.md quote is read back from its source (issue 47, "numbers in prose").

Design. :data:`SOURCES` partitions each page of :data:`DOCUMENTS` into regions (a section, or the lines from
one start to the next) and gives each region its list of ``(template, compute)``. A template is a piece of
the page's text with each number replaced by ``#`` (white space may break differently); it must match exactly
once in its region. ``compute()`` returns the numbers it stands for, each formatted with the rounding the
page writes (:func:`_f`: half up, as the pages round), computed from

* the shipped rows (``tpvp.experiments.shipped.shipped_rows``) through the tables the notebooks draw
  (``plants.tables``, ``rows.tables``, ``season.tables``, ``species.species_tables``),
* the benchmark outputs in ``benchmarks/results`` (which print 4 significant digits: a number written from
  one is compared with :class:`Printed`), the learning metrics in ``tpvp/data/learning``, the paper's tables
  in ``tpvp/data/paper``, ``provenance.json`` (refresh times, the machine), or
* the code that defines the protocol (``make_config``, a benchmark's constants, the Helios seeds).

A sentence that compares without a number of its own (``coverage rises monotonically ...``) is a template
without ``#`` whose compute returns nothing while the comparison holds (:func:`_claim`).

The tests fail on a number outside every region, a number of a region that no template covers, a template
found other than once, and a template whose numbers, as written, differ from its source. What no file of the
repository holds is declared, not skipped: :class:`Unsourced` with one of three reasons (:data:`NOT_KEPT`:
a run whose output no file keeps; :data:`EARLIER`: an earlier run the page tells as history; :data:`CODE_FACT`:
a property of our or the authors' code stated in words), for a number, a template or a whole region, and
:data:`UNSOURCED_AT_MOST` caps their count so that it can only shrink.

What is not a number here (:data:`IGNORED`, :data:`IGNORED_IN`, masked before the numbers are read): code
blocks and spans, link targets, dates, versions, issue numbers, a few names (3D, 4x4, cov@1), and the
README's sentence on the test suite's duration and count.
"""

from __future__ import annotations

import json
import math
import re
from functools import lru_cache
from pathlib import Path

import pandas as pd
import pytest

from tpvp.config_loading import make_config
from tpvp.experiments import plants, rows, season, shipped

ROOT = Path(__file__).resolve().parent.parent
NUMBER = r"\d+(?:,\d{3})*(?:\.\d+)?"
#: Masked before numbers are read, each for the reason given (in every document).
IGNORED = (
    (r"```.*?```", "fenced code blocks: commands and their comments"),
    (r"`[^`]*`", "code spans: paths, commands, option values, notebook names are names, not results"),
    (r"\]\([^)]*\)", "link targets: file names and anchors"),
    (r"\b\d{4}-\d{2}-\d{2}\b", "dates"),
    (r"\b\d+\.\d+\.\d+\b|\b(?:Python|ROS|Jupyter Book) \d+(?:\.\d+)?\b", "version numbers and versioned product names"),
    (r"\b[Ii]ssues? \d+(?:\.\d+)?", "issue numbers"),
    (r"\b\d+D\b|\b4x4\b|cov@1", "names: 3D, 6D, a 4x4 matrix, the measure cov@1"),
)
#: Masked in one document only.
IGNORED_IN = {
    "README.md": (
        (r"^- `make test` runs.*?(?=^- )",
         "the suite's duration and test count: measured on a busy machine and rewritten by the lead with each "
         "release of the suite, not a result of tpvp's"),
    ),
}


def _masked(text: str, document: str | None = None) -> str:
    for pattern, _why in IGNORED_IN.get(document, ()) + IGNORED:  # the document's own first: they may name code
        text = re.sub(pattern, lambda m: re.sub(r"[^\n]", " ", m.group(0)), text, flags=re.S | re.M)
    return text


def _span(document: str, region) -> tuple[int, int]:
    """Where ``region`` lies in ``document`` (character offsets): a heading (a markdown heading line; its
    section without the heading line, up to the next heading of its level or above) or ``(start, end)``:
    from the line starting with ``start`` to the line before the next one starting with ``end`` (None: the
    end of the document)."""
    lines = (ROOT / document).read_text().splitlines(keepends=True)
    offsets = [0]
    for line in lines:
        offsets.append(offsets[-1] + len(line))
    if isinstance(region, tuple):
        first = [i for i, line in enumerate(lines) if line.startswith(region[0])]
        assert len(first) == 1, (document, region)
        last = next((i for i in range(first[0] + 1, len(lines)) if region[1] and lines[i].startswith(region[1])),
                    len(lines))
        return offsets[first[0]], offsets[last]
    level = len(region) - len(region.lstrip("#"))
    start = [line.rstrip("\n") for line in lines].index(region)
    end = next((i for i in range(start + 1, len(lines)) if re.match(rf"#{{1,{level}}} ", lines[i])), len(lines))
    return offsets[start + 1], offsets[end]


def _section(document: str, region) -> str:
    start, end = _span(document, region)
    return (ROOT / document).read_text()[start:end]


class Unsourced:
    """A number no file of the repository holds: the template covers it (it is declared, with the reason)
    but nothing checks its value. As a template's compute it declares all the template's numbers; as an
    item of a compute's list, that one number; as a region's sources, every number of the region.
    :func:`test_the_unsourced_numbers_only_shrink` counts them."""

    def __init__(self, why: str):
        self.why = why

    def __call__(self):
        return self

    def __repr__(self) -> str:
        return f"unsourced ({self.why})"


#: The reasons a quoted number has no source yet (the list of what remains for issue 47).
NOT_KEPT = Unsourced("a run whose output no file of the repository keeps: a benchmark that writes no result "
                     "file, a printout, a log, or the wall-clock time of a run")
EARLIER = Unsourced("an earlier run's result that the page reports as history; replaced since, no file keeps it")
CODE_FACT = Unsourced("a property of our or the authors' code stated in words, read there, not recomputed here")


# ---------------------------------------------------------------- sources: the season (docs/results.md)
FLOOR = 0.975  # the issue's coverage floor per session: the counts below use it, the page quotes it


@lru_cache(maxsize=None)
def _season_rows() -> pd.DataFrame:
    return shipped.shipped_rows("season")


@lru_cache(maxsize=None)
def _season_totals() -> pd.DataFrame:
    return season.tables(_season_rows())["season_totals"]


def _per_season(space: str, replan: int) -> pd.DataFrame:
    """One row per plant's season: the arms' total views, path, lowest coverage and drift side by side."""
    t = _season_totals()
    t = t[(t["view_space"] == space) & (t["replan_after"] == replan)]
    return t.pivot(index="plant", columns="arm",
                   values=["total_views", "path_length_m", "lowest_coverage", "chamfer_drift_mm"])


def _season_row(space: str, replan: int) -> list[str]:
    g = _per_season(space, replan)
    views = g["total_views"]["own"] / g["total_views"]["truth"]
    low = g["lowest_coverage"]
    return [f"{low['own'].min():.2f}", f"{low['truth'].min():.2f}",
            str(int((low["own"] < FLOOR * 100).sum())), str(int((low["truth"] < FLOOR * 100).sum())),
            f"{views.mean():.2f}", f"{views.max():.2f}",
            f"{(g['total_views']['none'] / g['total_views']['truth']).mean():.2f}",
            f"{(g['path_length_m']['own'] / g['path_length_m']['truth']).mean():.2f}",
            f"{g['chamfer_drift_mm']['own'].max():.2f}"]


def _sessions(replan: int) -> pd.DataFrame:
    """Per session of the planned arms, whether ``own`` and ``truth`` fell below the floor."""
    r = _season_rows()
    r = r[(r["replan_after"] == replan) & r["method"].isin(["own", "truth"])]
    w = r.pivot_table(index=["view_space", "plant", "session"], columns="method", values="coverage")
    return w < FLOOR


def _session_misses(replan: int) -> list[str]:
    """own, n, own %, truth, n, truth %."""
    w = _sessions(replan)
    own, truth, n = int(w["own"].sum()), int(w["truth"].sum()), len(w)
    return [str(own), str(n), f"{100 * own / n:.1f}", str(truth), str(n), f"{100 * truth / n:g}"]


def _together(replan: int) -> list[int]:
    w = _sessions(replan)
    return [int((w["own"] & w["truth"]).sum()), int((w["own"] & ~w["truth"]).sum()),
            int((~w["own"] & w["truth"]).sum())]


def _seasons_below(replan: int, arm: str) -> int:
    return sum(int((_per_season(space, replan)["lowest_coverage"][arm] < FLOOR * 100).sum())
               for space in season.VIEW_SPACES)


def _n_seasons(replan: int) -> int:
    return sum(len(_per_season(space, replan)) for space in season.VIEW_SPACES)


def _one_shot_mean(column: str, arm: str, space: str | None = None, scale: float = 1.0) -> float:
    r = _season_rows()
    r = r[(r["replan_after"] == 0) & (r["method"] == arm)]
    if space is not None:
        r = r[r["view_space"] == space]
    return float(r[column].mean()) * scale


def _ratio_range(column: str, arm: str, per_season: bool) -> list[str]:
    values = []
    for space in season.VIEW_SPACES:
        for replan in season.REPLAN_AFTER:
            g = _per_season(space, replan)
            ratio = g[column][arm] / g[column]["truth"]
            values += list(ratio) if per_season else [ratio.mean()]
    return [f"{min(values):.2f}", f"{max(values):.2f}"]


def _mean_views(space: str, replan: int, arm: str) -> str:
    return f"{_per_season(space, replan)['total_views'][arm].mean():.1f}"


def _lowest(space: str, replan: int, arm: str) -> str:
    return f"{_per_season(space, replan)['lowest_coverage'][arm].min():.2f}"


def _provenance(name: str) -> dict:
    return json.loads((ROOT / "tpvp" / "data" / "results" / "provenance.json").read_text())[name]


@lru_cache(maxsize=None)
def _row_season() -> pd.DataFrame:
    r = shipped.shipped_rows("row_season")
    return r.groupby(["room", "method"]).agg(views=("views", "sum"), low=("coverage", "min"),
                                             path=("path_length_m", "sum"), missing=("prior_missing", "mean"),
                                             sessions=("session", "size"))


def _row(room: str, method: str, column: str) -> float:
    return float(_row_season().loc[(room, method), column])


def _row_drift() -> float:
    t = season.tables(shipped.shipped_rows("row_season"))["season_totals"]
    return float(t[t["arm"].isin(["own", "truth"])]["chamfer_drift_mm"].abs().max())


def _room_number(room: str) -> str:
    return room.removeprefix("room")


_TRUTH_REGISTRATION = ("registration_chamfer_mm", "truth")
def _miss_alpha() -> float:
    from tpvp.setcover.miss_model import load_miss_model

    return load_miss_model().alpha


def _season_prediction() -> dict:
    """season.tables' prediction summary of the shipped season rows, by (view space, arm)."""
    table = season.tables(shipped.shipped_rows("season"))["season_prediction"]
    return {(r.view_space, r.arm): r for r in table.itertuples()}


def _season_prediction_numbers() -> list:
    rows = _season_prediction()
    pct = lambda v: f"{100 * v:.1f}"  # noqa: E731
    holds = (all(abs(rows[("sphere", a)].below_bound - 0.05) <= 0.02 for a in ("own", "truth"))
             and all(abs(rows[("hemisphere", a)].below_bound - 0.05) > 0.02 for a in ("own", "truth"))
             and [k for k, r in rows.items() if r.mean_abs_error <= 0.005] == [("sphere", "truth")])
    return ([str(rows[("hemisphere", "own")].cases), pct(rows[("hemisphere", "own")].below_bound),
             pct(rows[("hemisphere", "truth")].below_bound), pct(rows[("sphere", "own")].below_bound),
             pct(rows[("sphere", "truth")].below_bound)]
            + [f"{100 * rows[(s, a)].mean_abs_error:.2f}" for s in ("hemisphere", "sphere") for a in ("own", "truth")]
            + _claim(holds, "the bound holds on the sphere only, the error only for the sphere's truth arm"))


def _season_session_targets() -> list:
    rows = _season_prediction().values()
    shares = [100 * r.below_97 for r in rows]
    lowest = min(rows, key=lambda r: r.coverage_min)
    return ["0.98", f"{min(shares):.1f}", f"{max(shares):.1f}", "97", f"{100 * lowest.coverage_min:.2f}"] + _claim(
        (lowest.arm, lowest.view_space) == ("own", "hemisphere"), "the lowest session is own's on the hemisphere")


_SEASON = [
    ("predicted\ntrue coverage and its # % lower bound", lambda: [f"{100 * (1 - _miss_alpha()):g}"]),
    ("Over the # sessions per view space and arm, the true coverage falls below the bound in # %\n(`own`) and # % "
     "(`truth`) of the hemisphere's sessions and in # % / # % of the sphere's, with\na mean error of # / # and # / # "
     "point", _season_prediction_numbers),
    ("bound holds on the sphere (within # points\nof # %), not on the hemisphere, and the mean error meets # point",
     lambda: ["2", "5", "0.5"]),
    ("targets at #: #-# % of them are below\n# %, and the lowest is # %", _season_session_targets),
    ("seeds #-#, six scans", lambda: [str(min(season.SEEDS)), str(max(season.SEEDS))]),
    ("# seasons x # arms, # min on # workers in its last refresh",
     lambda: [str(_n_seasons(0) + _n_seasons(1)), str(len(season.ARMS)),
              f"{_provenance('season')['refresh_minutes']:.1f}", str(shipped.PROTOCOLS["season"].workers)]),
    ("over the # plants (each season: # planned sessions at a # target)",
     lambda: [str(_season_rows()["plant"].nunique()), str(season.SESSIONS - 1), f"{season.COVERAGE_TARGET:g}"]),
    ("seasons with a session < # % (own / truth)", lambda: [f"{100 * FLOOR:g}"]),
    ("| hemisphere | no | # % | # % | # / # | #, # | # | # | # mm |", lambda: _season_row("hemisphere", 0)),
    ("| hemisphere | every view | # % | # % | # / # | #, # | # | # | # mm |", lambda: _season_row("hemisphere", 1)),
    ("| sphere | no | # % | # % | # / # | #, # | # | # | # mm |", lambda: _season_row("sphere", 0)),
    ("| sphere | every view | # % | # % | # / # | #, # | # | # | # mm |", lambda: _season_row("sphere", 1)),
    ("takes slightly more views than planning from the truth\n(#x / #x one-shot, at most #x per season)",
     lambda: [_season_row("hemisphere", 0)[4], _season_row("sphere", 0)[4],
              f"{max(float(_season_row(s, 0)[5]) for s in season.VIEW_SPACES):.2f}"]
     if all(float(_season_row(s, 0)[4]) > 1 for s in season.VIEW_SPACES) else ["not more"]),
    ("its registration ends # mm farther from the\ncoarse scan (# vs # mm mean, one-shot)",
     lambda: [f"{_one_shot_mean('registration_chamfer_mm', 'own') - _one_shot_mean(*_TRUTH_REGISTRATION):.2f}",
              f"{_one_shot_mean('registration_chamfer_mm', 'own'):.2f}",
              f"{_one_shot_mean('registration_chamfer_mm', 'truth'):.2f}"]),
    ("the registered prior misses # % of today's plant\nagainst # % for the truth on the hemisphere and # % against "
     "# % on the sphere (one-shot)",
     lambda: [f"{_one_shot_mean('prior_missing', arm, space, 100):.1f}"
              for space in season.VIEW_SPACES for arm in ("own", "truth")]),
    ("grows by at most # mm over a season, about as much as the truth arm's fused model",
     lambda: [f"{max(float(_season_row(s, r)[8]) for s in season.VIEW_SPACES for r in season.REPLAN_AFTER):.2f}"]),
    ("at least # %\nin every session", lambda: [f"{100 * FLOOR:g}"]),
    ("One-shot, # of # `own` seasons have a session below it (lowest # %) against\n# of # `truth` seasons "
     "(lowest # %)",
     lambda: [str(_seasons_below(0, "own")), str(_n_seasons(0)),
              f"{min(float(_lowest(s, 0, 'own')) for s in season.VIEW_SPACES):.2f}",
              str(_seasons_below(0, "truth")), str(_n_seasons(0)),
              f"{min(float(_lowest(s, 0, 'truth')) for s in season.VIEW_SPACES):.2f}"]),
    ("and # of # `own` sessions (# %) against # of # `truth` sessions (# %)",
     lambda: _session_misses(0)[:5] + [_f(float(_session_misses(0)[5]), 1)]),
    ("the two arms miss the same session # times, `own` alone # times, `truth`\nalone twice",
     lambda: [str(v) for v in _together(0)[:2]] if _together(0)[2] == 2 else ["`truth` alone not twice"]),
    ("Re-planned after every view: # of # `own` and # of # `truth` seasons have a session\nbelow # %",
     lambda: [str(_seasons_below(1, "own")), str(_n_seasons(1)), str(_seasons_below(1, "truth")),
              str(_n_seasons(1)), f"{100 * FLOOR:g}"]),
    ("# of # sessions in each arm (# %), both on the same session # times, each alone\n# times",
     lambda: ([_session_misses(1)[0], _session_misses(1)[1], _session_misses(1)[2], str(_together(1)[0]),
               str(_together(1)[1])]
              if _session_misses(1)[0] == _session_misses(1)[3] and _together(1)[1] == _together(1)[2]
              else ["the arms differ"])),
    ("stops on the ground truth at # % and takes\n#-#x the views (means per view space and re-planning; #-#x per "
     "season) with\n#-#x the path (means; #-#x per season)",
     lambda: [f"{100 * season.COVERAGE_TARGET:g}", *_ratio_range("total_views", "none", False),
              *_ratio_range("total_views", "none", True), *_ratio_range("path_length_m", "none", False),
              *_ratio_range("path_length_m", "none", True)]),
    ("saved views in\nboth arms (hemisphere: own # -> # per season, truth # -> #; sphere: own # -> #,\ntruth # -> #)",
     lambda: [_mean_views(s, r, a) for s in season.VIEW_SPACES for a in ("own", "truth") for r in season.REPLAN_AFTER]
     if all(float(_mean_views(s, 1, a)) < float(_mean_views(s, 0, a)) for s in season.VIEW_SPACES
            for a in ("own", "truth")) else ["did not save"]),
    ("lowest session (# -> # % hemisphere,\n# -> # % sphere)",
     lambda: [_lowest(s, r, "own") for s in season.VIEW_SPACES for r in season.REPLAN_AFTER]),
    # rows
    ("row_season`: room # and room #, seed #, the `handheld` reference, five scans, `paper-row`; # min\non # workers",
     lambda: [*[_room_number(r) for r in season.ROOMS],
              str(int(shipped.shipped_rows("row_season")["seed"].unique()[0])),
              f"{_provenance('row_season')['refresh_minutes']:.1f}", str(shipped.PROTOCOLS["row_season"].workers)]),
    ("per row over its # planned sessions", lambda: [str(season.ROW_SESSIONS - 1)]),
    ("views # vs # (room #, #x) and # vs # (room #, #x), lowest session # % vs\n# % and # % vs # %, "
     "path # vs # m and # vs # m",
     lambda: [v for room in season.ROOMS for v in (
         str(int(_row(room, "own", "views"))), str(int(_row(room, "truth", "views"))), _room_number(room),
         f"{_row(room, 'own', 'views') / _row(room, 'truth', 'views'):.2f}")]
     + [f"{100 * _row(room, arm, 'low'):.2f}" for room in season.ROOMS for arm in ("own", "truth")]
     + [f"{_row(room, arm, 'path'):.1f}" for room in season.ROOMS for arm in ("own", "truth")]),
    ("misses # % / # % of today's row, the `truth` arm's # % / # %",
     lambda: [f"{100 * _row(room, arm, 'missing'):.1f}" for arm in ("own", "truth") for room in season.ROOMS]),
    ("changes by at most # mm", lambda: [f"{_row_drift():.2f}"]),
    ("for its # % (# / #) but #x / #x the path (# / # m)",
     lambda: [f"{100 * season.ROW_NONE_TARGET:g}", *[str(int(_row(r, "none", "views"))) for r in season.ROOMS],
              *[f"{_row(r, 'none', 'path') / _row(r, 'truth', 'path'):.1f}" for r in season.ROOMS],
              *[f"{_row(r, 'none', 'path'):.0f}" for r in season.ROOMS]]
     if all(_row(r, "none", "low") >= season.ROW_NONE_TARGET for r in season.ROOMS) else ["missed its target"]),
]


# ---------------------------------------------------------------- sources: the species (docs/results.md)
def _md_tables(name: str) -> dict:
    """The tables of a benchmark output ``benchmarks/results/NAME.md``, by their ``## title``: lists of row dicts."""
    tables, title, header = {}, None, None
    for line in (ROOT / "benchmarks" / "results" / f"{name}.md").read_text().splitlines():
        if line.startswith("## "):
            title, header = line[3:].strip(), None
        elif line.startswith("|") and title is not None:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if header is None:
                header = cells
            elif not set("".join(cells)) <= set("-: "):
                tables.setdefault(title, []).append(dict(zip(header, cells)))
    return tables


def _calibration(title_start: str, group: str, space: str) -> dict:
    tables = _md_tables("species_calibration")
    title = next(t for t in tables if t.startswith(title_start))
    return next(r for r in tables[title] if r["group"] == group and r["view_space"] == space)


_BENCHMARK_RULE = "smallest planning target with mean >="
_ISSUE_RULE = "smallest planning target with the issue's"
_TARGET_OF = {"1": 0.98, "0.75": 0.985, "0.5": 0.99, "0.375": 0.9925, "0.25": 0.995}  # r -> planning target at 98 %


def _criterion(title_start: str) -> list[str]:
    """The mean and lowest coverage a rule table asks for, as its title writes them."""
    title = next(t for t in _md_tables("species_calibration") if t.startswith(title_start))
    return re.findall(NUMBER, title)[:2]


def _picked(title_start: str, space: str, groups=("both", "helios")) -> str:
    ratios = {_calibration(title_start, g, space)["miss_ratio"] for g in groups}
    return ratios.pop() if len(ratios) == 1 else f"groups differ: {ratios}"


def _pct(value: str, digits: int = 2) -> str:
    return f"{100 * float(value):.{digits}f}"


def _x(value: str, digits: int = 2) -> str:
    return f"{float(value):.{digits}f}"


@lru_cache(maxsize=None)
def _calibration_rows() -> pd.DataFrame:
    r = pd.read_csv(ROOT / "benchmarks" / "results" / "species_calibration.csv")
    return r[r["kind"] == "target"]


def _helios(species_name: str, space: str, r: str) -> pd.Series:
    rows = _calibration_rows()
    rows = rows[(rows["source"] == "dataset") & (rows["species"] == species_name) & (rows["view_space"] == space)]
    return rows[rows["target"] == _TARGET_OF[r]]["coverage"] * 100


def _only_pair_below(space: str, r: str, floor: float) -> list[str]:
    rows = _calibration_rows()
    rows = rows[(rows["source"] == "dataset") & (rows["view_space"] == space) & (rows["target"] == _TARGET_OF[r])]
    below = rows[rows["coverage"] < floor / 100]
    return [f"{floor:g}"] if len(below) == 1 and below["species"].iloc[0] == "maize" else [f"{len(below)} pairs"]


def _calibrated(space: str) -> str:
    from tpvp.setcover.config import CALIBRATED_MISS_RATIO

    return f"{CALIBRATED_MISS_RATIO[space]:g}"


def _margins() -> dict:
    rows = _md_tables("species_calibration")
    title = next(t for t in rows if "per organ margin" in t)
    return {(r["view_space"], r["margin"]): r for r in rows[title] if r["group"] == "helios"}


def _fruit_asked() -> str:
    """The fruit coverage the margin table counts cases at: its column ``cases_at_995`` (99.5 %)."""
    column = next(c for c in next(iter(_margins().values())) if c.startswith("cases_at_"))
    return f"{int(column.removeprefix('cases_at_')) / 10:g}"


def _chosen_margin() -> str:
    rows = _md_tables("species_calibration")["chosen organ margin"]
    return rows[0]["margin"]


def _no_ratio_meets(target: float) -> list[str]:
    """The issue's views target, when no planning target passing the issue's rule meets it (Helios)."""
    tables = _md_tables("species_calibration")
    passing = {(r["view_space"], r["target"]) for r in tables["per planning target"]
               if r["group"] == "helios" and float(r["coverage_mean"]) >= 0.98 and float(r["coverage_min"]) >= 0.97}
    meets = [r for r in tables["per planning target"] if r["group"] == "helios"
             and (r["view_space"], r["target"]) in passing and float(r["views_per_optimum"]) <= target]
    return [f"{target:g}"] if not meets else [f"met by {meets}"]


ISSUE_VIEWS_PER_OPTIMUM = 1.15  # issue 39's target for views / optimum: a requirement the page quotes, not a result


def _organ_margin_bullet() -> list[str]:
    m = _margins()
    from tpvp.setcover.config import SelectionConfig

    counts = [v for margin in range(5) for v in (str(margin), m[("hemisphere", str(margin))]["cases_at_995"],
                                                 m[("sphere", str(margin))]["cases_at_995"])]
    chosen = _chosen_margin()
    rows = pd.read_csv(ROOT / "benchmarks" / "results" / "species_calibration.csv")
    organ = rows[(rows["kind"] == "organ") & (rows["source"] == "dataset")]  # the md rounds: read the rows
    mean = organ.groupby(["view_space", "margin"])[["views", "fruit"]].mean()
    return [str(SelectionConfig().organ_margin_voxels) if chosen == str(SelectionConfig().organ_margin_voxels)
            else f"chosen {chosen}", _fruit_asked(), *counts, m[("hemisphere", "0")]["cases"],
            *[f"{mean.loc[(s, float(chosen)), 'views'] - mean.loc[(s, 1.0), 'views']:.1f}"
              for s in ("hemisphere", "sphere")],
            "1", *[f"{100 * mean.loc[(s, float(chosen)), 'fruit']:.1f}" for s in ("hemisphere", "sphere")]]


_SPECIES_CALIBRATION = [
    ("(r = # hemisphere, # sphere), by a looser", lambda: [_calibrated("hemisphere"), _calibrated("sphere")]),
    ("With the benchmark's #-point margin (mean >= # %, no case below # %) both sources together pick r = # on both "
     "view spaces (hemisphere # %, lowest # %, #x the optimum; sphere # % / # %, #x), and so do the Helios plants "
     "alone;",
     lambda: [f"{float(_criterion(_BENCHMARK_RULE)[0]) - float(_criterion(_ISSUE_RULE)[0]):.1f}",
              *_criterion(_BENCHMARK_RULE),
              _picked(_BENCHMARK_RULE, "hemisphere") if _picked(_BENCHMARK_RULE, "hemisphere")
              == _picked(_BENCHMARK_RULE, "sphere") else "view spaces differ",
              *[v for s in ("hemisphere", "sphere") for v in (
                  _pct(_calibration(_BENCHMARK_RULE, "both", s)["coverage_mean"]),
                  _pct(_calibration(_BENCHMARK_RULE, "both", s)["coverage_min"]),
                  _x(_calibration(_BENCHMARK_RULE, "both", s)["views_per_optimum"]))]]),
    ("r = # on the hemisphere passes only the issue's own targets (mean >= # %, no case below # %: # %, lowest # %, "
     "#x: one Helios maize pair falls below # %)",
     lambda: [_calibration(_ISSUE_RULE, "both", "hemisphere")["miss_ratio"], *_criterion(_ISSUE_RULE),
              _pct(_calibration(_ISSUE_RULE, "both", "hemisphere")["coverage_mean"]),
              _pct(_calibration(_ISSUE_RULE, "both", "hemisphere")["coverage_min"]),
              _x(_calibration(_ISSUE_RULE, "both", "hemisphere")["views_per_optimum"]),
              *_only_pair_below("hemisphere", _calibration(_ISSUE_RULE, "both", "hemisphere")["miss_ratio"],
                                float(_criterion(_BENCHMARK_RULE)[1]))]),
    ("The sphere stays at #, the", lambda: [_calibrated("sphere")]),
    ("the hemisphere's r = # was kept", lambda: [_calibrated("hemisphere")]),
    ("*No miss ratio meets #x on the calibration plants themselves*", lambda: _no_ratio_meets(ISSUE_VIEWS_PER_OPTIMUM)),
    ("passing the issue's targets costs #x (Helios, hemisphere) and #x (Helios, sphere); r = # (the target applied to "
     "the prediction as it is) takes #x / #x but leaves Helios maize at #-# % / #-# % (mean # % on both). Helios "
     "tomato comes to # % / # % at r = # (lowest # % / # %); Helios maize, whose leaves the registered prior "
     "predicts worst, still has pairs at # % / # % at r = #.",
     lambda: [_x(_calibration(_ISSUE_RULE, "helios", s)["views_per_optimum"]) for s in ("hemisphere", "sphere")]
     + ["1"] + [_x(r["views_per_optimum"]) for s in ("hemisphere", "sphere") for r in
                _md_tables("species_calibration")["per planning target"]
                if r["group"] == "helios" and r["view_space"] == s and r["target"] == "0.98"]
     + [v for s in ("hemisphere", "sphere") for v in (f"{_helios('maize', s, '1').min():.1f}",
                                                       f"{_helios('maize', s, '1').max():.1f}")]
     + ([f"{_helios('maize', 'hemisphere', '1').mean():.1f}"]
        if f"{_helios('maize', 'hemisphere', '1').mean():.1f}" == f"{_helios('maize', 'sphere', '1').mean():.1f}"
        else ["differ"])
     + [f"{_helios('tomato', s, '1').mean():.2f}" for s in ("hemisphere", "sphere")] + ["1"]
     + [f"{_helios('tomato', s, '1').min():.2f}" for s in ("hemisphere", "sphere")]
     + [f"{_helios('maize', s, '0.25').min():.2f}" for s in ("hemisphere", "sphere")] + ["0.25"]),
    ("*Organ margin #* (`selection.organ_margin_voxels`, before: #): the margin with the most calibration pairs at a "
     "true fruit coverage of # % or more (hemisphere / sphere: margin # # / #, # # / #, # # / #, # # / #, "
     "# # / # of #), "
     "+# / +# views against margin #. The mean true fruit coverage stays at # % / # %:",
     # "before: 1": the margin's earlier default, history that no file of the repository records
     lambda: [(b := _organ_margin_bullet())[0], "1", *b[1:]]),
]


def _species_overall_row(space: str) -> list[str]:
    from tpvp.experiments import species

    tables = species.species_tables(shipped.shipped_rows("species"))
    o = tables["overall"].set_index("view_space").loc[space]
    c = tables["calibration_species"].set_index("view_space").loc[space]
    return [f"{100 * o['coverage_mean']:.2f}", f"{100 * o['coverage_min']:.2f}", str(int(o["cases_below_97"])),
            f"{o['views_per_optimum']:.3f}", f"{o['ratio_of_means']:.2f}", f"{100 * c['coverage_mean']:.2f}",
            f"{100 * c['coverage_min']:.2f}", f"{c['views_per_optimum']:.2f}"]


def _species_counts() -> list[str]:
    from tpvp.experiments import species

    tables = species.species_tables(shipped.shipped_rows("species"))
    o, c = tables["overall"]["cases"], tables["calibration_species"]["cases"]
    return [str(int(cases.iloc[0])) if cases.nunique() == 1 else "differ" for cases in (o, c)]


_SPECIES_OVERALL = [
    ("the # cases per view space of the six evaluation species (and the # of Helios tomato and maize",
     _species_counts),
    ("| cases < # % |", lambda: ["97"]),  # species_tables' below_97 column: coverage < 0.97
    ("| hemisphere | # % (# %) | # | # (#) | # % (# %), #x |", lambda: _species_overall_row("hemisphere")),
    ("| sphere | # % (# %) | # | # (#) | # % (# %), #x |", lambda: _species_overall_row("sphere")),
]


@lru_cache(maxsize=None)
def _per_species() -> pd.DataFrame:
    from tpvp.experiments import species

    table = species.species_tables(shipped.shipped_rows("species"))["per_species"]
    table = table[table["species"].str.startswith("helios ")]
    return table.assign(name=table["species"].str.removeprefix("helios ").replace({"sugarbeet": "sugar beet"}))


ORGANS = ("stem", "leaf", "petiole", "peduncle", "flower", "fruit")


def _organ(value: float) -> str:
    """An organ's true coverage as the table writes it: one decimal, 100 without one, blank without the organ."""
    if pd.isna(value):
        return ""
    text = f"{100 * value:.1f}"
    return "100" if text == "100.0" else text


def _per_species_sources() -> list:
    out = []
    for row in _per_species().itertuples():
        organs = [_organ(getattr(row, organ)) for organ in ORGANS]
        template = (f"| {row.name} | {row.view_space} | # | # | # | # (#) | "
                    + " | ".join("#" if o else "" for o in organs) + " |").replace("|  |", "| |")
        values = [f"{row.views:.1f}", f"{row.optimum:.1f}", f"{row.views_per_optimum:.2f}",
                  f"{100 * row.coverage_mean:.2f}", f"{100 * row.coverage_min:.2f}", *[o for o in organs if o]]
        out.append((template, lambda values=values: values))
    return out


def _ratio(name: str, space: str) -> str:
    table = _per_species().set_index(["name", "view_space"])
    return f"{table.loc[(name, space), 'views_per_optimum']:.2f}"


def _over_on_the_sphere() -> list[str]:
    """The issue's target that the evaluation species' hemisphere mean meets (to the written digit) and their
    sphere mean does not, then the four largest sphere ratios of the evaluation species, largest first."""
    from tpvp.experiments import species

    overall = species.species_tables(shipped.shipped_rows("species"))["overall"].set_index("view_space")
    sphere = _per_species()[(_per_species()["view_space"] == "sphere")
                            & ~_per_species()["name"].isin(species.CALIBRATION_SPECIES)]  # the evaluation species
    sphere = sphere.sort_values("views_per_optimum", ascending=False)
    meets = (overall.loc["hemisphere", "views_per_optimum"] <= ISSUE_VIEWS_PER_OPTIMUM + 0.005
             and overall.loc["sphere", "views_per_optimum"] > ISSUE_VIEWS_PER_OPTIMUM)
    return ([f"{ISSUE_VIEWS_PER_OPTIMUM:g}"] if meets else ["not within"]) + [
        v for row in sphere.head(4).itertuples() for v in (row.name, f"{row.views_per_optimum:.2f}")]


def _sphere_list() -> list[str]:
    """The target, then the four sphere ratios in the order the sentence names the species (largest first)."""
    target, *named = _over_on_the_sphere()
    names, ratios = named[0::2], named[1::2]
    return [target, *ratios] if names == ["cowpea", "sugar beet", "rice", "soybean"] else [f"now {names}"]


_SPECIES_TABLE = [
    ("The coverage holds on every species; within #x on the hemisphere, over on the sphere: cowpea #x, sugar beet "
     "#x, rice #x, soybean #x;",
     _sphere_list),
    ("bean (#x hemisphere, #x sphere) and strawberry (#x / #x) come closest",
     lambda: [_ratio("bean", "hemisphere"), _ratio("bean", "sphere"), _ratio("strawberry", "hemisphere"),
              _ratio("strawberry", "sphere")]),
]


@lru_cache(maxsize=None)
def _species_tables() -> dict:
    from tpvp.experiments import species

    return species.species_tables(shipped.shipped_rows("species"))


def _beside() -> list[str]:
    """Our generated tomato and maize, then the bundled pair: ratio per view space, then coverage per view space."""
    table = _species_tables()["per_species"].set_index(["species", "view_space"])
    out = []
    for name, digits in (("generated tomato", 2), ("generated maize", 2), ("bundled tomato", 1)):  # 1 case: n / n
        out += [f"{table.loc[(name, s), 'views_per_optimum']:.{digits}f}" for s in ("hemisphere", "sphere")]
        out += [f"{100 * table.loc[(name, s), 'coverage_mean']:.2f}" for s in ("hemisphere", "sphere")]
    return out


def _fruiting_plants() -> list[str]:
    organ = _species_tables()["organ_targets"]
    cases = organ.groupby("species")["cases"].agg(["min", "max"])
    assert (cases["min"] == cases["max"]).all()  # the same plants on both view spaces
    named = {"helios cowpea": None, "helios maize": None, "helios rice": None, "helios strawberry": None,
             "helios tomato": None}
    counts = [int(cases.loc[n, "min"]) for n in named]
    none_yet = {"helios soybean", "helios bean"} & set(cases.index)
    if none_yet or len(set(counts[:3])) != 1:
        return [f"now {dict(zip(named, counts))}"]
    return [str(counts[0]), str(counts[3]), str(counts[4])]


def _fruit(mean: float) -> str:
    text = f"{100 * mean:.1f}"
    return "100" if text == "100.0" else text


def _organ_target_sources() -> list:
    out = []
    for row in _species_tables()["organ_targets"].itertuples():
        name = row.species.removeprefix("helios ")
        one = row.cases == 1  # one plant: no separate minimum
        template = f"| {name} | {row.view_space} | # | # | # % | # {'' if one else '(#) '}| # |"
        values = [f"{row.full_cover_views:.1f}", f"{row.organ_target_views:.1f}", f"{100 * row.views_saved:.0f}",
                  _fruit(row.fruit_mean), *([] if one else [_fruit(row.fruit_min)]), f"{100 * row.leaf_mean:.1f}"]
        out.append((template, lambda values=values: values))
    return out


_SPECIES_ORGANS = [
    ("our generated tomato #x / #x (# % / # %), our generated maize #x / #x (# % / # %), the bundled real tomato "
     "#x / #x (# % / # %).", _beside),
    ("against `--coverage-target 1.0`, on the cases whose previous session holds fruit (cowpea, maize, rice # plants; "
     "strawberry #; tomato #; soybean and bean had none yet):", _fruiting_plants),
    *_organ_target_sources(),
]


class Printed:
    """A value a benchmark output prints to 4 significant digits (``write_results``): a number written from it
    matches when the two roundings can hold the same value (the output alone cannot decide ``1.195`` -> 1.19 or
    1.20, and reads ``97`` as 97.00). The two intervals must overlap in more than a point: with as many decimals as
    the output, the written number must be the printed one (98.37 is not 98.36, though both could round 98.365),
    unless the value is a mean of whole numbers over ``cases`` and the point is such a mean, rounded half up by the
    page (2512.5 voxels over 8 cases is printed 2512 and written 2,513)."""

    def __init__(self, text: str, significant: int = 4, cases: int | None = None):
        self.text, self.value, self.cases = text, float(text), cases
        self.half = 0.0 if self.value == 0 else 0.5 * 10 ** (math.floor(math.log10(abs(self.value))) - significant + 1)

    def matches(self, written: str) -> bool:
        decimals = len(written.split(".")[1]) if "." in written else 0
        distance, limit = abs(float(written) - self.value), self.half + 0.5 * 10 ** -decimals
        if distance < limit - 1e-9:
            return True
        # the one common point, a mean over the cases, rounded half up as the pages round: the written number's floor
        point = self.value + self.half
        return (abs(distance - limit) <= 1e-9 and float(written) > self.value and self.cases is not None
                and abs(point * self.cases - round(point * self.cases)) < 1e-6)

    def __str__(self) -> str:
        return f"{self.text} (printed)"


def _evaluate_row(name: str, space: str, target: str) -> dict:
    lines = (ROOT / "benchmarks" / "results" / f"{name}.md").read_text().splitlines()
    header = next(line for line in lines if line.startswith("| source | view_space | target |"))
    names = [c.strip() for c in header.strip("|").split("|")]
    for line in lines:
        cells = [c.strip() for c in line.strip("|").split("|")]
        if cells[:3] == ["all", space, target]:
            return dict(zip(names, cells))
    raise AssertionError(f"{name}: no `all` row for {space} at {target}")


def _coverage_target_table_row(target: str, space: str) -> list:
    """One row of docs/results.md's coverage-target table: the unweighted evaluation, in brackets the weighted."""
    plain = _evaluate_row("coverage_target_evaluate", space, target)
    weighted = (_evaluate_row("coverage_target_evaluate_weighted", space, target)
                if float(target) < 1 else None)  # the weighted run asks for 1.0 as the unweighted (same rows)
    out = [Printed(plain["views_mean"])] + ([Printed(weighted["views_mean"])] if weighted else [])
    out += [Printed(plain["optimum_views_mean"])] + ([] if target == ASKED else [f"{100 * float(target):g}"])
    out += [Printed(plain["ratio_mean"])] + ([Printed(weighted["ratio_mean"])] if weighted else [])
    out += [Printed(plain["coverage_mean"]), Printed(plain["coverage_min"])]
    out += [Printed(weighted["coverage_mean"]), Printed(weighted["coverage_min"])] if weighted else []
    out += [plain["cases_below_97pct"]] + ([weighted["cases_below_97pct"]] if weighted else [])
    return out


def _coverage_target_sources() -> list:
    out = [("| cases < # % |", lambda: ["97"])]  # the column cases_below_97pct
    for target in ("0.98", "0.95", "0.99", "1"):
        asked = f"{float(target):.1f}" if target == "1" else target  # the row's key: locates it, so it is checked
        for space in ("hemisphere", "sphere"):
            optimum = "#" if target == ASKED else "# (# %)"
            if target == "1":
                template = f"| {asked} | {space} | # | {optimum} | # | # % (# %) | # |"
            else:
                template = f"| {asked} | {space} | # [#] | {optimum} | # [#] | # % (# %) [# % (# %)] | # [#] |"
            out.append((template, lambda target=target, space=space: _coverage_target_table_row(target, space)))
    return out


def _miss_model_sources() -> list:
    """docs/results.md's per-case miss model: benchmarks/results/miss_model_{rows.csv,fit.md,evaluate.md}."""
    import numpy as np

    from tpvp.setcover.config import CALIBRATED_MISS_RATIO
    from tpvp.setcover.miss_model import load_miss_model

    bench = _benchmark("miss_model")

    def rows():
        return pd.read_csv(ROOT / "benchmarks" / "results" / "miss_model_rows.csv")

    def cases(source=None):
        table = rows() if source is None else rows().query("source == @source")
        return str(len(table.drop_duplicates(["instance", "view_space", "rotation_deg", "initial_view"])))

    def seeds(source):
        values = sorted(set(rows().query("source == @source")["seed"]))
        return [str(values[0]), str(values[-1])]

    def chosen() -> dict:
        tables = _md_tables("miss_model_fit")
        title = next(t for t in tables if t.startswith("chosen: "))
        names = title[len("chosen: "):].split(";")[0]
        return next(r for r in tables[next(iter(tables))] if r["features"] == names)

    def evaluated(rule, space) -> dict:
        return next(r for r in _md_tables("miss_model_evaluate")["plans for 98 % (coverage and shares in %)"]
                    if r["rule"] == rule and r["view_space"] == space)

    def constant_on_calibration(space):
        target = 1 - CALIBRATED_MISS_RATIO[space] * (1 - bench.ASKED)
        t = rows().query("view_space == @space")
        t = t[np.isclose(t["target"], target)]
        return f"{(t['views'] / t['optimum_views']).mean():.2f}"

    def table_row(rule, space):
        r = evaluated(rule, space)
        return [Printed(r[c]) for c in ("views_per_optimum", "coverage_mean", "coverage_min", "below_97",
                                        "below_96", "below_bound", "mean_abs_error")]

    targets = {"views": 1.10, "mean": 98.0, "below_97": 5.0, "below_96": 0.0, "error": 0.5, "bound": (3.0, 7.0)}

    def met(rule, space) -> dict:
        r = {k: float(v) for k, v in evaluated(rule, space).items() if k not in ("rule", "view_space")}
        return {"views": r["views_per_optimum"] <= targets["views"], "mean": r["coverage_mean"] >= targets["mean"],
                "below_97": r["below_97"] <= targets["below_97"], "below_96": r["below_96"] <= targets["below_96"],
                "error": r["mean_abs_error"] <= targets["error"],
                "bound": targets["bound"][0] <= r["below_bound"] <= targets["bound"][1]}

    def verdicts():
        h, p = met("per-case", "hemisphere"), met("per-case", "sphere")
        holds = (h["views"] and p["views"] and not h["mean"] and not p["mean"] and h["below_97"] and h["below_96"]
                 and h["error"] and not h["bound"] and not any(p[k] for k in ("below_97", "below_96", "error", "bound")))
        return ["98", "1.10", "98", "5", "97", "96", "0.5", "3", "7"] + _claim(holds, "the per-case verdicts")

    out = [
        ("each one-shot plan below # predicts its own true coverage", lambda: [f"{make_config('plant').selection.coverage_target:g}"]),
        ("with a # % lower bound", lambda: [f"{100 * (1 - load_miss_model().alpha):g}"]),
        ("# cases of # plants", lambda: [cases(), str(bench.plant_key(rows()).nunique())]),
        ("generated tomato and maize of seeds #-# (# cases), generated growth series\nof seeds #-#, sessions # -> # (#), "
         "Helios tomato and maize grown with seed # (#)",
         lambda: [*seeds("generated"), cases("generated"), *seeds("series"), *map(str, bench.SERIES_PAIR),
                  cases("series"), *sorted({str(s) for s in rows().query("source == 'dataset'")["seed"]}),
                  cases("dataset")]),
        ("selection for # planning targets from # to # and the exact optimum for # %",
         lambda: [str(len(bench.TARGETS)), f"{min(bench.TARGETS):g}", f"{max(bench.TARGETS):.1f}",
                  f"{100 * bench.ASKED:g}"]),
        ("(`--mode fit`, `benchmarks/results/miss_model_fit.md`): # feature sets", lambda: [str(len(bench.FEATURE_SETS))]),
        ("gives #x / #x the optimum\n(hemisphere / sphere) with a mean of # / # % and a lowest case of # / # %",
         lambda: [Printed(chosen()[f"{s} {c}"]) for c in ("views_per_optimum",) for s in ("hemisphere", "sphere")]
         + [Printed(chosen()[f"{s} {c}"]) for c in ("coverage_mean", "coverage_min") for s in ("hemisphere", "sphere")]),
        ("constant rule on the same rows gives #x / #x", lambda: [constant_on_calibration(s) for s in ("hemisphere", "sphere")]),
        ("The bound lies # points below the prediction", lambda: [f"{-100 * load_miss_model().lower:.2f}"]),
        ("(`--mode evaluate`, # s on # workers;", lambda: [f"{_md_seconds('miss_model_evaluate')[0]:.0f}",
                                                           _md_seconds("miss_model_evaluate")[1]]),
        ("generated seeds #-# and the bundled\nreal pair, # cases per view space, the plan for # % by each rule",
         lambda: [*_md_seeds("miss_model_evaluate"), evaluated("per-case", "hemisphere")["cases"],
                  f"{100 * bench.ASKED:g}"]),
        ("| cases < # % | cases < # % |", lambda: ["97", "96"]),
        *[(f"| {rule} | {space} | # | # % (# %) | # % | # % | # % | # points |",
           lambda rule=rule, space=space: table_row(rule, space))
          for rule in ("per-case", "constant") for space in ("hemisphere", "sphere")],
        ("targets at # % (views at most #x the optimum, a mean of at least # %, at\nmost # % of the cases below # % and "
         "none below # %, a mean error of at most # point, #-# % of the\ncases below the bound)", verdicts),
        ("on the hemisphere it meets the cases below # % and # %", lambda: ["97", "96"]),
    ]
    return out


def _evaluation(benchmark: str, rule: str, space: str) -> dict:
    """A row of a miss model evaluation (benchmarks/miss_model.py --mode evaluate)."""
    return next(r for r in _md_tables(benchmark)["plans for 98 % (coverage and shares in %)"]
                if r["rule"] == rule and r["view_space"] == space)


_RULES_SPACES = [(rule, space) for rule in ("per-case", "constant") for space in ("hemisphere", "sphere")]
_IDEAL, _ARM, _PHONE = ("miss_model_evaluate", "miss_model_evaluate_arm-rgbd", "miss_model_evaluate_phone-lidar")


def _evaluation_rows(benchmark: str) -> list:
    """The rows of docs/results.md's table of one evaluation."""
    return [(f"| {rule} | {space} | # | # % (# %) | # % | # % | # % | # points |",
             lambda rule=rule, space=space: [Printed(_evaluation(benchmark, rule, space)[c]) for c in
                                              ("views_per_optimum", "coverage_mean", "coverage_min", "below_97",
                                               "below_96", "below_bound", "mean_abs_error")])
            for rule, space in _RULES_SPACES]


def _noisy_evaluation_sources() -> list:
    """docs/results.md's miss model under the arm-rgbd profile (miss_model_evaluate_arm-rgbd.md),
    beside the ideal sensor's rows (miss_model_evaluate.md)."""
    v = lambda row, c: float(row[c])  # noqa: E731

    def more():
        holds = all(v(_evaluation(_ARM, *k), c) > v(_evaluation(_IDEAL, *k), c) for k in _RULES_SPACES
                    for c in ("views_per_optimum", "coverage_mean"))
        return _claim(holds, "more views per optimum and a higher mean under noise, every rule and view space")

    def verdicts():
        h, s = (_evaluation(_ARM, "per-case", space) for space in ("hemisphere", "sphere"))
        holds = (all(v(r, "coverage_mean") >= 98 and v(r, "below_97") <= 5 and v(r, "below_96") == 0 for r in (h, s))
                 and v(h, "mean_abs_error") <= 0.5 and v(s, "mean_abs_error") > 0.5
                 and all(v(r, "views_per_optimum") > 1.10 and abs(v(r, "below_bound") - 5) > 2 for r in (h, s)))
        return ["97", "96", "2", "5"] + _claim(holds, "the per-case verdicts under noise")

    return [
        ("(`--mode evaluate --noise arm-rgbd`, run once, # s on # workers;",
         lambda: [f"{_md_seconds(_ARM)[0]:.0f}", _md_seconds(_ARM)[1]]),
        ("from a D#-class wrist\ncamera", lambda: ["405"]),
        ("| cases < # % | cases < # % |", lambda: ["97", "96"]),
        *_evaluation_rows(_ARM),
        ("every rule and view space takes more views per optimum", more),
        ("the cases below # % and\n# % on both view spaces", lambda: verdicts()[:2]),
        ("the\nbound's share on both (more than # points from # %)", lambda: verdicts()[2:]),
    ]


def _phone_evaluation_sources() -> list:
    """docs/results.md's miss model under the phone-lidar profile (miss_model_evaluate_phone-lidar.md)
    beside the other two, then the Helios evaluation species' prediction."""
    v = lambda row, c: float(row[c])  # noqa: E731

    def most():
        holds = all(v(_evaluation(_PHONE, "constant", space), c) > v(_evaluation(other, "constant", space), c)
                    for space in ("hemisphere", "sphere") for other in (_IDEAL, _ARM)
                    for c in ("views_per_optimum", "below_bound"))
        return _claim(holds, "the constant rule's views and bound failures are highest under the phone profile")

    def verdicts():
        h, s = (_evaluation(_PHONE, "per-case", space) for space in ("hemisphere", "sphere"))
        holds = (all(v(r, "coverage_mean") >= 98 for r in (h, s))
                 and v(s, "below_97") <= 5 and v(s, "below_96") == 0 and (v(h, "below_97") > 5 or v(h, "below_96") > 0)
                 and all(v(r, "views_per_optimum") > 1.10 and abs(v(r, "below_bound") - 5) > 2
                         and v(r, "mean_abs_error") > 0.5 for r in (h, s)))
        return ["97", "96"] + _claim(holds, "the per-case verdicts under the phone profile")

    return [
        ("(`--noise phone-lidar`: a phone LiDAR with ARKit-like poses, run once, # s\non # worker;",
         lambda: [f"{_md_seconds(_PHONE)[0]:.0f}", _md_seconds(_PHONE)[1]]),
        ("| cases < # % | cases < # % |", lambda: ["97", "96"]),
        *_evaluation_rows(_PHONE),
        ("the constant rule asks for the most views of any profile, and its bound\nfails most often", most),
        ("the cases below # % and\n# % on the sphere only", verdicts),
        ("(step #) draws this evaluation", lambda: [_notebook_step("03_table2_plant_complexity", "How sure a plan is")]),
        ("helios-plants)), # % of the # hemisphere cases and\n# % of the # "
         "sphere cases fall below their bound, and the mean error is # / # point", _species_prediction),
    ]


def _species_prediction() -> list:
    """The Helios evaluation species' plans against their prediction (species_tables' ``prediction``), and
    whether both calibration targets are missed."""
    table = _species_tables()["prediction"].set_index("view_space")
    missed = all(abs(table.loc[s, "below_bound"] - 0.05) > 0.02 and table.loc[s, "mean_abs_error"] > 0.005
                 for s in ("hemisphere", "sphere"))
    return ([x for s in ("hemisphere", "sphere") for x in (f"{100 * table.loc[s, 'below_bound']:.1f}",
                                                          str(table.loc[s, "cases"]))]
            + [f"{100 * table.loc[s, 'mean_abs_error']:.2f}" for s in ("hemisphere", "sphere")]
            + _claim(missed, "both calibration targets missed on the Helios evaluation species"))


def _notebook_step(notebook: str, title: str) -> str:
    """The number of the notebook's section ``## N. title``."""
    import nbformat

    cells = nbformat.read(ROOT / "notebooks" / f"{notebook}.ipynb", as_version=4).cells
    return next(re.match(r"## (\d+)\. " + re.escape(title), c.source).group(1) for c in cells
                if c.cell_type == "markdown" and re.match(r"## \d+\. " + re.escape(title), c.source))


def _closing_check_sources() -> list:
    """docs/results.md's closing check: benchmarks/results/closing_check.md."""
    from tpvp.setcover.config import SelectionConfig

    bench = _benchmark("closing_check")
    tables = _md_tables("closing_check")

    def plan(space, name) -> dict:
        return next(r for r in tables["plans for 98 % (coverage and shares in %)"]
                    if r["view_space"] == space and r["plan"] == name)

    def changed(column) -> list:
        rows = next(v for k, v in tables.items() if k.startswith("cases below 98 %"))
        return [next(r for r in rows if r["view_space"] == s)[column] for s in ("hemisphere", "sphere")]

    def target(space) -> str:
        return f"{100 * SelectionConfig(coverage_target=bench.ASKED).planning_target(space):g}"

    below, hits = changed("one_shot_below_98"), changed("changed_below_98")
    return [
        ("(run once, # s on # workers;", lambda: [f"{_md_seconds('closing_check')[0]:.0f}", _md_seconds("closing_check")[1]]),
        ("cases above, generated seeds #-# and the\nbundled real pair, # cases per view space, the plan for # % by the "
         "default rule", lambda: [*_md_seeds("closing_check"), plan("hemisphere", "one-shot")["cases"], f"{100 * bench.ASKED:g}"]),
        *[(f"| {space} | {name} | # | # % (# %) |",
           lambda space=space, name=name: [Printed(plan(space, name)[c]) for c in
                                            ("views_per_optimum", "coverage_mean", "coverage_min")])
          for space in ("hemisphere", "sphere") for name in ("one-shot", "closing check")],
        ("every hemisphere case below # % (# of #) and # of the # on the sphere, and\nleft # and # case below # %",
         lambda: ["98", hits[0], below[0], hits[1], below[1], *changed("closing_below_98"), "98"]),
        ("added views to # and # cases already at # % or more (# and\n# views added in all)",
         lambda: [*changed("changed_at_98_or_more"), "98", *changed("views_added")]),
        ("(# % of the surface\nthe captures corrected on the hemisphere, # % on the sphere)",
         lambda: [target("hemisphere"), target("sphere")]),
    ]


def _replanning_sources() -> list:
    """docs/results.md's re-planning evaluation table: benchmarks/results/replanning_evaluate.md, rows `all`."""
    out = [("| cases < # % |", lambda: ["97"])]  # the column cases_below_97pct

    def row(space: str, target: str) -> list:
        r = _evaluate_row("replanning_evaluate", space, target)
        return [Printed(r[c]) for c in ("optimum_views", "one_shot_views", "one_shot_ratio", "views", "ratio",
                                        "coverage_mean", "coverage_min")] + [
            r["cases_below_97pct"], Printed(r["path_ratio"]), Printed(r["replans"]), Printed(r["replanning_s"])]
    for target in ("0.98", "0.95", "0.99"):
        for space in ("hemisphere", "sphere"):
            out.append((f"| {target} | {space} | # | # (#) | # (#) | # % (# %) | # | # | #, # s |",
                        lambda space=space, target=target: row(space, target)))
    return out


# ---------------------------------------------------------------- sources: README's results at a glance
ASKED = "0.98"  # the row of benchmarks/results/coverage_target_evaluate.md the README quotes


def _coverage_target_evaluate(space: str) -> dict:
    """The `all` row at target :data:`ASKED` of benchmarks/results/coverage_target_evaluate.md, by its header."""
    return _evaluate_row("coverage_target_evaluate", space, ASKED)


def _coverage_target_row() -> list[str]:
    out = [f"{100 * float(ASKED):g}"]
    for space in ("hemisphere", "sphere"):
        row = _coverage_target_evaluate(space)  # the README writes the benchmark's cells to 2 decimals
        out += [f"{float(row[c]):.2f}" for c in ("views_mean", "coverage_mean", "coverage_min")]
    return out


def _species_row() -> list[str]:
    from tpvp.experiments import species

    rows = shipped.shipped_rows("species")
    helios = rows[rows["source"] == "dataset"]
    evaluation = helios[~helios["species"].isin(species.CALIBRATION_SPECIES)]["species"].nunique()
    overall = species.species_tables(rows)["overall"].set_index("view_space")
    return [str(evaluation), f"{100 * species.SPECIES_TARGET:g}"] + [v for space in ("hemisphere", "sphere") for v in (
        f"{100 * overall.loc[space, 'coverage_mean']:.2f}", f"{100 * overall.loc[space, 'coverage_min']:.2f}",
        f"{overall.loc[space, 'views_per_optimum']:.2f}")]


# ---------------------------------------------------------------- sources: generic helpers
def _f(value, digits: int = 2) -> str:
    """``value`` rounded half up to ``digits`` decimals, as the pages round (Python's format rounds half to even:
    154.25 -> 154.2, the page writes 154.3); the float's exact value decides, so 61.147 is 61.1."""
    from decimal import ROUND_HALF_UP, Decimal

    return str(Decimal(float(value)).quantize(Decimal(1).scaleb(-digits), rounding=ROUND_HALF_UP))


def _hundred(text: str) -> str:
    """A full coverage as the pages write it: 100, not 100.00."""
    return "100" if re.fullmatch(r"100(?:\.0+)?", text) else text


def _machine_cores() -> str:
    """The cores of the machine every shipped protocol ran on, as provenance.json records it."""
    machines = {entry["machine"] for entry in json.loads((ROOT / "tpvp" / "data" / "results" / "provenance.json")
                                                         .read_text()).values()}
    cores = {re.search(r"(\d+) cores", m).group(1) for m in machines}
    return cores.pop() if len(cores) == 1 else f"machines differ: {machines}"


def _md_header(name: str) -> str:
    """The ``Made by ...`` line of benchmarks/results/NAME.md: the run in words (cases, seeds, seconds, workers)."""
    return next(line for line in (ROOT / "benchmarks" / "results" / f"{name}.md").read_text().splitlines()
                if line.startswith("Made by"))


def _md_seconds(name: str) -> tuple[float, str]:
    """The run's seconds and workers, as its header prints them."""
    match = re.search(r"(\d+) s on (\d+) workers", _md_header(name))
    return float(match.group(1)), match.group(2)


def _md_minutes(name: str) -> list[str]:
    seconds, workers = _md_seconds(name)
    return [f"{seconds / 60:.0f}", workers]


def _md_seeds(name: str) -> list[str]:
    seeds = [int(s) for s in re.search(r"seeds \[([\d, ]+)\]", _md_header(name)).group(1).split(",")]
    return [str(min(seeds)), str(max(seeds))]


def _md_all_tables(name: str) -> list[list[dict]]:
    """Every table of benchmarks/results/NAME.md in order, each a list of row dicts by its header."""
    tables, header = [], None
    for line in (ROOT / "benchmarks" / "results" / f"{name}.md").read_text().splitlines():
        if not line.startswith("|"):
            header = None
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if header is None:
            header = cells
            tables.append([])
        elif not set("".join(cells)) <= set("-: "):
            tables[-1].append(dict(zip(header, cells)))
    return tables


# ---------------------------------------------------------------- sources: individual plants (docs/results.md)
@lru_cache(maxsize=None)
def _plant_tables(name: str = "table1") -> dict:
    return plants.tables(shipped.shipped_rows(name))


def _t1(source: str, space: str, method: str, budget=None, target=None, name: str = "table1") -> pd.Series:
    t = _plant_tables(name)["table1_coverage_effort"]
    t = t[(t["source"] == source) & (t["view_space"] == space) & (t["method"] == method)]
    if budget is not None:
        t = t[t["budget"] == budget]
    if target is not None:
        t = t[t["target"] == target]
    assert len(t) == 1, (source, space, method, budget, target)
    return t.iloc[0]


def _paper_plant(table: str, view_space: str, method: str, species: str = "all", budget=None) -> pd.Series:
    p = plants.paper_values()
    p = p[(p["table"] == table) & (p["view_space"] == view_space) & (p["method"] == method) & (p["species"] == species)]
    if budget is not None:
        p = p[p["budget"] == budget]
    assert len(p) == 1, (table, view_space, method, species, budget)
    return p.iloc[0]


def _mean_std(row: pd.Series, columns=("views", "coverage", "path_length_m")) -> list[str]:
    return [_f(row[f"{c}_{s}"]) for c in columns for s in ("mean", "std")]


def _plants_protocol() -> list[str]:
    r = shipped.shipped_rows("table1")
    ours = r[r["method"] == "ours"]
    g, b = ours[ours["source"] == "generated"], ours[ours["source"] == "bundled"]
    spaces = ours["view_space"].nunique()
    species = g["species"].nunique()
    return [str(species), str(g["instance"].nunique() // species), str(g["rotation_deg"].nunique()),
            str(g["initial_view"].nunique()), str(len(g) // spaces), str(len(b) // spaces), str(len(ours)),
            str(len(plants.PLANT_METHODS.defaults()))]


def _ours_row(source: str, space: str, name: str = "table1", method: str = "ours", paper: str | None = "ours") -> list:
    out = _mean_std(_t1(source, space, method, name=name))
    if paper:
        p = _paper_plant("I", space, paper)
        out += [_f(p["views_mean"]), _f(p["coverage_mean"]), _f(p["path_mean"])]
    return out


def _gmc_row(space: str, source: str = "generated", paper: bool = True) -> list:
    budgets = plants.GMC_BUDGETS
    rows = [_t1(source, space, "gmc", budget=b) for b in budgets]
    out = ([str(b) for b in budgets] + [_f(r["coverage_mean"]) for r in rows]
           + [_f(r["path_length_m_mean"]) for r in rows])
    if paper:
        p = [_paper_plant("I", space, "gmc", budget=b) for b in budgets]
        out += [_f(r["coverage_mean"]) for r in p] + [_f(r["path_mean"]) for r in p]
    return out


def _optimum_row(space: str) -> list:
    rows = [_t1("generated", space, "optimum", target=t) for t in (0.98, 1.0)]
    return ([f"{100 * t:g}" for t in (0.98, 1.0)] + [_f(r["views_mean"]) for r in rows]
            + [_hundred(_f(r["coverage_mean"])) for r in rows] + [_f(r["path_length_m_mean"]) for r in rows])


def _optimum_ratio(source: str, space: str, column: str = "views_ratio_mean") -> str:
    t = _plant_tables()["optimum_ratio"]
    t = t[(t["source"] == source) & (t["view_space"] == space) & (t["method"] == "ours")]
    return _f(t[column].iloc[0])


def _table2(species_name: str, space: str) -> str:
    t = _plant_tables("table2")["table2_plant_complexity"]
    t = t[(t["source"] == "generated") & (t["species"] == species_name) & (t["view_space"] == space)]
    return _f(t["views_mean"].iloc[0])


def _table3(species_name: str, method: str, column: str) -> float:
    t = _plant_tables("tables3_4")["table3_inflation"]
    t = t[(t["source"] == "generated") & (t["species"] == species_name) & (t["method"] == method)]
    return float(t[f"{column}_mean"].iloc[0])


def _claim(holds: bool, what: str) -> list[str]:
    """A sentence that compares without a number of its own: nothing to read back while it holds."""
    return [] if holds else [f"no longer holds: {what}"]


def _gmc_claim() -> list[str]:
    ours = {s: [_t1("generated", s, "gmc", budget=b)["coverage_mean"] for b in plants.GMC_BUDGETS]
            for s in ("hemisphere", "sphere")}
    paper = {s: [_paper_plant("I", s, "gmc", budget=b)["coverage_mean"] for b in plants.GMC_BUDGETS] for s in ours}
    gain = {s: [o - p for o, p in zip(ours[s], paper[s])] for s in ours}
    more = all(g > 0 for s in gain for g in gain[s])
    most_on_the_sphere = all(a > b for a, b in zip(gain["sphere"], gain["hemisphere"]))
    return _claim(more and most_on_the_sphere,
                  "GMC covers more than the paper's at every budget, by more on the sphere")


def _species_claim() -> list[str]:
    views = {(n, s): float(_table2(n, s)) for n in ("tomato", "maize") for s in ("hemisphere", "sphere")}
    paper = {n: _paper_plant("II", "hemisphere", "ours", species=n)["views_mean"] for n in ("tomato", "maize")}
    return _claim(views[("tomato", "hemisphere")] > views[("maize", "hemisphere")] and paper["tomato"] > paper["maize"]
                  and views[("tomato", "sphere")] <= views[("maize", "sphere")],
                  "tomato needs more views than maize on the hemisphere (as in the paper), not on the sphere")


def _inflation() -> list[str]:
    out = []
    for name in ("tomato", "maize"):
        out += [_f(_table3(name, m, "views")) for m in ("ours-no-inflation", "ours")]
        out += [_f(_table3(name, m, "coverage")) for m in ("ours-no-inflation", "ours")]
    paper = {name: {m: _paper_plant("III", "all", m, species=name) for m in ("ours-no-inflation", "ours")}
             for name in ("tomato", "maize")}
    views = {f"{p['ours']['views_mean'] - p['ours-no-inflation']['views_mean']:.0f}" for p in paper.values()}
    out += [views.pop() if len(views) == 1 else f"paper views differ: {views}"]
    out += [_f(p["ours"]["coverage_mean"] - p["ours-no-inflation"]["coverage_mean"], 1) for p in paper.values()]
    return out


def _table4() -> list[str]:
    t = _plant_tables("tables3_4")["table4_registration"].set_index(["source", "method"])
    g0, g1 = t.loc[("generated", "initial-view-only")], t.loc[("generated", "ours")]
    b0, b1 = t.loc[("bundled", "initial-view-only")], t.loc[("bundled", "ours")]
    return ([_f(g0["chamfer_truth_mm_mean"]), _f(g0["chamfer_truth_mm_std"]), _f(g1["chamfer_truth_mm_mean"]),
             _f(g1["chamfer_truth_mm_std"]), _f(b0["chamfer_truth_mm_mean"]), _f(b1["chamfer_truth_mm_mean"])]
            + [_f(_paper_plant("IV", "all", m)["chamfer_mean"]) for m in ("initial-view-only", "ours")])


def _tie(value: float) -> str:
    """Tie picks as the page writes them: 0 when none, two decimals under 0.1, else one."""
    return "0" if value == 0 else f"{value:.2f}" if value < 0.1 else f"{value:.1f}"


def _ties() -> list[str]:
    r = shipped.shipped_rows("table1")
    gmc = r[(r["method"] == "gmc") & r["budget"].isin(plants.GMC_BUDGETS)]
    mean = gmc.groupby(["view_space", "budget"])["tie_picks"].mean()  # every case, generated and real
    return ([_tie(mean[("hemisphere", b)]) for b in plants.GMC_BUDGETS] + [str(b) for b in plants.GMC_BUDGETS]
            + [_tie(mean[("sphere", b)]) for b in plants.GMC_BUDGETS])


def _gmc_gain_voxel() -> str:
    rules = {row["rule"] for table in _md_all_tables("gmc_gain") for row in table if "rule" in row}
    voxels = [re.fullmatch(r"(\d+) mm", rule).group(1) for rule in rules if re.fullmatch(r"\d+ mm", rule)]
    return voxels[0] if len(voxels) == 1 else f"rules {rules}"


def _planning_seconds() -> list[str]:
    r = shipped.shipped_rows("table1")
    mean = r[r["method"] == "ours"].groupby(["source", "view_space"])["seconds_planning"].mean()
    return [_f(mean[(s, v)]) for s in ("generated", "bundled") for v in ("hemisphere", "sphere")]


_PLANTS = [
    ("per view space # species x # generated instances x # rotations x # initial views = # cases, plus the bundled "
     "real tomato pair on its own # rows per view space: # cases, each with the # methods the command runs by default",
     _plants_protocol),
    ("A run of # of those methods took # min # s on # workers from an empty cache with the harder generated plants "
     "(# min # s before them; # worker took #x as long)", NOT_KEPT),
    ("| hemisphere | Ours, generated | # ± # | # ± # | # ± # | # / # / # |",
     lambda: _ours_row("generated", "hemisphere")),
    ("| hemisphere | Ours, real tomato | # ± # | # ± # | # ± # | |",
     lambda: _ours_row("bundled", "hemisphere", paper=None)),
    ("| hemisphere | GMC # / # / # / #, generated | | # / # / # / # | # / # / # / # | "
     "# / # / # / # %, # / # / # / # m |",
     lambda: _gmc_row("hemisphere")),
    ("| hemisphere | exact optimum, # % / # % | # / # | # / # | # / # | (beyond the paper) |",
     lambda: _optimum_row("hemisphere")),
    ("| sphere | Ours, generated | # ± # | # ± # | # ± # | # / # / # |", lambda: _ours_row("generated", "sphere")),
    ("| sphere | Ours, real tomato | # ± # | # ± # | # ± # | |", lambda: _ours_row("bundled", "sphere", paper=None)),
    ("| sphere | GMC # / # / # / #, generated | | # / # / # / # | # / # / # / # | "
     "# / # / # / # %, # / # / # / # m |",
     lambda: _gmc_row("sphere")),
    ("| sphere | exact optimum, # % / # % | # / # | # / # | # / # | |", lambda: _optimum_row("sphere")),
    ("Ours spends #x (hemisphere) and #x (sphere) the views of the exact optimum for the coverage it actually reached "
     "(generated pairs; #x / #x on the real tomato), and #x / #x the optimum for # %",
     lambda: [_optimum_ratio("generated", "hemisphere"), _optimum_ratio("generated", "sphere"),
              _optimum_ratio("bundled", "hemisphere"),
              _optimum_ratio("bundled", "sphere"), _optimum_ratio("generated", "hemisphere", "views_ratio_98_mean"),
              _optimum_ratio("generated", "sphere", "views_ratio_98_mean"), "98"]),
    ("Plant complexity (Table II): generated tomato # views (hemisphere) -> # (sphere), maize # -> #",
     lambda: [_table2(n, s) for n in ("tomato", "maize") for s in ("hemisphere", "sphere")]),
    ("tomato needs more views than maize on the hemisphere, as in the paper, but not on the sphere", _species_claim),
    ("GMC now covers more than the paper's GMC, most on the sphere", _gmc_claim),
    ("Inflation (Table III, both view spaces): tomato # -> # views, # -> # %; maize # -> # views, # -> # % "
     "(paper: +# view, +# / +# points)", _inflation),
    ("lowers the Chamfer of the transferred model to the ground truth from # ± # to # ± # mm (Table IV; real tomato "
     "# -> # mm; paper # -> # mm)", _table4),
    ("(# cases, # min # s on # workers) with GMC's own map (`gmc.map_resolution`, # mm)",
     lambda: [str(len(shipped.shipped_rows("table1").query("method == 'ours'"))), NOT_KEPT, NOT_KEPT, NOT_KEPT,
              f"{1000 * make_config('plant').gmc.map_resolution:g}"]),
    ("real tomato: # / # / # / # % with # / # / # / # m (hemisphere), # / # / # / # % with # / # / # / # m (sphere)",
     lambda: _gmc_row("hemisphere", "bundled", paper=False)[4:] + _gmc_row("sphere", "bundled", paper=False)[4:]),
    ("A tie decides on average # / # / # / # of the picks up to # / # / # / # views on the hemisphere and "
     "# / # / # / # on the sphere", _ties),
    ("Before (the warm-up's #-voxel map, lowest index on ties) every gain was # after #-# views and GMC reached "
     "# / # / # / # % (hemisphere) and # / # / # / # % (sphere) on the generated cases.", EARLIER),
    ("with the authors' # mm voxel", lambda: [_gmc_gain_voxel()]),
    ("takes # / # s per case on average (hemisphere / sphere, generated pairs; # / # s on the real tomato)",
     _planning_seconds),
]


# ---------------------------------------------------------------- sources: coverage target prose (docs/results.md)
def _evaluate_cases() -> list[str]:
    """The evaluation's protocol as its rows print it: generated cases, seeds, bundled cases, all, per view space."""
    rows = _md_all_tables("coverage_target_evaluate")[0]
    cases = {(r["source"], r["view_space"]): r["cases"] for r in rows if r["target"] == "0.98"}
    one = lambda source: cases[(source, "hemisphere")] if cases[(source, "hemisphere")] == cases[(source, "sphere")] \
        else "differ"  # noqa: E731
    return [one("generated"), *_md_seeds("coverage_target_evaluate"), one("bundled"), one("all")]


def _below_column(name: str = "coverage_target_evaluate") -> str:
    """The threshold of the printed column cases_below_97pct."""
    header = _md_all_tables(name)[0][0]
    return next(re.fullmatch(r"cases_below_(\d+)pct", c).group(1) for c in header
                if re.fullmatch(r"cases_below_\d+pct", c))


def _asked_99() -> list[str]:
    rows = [_evaluate_row("coverage_target_evaluate", s, "0.99") for s in ("hemisphere", "sphere")]
    means = {f"{float(r['coverage_mean']):.1f}" for r in rows}
    return ["99", means.pop() if len(means) == 1 else f"differ: {means}",
            f"{100 * _benchmark('coverage_target_calibration').ASKED:g}"]


@lru_cache(maxsize=None)
def _benchmark(name: str):
    """A module of benchmarks/ (its constants: what it asks, its margins)."""
    import importlib
    import sys

    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))


def _calibrate(title_start: str, weights: str, space: str) -> dict:
    tables = _md_tables("coverage_target_calibrate")
    title = next(t for t in tables if t.startswith(title_start))
    return next(r for r in tables[title] if r["weights"] == weights and r["view_space"] == space)


def _weightings() -> str:
    tables = _md_tables("coverage_target_calibrate")
    rule = next(rows for t, rows in tables.items() if t.startswith("smallest planning target with mean >="))
    per_space = {s: sum(r["view_space"] == s for r in rule) for s in ("hemisphere", "sphere")}
    return str(per_space["hemisphere"]) if per_space["hemisphere"] == per_space["sphere"] else f"differ {per_space}"


def _chosen_weights() -> list:
    tables = _md_tables("coverage_target_calibrate")
    chosen = next(rows for t, rows in tables.items() if t.startswith("chosen rule"))
    weights = {r["weights"] for r in chosen}
    assert len(weights) == 1, weights
    observed, near, far, inflation = re.fullmatch(r"([\d.]+)/([\d.]+)/([\d.]+)/([\d.]+) @1", weights.pop()).groups()
    by_space = {r["view_space"]: r for r in chosen}
    return [observed, near if near == far else f"near {near}, far {far}", inflation,
            *[by_space[s]["miss ratio"] for s in ("hemisphere", "sphere")],
            *[Printed(by_space[s]["ratio_mean"]) for s in ("hemisphere", "sphere")],
            *[Printed(by_space[s]["coverage_min"]) for s in ("hemisphere", "sphere")]]


def _calibrate_margin() -> str:
    """The benchmark's margin (mean >= 98 % + margin, in points), as its rule table's title prints it."""
    title = next(t for t in _md_tables("coverage_target_calibrate") if t.startswith("smallest planning target"))
    mean = float(re.search(r"mean >= ([\d.]+) %", title).group(1))
    return f"{mean - 98:.1f}"


def _sphere_cap() -> str:
    title = next(t for t in _md_tables("coverage_target_calibrate") if t.startswith("smallest planning target"))
    return re.search(r"'sphere': ([\d.]+)", title).group(1)


def _weighted_miss() -> list:
    weighted = [_evaluate_row("coverage_target_evaluate_weighted", s, "0.98") for s in ("hemisphere", "sphere")]
    plain = [_evaluate_row("coverage_target_evaluate", s, "0.98") for s in ("hemisphere", "sphere")]
    below = [w["cases_below_97pct"] for w in weighted]
    return (["98", *[Printed(w["coverage_mean"]) for w in weighted],
             _below_column("coverage_target_evaluate_weighted") if below == ["1", "1"] else f"cases below: {below}",
             NOT_KEPT, NOT_KEPT, NOT_KEPT, Printed(weighted[0]["coverage_min"]), NOT_KEPT, NOT_KEPT,
             Printed(weighted[1]["coverage_min"])]
            + [Printed(r["ratio_mean"]) for r in plain] + [Printed(r["ratio_mean"]) for r in weighted]
            + [f"{ISSUE_VIEWS_PER_OPTIMUM:g}"])


def _prior_sphere_rule() -> str:
    rows = _md_all_tables("coverage_target_calibrate_prior")[1]
    return next(r["miss ratio"] for r in rows if r["view_space"] == "sphere" and r["asked"] == "0.98")


_COVERAGE_TARGET = [
    ("--mode evaluate`, # min on # workers;", lambda: _md_minutes("coverage_target_evaluate")),
    ("the #-case protocol per view space on generated pairs of seeds #-# plus the bundled real pair's # cases "
     "(# per view space)", _evaluate_cases),
    ("cases < # % `cases_below_97pct`", lambda: [_below_column()]),
]
_COVERAGE_TARGET_PROSE = [
    ("A request of # % gets # % on both view spaces (the rule is calibrated for # %).", _asked_99),
    ("to the ground truth # mm hemisphere, # mm sphere; # / # mm with the prior warm-up)",
     lambda: [Printed(_evaluate_row("coverage_target_evaluate", s, "0.98")["chamfer_truth_mm"])
              for s in ("hemisphere", "sphere")] + [NOT_KEPT, NOT_KEPT]),
    ("A first rule with r = # on the sphere too (calibrated with the geometric warm-up only) missed on the "
     "evaluation seeds: # views, # % mean, # % min, # cases below # % (the bundled real pair: # % mean);", EARLIER),
    ("the sphere's r = # is what the calibration seeds give when the rule must hold for both warm-up NBVs",
     lambda: [_prior_sphere_rule() if float(_prior_sphere_rule()) == float(_calibrated("sphere")) else "differs"]),
    ("Calibrated on seeds #-# only (`python benchmarks/coverage_target_calibration.py --mode calibrate`, "
     "`benchmarks/results/coverage_target_calibrate.md`, # min on # workers: # weightings x # planning targets, the "
     "optimum for # % beside them)",
     lambda: [*_md_seeds("coverage_target_calibrate"), *_md_minutes("coverage_target_calibrate"), _weightings(),
              re.search(r"x (\d+) targets", _md_header("coverage_target_calibrate")).group(1),
              f"{100 * _benchmark('coverage_target_calibration').ASKED:g}"]),
    ("the chosen weights (observed #, transferred #, inflation #, near within one planning voxel; r # / #) predicted "
     "# / # views per optimum with the worst case at # / # %", _chosen_weights),
    ("No weighting beat the unweighted surface at r = # on both view spaces",
     lambda: [_calibrate("smallest planning target with mean >=", "unweighted", "hemisphere")["miss ratio"]]),
    ("the far and inflation classes hold under # % of the voxels", NOT_KEPT),
    ("The calibration was iterated on seeds #-# before the evaluation (a first grid with a #-point margin, then #, "
     "then the sphere's r held at #,",
     lambda: [*_md_seeds("coverage_target_calibrate"), EARLIER, _calibrate_margin(), _sphere_cap()]),
    ("Evaluated once on seeds #-# and the bundled pair", lambda: _md_seeds("coverage_target_evaluate_weighted")),
    ("it misses two of the issue's three targets at # %: the means hold (# / # %), one case per view space falls "
     "below # % (hemisphere maize seed #, rotation #, initial view #: # %; sphere bundled pair, rotation #, initial "
     "view #: # %), and the views per optimum fall only from # / # to # / # (target #)", _weighted_miss),
    ("(# mm truth voxels inside # mm planning voxels",
     lambda: [f"{1000 * make_config('plant').gt_resolution:g}",
              f"{1000 * make_config('plant').selection.cover_resolution:g}"]),
]


# ---------------------------------------------------------------- sources: species prose (docs/results.md)
def _helios_generation() -> list[str]:
    """The Helios dataset as benchmarks/results/helios_generation.md prints it: species x plants x sessions, each
    species' ages (first to last day), the surface sampling."""
    name = next(t for t in _md_tables("helios_generation") if t.startswith("Per species"))
    rows = {r["species"]: r for r in _md_tables("helios_generation")[name]}
    ages = {k: [int(a) for a in r["ages_days"].split()] for k, r in rows.items()}
    plants_ = {r["plants"] for r in rows.values()}
    sessions = {int(r["sessions"]) // int(r["plants"]) for r in rows.values()}
    span = lambda k: [str(min(ages[k])), str(max(ages[k]))]  # noqa: E731
    same = [k for k in ("strawberry", "soybean", "bean") if ages[k] == ages["strawberry"]]
    return ([str(len(rows)), plants_.pop() if len(plants_) == 1 else "differ", str(sessions.pop()),
             *span("tomato"), *(span("strawberry") if len(same) == 3 else ["differ", "differ"]), *span("cowpea"),
             *span("maize"), *span("rice"), *span("sugarbeet"), re.search(r"([\d.]+) mm spacing", name).group(1)])


def _species_protocol() -> list[str]:
    rows = shipped.shipped_rows("species")
    return [*[str(int(v[0])) if len(v := rows[c].unique()) == 1 else f"{c} differs"
              for c in ("rotation_deg", "initial_view")],
            f"{100 * species_module().SPECIES_TARGET:g}"]


def species_module():
    from tpvp.experiments import species

    return species


@lru_cache(maxsize=None)
def _calibration_csv() -> pd.DataFrame:
    return pd.read_csv(ROOT / "benchmarks" / "results" / "species_calibration.csv")


def _calibration_protocol() -> list:
    r = _calibration_csv()
    helios, generated = r[r["source"] == "dataset"], r[r["source"] == "generated"]
    plant = helios["instance"].str.split("-").str[0]  # Maize01-2025-02-26-2025-03-01: plant Maize01
    plants_per_species = helios.assign(plant=plant).groupby("species")["plant"].nunique()
    seeds = generated["instance"].str.extract(r"-generated-(\d+)$")[0].astype(int)
    targets = sorted(r["target"].dropna().unique(), reverse=False)
    asked = species_module().SPECIES_TARGET
    fruit = r[r["kind"] == "organ"]
    fruit_pairs = fruit.groupby("view_space")["instance"].nunique()
    return [str(plants_per_species.iloc[0]) if plants_per_species.nunique() == 1 else "differ",
            *[str(int(v)) for v in helios["initial_view"].unique()],
            str(seeds.min()), str(seeds.max()), *[str(int(v)) for v in generated["rotation_deg"].unique()],
            *[str(int(v)) for v in generated["initial_view"].unique()],
            str(len(r[r["kind"] == "target"]) // len(targets) // r["view_space"].nunique()),
            *[f"{(1 - t) / (1 - asked):.3g}" for t in targets],
            str(fruit_pairs.iloc[0]) if fruit_pairs.nunique() == 1 else "differ",
            str(int(fruit["margin"].min())), str(int(fruit["margin"].max())), NOT_KEPT, NOT_KEPT]


def _organ_prose() -> list[str]:
    organ = _species_tables()["organ_targets"].set_index(["species", "view_space"])
    evaluation = [s for s in organ.index.get_level_values(0).unique()
                  if s.removeprefix("helios ") not in species_module().CALIBRATION_SPECIES]
    reached = {k for k in organ.index if organ.loc[k, "fruit_mean"] >= 0.995}
    claim_evaluation = {k for k in reached if k[0] in evaluation} == {
        ("helios cowpea", "hemisphere"), ("helios cowpea", "sphere"), ("helios strawberry", "hemisphere")}
    claim_calibration = {k for k in reached if k[0] not in evaluation} == {("helios tomato", "hemisphere")}
    saved = 100 * organ["views_saved"]
    full = organ["full_cover_fruit"] * 100
    return [f"{saved.min():.0f}", f"{saved.max():.0f}",
            "99.5" if claim_evaluation and claim_calibration else f"reached by {sorted(reached)}",
            _fruit(organ.loc[("helios strawberry", "sphere"), "fruit_mean"]),
            _fruit(organ.loc[("helios rice", "hemisphere"), "fruit_mean"]),
            _fruit(organ.loc[("helios rice", "sphere"), "fruit_mean"]),
            f"{full.min():.1f}", _hundred(f"{full.max():.1f}")]


_SPECIES_INTRO = [
    ("grew # species x # plants x # sessions (tomato #-# days, strawberry, soybean and bean #-#, cowpea #-#, maize "
     "#-#, rice #-#, sugar beet #-#; the schedule of `benchmarks/helios_generation.py`), # mm surface sampling",
     _helios_generation),
    ("ran on them three times, with organ margins of #, # and # planning voxels",
     lambda: [EARLIER, EARLIER, str(make_config("plant").selection.organ_margin_voxels)]),
    ("(`python benchmarks/species_evaluation.py --dataset DIR`, # min on # workers;",
     lambda: [f"{_provenance('species')['refresh_minutes']:.0f}", str(shipped.PROTOCOLS["species"].workers)]),
    ("plant's last session pair, rotation #, initial view #, paper configuration; \"optimum\" is the fewest views that "
     "truly see # % of the oracle set", _species_protocol),
    # the calibration ran from a grown dataset; its result file was summarised again from the rows (--rows): no time
    ("(`python benchmarks/species_calibration.py --dataset DIR`, # min on # workers;", NOT_KEPT),
    ("maize grown from another seed (`--seed 1`, # plants each, all three session pairs, initial view #) and our "
     "generated tomato and maize of seeds #-# (rotation #, initial views # / # / #), # cases per view space; per case "
     "the plan for every miss ratio r in #, #, #, #, # of the planning target, and on the # pairs whose previous "
     "session holds fruit `fruit=1.0,leaf=0.95` with an organ margin of #-# planning voxels (# and # in a second run "
     "on those pairs)", _calibration_protocol),
]
_SPECIES_END = [
    ("with #-# % fewer views than asking all of it, but the *true* fruit coverage reaches # % on the evaluation "
     "species only on cowpea and the strawberry hemisphere (strawberry sphere # %, rice # % / # %); on the calibration "
     "species the tomato hemisphere reaches it, the maize ear and the tomato's sphere case do not (the full cover "
     "sees #-# % of the fruit)", _organ_prose),
    ("without a margin the fruit came to # (#) / # (#) % on maize, # (#) % on the rice sphere and # % on the tomato "
     "sphere", EARLIER),
    ("but the tomato sphere's # against #:",
     lambda: [EARLIER, _f(_species_tables()["organ_targets"].set_index(["species", "view_space"])
                          .loc[("helios tomato", "sphere"), "organ_target_views"], 0)]),
    ("grows from about # to about # points and three quarters of today's ear lies farther than # mm from the "
     "previous session", NOT_KEPT),
]


# ---------------------------------------------------------------- sources: re-planning prose (docs/results.md)
def _replan(table: int, space: str, ratio: str | None = None) -> dict:
    rows = _md_all_tables("replanning_calibrate")[table]
    return next(r for r in rows if r["view_space"] == space and (ratio is None or r["ratio"] == ratio))


def _replan_calibration() -> list:
    header = _md_header("replanning_calibrate")
    ratios = [f"{float(v):g}" for v in re.search(r"miss ratios \[([\d., ]+)\]", header).group(1).split(",")]
    title = next(t for t in _md_tables("replanning_calibrate") if t.startswith("largest miss ratio"))
    chosen = [_replan(0, s) for s in ("hemisphere", "sphere")]
    picked = {c["ratio"] for c in chosen}
    r1 = [_replan(1, s, "1") for s in ("hemisphere", "sphere")]
    return ([*ratios, *re.findall(r"([\d.]+) %", title)[:2], picked.pop() if len(picked) == 1 else "differ"]
            + [Printed(chosen[0]["coverage_mean"]), Printed(chosen[0]["coverage_min"]),
               Printed(chosen[1]["coverage_mean"]), Printed(chosen[1]["coverage_min"])]
            + [Printed(c["ratio_to_optimum"]) for c in chosen] + ["1"] + [Printed(r["ratio_to_optimum"]) for r in r1]
            + [Printed(r["coverage_min"]) for r in r1])


def _one_shot_on_calibration_seeds() -> list:
    """The one-shot rule on the calibration seeds: coverage_target_calibrate.md, unweighted, at each view space's r."""
    summary = next(rows for t, rows in _md_tables("coverage_target_calibrate").items() if t.startswith("summary"))
    out = []
    for space in ("hemisphere", "sphere"):
        r = float(_calibrated(space))
        target = f"{1 - r * (1 - 0.98):.4g}"
        row = next(x for x in summary
                   if x["view_space"] == space and x["weights"] == "unweighted" and x["target"] == target)
        out += [Printed(row["ratio_mean"]), _calibrated(space)]
        if space == "sphere":
            below = round((1 - float(row["reach_97"])) * int(row["cases"]))
            out += [Printed(row["coverage_min"])] if below == 1 else [f"{below} cases below 97 %"]
    return out


def _replan_evaluation_run() -> list:
    header = _md_header("replanning_evaluate")
    cases = int(re.search(r"\((\d+) cases", header).group(1))
    return [*_md_seeds("replanning_evaluate"), str(cases // 2), *_md_minutes("replanning_evaluate"), NOT_KEPT]


ISSUE_REPLAN_VIEWS = 1.10  # issue 27's targets for re-planning at 0.98: views / optimum, path / one-shot path
ISSUE_REPLAN_PATH = 1.15


def _against_targets() -> list:
    e = {s: _evaluate_row("replanning_evaluate", s, "0.98") for s in ("hemisphere", "sphere")}
    ratio = [float(e[s]["ratio"]) for s in e]
    below = [int(e[s]["cases_below_97pct"]) for s in e]
    path = [float(e[s]["path_ratio"]) for s in e]
    verdicts = (all(r > ISSUE_REPLAN_VIEWS for r in ratio) and below[0] == 0 and below[1] > 0
                and all(p <= ISSUE_REPLAN_PATH for p in path))
    if not verdicts:
        return ["the verdicts (missed / met) no longer hold"]
    return ([f"{_benchmark('replanning').ASKED:g}"] + [Printed(e[s]["ratio"]) for s in e]
            + [f"{ISSUE_REPLAN_VIEWS:.2f}"]
            + [Printed(e[s]["one_shot_ratio"]) for s in e] + [_below_column("replanning_evaluate")]
            + [str(below[1]), e["sphere"]["cases"], Printed(e["sphere"]["coverage_min"]),
               Printed(_replan(0, "sphere")["coverage_min"]), f"{ISSUE_REPLAN_PATH:.2f}"]
            + [Printed(e[s]["path_ratio"]) for s in e])


_REPLANNING = [
    ("seeds #-# only, # cases per view space, re-planning after every view, # min on # workers;",
     lambda: [*_md_seeds("replanning_calibrate"), _replan(0, "hemisphere")["cases"],
              *_md_minutes("replanning_calibrate")]),
    ("the miss ratio r of the planning target in #, #, #, #; the largest whose mean true coverage reaches # % with no "
     "case below # % is # on both view spaces (# % / # % min hemisphere, # % / # % sphere; #x / #x the optimum; r = # "
     "gave #x / #x but # % / # % minima)", _replan_calibration),
    ("rule took #x (hemisphere, r = #) and #x (sphere, r = #, one case at # %)", _one_shot_on_calibration_seeds),
    ("seeds #-# and the bundled pair, # cases per view space, # min on # workers beside another #-worker job;",
     _replan_evaluation_run),
]
_REPLANNING_END = [
    ("Against the issue's targets at #: views / optimum # (hemisphere) and # (sphere), target #: **missed** (from "
     "# / # one-shot); no case below # %: met on the hemisphere, **missed** on the sphere (# of # cases, lowest # %: "
     "the sphere's rule did not carry over from the calibration seeds, where its lowest case was # %); path at most "
     "#x the one-shot plan's: met (# / #)",
     _against_targets),
    ("measured beside another #-worker job (about half speed)", NOT_KEPT),
    ("(about #-# s alone)", NOT_KEPT),
    ("(on two calibration plants, re-planning every # views: #-# unexpected and #-# contradicted planning voxels per "
     "re-plan, of #-# that a view is predicted to see)", NOT_KEPT),
    ("(# / # added and # / # dropped per case, hemisphere / sphere, at r = # on the calibration seeds)",
     lambda: [*[f"{float(_replan(0, s)['views_added']):.1f}" for s in ("hemisphere", "sphere")],
              *[f"{float(_replan(0, s)['views_dropped']):.1f}" for s in ("hemisphere", "sphere")],
              _replan(0, "hemisphere")["ratio"]]),
    ("stays # in the `paper` configuration", lambda: [str(make_config("plant").selection.replan_after)]),
]


# ---------------------------------------------------------------- sources: greenhouse rows (docs/results.md)
@lru_cache(maxsize=None)
def _row_tables() -> dict:
    return rows.tables(shipped.shipped_rows("tables5_6"))


REFERENCE_COLUMNS = ("complete", "candidates", "handheld")  # the table's columns, left to right


def _t6(reference: str, method: str, budget=None, resolution=None) -> pd.Series:
    t = _row_tables()["table6_coverage_effort"]
    t = t[(t["reference"] == reference) & (t["method"] == method)]
    if budget is not None:
        t = t[t["budget"] == budget]
    if resolution is not None:
        t = t[t["cover_resolution_cm"] == resolution]
    assert len(t) == 1, (reference, method, budget, resolution)
    return t.iloc[0]


def _cell(row: pd.Series, method: str, paper: bool = False) -> list[str]:
    views, coverage, path = ((row["paper_views"], row["paper_coverage"], row["paper_path_length_m"]) if paper else
                             (row["views_mean"], row["coverage_mean"], row["path_length_m_mean"]))
    return [_f(views, 1) if method == "ours" else _f(views, 0), _f(coverage),
            _f(path, 2 if method == "coarse" else 1)]


_TABLE6_ROWS = {"passive sweep": ("coarse", None, None), **{
    f"Block-wise NBV {b}, one run": ("blockwise-nbv", b, None) for b in (100, 300, 500)}, **{
    f"{label} random {b}": (method, b, None) for label, method in (
        ("PriorOBB", "prior-obb-random"), ("PriorPassive", "prior-passive-random"),
        ("PriorTransfer", "prior-transfer-random")) for b in (100, 300, 500)}, **{
    f"Ours {r} cm": ("ours", None, r) for r in (10, 5, 4, 3)}}


def _table6_sources() -> list:
    out = []
    for label, (method, budget, resolution) in _TABLE6_ROWS.items():
        def compute(method=method, budget=budget, resolution=resolution):
            cells = [_t6(ref, method, budget, resolution) for ref in REFERENCE_COLUMNS]
            return [v for c in cells for v in _cell(c, method)] + _cell(cells[0], method, paper=True)
        out.append((f"| {label} | # / # / # | # / # / # | # / # / # | # / # / # |", compute))
    return out


def _prefix(reference: str, views: int) -> float:
    t = _row_tables()["blockwise_prefix_curve"]
    t = t[(t["reference"] == reference) & (t["views"] == views)]
    assert len(t) == 1
    return float(t["coverage_mean"].iloc[0])


def _table5(reference: str) -> pd.Series:
    t = _row_tables()["table5_upper_limit"]
    return t[t["reference"] == reference].set_index("prior")


PRIORS = ("obb", "passive", "transfer")


def _table5_row() -> list[str]:
    views = {float(_table5(r)["views_mean"].max()) for r in REFERENCE_COLUMNS}
    return ([f"{views.pop():.0f}" if len(views) == 1 else "differ"]
            + [_f(_table5(r).loc[p, "coverage_mean"]) for r in REFERENCE_COLUMNS for p in PRIORS]
            + [_f(_table5("handheld").loc[p, "paper_coverage_mean"]) for p in PRIORS])


def _row_cases() -> list[str]:
    r = shipped.shipped_rows("tables5_6")
    per_reference = r.groupby("reference")["case"].nunique()
    seeds = r["case"].str.extract(r"seed (\d+)")[0].unique()
    first, last = int(r["previous_session"].min()), int(r["previous_session"].max())
    return [str(per_reference.iloc[0]) if per_reference.nunique() == 1 else "differ",
            seeds[0] if len(seeds) == 1 else "differ", str(first), str(first + 1), str(last), str(last + 1)]


def _row_run() -> list:
    config = make_config("row")
    r = shipped.shipped_rows("tables5_6")
    cases = str(r.groupby(["reference", "case"]).ngroups)
    return [f"{100 * config.gt_resolution:g}", f"{config.sensor.max_range:g}", NOT_KEPT, NOT_KEPT, cases, cases]


def _warm_start() -> list[str]:
    coarse = _t6("handheld", "coarse")
    r = shipped.shipped_rows("tables5_6")
    random = r[r["method"].str.endswith("random")]
    repetitions = random.groupby(["reference", "case", "method", "budget"])["repetition"].nunique()
    return [f"{coarse['views_mean']:.0f}", _f(coarse["path_length_m_mean"]),
            str(repetitions.iloc[0]) if repetitions.nunique() == 1 else "differ"]


def _what_the_reference_moves() -> list:
    t = _row_tables()["table6_coverage_effort"]
    keys = ["method", "budget", "cover_resolution_cm"]
    spread = t.groupby(keys, dropna=False)["coverage_mean"].agg(lambda c: c.max() - c.min()).max()
    ours = t[t["method"] == "ours"].groupby("cover_resolution_cm")
    views = ours["views_mean"].agg(lambda v: v.max() / v.min() - 1).max()
    path = ours["path_length_m_mean"].agg(lambda v: v.max() / v.min() - 1).max()
    return [f"{spread:.0f}", f"{100 * views:.1f}", f"{100 * path:.0f}"]


def _sweep_and_candidates() -> list:
    coarse = _t6("handheld", "coarse")
    upper = _table5("handheld")
    return [_f(coarse["coverage_mean"], 1), _f(coarse["paper_coverage"], 1), _table5_row()[0],
            _f(upper["coverage_mean"].min(), 1), _f(upper["coverage_mean"].max(), 1),
            _f(upper["paper_coverage_mean"].min(), 1), _f(upper["paper_coverage_mean"].max(), 1)]


def _ours_against_random() -> list:
    ours = {r: _t6(r, "ours", resolution=5) for r in REFERENCE_COLUMNS}
    baselines = ("prior-obb-random", "prior-passive-random", "prior-transfer-random")
    best_random = {r: max(_t6(r, m, 300)["coverage_mean"] for m in baselines) for r in REFERENCE_COLUMNS}
    if not all(ours[r]["coverage_mean"] > best_random[r] for r in REFERENCE_COLUMNS):
        return ["Ours no longer sees more than every random baseline"]
    transfer = {r: _t6(r, "prior-transfer-random", 300) for r in REFERENCE_COLUMNS}
    return ["5", _f(ours["handheld"]["coverage_mean"]), f"{ours['handheld']['views_mean']:.0f}",
            _f(transfer["handheld"]["coverage_mean"]), f"{transfer['handheld']['views_mean']:.0f}",
            _f(ours["candidates"]["coverage_mean"]), _f(transfer["candidates"]["coverage_mean"])]


def _monotone_claim() -> list[str]:
    rises = all(all(a < b for a, b in zip(c, c[1:])) for c in (
        [_t6(r, "ours", resolution=cm)["coverage_mean"] for cm in (10, 5, 4, 3)] for r in REFERENCE_COLUMNS))
    return _claim(rises, "Ours' coverage rises as the covering voxel shrinks, with every reference")


def _paper_between_claim() -> list[str]:
    sweep = [_t6(r, "coarse")["coverage_mean"] for r in ("complete", "candidates")]
    paper_sweep = _t6("handheld", "coarse")["paper_coverage"]
    upper = [(_table5("complete").loc[p, "coverage_mean"], _table5("handheld").loc[p, "coverage_mean"],
              _table5("handheld").loc[p, "paper_coverage_mean"]) for p in PRIORS]
    return _claim(sweep[0] < paper_sweep < sweep[1] and all(lo < paper < hi for lo, hi, paper in upper),
                  "the paper's sweep share between complete and candidates, its Table V between complete and handheld")


def _blockwise_path() -> list:
    nbv = _t6("handheld", "blockwise-nbv", 300)
    ours5 = _t6("handheld", "ours", resolution=5)
    ours4 = _t6("candidates", "ours", resolution=4)
    low, high = _t6("candidates", "blockwise-nbv", 100), _t6("candidates", "blockwise-nbv", 300)
    share = (ours4["coverage_mean"] - low["coverage_mean"]) / (high["coverage_mean"] - low["coverage_mean"])
    interpolated = low["path_length_m_mean"] + share * (high["path_length_m_mean"] - low["path_length_m_mean"])
    ratios = sorted([nbv["path_length_m_mean"] / ours5["path_length_m_mean"],
                     interpolated / ours4["path_length_m_mean"]])
    return [f"{ratios[0]:.0f}", f"{ratios[1]:.0f}", _f(nbv["coverage_mean"]), f"{nbv['views_mean']:.0f}",
            _f(nbv["path_length_m_mean"], 1), _f(ours5["coverage_mean"]), "5", _f(ours5["path_length_m_mean"], 1),
            f"{interpolated:.0f}", _f(ours4["coverage_mean"]), "4", _f(ours4["path_length_m_mean"], 1)]


def _paper_blockwise() -> list:
    paper = [_t6("handheld", "blockwise-nbv", b)["paper_coverage"] for b in (100, 300, 500)]
    below = all(_t6(r, "blockwise-nbv", b)["coverage_mean"] > p for r in REFERENCE_COLUMNS
                for b, p in zip((100, 300, 500), paper))
    at100 = [_prefix(r, 100) for r in REFERENCE_COLUMNS]
    at300 = [_prefix(r, 300) for r in ("complete", "candidates")]
    if not (below and all(v < paper[0] for v in at100) and at300[0] < paper[1] < at300[1]):
        return ["the comparison with the paper's Block-wise NBV no longer holds"]
    return ([_f(p, 1) for p in paper] + ["100"] + [_f(v, 1) for v in at100] + ["300"] + [_f(v, 1) for v in at300])


def _blocks() -> str:
    config = make_config("row").blockwise
    return str(config.blocks_along * config.bands)


def _views_against_paper() -> list:
    out = []
    for resolution in (10, 5, 3):
        views = [_t6(r, "ours", resolution=resolution)["views_mean"] for r in REFERENCE_COLUMNS]
        paper = _t6("handheld", "ours", resolution=resolution)["paper_views"]
        out.append((resolution, f"{min(views):.0f}", f"{max(views):.0f}",
                    f"{paper:.1f}" if paper % 1 else f"{paper:.0f}"))
    return [str(out[0][0]), str(out[1][0]), out[0][1], out[0][2], out[0][3], out[1][1], out[1][2], out[1][3],
            str(out[2][0]), out[2][1], out[2][2], out[2][3]]


_ROWS = [
    ("on the # generated cases (room1 and room4, seed #, pairs #-># ... #->#) once per reference", _row_cases),
    ("`paper-row` configuration (# cm ground truth, # m range), # workers: # min for the # cases from empty caches "
     "(# oracles included)", _row_run),
    ("include its # views and # m; random baselines averaged over # repetitions per case first", _warm_start),
    *_table6_sources(),
    ("| Block-wise NBV, prefix # / # of the #-view run | # / # % | # / # % | # / # % | |",
     lambda: ["100", "300", "500"] + [_f(_prefix(r, v)) for r in REFERENCE_COLUMNS for v in (100, 300)]),
    ("| Table V: all # candidates, PriorOBB / PriorPassive / PriorTransfer | # / # / # % | # / # / # % | # / # / # % "
     "| # / # / # % |", _table5_row),
    ("every coverage, by up to # points, and hardly any view count or path (each reference filters both sessions the "
     "same way; Ours' views change by at most # % between references, its paths by at most # %)",
     _what_the_reference_moves),
    ("(about # m from the row's mid-plane, along the aisle)", CODE_FACT),
    ("the passive sweep alone sees # % of its oracle (paper # %), all # candidates of any prior #-# % (paper #-# %)",
     _sweep_and_candidates),
    ("(handheld, # cm: # % with # views against # % with #; candidates: # against # %)", _ours_against_random),
    ("coverage rises monotonically as the covering voxel shrinks", _monotone_claim),
    ("its sweep share sits between our `complete` and `candidates` references, its Table V between `complete` and "
     "`handheld`", _paper_between_claim),
    ("Block-wise NBV needs #-#x Ours' path for the same coverage (handheld: # % after # views on # m, Ours # % at # cm "
     "on # m; candidates: about # m interpolated for Ours' # % at # cm on # m)", _blockwise_path),
    ("read as prefixes of its #-view run", lambda: [str(max(make_config("row").protocol.nbv_budgets))]),
    ("its first # views visit only # of the # blocks", lambda: ["100", NOT_KEPT, _blocks()]),
    ("The paper's Block-wise NBV (# / # / # %) lies below our runs per budget with every reference; against our "
     "prefixes it lies above all three references at # views (# / # / # %) and between the `complete` and "
     "`candidates` prefixes at # views (# / # %)", _paper_blockwise),
    ("our three-state # cm map", lambda: [f"{100 * make_config('row').blockwise.map_resolution:g}"]),
    ("it selects more views at # and # cm (#-# against # and #-# against #) and fewer at # cm (#-# against #)",
     _views_against_paper),
    ("reached # / # / # % of the `candidates` rows", NOT_KEPT),
]


# ---------------------------------------------------------------- sources: why Ours selects more views
def _view_count(surface: str = "planning surface", candidates: str = "ours", reference: str = "handheld") -> dict:
    rows_ = _md_all_tables("row_view_count")[0]
    return {r["cover_cm"]: r for r in rows_ if r["reference"] == reference and r["surface"] == surface
            and r["candidates"] == candidates}


def _paper_planned(resolution: int) -> float:
    passive = _t6("handheld", "coarse")["views_mean"]
    return float(_t6("handheld", "ours", resolution=resolution)["paper_views"] - passive)


def _scaled(text: str, factor: float = 100) -> Printed:
    return Printed(f"{factor * float(text):.6g}")


def _planned(resolution: int) -> Printed:
    """Ours' planned views on the handheld reference (the printout's ``selected``): views less the passive sweep's,
    from the shipped rows (the printout's 4 digits cannot round 394.25 as the page does)."""
    planned = _t6("handheld", "ours", resolution=resolution)["views_mean"] - _t6("handheld", "coarse")["views_mean"]
    selected = float(_view_count()[str(resolution)]["selected"])
    same = Printed(f"{selected:g}").matches(f"{planned:.2f}")
    return _f(planned, 1) if same else f"rows {planned}, printout {selected}"


def _view_count_row(cm: str) -> list:
    r = _view_count()[cm]
    n = int(re.search(r"\((\d+) cases", _md_header("row_view_count")).group(1)) // 2  # per reference
    counts = lambda value: Printed(value, cases=n)  # noqa: E731  (means of whole numbers over the cases)
    return [counts(r[c]) for c in ("planning_voxels", "left_to_cover", "voxels_one_candidate")] + [
        _scaled(r["one_candidate_behind_front"]), counts(r["forced_views"]), Printed(r["voxels_per_candidate"]),
        _planned(int(cm)), counts(r["selected_front_1_layers"]), counts(r["selected_front_2_layers"]),
        counts(_view_count(candidates="authors' PriorTemporal")[cm]["selected"]),
        counts(_view_count("aligned previous only")[cm]["selected"]), _f(_paper_planned(int(cm)), 1)]


def _same_picture() -> list[str]:
    columns = ("planning_voxels", "left_to_cover", "voxels_one_candidate", "one_candidate_behind_front",
               "forced_views", "voxels_per_candidate", "selected", "selected_front_1_layers", "selected_front_2_layers")

    def most(surface, candidates, cols):
        a, b = _view_count(surface, candidates), _view_count(surface, candidates, "candidates")
        return max(abs(float(b[cm][c]) / float(a[cm][c]) - 1) for cm in a for c in cols)
    planning = max(most("planning surface", c, columns) for c in ("ours", "authors' PriorTemporal"))
    selected = max(most("planning surface", c, ("selected",)) for c in ("ours", "authors' PriorTemporal"))
    previous = most("aligned previous only", "ours", columns)
    return [f"{100 * selected:.0f}", f"{100 * planning:.0f}", f"{100 * previous:.0f}"]


def _view_count_layers() -> list[str]:
    """The numbers in the column names: voxels seen by one candidate, the front layers of the second restriction."""
    header = list(_md_all_tables("row_view_count")[0][0])
    one = re.search(r"voxels_(one)_candidate", " ".join(header))
    layers = [re.fullmatch(r"selected_front_(\d+)_layers", c).group(1) for c in header
              if re.fullmatch(r"selected_front_\d+_layers", c)]
    return ["1" if one else "no column", layers[-1]]


def _authors_fewer(cm: str) -> str:
    authors = float(_view_count(candidates="authors' PriorTemporal")[cm]["selected"])
    return f"{100 * (1 - authors / float(_view_count()[cm]['selected'])):.0f}"


def _flatter() -> list:
    selected = {ref: _view_count(reference=ref) for ref in ("handheld", "candidates")}
    at3 = sorted(float(selected[ref]["3"]["selected"]) for ref in selected)
    return [EARLIER, "10", f"{float(selected['handheld']['10']['selected']):.0f}", "10", f"{at3[0]:.0f}",
            f"{at3[1]:.0f}",
            "3", f"{_paper_planned(10):.0f}", f"{_paper_planned(3):.0f}"]


def _deep_voxels() -> list:
    v = _view_count()
    behind = [100 * float(v[cm]["one_candidate_behind_front"]) for cm in v]
    front = [float(v["10"][c]) for c in ("selected_front_1_layers", "selected_front_2_layers")]
    paper = _paper_planned(10)
    if not front[0] < paper < front[1]:
        return ["the paper's count no longer lies between the front layers'"]
    return [f"{min(behind):.0f}", f"{max(behind):.0f}", Printed(v["10"]["forced_views"]), Printed(v["10"]["selected"]),
            "10", f"{front[0]:.0f}", "10", f"{front[1]:.0f}", f"{paper:.0f}", f"{paper:.0f}",
            f"{_paper_planned(3):.0f}", "10", "3", f"{float(v['10']['selected']):.0f}",
            f"{float(v['3']['selected']):.0f}"]


def _target_missed() -> list:
    out = [Printed(_view_count()["10"]["selected"]), Printed(_view_count()["10"]["views (passive included)"]), "10"]
    for i, cm in enumerate((10, 5, 4, 3)):
        ours = _t6("handheld", "ours", resolution=cm)
        paper = ours["paper_views"]
        ratio = ours["views_mean"] / paper
        if i == 0:
            out += [_f(paper, 1), _f(ratio, 1)]
        else:
            out += [f"{ours['views_mean']:.0f}", f"{paper:.0f}", str(cm), _f(ratio)]
    return out


_WHY_10_CM = [
    ("Why Ours selects more views at # cm", lambda: [f"{100 * max(make_config('row').protocol.cover_resolutions):g}"]),
    ("| seen by # candidate (behind the front) | views forced by them | views per candidate (voxels) | selected | "
     "front layer only | front # layers |", lambda: _view_count_layers()),
    ("\"front layer only\" and \"front # layers\" solve the same cover", lambda: _view_count_layers()[1:]),
    ("deep voxels visible through gaps at # cm and many hard ones at # cm", lambda: ["10", "3"]),
    ("Ours selects #x the paper's views at a # cm covering voxel (and why its curve is flatter: # planned views at "
     "# cm, #-# at # cm, against the paper's # and #)", _flatter),
    ("(# cases, # min; `benchmarks/results/row_view_count.md`) measures the set-cover instance; means over the # cases "
     "of the handheld reference",
     lambda: [re.search(r"\((\d+) cases", _md_header("row_view_count")).group(1), NOT_KEPT,
              str(int(re.search(r"\((\d+) cases", _md_header("row_view_count")).group(1)) // 2)]),
    ("(\"selected\" and the paper are planned views, without the # passive ones;",
     lambda: [f"{_t6('handheld', 'coarse')['views_mean']:.0f}"]),
    ("its selected views differ by at most # %, its other columns by at most # %, and those of the aligned previous "
     "session alone by at most # %.)", _same_picture),
    ("the registered previous session + the # cm inflation + the passive cloud", CODE_FACT),
    ("the # PriorTemporal candidates (# targets x # rounds; # views = # passive + # positions, # of them without a "
     "look-at and excluded)", CODE_FACT),
    ("(Gurobi, # s)", CODE_FACT),
    ("instead of our targets, # % fewer views at # cm.",
     lambda: [_authors_fewer("10"), "10"]),
    ("truncated pixel # m deep", CODE_FACT),
    ("it changes the # cm count by +# and +# views, the # cm count by -# and -#, the # cm count by +# and +# (room1 "
     "pair #, room4 pair #)", NOT_KEPT),
    ("#-# % of the voxels that a single candidate sees lie one or more covering voxels behind the row's front surface: "
     "a candidate sees them through a gap in the generated canopy, and each forces its view (# of the # at # cm). "
     "Covering the front layer alone takes # views at # cm, two layers #; the paper's # lies between. The paper's "
     "curve rises much faster (# -> # from # to # cm, ours # -> #)", _deep_voxels),
    ("Target missed: # planned views (# with the sweep) at # cm against the paper's # (#x), # against # at # cm "
     "(#x), # against # at # cm (#x), # against # at # cm (#x)", _target_missed),
    ("(a #-degree roll: # degrees wide, # high;", CODE_FACT),
    ("On room1 pair # and room4 pair # (handheld) portrait lowers the sweep's coverage by # and # points and changes "
     "Ours' views by # to #.", NOT_KEPT),
]
_WHY_10_CM += [
    (f"| {cm} cm | # | # | # (# %) | # | # | # | # | # | # | # | # |", lambda cm=cm: _view_count_row(cm))
    for cm in ("10", "5", "3")]


# ---------------------------------------------------------------- sources: Table VII (docs/results.md)
@lru_cache(maxsize=None)
def _table7() -> pd.DataFrame:
    return rows.tables(shipped.shipped_rows("table7"))["table7_pose_noise"]


def _table7_row(sigma_t: float, sigma_r: float, icp) -> list:
    t = _table7()
    ours = t[(t["sigma_t_m"] == sigma_t) & (t["sigma_r_deg"] == sigma_r) & (t["icp"] == bool(icp))].iloc[0]
    p = rows.paper_pose_noise()
    paper = p[(p["sigma_t_m"] == sigma_t) & (p["sigma_r_deg"] == sigma_r)
              & (p["icp"] == ("-" if icp is None else "ON" if icp else "OFF"))].iloc[0]
    return [_f(ours["chamfer_mm_mean"]), _f(ours["chamfer_mm_std"]), EARLIER, EARLIER,
            *[v for c in ("precision", "recall", "f1") for v in (_f(100 * ours[f"{c}_10mm_mean"], 1), EARLIER)],
            _f(paper["chamfer_mm_mean"]), _f(paper["precision_1cm_mean"], 1), _f(paper["f1_1cm_mean"], 1)]


_TABLE7_LEVELS = {"0, 0": (0.0, 0.0, None), "0.002, 0.5 | off": (0.002, 0.5, False),
                  "0.005, 1 | off": (0.005, 1.0, False),
                  "0.01, 2 | off": (0.01, 2.0, False), "0.002, 0.5 | on": (0.002, 0.5, True),
                  "0.005, 1 | on": (0.005, 1.0, True), "0.01, 2 | on": (0.01, 2.0, True)}


def _table7_run() -> list:
    r = shipped.shipped_rows("table7")
    noisy = r[r["sigma_t_m"] > 0]
    draws = noisy.groupby(["case", "sigma_t_m", "icp"])["draw"].nunique()
    return [_f(r["views"].mean(), 1), str(r["case"].nunique()),
            str(draws.iloc[0]) if draws.nunique() == 1 else "differ",
            NOT_KEPT, NOT_KEPT, EARLIER, EARLIER, EARLIER, "1"]


def _icp_drift() -> list:
    r = shipped.shipped_rows("table7")
    noisy = r[r["sigma_t_m"] > 0]
    accepted = noisy[noisy["icp"]].groupby("sigma_t_m")["icp_accepted"].mean()
    drift = noisy.groupby(["icp", "sigma_t_m"])["drift_mm"].mean()
    accepted_ = {f"{v:.0f}" for v in accepted}
    return [accepted_.pop() if len(accepted_) == 1 else "differ", _f(r["views"].mean(), 1),
            _f(drift[True].min()), _f(drift[True].max()), f"{drift[False].min():.0f}", f"{drift[False].max():.0f}",
            EARLIER, EARLIER, EARLIER, EARLIER]


def _milder() -> list:
    t = _table7()
    largest = t[(t["sigma_t_m"] == t["sigma_t_m"].max()) & ~t["icp"]].iloc[0]
    free = t[t["sigma_t_m"] == 0].iloc[0]
    p = rows.paper_pose_noise()
    return ["1", _f(100 * largest["precision_10mm_mean"], 1), _f(p["precision_1cm_mean"].min(), 1),
            _f(100 * free["recall_10mm_mean"], 1), _f(p[p["sigma_t_m"] == 0]["recall_1cm_mean"].iloc[0], 1)]


_TABLE7 = [
    ("Ours at # cm on the handheld reference", lambda: [f"{make_config('row').pose_noise.cover_resolution * 100:g}"]),
    ("# views per case, # cases x # draws per level, # min on # workers with the rows' oracles cached while other jobs "
     "shared the cores; in brackets the earlier run on the candidates reference, `--reference candidates`, # views per "
     "case, # min # s; Chamfer in mm, precision / recall / F1 in % at tau = # cm", _table7_run),
    *[(f"| {key.split(' | ')[0]} | {'-' if icp is None else 'on' if icp else 'off'} | # ± # [# ± #] | # [#] | "
       "# [#] | "
       "# [#] | # / # / # |", lambda st=st, sr=sr, icp=icp: _table7_row(st, sr, icp))
      for key, (st, sr, icp) in _TABLE7_LEVELS.items()],
    ("Before the registration fix (candidates reference, # views per case): the same to within # mm and # points "
     "(largest level with ICP # ± # mm, F1 # %)", EARLIER),
    ("ICP accepts # of # views, residual drift #-# mm against #-# mm without it; on the earlier candidates run # of "
     "# views, #-# mm)", _icp_drift),
    ("(precision at # cm # % against # % at the largest level) and our noise-free recall higher (# against # %)",
     _milder),
    ("voxel centres of a # cm simulator", lambda: [f"{100 * make_config('row').gt_resolution:g}"]),
]


# ---------------------------------------------------------------- sources: learned baselines (docs/results.md)
def _dataclass_default(path: str, name: str, field: str):
    """A dataclass field's default as the source writes it (read, not imported: tpvp.learning.training imports
    torch)."""
    import ast

    tree = ast.parse((ROOT / path).read_text())
    cls = next(n for n in ast.walk(tree) if isinstance(n, ast.ClassDef) and n.name == name)
    return next(ast.literal_eval(n.value) for n in cls.body
                if isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name) and n.target.id == field)


def _learning_metrics(kind: str) -> pd.Series:
    m = pd.read_csv(ROOT / "tpvp" / "data" / "learning" / "metrics.csv")
    return m[(m["kind"] == kind) & (m["weights"] == "shipped")].iloc[0]


def _history(kind: str) -> pd.DataFrame:
    return pd.read_csv(ROOT / "tpvp" / "data" / "learning" / f"{kind}_history.csv")


def _training(kind: str) -> list[str]:
    m, h = _learning_metrics(kind), _history(kind)
    per_round = h["states_seen"].diff().dropna().unique()
    return [_f(m["seconds"] / 60, 1), f"{m['rounds']:.0f}", str(int(per_round[0])) if len(per_round) == 1 else "differ",
            _f(m["epochs"]), str(int(h.loc[h["validation_loss"].idxmin(), "round"]))]


def _dataset() -> list:
    from tpvp.learning.dataset import DatasetConfig

    d = DatasetConfig()
    per_species = {f"{d.train_plants // len(d.species)}"}
    return [str(d.train_plants), *[per_species.copy().pop() for _ in d.species], str(d.rotations),
            str(d.validation_plants),
            str(d.test_plants), str(d.held_out_rotations), NOT_KEPT, str(d.n1), NOT_KEPT, NOT_KEPT, NOT_KEPT]


def _weights_files() -> list[str]:
    folder = ROOT / "tpvp" / "data" / "learning"
    return [_f((folder / "ma-scvp.pt").stat().st_size / 1e6, 1), f"{_learning_metrics('ma-scvp')['parameters']:.0f}",
            _f((folder / "pc-nbv.pt").stat().st_size / 1e6, 2), f"{_learning_metrics('pc-nbv')['parameters']:.0f}"]


def _held_out() -> list:
    from tpvp.learning.dataset import DatasetConfig

    d = DatasetConfig()
    seeds = d.seeds("test")
    ma, pc = _learning_metrics("ma-scvp"), _learning_metrics("pc-nbv")
    return [str(seeds.start), str(seeds.stop - 1), NOT_KEPT, NOT_KEPT, NOT_KEPT, _f(ma["test_recall"], 3),
            _f(ma["test_precision"], 3), CODE_FACT, NOT_KEPT, NOT_KEPT, NOT_KEPT, NOT_KEPT, _f(pc["test_spearman"]),
            NOT_KEPT, NOT_KEPT, _f(pc["test_chosen_rank"], 1), _f(100 * pc["test_chosen_best"], 0)]


def _learned_row(space: str, method: str, paper: str | None) -> list:
    out = _mean_std(_t1("generated", space, method, name="table1_learned"))
    if paper:
        p = _paper_plant("I", space, paper)
        out += [_f(p["views_mean"]), _f(p["coverage_mean"]), _f(p["path_mean"])]
    return out


def _over_prediction() -> list[str]:
    t = {(s, m): _t1("generated", s, m, name="table1_learned") for s in ("hemisphere", "sphere")
         for m in ("ma-scvp", "ma-scvp-oracle")}
    views = [t[(s, "ma-scvp")]["views_mean"] - t[(s, "ma-scvp-oracle")]["views_mean"] for s in ("hemisphere", "sphere")]
    coverage = [t[(s, "ma-scvp-oracle")]["coverage_mean"] - t[(s, "ma-scvp")]["coverage_mean"]
                for s in ("hemisphere", "sphere")]
    oracle = [t[(s, "ma-scvp-oracle")]["views_mean"] for s in ("hemisphere", "sphere")]
    paper = _paper_plant("I", "hemisphere", "ma-scvp")
    sphere = min(t[("sphere", m)]["coverage_mean"] for m in ("ma-scvp", "ma-scvp-oracle"))
    weight = _dataclass_default("tpvp/learning/training.py", "TrainConfig", "positive_weight")
    return ["1", f"{weight:g}", _f(min(views), 1), _f(max(views), 1), _f(min(coverage)),
            _f(max(coverage)), _f(min(oracle), 0), _f(max(oracle), 0), f"{1000 * make_config('plant').gt_resolution:g}",
            _f(paper["views_mean"], 1), _f(paper["coverage_mean"], 1), _f(sphere, 1)]


def _real_ma_scvp() -> list[str]:
    rows_ = [_t1("bundled", s, "ma-scvp", name="table1_learned") for s in ("hemisphere", "sphere")]
    return [str(int(rows_[0]["cases"])), _f(rows_[0]["views_mean"]), _f(rows_[0]["coverage_mean"]),
            _f(rows_[1]["views_mean"]), _f(rows_[1]["coverage_mean"])]


def _views_of(space: str) -> int:
    from tpvp.viewspace.space import get_view_space

    return len(get_view_space(space).positions)


_LEARNED = [
    ("generated # training plants (# tomato, # maize) at # rotations, # validation and # test plants at #, and drew "
     "# states by MA-SCVP's long-tail rule (n1 = #): # train / # validation / # test", _dataset),
    ("Measured on this #-core machine: dataset # min (while other jobs shared the cores)", NOT_KEPT),
    ("MA-SCVP # min (# rounds of # states = # epochs, best round #,", lambda: _training("ma-scvp")),
    ("PC-NBV # min (# rounds of # = # epochs, best round #): # min in all (budget #)",
     lambda: _training("pc-nbv") + [NOT_KEPT, CODE_FACT]),
    ("(# MB, # parameters) and `pc-nbv.pt` (# MB, # parameters)", _weights_files),
    ("repeated the first one's # rounds to every printed digit", NOT_KEPT),
    ("Inference on # cores (`python benchmarks/learned_inference_bench.py`): MA-SCVP # ms per call (max #, grid ray "
     "insertion included), PC-NBV # ms (max #), the geometric NBV # ms (target # ms).", NOT_KEPT),
    ("Held-out test plants (seeds #-#; `python -m tpvp.learning evaluate --executed 1 2`, the shipped weights on the "
     "dataset's # test states, # of them after one view and # after two): MA-SCVP recall # and precision # of the "
     "label set at # (after two views, the state it sees in Table I: recall #, precision #, # views predicted for # "
     "in the label); PC-NBV Spearman # between predicted and true gains (# on one-view states, # on two-view states), "
     "the chosen view's true-gain rank # on average (# % a best view)", _held_out),
    ("This page said # on one-view states before the command printed it; # is what it prints.",
     lambda: [EARLIER, NOT_KEPT]),
    ("Table I on the # generated cases per view space (`tpvp experiments plants --methods ours ours-pc-nbv ma-scvp "
     "ma-scvp-oracle`, # min on # workers)",
     lambda: [str(int(_t1("generated", "hemisphere", "ours", name="table1_learned")["cases"])), NOT_KEPT, NOT_KEPT]),
    ("| hemisphere | MA-SCVP (# PC-NBV view + network) | # ± # | # ± # | # ± # | # / # / # |",
     lambda: [str(make_config("plant").nbv.warm_up_views), *_learned_row("hemisphere", "ma-scvp", "ma-scvp")]),
    ("| hemisphere | MA-SCVP with oracle labels | # ± # | # ± # | # ± # | |",
     lambda: _learned_row("hemisphere", "ma-scvp-oracle", None)),
    ("| hemisphere | Ours | # ± # | # ± # | # ± # | # / # / # |",
     lambda: _learned_row("hemisphere", "ours", "ours")),
    ("| sphere | MA-SCVP (first # views only) | # ± # | # ± # | # ± # | # / # / # |",
     lambda: [str(_views_of("hemisphere")), *_learned_row("sphere", "ma-scvp", "ma-scvp")]),
    ("| sphere | MA-SCVP with oracle labels | # ± # | # ± # | # ± # | |",
     lambda: _learned_row("sphere", "ma-scvp-oracle", None)),
    ("| sphere | Ours | # ± # | # ± # | # ± # | # / # / # |", lambda: _learned_row("sphere", "ours", "ours")),
    ("(its label-# weight is #, as in the released checkpoint): #-# views more than the exact set it learns, and still "
     "#-# points less coverage. Even its oracle labels need #-# views here, because the label is the full cover of "
     "every visible # mm voxel; the paper's # views at # % suggest its labels or voxels were coarser. On the sphere "
     "both stay near # %", _over_prediction),
    ("Real tomato pair (# cases each): MA-SCVP # views / # % (hemisphere), # / # % (sphere)", _real_ma_scvp),
]


def _warm_up_row(space: str, method: str, after_17: bool) -> list[str]:
    r = shipped.shipped_rows("table1_learned")
    r = r[(r["source"] == "generated") & (r["view_space"] == space) & (r["method"] == method)]
    t = _t1("generated", space, method, name="table1_learned")
    out = [_f(100 * r["coverage_after_warm_up"].mean(), 1), f"{r['warm_up_rank'].median():g}",
           str(_views_of(space) - 1)]
    if after_17:
        out += ["17", f"{r[r['initial_view'] == 17]['warm_up_rank'].median():g}"]
    return out + [_f(r["chamfer_truth_mm"].mean(), 3), _f(t["views_mean"]), _f(t["coverage_mean"]),
                  _f(t["path_length_m_mean"])]


def _same_plans() -> list[str]:
    views, coverage = [], []
    for space in ("hemisphere", "sphere"):
        a, b = (_t1("generated", space, m, name="table1_learned") for m in ("ours", "ours-pc-nbv"))
        views.append(abs(a["views_mean"] - b["views_mean"]))
        coverage.append(abs(a["coverage_mean"] - b["coverage_mean"]))
    real = [_t1("bundled", "hemisphere", m, name="table1_learned")["views_mean"] for m in ("ours", "ours-pc-nbv")]
    return [_f(max(views), 1), _f(max(coverage)), _f(real[1] - real[0], 1)]


_WARM_UP = [
    ("same # generated cases",
     lambda: [str(int(_t1("generated", "hemisphere", "ours-pc-nbv", name="table1_learned")["cases"]))]),
    ("| hemisphere | geometric | # % | # of # (after view #: #) | # | # | # | # |",
     lambda: _warm_up_row("hemisphere", "ours", True)),
    ("| hemisphere | PC-NBV | # % | # of # (after view #: #) | # | # | # | # |",
     lambda: _warm_up_row("hemisphere", "ours-pc-nbv", True)),
    ("| sphere | geometric | # % | # of # | # | # | # | # |", lambda: _warm_up_row("sphere", "ours", False)),
    ("| sphere | PC-NBV | # % | # of # (hemisphere views only) | # | # | # | # |",
     lambda: _warm_up_row("sphere", "ours-pc-nbv", False)),
    ("the final plans are the same within # view and # points; on the real tomato pair it costs # views in the "
     "hemisphere", _same_plans),
]


# ---------------------------------------------------------------- sources: Table I in the world (issue 49)
def _world(frame: str, noise: str, space: str) -> dict:
    table = next(rows_ for title, rows_ in _md_tables("table1_world").items() if title.startswith("Ours by planning"))
    return next(r for r in table if (r["frame"], r["noise"], r["view_space"]) == (frame, noise, space))


def _world_row(frame: str, noise: str) -> list:
    return [Printed(_world(frame, noise, space)[column]) for space in ("hemisphere", "sphere")
            for column in ("views", "coverage_pct", "lowest_coverage_pct")]


def _world_header() -> list:
    made = re.search(r"\((\d+) cases, Ours, (\d+) worker\(s\), ([\d.]+) min\)", _md_header("table1_world"))
    cases = int(made.group(1))
    return [str(cases), str(cases // 2), made.group(3), made.group(2)]


def _world_ratio(frame: str, noise: str) -> list:
    return [Printed(_world(frame, noise, s)["views vs current/ideal"]) for s in ("hemisphere", "sphere")]


def _world_previous() -> list:
    rows_ = {s: (_world("current", "ideal", s), _world("previous", "ideal", s)) for s in ("hemisphere", "sphere")}
    return (_world_ratio("previous", "ideal")
            + [_f(float(rows_[s][1]["coverage vs current/ideal (points)"])) for s in ("hemisphere", "sphere")]
            + [_f(float(rows_[s][0]["lowest_coverage_pct"]) - float(rows_[s][1]["lowest_coverage_pct"]))
               for s in ("hemisphere", "sphere")])


def _world_noise_claim() -> list:
    higher = all(float(_world(f, n, s)["coverage_pct"]) > float(_world(f, "ideal", s)["coverage_pct"])
                 for f in ("current", "previous") for n in ("arm-rgbd", "phone-lidar") for s in ("hemisphere", "sphere"))
    return _claim(higher, "every noisy row has a higher mean coverage than its frame's ideal row")


def _seen(noise: str, seen: bool, column: str) -> list:
    table = _md_tables("table1_world_captures_seen")
    rows_ = next(iter(table.values()))
    return [Printed(next(r for r in rows_ if (r["noise"], r["captures_seen"], r["view_space"]) == (noise, str(seen), s))
                    [column]) for s in ("hemisphere", "sphere")]


def _seen_calibration() -> list:
    code = (ROOT / "benchmarks" / "table1_world.py").read_text()
    cases = ("seeds=(10, 11)", "rotations=(0.0,)", "initial_views=(17,)")
    return ["10", "11", "0", "17"] if all(case in code for case in cases) else ["calibration cases changed"]


_WORLD = [
    ("Ours on the same # cases (# per view space)", lambda: _world_header()[:2]),
    ("# min on # worker;", lambda: _world_header()[2:]),
    *[(f"| {f} | {n} | # | # | # | # | # | # |", (lambda f=f, n=n: _world_row(f, n)))
      for f in ("current", "previous") for n in ("ideal", "arm-rgbd", "phone-lidar")],
    ("The frame a robot can know costs #x the views on the hemisphere and #x on the sphere, with the mean coverage "
     "# and # points higher and the lowest case # and # points lower.", _world_previous),
    ("in the `current` frame the wrist camera takes #x / #x the views (hemisphere / sphere) and the phone #x / #x; in "
     "the `previous` frame #x / #x and #x / #x;",
     lambda: sum((_world_ratio(f, n) for f in ("current", "previous") for n in ("arm-rgbd", "phone-lidar")), [])),
    ("every noisy row has a higher mean coverage than its frame's `ideal` row.", _world_noise_claim),
    ("(generated seeds # and #, rotation #, initial view #, apart from the #:", lambda: _seen_calibration()
     + [_world_header()[0]]),
    ("takes the phone's views from # / # to # / # (hemisphere / sphere; `ideal` without it: # / #), at # / # % mean "
     "coverage.", lambda: _seen("phone-lidar", False, "views") + _seen("phone-lidar", True, "views")
     + _seen("ideal", False, "views") + _seen("phone-lidar", True, "coverage_pct")),
    ("under `ideal` the same credit gives # / # views and # / # % (lowest # / # %), under `arm-rgbd` # / # % (lowest "
     "# / # %).", lambda: _seen("ideal", True, "views") + _seen("ideal", True, "coverage_pct")
     + _seen("ideal", True, "lowest_coverage_pct") + _seen("arm-rgbd", True, "coverage_pct")
     + _seen("arm-rgbd", True, "lowest_coverage_pct")),
]

# ---------------------------------------------------------------- sources: the season under noise (docs/results.md)
_SW_GAP, _SW_WORST_GAP = "mean gap (points, >= -0.3)", "worst gap (points, >= -0.5)"
_SW_VIEWS, _SW_GROWTH = "own / truth views (<= 1.10)", "own Chamfer growth mm (max, <= 1)"
_SW_KEYS = [(n, s) for n in ("arm-rgbd", "phone-lidar") for s in ("hemisphere", "sphere")]


def _sw(noise: str, space: str, name: str = "season_world", arm: str | None = None) -> dict:
    rows_ = next(iter(_md_tables(name).values()))
    return next(r for r in rows_ if (r["noise"], r["view_space"]) == (noise, space) and arm in (None, r.get("arm")))


@lru_cache(maxsize=None)
def _sw_rows() -> pd.DataFrame:
    return pd.read_csv(ROOT / "benchmarks" / "results" / "season_world.csv")


def _unsigned(text: str) -> Printed:
    """A printed value the page writes after its sign (``-#``: the template holds the sign)."""
    return Printed(text.lstrip("-"))


def _sw_sign(noise: str, space: str, column: str) -> str:
    return "-" if _sw(noise, space)[column].startswith("-") else ""


def _sw_table_row(noise: str, space: str) -> list:
    r = _sw(noise, space)
    return [_unsigned(r[c]) for c in ("own coverage %", "truth coverage %", _SW_GAP, "own worst %", "truth worst %",
                                    _SW_WORST_GAP, _SW_VIEWS, _SW_GROWTH)]


def _sw_header() -> list:
    made = re.search(r"\((\d+) plants x (\d+) view spaces x (\d+) profiles, arms truth, own, (\d+) worker\(s\), ([\d.]+) "
                     r"min\)", _md_header("season_world"))
    r = _sw_rows()
    seeds = sorted({int(p.rsplit("-", 1)[1]) for p in r["plant"]})
    assert r["session"].max() == 6  # six scans
    return [made.group(5), made.group(4), str(seeds[0]), str(seeds[-1]), f"{season.COVERAGE_TARGET:g}", str(r[r["arm"] == "own"].groupby("noise")["plant"].nunique().min()),
            str(int(r[r["arm"] == "own"].groupby(["noise", "view_space"]).size().min()))]


def _sw_verdicts() -> list:
    """Which targets hold, row by row (the page names them)."""
    met = {k: (float(_sw(*k)[_SW_GAP]) >= -0.3, float(_sw(*k)[_SW_WORST_GAP]) >= -0.5,
               float(_sw(*k)[_SW_VIEWS]) <= 1.10, float(_sw(*k)[_SW_GROWTH]) <= 1.0) for k in _SW_KEYS}
    said = {("arm-rgbd", "hemisphere"): (False, False, True, True), ("arm-rgbd", "sphere"): (True, True, True, True),
            ("phone-lidar", "hemisphere"): (False, True, True, False),
            ("phone-lidar", "sphere"): (True, False, True, True)}
    return _claim(met == said, "the targets met and missed, row by row, as the page lists them")


def _sw_truth_growth() -> list:
    values = [float(_sw(*k)["truth Chamfer growth mm (max)"]) for k in _SW_KEYS]
    return [_f(min(values)), _f(max(values))]


def _sw_missing() -> list:
    late = _sw_rows()[_sw_rows()["session"] > _sw_rows()["session"].min()]
    mean = late.groupby(["noise", "arm"])["prior_missing"].mean() * 100
    return [_f(mean[("arm-rgbd", "own")]), _f(mean[("phone-lidar", "own")]),
            _f(mean[("arm-rgbd", "truth")]), _f(mean[("phone-lidar", "truth")])]


def _sw_total_views() -> list:
    views = _sw_rows().groupby(["noise", "view_space", "arm"])["views"].sum()
    return [str(views[(n, s, a)]) for n, s in (("arm-rgbd", "hemisphere"), ("phone-lidar", "sphere"))
            for a in ("own", "truth")]


def _sw_calibration() -> list:
    carried = _sw("phone-lidar", "hemisphere", "season_world_calibrate", "own (carried)")
    alone = _sw("phone-lidar", "hemisphere", "season_world_calibrate", "own (fused only)")
    code = (ROOT / "benchmarks" / "season_world.py").read_text()
    seeds = ["10", "11"] if "((10, 11), (False, True))" in code else ["calibration seeds changed"]
    return seeds + [Printed(carried["own prior missing %"]), Printed(alone["own prior missing %"]),
                    Printed(carried[_SW_VIEWS]), _unsigned(carried[_SW_GAP]), Printed(alone[_SW_VIEWS]),
                    _unsigned(alone[_SW_GAP])]


_SEASON_WORLD = [
    ("rows in\n`season_world.csv`; # min on # workers, run once on these seeds): tomato and maize, seeds #-#,\nsix scans, "
     "both view spaces, plans made once at a # target", lambda: _sw_header()[:5]),
    ("(each\nprofile: # seasons, # sessions per arm and view space)", lambda: _sw_header()[5:]),
    ("| noise | view space | mean coverage own / truth | gap (target >= -#) | worst session own / truth | gap (target "
     ">= -#) | views own / truth (target <= #) | fused model's Chamfer growth, max (target <= # mm) |",
     lambda: [re.search(r"[<>]= -?([\d.]+)", c).group(1) for c in (_SW_GAP, _SW_WORST_GAP, _SW_VIEWS, _SW_GROWTH)]),
    *[(f"| {n} | {s} | # / # % | {_sw_sign(n, s, _SW_GAP)}# | # / # % | {_sw_sign(n, s, _SW_WORST_GAP)}# | # | # mm |",
       (lambda n=n, s=s: _sw_table_row(n, s))) for n, s in _SW_KEYS],
    ("- Met: the views (#-#x the `truth` arm's", lambda: [_f(min(float(_sw(*k)[_SW_VIEWS]) for k in _SW_KEYS)),
                                                         _f(max(float(_sw(*k)[_SW_VIEWS]) for k in _SW_KEYS))]),
    ("mean coverage on the sphere (-# and -# points)",
     lambda: [_unsigned(_sw(n, "sphere")[_SW_GAP]) for n in ("arm-rgbd", "phone-lidar")]),
    ("the fused model's growth in three of four rows.", _sw_verdicts),
    ("- Missed: the mean coverage on the hemisphere (-# and -# points), the worst session on the\n  wrist camera's "
     "hemisphere (-# points) and the phone's sphere (-#), and the phone's\n  hemisphere growth: one plant's fused model "
     "ends # mm farther",
     lambda: [_unsigned(_sw(n, "hemisphere")[_SW_GAP]) for n in ("arm-rgbd", "phone-lidar")]
     + [_unsigned(_sw("arm-rgbd", "hemisphere")[_SW_WORST_GAP]), _unsigned(_sw("phone-lidar", "sphere")[_SW_WORST_GAP]),
        Printed(_sw("phone-lidar", "hemisphere")[_SW_GROWTH])]),
    ("(the `truth` arm's largest growth there: # mm;",
     lambda: [Printed(_sw("phone-lidar", "hemisphere")["truth Chamfer growth mm (max)"])]),
    ("model grows too: #-# mm)", _sw_truth_growth),
    ("From session # on", lambda: [str(_sw_rows()["session"].min() + 1)]),
    ("prior holds nothing near # % of today's plant under the wrist camera and # % under the phone,\n  against # % and "
     "# % for the `truth` prior", _sw_missing),
    ("views (# against # views in all on the wrist camera's hemisphere, # against # on the\n  phone's sphere)",
     _sw_total_views),
    ("- A fix tried on calibration seeds # and # only", lambda: _sw_calibration()[:2]),
    ("(the phone's hemisphere prior misses # % instead of # %)", lambda: _sw_calibration()[2:4]),
    ("there: #x the `truth` arm's views and -# points mean coverage, against\n  #x and -# points for the fused model "
     "alone.", lambda: _sw_calibration()[4:]),
]

# ---------------------------------------------------------------- sources: README.md
def _exit_codes() -> list[str]:
    from tpvp import errors

    return ["0", "1", str(errors.TpvpError.exit_code), str(errors.BusyError.exit_code),
            str(errors.OutputWriteError.exit_code), "130" if "return 130" in (ROOT / "tpvp" / "errors.py").read_text()
            else "no 130"]


def _capture_fusion() -> list[str]:
    from data_tools.capture.fusion import SCALES

    tables = _md_tables("capture_fusion")
    fused = next(rows_ for t, rows_ in tables.items() if t.startswith("Fused cloud"))
    speed = tables["Fusion speed"][0]
    chamfer = {scale: [float(r["seen: chamfer_mm"]) for r in fused if r["scale"] == scale]
               for scale in ("plant", "row")}
    cores = re.search(r"on (\d+) cores", _md_header("capture_fusion")).group(1)
    return [_f(min(chamfer["plant"]), 1), _f(max(chamfer["plant"]), 1), f"{1000 * SCALES['plant'].voxel_size:g}",
            _f(min(chamfer["row"]), 1), _f(max(chamfer["row"]), 1), f"{100 * SCALES['row'].voxel_size:g}",
            speed["frames"], f"{float(speed['fusion s (read + integrate + extract + support)']):.0f}", cores]


def _coverage_rule() -> list[str]:
    from tpvp.setcover.config import CALIBRATED_MISS_RATIO, SelectionConfig

    room = SelectionConfig(coverage_target=0.9).planning_target("room1")  # a view space without a calibrated ratio
    return [f"{CALIBRATED_MISS_RATIO['hemisphere']:g}", f"{CALIBRATED_MISS_RATIO['sphere']:g}",
            f"{min(CALIBRATED_MISS_RATIO.values()):g}", _f(100 * room, 1)]


def _readme_rows_row(reference: str = "handheld") -> list[str]:
    ours = _t6(reference, "ours", resolution=4)
    return ["4", _f(ours["views_mean"], 1), _f(ours["views_std"], 1), _f(ours["coverage_mean"]),
            _f(ours["coverage_std"]),
            _f(ours["path_length_m_mean"], 1), _f(ours["path_length_m_std"], 1), _f(ours["paper_views"], 1),
            _f(ours["paper_coverage"]), _f(ours["paper_path_length_m"])]


def _readme_pose_noise() -> list[str]:
    t = _table7()
    largest = t[(t["sigma_t_m"] == t["sigma_t_m"].max()) & t["icp"]].iloc[0]
    p = rows.paper_pose_noise()
    paper = p[(p["sigma_t_m"] == largest["sigma_t_m"]) & (p["icp"] == "ON")].iloc[0]
    return [f"{largest['sigma_t_m']:g}", f"{largest['sigma_r_deg']:g}", _f(largest["chamfer_mm_mean"]),
            _f(largest["chamfer_mm_std"]), _f(100 * largest["f1_10mm_mean"], 1), _f(paper["chamfer_mm_mean"]),
            _f(paper["f1_1cm_mean"], 1)]


_README_QUICK_START = [
    ("About # s the first time (numba compiles the kernels it runs, ~# s), about #-# s after that.", NOT_KEPT),
    ("(about # minutes, # GB)", NOT_KEPT),
    ("(# done, # a bug, # bad input, # destination busy, # outputs not written, # interrupted)", _exit_codes),
    # the demo's output files are written by `make demo` (outputs/demo), not kept in the repository
    ("# views (# executed to start, # planned), # % of the oracle set covered, a # m path", NOT_KEPT),
]
_README_NOTEBOOKS = [
    ("`make docs` takes # s after `make test` on a fresh clone (measured on # cores:", NOT_KEPT),
    ("site builds in # s); a notebook or library changed since then runs again in reader's mode first (#-# s each",
     NOT_KEPT),
]
_README_PHONE = [
    ("its tomatoes and maize lie #-# mm (Chamfer) from the generated plants at # mm voxels, its rows #-# mm at # cm, "
     "and a #-frame capture fuses in # s on # cores", _capture_fusion),
]
_README_SESSION = [
    ("(`--wait`, default # s)", lambda: [f"{__import__('tpvp.session.cli', fromlist=['WAIT_S']).WAIT_S:g}"]),
]
_README_ROBOT = [
    ("stamped `--stamp` (default #:",
     lambda: [re.search(r'"--stamp", default="(\d+)"',
                        (ROOT / "tpvp" / "commands" / "export.py").read_text()).group(1)]),
]
_README_RULE = [
    ("with `r` per view space: # on the hemisphere and # on the sphere (calibrated on generated plants), # in the "
     "greenhouse rooms (not calibrated on rows: the most cautious). `T = 0.9` in a room therefore asks for # % of the "
     "planning surface", _coverage_rule),
    ("predicts its own true coverage with a # % lower bound",
     lambda: [f"{100 * (1 - __import__('tpvp.setcover.miss_model', fromlist=['x']).load_miss_model().alpha):g}"]),
]
_README_GLANCE = [
    ("Measured on a shared #-core machine", lambda: [_machine_cores()]),
    ("| plants, hemisphere: Ours (views / coverage / path) | # ± # / # ± # % / # ± # m | # / # / # |",
     lambda: _ours_row("generated", "hemisphere")),
    ("| plants, sphere: Ours | # ± # / # ± # % / # ± # m | # / # / # |", lambda: _ours_row("generated", "sphere")),
    ("| plants: Ours' views / the exact optimum's, same coverage | #x (hemisphere), #x (sphere) |",
     lambda: [_optimum_ratio("generated", "hemisphere"), _optimum_ratio("generated", "sphere")]),
    ("| greenhouse rows: Ours at # cm, handheld reference | # ± # / # ± # % / # ± # m | # / # / # |",
     _readme_rows_row),
    ("| rows: the same, candidate-filtered / complete reference | # ± # % / # ± # % | # |",
     lambda: [v for r in ("candidates", "complete") for v in (_f(_t6(r, "ours", resolution=4)["coverage_mean"]),
                                                              _f(_t6(r, "ours", resolution=4)["coverage_std"]))]
     + [_f(_t6("candidates", "ours", resolution=4)["paper_coverage"])]),
    ("| rows: passive sweep, handheld / candidates / complete reference | # / # / # % | # |",
     lambda: [_f(_t6(r, "coarse")["coverage_mean"]) for r in ("handheld", "candidates", "complete")]
     + [_f(_t6("handheld", "coarse")["paper_coverage"])]),
    ("| rows, pose noise # m / #°, with ICP: Chamfer, F1 | # ± # mm, # % | # mm, # % |", _readme_pose_noise),
    ("| learned MA-SCVP, hemisphere | # ± # / # ± # % / # ± # m | # / # / # |",
     lambda: _ours_row("generated", "hemisphere", method="ma-scvp", paper="ma-scvp")),
    ("| MA-SCVP after two views: recall / precision of the label set | # / # |", NOT_KEPT),  # `evaluate --executed 2`
    ("| one view, reference sensor model (tomato at # mm) | # ms (OctoMap # ms, #x) |", NOT_KEPT),  # sensor_bench.py
]


_README = [
    ("| asking for # %: views, true coverage mean (min) | hemisphere #, # % (# %); sphere #, # % (# %) |",
     _coverage_target_row),
    ("| # Helios evaluation species, asking for # %: true coverage mean (min), views / exact optimum | "
     "hemisphere # % (# %), #x; sphere # % (# %), #x |", _species_row),
]

#: (document, region) -> sources; the regions of a document partition it (every number lies in one).
#: A region is a heading (its section) or (first line's start, the next line's start; None: the end).
#: Its sources: (template, compute) pairs, or one :class:`Unsourced` for a region no file holds.
SOURCES = {
    ("docs/results.md", ("# Results (measured", "## Generated plants")):
        [("Results (measured on this #-core machine)", lambda: [_machine_cores()])],
    # benchmarks/plant_realism.py prints its table and writes no file: the section's numbers are its printout
    ("docs/results.md", ("## Generated plants", "## Individual plants")): NOT_KEPT,
    ("docs/results.md", ("## Individual plants", "## Table I in the world")): _PLANTS,
    ("docs/results.md", ("## Table I in the world", "## Coverage target")): _WORLD,
    ("docs/results.md", ("## Coverage target", "| asked | view space | views |")): _COVERAGE_TARGET,
    ("docs/results.md", ("| asked | view space | views |", "A request of 99 %")): _coverage_target_sources(),
    ("docs/results.md", ("A request of 99 %", "### Coverage a plan predicts per case")): _COVERAGE_TARGET_PROSE,
    ("docs/results.md", ("### Coverage a plan predicts per case", "**Under sensor noise**")): _miss_model_sources(),
    ("docs/results.md", ("**Under sensor noise**", "Under the phone profile")): _noisy_evaluation_sources(),
    ("docs/results.md", ("Under the phone profile", "### The closing check of a one-shot plan")):
        _phone_evaluation_sources(),
    ("docs/results.md", ("### The closing check of a one-shot plan", "## Across species")): _closing_check_sources(),
    ("docs/results.md", ("## Across species", "- *The coverage-target rule was left")): _SPECIES_INTRO,
    ("docs/results.md", ("- *The coverage-target rule was left", "At `--coverage-target 0.98`")): _SPECIES_CALIBRATION,
    ("docs/results.md", ("At `--coverage-target 0.98`", "The coverage holds on every species")): _SPECIES_OVERALL,
    ("docs/results.md", ("The coverage holds on every species", "Beside them, on the same protocol")):
        _SPECIES_TABLE + _per_species_sources(),
    ("docs/results.md", ("Beside them, on the same protocol", "A named organ's target also holds")): _SPECIES_ORGANS,
    ("docs/results.md", ("A named organ's target also holds", "## Re-planning")): _SPECIES_END,
    ("docs/results.md", ("## Re-planning", "| asked | view space | optimum | one-shot views")): _REPLANNING,
    ("docs/results.md", ("| asked | view space | optimum | one-shot views", "Against the issue's targets at 0.98")):
        _replanning_sources(),
    ("docs/results.md", ("Against the issue's targets at 0.98", "## A season")): _REPLANNING_END,
    ("docs/results.md", ("## A season", "### The closed loop under sensor noise")): _SEASON,
    ("docs/results.md", ("### The closed loop under sensor noise", "## Warm-up NBV quality")): _SEASON_WORLD,
    # benchmarks/nbv_rank.py writes its rows only with --output, and no such file is kept
    ("docs/results.md", ("## Warm-up NBV quality", "## Greenhouse rows")): NOT_KEPT,
    ("docs/results.md", ("## Greenhouse rows", "### Why Ours selects")): _ROWS,
    ("docs/results.md", ("### Why Ours selects", "Table VII (`tpvp experiments rows")): _WHY_10_CM,
    ("docs/results.md", ("Table VII (`tpvp experiments rows", "## Learned baselines")): _TABLE7,
    ("docs/results.md", ("## Learned baselines", "### Warm-up NBV: geometric vs PC-NBV")): _LEARNED,
    ("docs/results.md", ("### Warm-up NBV: geometric vs PC-NBV", None)): _WARM_UP,
    ("README.md", ("## Quick start", "## Reading the notebooks")): _README_QUICK_START,
    ("README.md", ("## Reading the notebooks", "## Your own scans")): _README_NOTEBOOKS,
    ("README.md", ("## Your own scans", "## Planning a real session")): _README_PHONE,
    ("README.md", ("## Planning a real session", "## Running a plan on a robot")): _README_SESSION,
    ("README.md", ("## Running a plan on a robot", "## Opening a recording")): _README_ROBOT,
    ("README.md", ("**Asking for less than everything.**", "## Results at a glance")): _README_RULE,
    ("README.md", ("## Results at a glance", "## Data")): _README_GLANCE + _README,
}
#: The documents whose every number must lie in a region of SOURCES.
DOCUMENTS = ("docs/results.md", "README.md")


def _template_regex(template: str) -> str:
    """``#``: a number; any run of white space: any run of white space (line breaks move)."""
    parts = re.split(r"(#|\s+)", template)
    return "".join(f"({NUMBER})" if part == "#" else r"\s+" if part.isspace() else re.escape(part)
                   for part in parts if part)


def _numbers(masked: str):
    return re.finditer(rf"(?<![\w.]){NUMBER}", masked)  # greedy: whole numbers


def _check(text: str, sources, where: str, document: str | None = None) -> dict:
    """Every number of ``text`` covered by a template of ``sources`` and, where it has a source, equal to
    it as written; returns how many were checked and how many are declared :class:`Unsourced`."""
    masked = _masked(text, document)
    if isinstance(sources, Unsourced):
        return {"checked": 0, "unsourced": sum(1 for _ in _numbers(masked))}
    covered = [False] * len(text)
    problems = []
    counts = {"checked": 0, "unsourced": 0}
    for template, compute in sources:
        # templates are matched on the text as written (they may hold code spans)
        matches = list(re.finditer(_template_regex(template), text))
        if len(matches) != 1:
            problems.append(f"{where}: template found {len(matches)} times: {template!r}")
            continue
        match = matches[0]
        for i in range(match.start(), match.end()):
            covered[i] = True
        written = [g.replace(",", "") for g in match.groups()]
        expected = compute()
        if isinstance(expected, Unsourced):
            counts["unsourced"] += len(written)
            continue
        expected = list(expected)
        counts["unsourced"] += sum(isinstance(e, Unsourced) for e in expected)
        counts["checked"] += sum(not isinstance(e, Unsourced) for e in expected)
        if len(written) != len(expected) or not all(
                isinstance(e, Unsourced) or (e.matches(w) if isinstance(e, Printed) else w == str(e))
                for w, e in zip(written, expected)):
            expected = ["-" if isinstance(e, Unsourced) else str(e) for e in expected]
            problems.append(f"{where}: {template!r} writes {written}, its source gives {expected}")
    for number in _numbers(masked):
        if not all(covered[number.start():number.end()]):
            line = text[:number.start()].count("\n") + 1
            context = text[max(0, number.start() - 40):number.end() + 20].replace("\n", " ")
            problems.append(f"{where}, line {line} of the region: {number.group(0)!r} has no source: ...{context}...")
    assert not problems, "\n".join(problems)
    return counts


def _region_id(key) -> str:
    document, region = key
    return f"{document}:{region if isinstance(region, str) else region[0]}"


@lru_cache(maxsize=None)
def _region_counts(key) -> dict:
    document, region = key
    return _check(_section(document, region), SOURCES[key], _region_id(key), document)


@pytest.mark.parametrize("key", list(SOURCES), ids=[_region_id(k) for k in SOURCES])
def test_every_number_of_the_region_is_read_back_from_its_source(key):
    counts = _region_counts(key)
    assert counts["checked"] + counts["unsourced"] > 0


@pytest.mark.parametrize("document", DOCUMENTS)
def test_the_regions_cover_every_number_of_the_document(document):
    text = (ROOT / document).read_text()
    spans = sorted(_span(d, r) for d, r in SOURCES if d == document)
    overlaps = [(a, b) for a, b in zip(spans, spans[1:]) if b[0] < a[1]]
    assert not overlaps, f"{document}: regions overlap: {overlaps}"
    outside = []
    for number in _numbers(_masked(text, document)):
        if not any(start <= number.start() < end for start, end in spans):
            line = text[:number.start()].count("\n") + 1
            context = text[max(0, number.start() - 40):number.end() + 20]
            outside.append(f"line {line}: {number.group(0)!r}: ...{context}...")
    assert not outside, f"{document}: numbers in no region of SOURCES:\n" + "\n".join(outside)


#: How many quoted numbers have no source yet (:class:`Unsourced`), per document: may only shrink.
UNSOURCED_AT_MOST = {"docs/results.md": 290, "README.md": 22}


def test_the_unsourced_numbers_only_shrink():
    for document in DOCUMENTS:
        unsourced = sum(_region_counts(key)["unsourced"] for key in SOURCES if key[0] == document)
        assert unsourced <= UNSOURCED_AT_MOST[document], (document, unsourced)


def test_a_number_without_a_source_or_with_another_value_fails():
    text = "The loop took 3 of 12 plans (lowest 95.95 %), see `tpvp 11_season`."
    with pytest.raises(AssertionError, match="'3' has no source"):
        _check(text, [("of # plans (lowest # %)", lambda: ["12", "95.95"])], "example")
    with pytest.raises(AssertionError, match="writes"):
        _check(text, [("took # of # plans (lowest # %)", lambda: ["3", "12", "95.96"])], "example")
    counts = _check(text, [("took # of # plans (lowest # %)", lambda: ["3", "12", "95.95"])], "example")
    assert counts == {"checked": 3, "unsourced": 0}


def test_the_species_tables_record_the_split_and_the_seed():
    """Issue 47: the Helios calibration and evaluation runs hold pairs of the same names; their tables
    say which run (``split``) and which seed the plants come from, with the measured values unchanged."""
    import importlib
    import sys

    from tpvp.experiments import species

    raw = shipped.shipped_rows("species")
    tables = species.species_tables(raw)
    for name, table in tables.items():
        assert list(table.columns[:2]) == ["split", "seed"], name
        assert set(table["split"]) == {"evaluation"}, name
    per_species = tables["per_species"].set_index("species")
    assert set(per_species.loc["helios maize", "seed"]) == {"0"}
    assert set(per_species.loc["generated tomato", "seed"]) == {"0,1,2"}
    assert set(per_species.loc["bundled tomato", "seed"]) == {""}  # a real scan: no seed
    assert (tables["overall"]["coverage_mean"].to_numpy()
            == raw[(raw["source"] == "dataset") & ~raw["species"].isin(species.CALIBRATION_SPECIES)]
            .groupby("view_space")["coverage"].mean().to_numpy()).all()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        calibration = importlib.import_module("species_calibration")
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    rows = pd.read_csv(ROOT / "benchmarks" / "results" / "species_calibration.csv")
    rule = calibration.rule_table(rows).set_index(["group", "view_space"])
    assert rule.loc[("helios", "hemisphere"), "seed"] == "1" and rule.loc[("generated", "sphere"), "seed"] == "10,11,12"
    assert set(rule["split"]) == {"calibration"}
    shipped_rule = _calibration(_BENCHMARK_RULE, "helios", "hemisphere")  # the printed table, unchanged
    assert f"{rule.loc[('helios', 'hemisphere'), 'coverage_mean']:.4f}" == shipped_rule["coverage_mean"]
    for table in (calibration.target_table(rows), calibration.margin_table(rows)):
        assert {"split", "seed"} <= set(table.columns) and set(table["split"]) == {"calibration"}
