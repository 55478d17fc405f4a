"""Statuses are spelled once, in contract/vocab.py: no module of the harness writes a verdict's or a
render's status as a raw string (`"pass"`, `"ok"`, ...), so a renamed status cannot be missed in one
place (issue 38; the Rust side holds the same rule through its `vocab` enums). Read with `ast`, so
docstrings and comments, which may name a status, do not count."""

from __future__ import annotations

import ast
from pathlib import Path

from rendiff_harness.contract.vocab import RenderStatus, Status

ROOT = Path(__file__).resolve().parents[1] / "rendiff_harness"
WORDS = {s.value for s in Status} | {s.value for s in RenderStatus}


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the string constants that are docstrings (a body's first expression)."""
    out: set[int] = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr):
            if isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str):
                out.add(id(body[0].value))
    return out


def raw_status_strings(source: str) -> list[int]:
    """Line numbers of string constants spelling a status, docstrings aside."""
    tree = ast.parse(source)
    skip = _docstrings(tree)
    return [
        n.lineno
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and n.value in WORDS and id(n) not in skip
    ]


def test_the_detector_sees_a_raw_status_and_not_a_docstring() -> None:
    assert raw_status_strings('"""pass"""\nx = 1\nif s == "fail":\n    pass\n') == [3]
    assert raw_status_strings('r = {"status": "ok"}\n') == [1]
    assert raw_status_strings("from v import Status\ns = Status.PASS\n") == []


def test_no_module_spells_a_status_outside_vocab() -> None:
    found = {
        str(p.relative_to(ROOT)): lines
        for p in sorted(ROOT.rglob("*.py"))
        if p != ROOT / "contract" / "vocab.py" and (lines := raw_status_strings(p.read_text(encoding="utf-8")))
    }
    assert found == {}, f"raw status strings (use contract.vocab.Status / RenderStatus): {found}"
