"""The rendiff core's own backends (rendered by the Rust side, never by the harness): their specs
carry precision only. raster and trace share one coverage predicate and one depth function, so
they must agree with each other bit for bit; Embree is driven by the core (its buffers are filled
from its hit keys) with float32 ray-triangle tests."""

from __future__ import annotations

from ..contract.vocab import VISIBILITY_FEATURES, Buffer, Feature
from ..judge.camera_budget import core_camera, embree_camera
from ..judge.tolerance import (
    Model,
    core_normals,
    embree_depth,
    embree_edge,
    embree_edge_products,
    embree_plane_move,
    exact_depth,
    exact_rgb,
    f32_origin,
)
from .spec import BackendSpec

_ALL_BUFFERS = frozenset({Buffer.Z, Buffer.ID, Buffer.N, Buffer.RGB})


def _loop(name: str, what: str, other: str) -> BackendSpec:
    """raster or trace: the rendiff loops share visibility and shading code."""
    reason = f"the rendiff {what} shares the coverage predicate with {other}: must be identical"
    return BackendSpec(
        name,
        frozenset(Feature),
        _ALL_BUFFERS,
        Model(name, 0.0, reason, exact_depth),
        calibration=core_camera,
        rgb_tolerance=exact_rgb,
        normals=core_normals,
        core_loop=True,
    )


def _embree(name: str, what: str, robust: bool) -> BackendSpec:
    """Embree (default or ROBUST): float32 ray-triangle tests on rays from the f32 eye; the edge terms
    of its arithmetic differ between the two tests: per pixel (tolerance.embree_edge), per edge (its
    edge functions' products) and per triangle (its copy at the ray origin, for the crack test)
    (judge/embree_products.py)."""

    return BackendSpec(
        name,
        frozenset(VISIBILITY_FEATURES),
        frozenset({Buffer.Z, Buffer.ID, Buffer.N}),
        Model(
            name,
            0.0,
            f'{what}: every term derived (docs/verifier.md, "Embree\'s arithmetic")',
            embree_depth,
            edge_extra=embree_edge(robust),
            position=f32_origin,
            edge_products=embree_edge_products(robust),
            plane_move=embree_plane_move(robust),
        ),
        calibration=embree_camera,
        normals=core_normals,
    )


SPECS = (
    _loop("trace", "tracer", "raster"),
    _loop("raster", "rasterizer", "trace"),
    _embree("embree", "float32 ray-triangle tests (Moeller-Trumbore)", robust=False),
    _embree("embree_robust", "float32 watertight ray-triangle tests (ROBUST, Pluecker)", robust=True),
)
"""The core's backends, in the order the registry lists them."""
