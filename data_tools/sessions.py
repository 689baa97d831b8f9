"""``prepare-session``: a user's new scan into an existing (or new) dataset of a site.

The scan is aligned to the site's reference day (landmarks + ICP on the static structure kept in
``reference/<site>_static.pcd``), cropped and cleaned like every other session
(:mod:`data_tools.greenhouse`), then written into the dataset and appended to its manifest. The raw
scan is only read. An existing session is replaced only with ``force``; all files are staged and
committed together, so an interrupted run leaves the dataset as it was.

A site without a dataset entry yet starts one: the new scan becomes its reference day. Its plant
box comes from ``config/<site>_bbx_config.yaml`` in the dataset, or the bundled room configuration
(room1, room4); a site with no box is only cleaned (no crop, no support removal).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from data_tools.alignment import IcpConfig
from data_tools.cleaning import CleanConfig
from data_tools.errors import ConfigError, DatasetError, InputFileError, PointCloudError
from data_tools.greenhouse import (
    MANIFEST_COLUMNS,
    PROCESSED_FOLDER,
    SessionScan,
    session_row,
    parse_date,
    process_session,
    reference_file,
    site_boxes,
    write_reference,
    write_session,
)
from data_tools.manifest import read_table, stage_table
from data_tools.staging import staged_update
from tpvp.io import read_point_cloud

#: A new scan whose extent differs from the reference day's by more than this factor has wrong units.
UNITS_RATIO_LIMIT = 20.0


def _reference_cloud(dataset: Path, site: str, reference_row) -> np.ndarray:
    static = dataset / reference_file(site)
    path = static if static.is_file() else dataset / reference_row["file"]
    return read_point_cloud(path, units="m")


def _check_units(scan_path: Path, points: np.ndarray, reference: np.ndarray) -> None:
    ratio = np.ptp(points, axis=0).max() / max(np.ptp(reference, axis=0).max(), 1e-9)
    if ratio > UNITS_RATIO_LIMIT:
        raise PointCloudError(f"{scan_path}: spans {ratio:.0f} times the site's reference day "
                              "(millimetres? pass --units mm)")
    if ratio < 1.0 / UNITS_RATIO_LIMIT:
        raise PointCloudError(f"{scan_path}: spans 1/{1 / ratio:.0f} of the site's reference day "
                              "(a different unit? check --units)")


def prepare_session(dataset, site: str, date, scan, *, landmarks=None, units: str = "m",
                    clean: CleanConfig = CleanConfig(), icp: IcpConfig = IcpConfig(),
                    force: bool = False) -> dict:
    """Add ``scan`` as session ``date`` of ``site`` to ``dataset``; returns its manifest row."""
    dataset, scan = Path(dataset), Path(scan)
    site = str(site).strip().lower()
    date = parse_date(date)
    if not scan.is_file():
        raise InputFileError(f"{scan}: scan not found")
    manifest_path = dataset / "manifest.csv"
    table = read_table(manifest_path, required=("site", "date", "file", "reference_date")) \
        if manifest_path.exists() else pd.DataFrame(columns=list(MANIFEST_COLUMNS))
    mine = table[table["site"] == site]
    existing = mine[mine["date"] == f"{date:%Y-%m-%d}"]
    if len(existing) and not force:
        raise DatasetError(f"session {site} {date} already exists in {manifest_path} "
                           f"({existing.iloc[0]['file']}); pass --force to replace it")
    session = SessionScan(site, date, scan, Path(landmarks) if landmarks is not None else None)
    if scan.resolve().parent.parent == dataset.resolve() and scan.parent.name in ("reference", PROCESSED_FOLDER):
        raise ConfigError(f"{scan}: a file of the dataset itself; raw scans are never modified - "
                          "prepare a scan from outside the dataset")
    boxes, config_path = site_boxes(site, dataset / "config")
    box = boxes["plant_box"] if boxes is not None else None
    points = read_point_cloud(scan, units=units)
    references = mine[mine["date"] == mine["reference_date"]]
    is_reference = len(references) == 0 or (len(existing) and existing.iloc[0]["date"] == existing.iloc[0]["reference_date"])
    if is_reference and len(mine) > len(existing):
        raise DatasetError(f"session {site} {date} is the reference day of {len(mine) - 1} other session(s) in "
                           f"{manifest_path}: replacing it would move their frame; rebuild the site with "
                           "`python -m data_tools greenhouse clean` instead")
    if is_reference:
        reference, reference_date = None, date
    else:
        reference_row = references.iloc[0]
        reference = _reference_cloud(dataset, site, reference_row)
        reference_date = parse_date(reference_row["reference_date"])
        _check_units(scan, points, reference)
    cleaned, alignment, counts = process_session(session, points, reference, box, clean, icp)
    row = session_row(session, reference_date, counts, cleaned, box, alignment, units)
    others = table[~((table["site"] == site) & (table["date"] == row["date"]))]
    updated = pd.concat([others, pd.DataFrame([row])], ignore_index=True) if len(others) else pd.DataFrame([row])
    updated = updated.sort_values(["site", "date"], kind="stable").reset_index(drop=True)
    with staged_update(dataset) as stage:
        if config_path is not None and config_path.parent != dataset / "config":
            shutil.copyfile(config_path, stage.path(f"config/{site}_bbx_config.yaml"))
        if is_reference:
            write_reference(stage, site, points, icp)
        write_session(stage, session, cleaned, alignment)
        stage_table(stage, updated, "manifest.csv")
    return row
