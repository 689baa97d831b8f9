"""View spaces of the single-plant setting (positions on a sphere around the plant centre)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpvp.errors import ConfigError, InputFileError

DATA = Path(__file__).resolve().parent.parent / "data" / "view_spaces"
BUNDLED = {"hemisphere": "view_space_hemisphere32.txt", "sphere": "view_space_sphere63.txt"}
# 0-based rows of the hemisphere file used as initial views (SPEC.md): near-horizontal (7 deg),
# oblique (48 deg) and near-top (77 deg). The sphere file starts with the same 32 rows.
INITIAL_VIEW_INDICES = {"near_horizontal": 17, "oblique": 8, "near_top": 21}


def load_view_space(name_or_path: str | Path = "hemisphere", radius: float | None = None) -> np.ndarray:
    """Camera positions ``(V, 3)`` in metres relative to the plant centre.

    ``name_or_path`` is ``"hemisphere"`` (32 views), ``"sphere"`` (63 views) or a file with a count
    line followed by ``x y z`` rows (the count line may be omitted). ``radius`` rescales the
    positions onto a sphere of that radius (the bundled files use 0.4 m).
    """
    path = DATA / BUNDLED[name_or_path] if name_or_path in BUNDLED else Path(name_or_path)
    if not path.is_file():
        raise InputFileError(
            f"view space {str(name_or_path)!r} is neither one of {sorted(BUNDLED)} nor an existing file"
        )
    try:
        rows = [line.split() for line in path.read_text().splitlines() if line.strip()]
        declared = None
        if rows and len(rows[0]) == 1:
            declared = int(float(rows[0][0]))
            rows = rows[1:]
        positions = np.array(rows, dtype=np.float64)
    except ValueError as exc:
        raise InputFileError(f"{path}: not a view-space file (count line, then 'x y z' rows): {exc}") from None
    if positions.ndim != 2 or positions.shape[1] != 3 or len(positions) == 0:
        raise InputFileError(f"{path}: expected rows of 3 numbers 'x y z', got shape {positions.shape}")
    if declared is not None and declared != len(positions):
        raise InputFileError(f"{path}: first line declares {declared} views but {len(positions)} follow")
    if not np.all(np.isfinite(positions)):
        raise InputFileError(f"{path}: contains NaN or infinite coordinates")
    if radius is not None:
        if not radius > 0:
            raise ConfigError(f"view-space radius must be > 0 m, got {radius!r}")
        norms = np.linalg.norm(positions, axis=1, keepdims=True)
        if np.any(norms == 0):
            raise InputFileError(f"{path}: a view lies at the plant centre; cannot rescale")
        positions = positions / norms * radius
    return positions
