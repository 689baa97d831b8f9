"""A benchmark's result tables as one Markdown file under benchmarks/results/, headed by the command
that made them, so the numbers can be checked without a rerun."""

from __future__ import annotations

import shlex
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from tpvp.io import atomic_write_text


def write_results(path, tables, what: str) -> None:
    """``tables``: (title, DataFrame) pairs; ``what``: the run in words (cases, seeds, time)."""
    path = Path(path)
    command = "python " + " ".join(shlex.quote(a) for a in [Path(sys.argv[0]).as_posix(), *sys.argv[1:]])
    text = [f"# {path.stem}", "", f"Made by `{command}` on {datetime.now(timezone.utc):%Y-%m-%d} ({what}).", ""]
    for title, table in tables:
        rows = [[f"{v:.4g}" if isinstance(v, (float, np.floating)) else str(v) for v in row]
                for row in table.itertuples(index=False)]
        text += [f"## {title}", "", "| " + " | ".join(map(str, table.columns)) + " |",
                 "|" + "---|" * len(table.columns), *("| " + " | ".join(row) + " |" for row in rows), ""]
    atomic_write_text(path, "\n".join(text))
    print(f"wrote {path}")
