"""A depth sensor's errors, as configuration: named noise profiles (``sensor.noise``) and the pure
function that applies one to a capture.

A capture is the points a view observes, in the world frame, and the camera position they were
seen from. :func:`apply_noise` perturbs it as a real sensor and a real robot would, in this order:

1. depth noise along each ray from the camera, Gaussian with ``sigma(d) = a + b d^2`` (d: the true
   depth along the ray, metres);
2. dropouts: each point is lost with probability ``dropout``;
3. mixed ("flying") pixels: at a depth discontinuity (a point whose angular neighbours, seen from
   the camera, differ in depth by more than ``edge_jump``) a share ``mixed_pixels`` of the points
   is moved along its ray to a depth drawn uniformly between the foreground and the background
   depth of its neighbourhood;
4. quantisation of the depth along the ray to a step ``quantisation`` (0: none), last among the
   depth errors so every reported depth lies on the grid, mixed pixels included;
5. the pose error, a rigid transform of the whole capture about the camera centre: per-capture
   jitter (Gaussian; ``jitter_m`` and ``jitter_deg`` are the RMS translation and rotation angle)
   and a drift that grows linearly with the capture's index over its sequence, from 0 at the
   first capture to ``drift_m`` / ``drift_deg`` at the last, in one direction per sequence.

The ``ideal`` profile (the default) returns its input array itself and draws nothing.
The figures of ``arm-rgbd`` and ``phone-lidar`` and their sources: docs/sensor.md#sensor-noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from scipy.spatial import cKDTree

from tpvp.errors import ConfigError
from tpvp.registry import Registry
from tpvp.sensor.camera import rotation_from_vector

DRIFT_STREAM = 0x64726966  # the drift directions' own random stream ("drif"), apart from the captures'


@dataclass(frozen=True)
class NoiseProfile:
    """A depth sensor's and its pose's errors (metres and degrees of the real world).

    sigma_a, sigma_b: depth noise along the ray, ``sigma = sigma_a + sigma_b * d**2`` (m; 1/m).
    dropout: share of the points lost. mixed_pixels: share of the points at a depth edge moved
    between the foreground and background depth (``edge_jump``: the depth step, m, that makes an
    edge among a point's ``edge_neighbours`` nearest rays). quantisation: depth step along the ray
    (m; 0 = none). jitter_m, jitter_deg: per-capture pose error (RMS translation, RMS rotation
    angle). drift_m, drift_deg: pose drift reached at the last capture of a sequence.
    """

    sigma_a: float = 0.0
    sigma_b: float = 0.0
    dropout: float = 0.0
    mixed_pixels: float = 0.0
    edge_jump: float = 0.01
    edge_neighbours: int = 8
    quantisation: float = 0.0
    jitter_m: float = 0.0
    jitter_deg: float = 0.0
    drift_m: float = 0.0
    drift_deg: float = 0.0

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
                    and value >= 0):
                raise ConfigError(f"noise profile: {f.name} must be a finite number >= 0, got {value!r}")
        for name in ("dropout", "mixed_pixels"):
            if getattr(self, name) > 1:
                raise ConfigError(f"noise profile: {name} is a share in [0, 1], got {getattr(self, name)!r}")
        if self.edge_jump <= 0 or int(self.edge_neighbours) != self.edge_neighbours or self.edge_neighbours < 1:
            raise ConfigError("noise profile: edge_jump must be > 0 m and edge_neighbours a positive integer")

    def sigma(self, depth):
        """The depth noise's standard deviation (m) at ``depth`` (m)."""
        return self.sigma_a + self.sigma_b * np.square(depth)

    @property
    def ideal(self) -> bool:
        """No error of any kind: captures are returned unchanged."""
        return not any((self.sigma_a, self.sigma_b, self.dropout, self.mixed_pixels, self.quantisation,
                        self.jitter_m, self.jitter_deg, self.drift_m, self.drift_deg))


NOISE_PROFILES = Registry("sensor noise profile")

#: Today's simulated sensor: exact depth, no dropout, exact pose (the default).
IDEAL = NOISE_PROFILES.register("ideal", "no error: the simulator's exact captures (the default)",
                                default=True)(NoiseProfile())

#: A wrist RGB-D camera of the Intel RealSense D405 class on a calibrated arm, at 0.3-0.7 m. The
#: figures are approximate, from Intel's published material as best known:
#: - sigma_b = 0.0066 /m: the D400 series' RMS-error formula (Intel, "Tuning depth cameras for best
#:   performance", Grunnet-Jepsen et al.) ``RMS = d^2 * subpixel / (f * baseline)`` with the D405
#:   data sheet's 18 mm baseline, its 87 deg horizontal depth field of view at 1280 px (f ~ 675 px)
#:   and the white paper's typical 0.08 subpixel: ~0.6 mm at 0.3 m, ~1.6 mm at 0.5 m, ~3.2 mm at 0.7 m;
#: - sigma_a = 0.1 mm: an assumed floor, of the order of the depth unit;
#: - quantisation = 0.1 mm: the D405's default depth unit (100 um, librealsense's depth scale);
#: - dropout = 1 %: the data sheet's fill-rate figure (>= 99 %) for the D400 series;
#: - mixed_pixels = 10 % of the edge points: assumed (stereo edge artefacts; no data-sheet figure);
#: - pose jitter 1 mm / 0.1 deg, no drift: a calibrated arm's repeatability and hand-eye error
#:   (assumed, typical of a collaborative arm).
ARM_RGBD = NOISE_PROFILES.register("arm-rgbd", "a D405-class wrist RGB-D camera on a calibrated arm (0.3-0.7 m)")(
    NoiseProfile(sigma_a=0.0001, sigma_b=0.0066, dropout=0.01, mixed_pixels=0.1, quantisation=0.0001,
                 jitter_m=0.001, jitter_deg=0.1))

#: A phone's LiDAR with ARKit's poses, held by a person walking an orbit: sigma = 2 mm + 6 mm d^2,
#: 3 % dropouts, mixed pixels at half of the depth edges' points (assumed share), depth as float
#: (no quantisation), pose jitter 2 mm / 0.2 deg and drift 5 mm / 0.5 deg over the orbit (the
#: project's figures for ARKit-like tracking, approximate).
PHONE_LIDAR = NOISE_PROFILES.register("phone-lidar", "a phone LiDAR with ARKit-like poses, on an orbit")(
    NoiseProfile(sigma_a=0.002, sigma_b=0.006, dropout=0.03, mixed_pixels=0.5, jitter_m=0.002, jitter_deg=0.2,
                 drift_m=0.005, drift_deg=0.5))


def noise_profile(name: str) -> NoiseProfile:
    """The profile called ``name``; an unknown name is one :class:`ConfigError` line listing the choices."""
    return NOISE_PROFILES.get(name)


def drift_directions(drift_seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The unit translation and rotation axes of a sequence's drift (the same for every capture)."""
    rng = np.random.default_rng([int(drift_seed), DRIFT_STREAM])
    axes = rng.standard_normal((2, 3))
    return tuple(axes / np.linalg.norm(axes, axis=1, keepdims=True))


def pose_error(profile: NoiseProfile, capture: int, captures: int, rng: np.random.Generator,
               drift_seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)``: the pose error of capture ``capture`` of ``captures`` (rotation, translation in
    metres, world axes): the jitter drawn from ``rng`` (6 normal draws) on top of the drift, which
    is ``capture / (captures - 1)`` of the profile's drift along :func:`drift_directions`."""
    root3 = math.sqrt(3.0)
    jitter_t = rng.standard_normal(3) * (profile.jitter_m / root3)
    jitter_r = rng.standard_normal(3) * (math.radians(profile.jitter_deg) / root3)
    share = capture / (captures - 1) if captures > 1 else 0.0
    if profile.drift_m or profile.drift_deg:
        axis_t, axis_r = drift_directions(drift_seed)
        drift_t, drift_r = share * profile.drift_m * axis_t, share * math.radians(profile.drift_deg) * axis_r
    else:
        drift_t = drift_r = np.zeros(3)
    return rotation_from_vector(jitter_r) @ rotation_from_vector(drift_r), drift_t + jitter_t


def edge_bounds(rays: np.ndarray, depth: np.ndarray, neighbours: int) -> tuple[np.ndarray, np.ndarray]:
    """Per point: the least and the greatest depth among itself and its ``neighbours`` nearest
    rays (unit directions from the camera): the foreground and background depth around it."""
    k = min(int(neighbours) + 1, len(depth))
    _, nearest = cKDTree(rays).query(rays, k=k)
    around = depth[np.reshape(nearest, (len(depth), k))]
    return around.min(axis=1), around.max(axis=1)


def apply_noise(profile: NoiseProfile, points, position, capture: int, captures: int, rng: np.random.Generator,
                per_metre: float = 1.0, drift_seed: int = 0) -> np.ndarray:
    """The capture ``points`` ((N, 3), world frame) seen from the camera at ``position``, as
    ``profile``'s sensor reports it: capture ``capture`` of a sequence of ``captures``, errors drawn
    from ``rng`` (see the module's order). ``per_metre``: the frame's units per metre of the real
    world (the profile's figures are metres). Dropouts remove rows: the result may be shorter.
    The ideal profile returns ``points`` itself and draws nothing from ``rng``."""
    if profile.ideal:
        return points
    points = np.asarray(points, dtype=np.float64)
    camera = np.asarray(position, dtype=np.float64).reshape(3)
    n = len(points)
    offsets = points - camera
    along = np.linalg.norm(offsets, axis=1)
    rays = offsets / np.where(along > 0, along, 1.0)[:, None]
    true_depth = along / per_metre
    depth = true_depth + rng.standard_normal(n) * profile.sigma(true_depth)
    keep = rng.random(n) >= profile.dropout
    if profile.mixed_pixels and n > 1:
        near, far = edge_bounds(rays, true_depth, profile.edge_neighbours)
        mixed = (far - near > profile.edge_jump) & (rng.random(n) < profile.mixed_pixels)
        depth = np.where(mixed, near + rng.random(n) * (far - near), depth)
    if profile.quantisation:
        depth = np.round(depth / profile.quantisation) * profile.quantisation
    depth = np.maximum(depth, 0.0)
    seen = (camera + rays * (depth * per_metre)[:, None])[keep]
    rotation, translation = pose_error(profile, capture, captures, rng, drift_seed)
    return camera + translation * per_metre + (seen - camera) @ rotation.T


def apply_depth_noise(profile: NoiseProfile, depth, intrinsics, camera_to_world, capture: int, captures: int,
                      rng: np.random.Generator, drift_seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """One pinhole depth image as ``profile``'s sensor and tracking report it: ``(depth, pose)``.

    ``depth``: ``(H, W)`` camera-z depth in metres, no return where it is 0 or not finite (kept as
    it is); ``intrinsics``: the image's pinhole (:class:`tpvp.sensor.camera.Intrinsics`, pixel
    ``(u, v)`` centred at ``u``, ``v``); ``camera_to_world``: the true ``(4, 4)`` pose (OpenCV
    axes); capture ``capture`` of a sequence of ``captures``. The same errors as :func:`apply_noise`:

    * the pose error is drawn first (so it does not depend on the image's size): ``(R, t) =``
      :func:`pose_error` of the same ``rng`` and ``drift_seed``; the reported pose turns the camera
      by ``R`` about its centre and moves it by ``t`` (world axes), so the image fused with it
      lands where :func:`apply_noise` puts the same points: ``[R @ R_true | c + t]``;
    * depth noise along each pixel's ray: the ray distance is ``r = z * s`` with
      ``s = |((u - cx) / fx, (v - cy) / fy, 1)|``; ``r`` gets a Gaussian error of
      ``sigma(r) = a + b r^2``, i.e. ``z`` one of ``sigma(r) / s`` (one normal draw per pixel);
    * dropouts: each pixel's depth becomes 0 with probability ``dropout`` (one uniform per pixel);
    * mixed pixels: a pixel whose neighbourhood (itself and the pixels within the smallest square
      window holding ``edge_neighbours`` neighbours: 3 x 3 for 8) has true depths with a step over
      ``edge_jump`` is, with the share ``mixed_pixels``, given a depth drawn uniformly between the
      least and the greatest true z there (two uniforms per pixel); pixels without a return count
      as no neighbour and are never moved;
    * quantisation of the reported z (a depth image's unit) to ``quantisation``, last; depth
      pushed below 0 becomes 0 (no return).

    All draws are over the whole image in row-major order. The ideal profile returns ``depth`` and
    ``camera_to_world`` themselves and draws nothing from ``rng``.
    """
    if profile.ideal:
        return depth, camera_to_world
    from scipy.ndimage import maximum_filter, minimum_filter

    pose = np.asarray(camera_to_world, dtype=np.float64)
    rotation, translation = pose_error(profile, capture, captures, rng, drift_seed)
    reported = np.eye(4)
    reported[:3, :3] = rotation @ pose[:3, :3]
    reported[:3, 3] = pose[:3, 3] + translation

    true_z = np.asarray(depth, dtype=np.float64)
    height, width = true_z.shape
    valid = np.isfinite(true_z) & (true_z > 0)
    k = intrinsics
    x = (np.arange(width, dtype=np.float64) - k.cx) / k.fx
    y = (np.arange(height, dtype=np.float64) - k.cy) / k.fy
    stretch = np.sqrt(1.0 + x[None, :] ** 2 + y[:, None] ** 2)  # ray distance per unit of z
    z = np.where(valid, true_z, 0.0)
    along = z * stretch
    n = height * width
    noisy = z + rng.standard_normal(n).reshape(height, width) * (profile.sigma(along) / stretch)
    dropped = rng.random(n).reshape(height, width) < profile.dropout
    if profile.mixed_pixels:
        radius = max(1, math.ceil((math.sqrt(profile.edge_neighbours + 1) - 1) / 2))
        size = 2 * radius + 1
        near = minimum_filter(np.where(valid, true_z, np.inf), size=size, mode="constant", cval=np.inf)
        far = maximum_filter(np.where(valid, true_z, -np.inf), size=size, mode="constant", cval=-np.inf)
        near, far = np.where(valid, near, 0.0), np.where(valid, far, 0.0)  # a valid pixel bounds itself
        mixed = valid & (far - near > profile.edge_jump) & (rng.random(n).reshape(height, width) < profile.mixed_pixels)
        between = rng.random(n).reshape(height, width)
        noisy = np.where(mixed, near + between * (far - near), noisy)
    if profile.quantisation:
        noisy = np.round(noisy / profile.quantisation) * profile.quantisation
    noisy = np.where(dropped, 0.0, np.maximum(noisy, 0.0))
    out = np.where(valid, noisy, depth).astype(np.asarray(depth).dtype, copy=False)
    return out, reported
