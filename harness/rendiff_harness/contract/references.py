"""Cached Mitsuba references for Monte Carlo scenes: the format, generated once
(renderers/mitsuba/reference.py), verified on every load (`load`, here).

A path-traced scene has no closed form, so the core's path tracer is compared with a
high-spp Mitsuba `path` render (renderers/mitsuba/backend.py, `global_illumination`:
R,G,B + var.R/G/B, K independent passes). Rendering that at every check would cost
minutes, so it is cached in tests/references/<scene>.exr with its provenance beside it
in <scene>.json:

    python -m rendiff_harness reference --scene RESOLVED_DIR --spp N --seed S \\
        --out tests/references/<scene>.exr

(RESOLVED_DIR from `rendiff export scenes/<scene>.toml -o RESOLVED_DIR`, or a check run's
RUN/scenes/<scene>/resolved.)

Options are checked before anything is rendered (`check_request`, exit 2 with one line naming
the option): --scene a folder; --spp in [2, MAX_SPP]; --seed in [0, MAX_SEED]; --out a path
ending in `.exr` (so that its provenance, the same path ending in `.json`, can never be the
EXR itself), in an existing folder, and neither it nor its provenance a FIFO, device, socket
or folder (atomic.py: outputs replace regular files only).

Provenance (<scene>.json, format "rendiff-reference/1"): mitsuba / drjit versions, the
variant, integrator and max_depth, spp (total and per pass), passes, seed, the exact
command (and the `rendiff export` that made its resolved scene), the resolved scene's
hash, the EXR's own sha256, size and creation time.

Scene hash (`scene_hash`): sha256 over, in this order, for each of scene.json,
triangles.f32 and object_ids.u32: the file name, a NUL byte, the content length as 8
little-endian bytes, the content. scene.json enters in canonical form: parsed, with its
`source` key removed (the path the scene was exported from, which differs between
checkouts and run folders but changes no pixel) and `files.vertex_ids` (the name of
vertex_ids.u32, which is a function of triangles.f32: a reference made before exports wrote
it stays valid), re-serialized with sorted keys and no whitespace. Everything that changes
the rendered image (camera, triangles, ids, materials, lights, integrator, requires) changes
the hash.

`load` refuses, with one ReferenceError whose message says how to regenerate:
a missing EXR or JSON ("missing"), an unreadable or inconsistent pair ("corrupt":
unparsable or too deeply nested JSON, wrong format, EXR checksum differing from the
JSON's, unreadable EXR, missing R,G,B or var channels, either file not a regular file or
larger than its limit, MAX_PROVENANCE_BYTES / MAX_EXR_BYTES), and a reference of another
scene ("reference is stale: regenerate with <command>": the hash or the image size
differs). Files in the references folder are user files (userfile.py): opened without
blocking, regular files only, read within their limit, so that a FIFO or a link to a
device there is one scene's error, never a hang or a run out of memory.
"""

from __future__ import annotations

import hashlib
import json
import os
import shlex
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import atomic, exrbuf, resolved
from .userfile import JsonFileError, UserFileError, read_json, sha256_regular

FORMAT = "rendiff-reference/1"
DEFAULT_SPP = 4096
DEFAULT_SEED = 0
HASHED_FILES = ("scene.json", "triangles.f32", "object_ids.u32")
# Most samples per pixel: 2^16 = 65,536, rendiff's own limit (MAX_SPP in
# crates/rendiff-core/src/scene/mod.rs, 16x the references' 4096), mirrored here.
MAX_SPP = 1 << 16
# Largest seed: 2^31 - 1. It is stored as the EXR's rendiff:seed int attribute, a signed 32-bit
# int (exrbuf), and the pass seeds (seed * passes + k, renderers/mitsuba/backend.py) are taken mod 2^32.
MAX_SEED = 2**31 - 1
EXR_SUFFIX = ".exr"

# Largest <scene>.json read: 64 KiB. A provenance file is about 1 KiB (a dozen short keys
# and two command lines); anything much bigger is not one.
MAX_PROVENANCE_BYTES = 1 << 16
# Largest <scene>.exr read: 64 MiB. The committed references are at most 64x64 (about
# 56 KiB, ZIP-compressed); even 1024x1024 with its six float32 channels is 24 MiB raw.
MAX_EXR_BYTES = 1 << 26


class ReferenceError(Exception):
    """A cached reference that cannot be used; the message names the file and the fix."""


@dataclass
class CachedReference:
    rgb: np.ndarray  # (H, W, 3) float32
    var: np.ndarray  # (H, W, 3) float32: variance of each pixel's mean
    attrs: dict[str, Any]  # the EXR's rendiff:* attributes
    provenance: dict[str, Any]  # <scene>.json
    path: Path


def _canonical_scene_json(data: bytes, where: Path) -> bytes:
    try:
        meta = json.loads(data)
    except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError, an integer of too many digits
        raise ReferenceError(f"{where}: not valid JSON: {exc}") from None
    except RecursionError:
        raise ReferenceError(f"{where}: not valid JSON: nested too deeply") from None
    if isinstance(meta, dict):
        meta.pop("source", None)
        if isinstance(meta.get("files"), dict):
            meta["files"].pop("vertex_ids", None)
    return json.dumps(meta, sort_keys=True, separators=(",", ":")).encode("utf-8")


def scene_hash(scene_dir: str | Path) -> str:
    """sha256 of a resolved scene folder, as the module docstring defines it."""
    scene_dir = Path(scene_dir)
    h = hashlib.sha256()
    for name in HASHED_FILES:
        path = scene_dir / name
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise ReferenceError(f"{path}: cannot read the resolved scene: {exc.strerror or exc}") from None
        if name == "scene.json":
            data = _canonical_scene_json(data, path)
        h.update(name.encode("ascii") + b"\0" + struct.pack("<Q", len(data)) + data)
    return h.hexdigest()


def file_sha256(path: Path, limit: int | None = None) -> str:
    """sha256 of a regular file of at most `limit` bytes (default MAX_EXR_BYTES; UserFileError
    otherwise, OSError from opening)."""
    return sha256_regular(path, MAX_EXR_BYTES if limit is None else limit)


def provenance_path(exr: str | Path) -> Path:
    """<out>.json beside <out>.exr: the EXR's name with its suffix replaced (`check_request` requires
    the `.exr` suffix, so the two never collide)."""
    return Path(exr).with_suffix(".json")


def check_request(scene_dir: str | Path, out: str | Path, spp: int, seed: int) -> str | None:
    """What is wrong with a `reference` request, in one line naming the option; None when it may run.

    Checked before any work (module docstring): nothing is rendered or written for a bad request.
    """
    scene_dir, out = Path(scene_dir), Path(out)
    if not 2 <= spp <= MAX_SPP:
        return f"--spp must be between 2 and {MAX_SPP} (rendiff's MAX_SPP), got {spp}"
    if not 0 <= seed <= MAX_SEED:
        return f"--seed must be between 0 and {MAX_SEED} (it is stored as a 32-bit EXR attribute), got {seed}"
    if not scene_dir.is_dir():
        what = "does not exist" if not os.path.lexists(scene_dir) else "is not a folder"
        return f"--scene {scene_dir}: {what} (expected a resolved scene folder from `rendiff export`)"
    if out.suffix.lower() != EXR_SUFFIX:
        return (
            f"--out {out}: must be a file name ending in {EXR_SUFFIX} (its provenance is written beside it, "
            f"with .json in place of {EXR_SUFFIX}, so the two never collide)"
        )
    if not out.parent.is_dir():
        return f"--out {out}: output folder {out.parent} does not exist"
    for path, role in ((out, "--out"), (provenance_path(out), "--out's provenance")):
        kind = atomic.special_entry(path)
        if kind is not None:
            return f"{role} {path}: {kind}; outputs are written to regular files only: choose another --out"
    return None


def command_line(scene_dir: str | Path, out: str | Path, spp: int, seed: int) -> str:
    """The command that (re)generates a reference, as a copy-pasteable shell line."""
    return " ".join(
        shlex.quote(a)
        for a in (
            "python",
            "-m",
            "rendiff_harness",
            "reference",
            "--scene",
            str(scene_dir),
            "--spp",
            str(spp),
            "--seed",
            str(seed),
            "--out",
            str(out),
        )
    )


def regenerate_command(scene_dir: str | Path, exr: str | Path) -> str:
    """The command for `exr` from `scene_dir`, keeping the spp/seed of the existing provenance if readable."""
    spp, seed = DEFAULT_SPP, DEFAULT_SEED
    try:
        prov = read_json(provenance_path(exr), MAX_PROVENANCE_BYTES)
        if isinstance(prov, dict):
            if isinstance(prov.get("spp_requested"), int) and prov["spp_requested"] > 1:
                spp = int(prov["spp_requested"])
            if isinstance(prov.get("seed"), int) and prov["seed"] >= 0:
                seed = int(prov["seed"])
    except JsonFileError:
        pass
    return command_line(scene_dir, exr, spp, seed)


# --------------------------------------------------------------------------- load


def load(exr: str | Path, scene: resolved.ResolvedScene) -> CachedReference:
    """Load and verify the cached reference for `scene` (module docstring); ReferenceError otherwise."""
    exr = Path(exr)
    js = provenance_path(exr)
    fix = regenerate_command(scene.directory, exr)
    try:
        exr_sum = file_sha256(exr)
    except FileNotFoundError:
        raise ReferenceError(f"{exr}: cached reference missing: generate it with {fix}") from None
    except UserFileError as exc:
        raise ReferenceError(f"{exr}: cached reference corrupt (the EXR {exc}): regenerate with {fix}") from None
    except OSError as exc:
        raise ReferenceError(
            f"{exr}: cached reference corrupt (EXR unreadable: {exc.strerror or exc}): regenerate with {fix}"
        ) from None
    try:
        prov = read_json(js, MAX_PROVENANCE_BYTES)
    except JsonFileError as exc:
        if exc.cause == "missing":
            why = "provenance of the cached reference missing"
        elif exc.cause == "file":
            why = f"cached reference corrupt (the provenance file {exc.detail})"
        else:
            why = f"cached reference corrupt (provenance unreadable: {exc.detail})"
        raise ReferenceError(f"{js}: {why}: regenerate with {fix}") from None
    if not isinstance(prov, dict) or prov.get("format") != FORMAT:
        got = prov.get("format") if isinstance(prov, dict) else prov
        # a short repr for a short value, else its type: the file's content may be large or deeply nested
        shown = (
            repr(got[:80] if isinstance(got, str) else got)
            if isinstance(got, (str, int, float, type(None)))
            else type(got).__name__
        )
        raise ReferenceError(
            f"{js}: cached reference corrupt (format {shown}, expected {FORMAT!r}): regenerate with {fix}"
        )
    want_sum = prov.get("exr_sha256")
    if not isinstance(want_sum, str) or exr_sum != want_sum:
        raise ReferenceError(
            f"{exr}: cached reference corrupt (its sha256 differs from {js.name}'s exr_sha256): regenerate with {fix}"
        )
    digest = scene_hash(scene.directory)
    if prov.get("scene_hash") != digest:
        raise ReferenceError(
            f"{exr}: reference is stale: regenerate with {fix} (it was made for scene hash "
            f"{str(prov.get('scene_hash'))[:12]}..., the resolved scene {scene.directory} hashes to {digest[:12]}...)"
        )
    try:
        bufs = exrbuf.read_buffers(exr, require=("RGB", "var"))
        attrs = dict(exrbuf.read_attrs(exr))
    except exrbuf.BufferError as exc:
        raise ReferenceError(f"{exr}: cached reference corrupt ({exc}): regenerate with {fix}") from None
    shape = (scene.camera.height, scene.camera.width)
    if bufs["RGB"].shape[:2] != shape:
        raise ReferenceError(
            f"{exr}: reference is stale: regenerate with {fix} (it is {bufs['RGB'].shape[1]}x{bufs['RGB'].shape[0]}, "
            f"the scene {shape[1]}x{shape[0]})"
        )
    if attrs.get("scene_hash") not in (None, digest):
        raise ReferenceError(f"{exr}: reference is stale: regenerate with {fix} (its EXR attribute scene_hash differs)")
    if not (np.all(np.isfinite(bufs["RGB"])) and np.all(np.isfinite(bufs["var"])) and np.all(bufs["var"] >= 0)):
        raise ReferenceError(f"{exr}: cached reference corrupt (non-finite or negative values): regenerate with {fix}")
    return CachedReference(bufs["RGB"], bufs["var"], attrs, prov, exr)
