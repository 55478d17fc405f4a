"""What a backend's camera-calibration model is made of (judge/calibration.py fits, docs/calibration.md).

A backend's `BackendSpec.calibration` (renderers/spec.py) is a `CameraModel`: from the probe pixels
used in the fit (`ProbePixels`) it bounds the error its own arithmetic can put into each pixel's
equation and, per triangle vertex, how far its plane may sit from the true one (`ErrorBudget`).
The core's models (raster and trace, Embree) are here because renderers/core.py and the fit's
fallback share them; each external backend's sits beside its exporter (renderers/<name>/backend.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .tolerance import F32_U, render_param

F64_U = 2.0**-53


class CalibrationError(Exception):
    """One (probe, backend) cannot be measured; becomes an `error` entry with this reason."""


@dataclass(frozen=True)
class ProbePixels:
    """What a precision model may look at: the K pixels used in the fit ((K,) float64) and the
    probe's triangles ((N, 3) per vertex)."""

    z: np.ndarray  # planar depth the backend wrote
    n_dot_d: np.ndarray  # |n.d|: the plane's normal against the unnormalized pixel ray
    n_perp: np.ndarray  # |(n.r, n.u)|: the plane's tilt; the equation's sensitivity to (sx, sy)
    d: np.ndarray  # (K, 3) the convention's unnormalized pixel ray
    d_norm: np.ndarray  # |d|
    cos: np.ndarray  # |n.d| / |d|
    point_norm: np.ndarray  # |X|: the hit point's distance from the world origin
    extent: np.ndarray  # longest edge of the triangle seen
    vertex_norm: np.ndarray  # (N, 3) |V|: each vertex's distance from the world origin
    vertex_depth: np.ndarray  # (N, 3) planar depth of each vertex
    vertex_d_norm: np.ndarray  # (N, 3) |d| of the ray through each vertex
    tri_extent: np.ndarray  # (N,) longest edge of each triangle
    eye: np.ndarray  # (3,)
    origin_offset: float  # |f32(eye) - eye|
    pixel: float  # one pixel on the image plane at distance 1: 2 tan(vfov/2) / H
    width: int
    height: int
    info: Mapping[str, Any]  # the render's info from manifest.json
    attrs: Mapping[str, Any]  # the EXR's rendiff attributes

    @property
    def eye_norm(self) -> float:
        return float(np.linalg.norm(self.eye))

    # Per-pixel error bounds in the equation's units (h/Z), from the three kinds of error:
    def depth_rel(self, rel: np.ndarray | float) -> np.ndarray:
        """A relative planar-depth error rel: d(h/Z) = |n.d| rel."""
        return np.asarray(self.n_dot_d * rel, dtype=np.float64)

    def shift(self, e: np.ndarray | float) -> np.ndarray:
        """A ray origin (or plane) moved by e world units: the plane's offset changes by <= e, d(h/Z) <= e/Z."""
        return np.asarray(np.asarray(e, dtype=np.float64) / self.z)

    def sample(self, ds: np.ndarray | float) -> np.ndarray:
        """A sample moved by ds on the image plane at distance 1 (s units): d(h/Z) <= |(n.r, n.u)| ds."""
        return np.asarray(self.n_perp * ds, dtype=np.float64)


@dataclass(frozen=True)
class ErrorBudget:
    """A backend's error bounds (module docstring).

    * `pixel` (K,): per-pixel bounds, in h/Z units, of the error in each pixel's equation;
    * `vertex` (N, 3) or None: bounds, in world units, on how far the backend's plane of each
      triangle may sit from the true one at each of its vertices.
    """

    pixel: np.ndarray
    text: str
    vertex: np.ndarray | None = None


CameraModel = Callable[[ProbePixels], ErrorBudget]


def probe_param(px: ProbePixels, key: str) -> float | None:
    """`render_param` of the probe render being fitted."""
    return render_param(px.attrs, px.info, key)


def f32_origin_error(eye: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """(K,) bound on |f32(f32(eye) + offset) - (eye + offset)| for per-pixel offsets (K, 3).

    Rounding to nearest moves each coordinate by at most half a float32 step, and never
    farther than f32(eye_j), itself a float32 candidate: |f32(eye_j) - eye_j| + |offset_j|.
    """
    e = np.asarray(eye, dtype=np.float64)[None, :]
    o = e + offset
    half = np.spacing(np.abs(o).astype(np.float32)).astype(np.float64) / 2.0
    eye_err = np.abs(e.astype(np.float32).astype(np.float64) - e)
    return np.asarray(np.linalg.norm(np.minimum(half, eye_err + np.abs(offset)), axis=1))


def core_camera(px: ProbePixels) -> ErrorBudget:
    """raster/trace: pixel rays in f64, one depth function rounded once to f32."""
    return ErrorBudget(
        px.depth_rel(F32_U) + px.sample(2.0 * math.sqrt(3.0) * F64_U * (px.eye_norm + px.d_norm)),
        "Z rounded once to f32 (2^-24 Z) + f64 pixel rays (P = eye + d rounded: "
        "2 sqrt(3) 2^-53 (|eye| + |d|) on the image plane)",
    )


RAY_TRIANGLE_ROUNDINGS = 8.0
"""Roundings of an f32 ray-triangle t relative to itself (the watertight test's shear, three 2x2
determinants, their sum and the quotient; Moeller-Trumbore's cross and dot products alike),
amplified by 1/|cos| as a plane's t is."""


def embree_camera(px: ProbePixels) -> ErrorBudget:
    """Embree: the core's pixel rays with origin and direction rounded to f32, f32 intersection."""
    return ErrorBudget(
        px.shift(px.origin_offset)
        + px.sample(F32_U * px.d_norm)
        + px.depth_rel(F32_U + RAY_TRIANGLE_ROUNDINGS * F32_U / px.cos),
        f"rays start at f32(eye), |f32(eye) - eye| = {px.origin_offset:.3g}; direction "
        f"rounded to f32 (2^-24 |d|), f32 ray-triangle t ({RAY_TRIANGLE_ROUNDINGS:g} 2^-24 / |cos|), "
        "Z stored as f32 (2^-24)",
    )
