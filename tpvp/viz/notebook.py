"""Showing what a notebook makes: every figure inline *and* as a file, every table rendered *and*
as CSV. Figures are drawn offscreen (Agg) by the ``plot_*`` functions, which write the files;
these helpers put the written files into the notebook's outputs, so the executed notebook, its
HTML copy and the site carry the pictures themselves, not paths to them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.io.atomic import atomic_write_text
from tpvp.viz.paper_gaps import DEVIATIONS, agreement, gap_lines

_PLOTLY_LOADED = False  # plotly.js is embedded once per kernel, in the first 3D view's output
# How each paper table shown in this kernel agrees with the paper (show_paper_table with ``gaps``),
# for the notebook's conclusion (show_conclusion).
_AGREEMENTS: dict = {}


def show(*figures):
    """Display PNG files inline (a list of paths is accepted too); returns nothing, so a cell
    ending in ``show(...)`` prints no path."""
    from IPython.display import Image, display

    for figure in figures:
        for path in figure if isinstance(figure, (list, tuple)) else [figure]:
            path = Path(path)
            if path.suffix.lower() != ".png":
                raise ValueError(f"show() displays PNG files; got {path.name}")
            display(Image(filename=str(path)))


def mean_std(table: pd.DataFrame, digits: int = 2) -> pd.DataFrame:
    """``x_mean`` and ``x_std`` columns merged into one ``x`` column of ``"m ± s"`` strings (in the
    mean column's place); other float columns rounded."""
    table = table.copy()
    for column in [c for c in table.columns if str(c).endswith("_mean")]:
        base = column[: -len("_mean")]
        std = table.pop(f"{base}_std") if f"{base}_std" in table else pd.Series(np.nan, index=table.index)
        merged = [("" if pd.isna(m) else f"{m:.{digits}f}" if pd.isna(s) else f"{m:.{digits}f} ± {s:.{digits}f}")
                  for m, s in zip(table[column], std)]
        table[column] = merged
        table = table.rename(columns={column: base})
    return table.round(digits + 1)


#: The most columns a displayed table has: a wider one is shown in parts (its key columns repeated),
#: so every table fits a page's column without a sideways scroll.
MAX_COLUMNS = 8
#: The most rows a displayed table shows: a longer one shows its first rows and links its CSV.
MAX_ROWS = 25
#: Columns beyond the paper tables' keys (:data:`KEY_LABELS`) that name what a row is about (repeated
#: in every part of a wide table) even when numeric.
KEY_COLUMNS = {"session", "replan_after", "seed", "plant", "arm", "room", "case", "rule", "noise", "date", "plan",
               "capture", "stage"}


def show_table(frame: pd.DataFrame, csv_path=None, title: str | None = None, *, merge_std: bool = True,
               digits: int = 2) -> None:
    """Write ``frame`` as CSV to ``csv_path`` (atomically; the raw numbers, std columns kept) and
    display it as a rendered table (mean ± std merged unless ``merge_std=False``): a one-row table
    as quantity-value pairs, a table of more than :data:`MAX_COLUMNS` columns in parts that repeat
    its key columns, a table of more than :data:`MAX_ROWS` rows by its first rows; a table cut in
    either way links its CSV (every row and column). Returns nothing, so a cell ending in
    ``show_table(...)`` shows the table once."""
    from IPython.display import Markdown, display

    if csv_path is not None:
        atomic_write_text(csv_path, frame.to_csv(index=False))
    if title:
        display(Markdown(f"**{title}**"))
    shown = mean_std(frame, digits) if merge_std else frame.round(digits + 1)
    _display_parts(shown.head(MAX_ROWS), digits + 1)
    if len(frame) > MAX_ROWS:
        display(Markdown(f"The first {MAX_ROWS} of {len(frame)} rows."))
    if len(frame.columns) > MAX_COLUMNS or len(frame) > MAX_ROWS:
        display(csv_link(frame, Path(csv_path).name if csv_path is not None else "table.csv"))


def table_parts(frame: pd.DataFrame, max_columns: int = MAX_COLUMNS) -> list[pd.DataFrame]:
    """``frame`` as tables of at most ``max_columns`` columns: one row with more than 4 columns as
    (quantity, value) rows; more columns than ``max_columns`` as parts that each repeat the leading
    key columns (text, or named in :data:`KEY_COLUMNS`; up to 3)."""
    if len(frame) == 1 and len(frame.columns) > 4:
        return [pd.DataFrame({"quantity": [str(c) for c in frame.columns],
                              "value": [_cell(v) for v in frame.iloc[0]]})]
    if len(frame.columns) <= max_columns:
        return [frame]
    keys = []
    for column in frame.columns[:3]:
        text = frame[column].dtype == object or isinstance(frame[column].dtype, pd.StringDtype)
        if not (text or str(column) in KEY_COLUMNS or str(column) in KEY_LABELS
                or str(column) in KEY_LABELS.values()):
            break
        keys.append(column)
    rest = [c for c in frame.columns if c not in keys]
    width = max(max_columns - len(keys), 1)
    return [frame[keys + rest[i:i + width]] for i in range(0, len(rest), width)]


def _display_parts(frame: pd.DataFrame, precision: int) -> None:
    """Render ``frame`` (:func:`table_parts`: at most :data:`MAX_COLUMNS` columns each)."""
    from IPython.display import display

    for part in table_parts(frame):
        display(part.style.hide(axis="index").format(precision=precision, na_rep="", escape="html")
                if len(part) else part)


def _cell(value) -> str:
    if isinstance(value, float):
        return "" if np.isnan(value) else f"{value:.6g}"
    return str(value)


def csv_link(frame: pd.DataFrame, name: str):
    """A link that downloads ``frame`` as the CSV file ``name`` (the data inside the link: it
    works in the notebook, its HTML copy and the site, offline)."""
    import base64
    import html

    from IPython.display import HTML

    data = base64.b64encode(frame.to_csv(index=False).encode()).decode()
    return HTML(f'<p class="tpvp-csv"><a download="{html.escape(name)}" href="data:text/csv;base64,{data}">'
                f"{html.escape(name)}</a>: every column ({len(frame.columns)}) of the {len(frame):,} rows</p>")


def paper_comparison(ours: pd.DataFrame, paper: pd.DataFrame, on: list, values: dict, keys: list | None = None,
                     digits: int = 2, labels: dict | None = None) -> pd.DataFrame:
    """A paper table as the paper shows it, ours beside theirs, one row per key: the columns
    ``keys`` (default ``on``, the join keys of :func:`beside_paper`), then per value
    ``{our column: (the paper's column, header)}`` one column ``"<header>: ours / paper / Δ"`` holding
    ``"mean ± std / paper / ours - paper"`` rounded to ``digits`` as the paper rounds (``–`` where the
    paper has no value). ``ours`` holds ``<column>_mean`` and ``<column>_std``, ``paper`` the paper's
    ``<column>_mean`` (``paper`` None: ``ours`` holds them as ``paper_<the paper's column>``);
    ``labels`` renames the key columns for display."""
    merged = ours if paper is None else beside_paper(ours, paper, on=on, values=tuple(n for n, _ in values.values()))
    table = merged[[k for k in (keys or on) if k in merged]].copy()
    for key in table.columns:  # keys as they read (a 0.002 m noise level is not 0.00)
        if pd.api.types.is_float_dtype(table[key]):
            table[key] = [("" if pd.isna(v) else f"{v:g}") for v in table[key]]
    for column, (theirs_name, header) in values.items():
        if f"{column}_mean" not in merged:
            continue
        mean = merged[f"{column}_mean"]
        std = merged[f"{column}_std"] if f"{column}_std" in merged else pd.Series(np.nan, index=merged.index)
        theirs = merged[f"paper_{theirs_name}"] if f"paper_{theirs_name}" in merged else \
            pd.Series(np.nan, index=merged.index)
        cells = []
        for m, s, p in zip(mean, std, theirs):
            if pd.isna(m):
                cells.append("")
                continue
            text = f"{m:.{digits}f}" + (f" ± {s:.{digits}f}" if pd.notna(s) else "")
            cells.append(text + (f" / {p:.{digits}f} / {m - p:+.{digits}f}" if pd.notna(p) else " / – / –"))
        table[f"{header}: ours / paper / Δ"] = cells
    return table.rename(columns=labels or {})


def show_paper_table(ours: pd.DataFrame, paper: pd.DataFrame, csv_path, title: str, *, on: list, values: dict,
                     keys: list | None = None, digits: int = 2, gaps: str | None = None) -> None:
    """Show a paper table compactly (:func:`paper_comparison`: ours / paper / Δ per value, the keys'
    display names from :data:`KEY_LABELS`) and write the wide one (every column, ours and the
    paper's side by side: :func:`beside_paper`; ``paper`` None: ``ours`` holds the paper's columns)
    to ``csv_path``, linked under the table. ``gaps``: the paper's table (``"I"``, ...): the values far
    from the paper's are listed under it with why (:mod:`tpvp.viz.paper_gaps`)."""
    from IPython.display import Markdown, display

    wide = ours if paper is None else beside_paper(ours, paper, on=on, values=tuple(n for n, _ in values.values()))
    atomic_write_text(csv_path, wide.to_csv(index=False))
    display(Markdown(f"**{title}**"))
    _display_parts(paper_comparison(wide, None, on, values, keys, digits, KEY_LABELS), digits)
    display(csv_link(wide, Path(csv_path).name))
    if gaps is not None:
        lines = gap_lines(wide, gaps, keys or on, values)
        if lines:
            display(Markdown("\n".join(lines)))
        _AGREEMENTS[title] = agreement(wide, gaps, keys or on, values)


def conclusion(takeaways: list[str], paper: list[str] | None = None) -> str:
    """A notebook's conclusion in Markdown: how its paper tables agree with the paper (``paper``: a
    line per table, by default those :func:`show_paper_table` showed in this kernel; empty: the
    notebook reproduces no paper table), then what to take away, each a sentence written from the
    data (:mod:`tpvp.experiments.claims`)."""
    paper = list(_AGREEMENTS.values()) if paper is None else paper
    if not takeaways:
        raise ValueError("a conclusion needs at least one finding to take away")
    lines = ["## Conclusion", "", "**Against the paper.**"]
    lines += [f"- {line}" for line in paper] if paper else ["- This notebook reproduces no table of the paper."]
    if paper:
        lines.append(f"- What differs from the paper's setting, and why, is listed in [deviations.md]({DEVIATIONS}).")
    lines += ["", "**What to take away.**"] + [f"- {finding}" for finding in takeaways]
    return "\n".join(lines)


def show_conclusion(takeaways: list[str], paper: list[str] | None = None) -> None:
    """Display :func:`conclusion`: the last cell of every notebook."""
    from IPython.display import Markdown, display

    display(Markdown(conclusion(takeaways, paper)))


#: The plants' tables (I-IV): our column -> (the paper's column, header with its unit).
PLANT_VALUES = {"views": ("views", "views"), "coverage": ("coverage", "coverage (%)"),
                "path_length_m": ("path", "path (m)")}
#: Display names of the tables' key columns.
KEY_LABELS = {"source": "pairs", "view_space": "view space", "species": "species", "method": "method",
              "budget": "budget", "target": "target", "cases": "cases", "reference": "reference",
              "cover_resolution_cm": "covering voxel (cm)", "prior": "prior", "sigma_t_m": "σ_t (m)",
              "sigma_r_deg": "σ_r (°)", "icp": "ICP"}


def beside_paper(ours: pd.DataFrame, paper: pd.DataFrame, on: list, values=("views", "coverage", "path"),
                 scale: dict | None = None) -> pd.DataFrame:
    """``ours`` with the paper's ``<value>_mean`` columns beside it (``paper_<value>``), joined on
    the key columns ``on``; rows the paper does not report get an empty paper cell. ``scale``
    multiplies a paper value into our units, e.g. ``{"coverage": 0.01}`` where the paper gives %."""
    keep = [f"{v}_mean" for v in values if f"{v}_mean" in paper]
    theirs = paper[on + keep].copy()
    for value, factor in (scale or {}).items():
        if f"{value}_mean" in theirs:
            theirs[f"{value}_mean"] = theirs[f"{value}_mean"] * factor
    theirs = theirs.rename(columns={c: f"paper_{c[: -len('_mean')]}" for c in keep})
    theirs = theirs.drop_duplicates(subset=on)
    left = ours.copy()
    for key in on:  # align key dtypes (the paper's CSV reads budgets as floats, ours are Int64)
        if key in theirs and pd.api.types.is_numeric_dtype(theirs[key]):
            left[key] = pd.to_numeric(left[key], errors="coerce").astype(float)
            theirs[key] = theirs[key].astype(float)
    return left.merge(theirs, on=on, how="left")


def show_3d(figure, html_path=None) -> None:
    """Display a plotly figure inline, offline (plotly.js is embedded in the output, once per
    kernel), and write it as a standalone HTML file to ``html_path`` (plotly.js embedded, so it
    opens anywhere without a network)."""
    global _PLOTLY_LOADED
    from IPython.display import HTML, display

    if html_path is not None:
        atomic_write_text(html_path, figure.to_html(include_plotlyjs=True, full_html=True))
    html = figure.to_html(include_plotlyjs=False, full_html=False, config={"displaylogo": False})
    if not _PLOTLY_LOADED:
        from plotly.offline import get_plotlyjs

        # A page with require.js (nbconvert's template) would take plotly.js's UMD header for an
        # anonymous AMD module and never set window.Plotly: hide ``define`` while it loads.
        html = ("<script>window._tpvpDefine = window.define; window.define = undefined;</script>"
                f"<script type=\"text/javascript\">{get_plotlyjs()}</script>"
                "<script>window.define = window._tpvpDefine;</script>" + html)
        _PLOTLY_LOADED = True
    display(HTML(html))
