"""`int_rows`: the vectorised SDL integer rows read as the per-row `str.format` text they replace."""

from __future__ import annotations

import numpy as np
import pytest

from rendiff_harness.renderers.povray.int_rows import int_rows


def _by_format(cells: np.ndarray, template: str) -> str:
    """The text before int_rows: one `str.format` call per row (braces escaped for format)."""
    fmt = template.replace("{", "{{").replace("}", "}}").replace("{{}}", "{}")
    return ",\n".join(fmt.format(*row) for row in cells.tolist())


@pytest.mark.parametrize(
    "template",
    ["<{},{},{}>", "<{},{},{}>,{}", "texture{pigment{rgb<{},{},0>/65535}}", "{}"],
)
def test_rows_are_the_formatted_rows_but_for_padding(template: str) -> None:
    rng = np.random.default_rng(3)
    k = template.count("{}")
    # Zeros, single digits, every width up to 10 digits, and the 32-bit maximum.
    cells = np.concatenate(
        [
            np.zeros((1, k), dtype=np.int64),
            rng.integers(0, 10, size=(50, k)),
            10 ** rng.integers(0, 10, size=(200, k)) - rng.integers(0, 2, size=(200, k)),
            np.full((1, k), 2**32 - 1, dtype=np.int64),
        ]
    ).clip(0)
    text = int_rows(cells, template)
    assert text.replace(" ", "") == _by_format(cells, template).replace(" ", "")
    rows = text.split(",\n")
    assert len(rows) == cells.shape[0]
    # Every row has the same length: each cell is padded to its column's widest.
    assert len({len(r) for r in rows}) == 1
    # Padding is leading spaces only: each number is still one token.
    assert all(" " not in tok.strip() for r in rows for tok in r.replace("<", ",").replace(">", ",").split(","))


def test_a_column_of_zeros_is_one_wide_and_zero_prints_as_0() -> None:
    assert int_rows(np.array([[0, 7], [0, 12]]), "<{},{}>") == "<0, 7>,\n<0,12>"


def test_no_rows_is_empty_text() -> None:
    assert int_rows(np.zeros((0, 3), dtype=np.int64), "<{},{},{}>") == ""


@pytest.mark.parametrize(
    ("cells", "template", "message"),
    [
        (np.array([[1, -2, 3]]), "<{},{},{}>", "negative"),
        (np.array([[1, 2]]), "<{},{},{}>", "slots"),
        (np.array([[2**32, 0]]), "<{},{}>", "32 bits"),
        (np.array([[1.5, 2.0]]), "<{},{}>", "integers"),
        (np.array([1, 2, 3]), "<{}>", "shape"),
    ],
)
def test_what_it_cannot_format_is_an_error(cells: np.ndarray, template: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        int_rows(cells, template)
