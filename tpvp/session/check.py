"""What can be wrong with a session folder, found before a step reads it, and what can be repaired.

A session folder is the robot's work of the day: a file deleted in a file manager, a state file
edited by hand or copied from another machine must not surface as a traceback halfway through a
step. :func:`folder_problems` reads the folder (the lock held by the caller) and lists every
problem: one line each, what is wrong and what to do. Some can be repaired safely - nothing that
was captured and is still readable is lost - by :func:`repair`: a capture whose files are gone or
damaged is dropped (capture that view again if it is asked for), a file of ``captures/`` that no capture names is
removed, a plan whose files are gone is dropped (plan again). The rest (``session.json``,
``previous.npy`` or ``config.yaml`` damaged, a session of another version) cannot be repaired here.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tpvp import __version__
from tpvp.config import load_config
from tpvp.errors import TpvpError
from tpvp.io import atomic_write_text
from tpvp.io.publish import staged_folder

#: A capture's voxel-key file, as session.json names it (never a path outside ``captures/``).
CAPTURE_FILE = re.compile(r"captures/(\d{3,})\.npy")
#: The plan's files a robot reads.
PLAN_FILES = ("plan/plan.csv", "plan/plan.json")
FORMAT, VERSION, STATE = "tpvp-session", 1, "session.json"
#: The previous model's organ codes, one per point of previous.npy (a session started with --labels).
ORGANS_FILE = "previous_organs.npy"


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
        return f"{self.what}: {self.fix}"


def state_text(state: dict) -> str:
    """session.json's text for ``state``."""
    return json.dumps(state, indent=1) + "\n"


def centroid_file(record: dict) -> str:
    """The file of a capture's per-voxel point centroids, beside its voxel keys."""
    return record["file"].replace(".npy", "_centroids.npy")


def capture_number(name: str) -> int | None:
    """The number of ``captures/NNN.npy`` or ``captures/NNN_centroids.npy``; None for other names."""
    match = re.fullmatch(r"captures/(\d+)(?:_centroids)?\.npy", name)
    return int(match.group(1)) if match else None


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
    if not integer and not (np.issubdtype(array.dtype, np.floating) and np.isfinite(array).all()):
        return "holds values that are not finite coordinates"
    if rows is not None and len(array) != rows:
        return f"holds {len(array):,} rows, session.json says {rows:,} voxels"
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
    for name, integer in ((file, True), (centroid_file(record), False)):
        why = _load(folder / name, integer, count)
        if why is not None:
            return [Problem(f"{folder / name} (capture {index + 1}, view {view}) {why}",
                            repair=f"drop capture {index + 1} (view {view})",
                            drop_capture=index)]
    return []


def _plan_problems(folder: Path, state: dict) -> list[Problem]:
    plan = state.get("plan")
    if plan is None:
        return []
    restore = f"restore {folder / STATE} from a backup"
    views = plan.get("planned_views") if isinstance(plan, dict) else None
    if not isinstance(views, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in views):
        return [Problem(f"{folder / STATE}: the plan has no valid 'planned_views' (edited by hand?)", restore,
                        repair="drop the plan (run `tpvp session plan` again)", drop_plan=True)]
    if state["kind"] == "row":
        for key in ("positions", "look_ats"):
            try:
                ok = np.asarray(plan.get(key), dtype=np.float64).shape == (len(views), 3)
            except (TypeError, ValueError):
                ok = False
            if not ok:
                return [Problem(f"{folder / STATE}: the plan's {key!r} are not one (x, y, z) per planned view",
                                repair="drop the plan (run `tpvp session plan` again)", drop_plan=True)]
    gone = [name for name in PLAN_FILES if not (folder / name).is_file()]
    if gone:
        return [Problem(f"{folder / gone[0]} is missing (deleted?)",
                        repair="drop the plan (run `tpvp session plan` again)", drop_plan=True)]
    return []


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
    config = folder / "config.yaml"
    if not config.is_file():
        problems.append(Problem(f"{config} (the session's configuration) is missing (deleted?)", restore))
    else:
        try:
            load_config(config)
        except TpvpError as exc:
            problems.append(Problem(f"{config} (the session's configuration): {exc}", restore))
    if state is None:
        return problems
    named, malformed = set(), False
    for index, record in enumerate(state["captures"]):
        found = _capture_problems(folder, index, record)
        malformed |= any(p.repair is None for p in found)
        problems += found
        if not malformed:
            named |= {record["file"], centroid_file(record)}
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
        remove += [record["file"], centroid_file(record)]
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
