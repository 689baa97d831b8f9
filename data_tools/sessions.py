"""``prepare-session``: a user's new scan into an existing (or new) dataset of a site.

The scan is aligned to the site's reference day (landmarks + ICP on the static structure kept in
``reference/<site>_static.pcd``), cropped and cleaned like every other session
(:mod:`data_tools.greenhouse`), then written into the dataset and appended to its manifest. The raw
scan is only read. An existing session is replaced only with ``force``.

The dataset is both read and written (``keep_existing``), but the user's files are not part of it:
a dataset that is, holds or lies inside the scan or the landmarks file is refused before anything
is read. A scan kept inside the dataset would be mixed with the files the tools wrote there (and
overwritten when it sits where its own session's model goes), so it must stay outside; a dataset
merely beside the scan, in the same folder, is fine: this command reads only the files it is given.

The dataset is updated through :func:`tpvp.io.publish.staged_folder` with ``keep_existing=True``:
the run adds or replaces its session's files in a hard-linked copy of the dataset, which then
replaces the dataset in one step. Everything that reads the dataset (manifest, reference day, box
configuration, the ``force`` check) happens under its lock, so two runs on one dataset cannot both
succeed with one of their sessions lost: the second is refused at once (exit status 3). An error or
Ctrl-C leaves the dataset wholly old or wholly new.

A site without a dataset entry yet starts one: the new scan becomes its reference day. Its plant
box comes from ``config/<site>_bbx_config.yaml`` in the dataset, or the bundled room configuration
(room1, room4); a site with no box is only cleaned (no crop, no support removal).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from data_tools.alignment import IcpConfig, read_landmarks
from data_tools.cleaning import CleanConfig
from data_tools.errors import DatasetError, InputFileError, PointCloudError
from data_tools.greenhouse import (
    MANIFEST_COLUMNS,
    SessionScan,
    check_site,
    parse_date,
    process_session,
    reference_file,
    session_row,
    site_boxes,
    stage_copy,
    write_reference,
    write_session,
)
from data_tools.manifest import read_table, record_written, stage_table
from tpvp.io import read_point_cloud
from tpvp.io.publish import check_outputs_outside_inputs, staged_folder

#: A new scan whose extent differs from the reference day's by more than this factor has wrong units.
UNITS_RATIO_LIMIT = 20.0


def _dataset_file(path: Path, read):
    """Read a file of the dataset; a broken one is a DatasetError naming it (not an input error)."""
    try:
        return read(path)
    except (InputFileError, PointCloudError) as exc:
        message = str(exc)
        raise DatasetError(message if str(path) in message else f"{path}: {message}") from None


def _reference_cloud(dataset: Path, site: str, reference_row) -> np.ndarray:
    static = dataset / reference_file(site)
    path = static if static.is_file() else dataset / reference_row["file"]
    return _dataset_file(path, lambda p: read_point_cloud(p, units="m"))


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
    site = check_site(site)
    date = parse_date(date)
    landmarks = Path(landmarks) if landmarks is not None else None
    if not scan.is_file():
        raise InputFileError(f"{scan}: scan not found")
    inputs = [scan, landmarks]
    check_outputs_outside_inputs(dataset, inputs, "dataset")
    # The inputs are read before the dataset is locked: their errors name them and cost no lock time.
    points = read_point_cloud(scan, units=units)
    if landmarks is not None:
        read_landmarks(landmarks)
    session = SessionScan(site, date, scan, landmarks)
    with staged_folder(dataset, keep_existing=True, inputs=inputs, what="dataset") as stage:
        row = _add_session(stage, session, points, units, clean, icp, force)
    return row


def _add_session(stage, session: SessionScan, points: np.ndarray, units: str, clean: CleanConfig,
                 icp: IcpConfig, force: bool) -> dict:
    """The part of :func:`prepare_session` that reads and writes the dataset (under its lock)."""
    dataset, site, date = stage.destination, session.site, session.date
    manifest_path = dataset / "manifest.csv"
    table = _dataset_file(manifest_path, lambda p: read_table(p, required=("site", "date", "file", "reference_date"))) \
        if manifest_path.exists() else pd.DataFrame(columns=list(MANIFEST_COLUMNS))
    mine = table[table["site"] == site]
    existing = mine[mine["date"] == f"{date:%Y-%m-%d}"]
    if len(existing) and not force:
        raise DatasetError(f"session {site} {date} already exists in {manifest_path} "
                           f"({existing.iloc[0]['file']}); pass --force to replace it")
    boxes, config_path = site_boxes(site, dataset / "config")
    box = boxes["plant_box"] if boxes is not None else None
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
        reference_date = parse_date(reference_row["reference_date"], f"{manifest_path}: reference_date")
        _check_units(session.path, points, reference)
    cleaned, alignment, counts = process_session(session, points, reference, box, clean, icp)
    row = session_row(session, reference_date, counts, cleaned, box, alignment, units)
    others = table[~((table["site"] == site) & (table["date"] == row["date"]))]
    updated = pd.concat([others, pd.DataFrame([row])], ignore_index=True) if len(others) else pd.DataFrame([row])
    updated = updated.sort_values(["site", "date"], kind="stable").reset_index(drop=True)
    if config_path is not None and config_path.parent != dataset / "config":
        stage_copy(stage, config_path, f"config/{site}_bbx_config.yaml")
    if is_reference:
        write_reference(stage, site, points, icp)
    write_session(stage, session, cleaned, alignment)
    stage_table(stage, updated, "manifest.csv")
    record_written(stage)
    return row
