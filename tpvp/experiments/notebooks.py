"""What the notebooks call to show the paper's tables: the rows of a protocol
(:func:`protocol_results`: computed in full mode, else from the experiment cache, what ``make
notebooks`` published or the rows shipped with tpvp) and the line saying where they come from.
Running the notebooks headless and the documentation site are project tools, not the library:
``tools/notebooks.py`` and ``tools/site.py``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from tpvp.errors import ConfigError
from tpvp.experiments import shipped
from tpvp.experiments.runner import experiment_cache  # noqa: F401 (the notebooks' cells read it from here)
from tpvp.io import atomic_write_bytes

ROOT = Path(__file__).resolve().parent.parent.parent


def published_results() -> Path:
    """Where ``make notebooks`` publishes (``$TPVP_NOTEBOOK_RESULTS`` or ``outputs/notebooks``)."""
    return Path(os.environ.get("TPVP_NOTEBOOK_RESULTS") or ROOT / "outputs" / "notebooks")


# --------------------------------------------------------------------------------------------------
# results for the tables: always the full protocol's rows
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ProtocolResults:
    raw: object  # pandas.DataFrame
    source: str  # where the rows come from, in words (shown above the tables)


def protocol_results(output, name: str, full: bool) -> ProtocolResults:
    """The raw rows of protocol ``name`` (:data:`tpvp.experiments.shipped.PROTOCOLS`) that a
    notebook's tables are made of. ``full``: computed (the experiment cache answers the tasks it
    holds; the rows are kept under ``output/results/<name>.parquet`` for ``make notebooks`` to
    publish). Reader's mode: from the experiment cache when it holds every task, else from what
    ``make notebooks`` published, else the rows shipped with tpvp. Never numbers typed in by hand."""
    import pandas as pd

    output, protocol = Path(output), shipped.protocol(name)
    cache = experiment_cache() / protocol.setting
    if full:
        raw = protocol.run(cache)
        atomic_write_bytes(output / "results" / f"{name}.parquet", raw.to_parquet(index=False))
        return ProtocolResults(raw, "the paper's full protocol, computed in this run")
    raw = protocol.cached(cache)
    if raw is not None:
        return ProtocolResults(raw, "the paper's full protocol, read from the experiment cache")
    published = published_results() / output.name / "results" / f"{name}.parquet"
    if published.is_file():
        stamp = datetime.fromtimestamp(published.stat().st_mtime, timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        return ProtocolResults(pd.read_parquet(published),
                               f"the paper's full protocol, published by `make notebooks` ({stamp})")
    raw = shipped.shipped_rows(name)
    if raw is None:
        raise ConfigError(f"no rows of protocol {name!r} are shipped: run `python -m tpvp.experiments.shipped "
                          f"refresh {name}`, or set full = True")
    return ProtocolResults(raw, f"the paper's full protocol, {shipped.describe(name)}")


def show_source(results: ProtocolResults) -> None:
    """One line above a table saying where its rows come from."""
    from IPython.display import Markdown, display

    display(Markdown(f"Rows: {results.source}; {len(results.raw)} raw rows."))


def benchmark_results(name: str, script: str | None = None) -> ProtocolResults:
    """A benchmark's table (``benchmarks/results/<name>.csv``, written by ``benchmarks/<script>``,
    by default ``<name>.py``) and, as its source, the script, the date and the run its Markdown file
    is headed by (not the command line, which may name the machine's folders)."""
    import pandas as pd

    table = ROOT / "benchmarks" / "results" / f"{name}.csv"
    if not table.is_file():
        raise ConfigError(f"{table} is missing: run python benchmarks/{script or name + '.py'}")
    made = (table.with_suffix(".md").read_text(encoding="utf-8").splitlines() + ["", "", ""])[2]
    run = made.rpartition("` on ")[2].rstrip(".") or "no header"
    return ProtocolResults(pd.read_csv(table), f"`benchmarks/{script or name + '.py'}`, {run}")
