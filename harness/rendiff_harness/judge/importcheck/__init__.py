"""The `import` verdict: rendiff's resolved triangles against an independent decode of the same
mesh files (docs/verifier.md, "The import verdict").

Every renderer reads rendiff's resolved scene, so a wrong import (a sparse accessor, a strip, a
node transform, a mirrored node's winding, an OBJ index) would make every renderer agree on the
wrong scene. Each scene object loaded from a file records where it came from (`objects[].mesh` in
scene.json: the file, the part, the scene object's transform); this package reads the file again
with a decoder rendiff does not use and compares, per object, the two sets of world-space
triangles: counts, object assignment (labels and order of the parts), positions within the derived
rounding bound, winding. One results.json entry per (scene, decoder), buffer `import`, backend the
decoder's name:

* `gltf_spec`: glTF 2.0 written from the specification here (gltf_spec.py);
* `trimesh`: OBJ through trimesh's parser (obj_trimesh.py).

A scene without mesh files has no `import` entry.
"""

from __future__ import annotations

import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path

from ...contract.resolved import ResolvedScene
from ...contract.results import Entry
from ...contract.vocab import Buffer, Status
from . import gltf_spec, obj_trimesh
from .match import Outcome, compare, place
from .parts import DecodeError, Part

DECODERS: dict[str, tuple[str, Callable[[Path], list[Part]]]] = {
    "gltf": ("gltf_spec", gltf_spec.decode),
    "obj": ("trimesh", obj_trimesh.decode),
}
"""The resolved scene's mesh format -> (decoder name in results.json, decoder)."""

TOLERANCE = (
    "per coordinate: half a float32 unit of rendiff's value + 2 gamma_k |M||v| (+ one float32 unit "
    "of |M||v| for OBJ decimal input), docs/verifier.md 'The import verdict'"
)

MAX_PROBLEMS = 3
"""Object problems spelled out in one entry's reason (the count says how many there were)."""


def _groups(scene: ResolvedScene) -> list[list[int]]:
    """Indices of the objects read from one scene object's mesh file, one list per file use
    (a new use starts at part 0)."""
    out: list[list[int]] = []
    for i, obj in enumerate(scene.objects):
        mesh = obj.get("mesh") if isinstance(obj, dict) else None
        if not isinstance(mesh, dict):
            continue
        if mesh.get("part") == 0 or not out:
            out.append([])
        out[-1].append(i)
    return out


def _pairs(
    scene: ResolvedScene, group: list[int], parts: list[Part], fmt: str
) -> tuple[list[tuple[int, Part]], list[str]]:
    """Which decoded part each rendiff object must equal, and the object-assignment problems."""
    names = [str(scene.objects[i].get("name", "")) for i in group]
    problems = []
    if fmt == "obj" and len(parts) == 1 and len(group) == 1:
        return [(group[0], parts[0])], []
    if fmt == "obj":
        pairs = []
        for i, name in zip(group, names, strict=True):
            hits = [p for p in parts if name.endswith("/" + p.label)]
            if len(hits) == 1:
                pairs.append((i, hits[0]))
            else:
                problems.append(f"object {name!r}: {len(hits)} decoded groups carry its group name")
        if len(parts) != len(group):
            problems.append(
                f"rendiff made {len(group)} objects of the file, the decoder found {len(parts)} groups with faces"
            )
        return pairs, problems
    if len(parts) != len(group):
        problems.append(f"rendiff made {len(group)} objects of the file, the decoder found {len(parts)} mesh nodes")
    pairs = []
    for i, name, part in zip(group, names, parts, strict=False):
        if not name.endswith("/" + part.label):
            problems.append(
                f"object {name!r} is the decoder's mesh node {part.label!r} ({part.where}): wrong assignment"
            )
        pairs.append((i, part))
    return pairs, problems


def _judge(scene: ResolvedScene, fmt: str, decoder: str, decode: Callable[[Path], list[Part]]) -> Entry | None:
    """The entry of one decoder over the scene's objects of format `fmt`; None when there are none."""
    groups = [g for g in _groups(scene) if scene.objects[g[0]]["mesh"].get("format") == fmt]
    if not groups:
        return None
    t0 = time.monotonic()
    e = Entry(scene.name, decoder, Buffer.IMPORT, status=Status.ERROR, tolerance=TOLERANCE)
    problems: list[str] = []
    notes: list[str] = []
    outcomes: list[Outcome] = []
    cache: dict[str, list[Part]] = {}
    try:
        for group in groups:
            mesh = scene.objects[group[0]]["mesh"]
            file = str(mesh.get("file", ""))
            if file not in cache:
                cache[file] = decode(Path(file))
            pairs, assignment = _pairs(scene, group, cache[file], fmt)
            problems += assignment
            for i, part in pairs:
                obj = scene.objects[i]
                first, count = int(obj["first_prim"]), int(obj["prim_count"])
                placed = place(part, scene.objects[i]["mesh"].get("transform"))
                out = compare(str(obj["name"]), first, scene.triangles[first : first + count], placed, decoder)
                outcomes.append(out)
                if out.problem:
                    problems.append(out.problem)
                if out.note:
                    notes.append(out.note)
    except DecodeError as exc:
        e.reason = f"{decoder} cannot decode the file: {exc}"
        return e
    except Exception as exc:  # noqa: BLE001 - a bug must not lose the other results
        traceback.print_exc(file=sys.stderr)
        e.reason = f"internal error in the import check (a rendiff bug): {type(exc).__name__}: {exc}"
        return e
    e.time_s = time.monotonic() - t0
    e.max_abs_error = max((o.max_error for o in outcomes), default=0.0)
    e.bound = max((o.bound for o in outcomes), default=0.0)
    compared = sum(o.compared for o in outcomes)
    e.extra = {"triangles": compared, "objects": len(outcomes)}
    e.interior_mismatches = sum(1 for o in outcomes if not o.ok) + (
        len(problems) - sum(1 for o in outcomes if o.problem)
    )
    shown = "; ".join(problems[:MAX_PROBLEMS]) + (
        f"; and {len(problems) - MAX_PROBLEMS} more" if len(problems) > MAX_PROBLEMS else ""
    )
    if problems:
        e.status = Status.FAIL
        e.reason = f"rendiff's import departs from {decoder}'s reading of the file ({_who(decoder)}): {shown}"
    else:
        e.status = Status.PASS
        e.reason = f"{len(outcomes)} objects, {compared} triangles as {decoder} reads them" + (
            "; " + "; ".join(notes) if notes else ""
        )
    return e


def _who(decoder: str) -> str:
    """Which side departs from the format's rules, where that can be decided."""
    if decoder == "gltf_spec":
        return "this decoder is written from the glTF 2.0 specification: rendiff departs from it"
    return "rendiff (tobj) and trimesh disagree; the OBJ format does not decide alone: check the named face"


def import_entries(scene: ResolvedScene) -> list[Entry]:
    """The scene's `import` entries, one per decoder with objects to check (none for a scene of
    generated shapes)."""
    out = []
    for fmt, (decoder, decode) in DECODERS.items():
        entry = _judge(scene, fmt, decoder, decode)
        if entry is not None:
            out.append(entry)
    return out
