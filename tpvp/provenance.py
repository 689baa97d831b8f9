"""Where a result came from: package and library versions, git commit, a digest of the code, seeds,
command line.

The commit alone does not name the code: a run from a tree with changes, or a row a cache kept
from older code, would name a commit that did not compute it. :func:`code_digest` hashes what
computes a result (the library's source and bundled data, the data tools that grow datasets; not
the shipped result rows themselves), so a cache key and a provenance record name the code exactly.
"""

from __future__ import annotations

import functools
import hashlib
import platform
import subprocess
import sys
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from tpvp import __version__

ROOT = Path(__file__).resolve().parent.parent
#: What computes a result, relative to the repository: hashed by :func:`code_digest`.
CODE = ("tpvp", "data_tools")
#: Inside :data:`CODE`, what does not: the shipped rows (the results themselves), byte code.
NOT_CODE = ("tpvp/data/results/", "__pycache__/")

LIBRARIES = ("numpy", "scipy", "numba", "torch", "open3d-cpu", "trimesh", "PuLP", "highspy", "pandas",
             "matplotlib", "PyYAML", "rerun-sdk")


def git_commit(folder: Path | None = None) -> str | None:
    """``<commit>`` (``+dirty`` when the tree has changes) of the checkout holding the package, or
    None outside a git checkout."""
    folder = Path(folder or Path(__file__).resolve().parent.parent)
    try:
        commit = subprocess.run(["git", "-C", str(folder), "rev-parse", "HEAD"], capture_output=True,
                                text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(folder), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return commit + ("+dirty" if dirty else "") if commit else None


def code_files(root: Path = ROOT) -> list[Path]:
    """The files :func:`code_digest` hashes, sorted by their path relative to ``root``."""
    files = [path for folder in CODE for path in (root / folder).rglob("*") if path.is_file()]
    relative = {path: path.relative_to(root).as_posix() for path in files}
    return sorted((p for p in files if not any(part in relative[p] + "/" for part in NOT_CODE)
                   and not relative[p].endswith((".pyc", ".pyo"))), key=relative.get)


@functools.lru_cache(maxsize=None)
def code_digest(root: Path = ROOT) -> str:
    """SHA-256 (hex) of every file of :func:`code_files`, each with its relative path: the same on
    every checkout of the same code, different after any change to it (a few ms)."""
    digest = hashlib.sha256()
    for path in code_files(root):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(hashlib.sha256(path.read_bytes()).digest())
    return digest.hexdigest()


def tree_state(folder: Path | None = None) -> tuple[str | None, bool]:
    """``(commit, clean)`` of the checkout: clean when the code (:data:`CODE`, the shipped rows
    aside) has no change against the commit, untracked files included."""
    folder = Path(folder or ROOT)
    try:
        commit = subprocess.run(["git", "-C", str(folder), "rev-parse", "HEAD"], capture_output=True,
                                text=True, timeout=10, check=True).stdout.strip()
        changes = subprocess.run(["git", "-C", str(folder), "status", "--porcelain", "--", *CODE,
                                  *(f":!{p}" for p in NOT_CODE if "/" in p.rstrip("/"))],
                                 capture_output=True, text=True, timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None, False
    return commit or None, not changes


def library_versions() -> dict:
    versions = {}
    for name in LIBRARIES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def provenance(config, seeds: dict | None = None, argv=None) -> dict:
    """Everything needed to re-run a result: with the resolved configuration written beside it."""
    return {
        "tpvp_version": __version__,
        "git_commit": git_commit(),
        "code_digest": code_digest(),
        "configuration": getattr(config, "name", None),
        "setting": getattr(config, "setting", None),
        "seeds": {"seed": getattr(config, "seed", None), **(seeds or {})},
        "command": list(sys.argv if argv is None else argv),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "libraries": library_versions(),
        "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
