"""Pheno4D: download the public archive and prepare a clean single-plant dataset.

Pheno4D (Schunck et al., PLOS ONE 2021, https://www.ipb.uni-bonn.de/data/pheno4d/) holds laser
scans of 7 maize and 7 tomato plants, scanned on most days of a few weeks in 2020. Layout of the
archive: plant folders ``Maize01..Maize07`` and ``Tomato01..Tomato07`` (possibly under a top folder
``Pheno4D/``) holding text files ``M01_0313_a.txt`` / ``T03_0305.txt``: ``x y z [label ...]`` in
millimetres, ``MMDD`` the scan date, ``_a`` = annotated (labels 0 soil, 1 stem, 2+ leaf instances).

:func:`prepare_pheno4d` turns the archive (or the three scans bundled with tpvp) into one folder per
plant with, per scan day, the scan in metres, the normalised plant (docs/single_plant.md#normalisation) and the
ground-truth voxel grid, plus ``manifest.csv`` (one row per scan) and ``pairs.csv`` (previous /
current session pairs). The raw data is only read, never modified.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import os
import re
import shutil
import tempfile
import warnings
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from data_tools.download import download_file, verify_zip
from data_tools.errors import ConfigError, DatasetError, InputFileError, TpvpError
from data_tools.manifest import stage_table
from data_tools.prepared import MANIFEST_COLUMNS, PAIR_COLUMNS, Scan, ScanConfig, session_pairs, write_scan
from tpvp.io import atomic_write_bytes, atomic_write_text, read_point_cloud
from tpvp.io.publish import check_outputs_outside_inputs, staged_folder

__all__ = [
    "MANIFEST_COLUMNS",
    "PAIR_COLUMNS",
    "PHENO4D_PAGE",
    "PHENO4D_URL",
    "Pheno4DConfig",
    "ScanRecord",
    "bundled_scans",
    "download_pheno4d",
    "find_scans",
    "prepare_pheno4d",
    "session_pairs",
]

PHENO4D_PAGE = "https://www.ipb.uni-bonn.de/data/pheno4d/"
PHENO4D_URL = "https://www.ipb.uni-bonn.de/html/projects/Pheno4D/Pheno4D.zip"
ARCHIVE_NAME = "Pheno4D.zip"
FOLDER_NAME = "Pheno4D"

EXPECTED_LAYOUT = ("plant folders Maize01..Maize07 / Tomato01..Tomato07 (possibly under a top "
                   "folder Pheno4D/) holding files like Maize01/M01_0313_a.txt or "
                   "Tomato03/T03_0305.txt")

# File name of one scan: species letter, plant number, MMDD, optional "_a" (annotated).
_SCAN_NAME = re.compile(r"^(?P<letter>[MT])(?P<number>\d{2})_(?P<mmdd>\d{4})(?P<annotated>_a)?\.txt$",
                        re.IGNORECASE)
_PLANT_FOLDER = re.compile(r"^(?P<species>maize|tomato)(?P<number>\d{2})$", re.IGNORECASE)
_SPECIES = {"m": "maize", "t": "tomato"}

# The real scans bundled with tpvp (tpvp.scene.samples): sample name, plant id, species, MMDD.
_BUNDLED = (
    ("maize_0313", "MaizeSample", "maize", "0313"),
    ("tomato_0305", "TomatoSample", "tomato", "0305"),
    ("tomato_0306", "TomatoSample", "tomato", "0306"),
)
_BUNDLED_YEAR = 2020


@dataclass(frozen=True)
class Pheno4DConfig:
    """How scans are prepared (docs/single_plant.md#normalisation)."""

    largest_side: float = 0.24  # m, largest bounding-box side after normalisation
    gt_resolution: float = 0.002  # m, ground-truth voxel size
    year: int = 2020  # year of the MMDD dates in the file names
    centre: str = "bbox"  # "bbox" (paper) or "centroid" (the authors' code)
    # Label of the soil/pot points of annotated scans: left out of the prepared plant (they are
    # not plant surface to plan for, and would set the plant's size). The archive keeps them.
    # None keeps them. Unannotated scans are used whole.
    soil_label: int | None = 0

    def __post_init__(self):
        ScanConfig(self.largest_side, self.gt_resolution, self.centre)  # checks these three
        if not isinstance(self.year, int) or isinstance(self.year, bool) \
                or not 1 <= self.year <= 9999:
            raise ConfigError(f"year must be an integer year, got {self.year!r}")
        if self.soil_label is not None and (not isinstance(self.soil_label, (int, np.integer))
                                            or isinstance(self.soil_label, bool)):
            raise ConfigError(f"soil_label must be an integer label or None, got {self.soil_label!r}")

    @property
    def scan(self) -> ScanConfig:
        """How each scan's normalised copy and ground truth are made (:func:`data_tools.prepared.write_scan`)."""
        return ScanConfig(self.largest_side, self.gt_resolution, self.centre)

    @property
    def gt_tag(self) -> str:
        """Resolution in the ground-truth file name: 0.002 -> "2mm", 0.0015 -> "1p5mm"."""
        return self.scan.gt_tag


@dataclass(frozen=True)
class ScanRecord:
    """One scan found in the raw data."""

    plant: str  # "Maize01", "Tomato03", "TomatoSample"
    species: str  # "maize" or "tomato"
    date: dt.date
    source: str  # file path, or "archive.zip::member" for a scan inside the ZIP archive
    annotated: bool  # an "_a" file (per-point labels)


# --------------------------------------------------------------------------------------------
# download


def download_pheno4d(output, *, url: str = PHENO4D_URL, sha256: str | None = None,
                     extract: bool = True, progress: bool = True) -> Path:
    """Download ``Pheno4D.zip`` into ``output`` (resumable), check it and extract it.

    No official checksum is published: the download is checked by size and by the CRC of every
    ZIP member, and against ``sha256`` when given. Extraction goes to a temporary folder inside
    ``output`` that is renamed to ``output/Pheno4D`` when complete, so an existing
    ``output/Pheno4D`` is always whole and is returned without downloading again. Returns that
    folder, or the ZIP file with ``extract=False``.
    """
    output = Path(output)
    archive, folder = output / ARCHIVE_NAME, output / FOLDER_NAME
    if extract and folder.is_dir():
        return folder
    download_file(url, archive, sha256=sha256, progress=progress,
                  offline_hint=f"Download {url} by hand (e.g. in a browser) and prepare it directly: "
                               f"python -m data_tools pheno4d prepare PATH/{ARCHIVE_NAME}")
    verify_zip(archive, progress=progress)
    if not extract:
        return archive
    return _extract_atomically(archive, folder, progress)


def _extract_atomically(archive: Path, folder: Path, progress: bool) -> Path:
    from tqdm.auto import tqdm

    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.extract-", dir=folder.parent))
    except OSError as exc:
        raise InputFileError(f"cannot write to {folder.parent}: {exc.strerror or exc}") from None
    try:
        try:
            with zipfile.ZipFile(archive) as zf:
                members = zf.infolist()
                with tqdm(total=sum(m.file_size for m in members), unit="B", unit_scale=True,
                          unit_divisor=1024, desc=f"extract {archive.name}",
                          disable=not progress, leave=False) as bar:
                    for member in members:
                        zf.extract(member, tmp)  # zipfile drops "..", drive and root parts
                        bar.update(member.file_size)
        except (zipfile.BadZipFile, zlib.error, EOFError, ValueError) as exc:
            raise InputFileError(f"{archive}: cannot extract ({_first_line(exc)}): corrupt "
                                 f"archive? delete it and download again") from None
        except OSError as exc:
            raise InputFileError(f"{archive}: cannot extract into {folder.parent}: "
                                 f"{exc.strerror or exc}") from None
        # A single top folder that is not a plant folder ("Pheno4D/") is the dataset root.
        entries = list(tmp.iterdir())
        root = tmp
        if len(entries) == 1 and entries[0].is_dir() and not _PLANT_FOLDER.match(entries[0].name):
            root = entries[0]
        try:
            os.replace(root, folder)
        except OSError as exc:
            raise InputFileError(f"cannot create {folder}: {exc.strerror or exc}") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return folder


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


# --------------------------------------------------------------------------------------------
# finding scans


def _list_source(source: Path) -> tuple[list[str], str]:
    """Relative (POSIX) names of all files in a folder or ZIP archive, sorted, and the prefix that
    turns a name into a record source ("folder/" or "archive.zip::")."""
    if source.is_dir():
        names = []
        for root, dirs, files in os.walk(source):
            # Hidden folders (e.g. an interrupted extraction, .git) are not part of the data.
            dirs[:] = sorted(d for d in dirs if not d.startswith("."))
            rel = Path(root).relative_to(source)
            names.extend((rel / f).as_posix() for f in files)
        return sorted(names), f"{source}{os.sep}"
    try:
        with zipfile.ZipFile(source) as zf:
            names = [m.filename for m in zf.infolist() if not m.is_dir()]
    except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
        raise InputFileError(f"{source}: not a folder nor a readable ZIP archive "
                             f"({_first_line(exc)}); expected the Pheno4D folder or "
                             f"{ARCHIVE_NAME} with {EXPECTED_LAYOUT}") from None
    return sorted(names), f"{source}::"


def find_scans(source, *, year: int = 2020) -> tuple[list[ScanRecord], list[tuple[str, str]]]:
    """Scans in an extracted Pheno4D folder or in ``Pheno4D.zip`` (read without extracting).

    Returns ``(records, skipped)``: records sorted by plant and date, one per plant and day (the
    annotated ``_a`` file when a day exists twice); ``skipped`` lists ``(name, reason)`` for every
    other file. Raises InputFileError when ``source`` is missing or holds no scan.
    """
    source = Path(source)
    if not source.exists():
        raise InputFileError(f"{source}: not found; expected the extracted Pheno4D folder or "
                             f"{ARCHIVE_NAME} with {EXPECTED_LAYOUT}")
    names, prefix = _list_source(source)
    skipped: list[tuple[str, str]] = []
    candidates: dict[tuple[str, dt.date], list[tuple[str, bool]]] = {}
    for name in names:
        parts = name.split("/")
        match = _SCAN_NAME.match(parts[-1])
        if match is None:
            skipped.append((name, "not a Pheno4D scan name (expected e.g. Maize01/M01_0313_a.txt)"))
            continue
        species = _SPECIES[match["letter"].lower()]
        plant = f"{species.capitalize()}{match['number']}"
        folder = _PLANT_FOLDER.match(parts[-2]) if len(parts) > 1 else None
        if folder is not None and folder.group(0).lower() != plant.lower():
            skipped.append((name, f"file of plant {plant} inside folder {parts[-2]}"))
            continue
        mmdd = match["mmdd"]
        try:
            date = dt.date(year, int(mmdd[:2]), int(mmdd[2:]))
        except ValueError:
            skipped.append((name, f"{mmdd} is not a valid MMDD date in {year}"))
            continue
        candidates.setdefault((plant, date), []).append((name, bool(match["annotated"])))

    records = []
    for (plant, date), found in sorted(candidates.items()):
        # Prefer the annotated twin; among equals, the first name in sorted order.
        found.sort(key=lambda item: (not item[1], item[0]))
        name, annotated = found[0]
        for other, other_annotated in found[1:]:
            why = (f"annotated twin {name} used instead" if annotated and not other_annotated
                   else f"duplicate of {name}")
            skipped.append((other, why))
        species = "maize" if plant.startswith("Maize") else "tomato"
        records.append(ScanRecord(plant, species, date, prefix + name, annotated))
    if not records:
        raise InputFileError(f"{source}: no Pheno4D scan found ({len(names)} file(s) looked at); "
                             f"expected {EXPECTED_LAYOUT}")
    skipped.sort()
    return records, skipped


def bundled_scans() -> list[ScanRecord]:
    """The three real Pheno4D scans bundled with tpvp (works offline; MIT licence)."""
    from tpvp.scene.samples import sample_path

    return [ScanRecord(plant, species, _bundled_date(mmdd), str(sample_path(name)), False)
            for name, plant, species, mmdd in _BUNDLED]


def _bundled_date(mmdd: str) -> dt.date:
    return dt.date(_BUNDLED_YEAR, int(mmdd[:2]), int(mmdd[2:]))


# --------------------------------------------------------------------------------------------
# preparing


def _read_scan(record: ScanRecord, archive: zipfile.ZipFile | None, archive_prefix: str,
               workdir: Path):
    """(points in metres, labels or None) of one record; errors name ``record.source``."""
    if archive is None:
        return read_point_cloud(record.source, units="mm", return_labels=True)
    member = record.source[len(archive_prefix):]
    tmp = workdir / Path(member).name  # keeps the extension, which selects the reader
    try:
        with archive.open(member) as src, open(tmp, "wb") as dst:
            shutil.copyfileobj(src, dst, 1 << 20)
    except (zipfile.BadZipFile, zlib.error, EOFError, ValueError, KeyError) as exc:
        tmp.unlink(missing_ok=True)
        raise InputFileError(f"{record.source}: corrupt ZIP member ({_first_line(exc)})") from None
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise InputFileError(f"{record.source}: cannot extract to {workdir}: "
                             f"{exc.strerror or exc}") from None
    # The reader names the temporary file in errors and warnings: name the member instead.
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = read_point_cloud(tmp, units="mm", return_labels=True)
    except TpvpError as exc:
        raise type(exc)(str(exc).replace(str(tmp), record.source)) from None
    finally:
        tmp.unlink(missing_ok=True)
    for warning in caught:
        warnings.warn(str(warning.message).replace(str(tmp), record.source), warning.category,
                      stacklevel=3)
    return result


def prepare_pheno4d(source=None, output="data/pheno4d", config: Pheno4DConfig = Pheno4DConfig(),
                    *, force: bool = False, progress: bool = True) -> pd.DataFrame:
    """Prepare Pheno4D scans (``source``: extracted folder or ZIP; None = the bundled samples).

    Writes per scan ``<output>/<plant>/<plant>_<MMDD>.ply`` (the plant - soil points of annotated
    scans left out - in metres, scanner frame, labels kept; consecutive days share the scanner
    frame, so ``pairs.csv`` points at these), ``..._normalised.ply`` (largest side
    ``config.largest_side``, centred; each scan on its own, so two days' copies do not share a
    frame) and
    ``..._gt<res>mm.ply`` (ground-truth voxel centres of the normalised plant), then ``NOTICE.md``,
    ``pairs.csv`` and ``manifest.csv`` (+ Parquet copies), written into a staging folder beside
    ``output`` and published in one step (:func:`tpvp.io.publish.staged_folder`). The output is a
    whole new dataset: ``force`` replaces the previous one (files of plants no longer in the source
    included, so two preparations never mix); a concurrent run on the same output is refused at once
    (exit status 3), an output that is, holds or lies inside the source is refused before anything
    is read, and an error or
    Ctrl-C leaves the output wholly old or wholly new. Returns the manifest; its
    ``attrs`` hold ``"pairs"`` (DataFrame) and ``"skipped"`` (list of (name, reason)).
    """
    from tqdm.auto import tqdm

    if not isinstance(config, Pheno4DConfig):
        raise ConfigError(f"config must be a Pheno4DConfig, got {type(config).__name__}")
    output = Path(output)

    if source is None:
        from tpvp.scene.samples import SAMPLES

        records, skipped = bundled_scans(), []
        shown = {r.source: f"tpvp/data/pheno4d/{SAMPLES[name]}"
                 for r, (name, *_) in zip(records, _BUNDLED)}
        archive_path = None
        inputs = [r.source for r in records]
    else:
        inputs = [source]
        check_outputs_outside_inputs(output, inputs, "dataset")  # before listing and reading the source
        records, skipped = find_scans(source, year=config.year)
        shown = {r.source: r.source for r in records}
        archive_path = Path(source) if Path(source).is_file() else None

    rows = []
    with staged_folder(output, inputs=inputs, what="dataset") as stage, contextlib.ExitStack() as stack:
        # Under the output's lock: no other run can prepare it between this check and the commit.
        manifest_path = output / "manifest.csv"
        if stage.existing("manifest.csv").exists() and not force:
            raise DatasetError(f"{manifest_path} exists: this dataset was prepared already; pass "
                               f"--force to prepare it again (files are replaced)")
        archive, prefix, workdir = None, "", None
        if archive_path is not None:
            try:
                archive = stack.enter_context(zipfile.ZipFile(archive_path))
            except (zipfile.BadZipFile, OSError) as exc:
                raise InputFileError(f"{archive_path}: not a readable ZIP archive "
                                     f"({_first_line(exc)})") from None
            prefix = f"{archive_path}::"
            workdir = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="tpvp-pheno4d-")))
        for record in tqdm(records, desc="prepare Pheno4D", unit="scan", disable=not progress):
            rows.append(_prepare_scan(record, archive, prefix, workdir, stage, config,
                                      shown[record.source]))
        manifest = pd.DataFrame(rows, columns=list(MANIFEST_COLUMNS))
        pairs = session_pairs(manifest)
        _write_notice(stage, source, config, skipped)
        stage_table(stage, pairs, "pairs.csv")
        stage_table(stage, manifest, "manifest.csv")
    manifest.attrs["pairs"] = pairs
    manifest.attrs["skipped"] = list(skipped)
    return manifest


def _prepare_scan(record: ScanRecord, archive, prefix: str, workdir, stage,
                  config: Pheno4DConfig, shown_source: str) -> dict:
    try:
        points, labels = _read_scan(record, archive, prefix, workdir)
        plant = np.ones(len(points), dtype=bool)
        if labels is not None and config.soil_label is not None:
            plant = labels != config.soil_label
            if not plant.any():
                raise DatasetError(f"every point has the soil label {config.soil_label}: no plant left")
    except TpvpError as exc:
        message = str(exc)
        if record.source not in message:
            message = f"{record.source}: {message}"
        raise type(exc)(message) from None
    scan = Scan(record.plant, record.species, record.date, points[plant],
                labels[plant] if labels is not None else None, "pheno4d", shown_source,
                origin=record.source, scanned_points=len(points))
    return write_scan(stage, scan, config.scan)


def _write_notice(stage, source, config: Pheno4DConfig,
                  skipped: list[tuple[str, str]]) -> None:
    settings = (f"Plants in metres (scanner frame, labels kept); normalised copies scaled to a "
                f"largest side of {config.largest_side} m and centred on the "
                f"{'bounding-box centre' if config.centre == 'bbox' else 'centroid'}; "
                f"ground-truth voxel grids at {config.gt_resolution} m."
                + (f" Points labelled {config.soil_label} (soil) of annotated scans are left out; the "
                   "original archive keeps them." if config.soil_label is not None else ""))
    if source is None:
        from tpvp.scene.samples import DATA

        atomic_write_bytes(stage.path("LICENSE"), (DATA / "LICENSE").read_bytes())
        text = [
            "# Pheno4D samples bundled with tpvp",
            "",
            "Three real laser scans from the public Pheno4D / 4D plant registration data of "
            "Chebrolu, Magistri, Läbe and Stachniss (University of Bonn), as published in "
            "PRBonn/4d_plant_registration under the MIT licence (see `LICENSE` in this folder).",
            f"Dataset page: {PHENO4D_PAGE}",
            "",
            settings,
        ]
    else:
        text = [
            "# Pheno4D, prepared by tpvp",
            "",
            f"Prepared from `{source}`, the Pheno4D dataset of the University of Bonn "
            f"(Schunck et al., \"Pheno4D: A spatio-temporal dataset of maize and tomato plant "
            f"point clouds for phenotyping and advanced plant analysis\", PLOS ONE 16(8): "
            f"e0256340, 2021).",
            f"Dataset page and terms of use: {PHENO4D_PAGE} - check them before redistributing "
            f"these files, and cite the paper when you use them.",
            "",
            settings,
        ]
    if skipped:
        text += ["", f"Files skipped ({len(skipped)}):", ""]
        text += [f"- `{name}`: {reason}" for name, reason in skipped]
    atomic_write_text(stage.path("NOTICE.md"), "\n".join(text) + "\n")
