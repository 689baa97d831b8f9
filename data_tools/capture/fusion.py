"""A capture's frames read and checked for the fusion, then fused by :mod:`tpvp.fusion`.

Before any fusion, :func:`frame_depths` reads and checks every frame (enough frames, image sizes,
depth at the distances the scale fuses: :func:`depth_bounds`), so a bad frame is one line naming
it and no frame without depth in range reaches Open3D. The fusion itself (TSDF integration, pose
refinement, surface extraction: :func:`tpvp.fusion.tsdf.fuse_frames`) lives in the library; its
names are importable from here as before.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from data_tools.capture.formats import Capture, load_colour, load_confidence, load_depth
from data_tools.errors import InputFileError
from tpvp.fusion.tsdf import (GREY, NEAREST_VOXELS, SCALES, DepthFrame, Fused, FusionConfig, PoseCorrection,
                              canonical_mesh, fuse_frames, fusion_config, supported, surface_samples)

__all__ = ["GREY", "NEAREST_VOXELS", "NEAR_PERCENTILE", "SCALES", "DepthFrame", "Fused", "FusionConfig",
           "PHONE_LAYOUTS", "PoseCorrection", "canonical_mesh", "corrections_csv", "corrections_path", "depth_bounds",
           "frame_depths", "frames_needed", "fuse", "fuse_capture", "fusion_config", "supported", "surface_samples"]

#: The layouts a phone writes with ARKit's tracked poses (drift of a few mm to cm over a walk):
#: their frames of a plant are refined against the model fused so far unless told not to.
PHONE_LAYOUTS = ("nerfstudio", "polycam")
CORRECTION_COLUMNS = ("frame", "status", "translation_mm", "rotation_deg", "fitness", "rmse_mm",
                      *(f"delta_{r}{c}" for r in range(3) for c in range(4)))

#: A frame's depth is judged by its nearest tenth (this percentile of its measured depth): the
#: subject is the nearest thing a capture looks at; background beyond it (a room's walls) is not.
NEAR_PERCENTILE = 10


def depth_bounds(config: FusionConfig) -> tuple[float, float]:
    """Where a frame's nearest tenth of depth (:data:`NEAR_PERCENTILE`) must lie, metres, to be fused
    at ``config``: from :data:`NEAREST_VOXELS` voxels to ``max_depth`` (a plant 0.1-1.5 m, a row
    0.2-3 m). The range spans a factor 15, so depth 10 or more times off moves a frame out of it
    unless the frame was seen from within a factor 1.5 of the range's ends."""
    return NEAREST_VOXELS * config.voxel_size, config.max_depth


def frames_needed(config: FusionConfig) -> int:
    """The fewest frames a surface can come from: each frame adds weight 1 to the voxels it sees, and
    a voxel is kept with more than ``min_weight``."""
    return int(np.floor(config.min_weight)) + 1


def frame_depths(capture: Capture, config: FusionConfig):
    """Every frame's ``(depth, intrinsics)`` as the fusion integrates it (float32 metres, 0: none;
    below the confidence floor and beyond ``max_depth`` dropped), all read and checked before any
    fusion: enough frames (:func:`frames_needed`), images of their intrinsics' size, some depth in
    every frame, and every frame's nearest tenth within :func:`depth_bounds` (else a units
    mistake: one line naming the first such frame and the ``--depth-scale`` that fits it). So every
    frame holds depth within ``max_depth``: Open3D aborts on a frame without any. No progress bar:
    an error is then the only line on stderr (reading is a fraction of the fusion's time)."""
    needed = frames_needed(config)
    if len(capture.frames) < needed:
        raise InputFileError(f"{capture.folder}: the capture holds {len(capture.frames)} frame"
                             f"{'s' if len(capture.frames) != 1 else ''}, and a surface is kept only where more than "
                             f"{config.min_weight:g} frame{'s' if config.min_weight != 1 else ''} saw it: fusion needs "
                             f"at least {needed} frames that overlap (capture the subject from several places)")
    low, high = depth_bounds(config)
    depths, outside = [], []
    for frame in capture.frames:
        depth, k = load_depth(frame)
        if not np.isfinite(depth).any():
            raise InputFileError(f"{frame.depth}: frame {frame.name} holds no depth (every pixel is 0 or NaN); export "
                                 f"the frame again, or remove it")
        confidence = load_confidence(frame, depth.shape)
        if confidence is not None:
            depth[confidence < config.min_confidence] = np.nan
        measured = depth[np.isfinite(depth)]
        if measured.size == 0:
            raise InputFileError(f"{frame.confidence}: frame {frame.name} holds no depth at confidence "
                                 f"{config.min_confidence} or more: lower --min-confidence, or remove the frame")
        near = float(np.percentile(measured, NEAR_PERCENTILE))
        if not low <= near <= high:
            outside.append((frame, near))
        depth[~(depth <= config.max_depth)] = 0.0  # NaN and beyond the range: no measurement
        depths.append((depth.astype(np.float32), k))
    if outside:
        raise _units_error(outside, len(capture.frames), low, high)
    return depths


def _units_error(outside, count: int, low: float, high: float) -> InputFileError:
    """The line for frames whose nearest tenth lies outside ``low``-``high``: the first such frame,
    the power of ten its depth would need, and whether ``--depth-scale`` (one for every frame) can
    give it."""
    frame, near = outside[0]
    scale = frame.depth_scale or (0.001 if frame.depth.suffix.lower() == ".png" else 1.0)
    power = round(np.log10(np.sqrt(low * high) / near))  # nearest the range's middle: within it if it spans 10x
    fit = scale * 10.0**power
    head = (f"{frame.depth}: frame {frame.name}'s depth lies {near:.3g} m away (its nearest tenth) read at {scale:g} m "
            f"per unit, outside the {low:g}-{high:g} m these settings fuse ({NEAREST_VOXELS} voxels to --max-depth)")
    if len(outside) == count:
        # one power of ten too far may be a real distance, not units
        farther = "; if it is that far, raise --max-depth" if power == -1 else ""
        return InputFileError(f"{head}; all {count} frames do: are the units wrong? try --depth-scale {fit:g}{farther}")
    return InputFileError(f"{head}, while {count - len(outside)} of the {count} frames lie within: if its units differ "
                          f"from theirs, convert that file ({fit:g} m per unit would fit it; --depth-scale applies to "
                          f"every frame), else remove the frame")


def fuse_capture(capture: Capture, config: FusionConfig = FusionConfig(), progress: bool = True) -> Fused:
    """The fused surface of every frame (:class:`tpvp.fusion.tsdf.Fused`: points in metres in the
    capture's world frame, uint8 RGB colours, each frame's pose and correction). Every frame is
    read and checked first (:func:`frame_depths`), then its colour read."""
    measured = frame_depths(capture, config)  # every frame's depth and intrinsics, checked
    frames = [DepthFrame(depth, k, frame.camera_to_world, load_colour(frame, depth.shape), frame.name)
              for frame, (depth, k) in zip(capture.frames, measured)]
    return fuse_frames(frames, config, progress, source=str(capture.folder))


def fuse(capture: Capture, config: FusionConfig = FusionConfig(), progress: bool = True):
    """``(points, colours)``: the fused surface of every frame, ``(N, 3)`` metres in the capture's
    world frame and ``(N, 3)`` uint8 RGB (:func:`fuse_capture`)."""
    fused = fuse_capture(capture, config, progress)
    return fused.points, fused.colours


def corrections_path(output) -> Path:
    """Where the per-frame pose corrections of the cloud ``output`` are written: beside it,
    ``NAME.corrections.csv``."""
    output = Path(output)
    return output.with_name(f"{output.stem}.corrections.csv")


def corrections_csv(corrections) -> str:
    """Every frame's :class:`~tpvp.fusion.tsdf.PoseCorrection` as CSV text (:data:`CORRECTION_COLUMNS`):
    its name, status, the camera's shift (mm) and turn (degrees), the ICP's fitness and RMSE (mm;
    empty for the first frame), and the 3 x 4 world-frame delta (refined = delta @ reported)."""
    def number(value: float) -> str:
        return "" if not np.isfinite(value) else f"{value:.6g}"

    lines = [",".join(CORRECTION_COLUMNS)]
    for c in corrections:
        delta = ",".join(f"{v:.10g}" for v in c.delta[:3].ravel())
        lines.append(f"{c.name},\"{c.status}\",{c.translation_mm:.4f},{c.rotation_deg:.5f},{number(c.fitness)},"
                     f"{number(c.rmse_mm)},{delta}")
    return "\n".join(lines) + "\n"
