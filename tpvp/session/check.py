"""What can be wrong with a session folder, found before a step reads it, and what can be repaired.

A session folder is the robot's work of the day: a file deleted in a file manager, a state file
edited by hand or copied from another machine must not surface as a traceback halfway through a
step. :func:`folder_problems` reads the folder (the lock held by the caller) and lists every
problem: one line each, what is wrong and what to do. It reads every file a step reads, as the step
reads it: the state, the previous model and its organ labels, the configuration, every capture's
files, and the plan's record and files (``plan.csv``, ``plan.json``, a plant's ``prediction.npz``,
which a re-plan reads). Some can be repaired safely - nothing that was captured and is still
readable is lost - by :func:`repair`: a capture whose files are gone or damaged is dropped (capture
that view again if it is asked for), a file of ``captures/`` that no capture names is removed, a
plan whose record or files are gone or damaged is dropped (plan again). The rest
(``session.json``, ``previous.npy``, ``previous_organs.npy`` or ``config.yaml`` damaged, a session
of another version) cannot be repaired here.
"""

from __future__ import annotations

import dataclasses
import json
import re
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tpvp import __version__
from tpvp.config_loading import flatten_keys, load_config, to_dict
from tpvp.errors import InputFileError, TpvpError
from tpvp.io import atomic_write_text
from tpvp.io.plan import PlanFileError, read_plan_values
from tpvp.io.publish import staged_folder
from tpvp.pipeline.replan import Prediction, Replan
from tpvp.scene.organs import ORGANS
from tpvp.scene.voxels import KEY_OFFSET

#: A capture's voxel-key file, as session.json names it (never a path outside ``captures/``).
CAPTURE_FILE = re.compile(r"captures/(\d{3,})\.npy")
#: The plan's files a robot reads.
PLAN_FILES = ("plan/plan.csv", "plan/plan.json")
#: What a plant's last plan predicts its views see, read by the next plan to re-plan from the captures.
PREDICTION_FILE = "plan/prediction.npz"
FORMAT, VERSION, STATE = "tpvp-session", 1, "session.json"
#: The previous model's organ codes, one per point of previous.npy (a session started with --labels;
#: session.json names it under ``previous_organs``, so a deleted file is not taken for no labels).
ORGANS_FILE = "previous_organs.npy"
DROP_PLAN = "drop the plan (run `tpvp session plan` again)"


@dataclass(frozen=True)
class Problem:
    """One problem of a session folder: ``what`` is wrong; ``repair`` says what ``--repair`` does
    about it (``None``: it cannot, and ``fix`` says what the user can do)."""

    what: str
    fix: str = ""
    repair: str | None = None
    drop_capture: int | None = None  # index in session.json's captures
    remove_file: str | None = None  # relative path
    drop_plan: bool = False

    def line(self, folder) -> str:
        """The one line a step prints when it refuses the folder for this problem."""
        if self.repair is not None:
            return f"{self.what}: `tpvp session check {folder} --repair` will {self.repair}"
        return f"{self.what}: {self.fix}" if self.fix else self.what


def state_text(state: dict) -> str:
    """session.json's text for ``state``."""
    return json.dumps(state, indent=1) + "\n"


def centroid_file(record: dict) -> str:
    """The file of a capture's per-voxel point centroids, beside its voxel keys."""
    return record["file"].replace(".npy", "_centroids.npy")


def depth_file(record: dict) -> str:
    """The file of a depth capture's image, its intrinsics and pose (what ``export`` fuses)."""
    return record["file"].replace(".npy", "_depth.npz")


def capture_files(record: dict) -> list[str]:
    """Every file of a capture: its voxel keys, their centroids and, for a depth image that kept
    it, the image."""
    return [record["file"], centroid_file(record), *([depth_file(record)] if record.get("depth_image") else [])]


def capture_number(name: str) -> int | None:
    """The number of ``captures/NNN.npy``, ``NNN_centroids.npy`` or ``NNN_depth.npz``; None for other names."""
    match = re.fullmatch(r"captures/(\d+)(?:(?:_centroids)?\.npy|_depth\.npz)", name)
    return int(match.group(1)) if match else None


#: What a depth capture's image file holds: the depth (H, W, metres, 0: none), the pinhole
#: (fx, fy, cx, cy, width, height) and the camera-to-world pose it was placed at (4, 4).
DEPTH_ARRAYS = {"depth": 2, "intrinsics": 1, "camera_to_world": 2}


def _depth_problem(path: Path) -> str | None:
    """Why ``path`` is not a depth capture's image file; None if it is."""
    if not path.is_file():
        return "is missing (deleted?)"
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in DEPTH_ARRAYS}
    except (OSError, ValueError, EOFError, KeyError) as exc:
        return f"is damaged (truncated? {str(exc).splitlines()[0][:80]})"
    if any(arrays[name].ndim != ndim for name, ndim in DEPTH_ARRAYS.items()) or arrays["intrinsics"].shape != (6,) \
            or arrays["camera_to_world"].shape != (4, 4) or not all(np.isfinite(a).all() for a in arrays.values()):
        return "does not hold a depth image, its intrinsics and its pose"
    return None


def is_session_folder(folder: Path) -> bool:
    """Whether ``folder`` holds a session (or what is left of one)."""
    return any((folder / name).exists() for name in (STATE, "previous.npy", "captures"))


def read_state(folder: Path, kinds) -> tuple[dict | None, list[Problem]]:
    """``(state, problems)``: session.json's content when it is a state this tpvp reads (else None);
    ``kinds``: the session kinds there are (plant, row)."""
    path = folder / STATE
    restore = f"restore {path} from a backup, or start a new session (`tpvp session start`)"
    try:
        text = path.read_text()
    except FileNotFoundError:
        if is_session_folder(folder):
            return None, [Problem(f"{path} (the session's state) is missing (deleted?)", restore)]
        return None, [Problem(f"{folder}: not a session folder (no {STATE})",
                              "start one with `tpvp session start`, or give the session's folder")]
    except (OSError, UnicodeDecodeError) as exc:
        return None, [Problem(f"{path}: unreadable ({getattr(exc, 'strerror', None) or exc})", restore)]
    try:
        state = json.loads(text)
    except ValueError as exc:
        what = "empty (truncated?)" if not text.strip() else f"not valid JSON ({exc})"
        return None, [Problem(f"{path}: {what}", restore)]
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        return None, [Problem(f"{path}: not a tpvp session state file (no \"format\": \"{FORMAT}\")", restore)]
    version = state.get("version")
    if version != VERSION:
        written = f"tpvp {state['tpvp']}" if isinstance(state.get("tpvp"), str) else "another tpvp"
        newer = isinstance(version, int) and not isinstance(version, bool) and version > VERSION
        fix = (f"update tpvp (this is {__version__}), or finish the session with {written}" if newer
               else f"finish it with {written}, or start a new session")
        return None, [Problem(f"{path}: a session of format version {version!r} ({written}); this tpvp reads "
                              f"version {VERSION}", fix)]
    problems = []
    types = {"kind": str, "previous_file": str, "units": str, "captures": list}
    for key, kind in types.items():
        if key not in state:
            problems.append(Problem(f"{path}: no {key!r} key (edited by hand?)", restore))
        elif not isinstance(state[key], kind):
            problems.append(Problem(f"{path}: {key!r} must be a {kind.__name__}, got {state[key]!r:.40}", restore))
    if isinstance(state.get("kind"), str) and state["kind"] not in kinds:
        problems.append(Problem(f"{path}: kind {state['kind']!r} is not one of {', '.join(kinds)}", restore))
    if state.get("units") not in (None, "m", "mm") and isinstance(state.get("units"), str):
        problems.append(Problem(f"{path}: units {state['units']!r} are not m or mm", restore))
    if state.get("previous_organs", ORGANS_FILE) != ORGANS_FILE:
        problems.append(Problem(f"{path}: 'previous_organs' must be {ORGANS_FILE!r}, got "
                                f"{state['previous_organs']!r:.40} (edited by hand?)", restore))
    return (None if problems else state), problems


def _organs_problem(folder: Path) -> str | None:
    """Why ``previous_organs.npy`` is not one integer per point of ``previous.npy``; None if it is."""
    try:
        organs = np.load(folder / ORGANS_FILE, allow_pickle=False)
        points = np.load(folder / "previous.npy", mmap_mode="r", allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        return f"is damaged (truncated? {str(exc).splitlines()[0][:80]})"
    if organs.shape != (len(points),) or not np.issubdtype(organs.dtype, np.integer):
        return f"holds {organs.shape} {organs.dtype}, not one organ code per point of previous.npy ({len(points):,})"
    if len(organs) and not 0 <= organs.min() <= organs.max() < len(ORGANS):
        wrong = organs[(organs < 0) | (organs >= len(ORGANS))][0]
        return f"holds the organ code {wrong}, not one of 0..{len(ORGANS) - 1} ({', '.join(ORGANS)})"
    return None


def _load(path: Path, integer: bool, rows: int | None) -> str | None:
    """Why ``path`` is not an (N, 3) array (integer or finite float, ``rows`` rows); None if it is."""
    if not path.is_file():
        return "is missing (deleted?)"
    try:
        array = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        return f"is damaged (truncated? {str(exc).splitlines()[0][:80]})"
    if array.ndim != 2 or array.shape[1] != 3:
        return f"holds an array of shape {array.shape}, not (N, 3)"
    if integer and not np.issubdtype(array.dtype, np.integer):
        return f"holds {array.dtype} values, not voxel keys"
    if integer and array.size and not -KEY_OFFSET <= array.min() <= array.max() < KEY_OFFSET:
        return f"holds voxel keys beyond +-{KEY_OFFSET:,}, no voxel of a plant"
    if not integer and not (np.issubdtype(array.dtype, np.floating) and np.isfinite(array).all()):
        return "holds values that are not finite coordinates"
    if rows is not None and len(array) != rows:
        return f"holds {len(array):,} rows, session.json says {rows:,} voxels"
    if rows is None and len(array) == 0:
        return "holds no points"
    return None


def _capture_problems(folder: Path, index: int, record) -> list[Problem]:
    """A capture record's problems: malformed (not repairable) or its files gone or damaged (drop it)."""
    where = f"{folder / STATE}: capture {index + 1}"
    if not isinstance(record, dict):
        return [Problem(f"{where} is not a record", f"restore {folder / STATE} from a backup")]
    view, file, count = record.get("view"), record.get("file"), record.get("voxels")
    bad = [key for key, value in (("view", view), ("voxels", count))
           if not isinstance(value, int) or isinstance(value, bool) or value < 0]
    if not isinstance(file, str) or not CAPTURE_FILE.fullmatch(file):
        bad.append("file")
    if bad:
        return [Problem(f"{where} has no valid {', '.join(repr(b) for b in bad)} (edited by hand?)",
                        f"restore {folder / STATE} from a backup")]
    for name, integer in ((file, True), (centroid_file(record), False), *([(depth_file(record), None)]
                                                                          if record.get("depth_image") else [])):
        why = _depth_problem(folder / name) if integer is None else _load(folder / name, integer, count)
        if why is not None:
            return [Problem(f"{folder / name} (capture {index + 1}, view {view}) {why}",
                            repair=f"drop capture {index + 1} (view {view})",
                            drop_capture=index)]
    return []


def _is_count(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _is_views(value) -> bool:
    return isinstance(value, list) and all(map(_is_count, value))


def _plan_record_problem(plan, kind: str) -> str | None:
    """What is wrong with session.json's plan record as the steps of ``kind`` read it; None if nothing."""
    if not isinstance(plan, dict):
        return "the plan is not a record"
    if not _is_views(plan.get("planned_views")):
        return "the plan has no valid 'planned_views'"
    if kind == "row":
        for key in ("positions", "look_ats"):
            try:
                values = np.asarray(plan.get(key), dtype=np.float64)
                ok = values.shape == (len(plan["planned_views"]), 3) and np.isfinite(values).all()
            except (TypeError, ValueError):
                ok = False
            if not ok:
                return f"the plan's {key!r} are not one finite (x, y, z) per planned view"
        return None
    if "executed_views" in plan and not _is_views(plan["executed_views"]):
        return "the plan has no valid 'executed_views'"
    for key in ("warm_up", "views_so_far", "replan_after"):
        if key in plan and not _is_count(plan[key]):
            return f"the plan's {key!r} is not a count"
    if "views_so_far" in plan and "warm_up" not in plan:  # a re-plan reads both
        return "the plan has 'views_so_far' but no 'warm_up'"

    fields = {field.name for field in dataclasses.fields(Replan)}
    required = {field.name for field in dataclasses.fields(Replan) if field.default is dataclasses.MISSING}
    replans = plan.get("replans", [])
    if not isinstance(replans, list) or not all(
            isinstance(row, dict) and required <= set(row) <= fields
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in row.values()) for row in replans):
        return "the plan's 'replans' are not re-plan rows"
    return None


def _plan_csv_problem(path: Path, plan: dict) -> tuple[str | None, int | None]:
    """``(why plan.csv is not the plan session.json records, or None; its views when it reads)``,
    read as ``tpvp export`` reads it."""
    try:
        columns, fields, _ = read_plan_values(path)
    except PlanFileError as exc:
        return f"is damaged ({exc.fault})", None
    except InputFileError as exc:
        return f"is unreadable ({str(exc).split(': ', 1)[-1]})", None
    role = columns.index("role")
    planned, recorded = sum(values[role].strip() == "planned" for values in fields), len(plan["planned_views"])
    if planned != recorded:  # cut at a line's end: every line left reads
        return f"is damaged (truncated? it holds {planned} planned views, session.json's plan {recorded})", None
    return None, len(fields)


def _plan_json_problem(path: Path, rows: int | None) -> str | None:
    """Why ``plan.json`` is not the plan's views (``rows``: plan.csv's, when it reads)."""
    try:
        data = json.loads(path.read_text())
    except OSError as exc:
        return f"is unreadable ({exc.strerror or exc})"
    except (ValueError, UnicodeDecodeError) as exc:
        return f"is damaged (truncated? not valid JSON: {exc})"
    views = data.get("views") if isinstance(data, dict) else None
    if not isinstance(views, list):
        return "is damaged (no 'views' list)"
    if rows is not None and len(views) != rows:
        return f"is damaged (it holds {len(views)} views, plan.csv {rows})"
    return None


def _prediction_problem(path: Path, plan: dict) -> str | None:
    """Why ``prediction.npz`` is not what a re-plan reads: the plan's prediction of the visibility of
    views on its planning voxels (that they are the session's views: :func:`prediction_views`)."""

    try:
        prediction = Prediction.from_bytes(path.read_bytes())
    except (OSError, ValueError, TypeError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        return f"is damaged (truncated? {(str(exc).splitlines() or [type(exc).__name__])[0][:80]})"
    centres, matrix, resolution = prediction.centres, prediction.visibility, prediction.resolution
    if not (centres.ndim == 2 and centres.shape[1] == 3 and np.issubdtype(centres.dtype, np.floating)
            and np.isfinite(centres).all()):
        return f"is damaged (its voxel centres are {centres.shape} {centres.dtype}, not finite (N, 3) coordinates)"
    if not (np.isfinite(resolution) and resolution > 0):
        return f"is damaged (its voxel size is {resolution:g})"
    try:
        matrix.check_format(full_check=True)
    except ValueError as exc:
        return f"is damaged (its visibility: {exc})"
    if matrix.shape[1] != len(centres):
        return f"is damaged (its visibility is of {matrix.shape[1]} voxels, its voxel centres {len(centres)})"
    if "views_so_far" in plan and prediction.views_so_far != plan["views_so_far"]:
        return (f"is the prediction of a plan made after {prediction.views_so_far} captures, session.json's plan "
                f"after {plan.get('views_so_far')} (left from another plan?)")
    return None


def prediction_views(folder: Path) -> int | None:
    """How many views a sound plant session's ``prediction.npz`` holds the visibility of (each of
    the session's views, which only the opened session knows); None without one."""
    path = folder / PREDICTION_FILE
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as arrays:
        return int(arrays["shape"][0])


def _plan_problems(folder: Path, state: dict) -> list[Problem]:
    """The plan's problems: its record, then each of its files; each repaired by dropping the plan."""
    plan = state.get("plan")
    if plan is None:
        return []
    why = _plan_record_problem(plan, state["kind"])
    if why is not None:
        return [Problem(f"{folder / STATE}: {why} (edited by hand?)", f"restore {folder / STATE} from a backup",
                        repair=DROP_PLAN, drop_plan=True)]
    files = {name: folder / name for name in PLAN_FILES}
    found = {name: "is missing (deleted?)" for name, path in files.items() if not path.is_file()}
    rows = None
    if "plan/plan.csv" not in found:
        found["plan/plan.csv"], rows = _plan_csv_problem(files["plan/plan.csv"], plan)
    if "plan/plan.json" not in found:
        found["plan/plan.json"] = _plan_json_problem(files["plan/plan.json"], rows)
    prediction = folder / PREDICTION_FILE
    if state["kind"] == "plant" and (prediction.is_file() or "views_so_far" in plan):
        if not prediction.is_file():
            found[PREDICTION_FILE] = "is missing (deleted?)"
        else:
            found[PREDICTION_FILE] = _prediction_problem(prediction, plan)
    return [Problem(f"{folder / name} {why}", repair=DROP_PLAN, drop_plan=True)
            for name, why in found.items() if why is not None]


def _config_problem(folder: Path, state: dict | None) -> Problem | None:
    """Why ``config.yaml`` is not the configuration of this session's kind, as written at its start."""
    path, restore = folder / "config.yaml", "restore it from a backup, or start a new session"
    if not path.is_file():
        return Problem(f"{path} (the session's configuration) is missing (deleted?)", restore)
    try:
        config = load_config(path)
    except TpvpError as exc:
        return Problem(f"{path} (the session's configuration): {exc}", restore)
    if state is None:
        return None
    if config.setting != state["kind"]:
        return Problem(f"{path} (the session's configuration) is of a {config.setting} setting, session.json's "
                       f"session is a {state['kind']} (edited or copied in?)", restore)
    if state.get("tpvp") == __version__:  # written by this tpvp: every key it has; a line cut off falls back silently
        import yaml

        written = flatten_keys(yaml.safe_load(path.read_text()))
        missing = [key for key in flatten_keys({"setting": config.setting, **to_dict(config)}) if key not in written]
        if missing:
            return Problem(f"{path} (the session's configuration) is damaged (truncated? it has no "
                           f"{missing[0]}{f' and {len(missing) - 1} more keys' if len(missing) > 1 else ''})",
                           restore)
    return None


def folder_problems(folder, kinds) -> list[Problem]:
    """Every problem of the session folder ``folder`` (of one of ``kinds``), in the order a step
    would meet them."""
    folder = Path(folder)
    state, problems = read_state(folder, kinds)
    if not is_session_folder(folder):
        return problems
    restore = "restore it from a backup, or start a new session"
    why = _load(folder / "previous.npy", False, None)
    if why is not None:
        problems.append(Problem(f"{folder / 'previous.npy'} (the previous model) {why}", restore))
    elif (folder / ORGANS_FILE).exists() and (why := _organs_problem(folder)):
        problems.append(Problem(f"{folder / ORGANS_FILE} (the previous model's organ labels) {why}", restore))
    elif state is not None and "previous_organs" in state and not (folder / ORGANS_FILE).exists():
        problems.append(Problem(f"{folder / ORGANS_FILE} (the previous model's organ labels) is missing (deleted?)",
                                restore))
    config = _config_problem(folder, state)
    if config is not None:
        problems.append(config)
    if state is None:
        return problems
    named, malformed = set(), False
    for index, record in enumerate(state["captures"]):
        found = _capture_problems(folder, index, record)
        malformed |= any(p.repair is None for p in found)
        problems += found
        if not malformed:
            named |= set(capture_files(record))
    captures = folder / "captures"
    if captures.is_dir() and not malformed:  # which files are orphans is known once every record is sound
        for path in sorted(captures.rglob("*")):
            name = path.relative_to(folder).as_posix()
            if path.is_file() and name not in named:
                problems.append(Problem(f"{folder / name} is not a file of any capture in {STATE} (left over, or "
                                        f"copied in)", repair=f"remove {name}", remove_file=name))
    problems += _plan_problems(folder, state)
    return problems


def repaired_state(state: dict, problems: list[Problem]) -> tuple[dict, list[str]]:
    """``(new state, files and folders to remove)`` after the repairable ``problems``: a dropped
    capture's files go with it, a dropped plan's folder with it."""
    dropped = {p.drop_capture for p in problems if p.drop_capture is not None}
    remove = [p.remove_file for p in problems if p.remove_file is not None]
    for index in sorted(dropped):
        record = state["captures"][index]
        remove += capture_files(record)
    captures = [c for i, c in enumerate(state["captures"]) if i not in dropped]
    new = dict(state, captures=captures)
    if any(p.drop_plan for p in problems):
        new.pop("plan", None)
        remove.append("plan")
    return new, sorted(set(remove))


def repair_folder(folder, problems: list[Problem]) -> None:
    """Repair the repairable ``problems`` of ``folder`` (found under the lock the caller holds) in one
    commit: the new session.json, without the dropped captures' and plan's files and the orphans."""
    folder = Path(folder)
    state = json.loads((folder / STATE).read_text())
    state, remove = repaired_state(state, [p for p in problems if p.repair is not None])
    with staged_folder(folder, keep_existing=True, what="session folder") as stage:
        for name in remove:
            stage.remove(name)
        atomic_write_text(stage.path(STATE), state_text(state))
