"""rendiff's vocabulary on the Python side: features, statuses, buffers and mismatch classes.

The one definition is Rust's ``rendiff_core::vocab`` (``rendiff vocab --json`` prints it);
this module mirrors it as ``StrEnum``s so the harness compares and writes the same words,
and ``tests/vocab_drift.rs`` fails if the two differ. ``StrEnum`` members equal their
strings, so results.json and the manifest keep plain strings.
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import StrEnum

BACKGROUND_ID = 0xFFFFFFFF
"""The id.prim / id.object of a pixel that shows no triangle (Rust's ``rendiff_core::frame::BACKGROUND_ID``,
u32::MAX); its depth is +inf. The harness's one copy: everything else names this constant."""

CACHED_REFERENCE_BACKEND = "mitsuba_ref"
"""The backend name results.json gives a comparison with a cached Mitsuba reference (references.py):
no renderer may take it."""

IMPORT_DECODERS = ("gltf_spec", "trimesh")
"""The backend names results.json gives the `import` verdict's decoders (judge/importcheck): no
renderer may take them."""


class Feature(StrEnum):
    """What a scene requires of a renderer (``requires = [...]``)."""

    DEPTH = "depth"
    IDS = "ids"
    NORMALS = "normals"
    EMISSION = "emission"
    LAMBERT = "lambert"
    POINT_LIGHT = "point_light"
    DIRECTIONAL_LIGHT = "directional_light"
    SHADOWS = "shadows"
    AREA_LIGHT = "area_light"
    GLOBAL_ILLUMINATION = "global_illumination"
    TWO_SIDED = "two_sided"
    ONE_SIDED = "one_sided"
    SHADOWLESS = "shadowless"


VISIBILITY_FEATURES: tuple[Feature, ...] = (Feature.DEPTH, Feature.IDS, Feature.NORMALS)
"""What the visibility buffers (Z, id, N) need; every other feature is needed by RGB only."""

SHADED_FEATURES: tuple[Feature, ...] = (Feature.LAMBERT, Feature.EMISSION, Feature.GLOBAL_ILLUMINATION)
"""Features that make a scene ask for radiance at all."""


def needs_shading(requires: Iterable[str]) -> bool:
    """True when a scene requiring ``requires`` asks for radiance (the one rule, as in Rust)."""
    return any(r in SHADED_FEATURES for r in requires)


class Status(StrEnum):
    """A verdict's status in results.json and the baseline."""

    PASS = "pass"
    FAIL = "fail"
    SKIPPED = "skipped"
    ERROR = "error"
    EXPECTED_FAIL = "expected_fail"
    UNEXPECTED_PASS = "unexpected_pass"


FAILING_STATUSES: tuple[Status, ...] = (Status.FAIL, Status.ERROR, Status.UNEXPECTED_PASS)
"""Statuses that turn a run red."""


class RenderStatus(StrEnum):
    """What happened to one render in manifest.json."""

    OK = "ok"
    SKIPPED = "skipped"
    ERROR = "error"


class Buffer(StrEnum):
    """What a verdict compares (``buffer`` in results.json)."""

    ID = "id"
    Z = "Z"
    N = "N"
    RGB = "RGB"
    CAMERA = "camera"
    SCENE = "scene"
    IMPORT = "import"


class MismatchClass(StrEnum):
    """The verifier's class of one ID mismatch (docs/verifier.md)."""

    EDGE = "edge"
    TIE = "tie"
    CRACK = "crack"
    INTERIOR = "interior"


EXIT_SKIPPED = 3
"""Exit status of a skipped render (Rust's `vocab::EXIT_SKIPPED`): the harness's `render`, and
every command renderer (docs/your-renderer.md)."""


MANIFEST_FORMAT = "rendiff-manifest/1"
"""Format tag of a run's manifest.json (Rust's `vocab::MANIFEST_FORMAT`)."""

RESULTS_FORMAT = "rendiff-results/1"
"""Format tag of a run's results.json (Rust's `vocab::RESULTS_FORMAT`): gate, bless and report
refuse any other."""


def as_json() -> dict[str, list[str] | int | str]:
    """The vocabulary in the shape of ``rendiff vocab --json``."""
    return {
        "features": [f.value for f in Feature],
        "visibility_features": [f.value for f in VISIBILITY_FEATURES],
        "shaded_features": [f.value for f in SHADED_FEATURES],
        "statuses": [s.value for s in Status],
        "failing_statuses": [s.value for s in FAILING_STATUSES],
        "render_statuses": [s.value for s in RenderStatus],
        "buffers": [b.value for b in Buffer],
        "mismatch_classes": [c.value for c in MismatchClass],
        "exit_skipped": EXIT_SKIPPED,
        "manifest_format": MANIFEST_FORMAT,
        "results_format": RESULTS_FORMAT,
    }
