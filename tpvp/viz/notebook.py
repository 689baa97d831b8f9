"""Showing what a notebook makes: every figure inline *and* as a file, every table rendered *and*
as CSV. Figures are drawn offscreen (Agg) by the ``plot_*`` functions, which write the files;
these helpers put the written files into the notebook's outputs, so the executed notebook, its
HTML copy and the site carry the pictures themselves, not paths to them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.io.atomic import atomic_write_text

_PLOTLY_LOADED = False  # plotly.js is embedded once per kernel, in the first 3D view's output


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


def show_table(frame: pd.DataFrame, csv_path=None, title: str | None = None, *, merge_std: bool = True,
               digits: int = 2) -> None:
    """Write ``frame`` as CSV to ``csv_path`` (atomically; the raw numbers, std columns kept) and
    display it as a rendered table (mean ± std merged unless ``merge_std=False``). Returns nothing,
    so a cell ending in ``show_table(...)`` shows the table once."""
    from IPython.display import Markdown, display

    if csv_path is not None:
        atomic_write_text(csv_path, frame.to_csv(index=False))
    if title:
        display(Markdown(f"**{title}**"))
    shown = mean_std(frame, digits) if merge_std else frame.round(digits + 1)
    display(shown.style.hide(axis="index").format(precision=digits + 1, na_rep="", escape="html") if len(shown) else shown)


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
