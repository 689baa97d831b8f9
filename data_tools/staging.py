"""All-or-nothing updates of a dataset folder.

Files are first written into a hidden staging folder inside the dataset (same file system, so the
final moves are renames). :func:`staged_update` then moves them into place in the order they were
staged - put the manifest last - keeping a backup of every file it replaces. If anything fails or
the run is interrupted before the last move, the moves already made are undone and the backups
restored, so the dataset is left exactly as it was; the staging folder is always removed.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterator

from data_tools.errors import InputFileError


class Stage:
    """Where the new files of one update are written before they are moved into the dataset."""

    def __init__(self, dataset: Path, folder: Path):
        self.dataset = dataset
        self.folder = folder
        self.order: list[str] = []

    def path(self, relative: str | os.PathLike) -> Path:
        """Staging path of ``dataset/relative``; its parent exists. Write the file there."""
        relative = Path(relative)
        if relative.is_absolute() or ".." in relative.parts:
            raise ValueError(f"staged paths must be relative to the dataset, got {relative}")
        key = relative.as_posix()
        if key not in self.order:
            self.order.append(key)
        staged = self.folder / relative
        staged.parent.mkdir(parents=True, exist_ok=True)
        return staged


def _commit(stage: Stage) -> None:
    done: list[tuple[Path, Path | None]] = []  # (final path, backup of the file it replaced)
    try:
        for key in stage.order:
            staged, final = stage.folder / key, stage.dataset / key
            if not staged.is_file():
                raise InputFileError(f"{final}: staged file was never written")
            final.parent.mkdir(parents=True, exist_ok=True)
            backup = None
            if final.exists():
                backup = stage.folder / ".backup" / key
                backup.parent.mkdir(parents=True, exist_ok=True)
                os.replace(final, backup)
            done.append((final, backup))
            os.replace(staged, final)
    except BaseException:
        for final, backup in reversed(done):
            with contextlib.suppress(OSError):
                if backup is not None:
                    os.replace(backup, final)
                else:
                    final.unlink()
        raise


@contextlib.contextmanager
def staged_update(dataset) -> Iterator[Stage]:
    """Context manager: write new files via ``stage.path(...)``; on normal exit they replace the
    dataset's files (in staging order), on an exception nothing in the dataset changes."""
    dataset = Path(dataset)
    created = not dataset.exists()
    try:
        dataset.mkdir(parents=True, exist_ok=True)
        folder = Path(tempfile.mkdtemp(prefix=".staging-", dir=dataset))
    except OSError as exc:
        raise InputFileError(f"{dataset}: cannot write the dataset folder ({exc.strerror or exc})") from None
    try:
        stage = Stage(dataset, folder)
        yield stage
        _commit(stage)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
        if created:
            with contextlib.suppress(OSError):
                dataset.rmdir()  # only succeeds when nothing was committed
