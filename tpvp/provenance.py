"""Where a result came from: package and library versions, git commit, seeds, command line."""

from __future__ import annotations

import platform
import subprocess
import sys
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from tpvp import __version__

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
        "configuration": getattr(config, "name", None),
        "setting": getattr(config, "setting", None),
        "seeds": {"seed": getattr(config, "seed", None), **(seeds or {})},
        "command": list(sys.argv if argv is None else argv),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "libraries": library_versions(),
        "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
