"""The verdict table shows names as one escaped line each: a scene, backend or buffer name
(a file name, or a field of a merged run's results.json) never reaches the terminal raw."""

from __future__ import annotations

from typing import Any

from rendiff_harness.contract import results


def _row(scene: str, backend: str = "b", buffer: str = "id", status: str = "fail") -> dict[str, Any]:
    return {"scene": scene, "backend": backend, "buffer": buffer, "status": status, "reason": "r"}


def test_a_newline_or_escape_in_a_name_never_splits_a_row_or_reaches_the_terminal() -> None:
    hostile = "two\nlines\x1b[31mred\u202eflipped"
    entries = [
        _row(hostile),
        _row("ok", backend=hostile),
        _row("ok2", buffer=hostile),
        _row("ok3", status=hostile),
    ]
    table = results.format_table(entries)
    lines = table.split("\n")
    # A header, one line per entry, the count line: nothing more.
    assert len(lines) == 1 + len(entries) + 1, table
    assert not any(c in table for c in "\x1b\r\u202e"), repr(table)
    shown = "two\\nlines\\u{1b}[31mred\\u{202e}flipped"
    assert sum(shown in line for line in lines[1:-1]) == len(entries), table
    assert shown in lines[-1], lines[-1]  # the count by status escapes the status too
    # Columns still line up: every row's "fail"/status column starts where the header's does.
    start = lines[0].index("status")
    assert all(line[start:].startswith(("fail", shown)) for line in lines[1:-1]), table


def test_names_that_are_not_strings_still_make_a_table() -> None:
    # A tampered results.json may hold a number where a name belongs; the table shows it.
    table = results.format_table([_row("a"), {**_row("b"), "scene": 7}])
    assert len(table.split("\n")) == 4, table
