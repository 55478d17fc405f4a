"""The backend registry: adding a renderer is one module in `backends/` plus one line here.

A backend module implements the `BackendModule` protocol (backends/__init__.py, which
documents each member; see backends/povray.py for a complete one):

    NAME: str                                  # e.g. "povray"
    FEATURES: frozenset[str]                   # scene features it can model ("depth", "ids", ...)
    BUFFERS: frozenset[str]                    # subset of {"Z", "id", "N", "RGB"}
    def version() -> str                       # may raise BackendUnavailable
    def unavailable_reason() -> str | None     # None when usable, else what to install
    def render(scene, out_exr, workdir, timeout_s, **optional keywords) -> dict[str, object]

`Backend` is the registry's entry for one module: the module, or why it could not be used.

Capabilities are judged per buffer (`plan`): the visibility buffers need only the
VISIBILITY_FEATURES, radiance needs every other feature the scene requires.

Modules are imported lazily and one failing import never hides the others: an
ImportError (a missing Python package, typically) turns that backend into an
*unavailable* one whose reason says what is missing, so `info` and the report
can still list it.

Renderers declared by a command (command_renderers.py: the TOML file that the environment
variable RENDIFF_RENDERERS names) join the list after the modules, as `Backend`s whose
module is a `command_renderers.CommandBackend`; `all_backends`, `get` and `known_names`
raise `command_renderers.RenderersError` (one line) when that file is malformed.
"""

from __future__ import annotations

import importlib
import inspect
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, cast

from . import command_renderers
from .backends import MEMBERS, BackendModule
from .contract import vocab
from .contract.resolved import ResolvedScene
from .errors import BackendError, BackendUnavailable

if TYPE_CHECKING:
    # mypy checks every shipped module against the protocol; nothing is imported at run time.
    from .backends import mitsuba_backend, povray, pyrender_backend

    _POVRAY: BackendModule = povray
    _PYRENDER: BackendModule = pyrender_backend
    _MITSUBA: BackendModule = mitsuba_backend

BACKEND_MODULES = [
    "povray",
    "pyrender_backend",
    "mitsuba_backend",
]

_REQUIRED = MEMBERS
KNOWN_BUFFERS = frozenset({"Z", "id", "N", "RGB"})
VISIBILITY_FEATURES = frozenset(f.value for f in vocab.VISIBILITY_FEATURES)
"""The features the visibility buffers (Z, id, N) need; every other feature is a shading one
(needed by RGB only). From `vocab` (which mirrors Rust's `vocab::Feature::VISIBILITY`)."""
VISIBILITY_BUFFERS = frozenset({"Z", "id", "N"})
UNMEASURED_MEMORY = (400 * 2**20, 2000)
"""Peak memory assumed for a backend that declares none (a renderer declared by command): a
generous guess above every measured backend's (`PEAK_MEMORY` in backends/)."""
VISIBILITY_ONLY = "visibility_only"
"""The render() keyword that asks a backend for its visibility buffers only."""


@dataclass(frozen=True)
class Backend:
    """A registry entry: the imported module, or why it could not be imported."""

    module_name: str
    module: BackendModule | None
    import_error: str | None

    @property
    def name(self) -> str:
        if self.module is not None:
            return str(self.module.NAME)
        return self.module_name.removesuffix("_backend")

    @property
    def features(self) -> frozenset[str]:
        return frozenset(self.module.FEATURES) if self.module is not None else frozenset()

    @property
    def buffers(self) -> frozenset[str]:
        return frozenset(self.module.BUFFERS) if self.module is not None else frozenset()

    @property
    def peak_memory(self) -> tuple[int, int]:
        """(fixed bytes, bytes per triangle) of a render at its peak: the module's measured
        `PEAK_MEMORY`, else `UNMEASURED_MEMORY`. `rendiff check` budgets memory with it."""
        declared = getattr(self.module, "PEAK_MEMORY", None) if self.module is not None else None
        if isinstance(declared, tuple) and len(declared) == 2:
            return int(declared[0]), int(declared[1])
        return UNMEASURED_MEMORY

    def unavailable_reason(self) -> str | None:
        """None when the backend can render here, else an actionable reason."""
        if self.module is None:
            return self.import_error
        try:
            return self.module.unavailable_reason()
        except Exception as exc:  # a broken probe must not take `info` down with it
            return f"unavailable_reason() failed: {type(exc).__name__}: {exc}"

    def version(self) -> str:
        if self.module is None:
            raise BackendUnavailable(f"{self.name}: {self.import_error}")
        return str(self.module.version())

    def accepts(self, option: str) -> bool:
        """True when the module's render() takes the keyword `option` (a quality setting, spp, seed)."""
        if self.module is None:
            return False
        params = inspect.signature(self.module.render).parameters
        return option in params or any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())

    def render(
        self, scene: ResolvedScene, out_exr: Path, workdir: Path, timeout_s: float, **options: object
    ) -> dict[str, object]:
        """Render; `options` (spp, seed) reach the module only if its render() accepts them."""
        if self.module is None:
            raise BackendUnavailable(f"{self.name}: {self.import_error}")
        params = inspect.signature(self.module.render).parameters
        accepts_all = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
        passed = {k: v for k, v in options.items() if v is not None and (accepts_all or k in params)}
        return dict(self.module.render(scene, out_exr, workdir, timeout_s, **passed))


def load(module_name: str) -> Backend:
    """Import `backends/<module_name>.py`; import problems become an unavailable Backend."""
    try:
        module = importlib.import_module(f"{__package__}.backends.{module_name}")
    except ImportError as exc:
        qualified = f"{__package__}.backends.{module_name}"
        missing = getattr(exc, "name", None)
        if missing == qualified:
            return Backend(module_name, None, f"backend module backends/{module_name}.py not found")
        hint = f" (Python package {missing!r} missing; run scripts/setup.sh)" if missing else ""
        return Backend(module_name, None, f"cannot import backend module {module_name!r}: {exc}{hint}")
    absent = [attr for attr in _REQUIRED if not hasattr(module, attr)]
    if absent:
        return Backend(module_name, None, f"backend module {module_name!r} lacks {', '.join(absent)}")
    backend = cast(BackendModule, module)  # every member of the protocol is there (checked just above)
    extra = frozenset(backend.BUFFERS) - KNOWN_BUFFERS
    if extra:
        return Backend(module_name, None, f"backend module {module_name!r} declares unknown buffers {sorted(extra)}")
    return Backend(module_name, backend, None)


def command_backends() -> list[Backend]:
    """The renderers declared in RENDIFF_RENDERERS (none when unset); RenderersError if malformed."""
    return [Backend(f"command:{c.NAME}", c, None) for c in command_renderers.backends()]


def all_backends() -> list[Backend]:
    return [load(m) for m in BACKEND_MODULES] + command_backends()


def get(name: str) -> Backend:
    """Look a backend up by its NAME (e.g. 'pyrender') or its module name; KeyError if unknown."""
    for module_name in BACKEND_MODULES:
        if name == module_name or name == module_name.removesuffix("_backend"):
            return load(module_name)
    for backend in all_backends():  # a module whose NAME differs from its file name; a declared one
        if backend.name == name:
            return backend
    raise KeyError(name)


def known_names() -> list[str]:
    return [b.name for b in all_backends()]


def missing_features(backend: Backend | BackendModule, scene: ResolvedScene) -> list[str]:
    """Scene requirements the backend cannot model (sorted); empty means it may run."""
    features = backend.features if isinstance(backend, Backend) else frozenset(backend.FEATURES)
    return sorted(scene.requires - features)


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
    "BACKEND_MODULES",
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
    "visibility_only_reason",
]
