"""SDL rows of non-negative integers, formatted by numpy in one pass.

A `mesh2` of a million triangles has millions of integers (face indices, texture indices, ID
codes), and formatting them one Python `str.format` call per row took about 0.9 s per block on
`million` (1.3M rows), twice per render (ID and depth passes). Here every cell becomes digits by
integer arithmetic on whole columns, right-aligned in its column's width with leading spaces,
which SDL reads like any other whitespace: `<  12,3456,  789>` is `<12,3456,789>` to POV-Ray.
"""

from __future__ import annotations

import numpy as np

SEPARATOR = b",\n"
"""Between rows (none after the last), as the blocks' counts and closing braces expect."""


def _write_column(out: np.ndarray, start: int, width: int, column: np.ndarray) -> None:
    """`column`'s cells into `out[:, start:start + width]` as right-aligned ASCII digits.

    Digit by digit from the right, on uint32 copies (numpy divides by a constant without a
    division instruction): a few small temporaries per digit instead of (N, width) int64 ones,
    whose fresh pages cost more to clear than the digits cost to compute.
    """
    rest = column.astype(np.uint32)
    for pos in range(width - 1, -1, -1):
        quotient = rest // np.uint32(10)
        digit = (rest - quotient * np.uint32(10)).astype(np.uint8) + np.uint8(ord("0"))
        if pos < width - 1:
            # Nothing left of the number: a space, but never in the last place (0 prints "0").
            digit[rest == 0] = ord(" ")
        out[:, start + pos] = digit
        rest = quotient


def int_rows(cells: np.ndarray, template: str) -> str:
    """`template` filled row by row from `cells` (N, k) and the rows joined by ",\\n".

    Each `{}` in `template` is a slot (k of them); everything else is literal text, braces
    included (`texture{pigment{rgb<{},{},0>}}` has two slots: no `str.format` escapes). Each
    row reads as `template` with the row's values in its slots, but for the spaces that pad
    each cell to its column's width.
    """
    table = np.asarray(cells)
    if table.ndim != 2:
        raise ValueError(f"int_rows: cells must be (N, k), got shape {table.shape}")
    literals = template.split("{}")
    if len(literals) != table.shape[1] + 1:
        raise ValueError(f"int_rows: template {template!r} does not have {table.shape[1]} slots")
    n = table.shape[0]
    if n == 0:
        return ""
    if not np.issubdtype(table.dtype, np.integer):
        raise ValueError(f"int_rows: cells must be integers, got {table.dtype}")
    values = table.astype(np.int64)
    if (values < 0).any():
        raise ValueError(f"int_rows: negative value {int(values.min())} in an SDL index")
    if int(values.max()) >= 2**32:
        raise ValueError(f"int_rows: value {int(values.max())} does not fit 32 bits")
    widths = [len(str(int(values[:, j].max()))) for j in range(values.shape[1])]
    texts = [t.encode("ascii") for t in literals]
    texts[-1] += SEPARATOR
    row = sum(map(len, texts)) + sum(widths)
    out = np.empty((n, row), dtype=np.uint8)
    at = 0
    for j, text in enumerate(texts):
        if text:
            out[:, at : at + len(text)] = np.frombuffer(text, dtype=np.uint8)
            at += len(text)
        if j < len(widths):
            _write_column(out, at, widths[j], values[:, j])
            at += widths[j]
    return out.tobytes()[: n * row - len(SEPARATOR)].decode("ascii")
