"""Organ geometry of the procedural plants (:mod:`tpvp.synthetic.plants`).

A :class:`Curve` is an organ's axis or midrib with a frame along it; a :class:`Tube` (stem,
petiole, rachis) and a :class:`Blade` (leaf, leaflet, cotyledon) are surfaces around a curve,
evaluated at material samples ``(s, t, w)``: along the curve, across it, and into the scanned
layer. Every organ grows along :func:`relative_size` of its own age.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CURVE_NODES = 65  # nodes of a curve's arc-length table
G_VISIBLE = 0.06  # a leaf is generated once it has reached 6% of its final length


def relative_size(age, T):
    """Relative size of an organ of age ``age`` days and growth time ``T``: 1 - exp(-(a/T)^2)."""
    a = np.maximum(np.asarray(age, dtype=np.float64), 0.0)
    return 1.0 - np.exp(-((a / T) ** 2))


def age_visible(T):
    """Age at which an organ with growth time T reaches the visibility threshold."""
    return T * np.sqrt(-np.log(1.0 - G_VISIBLE))


def smoothstep(a, b, x):
    """0 below ``a``, 1 above ``b``, a smooth cubic in between."""
    u = np.clip((x - a) / (b - a), 0.0, 1.0)
    return u * u * (3 - 2 * u)


def beta_profile(s, a, b):
    """s^a (1-s)^b normalised to a maximum of 1 (a blade outline)."""
    s = np.clip(s, 0.0, 1.0)
    m = a / (a + b)
    return (s**a) * ((1 - s) ** b) / ((m**a) * ((1 - m) ** b))


class Curve:
    """An arc-length parameterised 3D curve with a frame, on normalised parameter s in [0, 1].

    Direction from azimuth ``phi(s)`` and elevation ``theta(s)`` (arrays on the node grid); the
    lateral vector B is horizontal, N = T x B points 'up' out of the blade, ``psi(s)`` twists B, N
    about T.
    """

    def __init__(self, p0, length, phi, theta, psi=None):
        self.length = float(length)
        s = np.linspace(0.0, 1.0, CURVE_NODES)
        ct, st = np.cos(theta), np.sin(theta)
        cp, sp = np.cos(phi), np.sin(phi)
        T = np.stack([ct * cp, ct * sp, st], axis=1)
        B = np.stack([-sp, cp, np.zeros_like(sp)], axis=1)
        N = np.stack([-st * cp, -st * sp, ct], axis=1)
        if psi is not None:
            c, sn = np.cos(psi)[:, None], np.sin(psi)[:, None]
            B, N = c * B + sn * N, -sn * B + c * N
        ds = np.diff(s)[:, None]
        steps = 0.5 * (T[1:] + T[:-1]) * ds * self.length
        self.pos = np.asarray(p0, dtype=np.float64)[None, :] + np.vstack([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
        self.T, self.B, self.N = T, B, N

    def at(self, s):
        s = np.clip(np.asarray(s, dtype=np.float64), 0.0, 1.0)
        x = s * (CURVE_NODES - 1)
        i = np.minimum(np.floor(x).astype(np.int64), CURVE_NODES - 2)
        w = (x - i)[:, None]

        def lerp(a):
            return a[i] * (1 - w) + a[i + 1] * w

        def unit(v):
            return v / np.linalg.norm(v, axis=1, keepdims=True)

        return lerp(self.pos), unit(lerp(self.T)), unit(lerp(self.B)), unit(lerp(self.N))

    def point(self, s):
        p, T, B, N = self.at(np.array([s]))
        return p[0], T[0], B[0], N[0]


class Tube:
    """Tube of radius ``radius(s)`` around the sub-range [s0, s1] of a curve (t = angle / 2 pi)."""

    kind = "tube"

    def __init__(self, curve, s0, s1, radius):
        self.curve, self.s0, self.s1, self._radius = curve, s0, s1, radius
        self.length = (s1 - s0) * curve.length
        self.layer = 0.0  # thickness of the scanned layer (m), set per species by the plant generator

    def radius(self, f):
        return self._radius(self.s0 + np.asarray(f) * (self.s1 - self.s0))

    def max_radius(self):
        return float(np.max(self.radius(np.linspace(0, 1, 9))))

    def eval(self, f, t, w=None):
        """Surface points at (f, t); ``w`` (layer depth, in layer thicknesses) moves them radially."""
        p, _, B, N = self.curve.at(self.s0 + f * (self.s1 - self.s0))
        a = 2 * np.pi * t
        r = self.radius(f)
        if w is not None:
            r = np.maximum(r + w * self.layer, 0.5 * r)
        return p + r[:, None] * (np.cos(a)[:, None] * B + np.sin(a)[:, None] * N)


class Blade:
    """Thin sheet around a midrib curve.

    halfwidth(s) = hw * profile(s). Cross-section at s: a curve of arc length |l| = |t| hw(s) whose
    angle to B starts at ``fold(s)`` (margins raised: a V) and bends by ``roll(s)`` radians per
    half-width (a cup or a roll), plus a small margin wave along N. ``w`` (layer depth) moves a
    sample along the cross-section's normal by ``w * layer``.
    """

    kind = "blade"

    def __init__(self, curve, hw, profile, fold=(0.0, 0.0), roll=lambda s: 0.0 * s, wave=(0.0, 0.0, 0.0)):
        self.curve, self.hw, self.profile = curve, float(hw), profile
        self.length = curve.length
        self.fold, self.roll, self.wave = fold, roll, wave
        self.layer = 0.0  # thickness of the scanned layer (m), set per species by the plant generator

    def halfwidth(self, s):
        return self.hw * self.profile(np.asarray(s, dtype=np.float64))

    def eval(self, s, t, w=None):
        p, _, B, N = self.curve.at(s)
        hw = self.halfwidth(s)
        u = np.abs(t) * hw
        f = self.fold[0] + (self.fold[1] - self.fold[0]) * s
        rho = self.roll(s)  # total bend over the half-width (rad)
        c = rho / np.maximum(hw, 1e-9)
        c = np.where(np.abs(c) < 1e-3, 1e-3, c)
        lat = (np.sin(f + c * u) - np.sin(f)) / c
        up = (np.cos(f) - np.cos(f + c * u)) / c
        amp, k, ph = self.wave
        if amp:
            up = up + amp * np.abs(t) ** 3 * np.sin(2 * np.pi * k * s + ph)
        if w is not None:  # the scanned layer: along the normal of the cross-section curve
            ang = f + c * u
            off = w * self.layer
            lat = lat - off * np.sin(ang)
            up = up + off * np.cos(ang)
        return p + (np.sign(t) * lat)[:, None] * B + up[:, None] * N


@dataclass
class Part:
    """One piece of a plant (an internode, a petiole or rachis, a blade or leaflet) and its surface."""

    key: tuple
    organ: int
    kind: str  # "stem", "petiole", "blade"
    geom: object
