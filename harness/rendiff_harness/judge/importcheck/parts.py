"""What an independent decoder hands the import check: a mesh file's parts (glTF mesh nodes, OBJ
groups) as f64 triangles in the file's own frame, each triangle with where it came from and the
magnitude its coordinates' rounding errors scale with (docs/verifier.md, "The import verdict")."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...contract.meshfile import MeshFileError

DecodeError = MeshFileError
"""A mesh file an independent decoder cannot read (contract/meshfile.py, shared with the glTF graph)."""


@dataclass
class Part:
    """One part of a mesh file, as one decoder read it: the rendiff object it must equal.

    `tris` (n, 3, 3) float64: the triangles with the file's own transforms applied (glTF: the
    node's world matrix, winding already reversed where it mirrors). `mag` (n, 3, 3): for each
    coordinate, the same transform applied to absolute values (|W| |v|, |W| the product of the
    absolute local matrices), which bounds every f64 rounding error of the chain (docs/verifier.md).
    `ops` bounds the number of roundings any coordinate went through (its gamma factor).
    `prim` (n,) indexes `prims`, the human names of the primitives; `prim_tri` (n,) is the
    triangle's index within its primitive."""

    label: str
    where: str
    tris: np.ndarray
    mag: np.ndarray
    ops: int
    prim: np.ndarray
    prim_tri: np.ndarray
    prims: list[str] = field(default_factory=list)
    input_rel: float = 0.0
    """How far (relative to `mag`) this decoder's input values may lie from rendiff's for the same
    file, before any arithmetic (0: both read the same binary float32)."""


def empty_part(label: str, where: str, ops: int) -> Part:
    """A part without triangles (filled by `extend`)."""
    z3 = np.zeros((0, 3, 3))
    zi = np.zeros(0, dtype=np.int64)
    return Part(label, where, z3, z3.copy(), ops, zi, zi.copy())


def extend(part: Part, name: str, tris: np.ndarray, mag: np.ndarray) -> None:
    """Appends one primitive's triangles (in its own order) to `part` under the name `name`."""
    k = len(part.prims)
    part.prims.append(name)
    n = tris.shape[0]
    part.tris = np.concatenate([part.tris, tris.reshape(n, 3, 3)])
    part.mag = np.concatenate([part.mag, mag.reshape(n, 3, 3)])
    part.prim = np.concatenate([part.prim, np.full(n, k, dtype=np.int64)])
    part.prim_tri = np.concatenate([part.prim_tri, np.arange(n, dtype=np.int64)])
