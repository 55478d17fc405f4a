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
* `trimesh`: OBJ through trimesh's parser (obj_trimesh.py), and glTF through trimesh's loader
  (gltf_trimesh.py), its known departures from the specification declared with their reasons.

A scene without mesh files has no `import` entry.
"""

from __future__ import annotations

import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path

from ...contract.meshfile import file_uses
from ...contract.resolved import ResolvedScene
from ...contract.results import Entry
from ...contract.vocab import IMPORT_DECODERS, Buffer, Status
from . import gltf_spec, gltf_trimesh, obj_trimesh
from .match import Outcome, compare, place
from .parts import DecodeError, Part

Decoded = tuple[list[Part | None], list[str]]
"""A file's parts as one decoder reads them (None: not comparable, a declared decoder bug) and notes."""


Decoder = Callable[[Path, int | None], Decoded]
"""Reads a mesh file (and, for glTF, the glTF scene rendiff showed: `objects[].mesh.gltf_scene`)."""


def _spec(path: Path, chosen: int | None) -> Decoded:
    return list(gltf_spec.decode(path, chosen)), []


def _obj(path: Path, chosen: int | None) -> Decoded:
    return list(obj_trimesh.decode(path)), []


SPEC, TRIMESH = IMPORT_DECODERS
DECODERS: dict[str, dict[str, Decoder]] = {
    SPEC: {"gltf": _spec},
    TRIMESH: {"obj": _obj, "gltf": gltf_trimesh.decode},
}
"""Decoder name in results.json -> the resolved scene's mesh formats it reads."""

VERDICT = {
    ("gltf_spec", "gltf"): "gltf_spec follows the glTF 2.0 specification: rendiff departs from it",
    ("trimesh", "obj"): "tobj (rendiff) and trimesh disagree; the face named decides by the OBJ rules",
}
"""Who departs from the format's rules when rendiff and the decoder disagree (trimesh's glTF:
decided per object against gltf_spec)."""

TOLERANCE = (
    "per coordinate: half a float32 unit of rendiff's value + 2 gamma_k |M||v| (+ one float32 unit "
    "of |M||v| for OBJ decimal input), docs/verifier.md 'The import verdict'"
)

MAX_PROBLEMS = 3
"""Object problems spelled out in one entry's reason (the count says how many there were)."""


def _pairs(
    scene: ResolvedScene, group: list[int], parts: list[Part | None], fmt: str
) -> tuple[list[tuple[int, Part | None]], list[str]]:
    """Which decoded part each rendiff object must equal, and the object-assignment problems."""
    names = [str(scene.objects[i].get("name", "")) for i in group]
    problems: list[str] = []
    pairs: list[tuple[int, Part | None]] = []
    if fmt == "obj" and len(parts) == 1 and len(group) == 1:
        return [(group[0], parts[0])], []
    if fmt == "obj":
        for i, name in zip(group, names, strict=True):
            hits = [p for p in parts if p is not None and name.endswith("/" + p.label)]
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
        problems.append(
            f"rendiff made {len(group)} objects of the file, the decoder found {len(parts)} mesh nodes and instances"
        )
    for i, name, part in zip(group, names, parts, strict=False):
        if part is not None and not name.endswith("/" + part.label):
            problems.append(
                f"object {name!r} is the decoder's mesh node or instance {part.label!r} ({part.where}): "
                "wrong assignment"
            )
        pairs.append((i, part))
    return pairs, problems


def _chosen(mesh: dict[str, object]) -> int | None:
    """The glTF scene the object shows (None: an export that did not record it, the file's default)."""
    chosen = mesh.get("gltf_scene")
    return chosen if isinstance(chosen, int) and not isinstance(chosen, bool) else None


def _judge(scene: ResolvedScene, name: str, decoder: str, formats: dict[str, Decoder]) -> Entry | None:
    """The entry of one decoder over the scene's objects of the formats it reads; None when there are none."""
    groups = [g for g in file_uses(scene) if scene.objects[g[0]]["mesh"].get("format") in formats]
    if not groups:
        return None
    t0 = time.monotonic()
    e = Entry(name, decoder, Buffer.IMPORT, status=Status.ERROR, tolerance=TOLERANCE)
    problems: list[str] = []
    notes: list[str] = []
    outcomes: list[Outcome] = []
    cache: dict[tuple[str, str, int | None], Decoded] = {}
    try:
        for group in groups:
            mesh = scene.objects[group[0]]["mesh"]
            file, fmt, chosen = str(mesh.get("file", "")), str(mesh.get("format")), _chosen(mesh)
            if (file, fmt, chosen) not in cache:
                cache[file, fmt, chosen] = formats[fmt](Path(file), chosen)
                notes += cache[file, fmt, chosen][1]
            pairs, assignment = _pairs(scene, group, cache[file, fmt, chosen][0], fmt)
            problems += assignment
            for i, part in pairs:
                if part is None:
                    continue
                out = _object(scene, i, part, decoder)
                outcomes.append(out)
                if out.problem:
                    problems.append(f"{out.problem} ({_who(scene, i, decoder, fmt, file)})")
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
    e.interior_mismatches = len(problems)
    shown = "; ".join(problems[:MAX_PROBLEMS]) + (
        f"; and {len(problems) - MAX_PROBLEMS} more" if len(problems) > MAX_PROBLEMS else ""
    )
    if not problems and not outcomes:
        e.status = Status.SKIPPED
        e.reason = "nothing compared: " + "; ".join(notes)
    elif problems:
        e.status = Status.FAIL
        e.reason = f"rendiff's import departs from {decoder}'s reading of the file: {shown}"
    else:
        e.status = Status.PASS
        e.reason = f"{len(outcomes)} objects, {compared} triangles as {decoder} reads them" + (
            "; " + "; ".join(notes) if notes else ""
        )
    return e


def _object(scene: ResolvedScene, i: int, part: Part, decoder: str) -> Outcome:
    """Object `i`'s resolved triangles against `part` placed by the object's transform."""
    obj = scene.objects[i]
    first, count = int(obj["first_prim"]), int(obj["prim_count"])
    placed = place(part, obj["mesh"].get("transform"))
    return compare(str(obj["name"]), first, scene.triangles[first : first + count], placed, decoder)


def _who(scene: ResolvedScene, i: int, decoder: str, fmt: str, file: str) -> str:
    """Which side departs from the format's rules, where that can be decided."""
    if (decoder, fmt) in VERDICT:
        return VERDICT[decoder, fmt]
    mesh = scene.objects[i]["mesh"]
    part = mesh.get("part")
    spec = gltf_spec.decode(Path(file), _chosen(mesh))
    if not isinstance(part, int) or not 0 <= part < len(spec):
        return "gltf_spec has no such mesh node either"
    if _object(scene, i, spec[part], "gltf_spec").ok:
        return (
            "gltf_spec, written from the specification, agrees with rendiff: trimesh departs from it; "
            "declare it in contract/gltfgraph.TRIMESH_GAPS with its reason"
        )
    return "gltf_spec disagrees with rendiff too: rendiff departs from the specification"


def import_entries(scene: ResolvedScene, name: str | None = None) -> list[Entry]:
    """The scene's `import` entries under `name` (the run's scene name; default the resolved scene's),
    one per decoder with objects to check (none for a scene of generated shapes)."""
    out = []
    for decoder, formats in DECODERS.items():
        entry = _judge(scene, scene.name if name is None else name, decoder, formats)
        if entry is not None:
            out.append(entry)
    return out


def main(argv: list[str]) -> int:
    """`python -m rendiff_harness import DIR`: the import entries of the resolved scene in DIR, one line
    each; exit 0 when none fails, 1 when one fails or errs, 2 when DIR cannot be read."""
    from ...contract import resolved
    from ...contract.text import printable

    if len(argv) != 1:
        print("usage: python -m rendiff_harness import RESOLVED_DIR", file=sys.stderr)
        return 2
    try:
        scene = resolved.load(argv[0])
    except resolved.SceneError as exc:
        print(f"rendiff_harness import: {printable(str(exc))}", file=sys.stderr)
        return 2
    entries = import_entries(scene)
    for e in entries:
        print(printable(f"{e.scene} {e.backend} {e.buffer} {e.status}: {e.reason}"))
    return 1 if any(e.status in (Status.FAIL, Status.ERROR) for e in entries) else 0
