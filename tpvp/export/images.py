"""What the nerfstudio and COLMAP exports share: the colour images the robot kept, read from an
``--images`` folder and copied into the export's :data:`IMAGES` folder, and the colour of the
exported points.

The images are named ``frame_00001.png`` ... in capture order (zero-padded, so a sort by name keeps
that order, as nerfstudio sorts its frames).
"""

from __future__ import annotations

import shutil
from pathlib import Path

from tpvp.errors import InputFileError

#: The colour files an ``--images`` folder is read for (other files there are left alone).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
IMAGES = "images"  # the image folder inside an export, as nerfstudio's and COLMAP's examples name it
GREY = 128  # the points' colour: the fused model has none; nerfstudio reads one per point to seed its splats


def frame_names(count: int, suffixes=None) -> list[str]:
    """``frame_00001.png`` ... (``suffixes``: each image's own extension, default ``.png``)."""
    suffixes = suffixes or [".png"] * count
    return [f"frame_{i + 1:05d}{suffix.lower()}" for i, suffix in enumerate(suffixes)]


def image_files(folder, count: int, what: str = "captures") -> list[Path]:
    """The colour images in ``folder`` (by :data:`IMAGE_SUFFIXES`), sorted by name: the first is the
    first capture's (of ``what``). One clear error when the folder is missing or holds another number
    of them."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputFileError(f"--images {folder}: no such folder")
    files = sorted(p for p in folder.iterdir()
                   if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in IMAGE_SUFFIXES)
    if len(files) != count:
        raise InputFileError(f"--images {folder}: {len(files)} images ({'/'.join(IMAGE_SUFFIXES)}) for {count} "
                             f"{what}; give one colour image per {what[:-1]}, sorted by name in their order")
    return files


def copy_images(files, folder) -> list[str]:
    """Copy ``files`` into ``folder/images`` as :func:`frame_names`; returns their names there."""
    names = frame_names(len(files), [Path(f).suffix for f in files])
    (Path(folder) / IMAGES).mkdir(parents=True, exist_ok=True)
    for source, name in zip(files, names):
        try:
            shutil.copyfile(source, Path(folder) / IMAGES / name)
        except OSError as exc:
            if str(exc.filename) != str(source):
                raise  # writing the copy failed: the publishing reports it (a full disk, exit status 4)
            raise InputFileError(f"{source}: cannot read the image ({exc.strerror or exc})") from None
    return names
