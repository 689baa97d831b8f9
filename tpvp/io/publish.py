"""Whole-folder atomic outputs: stage a run next to its destination, publish it in one step.

Every command that writes a folder (``tpvp plan/demo/render``, the data tools' datasets, the
experiment runners' caches) goes through :func:`staged_folder`:

1. an OS lock (``flock`` on ``<parent>/.<name>.tpvp-lock``; a killed process cannot leave it
   behind) makes a second concurrent run on the same destination fail at once with one line;
2. leftovers of a run that crashed are repaired (see :func:`_recover`);
3. the command writes its files into a hidden staging folder beside the destination (same file
   system). ``keep_existing=True`` (datasets) starts the staging folder as a hard-linked copy of the
   destination, so the command adds or replaces files and keeps the others;
4. the commit swaps the staging folder into place with two renames while SIGINT and SIGTERM are
   held back (delivered right after), so Ctrl-C lands before the commit (nothing changed) or after it (everything
   published), never between; the report says which (:class:`RunInterrupted`).

A command that reads the destination and then writes it (a session step) holds the lock from the
read to the commit with :func:`hold_folder`; :func:`staged_folder` inside it publishes under that
lock, so no other run's commit can fall between the read and the write. A command whose work ends
with its publish (:func:`arm_step`) is complete from the commit on: a stop signal after it is noted
(:func:`late_signals`), not raised, so the command reports the finished step.

A reader therefore sees the destination wholly old or wholly new. Nothing the command did not write
is deleted: a run folder may only replace a folder that is empty or holds a previous tpvp run's
files and nothing else (``.tpvp-run.json`` lists them); inputs inside the destination are refused.

A command that writes one file (``tpvp export moveit``, ``data_tools capture fuse``, ``tpvp session
export``) goes through :func:`staged_file`: the same lock, the same check against its inputs, an
existing file replaced only with ``--force``, the file written beside its destination and renamed
onto it.

A mount point cannot be renamed, so a destination that is one is published *in place*: the lock,
the staging folder and the backup live inside it (``.tpvp-*``), and the commit swaps its entries
rather than the folder, under a journal (``.tpvp-commit-<pid>``) that lets the next run roll a cut
commit back or forward. A read-only file system is refused before any work.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import shutil
import signal
import threading
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Iterator

from tpvp.errors import BusyError, ConfigError, InputFileError, OutputWriteError, TpvpError
from tpvp.io import faults
from tpvp.io.atomic import fsync_path

RUN_MARKER = ".tpvp-run.json"
_HELD = (signal.SIGINT, signal.SIGTERM)
_WAIT_POLL_S = 0.05
_ADVICE = "wait for it to finish or choose another folder"  # what a refused run is told to do
_UNWRITABLE = "nothing was written: choose a place you can write (--output), or check its permissions"
_locks: dict[str, int] = {}  # real path of a destination -> fd of the lock this process holds (hold_folder)
# The command's step (arm_step): armed, the destination its commit published, signals that came after.
_step = {"armed": False, "published": None, "signals": []}


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C (or SIGTERM) during a staged run; ``published`` tells whether the commit happened."""

    def __init__(self, destination: Path, published: bool, existed: bool = True):
        super().__init__(str(destination))
        self.destination = destination
        self.published = published
        self.existed = existed

    def report(self) -> str:
        if self.published:
            return f"interrupted after {self.destination} was published completely"
        if not self.existed:
            return f"interrupted; nothing was written: {self.destination} was not created"
        return f"interrupted; nothing was written: {self.destination} is as it was"


class Stage:
    """The staging folder of one run: write files under :attr:`folder` or via :meth:`path`."""

    def __init__(self, destination: Path, folder: Path):
        self.destination = destination
        self.folder = folder
        self.published = False

    def _staged(self, relative: str | os.PathLike) -> Path:
        relative = Path(relative)
        if relative.is_absolute() or ".." in relative.parts:
            raise ConfigError(f"staged paths must be relative to {self.destination}, got {relative}")
        return self.folder / relative

    def path(self, relative: str | os.PathLike) -> Path:
        """Staging path of ``destination/relative``, parent created. A hard link to the old file
        (``keep_existing``) is removed first, so writing there never alters the published copy."""
        staged = self._staged(relative)
        staged.parent.mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(FileNotFoundError):
            staged.unlink()
        return staged

    def remove(self, relative: str | os.PathLike) -> None:
        """Leave the file or folder ``destination/relative`` out of the new version (``keep_existing``)."""
        staged = self._staged(relative)
        if staged.is_dir() and not staged.is_symlink():
            shutil.rmtree(staged)
        else:
            with contextlib.suppress(FileNotFoundError):
                staged.unlink()

    def existing(self, relative: str | os.PathLike) -> Path:
        """Path of ``relative`` in the published destination (to read the old version)."""
        return self.destination / relative


_KINDS = ("lock", "staging-", "old-", "commit-")  # what a run keeps beside (or in) its destination


def _in_place(destination: Path) -> bool:
    """Whether ``destination`` is published in place (a mount point: it cannot be renamed)."""
    return destination.is_dir() and os.path.ismount(destination)


def _sibling(destination: Path, kind: str) -> Path:
    """Where the run keeps its ``kind`` (lock, staging-<pid>, old-<pid>, commit-<pid>): beside the
    destination, or inside it when it is published in place."""
    if _in_place(destination):
        return destination / f".tpvp-{kind}"
    return destination.parent / f".{destination.name}.tpvp-{kind}"


def _internal(name: str) -> bool:
    """Entries of an in-place destination that belong to the publishing (or to the file system)."""
    return name.startswith(tuple(f".tpvp-{kind}" for kind in _KINDS)) or name == "lost+found"


def _check_writable(destination: Path, what: str) -> None:
    """Refuse a read-only file system before any work: the destination itself when it is published
    in place, else the folder that will hold it (its nearest existing parent)."""
    probe = destination if _in_place(destination) else destination.parent
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    try:
        read_only = bool(os.statvfs(probe).f_flag & os.ST_RDONLY)
    except OSError:
        return  # unknown: the lock's creation reports it
    if read_only:
        raise OutputWriteError(f"cannot write {what} {destination}: {probe} is on a read-only file system; "
                               f"choose a folder on a writable disk")


def _lock(destination: Path, what: str, wait: float = 0.0, on_wait=None,
          advice: str = _ADVICE) -> int:
    """Take ``destination``'s lock, waiting up to ``wait`` seconds for another run to release it
    (``on_wait()`` is called once when it has to wait); :class:`BusyError` after that."""
    lock = _sibling(Path(_lock_key(destination)), "lock")
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError as exc:
        raise OutputWriteError(f"cannot write {what} {destination}: {exc.strerror or exc}; {_UNWRITABLE}") from None
    deadline = time.monotonic() + wait
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return fd
        except OSError as exc:
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                os.close(fd)
                raise OutputWriteError(f"cannot lock {what} {destination}: {exc.strerror or exc}") from None
        if time.monotonic() >= deadline:
            os.close(fd)
            waited = f" (waited {wait:g} s)" if wait > 0 else ""
            raise BusyError(f"{what} {destination} is being written by another run{waited}; {advice}")
        if on_wait is not None:
            on_wait()
            on_wait = None
        time.sleep(_WAIT_POLL_S)


def _lock_key(destination: Path) -> str:
    return os.path.realpath(destination)


@contextlib.contextmanager
def hold_folder(destination, *, what: str = "output folder", wait: float = 0.0, on_wait=None,
                advice: str = _ADVICE) -> Iterator[Path]:
    """Hold ``destination``'s lock for the block (waiting up to ``wait`` seconds for another run,
    then :class:`BusyError` with ``advice``), after repairing what a crashed run left: the block
    reads the destination, and :func:`staged_folder` inside it publishes under the same lock, so no
    other run's commit falls in between. Re-entrant within a process."""
    destination = Path(destination).absolute()
    key = _lock_key(destination)
    if key in _locks:
        yield destination
        return
    try:
        destination.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputWriteError(f"cannot create {destination.parent}: {exc.strerror or exc}") from None
    _locks[key] = _lock(destination, what, wait, on_wait, advice)
    try:
        _recover(destination)
        yield destination
    finally:
        os.close(_locks.pop(key))  # releases the flock


def arm_step() -> None:
    """The next publish completes this command's step: from its commit on, SIGINT and SIGTERM are
    noted (:func:`late_signals`) instead of interrupting, so the command can finish its report."""
    _step.update(armed=True, published=None, signals=[])


@contextlib.contextmanager
def armed_step():
    """:func:`arm_step` for the block; disarmed after it, published or not: a step that ends
    without a publish (refused, nothing to write) must not arm the next command's publish in the
    same process (the tests run many commands in one)."""
    arm_step()
    try:
        yield
    finally:
        _step["armed"] = False


def step_published() -> Path | None:
    """The destination the armed step published (None before its commit, or when none is armed)."""
    return _step["published"]


def note_late_signal(signum: int) -> None:
    """Record a stop signal that arrived after the step was published (the command's handler)."""
    _step["signals"].append(signum)


def late_signals() -> list[int]:
    """The stop signals that arrived after the armed step was published."""
    return list(_step["signals"])


def _recover(destination: Path) -> None:
    """Repair what a crashed run left (we hold the lock, so every staging folder is stale): a
    backup without its destination is a commit cut between its two renames - roll it back; a
    backup beside its destination is a finished commit - drop it. In place, a commit's journal says
    which half was cut: moving the old entries out (roll back) or the new ones in (roll forward)."""
    if _in_place(destination):
        _recover_in_place(destination)
        return
    for old in destination.parent.glob(f".{destination.name}.tpvp-old-*"):
        if destination.exists():
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(old, destination)
    for staging in destination.parent.glob(f".{destination.name}.tpvp-staging-*"):
        shutil.rmtree(staging, ignore_errors=True)


def _move_entries(source: Path, target: Path) -> None:
    for entry in sorted(os.listdir(source)):
        os.rename(source / entry, target / entry)


def _recover_in_place(destination: Path) -> None:
    for journal in destination.glob(".tpvp-commit-*"):
        pid = journal.name.rsplit("-", 1)[1]
        old, staging = _sibling(destination, f"old-{pid}"), _sibling(destination, f"staging-{pid}")
        with contextlib.suppress(OSError):
            if journal.read_text().strip() == "new":
                _move_entries(staging, destination)  # the new run was moving in: finish it
            else:
                _move_entries(old, destination)  # the old run was moving out: bring it back
        journal.unlink()
    for leftover in [*destination.glob(".tpvp-old-*"), *destination.glob(".tpvp-staging-*")]:
        shutil.rmtree(leftover, ignore_errors=True)


def check_outputs_outside_inputs(destination, inputs, what: str = "output folder") -> None:
    """Refuse an output ``destination`` that is an input, lies inside an input folder or holds an
    input (paths resolved: a symbolic link counts as what it points to), or is the folder the
    process runs in (replacing it would pull the shell's working folder away). Raises a one-line
    :class:`ConfigError` naming both and saying what to do; reads and writes nothing, so commands
    call it before any work. ``None`` inputs are skipped. :func:`staged_folder` calls it too."""
    dest = Path(destination).resolve()
    for item in inputs:
        if item is None:
            continue
        src = Path(item).resolve()
        if src == dest:
            problem, fix = f"is the input {item}", f"choose another {what}" + (f" outside {item}" if src.is_dir() else "")
        elif dest in src.parents:
            problem, fix = f"holds the input {item}", f"choose another {what} that does not hold it, or move the input out"
        elif src in dest.parents:
            problem, fix = f"lies inside the input {item}", f"choose another {what} outside {item}"
        else:
            continue
        given = (Path(os.path.abspath(destination)), Path(os.path.abspath(item)))
        linked = f" (after following symbolic links: {dest} and {src})" if given != (dest, src) else ""
        raise ConfigError(f"{what} {destination} {problem}{linked}; inputs are only read: {fix}")
    cwd = Path.cwd().resolve()
    if cwd == dest or dest in cwd.parents:
        raise ConfigError(f"{what} {destination} is the folder you are working in (or holds it); "
                          f"choose a new subfolder, e.g. {Path(destination) / 'run'}")


def _run_files(folder: Path, in_place: bool = False) -> set[str]:
    files = {p.relative_to(folder).as_posix() for p in folder.rglob("*") if not p.is_dir()}
    return {f for f in files if not _internal(f.split("/", 1)[0])} if in_place else files


def _check_replaceable(destination: Path, what: str) -> None:
    """A run folder may replace an empty folder or a previous tpvp run's files, nothing else."""
    if not destination.exists():
        return
    if not destination.is_dir():
        raise ConfigError(f"{what} {destination} exists and is not a folder")
    present = _run_files(destination, _in_place(destination))
    if not present:
        return
    marker = destination / RUN_MARKER
    written = set()
    if marker.is_file():
        with contextlib.suppress(OSError, ValueError, TypeError):
            written = set(json.loads(marker.read_text())["files"]) | {RUN_MARKER}
    foreign = sorted(present - written)
    if foreign:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise ConfigError(f"{what} {destination} holds files that no tpvp run recorded as its own ({shown}); "
                          f"choose a new or empty folder, or move them away (tpvp never deletes files it did "
                          f"not write)")


def _link_tree(source: Path, target: Path) -> None:
    """Hard-link every file of ``source`` into ``target`` (copy where links are not possible);
    in place, not the publishing's own entries."""
    in_place = _in_place(source)
    for item in source.rglob("*"):
        relative = item.relative_to(source)
        if in_place and _internal(relative.parts[0]):
            continue
        if item.is_dir() and not item.is_symlink():
            (target / relative).mkdir(parents=True, exist_ok=True)
            continue
        (target / relative).parent.mkdir(parents=True, exist_ok=True)
        try:
            os.link(item, target / relative, follow_symlinks=False)
        except OSError:
            shutil.copy2(item, target / relative, follow_symlinks=False)


def _commit(stage: Stage, keep_existing: bool) -> None:
    destination, staging = stage.destination, stage.folder
    if not keep_existing:
        files = sorted(_run_files(staging))
        payload = {"files": files, "written_utc": datetime.now(timezone.utc).isoformat(timespec="seconds")}
        (staging / RUN_MARKER).write_text(json.dumps(payload, indent=1) + "\n")
    fsync_path(staging)
    if _in_place(destination):
        _commit_in_place(stage)
        return
    old = _sibling(destination, f"old-{os.getpid()}")
    with _signals_held():
        faults.checkpoint("commit")
        if destination.exists():
            os.rename(destination, old)
        faults.checkpoint("swap")
        os.rename(staging, destination)
        _published(stage)
        fsync_path(destination.parent)
        shutil.rmtree(old, ignore_errors=True)  # still held: no backup is left behind
    faults.checkpoint("published")


def _commit_in_place(stage: Stage) -> None:
    """Swap the entries of a destination that cannot be renamed, under a journal that
    :func:`_recover_in_place` reads after a crash."""
    destination, staging, pid = stage.destination, stage.folder, os.getpid()
    old, journal = _sibling(destination, f"old-{pid}"), _sibling(destination, f"commit-{pid}")
    with _signals_held():
        faults.checkpoint("commit")
        old.mkdir()
        journal.write_text("old\n")
        for entry in sorted(os.listdir(destination)):
            if not _internal(entry):
                os.rename(destination / entry, old / entry)
        faults.checkpoint("swap")
        journal.write_text("new\n")
        _move_entries(staging, destination)
        _published(stage)
        fsync_path(destination)
        journal.unlink()
        shutil.rmtree(old, ignore_errors=True)
        staging.rmdir()
    faults.checkpoint("published")


def _published(stage: Stage) -> None:
    stage.published = True
    if _step["armed"]:
        _step.update(armed=False, published=stage.destination)


@contextlib.contextmanager
def _signals_held():
    """Hold SIGINT and SIGTERM back for the block, then deliver them. Handlers, not a signal mask:
    a mask holds only the calling thread, and a Ctrl-C may land on any of numba's or torch's."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived = []
    previous = {signum: signal.signal(signum, lambda signum, frame: arrived.append(signum)) for signum in _HELD}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    if _step["published"] is not None:  # the step is complete: note them, do not interrupt it
        _step["signals"].extend(arrived)
        return
    for signum in dict.fromkeys(arrived):
        signal.raise_signal(signum)  # now under the usual handler: KeyboardInterrupt for Ctrl-C


@contextlib.contextmanager
def staged_folder(destination, *, keep_existing: bool = False, inputs=(), what: str = "output folder") -> Iterator[Stage]:
    """Lock ``destination``, yield a :class:`Stage` to write into, publish it all at once on normal
    exit; on an error or Ctrl-C the destination is left as it was. See the module docstring."""
    destination = Path(destination).absolute()
    check_outputs_outside_inputs(destination, inputs, what)
    _check_writable(destination, what)
    try:
        destination.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputWriteError(f"cannot create {destination.parent}: {exc.strerror or exc}") from None
    if not _step["armed"]:
        _step["published"] = None  # not a step: signals interrupt up to the commit and after it
    held = _lock_key(destination) in _locks  # hold_folder: the caller read under this lock
    lock = None if held else _lock(destination, what)
    stage = None
    existed = destination.exists()
    try:
        _recover(destination)
        if not keep_existing:
            _check_replaceable(destination, what)
        elif destination.exists() and not destination.is_dir():
            raise ConfigError(f"{what} {destination} exists and is not a folder")
        staging = _sibling(destination, f"staging-{os.getpid()}")
        staging.mkdir()
        stage = Stage(destination, staging)
        if keep_existing and destination.is_dir():
            _link_tree(destination, staging)
        yield stage
        _commit(stage, keep_existing)
    except KeyboardInterrupt:
        raise RunInterrupted(destination, bool(stage and stage.published), existed) from None
    except OSError as exc:
        if isinstance(exc, InputFileError) and not _mentions(exc, destination):
            raise
        raise OutputWriteError(_in_user_terms(exc, stage, destination)) from None
    finally:
        if stage is not None and not stage.published:
            shutil.rmtree(stage.folder, ignore_errors=True)
        if lock is not None:
            os.close(lock)  # releases the flock


@contextlib.contextmanager
def staged_file(destination, *, inputs=(), force: bool = False, what: str = "output file") -> Iterator[Path]:
    """Lock the output file ``destination`` as :func:`staged_folder` locks a folder, refuse it when
    it is an input or lies inside one, or exists without ``force``; yield a hidden path beside it
    (same extension: writers choose the format by it) and rename that onto ``destination`` on
    normal exit. On an error or Ctrl-C ``destination`` is left as it was; a write failure is an
    :class:`OutputWriteError` (exit 4) that says so."""
    destination = Path(destination).absolute()
    check_outputs_outside_inputs(destination, inputs, what)
    if destination.is_dir():
        raise ConfigError(f"{what} {destination} is a folder: give the file to write")
    _check_writable(destination, what)
    try:
        destination.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputWriteError(f"cannot create {destination.parent}: {exc.strerror or exc}; {_UNWRITABLE}") from None
    lock = _lock(destination, what)
    staging = destination.with_name(f".{destination.name}.tpvp-staging-{os.getpid()}{destination.suffix}")
    existed, published = destination.exists(), False
    try:
        for leftover in destination.parent.glob(f".{destination.name}.tpvp-staging-*"):
            leftover.unlink(missing_ok=True)  # a crashed run's: we hold the lock
        if existed and not force:  # checked under the lock: a concurrent run may have just written it
            raise ConfigError(f"{what} {destination} exists: choose a new one, or --force to replace it")
        yield staging
        if not staging.is_file():
            raise OutputWriteError(f"cannot write {destination}: the writer wrote nothing; {_UNWRITABLE}")
        with _signals_held():
            faults.checkpoint("commit")
            os.replace(staging, destination)
            published = True
        fsync_path(destination.parent)
        faults.checkpoint("published")
    except KeyboardInterrupt:
        raise RunInterrupted(destination, published, existed) from None
    except OSError as exc:
        if isinstance(exc, TpvpError) and (not isinstance(exc, InputFileError) or not _mentions(exc, destination)):
            raise
        text = str(exc) if isinstance(exc, InputFileError) else f"cannot write {destination}: {exc.strerror or exc}"
        kept = f"{destination} is as it was" if existed else f"{destination} was not created"
        raise OutputWriteError(f"{text.replace(str(staging), str(destination))}; nothing was written: {kept}") from None
    finally:
        if not published:
            with contextlib.suppress(OSError):
                staging.unlink()
        os.close(lock)


def _mentions(exc: BaseException, destination: Path) -> bool:
    """Whether an error is about writing the destination (not about reading an input)."""
    text = str(exc)
    return f".{destination.name}.tpvp-staging-" in text or any(
        text.find(str(destination) + end) >= 0 for end in (os.sep, ":", " ", ";", ","))


def _in_user_terms(exc: OSError, stage: Stage | None, destination: Path) -> str:
    """The error with staging paths written as their destination paths, and what happened."""
    text = str(exc) if isinstance(exc, InputFileError) else f"{exc.strerror or exc}"
    if stage is not None:
        text = text.replace(str(stage.folder), str(destination))
    if not isinstance(exc, InputFileError):
        text = f"cannot write {getattr(exc, 'filename', None) or destination}: {text}"
        if stage is not None:
            text = text.replace(str(stage.folder), str(destination))
    return f"{text}; nothing was published: {destination} is as it was"
