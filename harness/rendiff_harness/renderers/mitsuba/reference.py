"""`python -m rendiff_harness reference`: render a cached Mitsuba reference with its provenance.

The format, the scene hash, the request checks and `load` are contract/references.py's (its
docstring has the whole story); this module only renders one, with Mitsuba's `path` integrator.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from ...contract import atomic, exrbuf, resolved
from ...contract.references import (
    DEFAULT_SEED,
    DEFAULT_SPP,
    FORMAT,
    MAX_SEED,
    MAX_SPP,
    ReferenceError,
    check_request,
    command_line,
    file_sha256,
    provenance_path,
    scene_hash,
)
from ...contract.userfile import UserFileError
from ...contract.vocab import CACHED_REFERENCE_BACKEND, RenderStatus
from ..errors import BackendError
from . import backend as mb

# --------------------------------------------------------------------------- generate


def _write_json_atomically(path: Path, doc: dict[str, Any]) -> None:
    atomic.write_text_atomically(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")


def generate(
    scene_dir: str | Path, out: str | Path, spp: int = DEFAULT_SPP, seed: int = DEFAULT_SEED
) -> dict[str, Any]:
    """Render the reference with Mitsuba `path` and write <out> (EXR) and its <.json>; returns the provenance."""
    scene_dir, out = Path(scene_dir), Path(out)
    problem = check_request(scene_dir, out, spp, seed)
    if problem is not None:
        raise ReferenceError(problem)
    scene = resolved.load(scene_dir)
    if "global_illumination" not in scene.requires:
        raise ReferenceError(
            f"{scene_dir}: the scene does not require global_illumination; cached references are for "
            "path-traced scenes (local shading is compared deterministically)"
        )
    missing = sorted(scene.requires - mb.FEATURES)
    if missing:
        raise ReferenceError(f"{scene_dir}: mitsuba cannot model {', '.join(missing)}")
    digest = scene_hash(scene_dir)
    t0 = time.monotonic()
    rgb, var, info = mb.render_radiance(scene, spp=spp, seed=seed)
    seconds = time.monotonic() - t0
    assert var is not None
    version = mb.version()
    attrs: dict[str, str | float | int] = {
        "backend": CACHED_REFERENCE_BACKEND,
        "integrator": "path",
        "spp": int(info["spp"]),
        "seed": int(seed),
        "passes": int(info["passes"]),
        "var_samples": int(info["var_samples"]),
        "scene_hash": digest,
        "renderer": version,
        "rgb_encoding": "float32",
    }
    exrbuf.write_buffers(out, RGB=rgb.astype(np.float32), var=var.astype(np.float32), attrs=attrs)
    try:
        exr_sum = file_sha256(out)
    except UserFileError as exc:  # past MAX_EXR_BYTES: `load` would refuse it
        raise ReferenceError(f"{out}: the written reference {exc} (MAX_EXR_BYTES): render a smaller image") from None
    import drjit
    import mitsuba

    prov: dict[str, Any] = {
        "format": FORMAT,
        "scene": scene.name,
        "source": scene.source,
        "scene_hash": digest,
        "hash_method": "sha256 over scene.json (canonical, without 'source'), triangles.f32, object_ids.u32: "
        "name NUL len(u64 le) bytes each",
        "renderer": version,
        "mitsuba": getattr(mitsuba, "__version__", "?"),
        "drjit": getattr(drjit, "__version__", "?"),
        "variant": mitsuba.variant(),
        "integrator": "path",
        "max_depth": int(info["max_depth"]),
        "spp": int(info["spp"]),
        "spp_requested": int(spp),
        "spp_per_pass": int(info["spp_per_pass"]),
        "passes": int(info["passes"]),
        "seed": int(seed),
        "width": scene.camera.width,
        "height": scene.camera.height,
        "command": command_line(scene_dir, out, spp, seed),
        "export_command": (
            f"rendiff export {shlex.quote(scene.source)} -o {shlex.quote(str(scene_dir))}"
            if scene.source.endswith(".toml")
            else None
        ),
        "python": sys.version.split()[0],
        "created": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "render_seconds": round(seconds, 3),
        "exr_sha256": exr_sum,
    }
    _write_json_atomically(provenance_path(out), prov)
    for path in (out, provenance_path(out)):  # files meant for the repository: readable by all
        os.chmod(path, 0o644)
    return prov


# --------------------------------------------------------------------------- CLI


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(
        prog="python -m rendiff_harness reference",
        description="Render a high-spp Mitsuba path-traced reference (R,G,B + var) with provenance.",
    )
    p.add_argument("--scene", required=True, help="resolved scene folder (rendiff export)")
    p.add_argument(
        "--spp", type=int, default=DEFAULT_SPP, help=f"samples per pixel, 2 to {MAX_SPP} (default {DEFAULT_SPP})"
    )
    p.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"seed, 0 to {MAX_SEED} (default {DEFAULT_SEED})")
    p.add_argument(
        "--out",
        required=True,
        help="output EXR, ending in .exr (tests/references/<scene>.exr); its provenance is written beside it "
        "with .json in place of .exr (tests/references/<scene>.json)",
    )
    args = p.parse_args(argv)
    problem = check_request(args.scene, args.out, args.spp, args.seed)
    if problem is not None:
        print(f"rendiff_harness reference: {problem}", file=sys.stderr)
        return 2
    try:
        prov = generate(args.scene, args.out, args.spp, args.seed)
    except (ReferenceError, resolved.SceneError, BackendError, exrbuf.BufferError) as exc:
        print(f"rendiff_harness reference: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # writing the provenance (atomic.OutputError included)
        print(
            f"rendiff_harness reference: {exc.filename or args.out}: cannot write: {exc.strerror or exc}",
            file=sys.stderr,
        )
        return 2
    print(
        json.dumps(
            {
                "status": RenderStatus.OK,
                "out": str(args.out),
                "provenance": str(provenance_path(args.out)),
                "spp": prov["spp"],
                "seconds": prov["render_seconds"],
                "renderer": prov["renderer"],
            }
        )
    )
    return 0
