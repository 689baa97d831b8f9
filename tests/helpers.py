"""Small helpers shared by the data-tools tests."""

from __future__ import annotations

import hashlib
from pathlib import Path


def tree_digest(folder: Path) -> dict:
    """Every file under ``folder`` (hidden ones included) with the SHA-256 of its bytes: two equal
    digests mean the folder was left exactly as it was."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(Path(folder).rglob("*")) if p.is_file()}


def benchmark_module(name: str):
    """``benchmarks/<name>.py`` imported as a module (the benchmarks folder is not a package)."""
    import importlib.util
    import sys

    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parent.parent / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def plan_folder(folder: Path) -> Path:
    """A two-view plan written by hand (plan.csv, plan.json) in ``folder/run``."""
    import numpy as np

    from tpvp.io.plan import plan_table, write_plan
    from tpvp.sensor.camera import look_at_rotations, rotation_to_quaternion

    positions, look_ats = np.array([[0.4, 0, 0.2], [0, 0.4, 0.2]]), np.zeros((2, 3))
    quaternions = [rotation_to_quaternion(r) for r in look_at_rotations(positions, look_ats)]
    write_plan(folder / "run", {"scan": plan_table(positions, look_ats, quaternions, ["initial", "planned"])},
               {"scan": "the scans' frame"})
    return folder / "run"
