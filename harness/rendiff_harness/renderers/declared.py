"""A renderer declared by a command (renderers/command.py) as a `BackendSpec`: its precision is
the numbers it declares in `[renderer.precision]` (docs/your-renderer.md), nothing else.

Kept apart from command.py so that reading a renderers file stays light (no numpy): the
registry builds these specs only when a backend is looked up.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..contract.vocab import Buffer, Feature
from ..judge.camera_budget import CameraModel, ErrorBudget, ProbePixels
from ..judge.tolerance import (
    F32_U,
    MAX_REL,
    DepthContext,
    Model,
    NormalModel,
    RgbModel,
    RgbTolerance,
    f32_normals,
    relative_grazing,
)
from .command import CommandBackend, Renderer
from .spec import BackendSpec


def depth_model(r: Renderer) -> Model:
    """The `Model` of a declared renderer, from the numbers it declares, nothing else.

    Edge: `edge_px` (0 when it writes no ids). Depth: |dZ| <= depth_absolute + depth_relative Z,
    the relative term over |cos| (capped at MAX_REL Z) when `depth_grazing` is set.

    The absolute term counts at most MAX_REL Z at each pixel, the bound on `depth_relative`
    (command.PRECISION_BOUNDS, derived in docs/your-renderer.md, "What can be judged"): a
    number in scene units has no bound valid for every scene, so it is bounded where it is
    used, and a `depth_absolute` of 1e6 no longer passes any depth at all. The text says so.
    """
    p = r.precision
    rel, absolute, grazing = p.depth_relative or 0.0, p.depth_absolute, p.depth_grazing
    cap = f"min({absolute:g}, {MAX_REL:g}*Z)" if absolute > 0 else "0"

    def depth(ctx: DepthContext) -> tuple[np.ndarray, str]:
        tol = np.minimum(absolute, MAX_REL * np.abs(ctx.z_ref))
        if grazing:
            tol = tol + relative_grazing(ctx, rel)
            term = f"Z*min({rel:g}/|cos|, {MAX_REL:g})"
        else:
            tol = tol + rel * np.abs(ctx.z_ref)
            term = f"{rel:g}*Z"
        return np.asarray(tol, dtype=np.float64), f"|dZ| <= {cap} + {term}, declared by the user in {r.declared}"

    if p.edge_px is None:
        edge, reason = 0.0, f"{r.declared} writes no ids"
    else:
        edge, reason = p.edge_px, f"edge_px declared by the user in {r.declared}"
    return Model(r.name, edge, reason, depth)


def rgb_model(r: Renderer) -> RgbModel:
    """|dL| <= rgb_absolute + rgb_relative |L|, as declared."""
    p = r.precision
    rel = p.rgb_relative or 0.0

    def rgb(ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]) -> RgbTolerance:
        return RgbTolerance(
            p.rgb_absolute, rel, f"|dL| <= {p.rgb_absolute:g} + {rel:g}*|L|, declared by the user in {r.declared}"
        )

    return rgb


def normal_model(r: Renderer) -> NormalModel:
    """The angle it declares (`normal_relative`); without one, f32 arithmetic's."""
    angle = r.precision.normal_relative
    if angle is None:
        return f32_normals

    def normals(cond: np.ndarray) -> tuple[np.ndarray, str]:
        text = f"angle <= {angle:g} rad (normal_relative), declared by the user in {r.declared}"
        return np.full(cond.shape, angle), text

    return normals


def camera_model(r: Renderer) -> CameraModel:
    """Its declared numbers as errors of each pixel's equation in the camera fit.

    A planar depth off by depth_absolute + depth_relative Z (over |cos| with depth_grazing) is a
    relative error of depth_absolute / Z (at most MAX_REL, as in `depth_model`) + depth_relative;
    edge_px bounds how far from the pixel center it may sample (edge_px pixels on the image
    plane); Z is stored as f32 (2^-24).
    """
    p = r.precision
    rel = p.depth_relative or 0.0
    edge = p.edge_px or 0.0

    def model(px: ProbePixels) -> ErrorBudget:
        if p.depth_grazing:
            relative = np.minimum(rel / np.maximum(px.cos, 1e-300), MAX_REL) if rel > 0 else np.zeros_like(px.z)
        else:
            relative = np.full(px.z.shape, rel)
        return ErrorBudget(
            px.depth_rel(relative + np.minimum(p.depth_absolute / px.z, MAX_REL) + F32_U) + px.sample(edge * px.pixel),
            f"declared by the user in {r.declared}: depth min({p.depth_absolute:g}, {MAX_REL:g} Z) + {rel:g} Z"
            + (" / |cos|" if p.depth_grazing else "")
            + f", samples within edge_px {edge:g} px of the pixel center; Z stored as f32 (2^-24)",
        )

    return model


def spec(r: Renderer) -> BackendSpec:
    """The declared renderer `r` as a backend: run by its command, judged by its numbers."""
    backend = CommandBackend(r)
    return BackendSpec(
        r.name,
        frozenset(Feature(f) for f in r.features),
        frozenset(Buffer(b) for b in r.buffers),
        depth_model(r),
        calibration=camera_model(r),
        rgb_tolerance=rgb_model(r),
        normals=normal_model(r),
        render=backend.render,
        version=backend.version,
        unavailable_reason=backend.unavailable_reason,
        declared=True,
    )
