"""One scene of a run: every backend's render against the reference, buffer by buffer, and the
cached Monte Carlo reference where the scene has one."""

from __future__ import annotations

import re
import sys
import traceback
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..contract import references, vocab
from ..contract.manifest import (
    EntryError,
    Reference,
    declared_buffers,
    load_reference,
    read_test_buffers,
    render_reason,
)
from ..contract.results import Entry
from ..contract.vocab import Buffer, Status
from ..renderers.spec import BackendSpec, SpecLookup
from . import expectations, importcheck, precision, radiance, tolerance
from .buffers import (
    BUFFER_FIELDS,
    BUFFER_TABLE,
    BUFFERS,
    SHADED_BUFFERS,
    BackendRender,
    applies,
    compare_buffer,
    finish,
    is_shaded,
)
from .normals import compare_normals
from .rgb import RGB_ENTRY_FIELDS, compare_rgb, record_rgb

_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+-]*$")
"""Scene and backend names that may name a diff folder and file."""


def compare_backend(
    run: Path,
    scene_name: str,
    render: Mapping[str, Any],
    ref: Reference,
    exps: expectations.Expectations,
    images: bool,
    spec: BackendSpec | None,
) -> list[Entry]:
    """The entries of one ok render of one backend: one per applicable row of BUFFER_TABLE."""
    backend = render["backend"]
    model = precision.depth_model(spec, backend)
    got = read_test_buffers(run, render, ref)
    diff_dir = None
    if images and _SAFE_NAME.match(scene_name) and _SAFE_NAME.match(backend):
        diff_dir = run / "scenes" / scene_name / "diff"
    r = BackendRender(
        run,
        scene_name,
        backend,
        render,
        ref,
        got.buffers,
        got.attrs,
        got.exr,
        model,
        spec,
        declared_buffers(render),
        diff_dir,
    )
    return [compare_buffer(spec, r, exps) for spec in BUFFER_TABLE if applies(spec, r)]


def buffers_for(scene_entry: Mapping[str, Any]) -> tuple[str, ...]:
    return SHADED_BUFFERS if is_shaded(scene_entry.get("requires")) else BUFFERS


def status_entries(
    scene: str, render: Mapping[str, Any], status: str, reason: str, buffers: Sequence[str] = BUFFERS
) -> list[Entry]:
    """A render that was not compared: one entry per buffer, each with its status and reason."""
    backend = str(render.get("backend", "?"))
    return [
        Entry.for_render(scene, backend, buf, render, BUFFER_FIELDS.get(buf, ()), status=status, reason=reason)
        for buf in buffers
    ]


# --------------------------------------------------------------------------- one scene


def compare_scene(
    run: Path,
    scene_entry: Mapping[str, Any],
    reference: str,
    exps: expectations.Expectations,
    specs: SpecLookup,
    images: bool = True,
    references_dir: Path | None = None,
) -> list[Entry]:
    """Every entry of one scene; each backend judged with its spec (`specs`)."""
    name = scene_entry["scene"]
    renders = [r for r in scene_entry.get("renders", []) if r.get("backend") != reference]
    bufs = buffers_for(scene_entry)
    try:
        ref = load_reference(run, scene_entry, reference)
    except EntryError as exc:
        out = []
        own_ref = [r for r in scene_entry.get("renders", []) if r.get("backend") == reference]
        if not renders or (own_ref and own_ref[0].get("status") == vocab.RenderStatus.ERROR):
            # The scene itself failed (it could not be loaded, or the reference could not
            # render it): one `scene` entry, so a broken scene can never look like a pass.
            out.append(Entry.for_render(name, reference, Buffer.SCENE, own_ref[0] if own_ref else {}, reason=str(exc)))
        for r in renders:
            own = (
                ""
                if r.get("status") == vocab.RenderStatus.OK
                else f" ({r['backend']} itself {r.get('status')}: {render_reason(r)})"
            )
            out += status_entries(name, r, Status.ERROR, f"{exc}{own}", bufs)
        return [e.blank_if_not_compared() for e in out]
    if is_shaded(ref.scene.requires):
        bufs = SHADED_BUFFERS
    results: list[Entry] = []
    if "N" in ref.buffers:  # the reference's own normals, against the winding convention
        own = [r for r in scene_entry.get("renders", []) if r.get("backend") == reference][0]
        results.append(compare_normals(name, reference, own, ref, ref.buffers, exps, specs(reference)))
    for r in renders:
        status = r.get("status")
        if status in (vocab.RenderStatus.SKIPPED, vocab.RenderStatus.ERROR):
            results += status_entries(name, r, status, render_reason(r), bufs)
            continue
        try:
            results += compare_backend(run, name, r, ref, exps, images, specs(r["backend"]))
        except EntryError as exc:
            results += status_entries(name, r, Status.ERROR, str(exc), bufs)
        except Exception as exc:  # noqa: BLE001 - a bug must not lose the other results
            traceback.print_exc(file=sys.stderr)
            results += status_entries(
                name, r, Status.ERROR, f"internal error in compare (a rendiff bug): {type(exc).__name__}: {exc}", bufs
            )
    if references_dir is not None and vocab.Feature.GLOBAL_ILLUMINATION in ref.scene.requires:
        results.append(compare_cached_reference(run, name, ref, references_dir, exps, images, specs))
    results += importcheck.import_entries(ref.scene, name)  # the resolved triangles against a second decoder
    return [e.blank_if_not_compared() for e in results]


def compare_cached_reference(
    run: Path,
    name: str,
    ref: Reference,
    references_dir: Path,
    exps: expectations.Expectations,
    images: bool,
    specs: SpecLookup,
) -> Entry:
    """The reference render's RGB against the cached Mitsuba reference DIR/<name>.exr (references.py)."""
    exr = references_dir / f"{name}.exr"
    render = {
        "backend": vocab.CACHED_REFERENCE_BACKEND,
        "command": references.regenerate_command(ref.scene.directory, exr),
    }
    e = Entry.for_render(name, vocab.CACHED_REFERENCE_BACKEND, Buffer.RGB, render, RGB_ENTRY_FIELDS)
    e.pixels = ref.pixels
    try:
        cached = references.load(exr, ref.scene)
    except references.ReferenceError as exc:
        e.reason = str(exc)
        return e
    e.version = cached.provenance.get("renderer")
    if "RGB" not in ref.buffers:
        e.reason = "reference has no R,G,B channels (the scene requires shading)"
        return e
    test = {"RGB": cached.rgb, "var": cached.var}
    try:
        res = compare_rgb(
            ref, test, cached.attrs, vocab.CACHED_REFERENCE_BACKEND, render, None, specs(vocab.CACHED_REFERENCE_BACKEND)
        )
    except (tolerance.ToleranceError, radiance.RadianceError) as exc:
        e.reason = str(exc)
        return e
    judged = record_rgb(e, res, ref.buffers["RGB"], cached.rgb)
    diff_dir = run / "scenes" / name / "diff" if images and _SAFE_NAME.match(name) else None
    finish(e, judged, exps, run, diff_dir)
    return e
