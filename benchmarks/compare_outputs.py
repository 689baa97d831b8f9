"""Compare two result folders written by ``benchmarks/reference_outputs.sh`` (or any two runs of
the same commands) value for value: every table (CSV, Parquet) and every JSON / YAML document, with
the fields that measure time or name the machine left out. Exit 0 when everything else is
identical, 1 otherwise; the table printed lists each compared file.

    python benchmarks/compare_outputs.py BEFORE AFTER
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import pandas as pd
import yaml

# Fields that differ between two identical runs: wall times, dates, host and code identity.
VOLATILE = re.compile(r"(^|_)(time|times|timings|seconds|s|wall|elapsed|date|created|started|finished|host|"
                      r"hostname|version|code|commit|python|platform|cache|compile|duration|utc)$"
                      r"|_time|time_|seconds|timing", re.IGNORECASE)
SKIPPED_FILES = {"provenance.json", "manifest.json"}
# Tables of measured times (planning time per stage, inference time): only their labels compare.
TIMING_TABLE = re.compile(r"time|seconds", re.IGNORECASE)
SKIPPED_FOLDERS = {"cache", ".ipynb_checkpoints", "mathjax"}


def volatile(key) -> bool:
    return bool(VOLATILE.search(str(key)))


def without_volatile(value):
    if isinstance(value, dict):
        return {k: without_volatile(v) for k, v in value.items() if not volatile(k)}
    if isinstance(value, list):
        return [without_volatile(v) for v in value]
    return value


STAGING = re.compile(r"\.[^/]*\.tpvp-staging-\d+")


def without_roots(table: pd.DataFrame, root: Path) -> pd.DataFrame:
    """Paths inside a result folder name the folder (and the staging folder it was written in):
    compared relative to it."""
    for column in [c for c in table.columns if table[c].dtype == object or pd.api.types.is_string_dtype(table[c])]:
        table[column] = table[column].map(lambda v: STAGING.sub("<staging>", v.replace(str(root), "<root>"))
                                          if isinstance(v, str) else v)
    return table


def read_table(path: Path, root: Path) -> pd.DataFrame:
    table = without_roots(pd.read_parquet(path) if path.suffix == ".parquet" else pd.read_csv(path), root)
    table = table[[c for c in table.columns if not volatile(c)]]
    if TIMING_TABLE.search(path.stem):
        table = table.select_dtypes(exclude="float")
    # Rows of parallel runs arrive in completion order: compare as sorted sets of rows.
    return table.sort_values(list(table.columns), kind="stable", ignore_index=True) if len(table.columns) else table


def compare_tables(before: Path, after: Path, roots) -> str:
    a, b = read_table(before, roots[0]), read_table(after, roots[1])
    if list(a.columns) != list(b.columns):
        return f"columns differ: {sorted(set(a.columns) ^ set(b.columns))}"
    if a.shape != b.shape:
        return f"shape {a.shape} -> {b.shape}"
    differing = [c for c in a.columns if not a[c].equals(b[c])]
    return f"values differ in {differing}" if differing else ""


def read_document(path: Path):
    text = path.read_text()
    try:
        return without_volatile(json.loads(text) if path.suffix == ".json" else yaml.safe_load(text))
    except (ValueError, yaml.YAMLError):  # not plain JSON / YAML (e.g. OpenCV's %YAML:1.0): as text
        return text


def compare_documents(before: Path, after: Path, roots) -> str:
    a, b = read_document(before), read_document(after)
    if a == b:
        return ""
    if isinstance(a, dict) and isinstance(b, dict):
        keys = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
        return f"keys differ: {keys[:8]}"
    return "contents differ"


COMPARERS = {".csv": compare_tables, ".parquet": compare_tables, ".json": compare_documents,
             ".yaml": compare_documents}


def compared_files(root: Path) -> set[Path]:
    return {p.relative_to(root) for p in root.rglob("*")
            if p.suffix in COMPARERS and p.name not in SKIPPED_FILES
            and not SKIPPED_FOLDERS & set(p.relative_to(root).parts)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    args = parser.parse_args(argv)
    files_before, files_after = compared_files(args.before), compared_files(args.after)
    failures = 0
    print(f"{'file':64s} result")
    for name in sorted(files_before | files_after):
        if name not in files_after or name not in files_before:
            result = "only in " + ("before" if name in files_before else "after")
        else:
            result = COMPARERS[name.suffix](args.before / name, args.after / name,
                                            (args.before.resolve(), args.after.resolve())) or "identical"
        failures += result != "identical"
        print(f"{str(name):64s} {result}")
    print(f"\n{len(files_before | files_after)} files compared, {failures} differ")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
