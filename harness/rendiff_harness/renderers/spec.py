"""`BackendSpec`: everything the harness knows about one backend, declared in one place.

Why one record: the registry lists, plans and runs a backend from it (renderers/registry.py),
the judge finds its precision in it (judge/precision.py), and calibration its camera-error
model, so that adding a built-in backend is its own folder (renderers/<name>/backend.py,
whose `SPEC` is one of these), one line in the registry and its tests. No other table lists
backends.

What the judge may import from here is this module alone (the types), never the registry:
whoever starts a comparison passes the registry's lookup in (`SpecLookup`), so the judge stands
on the contract and these types only (tests/test_layout.py checks it).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from ..contract.vocab import Buffer, Feature
from ..judge.camera_budget import CameraModel, core_camera
from ..judge.tolerance import Model, NormalModel, RgbModel, ShadingMove, f32_normals

if TYPE_CHECKING:
    from ..contract.resolved import ResolvedScene


class RenderFn(Protocol):
    """A backend's render: the scene into the buffer EXR `out_exr` (atomically); returns what was
    done (the `info` of `render`'s JSON line). Raises BackendError (BackendUnavailable when it
    cannot run here).

    It may also take keyword-only options; `registry.Backend.render` passes one only when it is
    given and the function takes it (read from its signature at run time):

    * `spp`, `seed`: Monte Carlo backends;
    * quality settings (`aa_method`, `aa_threshold`, `aa_depth`, `quality`, `max_depth`): the CLI
      refuses one that the backend's render does not take (`registry.Backend.accepts`);
    * `visibility_only: bool`: render Z/id (and N) but no RGB, so that a scene needing a shading
      feature the backend lacks is still compared on depth and IDs (`registry.plan`); a backend
      without it is skipped on such scenes.
    """

    def __call__(
        self, scene: ResolvedScene, out_exr: Path, workdir: Path, timeout_s: float, /
    ) -> Mapping[str, object]: ...


@dataclass(frozen=True)
class BackendSpec:
    """One backend: what it can model, what it writes, how precise it is, and how it renders."""

    name: str
    """e.g. "povray": `--backend`, and the results' backend field."""
    features: frozenset[Feature]
    """Scene features it can model."""
    buffers: frozenset[Buffer]
    """The buffers it writes: a subset of registry.KNOWN_BUFFERS ({Z, id, N, RGB})."""
    precision: Model
    """Its edge, position and depth model (judge/tolerance.py has the machinery)."""
    calibration: CameraModel = core_camera
    """The error bounds its arithmetic puts into the camera fit (judge/camera_budget.py)."""
    rgb_tolerance: RgbModel | None = None
    """Its deterministic RGB tolerance; None: it has no RGB model (judge/tolerance.rgb_fallback)."""
    rgb_moved_point: ShadingMove | None = None
    """Where it shades: how far its own arithmetic moves the point it shades from the reference's hit
    (and whether it rounds its point lights to f32), derived in its backend module; its RGB tolerance
    then also allows the direct light's change over that move (judge/moved_point.py). None keeps the
    RGB tolerance as its model gives it."""
    shadow_ray_offset: Callable[[np.ndarray], np.ndarray] | None = None
    """Its own shadow-ray origin offset at the shading points (K, 3) -> (K,) world units, when it is larger
    than the contract's: a failing pixel whose shadow ray passes that close to an occluder's edge or end is
    a shadow edge (judge/rgb.py, lighting.shadow_ambiguity). None: the contract's band only."""
    normals: NormalModel = f32_normals
    """The angle its N may be off the winding convention."""
    peak_memory: tuple[int, int] | None = None
    """(fixed bytes, bytes per triangle) of a render at its peak, measured as GNU time's max RSS
    and rounded up; None: not measured (the registry then assumes `UNMEASURED_MEMORY`).
    `rendiff check` budgets memory with it (check/pool.rs)."""
    waits_below: int = 0
    """Renders of scenes with fewer triangles than this keep a core busy for at most a fifth of
    their wall time (they mostly wait: POV-Ray's front end polls), measured; `rendiff check` may
    run such renders beside its CPU-bound ones (check/pool.rs, wait slots). 0: never."""
    render: RenderFn | None = None
    """None: rendered by rendiff itself (the Rust core), never by the harness."""
    version: Callable[[], str] | None = None
    """The renderer's version; may raise BackendUnavailable."""
    unavailable_reason: Callable[[], str | None] | None = None
    """None when usable here, else what to install."""
    core_loop: bool = False
    """True for the rendiff core's own loops (raster, trace): one camera, coverage predicate and depth
    function, so calibration blames the core's camera, and metamorphic relations hold them to the
    core's own bounds (judge/metamorphic.py)."""
    declared: bool = False
    """True for a renderer declared by command (renderers/declared.py): rendiff exports nothing for it
    (it reads the resolved scene itself), so a convention error is the renderer's, not an exporter's."""


DIRECT_LIGHT_FEATURES = frozenset(
    {
        Feature.DEPTH,
        Feature.IDS,
        Feature.EMISSION,
        Feature.LAMBERT,
        Feature.POINT_LIGHT,
        Feature.DIRECTIONAL_LIGHT,
    }
)
"""What every built-in shading backend (POV-Ray, pyrender, Mitsuba) models: depth and IDs, and
Lambert and emissive surfaces lit by point and directional lights. Each backend's `FEATURES` is
this plus what sets it apart (shadows or none, sidedness, area lights, global illumination)."""


SpecLookup = Callable[[str], "BackendSpec | None"]
"""A backend's name -> its spec, None when no backend has that name (the registry's `spec`)."""
