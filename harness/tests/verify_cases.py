"""The verifier's tests' one-pixel question: how `verify.classify_mismatches` classes a single
mismatched pixel, with an exact depth tolerance unless told otherwise."""

from __future__ import annotations

import numpy as np

from rendiff_harness.contract import resolved
from rendiff_harness.judge import verify


def exact_depth(z: np.ndarray, cos: np.ndarray, prims: np.ndarray) -> np.ndarray:
    """A depth tolerance of zero: only an exact depth agrees."""
    return np.zeros_like(z)


def classify_one(
    scene: resolved.ResolvedScene,
    ref: int,
    test: int,
    px: tuple[int, int],
    eps: float = 1e-3,
    depth_tol: verify.DepthTolerance = exact_depth,
    eye_slack: float = 0.0,
) -> tuple[str, str]:
    """The class and reason of pixel `px` (x, y) where the reference saw prim `ref` and the test
    renderer prim `test`."""
    x, y = px
    res = verify.classify_mismatches(
        scene,
        np.array([ref], dtype=np.uint32),
        np.array([test], dtype=np.uint32),
        np.array([y]),
        np.array([x]),
        eps,
        depth_tol,
        eye_slack=eye_slack,
    )
    return verify.CLASSES[int(res.cls[0])], res.why[0]
