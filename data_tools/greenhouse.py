"""The greenhouse multi-session row dataset: find the sessions, clean them, align them to day one.

Input layouts accepted (:func:`find_sessions`):

* a folder (searched recursively) of per-session scans whose names hold the room and the date,
  ``room1_20250918*.ply`` / ``room4-2025-09-22.pcd`` ... - the dataset's processed models
  ``Processed_3D_Model/room<k>_<YYYYMMDD>.pcd`` as well as raw captures;
* an explicit manifest CSV with columns ``site`` (or ``room``), ``date``, ``file`` and optionally
  ``landmarks`` (paths relative to the manifest).

Output (:func:`clean_greenhouse`), a dataset folder the notebooks and ``prepare-session`` read::

    Processed_3D_Model/<site>_<YYYYMMDD>.pcd   cleaned, aligned to the site's first day, metres
    transforms/<site>_<YYYYMMDD>.txt           4x4 capture frame -> reference frame
    reference/<site>_static.pcd                the first day's full scan (downsampled), to align
                                               later sessions on its static structure
    config/<site>_bbx_config.yaml              the plant/view boxes used for cropping
    report/<site>_sessions.png                 side and top views of every cleaned session
    manifest.csv (+ .parquet)                  one row per session, see MANIFEST_COLUMNS

The whole output is written into a staging folder beside the dataset and published in one step
(:func:`tpvp.io.publish.staged_folder`, a whole new dataset: ``--force`` replaces the previous one):
a concurrent run on the same dataset is refused (exit status 3), and an error or Ctrl-C leaves the
dataset wholly old or wholly new.
"""

from __future__ import annotations

import datetime as dt
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from data_tools.alignment import Alignment, IcpConfig, align_to_reference, transform_points
from data_tools.cleaning import CleanConfig, clean_scan, voxel_downsample
from data_tools.errors import ConfigError, DatasetError, InputFileError, PointCloudError
from data_tools.manifest import read_table, stage_table
from tpvp.io import READ_EXTENSIONS, atomic_write_bytes, atomic_write_text, cloud_extension, read_point_cloud, write_point_cloud
from tpvp.io.publish import check_outputs_outside_inputs, staged_folder
from tpvp.scene.boxes import DATA_DIR as BUNDLED_CONFIG_DIR
from tpvp.scene.boxes import OrientedBox, read_bbx_config
from tpvp.viz.figures import plot_row_sessions

PROCESSED_FOLDER = "Processed_3D_Model"
SESSION_NAME = re.compile(r"(?P<site>room\d+)[_\-. /]?(?P<date>20\d\d-?\d\d-?\d\d)", re.IGNORECASE)
MANIFEST_COLUMNS = (
    "site", "date", "file", "source", "reference_date", "transform_file",
    "points_raw", "points_cropped", "points_supports_removed", "points_outliers_removed",
    "points_downsampled", "points", "extent_x", "extent_y", "extent_z",
    "alignment", "fitness", "inlier_rmse_m", "landmark_rmse_m", "rotation_deg", "translation_m", "units",
)
# Preferred file types when one session has several files (point clouds before meshes).
_EXT_RANK = {ext: i for i, ext in enumerate((".pcd", ".ply", ".xyz", ".txt", ".pts", ".csv", ".obj", ".glb", ".stl", ".off"))}


@dataclass(frozen=True)
class SessionScan:
    """One session's input scan."""

    site: str
    date: dt.date
    path: Path
    landmarks: Path | None = None

    @property
    def name(self) -> str:
        return f"{self.site}_{self.date:%Y%m%d}"


@dataclass(frozen=True)
class Discovery:
    sessions: list[SessionScan]
    skipped: list[tuple[str, str]] = field(default_factory=list)  # (file, why)

    def report(self) -> str:
        """What was found and what was skipped, for the user."""
        lines = [f"found {len(self.sessions)} session(s):"]
        lines += [f"  {s.site} {s.date}  {s.path}" + (f"  (landmarks {s.landmarks.name})" if s.landmarks else "")
                  for s in self.sessions]
        if self.skipped:
            lines.append(f"skipped {len(self.skipped)} file(s):")
            lines += [f"  {name}: {why}" for name, why in self.skipped]
        return "\n".join(lines)


_SITE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_\-]{0,63}")


def check_site(value, what: str = "site") -> str:
    """A site (room) name as used in the dataset's file names: 1-64 ASCII letters, digits, '-' or
    '_', starting with a letter or digit; returned lower-case. ConfigError naming ``what`` otherwise
    (so ``../x``, ``a/b`` or an empty name can never move a file out of the dataset layout)."""
    text = str(value).strip() if value is not None else ""
    if not _SITE_NAME.fullmatch(text):
        raise ConfigError(f"{what} must be 1-64 letters, digits, '-' or '_' (starting with a letter or "
                          f"digit), got {value!r}")
    return text.lower()


def parse_date(value, what: str = "date") -> dt.date:
    """``YYYY-MM-DD`` or ``YYYYMMDD`` -> date; ConfigError naming ``what`` otherwise."""
    text = str(value).strip()
    digits = text.replace("-", "")
    if re.fullmatch(r"\d{8}", digits) and (len(text) == 8 or re.fullmatch(r"\d{4}-\d{2}-\d{2}", text)):
        try:
            return dt.date(int(digits[:4]), int(digits[4:6]), int(digits[6:]))
        except ValueError:
            pass
    raise ConfigError(f"{what} must be a date YYYY-MM-DD or YYYYMMDD, got {value!r}")


def _is_processed(path: Path, site: str, date: dt.date) -> bool:
    return PROCESSED_FOLDER.lower() in (p.lower() for p in path.parts) or path.stem.lower() == f"{site}_{date:%Y%m%d}"


def _landmarks_for(landmarks_dir: Path | None, site: str, date: dt.date) -> Path | None:
    if landmarks_dir is None:
        return None
    found = []
    for path in sorted(landmarks_dir.rglob("*")):
        match = SESSION_NAME.search(path.name)
        if path.is_file() and path.suffix.lower() in (".csv", ".txt") and match \
                and match["site"].lower() == site and parse_date(match["date"]) == date:
            found.append(path)
    if len(found) > 1:
        raise InputFileError(f"{landmarks_dir}: several landmark files for {site} {date}: "
                             f"{', '.join(p.name for p in found)}")
    return found[0] if found else None


def _session_match(relative: str):
    """The room/date match in a path relative to the source, nearest the file name (so both
    ``room1_20250918_raw.ply`` and ``room1/20250918/pointcloud.ply`` name their session)."""
    matches = list(SESSION_NAME.finditer(relative))
    return matches[-1] if matches else None


def find_sessions(source, *, manifest=None, landmarks=None) -> Discovery:
    """Find the session scans in ``source`` (a folder), or those listed in ``manifest`` (a CSV).

    A scan's room and date are read from its name or, failing that, its folders
    (``room1/20250918/scan.ply``). ``landmarks``: a folder of landmark files named like the
    sessions (``room1_20250918*.csv``), skipped when it lies inside ``source``. When a session
    has several files, the processed model is kept (then point clouds before meshes); the others
    are reported as skipped.
    """
    landmarks_dir = Path(landmarks) if landmarks is not None else None
    if landmarks_dir is not None and not landmarks_dir.is_dir():
        raise InputFileError(f"{landmarks_dir}: landmarks folder not found")
    if manifest is not None:
        return _sessions_from_manifest(Path(manifest), landmarks_dir)
    source = Path(source)
    if not source.is_dir():
        raise InputFileError(f"{source}: folder not found" if not source.exists() else
                             f"{source}: not a folder (pass the folder holding the session scans, or --manifest)")
    ignored = [landmarks_dir.resolve()] if landmarks_dir is not None else []
    candidates: dict[tuple[str, dt.date], list[Path]] = {}
    skipped = []
    for path in sorted(p for p in source.rglob("*") if p.is_file()):
        rel = path.relative_to(source).as_posix()
        if any(part.startswith(".") for part in path.relative_to(source).parts):
            continue  # hidden files and our own staging folders
        if any(folder in path.resolve().parents for folder in ignored):
            continue
        if cloud_extension(path)[0] not in READ_EXTENSIONS:
            skipped.append((rel, f"not a point cloud or mesh ({path.suffix or 'no extension'})"))
            continue
        if "landmark" in path.name.lower():
            skipped.append((rel, "a landmarks file (pass its folder with --landmarks)"))
            continue
        match = _session_match(rel)
        if not match:
            skipped.append((rel, "path holds no room and date (expected e.g. room1_20250918*.ply)"))
            continue
        try:
            date = parse_date(match["date"])
        except ConfigError:
            skipped.append((rel, f"{match['date']!r} is not a valid date"))
            continue
        candidates.setdefault((match["site"].lower(), date), []).append(path)
    sessions = []
    for (site, date), paths in sorted(candidates.items()):
        ranked = sorted(paths, key=lambda p: (not _is_processed(p, site, date), _EXT_RANK.get(p.suffix.lower(), 99), str(p)))
        for other in ranked[1:]:
            skipped.append((other.relative_to(source).as_posix(),
                            f"another file of {site} {date} was used: {ranked[0].relative_to(source).as_posix()}"))
        sessions.append(SessionScan(site, date, ranked[0], _landmarks_for(landmarks_dir, site, date)))
    if not sessions:
        raise InputFileError(f"{source}: no session scans found (expected files named like room1_20250918*.ply "
                             f"or {PROCESSED_FOLDER}/room1_20250915.pcd; {len(skipped)} file(s) skipped)")
    return Discovery(sessions, skipped)


def _sessions_from_manifest(path: Path, landmarks_dir: Path | None) -> Discovery:
    table = read_table(path, required=("date", "file"))
    site_column = "site" if "site" in table.columns else "room" if "room" in table.columns else None
    if site_column is None:
        raise DatasetError(f"{path}: missing column 'site' (or 'room')")
    sessions, seen = [], set()
    for i, row in table.iterrows():
        where = f"{path}, row {i + 2}"
        try:
            site = check_site(row[site_column], f"{where}: site")
        except ConfigError as exc:
            raise DatasetError(str(exc)) from None
        date = parse_date(row["date"], f"{where}: date")
        scan = (path.parent / row["file"]).resolve()
        if not scan.is_file():
            raise InputFileError(f"{where}: file {row['file']!r} not found ({scan})")
        if (site, date) in seen:
            raise DatasetError(f"{where}: session {site} {date} is listed twice")
        seen.add((site, date))
        marks = row.get("landmarks")
        marks = marks.strip() if isinstance(marks, str) else ""
        marks_path = (path.parent / marks).resolve() if marks else _landmarks_for(landmarks_dir, site, date)
        sessions.append(SessionScan(site, date, scan, marks_path))
    if not sessions:
        raise DatasetError(f"{path}: the manifest lists no sessions")
    return Discovery(sorted(sessions, key=lambda s: (s.site, s.date)), [])


# ----------------------------------------------------------------------------- site configuration
def site_boxes(site: str, config_dir=None) -> tuple[dict[str, OrientedBox], Path] | tuple[None, None]:
    """Boxes of ``site`` from ``config_dir/<site>_bbx_config.yaml``, else the bundled room
    configuration; ``(None, None)`` when neither exists."""
    for folder in ([Path(config_dir)] if config_dir is not None else []) + [BUNDLED_CONFIG_DIR]:
        path = folder / f"{site}_bbx_config.yaml"
        if path.is_file():
            return read_bbx_config(path), path
    return None, None


def session_row(scan: SessionScan, reference_date: dt.date, counts: dict, points: np.ndarray,
                box: OrientedBox | None, alignment: Alignment, units: str) -> dict:
    """The manifest row (MANIFEST_COLUMNS) of a cleaned session."""
    local = box.to_local(points) if box is not None else points
    extent = local.max(axis=0) - local.min(axis=0)
    return {
        "site": scan.site, "date": f"{scan.date:%Y-%m-%d}",
        "file": f"{PROCESSED_FOLDER}/{scan.name}.pcd", "source": str(scan.path),
        "reference_date": f"{reference_date:%Y-%m-%d}", "transform_file": f"transforms/{scan.name}.txt",
        "points_raw": counts["raw"], "points_cropped": counts.get("cropped", counts["raw"]),
        "points_supports_removed": counts.get("supports_removed", counts["raw"]),
        "points_outliers_removed": counts["outliers_removed"], "points_downsampled": counts["downsampled"],
        "points": len(points), "extent_x": extent[0], "extent_y": extent[1], "extent_z": extent[2],
        "alignment": alignment.method, "fitness": alignment.fitness, "inlier_rmse_m": alignment.inlier_rmse,
        "landmark_rmse_m": alignment.landmark_rmse, "rotation_deg": alignment.rotation_deg,
        "translation_m": float(np.linalg.norm(alignment.translation)), "units": units,
    }


def _transform_text(transform: np.ndarray) -> str:
    return "\n".join(" ".join(f"{v:.12g}" for v in row) for row in transform) + "\n"


def reference_file(site: str) -> str:
    """Dataset path of a site's reference-day scan (full, downsampled): later sessions align to it."""
    return f"reference/{site}_static.pcd"


def write_reference(stage, site: str, points: np.ndarray, icp: IcpConfig) -> None:
    """Stage the reference day's whole scan, downsampled finer than ICP uses it."""
    write_point_cloud(stage.path(reference_file(site)), voxel_downsample(points, icp.voxel_size / 2),
                      dtype="float32")


def write_session(stage, scan: SessionScan, cleaned: np.ndarray, alignment: Alignment) -> None:
    """Stage a session's model and transform."""
    write_point_cloud(stage.path(f"{PROCESSED_FOLDER}/{scan.name}.pcd"), cleaned, dtype="float32")
    atomic_write_text(stage.path(f"transforms/{scan.name}.txt"), _transform_text(alignment.transform))


def stage_copy(stage, source: Path, relative: str) -> None:
    """Copy an input file (a box configuration) into the stage, atomically."""
    try:
        data = Path(source).read_bytes()
    except OSError as exc:
        raise InputFileError(f"{source}: cannot read ({exc.strerror or exc})") from None
    atomic_write_bytes(stage.path(relative), data)


def process_session(scan: SessionScan, points: np.ndarray, reference: np.ndarray | None,
                    box: OrientedBox | None, clean: CleanConfig, icp: IcpConfig) -> tuple[np.ndarray, Alignment, dict]:
    """Align ``points`` to ``reference`` (None: it is the reference day) and clean it."""
    try:
        if reference is None:
            alignment = Alignment(np.eye(4), 1.0, 0.0, None, "reference day")
        else:
            alignment = align_to_reference(points, reference, landmarks=scan.landmarks, plant_box=box, config=icp)
        result = clean_scan(transform_points(points, alignment.transform), box, clean)
    except PointCloudError as exc:
        raise PointCloudError(f"{scan.path}: {exc}") from None
    return result.points, alignment, result.counts


def clean_greenhouse(source=None, output="data/greenhouse", *, manifest=None, landmarks=None,
                     config_dir=None, units: str = "m", clean: CleanConfig = CleanConfig(),
                     icp: IcpConfig = IcpConfig(), force: bool = False, progress: bool = True,
                     log=print) -> pd.DataFrame:
    """Clean every session found in ``source`` (or ``manifest``) and align it to its site's first day.

    Writes the dataset described in the module docstring to ``output`` and returns its manifest.
    Refuses to replace an existing dataset's manifest without ``force``. The output is a whole new
    dataset (``staged_folder`` without ``keep_existing``): with ``force`` it replaces the previous
    one, files of sessions no longer found included, so old and new sessions never mix. An output
    that is, holds or lies inside an input is refused before anything is read: the inputs are
    ``source`` (the folder, not only the scans found in it: a later clean of it would read this
    output as raw scans), ``manifest`` and every file it lists, the ``landmarks`` and ``config_dir``
    folders and the landmark and box files used.
    """
    from tqdm.auto import tqdm

    output = Path(output)
    given = [source if manifest is None else None, manifest, landmarks, config_dir]
    check_outputs_outside_inputs(output, given, "dataset")  # before the (long) search and cleaning
    found = find_sessions(source, manifest=manifest, landmarks=landmarks)
    inputs = given + [scan.path for scan in found.sessions] + [scan.landmarks for scan in found.sessions]
    check_outputs_outside_inputs(output, inputs, "dataset")  # a manifest's scans may lie anywhere
    sites = sorted({s.site for s in found.sessions})
    boxes = {}
    for site in sites:
        boxes[site] = site_boxes(site, config_dir)
        if boxes[site][0] is None:
            raise InputFileError(f"no plant box for site {site!r}: put {site}_bbx_config.yaml in a folder "
                                 "and pass it with --config (format: tpvp/data/greenhouse_row/room1_bbx_config.yaml)")
    inputs += [path for _, path in boxes.values()]
    rows = []
    with staged_folder(output, inputs=inputs, what="dataset") as stage:
        # Under the dataset's lock: no other run can write it between this check and the commit.
        if stage.existing("manifest.csv").exists() and not force:
            raise DatasetError(f"{output}/manifest.csv exists: pass --force to rebuild the dataset")
        log(found.report())
        for site in sites:
            config, config_path = boxes[site]
            box = config["plant_box"]
            stage_copy(stage, config_path, f"config/{site}_bbx_config.yaml")
            reference, models, titles = None, [], []
            for scan in tqdm([s for s in found.sessions if s.site == site], desc=f"cleaning {site}",
                             unit="session", disable=not progress):
                points = read_point_cloud(scan.path, units=units)
                cleaned, alignment, counts = process_session(scan, points, reference, box, clean, icp)
                if reference is None:
                    reference, reference_date = points, scan.date
                    write_reference(stage, site, points, icp)
                write_session(stage, scan, cleaned, alignment)
                rows.append(session_row(scan, reference_date, counts, cleaned, box, alignment, units))
                models.append(cleaned)
                titles.append(f"{scan.date}  {len(cleaned):,} points\n{alignment.method}, fitness "
                              f"{alignment.fitness:.2f}, RMSE {1000 * alignment.inlier_rmse:.1f} mm")
                if alignment.fitness < 0.5:
                    log(f"warning: {scan.name}: alignment fitness {alignment.fitness:.2f} < 0.5 "
                        f"(RMSE {1000 * alignment.inlier_rmse:.1f} mm); check its landmarks")
            plot_row_sessions(stage.path(f"report/{site}_sessions.png"), models, titles, box,
                              f"{site}: cleaned sessions in the plant-box frame (side and top views)")
        table = pd.DataFrame(rows, columns=list(MANIFEST_COLUMNS))
        stage_table(stage, table, "manifest.csv")
    return table
