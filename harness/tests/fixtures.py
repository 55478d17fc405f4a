"""Writes small resolved scenes for the harness's own tests, without the Rust core.

The real ones come from `rendiff export`; these let each backend's conversion be
tested in isolation, against closed-form answers.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[2]


def rendiff_binary() -> Path | None:
    """The built `rendiff` (release first), in $CARGO_TARGET_DIR or the checkout's target/; None
    when neither has one (tests that need it skip, saying so). scripts/test.sh builds it first."""
    targets = [Path(t) for t in (os.environ.get("CARGO_TARGET_DIR"),) if t] + [REPO / "target"]
    for target in targets:
        for build in ("release", "debug"):
            p = target / build / "rendiff"
            if p.is_file():
                return p
    return None


def _normalize(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def write_scene(
    directory: Path,
    triangles: Sequence[Sequence[Sequence[float]]],
    object_ids: Sequence[int] | None = None,
    *,
    eye: Sequence[float] = (0.0, 0.0, 5.0),
    look_at: Sequence[float] = (0.0, 0.0, 0.0),
    up: Sequence[float] = (0.0, 1.0, 0.0),
    vfov_deg: float = 45.0,
    width: int = 32,
    height: int = 24,
    near: float = 1e-3,
    far: float | None = None,
    requires: Sequence[str] = ("depth", "ids"),
    name: str = "fixture",
    materials: list[dict[str, Any]] | None = None,
    lights: list[dict[str, Any]] | None = None,
) -> Path:
    """Write DIR/scene.json, triangles.f32, object_ids.u32 in the resolved format."""
    directory.mkdir(parents=True, exist_ok=True)
    tris = np.asarray(triangles, dtype=np.float32).reshape(-1, 3, 3)
    n = tris.shape[0]
    oids = np.zeros(n, dtype=np.uint32) if object_ids is None else np.asarray(object_ids, dtype=np.uint32)
    e, la, u0 = (np.asarray(v, dtype=np.float64) for v in (eye, look_at, up))
    f = _normalize(la - e)
    r = _normalize(np.cross(f, u0))
    u = np.cross(r, f)
    tan_half = 1.0 if vfov_deg == 90.0 else math.tan(math.radians(vfov_deg) / 2.0)
    n_obj = int(oids.max()) + 1 if n else 0
    objects = []
    for o in range(n_obj):
        idx = np.nonzero(oids == o)[0]
        objects.append(
            {
                "name": f"object{o}",
                "material": 0,
                "first_prim": int(idx[0]) if idx.size else 0,
                "prim_count": int(idx.size),
            }
        )
    meta = {
        "format": "rendiff-resolved/1",
        "name": name,
        "source": "fixture",
        "requires": list(requires),
        "camera": {
            "eye": e.tolist(),
            "look_at": la.tolist(),
            "up": u0.tolist(),
            "vfov_deg": vfov_deg,
            "tan_half_vfov": tan_half,
            "width": width,
            "height": height,
            "forward": f.tolist(),
            "right": r.tolist(),
            "up_ortho": u.tolist(),
            "near": near,
            "far": far,
        },
        "triangle_count": n,
        "objects": objects,
        "materials": materials or [{"name": "grey", "albedo": [0.5, 0.5, 0.5], "emission": [0, 0, 0]}],
        "lights": lights or [],
        "files": {"triangles": "triangles.f32", "object_ids": "object_ids.u32"},
    }
    (directory / "scene.json").write_text(json.dumps(meta, indent=1))
    tris.astype("<f4").tofile(directory / "triangles.f32")
    oids.astype("<u4").tofile(directory / "object_ids.u32")
    return directory


def three_triangles(directory: Path) -> Path:
    """The course lesson's three overlapping triangles at different depths."""
    tris = [
        [[-1.5, -1.0, 0.0], [0.5, -1.0, 0.0], [-0.5, 1.2, 0.0]],
        [[-0.5, -1.2, -1.0], [1.5, -1.2, -1.0], [0.5, 1.0, -1.0]],
        [[-1.0, -0.2, 1.0], [1.0, -0.2, 1.0], [0.0, 0.6, 1.0]],
    ]
    return write_scene(directory, tris, [0, 1, 2], name="three_triangles")


# Scene "quads" (W = H = 32, vfov 90, eye (0, 0, 5) looking at -z): at world z = 0,
# px = (x/5 + 1) * 16, py = (1 - y/5) * 16. Two quads share the vertical edge x = 5/32,
# which projects to px = 16.5: every center of column 16 lies exactly on it.
# prims 0, 1: left quad (object 0); 2, 3: right quad (object 1); 4: a triangle in front (z = 1).
QUADS_X = 0.15625
QUADS_TRIS = [
    [[-3, -3, 0], [QUADS_X, -3, 0], [QUADS_X, 3, 0]],
    [[-3, -3, 0], [QUADS_X, 3, 0], [-3, 3, 0]],
    [[QUADS_X, -3, 0], [3, -3, 0], [3, 3, 0]],
    [[QUADS_X, -3, 0], [3, 3, 0], [QUADS_X, 3, 0]],
    [[-1, -1, 1], [1, -1, 1], [0, 1.2, 1]],
]
QUADS_OIDS = [0, 0, 1, 1, 2]


def process_gone(pid: int, limit_s: float) -> bool:
    """True when `pid` has exited (or is a zombie) within `limit_s` (reads Linux's /proc)."""
    end = time.monotonic() + limit_s
    while time.monotonic() < end:
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except FileNotFoundError:
            return True
        if stat.rsplit(")", 1)[1].split()[0] == "Z":
            return True
        time.sleep(0.05)
    return False


def manifest_scene(
    name: str, renders: list[dict[str, Any]], requires: Sequence[str] = ("depth", "ids")
) -> dict[str, Any]:
    """One scene's entry of manifest.json: its resolved scene under `scenes/NAME/resolved`."""
    return {
        "scene": name,
        "scene_file": f"scenes/{name}.toml",
        "resolved": f"scenes/{name}/resolved",
        "requires": list(requires),
        "renders": renders,
    }


def write_manifest(run: Path, scenes: list[dict[str, Any]]) -> dict[str, Any]:
    """Writes RUN/manifest.json (reference: the raster) listing `scenes`; returns it."""
    manifest = {
        "format": "rendiff-manifest/1",
        "reference": "raster",
        "created": "2026-11-25T16:00:00Z",
        "rendiff_version": "0.1.0",
        "scenes": scenes,
    }
    (run / "manifest.json").write_text(json.dumps(manifest))
    return manifest


def cli(*argv: str) -> tuple[int, str, str]:
    """`python -m rendiff_harness ARGV...` in process: its exit code, stdout and stderr."""
    from rendiff_harness.__main__ import main as harness_main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = harness_main(list(argv))
    return rc, out.getvalue(), err.getvalue()
