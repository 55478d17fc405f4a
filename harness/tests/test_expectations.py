"""expectations.py: parsing, validation messages and verdicts."""

from __future__ import annotations

from pathlib import Path

import pytest

from rendiff_harness import expectations as ex

REPO = Path(__file__).resolve().parents[2]


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "expectations.toml"
    p.write_text(text)
    return p


def _entry(**kw: object) -> str:
    base: dict[str, object] = {"scene": "grid", "backend": "povray", "buffer": "id", "reason": "ties",
                               "edge_mismatches": [0, 5]}
    base.update(kw)
    lines = ["[[expect]]"]
    for k, v in base.items():
        if v is None:
            continue
        lines.append(f"{k} = {v!r}".replace("'", '"').replace("True", "true"))
    return "\n".join(lines) + "\n"


def test_repo_file_is_valid() -> None:
    loaded = ex.load(REPO / "tests" / "expectations.toml")
    assert loaded.path is not None
    assert all(e.reason for e in loaded.entries)


def test_none_means_no_entries() -> None:
    assert ex.load(None).entries == []


def test_parse_valid_entries(tmp_path: Path) -> None:
    text = _entry() + _entry(scene="*", buffer="Z", edge_mismatches=None, interior_mismatches=[0, 2]) + _entry(
        backend="mitsuba", status="expected_fail", edge_mismatches=None
    )
    loaded = ex.load(_write(tmp_path, text))
    a, b, c = loaded.entries
    assert (a.index, a.bound("edge_mismatches"), a.bound("interior_mismatches")) == (1, (0, 5), (0, 0))
    assert b.bound("edge_mismatches") == (0, 0) and b.bound("interior_mismatches") == (0, 2)
    assert c.expected_fail and c.bound("edge_mismatches") == (0, ex.INF)
    assert c.bound_json() == {"edge_mismatches": [0, None], "interior_mismatches": [0, None]}


def test_exact_scene_beats_wildcard_and_usage_is_tracked(tmp_path: Path) -> None:
    text = _entry(scene="*", edge_mismatches=[0, 9], reason="any") + _entry(edge_mismatches=[0, 1])
    loaded = ex.load(_write(tmp_path, text))
    assert loaded.lookup("grid", "povray", "id").index == 2
    assert loaded.lookup("other", "povray", "id").index == 1
    assert loaded.lookup("grid", "povray", "Z") is None
    assert loaded.lookup("grid", "pyrender", "id") is None
    assert loaded.unused() == []


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        (_entry(edge_mismatch=[0, 1]), ["entry 1", "'edge_mismatch'", "unknown key"]),
        (_entry(edge_mismatches=[3, 1]), ["entry 1", "'edge_mismatches'", "0 <= lo <= hi"]),
        (_entry(edge_mismatches=[-1, 1]), ["'edge_mismatches'", "0 <= lo <= hi"]),
        (_entry(edge_mismatches=[0, 1.5]), ["'edge_mismatches'", "two integers"]),
        (_entry(edge_mismatches=[0, True]), ["'edge_mismatches'", "two integers"]),
        (_entry(edge_mismatches=[1, 2, 3]), ["'edge_mismatches'", "two integers"]),
        (_entry(edge_mismatches=5), ["'edge_mismatches'", "two integers"]),
        (_entry(reason=None), ["entry 1", "'reason' is required"]),
        (_entry(reason=""), ["'reason'", "non-empty string"]),
        (_entry(buffer="rgb"), ["'buffer'", "'id', 'Z'"]),
        (_entry(backend="*"), ["'backend'"]),
        (_entry(status="known"), ["'status'", "expected_fail"]),
        (_entry(edge_mismatches=None), ["at least one bound"]),
        (_entry() + _entry(), ["entry 2", "duplicates entry 1"]),
        (_entry() + _entry(scene="b", interior_mismatches=[0, "x"]), ["entry 2 (b/povray/id)", "'interior_mismatches'"]),
        ("[expect]\nscene = 1\n", ["'expect' must be an array"]),
        ("[[expectation]]\n", ["unknown top-level key", "expectation"]),
        ("[[expect]\n", ["invalid TOML"]),
    ],
)
def test_malformed_files_name_file_entry_and_key(tmp_path: Path, text: str, needles: list[str]) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(ex.ExpectationsError) as info:
        ex.load(path)
    msg = str(info.value)
    assert msg.startswith(str(path))
    for n in needles:
        assert n in msg, msg


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ex.ExpectationsError, match="not found"):
        ex.load(tmp_path / "nope.toml")


def _exp(**kw: object) -> ex.Expectation:
    bounds = kw.pop("bounds", {})
    return ex.Expectation(1, "grid", "povray", "id", "recorded reason", bool(kw.pop("xfail", False)), bounds)


C = ex.COUNT_KEYS


@pytest.mark.parametrize(
    ("counts", "exp", "status"),
    [
        ((0, 0), None, "pass"),
        ((1, 0), None, "fail"),
        ((0, 1), None, "fail"),
        ((3, 0), _exp(bounds={"edge_mismatches": (0, 5)}), "pass"),
        ((5, 0), _exp(bounds={"edge_mismatches": (5, 5)}), "pass"),
        ((6, 0), _exp(bounds={"edge_mismatches": (0, 5)}), "fail"),
        ((3, 1), _exp(bounds={"edge_mismatches": (0, 5)}), "fail"),  # interior defaults to [0, 0]
        ((2, 0), _exp(bounds={"edge_mismatches": (3, 5)}), "unexpected_pass"),
        ((2, 1), _exp(bounds={"edge_mismatches": (3, 5)}), "fail"),  # fail dominates
        ((4, 2), _exp(bounds={"edge_mismatches": (0, 5), "interior_mismatches": (2, 2)}), "pass"),
        ((4, 1), _exp(bounds={"edge_mismatches": (0, 5), "interior_mismatches": (2, 2)}), "unexpected_pass"),
        ((7, 3), _exp(xfail=True), "expected_fail"),
        ((0, 0), _exp(xfail=True), "unexpected_pass"),
        ((0, 9), _exp(xfail=True, bounds={"interior_mismatches": (0, 10)}), "expected_fail"),
        ((0, 11), _exp(xfail=True, bounds={"interior_mismatches": (0, 10)}), "fail"),
        ((0, 4), _exp(xfail=True, bounds={"interior_mismatches": (5, 10)}), "unexpected_pass"),
    ],
)
def test_verdicts(counts: tuple[int, int], exp: ex.Expectation | None, status: str) -> None:
    v = ex.evaluate(dict(zip(C, counts)), exp)
    assert v.status == status, v.reason
    if exp is not None:
        assert "recorded reason" in v.reason
    if status == "unexpected_pass" and exp is not None and not (exp.expected_fail and counts == (0, 0)):
        assert "tighten" in v.reason
