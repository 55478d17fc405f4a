"""expectations.py: parsing, validation messages and verdicts."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from rendiff_harness.judge import expectations as ex

REPO = Path(__file__).resolve().parents[2]


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "expectations.toml"
    p.write_text(text)
    return p


def _entry(**kw: object) -> str:
    base: dict[str, object] = {
        "scene": "grid",
        "backend": "povray",
        "buffer": "id",
        "reason": "a bug",
        "status": "expected_fail",
    }
    base.update(kw)
    lines = ["[[expect]]"]
    for k, v in base.items():
        if v is None:
            continue
        lines.append(f"{k} = {v!r}".replace("'", '"').replace("True", "true"))
    return "\n".join(lines) + "\n"


def _declare(**kw: object) -> str:
    base: dict[str, object] = {"backend": "povray", "allows": "crack", "reason": "not watertight"}
    base.update(kw)
    lines = ["[[declare]]"] + [f"{k} = {v!r}".replace("'", '"') for k, v in base.items() if v is not None]
    return "\n".join(lines) + "\n"


def test_repo_file_is_valid_and_pins_no_counts() -> None:
    loaded = ex.load(REPO / "tests" / "expectations.toml")
    assert loaded.path is not None
    assert all(e.reason and e.expected_fail for e in loaded.entries)
    assert all(d.reason for d in loaded.declarations)
    # Watertight backends must not declare cracks.
    assert not {"raster", "trace", "embree_robust", "pyrender"} & {d.backend for d in loaded.declarations}


def test_none_means_no_entries() -> None:
    assert ex.load(None).entries == []


def test_parse_valid_entries_and_declarations(tmp_path: Path) -> None:
    text = (
        _entry() + _entry(scene="*", buffer="Z", interior_mismatches=[0, 2]) + _declare() + _declare(backend="mitsuba")
    )
    loaded = ex.load(_write(tmp_path, text))
    a, b = loaded.entries
    assert a.expected_fail and a.bound("interior_mismatches") == (0, ex.INF)
    assert b.bound("interior_mismatches") == (0, 2)
    assert a.bound_json() == {"interior_mismatches": [0, None], "crack_mismatches": [0, None]}
    d = loaded.declared("povray", "crack")
    assert d is not None and d.reason == "not watertight"
    assert loaded.declared("pyrender", "crack") is None


def test_exact_scene_beats_wildcard_and_usage_is_tracked(tmp_path: Path) -> None:
    text = _entry(scene="*", reason="any") + _entry()
    loaded = ex.load(_write(tmp_path, text))
    assert loaded.lookup("grid", "povray", "id").index == 2
    assert loaded.lookup("other", "povray", "id").index == 1
    assert loaded.lookup("grid", "povray", "Z") is None
    assert loaded.lookup("grid", "pyrender", "id") is None
    assert loaded.unused() == []


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        (_entry(interior_mismatch=[0, 1]), ["entry 1", "'interior_mismatch'", "unknown key"]),
        (_entry(interior_mismatches=[3, 1]), ["entry 1", "'interior_mismatches'", "0 <= lo <= hi"]),
        (_entry(interior_mismatches=[-1, 1]), ["'interior_mismatches'", "0 <= lo <= hi"]),
        (_entry(interior_mismatches=[0, 1.5]), ["'interior_mismatches'", "two integers"]),
        (_entry(interior_mismatches=[0, True]), ["'interior_mismatches'", "two integers"]),
        (_entry(interior_mismatches=[1, 2, 3]), ["'interior_mismatches'", "two integers"]),
        (_entry(interior_mismatches=5), ["'interior_mismatches'", "two integers"]),
        (_entry(edge_mismatches=[0, 5]), ["entry 1", "'edge_mismatches'", "allowed classes"]),
        (_entry(tie_mismatches=[0, 5]), ["'tie_mismatches'", "allowed classes"]),
        (_entry(reason=None), ["entry 1", "'reason' is required"]),
        (_entry(reason=""), ["'reason'", "non-empty string"]),
        (_entry(buffer="rgb"), ["'buffer'", "'id', 'Z'"]),
        (_entry(backend="*"), ["'backend'"]),
        (_entry(status="known"), ["'status'", "expected_fail"]),
        (_entry(status=None), ["'status'", "only known bugs"]),
        (_entry() + _entry(), ["entry 2", "duplicates entry 1"]),
        (
            _entry() + _entry(scene="b", interior_mismatches=[0, "x"]),
            ["entry 2 (b/povray/id)", "'interior_mismatches'"],
        ),
        (_declare(allows="edge"), ["[[declare]] entry 1", "'allows'", "crack"]),
        (_declare(reason=None), ["[[declare]] entry 1", "'reason' is required"]),
        (_declare(color="red"), ["[[declare]] entry 1", "unknown key 'color'"]),
        (_declare() + _declare(), ["[[declare]] entry 2", "duplicates entry 1"]),
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


def test_special_and_oversized_files_are_refused(tmp_path: Path) -> None:
    """A FIFO or device is refused (never waited on or read whole), as is a file past the limit."""
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)
    big = tmp_path / "big.toml"
    big.write_bytes(b"#" * (ex.MAX_FILE_BYTES + 1))
    for path, needle in ((fifo, "not a regular file"), (Path("/dev/zero"), "not a regular file"), (big, "larger than")):
        with pytest.raises(ex.ExpectationsError, match=needle):
            ex.load(path)


def _exp(**kw: object) -> ex.Expectation:
    bounds = kw.pop("bounds", {})
    return ex.Expectation(1, "grid", "povray", "id", "recorded reason", True, bounds)


@pytest.mark.parametrize(
    ("counts", "exp", "cracks_allowed", "status"),
    [
        # counts: (edge, tie, crack, interior)
        ((0, 0, 0, 0), None, False, "pass"),
        ((500, 40, 0, 0), None, False, "pass"),  # allowed classes need no entry
        ((0, 0, 0, 1), None, False, "fail"),
        ((0, 0, 3, 0), None, False, "fail"),  # a crack fails a backend that declares none
        ((0, 0, 3, 0), None, True, "pass"),
        ((0, 0, 3, 1), None, True, "fail"),
        ((7, 0, 0, 3), _exp(), False, "expected_fail"),
        ((7, 2, 0, 0), _exp(), False, "unexpected_pass"),
        ((0, 0, 4, 0), _exp(), True, "unexpected_pass"),  # declared cracks are not the known bug
        ((0, 0, 0, 9), _exp(bounds={"interior_mismatches": (0, 10)}), False, "expected_fail"),
        ((0, 0, 0, 11), _exp(bounds={"interior_mismatches": (0, 10)}), False, "fail"),
        ((0, 0, 0, 4), _exp(bounds={"interior_mismatches": (5, 10)}), False, "unexpected_pass"),
    ],
)
def test_verdicts(
    counts: tuple[int, int, int, int], exp: ex.Expectation | None, cracks_allowed: bool, status: str
) -> None:
    keys = ("edge_mismatches", "tie_mismatches", "crack_mismatches", "interior_mismatches")
    v = ex.evaluate(dict(zip(keys, counts, strict=True)), exp, cracks_allowed)
    assert v.status == status, v.reason
    if exp is not None:
        assert "recorded reason" in v.reason
