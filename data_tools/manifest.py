"""Manifest tables of the prepared datasets: CSV (the one read back) plus a Parquet copy.

Both files are written atomically (temporary file + rename). The Parquet copy is written first, so
an interruption leaves the CSV - the table of record - either old or new, never half-written.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import pandas as pd

from data_tools.errors import DatasetError, InputFileError
from tpvp.io import atomic_path, atomic_write_text
from tpvp.io.publish import RUN_MARKER


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
    """Write ``table`` as ``name`` (CSV) plus its Parquet copy into the staging folder of a
    :func:`tpvp.io.publish.staged_folder` run (both files are new files there: the published copies
    of a ``keep_existing`` stage are never touched)."""
    stage.path(Path(name).with_suffix(".parquet"))
    write_table(table, stage.path(name))


def _files(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if not p.is_dir()} if folder.is_dir() else set()


def record_written(stage) -> None:
    """Add the files this run created to the dataset's list of files tpvp wrote (``.tpvp-run.json``,
    see :mod:`tpvp.io.publish`), so that a later rebuild with ``--force`` (a whole-folder run) may
    replace them. Call it last in a ``keep_existing`` stage. A new dataset gets the list; a dataset
    that has none (written by hand or by an older version) keeps having none - its other files'
    origin is unknown."""
    marker = stage.existing(RUN_MARKER)
    if marker.is_file():
        try:
            payload = json.loads(marker.read_text())
            listed = set(payload["files"])
        except (OSError, ValueError, TypeError, KeyError):
            return  # unreadable: leave it as it is, a --force rebuild will name the files it refuses
    elif not stage.destination.exists():
        payload, listed = {}, set()
    else:
        return
    created = _files(stage.folder) - _files(stage.destination) - {RUN_MARKER}
    if not created - listed and marker.is_file():
        return
    payload["files"] = sorted(listed | created)
    atomic_write_text(stage.path(RUN_MARKER), json.dumps(payload, indent=1) + "\n")
