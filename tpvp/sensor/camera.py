"""Pinhole camera of the virtual sensor: intrinsics and poses from position + look-at.

The camera frame is OpenCV's: +z along the optical axis, +x to the right of the image, +y down.
Roll is fixed by the world up vector +Z (docs/sensor.md#look-at-pose): ``x = z x up`` normalised, ``y = z x x``.
When the optical axis is (anti)parallel to up the cross product vanishes; the world +Y axis then
stands in for "up" so looking straight down or up still gives a valid rotation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tpvp.errors import SensorError

WORLD_UP = np.array([0.0, 0.0, 1.0])
_FALLBACK_UP = np.array([0.0, 1.0, 0.0])


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics; defaults are the Intel RealSense D435 colour stream at 1280 x 720."""

    fx: float = 915.6067
    fy: float = 913.3267
    cx: float = 647.1453
    cy: float = 372.5153
    width: int = 1280
    height: int = 720

    def matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def resized(self, width: int, height: int) -> "Intrinsics":
        """The same camera's intrinsics for an image of ``width`` x ``height`` pixels (a phone's
        depth map beside its colour image): the image's corners stay where they are, so the
        principal point scales about the top-left pixel's corner, half a pixel before its centre."""
        sx, sy = width / self.width, height / self.height
        return Intrinsics(self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5,
                          int(width), int(height))


D435 = Intrinsics()
#: Where nerfstudio and COLMAP put the top-left pixel's centre in tpvp's pixel coordinates (those of
#: OpenCV and Open3D, where it is (0, 0)): their principal point is tpvp's plus this.
PIXEL_CENTRE = 0.5


def look_at_rotation(position, look_at) -> np.ndarray:
    """Camera-to-world rotation (columns = camera x, y, z axes in world coordinates)."""
    px, py, pz = (float(c) for c in np.asarray(position, dtype=np.float64).reshape(3))
    lx, ly, lz = (float(c) for c in np.asarray(look_at, dtype=np.float64).reshape(3))
    if not all(math.isfinite(c) for c in (px, py, pz, lx, ly, lz)):
        raise SensorError(f"camera position {[px, py, pz]} and look-at {[lx, ly, lz]} must be finite")
    zx, zy, zz = lx - px, ly - py, lz - pz
    length = math.sqrt(zx * zx + zy * zy + zz * zz)
    if length < 1e-9:
        raise SensorError(
            f"zero-length look-at: the camera at {[round(px, 6), round(py, 6), round(pz, 6)]} "
            "looks at its own position"
        )
    zx, zy, zz = zx / length, zy / length, zz / length
    # x = z cross up with up = +Z; fall back to up = +Y when looking straight up or down.
    xx, xy, xz = zy, -zx, 0.0
    norm = math.sqrt(xx * xx + xy * xy)
    if norm < 1e-9:
        xx, xy, xz = -zz, 0.0, zx
        norm = math.sqrt(xx * xx + xz * xz)
    xx, xy, xz = xx / norm, xy / norm, xz / norm
    yx, yy, yz = zy * xz - zz * xy, zz * xx - zx * xz, zx * xy - zy * xx
    return np.array([[xx, yx, zx], [xy, yy, zy], [xz, yz, zz]])


def look_at_rotations(positions, look_ats) -> np.ndarray:
    """Vectorised :func:`look_at_rotation` for ``(V, 3)`` positions and look-ats -> ``(V, 3, 3)``."""
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    look_ats = np.broadcast_to(np.asarray(look_ats, dtype=np.float64).reshape(-1, 3), positions.shape)
    return np.stack([look_at_rotation(p, t) for p, t in zip(positions, look_ats)]) if len(positions) else (
        np.zeros((0, 3, 3))
    )


def rotation_from_vector(rotvec: np.ndarray) -> np.ndarray:
    """The rotation matrix of a rotation vector (radians; Rodrigues' formula)."""
    angle = float(np.linalg.norm(rotvec))
    if angle == 0.0:
        return np.eye(3)
    axis = rotvec / angle
    cross = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * cross + (1.0 - math.cos(angle)) * (cross @ cross)


def rotation_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)`` of a rotation matrix (for robot-facing pose files)."""
    m = np.asarray(rotation, dtype=np.float64)
    trace = np.trace(m)
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = [0.0, 0.0, 0.0, (m[k, j] - m[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (m[j, i] + m[i, j]) / s
        q[k] = (m[k, i] + m[i, k]) / s
    q = np.asarray(q)
    return q / np.linalg.norm(q)


def rigid_error(matrix) -> float:
    """How far a 4x4 matrix is from a rigid transform: the largest deviation of its rotation from
    an orthonormal matrix of determinant +1, or of its last row from 0 0 0 1 (0 for a rigid one)."""
    matrix = np.asarray(matrix, dtype=np.float64)
    rotation = matrix[:3, :3]
    return float(max(np.abs(rotation @ rotation.T - np.eye(3)).max(), abs(np.linalg.det(rotation) - 1.0),
                     np.abs(matrix[3] - [0, 0, 0, 1]).max()))


def switch_camera_axes(camera_to_world) -> np.ndarray:
    """A ``(..., 4, 4)`` camera-to-world pose with OpenCV camera axes (x right, y down, z forward)
    as the same pose with OpenGL's (x right, y up, z backward: nerfstudio's ``transform_matrix``),
    and back: the y and z axes change sign, so the function is its own inverse."""
    pose = np.array(camera_to_world, dtype=np.float64)
    pose[..., :3, 1:3] *= -1.0
    return pose


def project(points, position, rotation, intrinsics: Intrinsics = D435):
    """Pixel coordinates ``(u, v)`` and depth ``z`` of world points seen from a camera."""
    local = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - position) @ rotation
    z = local[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = intrinsics.fx * local[:, 0] / z + intrinsics.cx
        v = intrinsics.fy * local[:, 1] / z + intrinsics.cy
    return u, v, z


def in_frustum(points, position, rotation, intrinsics: Intrinsics = D435) -> np.ndarray:
    """Mask of points in front of the camera that project inside the image (borders included)."""
    u, v, z = project(points, position, rotation, intrinsics)
    return (z > 0) & (u >= 0) & (u <= intrinsics.width) & (v >= 0) & (v <= intrinsics.height)


def pixel_ray_directions(rotation, intrinsics: Intrinsics = D435, stride: int = 1) -> np.ndarray:
    """World-frame directions (unnormalised, camera z = 1) through pixels ``(u, v)`` at ``stride``.

    Pixel ``(u, v)`` is the point ``(u, v)`` of the image plane, as in RealSense deprojection.
    Row-major order: ``v`` outer, ``u`` inner. Written element-wise (no matmul) so the float
    operations are exactly those of the numba pixel kernel.
    """
    if int(stride) < 1:
        raise SensorError(f"pixel stride must be a positive integer, got {stride!r}")
    stride = int(stride)
    rot = np.asarray(rotation, dtype=np.float64)
    us = np.arange(0, intrinsics.width, stride)
    vs = np.arange(0, intrinsics.height, stride)
    xn = (us.astype(np.float64) - intrinsics.cx) / intrinsics.fx
    yn = (vs.astype(np.float64) - intrinsics.cy) / intrinsics.fy
    xx, yy = np.meshgrid(xn, yn)
    return np.stack([rot[i, 0] * xx + rot[i, 1] * yy + rot[i, 2] for i in range(3)], axis=-1).reshape(-1, 3)
