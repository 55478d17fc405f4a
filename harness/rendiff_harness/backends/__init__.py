"""One module per external renderer; see registry.py for the list.

`BackendModule` below is what each of these modules provides: the registry uses nothing else.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from ..contract.resolved import ResolvedScene


class BackendModule(Protocol):
    """The interface of a backend module (backends/povray.py is a complete one).

    A module satisfies it with module-level constants and functions; mypy checks the shipped
    modules against it (registry.py), and `registry.load` refuses a module that lacks a member
    (`MEMBERS`), so that a broken backend is reported as unavailable instead of failing later.

    `render` may also take keyword-only options; `registry.Backend.render` passes one only when
    it is given and the module's render() takes it (read from its signature at run time):

    * `spp`, `seed`: Monte Carlo backends;
    * quality settings (`aa_method`, `aa_threshold`, `aa_depth`, `quality`, `max_depth`): the CLI
      refuses one that the backend's render() does not take (`registry.Backend.accepts`);
    * `visibility_only: bool`: render Z/id (and N) but no RGB, so that a scene needing a shading
      feature the backend lacks is still compared on depth and IDs (`registry.plan`); a backend
      without it is skipped on such scenes.
    """

    NAME: str
    """The backend's name, e.g. "povray" (`--backend`, and the results' backend field)."""
    FEATURES: frozenset[str]
    """Scene features it can model ("depth", "ids", "lambert", ...)."""
    BUFFERS: frozenset[str]
    """The buffers it writes: a subset of registry.KNOWN_BUFFERS ({"Z", "id", "N", "RGB"})."""

    def version(self) -> str:
        """The renderer's version; may raise BackendUnavailable."""
        ...

    def unavailable_reason(self) -> str | None:
        """None when usable here, else what to install."""
        ...

    def render(self, scene: ResolvedScene, out_exr: Path, workdir: Path, timeout_s: float, /) -> Mapping[str, object]:
        """Render `scene` into the buffer EXR `out_exr` (atomically); return what was done (the
        `info` of `render`'s JSON line). Raises BackendError (BackendUnavailable when it cannot run)."""
        ...


MEMBERS = ("NAME", "FEATURES", "BUFFERS", "version", "unavailable_reason", "render")
"""The members of `BackendModule`, for `registry.load`'s run-time check (tests/test_registry.py
checks that the two agree)."""
