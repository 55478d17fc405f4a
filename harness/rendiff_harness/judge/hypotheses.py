"""Which convention does a failing camera follow? (docs/calibration.md "Diagnosis").

The calibration (calibration.py) fits a general pinhole camera G to a probe's depths, read as
the contract's planar depth. When that fails, the fitted numbers of a renderer that broke a
*different* convention mean little: a renderer writing radial distance was reported as "horizontal
FOV scale 0.92x, vertical 1.13x, rotated, sheared", its real fault last. This module tests the
conventions renderers actually follow against each other, on the same pixels and equations, and
names the one the renderer follows, with the residual of each.

Depth hypotheses: what the stored value `w` is, each giving the planar depth Z the fit needs
(near and far are the probe's; d = f + sx r + sy u, the contract's unnormalized pixel ray):

* planar depth (the contract): Z = w;
* radial distance from the eye: Z = w / |d|;
* window depth in [0, 1] (OpenGL's default depth range): 1/Z = 1/near - w (1/near - 1/far);
* NDC depth in [-1, 1]: the same with w -> (w + 1) / 2;
* reversed-Z window depth (1 at near, 0 at far): 1/Z = 1/near - (1 - w) (1/near - 1/far).

For each, the general pinhole camera is fitted (the equations h/Z = n.G(1, sx, sy) are linear in
G) and its rms residual (in px, as calibration.py scales the equations) is recorded. The best is
the one with the smallest residual; a depth other than planar is named only when it fits (its rms
residual within `rms_bound_px`, the derived bound calibration.py holds residuals to) and planar
does not.

Camera hypotheses, fitted under the best depth, each a linear family of G (a depth scale k is
free in every one, as a depth unit is not a camera error):

* the convention: G = k I;
* pixel-center offset: G = k I + offset in the image plane (the first column's r and u entries);
* field of view: G = k diag(1, s, s);
* aspect (field of view per axis): G = k diag(1, sx, sy);
* x mirrored (handedness): G = k diag(1, -1, 1);
* y flipped: G = k diag(1, 1, -1);
* general pinhole: all nine entries (calibration.py's fit).

The best camera hypothesis is the one with the fewest parameters that fits (rms within the bound;
the convention only when the calibration itself passed), ties to the smaller residual; when none
of the named ones fits, the general pinhole if it does, else none.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

PLANAR = "planar depth"
RADIAL = "radial distance"
WINDOW = "window depth [0, 1]"
NDC = "NDC depth [-1, 1]"
REVERSED = "reversed-Z window depth"
DEPTH_WORDS = {
    PLANAR: "planar depth along the view axis",
    RADIAL: "radial distance from the eye",
    WINDOW: "window depth in [0, 1] (1/Z interpolated between near and far)",
    NDC: "NDC depth in [-1, 1]",
    REVERSED: "reversed-Z window depth (1 at near, 0 at far)",
}
"""Each depth hypothesis in words, for the message that names it."""

CONVENTION = "convention"
OFFSET = "pixel-center offset"
FOV = "field of view"
ASPECT = "aspect (field of view per axis)"
MIRRORED = "x mirrored (handedness)"
FLIPPED = "y flipped"
GENERAL = "general pinhole"


def _unit(i: int, j: int) -> np.ndarray:
    m = np.zeros((3, 3))
    m[i, j] = 1.0
    return m


# name -> (the matrix the depth scale multiplies, further directions of G)
CAMERA_FAMILIES: dict[str, tuple[np.ndarray, list[np.ndarray]]] = {
    CONVENTION: (np.eye(3), []),
    OFFSET: (np.eye(3), [_unit(1, 0), _unit(2, 0)]),
    FOV: (np.eye(3), [_unit(1, 1) + _unit(2, 2)]),
    ASPECT: (np.eye(3), [_unit(1, 1), _unit(2, 2)]),
    MIRRORED: (np.diag([1.0, -1.0, 1.0]), []),
    FLIPPED: (np.diag([1.0, 1.0, -1.0]), []),
    GENERAL: (np.eye(3), [_unit(i, j) for i in range(3) for j in range(3) if (i, j) != (0, 0)]),
}
"""The camera hypotheses as linear families of G (module docstring)."""


@dataclass(frozen=True)
class Diagnosis:
    """The hypotheses tested on one probe: rms residual (px) of each, and the best of each kind."""

    depth: str
    depth_rms: dict[str, float]
    camera: str | None
    camera_rms: dict[str, float]
    rms_bound_px: float

    def as_json(self) -> dict[str, object]:
        """results.json `hypotheses` (non-finite residuals as null)."""

        def clean(d: dict[str, float]) -> dict[str, float | None]:
            return {k: (v if math.isfinite(v) else None) for k, v in d.items()}

        return {
            "depth": self.depth,
            "camera": self.camera,
            "depth_rms_px": clean(self.depth_rms),
            "camera_rms_px": clean(self.camera_rms),
            "rms_bound_px": self.rms_bound_px,
        }

    def fits(self, rms: float) -> bool:
        """Whether a residual is within the bound a right model's residual keeps to."""
        return math.isfinite(rms) and rms <= self.rms_bound_px

    def summary(self) -> str:
        """Every hypothesis with its residual, best first within each kind."""

        def listed(d: dict[str, float]) -> str:
            order = sorted(d.items(), key=lambda kv: (not math.isfinite(kv[1]), kv[1]))
            return ", ".join(f"{k} {_num(v)}" for k, v in order)

        within = _num(self.rms_bound_px)
        text = f"hypotheses tested, rms residual in px (a fit is within {within}): depth: {listed(self.depth_rms)}"
        if self.camera_rms:
            text += f"; camera (under {self.depth}): {listed(self.camera_rms)}"
        return text

    def lead(self) -> str:
        """The best hypothesis in words: what the message starts with."""
        if self.depth != PLANAR:
            text = (
                f"Z holds {DEPTH_WORDS[self.depth]}, not planar depth "
                f"(rms residual {_num(self.depth_rms[self.depth])} px as {self.depth}, "
                f"{_num(self.depth_rms[PLANAR])} px as planar depth)"
            )
            if self.camera == CONVENTION:
                text += "; read as such, the camera follows the convention"
            elif self.camera is not None:
                text += f"; read as such, the camera follows the {self.camera} hypothesis"
            return text
        if self.camera is None:
            best = min(self.camera_rms.items(), key=lambda kv: kv[1] if math.isfinite(kv[1]) else math.inf)
            return f"no camera or depth hypothesis fits (closest: {best[0]}, rms residual {_num(best[1])} px)"
        return f"{self.camera} (rms residual {_num(self.camera_rms[self.camera])} px, the best camera hypothesis)"


def _num(x: float) -> str:
    return f"{x:.4g}"


def planar_inverse(w: np.ndarray, d_norm: np.ndarray, near: float, far: float) -> dict[str, np.ndarray]:
    """1/Z (planar) under each depth hypothesis, from the stored values w (module docstring)."""
    inv_near = 1.0 / near if near > 0 else math.inf
    span = inv_near - (1.0 / far if math.isfinite(far) and far > 0 else 0.0)
    with np.errstate(all="ignore"):
        return {
            PLANAR: 1.0 / w,
            RADIAL: d_norm / w,
            WINDOW: inv_near - w * span,
            NDC: inv_near - (w + 1.0) / 2.0 * span,
            REVERSED: inv_near - (1.0 - w) * span,
        }


def _family_rms(design: np.ndarray, y: np.ndarray, family: tuple[np.ndarray, list[np.ndarray]]) -> float:
    """rms residual (px) of the least-squares fit of y by design @ vec(G), G in the family."""
    base, extra = family
    cols = np.stack([m.ravel() for m in (base, *extra)], axis=1)  # (9, P)
    a = design @ cols
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    r = y - a @ coef
    return float(np.sqrt(np.mean(r * r)))


def diagnose(
    design: np.ndarray,
    h_over_g: np.ndarray,
    w: np.ndarray,
    d_norm: np.ndarray,
    near: float,
    far: float,
    rms_bound_px: float,
    convention_passed: bool,
) -> Diagnosis:
    """Every hypothesis's residual and the best ones.

    `design` (K, 9) and `h_over_g` (K,) are calibration.py's equations (design @ vec(G) = h / (Z g),
    residuals in px), `w` the stored depths of the K pixels, `d_norm` |d| there.
    """
    depth_rms: dict[str, float] = {}
    ys: dict[str, np.ndarray] = {}
    for name, inv in planar_inverse(w, d_norm, near, far).items():
        y = h_over_g * inv
        if not np.all(np.isfinite(y)) or not np.all(inv > 0):
            depth_rms[name] = math.inf
            continue
        ys[name] = y
        depth_rms[name] = _family_rms(design, y, CAMERA_FAMILIES[GENERAL])
    bound = rms_bound_px

    def fits(r: float) -> bool:
        return math.isfinite(r) and r <= bound

    best = min(depth_rms, key=lambda k: depth_rms[k])
    depth = best if best != PLANAR and fits(depth_rms[best]) and not fits(depth_rms[PLANAR]) else PLANAR
    camera_rms: dict[str, float] = {}
    camera: str | None = None
    if depth in ys:
        y = ys[depth]
        camera_rms = {name: _family_rms(design, y, fam) for name, fam in CAMERA_FAMILIES.items()}
        candidates = [
            (len(CAMERA_FAMILIES[n][1]), r, n)
            for n, r in camera_rms.items()
            if n != GENERAL and fits(r) and (n != CONVENTION or convention_passed or depth != PLANAR)
        ]
        if candidates:
            camera = min(candidates)[2]
        elif fits(camera_rms[GENERAL]):
            camera = GENERAL
    return Diagnosis(depth, depth_rms, camera, camera_rms, bound)
