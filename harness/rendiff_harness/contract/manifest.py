"""A `rendiff check` run folder as the comparison reads it: RUN/manifest.json and the buffer EXRs.

RUN/manifest.json (docs/run-format.md) lists every scene with its resolved scene.json and
every backend's render of it (status, EXR, time, version, command, info). This module
validates it (`load_manifest`), turns its paths into real ones that never leave RUN
(`run_path`), and loads a scene's reference render (`load_reference`) and a backend's
buffers (`read_test_buffers`), checking every buffer against the scene's camera.

ManifestError: the manifest cannot be used at all (compare exits 2, naming the file).
EntryError: one scene/backend cannot be compared (its entries become `error` with the reason).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import exrbuf, resolved, vocab
from .userfile import JsonFileError, read_record

MANIFEST_FORMAT = vocab.MANIFEST_FORMAT
# Largest manifest.json read: Rust's limit on run records (`check::manifest::MAX_RECORD_BYTES`).
MAX_MANIFEST_BYTES = 256 << 20
RENDER_STATUSES = tuple(vocab.RenderStatus)


class ManifestError(Exception):
    """manifest.json cannot be used at all; the message names the file."""


class EntryError(Exception):
    """One scene/backend cannot be compared; becomes `error` entries with this reason."""


def load_manifest(run: Path) -> dict[str, Any]:
    """Read and structurally validate RUN/manifest.json; ManifestError names the file."""
    path = run / "manifest.json"
    try:
        data = read_record(path, MAX_MANIFEST_BYTES, MANIFEST_FORMAT, " (run `rendiff check` first)")
    except JsonFileError as exc:
        raise ManifestError(str(exc)) from None
    reference = data.get("reference", "raster")
    if not isinstance(reference, str) or not reference:
        raise ManifestError(f"{path}: 'reference' must be a backend name, got {reference!r}")
    scenes = data.get("scenes")
    if not isinstance(scenes, list):
        raise ManifestError(f"{path}: 'scenes' must be a list")
    for i, sc in enumerate(scenes):
        if not isinstance(sc, dict) or not isinstance(sc.get("scene"), str) or not sc["scene"]:
            raise ManifestError(f"{path}: scenes[{i}] must be an object with a 'scene' name")
        renders = sc.get("renders", [])
        if not isinstance(renders, list):
            raise ManifestError(f"{path}: scenes[{i}] ({sc['scene']}): 'renders' must be a list")
        for j, r in enumerate(renders):
            if not isinstance(r, dict) or not isinstance(r.get("backend"), str) or not r["backend"]:
                raise ManifestError(
                    f"{path}: scenes[{i}] ({sc['scene']}).renders[{j}] must be an object with a 'backend' name"
                )
            if r.get("status") not in RENDER_STATUSES:
                raise ManifestError(
                    f"{path}: scenes[{i}] ({sc['scene']}).renders[{j}] ({r['backend']}): "
                    f"status must be ok, skipped or error, got {r.get('status')!r}"
                )
    return data


def run_path(run: Path, rel: Any, what: str) -> Path:
    """A manifest path (relative to RUN, never escaping it) as a real path; EntryError if bad."""
    if not isinstance(rel, str) or not rel:
        raise EntryError(f"{what}: no path in manifest.json")
    p = Path(rel)
    if p.is_absolute() or ".." in p.parts:
        raise EntryError(f"{what}: path {rel!r} in manifest.json must be relative to the run folder")
    return run / p


def render_reason(render: Mapping[str, Any]) -> str:
    """Why a render is skipped or errored, as the manifest says (or a placeholder)."""
    if render.get("status") == vocab.RenderStatus.SKIPPED:
        return str(render.get("reason") or "skipped (no reason given)")
    return str(render.get("message") or render.get("reason") or "error (no message given)")


def render_info(render: Mapping[str, Any]) -> Mapping[str, Any]:
    """The render's `info` object (what the backend reported), or {}."""
    info = render.get("info")
    return info if isinstance(info, dict) else {}


def declared_buffers(render: Mapping[str, Any]) -> set[str] | None:
    """The buffers the manifest says the render wrote (None: it does not say)."""
    b = render.get("buffers")
    if isinstance(b, list) and all(isinstance(x, str) for x in b):
        return set(b)
    return None


# --------------------------------------------------------------------------- reference data


@dataclass
class Reference:
    scene: resolved.ResolvedScene
    buffers: dict[str, np.ndarray]
    shape: tuple[int, int]
    _normals: np.ndarray | None = field(default=None, repr=False)
    attrs: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None
    topology_cache: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def pixels(self) -> int:
        """Pixels in the image (width x height)."""
        return self.shape[0] * self.shape[1]

    def unit_normals(self) -> np.ndarray:
        """(N, 3) float64 unit normals of every triangle (zero for degenerate ones)."""
        if self._normals is None:
            self._normals = _unit_normals(self.scene.triangles)
        return self._normals

    def ray_cos(self, rows: np.ndarray, cols: np.ndarray, prims: np.ndarray) -> np.ndarray:
        """|cos| between the pixel rays and the triangles' normals, (K,) float64 in [0, 1].

        Only the K named triangles' normals are computed (row by row the same numbers as
        `unit_normals`): a 1.31M-triangle scene's whole table cost 0.1-0.3 s a call.
        """
        d = self.scene.camera.center_directions(rows, cols)
        n = (
            self._normals[prims.astype(np.int64)]
            if self._normals is not None
            else _unit_normals(self.scene.triangles[prims.astype(np.int64)])
        )
        cos: np.ndarray = np.clip(np.abs(np.einsum("ij,ij->i", d, n)) / np.linalg.norm(d, axis=1), 0.0, 1.0)
        return cos


def _unit_normals(tris: np.ndarray) -> np.ndarray:
    """(N, 3) float64 unit normals of (N, 3, 3) triangles (zero for degenerate ones), row by row."""
    t = tris.astype(np.float64)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    length = np.linalg.norm(n, axis=1)
    with np.errstate(all="ignore"):
        out: np.ndarray = np.where(length[:, None] > 0, n / np.where(length > 0, length, 1.0)[:, None], 0.0)
    return out


def load_reference(run: Path, scene_entry: Mapping[str, Any], reference: str) -> Reference:
    """Resolved scene + reference buffers for one scene; EntryError with the reason otherwise."""
    name = scene_entry["scene"]
    refs = [r for r in scene_entry.get("renders", []) if r.get("backend") == reference]
    if not refs:
        raise EntryError(f"reference {reference} has no render for scene {name} in manifest.json")
    ref = refs[0]
    if ref.get("status") != vocab.RenderStatus.OK:
        raise EntryError(f"reference {reference} {ref.get('status')}: {render_reason(ref)}")
    try:
        scene = resolved.load(run_path(run, scene_entry.get("resolved"), "resolved scene"))
    except EntryError:
        raise
    except Exception as exc:  # noqa: BLE001 - SceneError or a malformed scene.json
        raise EntryError(f"cannot load the resolved scene: {type(exc).__name__}: {exc}") from None
    exr = run_path(run, ref.get("exr"), f"reference {reference} EXR")
    try:
        buffers, attrs = exrbuf.read_render(exr)
    except exrbuf.BufferError as exc:
        raise EntryError(f"reference {reference} unreadable: {exc}") from None
    cam = scene.camera
    shape = (cam.height, cam.width)
    for key, arr in buffers.items():
        if arr.shape[:2] != shape:
            raise EntryError(
                f"reference {reference} {exr}: {key} is {arr.shape[1]}x{arr.shape[0]}, "
                f"the scene's camera is {cam.width}x{cam.height}"
            )
    return Reference(scene, buffers, shape, attrs=attrs, path=exr)


@dataclass(frozen=True)
class BackendBuffers:
    """One backend's render as read from its EXR: the buffers and the rendiff attributes."""

    exr: Path
    buffers: dict[str, np.ndarray]
    attrs: Mapping[str, Any]


def read_test_buffers(run: Path, render: Mapping[str, Any], ref: Reference) -> BackendBuffers:
    """A backend's buffers and attributes, each buffer the reference's size; EntryError otherwise."""
    backend = render["backend"]
    exr = run_path(run, render.get("exr"), f"{backend} EXR")
    try:
        test, attrs = exrbuf.read_render(exr)
    except exrbuf.BufferError as exc:
        raise EntryError(f"{backend} buffers unreadable: {exc}") from None
    for key, arr in test.items():
        if arr.shape[:2] != ref.shape:
            raise EntryError(
                f"{exr}: {key} is {arr.shape[1]}x{arr.shape[0]}, the reference is {ref.shape[1]}x{ref.shape[0]}"
            )
    return BackendBuffers(exr, test, attrs)
