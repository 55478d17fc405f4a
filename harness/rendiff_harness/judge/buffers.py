"""The buffer table: per buffer, when it applies, which function compares it and which fields its
entry has (`BUFFER_TABLE`), and how one buffer of one render becomes its entry (`compare_buffer`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from ..contract import vocab
from ..contract.manifest import Reference
from ..contract.results import Entry, finite
from ..contract.vocab import Buffer, Status
from ..renderers.spec import BackendSpec
from . import diffimages, expectations, radiance, tolerance
from .depth import compare_depth, depth_tolerance_fn
from .ids import IdResult, compare_ids
from .normals import N_FIELDS, judge_normals
from .rgb import RGB_ENTRY_FIELDS, compare_rgb, explain_rgb, record_rgb
from .verdict import Judged


def is_shaded(requires: Any) -> bool:
    """A scene whose buffers include radiance (docs/radiance.md)."""
    return isinstance(requires, (list, tuple, set, frozenset)) and vocab.needs_shading(requires)


@dataclass
class BackendRender:
    """One ok render of one backend, read and ready to compare buffer by buffer."""

    run: Path
    scene: str
    backend: str
    render: Mapping[str, Any]
    ref: Reference
    test: Mapping[str, np.ndarray]
    attrs: Mapping[str, Any]
    exr: Path
    model: tolerance.Model
    spec: BackendSpec | None  # its precision (None: it has none, and is compared exactly)
    declared: set[str] | None  # the buffers the manifest says it wrote (None: it does not say)
    diff_dir: Path | None  # where heat maps go (None: none are written)
    id_result: IdResult | None = None  # the id comparison, once done (Z and RGB use its classes)


Judge = Callable[[BackendRender, Entry], Judged | None]
"""Compares one buffer of a render and fills the entry's counts; None: the entry is final
(its reason says why it was not compared)."""


def judge_ids(r: BackendRender, e: Entry) -> Judged:
    res = compare_ids(
        r.ref,
        r.test,
        r.model,
        depth_tol=depth_tolerance_fn(r.ref, r.model, r.render, r.attrs),
        backend=r.backend,
        attrs=r.attrs,
    )
    r.id_result = res
    e.record_classes(res.edge, res.tie, res.crack, res.interior)
    e.tolerance = res.tolerance
    e.explanations = res.explanations
    notes = (
        []
        if r.model.known
        else [f"no precision model for {r.backend} in the registry (renderers/registry.py): compared exactly"]
    )
    ref_ids, test_ids = r.ref.buffers["id.prim"], r.test["id.prim"]

    def heat_map(path: Path) -> None:
        diffimages.write_id_diff(path, ref_ids, test_ids, res.edge_mask, res.interior_mask)

    return Judged(res.details, notes, heat_map)


def judge_depth(r: BackendRender, e: Entry) -> Judged | None:
    ids = r.id_result
    try:
        res = compare_depth(
            r.ref,
            r.test,
            r.model,
            r.render,
            r.attrs,
            ids.edge_mask if ids is not None else None,
            ids.classes if ids is not None else None,
            own_plane=True,
        )
    except tolerance.ToleranceError as exc:
        e.reason = str(exc)
        return None
    e.record_classes(res.edge, res.tie, res.crack, res.interior)
    e.mask_mismatches = res.mask
    e.compared_pixels = res.compared
    e.record_errors(res.max_abs, res.mean_abs, res.max_rel)
    e.tolerance = res.tolerance
    # Where both hit other prims: judged against the test's own plane (judge/depth.py), or not comparable.
    e.extra["own_plane_pixels"] = res.own_plane
    e.extra["own_plane_max_abs_error"] = finite(res.own_plane_max_abs)
    e.extra["not_comparable"] = dict(res.not_comparable)
    if res.explanations:
        e.explanations = res.explanations
    ref_z, test_z = r.ref.buffers["Z"], r.test["Z"]

    def heat_map(path: Path) -> None:
        diffimages.write_depth_diff(path, ref_z, test_z, res.max_abs)

    return Judged(res.details, heat_map=heat_map)


def judge_rendered_normals(r: BackendRender, e: Entry) -> Judged | None:
    return judge_normals(r.ref, r.backend, r.test, e, r.spec, r.attrs)


def judge_rgb(r: BackendRender, e: Entry) -> Judged | None:
    ids = r.id_result
    try:
        res = compare_rgb(
            r.ref, r.test, r.attrs, r.backend, r.render, ids.edge_mask if ids is not None else None, r.spec
        )
    except (tolerance.ToleranceError, radiance.RadianceError) as exc:
        e.reason = str(exc)
        return None
    judged = record_rgb(e, res, r.ref.buffers["RGB"], r.test["RGB"])
    e.explanations = explain_rgb(
        res.fail_mask & ~res.edge_mask, res.score, r.ref.buffers.get("id.prim"), r.test.get("id.prim")
    )
    return judged


class When(StrEnum):
    """When a buffer has an entry for a render."""

    ALWAYS = "always"  # every render of every scene
    SHADED = "shaded"  # scenes that require shading (vocab.SHADED_FEATURES)
    WRITTEN = "written"  # renders whose EXR has the buffer's channel


@dataclass(frozen=True)
class BufferSpec:
    """How one buffer is compared: a row of `BUFFER_TABLE`."""

    buffer: Buffer
    when: When
    channel: str  # the exrbuf key that holds it, in the test EXR (and the reference's)
    channel_text: str  # that channel in "the EXR has no ..." when a declared buffer lacks it
    ref_missing: str | None  # the reason when the reference lacks `channel`; None: not read from the reference
    judge: Judge
    fields: tuple[str, ...] = ()  # its entry's own fields after `images` (results.Entry.own_fields)
    skip_reason_from_render: bool = False  # a skipped entry gives the render's own reason, if any


BUFFER_TABLE: tuple[BufferSpec, ...] = (
    BufferSpec(
        Buffer.ID,
        When.ALWAYS,
        "id.prim",
        "id.prim channel",
        "reference has no id.prim channel",
        judge_ids,
        fields=("explanations",),
    ),
    BufferSpec(
        Buffer.Z, When.ALWAYS, "Z", "Z channel", "reference has no Z channel", judge_depth, fields=("explanations",)
    ),
    BufferSpec(Buffer.N, When.WRITTEN, "N", "N channel", None, judge_rendered_normals, fields=N_FIELDS),
    BufferSpec(
        Buffer.RGB,
        When.SHADED,
        "RGB",
        "R,G,B channels",
        "reference has no R,G,B channels (the scene requires shading)",
        judge_rgb,
        fields=RGB_ENTRY_FIELDS,
        skip_reason_from_render=True,
    ),
)
"""Every buffer compared, in the order of its entries for each render."""

BUFFER_FIELDS: dict[str, tuple[str, ...]] = {spec.buffer: spec.fields for spec in BUFFER_TABLE}
BUFFERS = tuple(spec.buffer for spec in BUFFER_TABLE if spec.when == When.ALWAYS)
"""The entries of a render that was not compared (skipped, error) in a scene without shading."""
SHADED_BUFFERS = tuple(spec.buffer for spec in BUFFER_TABLE if spec.when in (When.ALWAYS, When.SHADED))
"""The same in a scene that requires shading."""


def applies(spec: BufferSpec, r: BackendRender) -> bool:
    if spec.when == When.SHADED:
        return is_shaded(r.ref.scene.requires)
    if spec.when == When.WRITTEN:
        return spec.channel in r.test
    return True


def compare_buffer(spec: BufferSpec, r: BackendRender, exps: expectations.Expectations) -> Entry:
    """One buffer's entry: skipped/error when a side lacks it, else compared and judged."""
    e = Entry.for_render(r.scene, r.backend, spec.buffer, r.render, spec.fields)
    e.pixels = r.ref.pixels
    if spec.channel not in r.test:
        if r.declared is not None and spec.buffer in r.declared:
            e.reason = f"{r.exr}: manifest lists buffer {spec.buffer} but the EXR has no {spec.channel_text}"
        else:
            e.status = Status.SKIPPED
            own = str(r.render.get("reason") or "") if spec.skip_reason_from_render else ""
            e.reason = own or f"{r.backend} does not produce {spec.buffer}"
    elif spec.ref_missing is not None and spec.channel not in r.ref.buffers:
        e.reason = spec.ref_missing
    else:
        judged = spec.judge(r, e)
        if judged is not None:
            finish(e, judged, exps, r.run, r.diff_dir)
    return e


def finish(e: Entry, judged: Judged, exps: expectations.Expectations, run: Path, diff_dir: Path | None) -> None:
    """The verdict, the notes, and the heat map RUN/scenes/<scene>/diff/<backend>.<buffer>.png."""
    expectations.apply_verdict(e, exps, judged.details)
    for note in judged.notes:
        e.add_reason(note)
    if diff_dir is None or judged.heat_map is None:
        return
    path = diff_dir / f"{e.backend}.{e.buffer}.png"
    try:
        judged.heat_map(path)
        e.images = {"heat": path.relative_to(run).as_posix()}
    except diffimages.DiffImageError as exc:
        e.add_reason(f"diff image not written: {exc}")
