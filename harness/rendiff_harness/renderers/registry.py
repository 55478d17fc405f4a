"""The backend registry: the one list of backends. Adding a built-in renderer is one folder
(renderers/<name>/, whose backend.py defines `SPEC`, a `BackendSpec`) plus one line in `BUILT_IN`.

Three kinds of backend, all `BackendSpec`s (renderers/spec.py):

* the rendiff core's own (renderers/core.py: raster, trace, Embree): rendered by the Rust side,
  listed here for their precision only (`spec`);
* the built-in external ones (`BUILT_IN`), rendered by the harness;
* renderers declared by a command (renderers/command.py: the TOML file that the environment
  variable RENDIFF_RENDERERS names), after the built-in ones; `all_backends`, `get`, `spec`
  and `known_names` raise `command.RenderersError` (one line) when that file is malformed.

`Backend` is the registry's entry for a backend the harness renders: its spec, or why it could
not be loaded. Backend folders are imported lazily and one failing import never hides the
others: an ImportError (a missing Python package, typically) turns that backend into an
*unavailable* one whose reason says what is missing, so `info` and the report can still list it.

Capabilities are judged per buffer (`plan`): the visibility buffers need only the
VISIBILITY_FEATURES, radiance needs every other feature the scene requires.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from ..contract import vocab
from ..contract.resolved import ResolvedScene
from . import command, core, declared
from .errors import BackendError, BackendUnavailable
from .spec import BackendSpec

BUILT_IN = (
    "povray",
    "pyrender",
    "mitsuba",
    "mitsuba_file",
    "pyrender_file",
)
"""The built-in external backends, in the order `info` lists them: renderers/<name>/backend.py's `SPEC`."""

RESERVED_NAMES = frozenset(
    {s.name for s in core.SPECS} | set(BUILT_IN) | {vocab.CACHED_REFERENCE_BACKEND} | set(vocab.IMPORT_DECODERS)
)
"""Names a declared renderer cannot take: every backend above, the comparison's cached references
and the import verdict's decoders."""
KNOWN_BUFFERS = frozenset({vocab.Buffer.Z, vocab.Buffer.ID, vocab.Buffer.N, vocab.Buffer.RGB})
VISIBILITY_FEATURES = frozenset(f.value for f in vocab.VISIBILITY_FEATURES)
"""The features the visibility buffers (Z, id, N) need; every other feature is a shading one
(needed by RGB only). From `vocab` (which mirrors Rust's `vocab::Feature::VISIBILITY`)."""
VISIBILITY_BUFFERS = frozenset({vocab.Buffer.Z, vocab.Buffer.ID, vocab.Buffer.N})
UNMEASURED_MEMORY = (400 * 2**20, 2000)
"""Peak memory assumed for a backend that declares none (a renderer declared by command): a
generous guess above every measured backend's (`peak_memory` in the built-in specs)."""
VISIBILITY_ONLY = "visibility_only"
"""The render() keyword that asks a backend for its visibility buffers only."""


@dataclass(frozen=True)
class Backend:
    """A registry entry: the backend's spec, or why it could not be loaded."""

    key: str
    """What it was loaded as: a BUILT_IN name, or "command:<name>" for a declared renderer."""
    spec: BackendSpec | None
    import_error: str | None
    declared_in: Path | None = None
    """The renderers file of a declared renderer; None for a built-in one."""

    @property
    def name(self) -> str:
        return self.spec.name if self.spec is not None else self.key

    @property
    def features(self) -> frozenset[str]:
        return frozenset(self.spec.features) if self.spec is not None else frozenset()

    @property
    def buffers(self) -> frozenset[str]:
        return frozenset(self.spec.buffers) if self.spec is not None else frozenset()

    @property
    def peak_memory(self) -> tuple[int, int]:
        """(fixed bytes, bytes per triangle) of a render at its peak: the spec's measured
        `peak_memory`, else `UNMEASURED_MEMORY`. `rendiff check` budgets memory with it."""
        declared = self.spec.peak_memory if self.spec is not None else None
        return declared if declared is not None else UNMEASURED_MEMORY

    @property
    def waits_below(self) -> int:
        """The spec's `waits_below` (0 for a declared renderer: nothing is known of its CPU use)."""
        return self.spec.waits_below if self.spec is not None else 0

    def unavailable_reason(self) -> str | None:
        """None when the backend can render here, else an actionable reason."""
        if self.spec is None:
            return self.import_error
        if self.spec.unavailable_reason is None:
            return None
        try:
            return self.spec.unavailable_reason()
        except Exception as exc:  # a broken probe must not take `info` down with it
            return f"unavailable_reason() failed: {type(exc).__name__}: {exc}"

    def version(self) -> str:
        if self.spec is None or self.spec.version is None:
            raise BackendUnavailable(f"{self.name}: {self.import_error}")
        return str(self.spec.version())

    def _parameters(self) -> Mapping[str, inspect.Parameter]:
        if self.spec is None or self.spec.render is None:
            return {}
        return inspect.signature(self.spec.render).parameters

    def accepts(self, option: str) -> bool:
        """True when the spec's render takes the keyword `option` (a quality setting, spp, seed)."""
        params = self._parameters()
        return option in params or any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())

    def render(
        self, scene: ResolvedScene, out_exr: Path, workdir: Path, timeout_s: float, **options: object
    ) -> dict[str, object]:
        """Render; `options` (spp, seed) reach the spec's render only if it accepts them."""
        if self.spec is None or self.spec.render is None:
            raise BackendUnavailable(f"{self.name}: {self.import_error}")
        params = self._parameters()
        accepts_all = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
        passed = {k: v for k, v in options.items() if v is not None and (accepts_all or k in params)}
        return dict(self.spec.render(scene, out_exr, workdir, timeout_s, **passed))


def load(name: str) -> Backend:
    """Import renderers/<name>/backend.py and take its `SPEC`; import problems become an unavailable Backend."""
    qualified = f"{__package__}.{name}.backend"
    try:
        module = importlib.import_module(qualified)
    except ImportError as exc:
        missing = getattr(exc, "name", None)
        if missing in (qualified, f"{__package__}.{name}"):
            return Backend(name, None, f"backend module renderers/{name}/backend.py not found")
        hint = f" (Python package {missing!r} missing; run scripts/setup.sh)" if missing else ""
        return Backend(name, None, f"cannot import backend {name!r}: {exc}{hint}")
    spec = getattr(module, "SPEC", None)
    if not isinstance(spec, BackendSpec):
        return Backend(name, None, f"backend module renderers/{name}/backend.py lacks SPEC (a BackendSpec)")
    extra = spec.buffers - KNOWN_BUFFERS
    if extra:
        return Backend(name, None, f"backend {name!r} declares unknown buffers {sorted(extra)}")
    if spec.render is None or spec.version is None or spec.unavailable_reason is None:
        return Backend(name, None, f"backend {name!r} lacks render, version or unavailable_reason")
    return Backend(name, spec, None)


def command_backends() -> list[Backend]:
    """The renderers declared in RENDIFF_RENDERERS (none when unset); RenderersError if malformed."""
    return [
        Backend(f"command:{r.name}", declared.spec(r), None, declared_in=r.source)
        for r in command.from_env(RESERVED_NAMES)
    ]


def all_backends() -> list[Backend]:
    """Every backend the harness renders: the built-in ones, then the declared ones."""
    return [load(m) for m in BUILT_IN] + command_backends()


def get(name: str) -> Backend:
    """Look a backend the harness renders up by its name (e.g. 'pyrender'); KeyError if unknown."""
    if name in BUILT_IN:
        return load(name)
    for backend in command_backends():
        if backend.name == name:
            return backend
    raise KeyError(name)


def spec(name: str) -> BackendSpec | None:
    """The spec of any backend by name (the core's included), None when there is none: the
    lookup the judge is given (`spec.SpecLookup`). A built-in backend that cannot be imported has
    none, as before it could be compared."""
    for s in core.SPECS:
        if s.name == name:
            return s
    try:
        return get(name).spec
    except KeyError:
        return None


def known_names() -> list[str]:
    return [b.name for b in all_backends()]


def missing_features(backend: Backend, scene: ResolvedScene) -> list[str]:
    """Scene requirements the backend cannot model (sorted); empty means it may run."""
    return sorted(scene.requires - backend.features)


@dataclass(frozen=True)
class Plan:
    """What a backend renders of a scene: everything, the visibility buffers only, or nothing.

    `reason` says why anything is left out: "missing features: ..." for a skip,
    "RGB not rendered: missing features: ..." for a visibility-only render, "" otherwise.
    """

    render: bool
    visibility_only: bool
    missing: tuple[str, ...]
    reason: str


def visibility_only_reason(missing: list[str] | tuple[str, ...]) -> str:
    """The reason recorded for a render without RGB (the Rust side writes the same words)."""
    return f"RGB not rendered: missing features: {', '.join(missing)}"


def plan(backend: Backend, scene: ResolvedScene, visibility_only: bool = False) -> Plan:
    """Decide per buffer: a missing visibility feature skips the backend; a missing shading
    feature drops only RGB, when `visibility_only` is allowed and the backend's render() takes
    it (`Backend.accepts`), else the backend is skipped as a whole.

    With `visibility_only` and nothing missing, an accepting backend still renders no RGB.
    """
    missing = tuple(missing_features(backend, scene))
    skip = Plan(False, False, missing, f"missing features: {', '.join(missing)}")
    if any(f in VISIBILITY_FEATURES for f in missing):
        return skip
    if not visibility_only or not backend.accepts(VISIBILITY_ONLY):
        return skip if missing else Plan(True, False, (), "")
    return Plan(True, True, missing, visibility_only_reason(missing) if missing else "")


__all__ = [
    "BUILT_IN",
    "Backend",
    "BackendError",
    "BackendUnavailable",
    "Plan",
    "VISIBILITY_FEATURES",
    "all_backends",
    "command_backends",
    "get",
    "known_names",
    "load",
    "missing_features",
    "plan",
    "spec",
    "visibility_only_reason",
]
