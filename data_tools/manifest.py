"""Manifest tables of the prepared datasets: CSV (the one read back) plus a Parquet copy.

Both files are written atomically (temporary file + rename). The Parquet copy is written first, so
an interruption leaves the CSV - the table of record - either old or new, never half-written.
"""

from __future__ import annotations

import io
from pathlib import Path

import pandas as pd

from data_tools.errors import DatasetError, InputFileError
from tpvp.io import atomic_path, atomic_write_text


def write_table(df: pd.DataFrame, path, parquet: bool = True) -> Path:
    """Write ``df`` to ``path`` (CSV) and, with ``parquet``, to ``path`` with suffix ``.parquet``."""
    path = Path(path)
    if parquet:
        with atomic_path(path.with_suffix(".parquet")) as tmp:
            df.to_parquet(tmp, index=False)
    buf = io.StringIO()
    df.to_csv(buf, index=False)
    atomic_write_text(path, buf.getvalue())
    return path


def read_table(path, required: tuple[str, ...] = ()) -> pd.DataFrame:
    """Read a manifest CSV; raise a one-line error naming the file when it is missing, unreadable
    or lacks one of the ``required`` columns. Required columns are read as text (empty cells ""),
    the others with pandas' type inference."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: manifest not found")
    try:
        df = pd.read_csv(path, dtype={c: str for c in required})
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputFileError(f"{path}: not a readable CSV table ({str(exc).splitlines()[0]})") from None
    missing = [c for c in required if c not in df.columns]
    if missing:
        raise DatasetError(f"{path}: missing column(s) {', '.join(missing)} "
                           f"(found: {', '.join(df.columns) or 'none'})")
    for c in required:
        df[c] = df[c].fillna("")
    return df


def stage_table(stage, table: pd.DataFrame, name: str) -> None:
    """Write ``table`` as ``name`` (CSV) plus its Parquet copy into a staged update
    (:mod:`data_tools.staging`), registered now: stage the manifest last so it moves in last."""
    stage.path(Path(name).with_suffix(".parquet"))
    write_table(table, stage.path(name))
