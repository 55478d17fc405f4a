"""RGB explanations: interior failing pixels grouped by the prims each side saw (judge/rgb.py)."""

from __future__ import annotations

import numpy as np

from rendiff_harness.contract.vocab import BACKGROUND_ID
from rendiff_harness.judge import verify
from rendiff_harness.judge.rgb import explain_rgb


def test_groups_by_prims_largest_first_with_the_worst_pixel_as_example() -> None:
    prim = np.full((4, 6), BACKGROUND_ID, dtype=np.uint32)
    prim[:, :3] = 7
    prim[:, 3:5] = 2
    interior = np.zeros((4, 6), dtype=bool)
    interior[0:3, 0] = True  # 3 pixels on prim 7
    interior[1, 4] = True  # 1 pixel on prim 2
    interior[2, 5] = True  # 1 pixel on the background
    score = np.ones((4, 6))
    score[2, 0] = 9.0  # prim 7's worst
    groups = explain_rgb(interior, score, prim, prim)
    assert groups is not None
    assert [(g["ref_prim"], g["test_prim"], g["pixels"]) for g in groups] == [(7, 7, 3), (2, 2, 1), (None, None, 1)]
    assert groups[0]["example"] == [0, 2] and groups[0]["class"] == "interior"
    assert groups[1]["example"] == [4, 1]
    # Each side's own prim: the test saw prim 2 where the reference saw 7.
    test = prim.copy()
    test[0, 0] = 2
    pairs = {(g["ref_prim"], g["test_prim"]): g["pixels"] for g in explain_rgb(interior, score, prim, test) or []}
    assert pairs[(7, 2)] == 1 and pairs[(7, 7)] == 2


def test_none_without_interior_pixels_or_ids_and_at_most_max_groups() -> None:
    prim = np.arange(30 * 30, dtype=np.uint32).reshape(30, 30)
    none = np.zeros((30, 30), dtype=bool)
    assert explain_rgb(none, np.ones((30, 30)), prim, prim) is None
    every = ~none
    assert explain_rgb(every, np.ones((30, 30)), None, prim) is None
    groups = explain_rgb(every, np.ones((30, 30)), prim, prim)
    assert groups is not None and len(groups) == verify.MAX_EXPLANATIONS
