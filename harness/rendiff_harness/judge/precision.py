"""A backend's precision, found through its spec (renderers/spec.py), with the judge's rule for a
backend that has none: compared exactly, and every text says so, so that a new backend fails
loudly until its models are written."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..renderers.spec import BackendSpec
from .camera_budget import CameraModel, core_camera
from .tolerance import Model, RgbTolerance, f32_normals, rgb_fallback, strict_model


def depth_model(spec: BackendSpec | None, backend: str) -> Model:
    """The edge, position and depth model of `backend`; without a spec a strict, exact one."""
    return spec.precision if spec is not None else strict_model(backend)


def rgb_tolerance(
    spec: BackendSpec | None, backend: str, ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]
) -> RgbTolerance:
    """The deterministic RGB tolerance of `backend` at the reference values `ref` (H, W, 3)."""
    if spec is not None and spec.rgb_tolerance is not None:
        return spec.rgb_tolerance(ref, attrs, info)
    return rgb_fallback(backend, attrs)


def normal_tolerance(spec: BackendSpec | None, cond: np.ndarray) -> tuple[np.ndarray, str]:
    """Allowed angle (radians) between the backend's N and the winding convention, per pixel
    (`cond` = |e1| |e2| / |e1 x e2|); a backend without a spec is held to f32 arithmetic."""
    return (spec.normals if spec is not None else f32_normals)(cond)


def camera_model(spec: BackendSpec | None) -> tuple[CameraModel, bool]:
    """The backend's camera-error model, and whether it has one (else: exact f32 depth)."""
    return (spec.calibration, True) if spec is not None else (core_camera, False)


def camera_owner(spec: BackendSpec | None, backend: str) -> str:
    """Whose convention a calibration failure blames: the core's camera, a renderer declared by
    command (it reads the resolved scene itself), or the built-in backend's exporter."""
    if spec is not None and spec.core_loop:
        return f"the rendiff core's camera ({backend})"
    if spec is not None and spec.declared:
        return f"the {backend} renderer"
    return f"the {backend} exporter"
