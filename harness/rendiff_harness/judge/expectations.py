"""The expectations file: known renderer bugs and per-backend declarations, each with a reason.

docs/DESIGN.md "Comparing": allowed classes (edge, tie; crack where declared) pass without any
entry, and their counts are held by the regression gate, not here. This file keeps only

* known bugs: `[[expect]]` with `status = "expected_fail"` and a reason that says what
  is wrong, optionally bounding the failing count (`interior_mismatches`,
  `crack_mismatches`: [lo, hi]); and
* per-backend declarations: `[[declare]]` with `backend`, `allows = "crack"` and a
  reason, written once per backend (for example "POV-Ray mesh2 is not watertight at
  exact ties"): that backend's crack mismatches are allowed (still counted and gated).

Format (TOML, read with tomllib):

    [[expect]]
    scene = "pixel_grid"            # a scene name, or "*" for every scene
    backend = "povray"              # a backend name
    buffer = "id"                   # "id", "Z", "N" or "RGB"
    status = "expected_fail"        # required: only known failures are recorded
    interior_mismatches = [0, 120]  # optional two-sided bound [lo, hi] on the failing count
    reason = "what is wrong"        # required

    [[declare]]
    backend = "povray"
    allows = "crack"
    reason = "why this backend is not watertight"

Verdicts (`evaluate`): failing = interior (+ crack unless the backend declares cracks).
No entry: `pass` when failing is 0, else `fail`. An `expected_fail` entry: no failing
pixel -> `unexpected_pass` (the bug is gone: remove the entry); a count above its hi ->
`fail` (worse than the known bug); below its lo -> `unexpected_pass` (tighten); else
`expected_fail`. Per-scene count pins of allowed classes (the old plain entries) are
rejected with a message saying so.

A more specific entry (exact scene name) wins over a "*" one; two entries for the same
(scene, backend, buffer) are an error. Every problem is reported as one
ExpectationsError naming the file, the entry (1-based, in file order) and the key, in one
line: values from the file are shown short and escaped (`_show`), and a file the parser
cannot take (nested too deeply, an integer of thousands of digits) is "invalid TOML".
`python -m rendiff_harness expectations FILE` runs `load` alone (__main__.py), so that a
bad file is refused before anything renders.
"""

from __future__ import annotations

import math
import reprlib
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..contract.results import Entry
from ..contract.userfile import UserFileError, read_regular
from ..contract.vocab import MismatchClass, Status

# Largest expectations file read: 1 MiB. rendiff's own is 2.5 KiB for a
# dozen entries (about 200 bytes each), so this is some 5,000 entries; a
# bigger file is a mistake, and reading a device whole would fill memory.
MAX_FILE_BYTES = 1 << 20

BUFFERS = ("id", "Z", "N", "RGB")
COUNT_KEYS = ("interior_mismatches", "crack_mismatches")
ALLOWED_CLASS_KEYS = ("edge_mismatches", "tie_mismatches")
ENTRY_KEYS = frozenset({"scene", "backend", "buffer", "status", "reason", *COUNT_KEYS})
DECLARE_KEYS = frozenset({"backend", "allows", "reason"})
DECLARABLE = ("crack",)
TOP_KEYS = frozenset({"expect", "declare"})
STATUSES = (Status.EXPECTED_FAIL,)
MAX_COUNT = 2**63 - 1  # largest bound: TOML's largest integer
INF = math.inf

Bound = tuple[int, float]  # (lo, hi); hi may be inf for expected_fail defaults

# Values from the file in messages: short (a string's first 60 characters, a list's first
# 4 items, 3 levels deep), escaped by repr, so that a message stays one readable line.
_REPR = reprlib.Repr()
_REPR.maxstring = _REPR.maxother = 60
_REPR.maxlist = _REPR.maxdict = 4
_REPR.maxlevel = 3


def _show(value: Any) -> str:
    """`value` for a message: a short repr (an integer too long for str() is described instead)."""
    try:
        return _REPR.repr(value)
    except (ValueError, RecursionError):
        return f"<{type(value).__name__} too large to show>"


def _label(value: Any) -> str:
    """A scene/backend/buffer name for a message: as it is when short and printable, else `_show`."""
    if isinstance(value, str) and value.isprintable() and len(value) <= 60:
        return value
    return _show(value)


class ExpectationsError(Exception):
    """A malformed expectations file; the message names the file, entry and key."""


@dataclass(frozen=True)
class Expectation:
    index: int  # 1-based position among the [[expect]] entries
    scene: str
    backend: str
    buffer: str
    reason: str
    expected_fail: bool
    bounds: dict[str, Bound] = field(default_factory=dict)  # only the keys given in the file

    def bound(self, key: str) -> Bound:
        if key in self.bounds:
            return self.bounds[key]
        return (0, INF) if self.expected_fail else (0, 0)

    def bound_json(self) -> dict[str, list[float | int | None]]:
        """The bounds for results.json (`bound`): every count key, given or defaulted; inf -> null."""
        out: dict[str, list[float | int | None]] = {}
        for key in COUNT_KEYS:
            lo, hi = self.bound(key)
            out[key] = [lo, None if hi == INF else int(hi)]
        return out

    def label(self) -> str:
        return f"{self.scene}/{self.backend}/{self.buffer}"


@dataclass(frozen=True)
class Declaration:
    """A backend's declared property: a class of mismatch it is allowed, with the reason."""

    index: int
    backend: str
    allows: str
    reason: str


@dataclass(frozen=True)
class Verdict:
    status: str  # pass | fail | expected_fail | unexpected_pass
    reason: str


@dataclass
class Expectations:
    path: Path | None
    entries: list[Expectation] = field(default_factory=list)
    used: set[int] = field(default_factory=set)
    declarations: list[Declaration] = field(default_factory=list)

    def declared(self, backend: str, allows: str) -> Declaration | None:
        """The backend's declaration that `allows` (e.g. "crack") is its known property."""
        for d in self.declarations:
            if d.backend == backend and d.allows == allows:
                return d
        return None

    def lookup(self, scene: str, backend: str, buffer: str) -> Expectation | None:
        """The entry for (scene, backend, buffer): an exact scene match beats "*"."""
        best: Expectation | None = None
        for e in self.entries:
            if e.backend != backend or e.buffer != buffer:
                continue
            if e.scene == scene:
                best = e
                break
            if e.scene == "*" and best is None:
                best = e
        if best is not None:
            self.used.add(best.index)
        return best

    def unused(self) -> list[Expectation]:
        return [e for e in self.entries if e.index not in self.used]


def _where(path: Path | str, index: int, entry: Mapping[str, Any] | None = None) -> str:
    label = ""
    if entry is not None:
        parts = [_label(entry.get(k, "?")) for k in ("scene", "backend", "buffer")]
        label = f" ({'/'.join(parts)})"
    return f"{path}: [[expect]] entry {index}{label}"


def _bound(value: Any, where: str, key: str) -> Bound:
    if (
        not isinstance(value, list)
        or len(value) != 2
        or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)
    ):
        raise ExpectationsError(f"{where}: key {key!r} must be a list of two integers [lo, hi], got {_show(value)}")
    lo, hi = value
    if hi > MAX_COUNT:  # TOML integers are 64-bit; tomllib takes bigger ones, which results.json cannot show
        raise ExpectationsError(f"{where}: key {key!r}: hi must be at most {MAX_COUNT}, got {_show(hi)}")
    if lo < 0 or hi < lo:
        raise ExpectationsError(f"{where}: key {key!r} must satisfy 0 <= lo <= hi, got [{_show(lo)}, {_show(hi)}]")
    return (lo, hi)


def _string(entry: Mapping[str, Any], key: str, where: str, required: bool = True) -> str | None:
    if key not in entry:
        if required:
            raise ExpectationsError(f"{where}: key {key!r} is required")
        return None
    value = entry[key]
    if not isinstance(value, str) or not value.strip():
        raise ExpectationsError(f"{where}: key {key!r} must be a non-empty string, got {_show(value)}")
    return value


def _known_keys(entry: Mapping[str, Any], allowed: frozenset[str], where: str) -> None:
    """ExpectationsError naming the first key of `entry` (in sorted order) that is not `allowed`."""
    extra = sorted(set(entry) - allowed)
    if extra:
        raise ExpectationsError(f"{where}: unknown key {_show(extra[0])} (allowed: {', '.join(sorted(allowed))})")


def parse(data: Mapping[str, Any], path: Path | str) -> list[Expectation]:
    """Validate the TOML document `data` (from `path`, for messages) into entries."""
    unknown = sorted(set(data) - TOP_KEYS)
    if unknown:
        raise ExpectationsError(
            f"{path}: unknown top-level key(s) {_show(unknown)}; only [[expect]] entries are allowed"
        )
    raw = data.get("expect", [])
    for key in ALLOWED_CLASS_KEYS:
        for i, entry in enumerate(raw if isinstance(raw, list) else [], start=1):
            if isinstance(entry, dict) and key in entry:
                raise ExpectationsError(
                    f"{_where(path, i, entry)}: key {key!r}: edge and tie mismatches are allowed classes, "
                    "passed by the verifier and held by the regression gate; per-scene counts are not recorded here"
                )
    if not isinstance(raw, list):
        raise ExpectationsError(f"{path}: 'expect' must be an array of tables ([[expect]])")
    entries: list[Expectation] = []
    seen: dict[tuple[str, str, str], int] = {}
    for i, entry in enumerate(raw, start=1):
        if not isinstance(entry, dict):
            raise ExpectationsError(f"{_where(path, i)}: must be a table")
        where = _where(path, i, entry)
        _known_keys(entry, ENTRY_KEYS, where)
        scene = _string(entry, "scene", where)
        backend = _string(entry, "backend", where)
        buffer = _string(entry, "buffer", where)
        reason = _string(entry, "reason", where)
        assert scene is not None and backend is not None and buffer is not None and reason is not None
        if buffer not in BUFFERS:
            raise ExpectationsError(f"{where}: key 'buffer' must be one of {list(BUFFERS)}, got {_show(buffer)}")
        if backend == "*":
            raise ExpectationsError(f"{where}: key 'backend' must name one backend ('*' is for scenes only)")
        status = _string(entry, "status", where, required=False)
        if status not in STATUSES:
            raise ExpectationsError(
                f"{where}: key 'status' must be \"expected_fail\" (only known bugs are recorded; allowed "
                f"classes need no entry), got {_show(status)}"
            )
        bounds = {k: _bound(entry[k], where, k) for k in COUNT_KEYS if k in entry}
        ident = (scene, backend, buffer)
        if ident in seen:
            raise ExpectationsError(f"{where}: duplicates entry {seen[ident]} for the same scene/backend/buffer")
        seen[ident] = i
        entries.append(Expectation(i, scene, backend, buffer, reason, True, bounds))
    return entries


def parse_declarations(data: Mapping[str, Any], path: Path | str) -> list[Declaration]:
    """The `[[declare]]` entries: one per (backend, allows), each with a reason."""
    raw = data.get("declare", [])
    if not isinstance(raw, list):
        raise ExpectationsError(f"{path}: 'declare' must be an array of tables ([[declare]])")
    out: list[Declaration] = []
    seen: dict[tuple[str, str], int] = {}
    for i, entry in enumerate(raw, start=1):
        where = f"{path}: [[declare]] entry {i}"
        if not isinstance(entry, dict):
            raise ExpectationsError(f"{where}: must be a table")
        _known_keys(entry, DECLARE_KEYS, where)
        backend = _string(entry, "backend", where)
        allows = _string(entry, "allows", where)
        reason = _string(entry, "reason", where)
        assert backend is not None and allows is not None and reason is not None
        if allows not in DECLARABLE:
            raise ExpectationsError(f"{where}: key 'allows' must be one of {list(DECLARABLE)}, got {_show(allows)}")
        if (backend, allows) in seen:
            raise ExpectationsError(
                f"{where}: duplicates entry {seen[(backend, allows)]} ({_label(backend)} allows {allows})"
            )
        seen[(backend, allows)] = i
        out.append(Declaration(i, backend, allows, reason))
    return out


def load(path: str | Path | None) -> Expectations:
    """Read and validate an expectations file; None gives an empty set (every mismatch fails)."""
    if path is None:
        return Expectations(None)
    path = Path(path)
    try:
        text = read_regular(path, MAX_FILE_BYTES)
    except UserFileError as exc:
        raise ExpectationsError(f"{path}: the expectations file {exc}") from None
    except FileNotFoundError:
        raise ExpectationsError(f"{path}: expectations file not found") from None
    except OSError as exc:
        raise ExpectationsError(f"{path}: cannot read expectations file: {exc.strerror or exc}") from None
    try:
        data = tomllib.loads(text.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ExpectationsError(f"{path}: not UTF-8 text: {exc}") from None
    except ValueError as exc:  # tomllib.TOMLDecodeError, or an integer of over 4300 digits
        raise ExpectationsError(f"{path}: invalid TOML: {str(exc).split(';')[0]}") from None
    except RecursionError:
        raise ExpectationsError(f"{path}: invalid TOML: nested too deeply") from None
    return Expectations(path, parse(data, path), declarations=parse_declarations(data, path))


def _counts_text(counts: Mapping[str, int]) -> str:
    return ", ".join(f"{k.replace('_mismatches', '')} {v}" for k, v in counts.items())


def _fmt_bound(b: Bound) -> str:
    lo, hi = b
    return f"[{lo}, {'inf' if hi == INF else int(hi)}]"


def failing_counts(counts: Mapping[str, int], cracks_allowed: bool) -> dict[str, int]:
    """The counts that fail a result: interior, and crack unless the backend declares cracks."""
    out = {"interior_mismatches": int(counts.get("interior_mismatches", 0) or 0)}
    if not cracks_allowed:
        out["crack_mismatches"] = int(counts.get("crack_mismatches", 0) or 0)
    return out


def evaluate(counts: Mapping[str, int], expectation: Expectation | None, cracks_allowed: bool = False) -> Verdict:
    """Verdict for one result's class counts (interior_mismatches, crack_mismatches, ...)."""
    bad = failing_counts(counts, cracks_allowed)
    if expectation is None:
        over = {k: v for k, v in bad.items() if v > 0}
        if not over:
            return Verdict(Status.PASS, "")
        hint = "" if cracks_allowed or not over.get("crack_mismatches") else " (this backend declares no cracks)"
        return Verdict(Status.FAIL, f"{_counts_text(over)} mismatches{hint}")

    e = expectation
    above = [k for k in bad if bad[k] > e.bound(k)[1]]
    below = [k for k in bad if bad[k] < e.bound(k)[0]]
    tag = f"expectation {e.index} ({e.label()}): {e.reason}"
    if above:
        detail = "; ".join(f"{k} {bad[k]} above bound {_fmt_bound(e.bound(k))}" for k in above)
        return Verdict(Status.FAIL, f"{detail} (worse than the known failure) [{tag}]")
    if all(v == 0 for v in bad.values()):
        return Verdict(
            Status.UNEXPECTED_PASS, f"no failing mismatches: the known failure is gone, remove the expectation [{tag}]"
        )
    if below:
        detail = "; ".join(f"{k} {bad[k]} below bound {_fmt_bound(e.bound(k))}" for k in below)
        return Verdict(Status.UNEXPECTED_PASS, f"{detail}: better than recorded, tighten the bound [{tag}]")
    return Verdict(Status.EXPECTED_FAIL, f"known failure ({_counts_text(bad)}): {tag}")


def apply_verdict(e: Entry, exps: Expectations, details: list[str]) -> None:
    """An entry's status, bound and reason from its counts and the matching expectation.

    `details` (examples of mismatches) join the reason of a failing or surprising verdict.
    """
    exp = exps.lookup(e.scene, e.backend, e.buffer)
    counts = {k: int(getattr(e, k) or 0) for k in COUNT_KEYS}
    declared = exps.declared(e.backend, MismatchClass.CRACK)
    verdict = evaluate(counts, exp, cracks_allowed=declared is not None)
    e.status = verdict.status
    if exp is not None:
        e.bound = exp.bound_json()
    parts = [verdict.reason] if verdict.reason else []
    if verdict.status in (Status.FAIL, Status.EXPECTED_FAIL, Status.UNEXPECTED_PASS):
        parts += details
    if declared is not None and int(e.crack_mismatches or 0) > 0:
        parts.append(f"cracks allowed: {declared.reason} (declaration {declared.index})")
    e.reason = "; ".join(parts)
