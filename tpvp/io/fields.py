"""Fields of a point-cloud file besides x, y, z: which hold labels, and how they are typed."""

from __future__ import annotations

import logging

import numpy as np

log = logging.getLogger(__name__)

#: Column/property names taken as per-point integer labels.
LABEL_NAMES = ("label", "labels", "class", "classification", "scalar_label", "semantic",
               "semantic_label", "category")


def unique_names(names: list[str]) -> list[str]:
    """``names`` made unique (``_``, ``_1``, ``_2``, ...): structured dtypes need unique field
    names, and PCL pads with several "_" fields."""
    seen: set[str] = set()
    out = []
    for n in names:
        key, i = n, 1
        while key in seen:
            key, i = f"{n}_{i}", i + 1
        seen.add(key)
        out.append(key)
    return out


def label_index(names: list[str]) -> int | None:
    """Index of the first field named like a label (:data:`LABEL_NAMES`, any case), or None."""
    low = [n.lower() for n in names]
    return next((i for i, n in enumerate(low) if n in LABEL_NAMES), None)


def int_labels(path, values: np.ndarray, what: str) -> np.ndarray | None:
    """``values`` as int64 labels; None (logged) when they are not whole numbers."""
    values = np.asarray(values)
    if values.dtype.kind in "iu":
        return values.astype(np.int64)
    if np.isfinite(values).all() and np.array_equal(values, np.round(values)):
        return values.astype(np.int64)
    log.info("%s: %s is not integer-valued; not returned as labels", path, what)
    return None


def as_declared(cols: np.ndarray, codes: list[str]) -> np.ndarray:
    """Round text values to the declared float type, so ASCII and binary files read alike."""
    out = np.array(cols, dtype=np.float64)
    for j, code in enumerate(codes):
        if code in ("f2", "f4"):
            out[:, j] = out[:, j].astype(code)
    return out
