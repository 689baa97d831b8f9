"""The prepared single-plant dataset: the layout ``pheno4d prepare`` and ``helios`` write and
``tpvp experiments plants|season --dataset`` read.

Per plant and session ``<plant>/<plant>_<MMDD>.ply`` (the plant in metres, labels kept),
``..._normalised.ply`` (largest side ``largest_side``, centred; docs/single_plant.md#normalisation)
and ``..._gt<res>mm.ply`` (ground-truth voxel centres of the normalised plant), plus
``manifest.csv`` (one row per scan, :data:`MANIFEST_COLUMNS`) and ``pairs.csv`` (each scan with
the plant's next one, :data:`PAIR_COLUMNS`). :func:`write_scan` writes one scan and returns its
manifest row; the callers publish the whole folder with :func:`tpvp.io.publish.staged_folder`.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from data_tools.errors import ConfigError, TpvpError
from tpvp.io import write_point_cloud
from tpvp.scene.normalise import normalise_plant
from tpvp.scene.organs import LABEL_KINDS
from tpvp.scene.voxels import voxel_centres

__all__ = ["MANIFEST_COLUMNS", "PAIR_COLUMNS", "Scan", "ScanConfig", "session_pairs", "write_scan"]

MANIFEST_COLUMNS = ("plant", "species", "date", "file", "normalised_file", "gt_file", "points",
                    "plant_points", "extent_x", "extent_y", "extent_z", "scale", "gt_voxels", "labelled",
                    "label_kind", "source")
PAIR_COLUMNS = ("plant", "species", "previous_date", "current_date", "days_apart",
                "previous_file", "current_file")


@dataclass(frozen=True)
class ScanConfig:
    """How a scan's normalised copy and ground truth are made (docs/single_plant.md#normalisation)."""

    largest_side: float = 0.24  # m, largest bounding-box side after normalisation
    gt_resolution: float = 0.002  # m, ground-truth voxel size
    centre: str = "bbox"  # "bbox" (paper) or "centroid" (the authors' code)

    def __post_init__(self):
        for name in ("largest_side", "gt_resolution"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or isinstance(value, bool) \
                    or not np.isfinite(value) or value <= 0:
                raise ConfigError(f"{name} must be a positive number of metres, got {value!r}")
        if self.centre not in ("bbox", "centroid"):
            raise ConfigError(f"centre must be 'bbox' or 'centroid', got {self.centre!r}")

    @property
    def gt_tag(self) -> str:
        """Resolution in the ground-truth file name: 0.002 -> "2mm", 0.0015 -> "1p5mm"."""
        return f"{self.gt_resolution * 1000:g}".replace(".", "p") + "mm"


@dataclass(frozen=True)
class Scan:
    """One session of one plant, ready to write."""

    plant: str  # "Tomato01": the plant's folder and file names
    species: str
    date: dt.date
    points: np.ndarray  # (N, 3) the plant, metres
    labels: np.ndarray | None  # (N,) integer labels, or None
    label_kind: str  # what the labels mean (tpvp.scene.organs.LABEL_KINDS)
    source: str  # where it came from, as the manifest shows it
    origin: str = ""  # what errors name (default: source)
    scanned_points: int | None = None  # points before any were left out (default: len(points))


def write_scan(stage, scan: Scan, config: ScanConfig) -> dict:
    """Write ``scan``'s three files into the staging folder ``stage`` and return its manifest row.
    A cloud that cannot be normalised raises its one-line error, naming ``scan.origin``."""
    if scan.label_kind not in LABEL_KINDS:
        raise ConfigError(f"unknown label kind {scan.label_kind!r}; choose one of {', '.join(LABEL_KINDS)}")
    origin = scan.origin or scan.source
    try:
        extent = np.ptp(scan.points, axis=0)
        scene = normalise_plant(scan.points, largest_side=config.largest_side, centre=config.centre)
        gt = voxel_centres(scene.points, config.gt_resolution)
    except TpvpError as exc:
        message = str(exc)
        if origin not in message:
            message = f"{origin}: {message}"
        raise type(exc)(message) from None

    stem = f"{scan.plant}_{scan.date:%m%d}"
    folder = Path(scan.plant)
    file = folder / f"{stem}.ply"
    normalised_file = folder / f"{stem}_normalised.ply"
    gt_file = folder / f"{stem}_gt{config.gt_tag}.ply"
    write_point_cloud(stage.path(file), scan.points, scan.labels)
    write_point_cloud(stage.path(normalised_file), scene.points, scan.labels)
    write_point_cloud(stage.path(gt_file), gt)
    return {
        "plant": scan.plant,
        "species": scan.species,
        "date": scan.date.isoformat(),
        "file": file.as_posix(),
        "normalised_file": normalised_file.as_posix(),
        "gt_file": gt_file.as_posix(),
        "points": int(len(scan.points) if scan.scanned_points is None else scan.scanned_points),
        "plant_points": int(len(scan.points)),
        "extent_x": float(extent[0]),
        "extent_y": float(extent[1]),
        "extent_z": float(extent[2]),
        "scale": float(scene.scale),
        "gt_voxels": int(len(gt)),
        "labelled": scan.labels is not None,
        "label_kind": scan.label_kind,
        "source": scan.source,
    }


def session_pairs(manifest: pd.DataFrame) -> pd.DataFrame:
    """(previous, current) session pairs: each scan with the plant's next scan in time."""
    rows = []
    for plant, scans in manifest.sort_values(["plant", "date"]).groupby("plant", sort=True):
        scans = scans.to_dict("records")
        for previous, current in zip(scans, scans[1:]):
            days = (dt.date.fromisoformat(current["date"])
                    - dt.date.fromisoformat(previous["date"])).days
            rows.append({"plant": plant, "species": current["species"],
                         "previous_date": previous["date"], "current_date": current["date"],
                         "days_apart": days, "previous_file": previous["file"],
                         "current_file": current["file"]})
    pairs = pd.DataFrame(rows, columns=list(PAIR_COLUMNS))
    return pairs.astype({"days_apart": "int64"})
