"""The expectations file: known divergences of external renderers, each with a reason and an exact bound.

DESIGN.md: "A known divergence of an external renderer is recorded in an expectations
file with its reason and an exact bound; a run that does better than recorded is
flagged as an *unexpected pass* so the bound gets tightened."

Format (TOML, read with tomllib):

    [[expect]]
    scene = "pixel_grid"            # a scene name, or "*" for every scene
    backend = "povray"              # a backend name
    buffer = "id"                   # "id", "Z" or "RGB"
    edge_mismatches = [0, 120]      # two-sided bound [lo, hi] on the count (default [0, 0])
    interior_mismatches = [0, 0]    # likewise (default [0, 0])
    status = "expected_fail"        # optional: a known failure (default: a bound to pass within)
    reason = "why this differs"     # required

Verdicts (`evaluate`), with counts c = (edge, interior):

* no entry: bounds [0, 0] for both -> `pass` when both are 0, else `fail`.
* plain entry: any count above its hi -> `fail`; else any count below its lo ->
  `unexpected_pass` (the run does better than recorded: tighten the bound); else `pass`.
* `status = "expected_fail"` entry (bounds default to [0, inf): any failure is expected):
  no mismatch at all -> `unexpected_pass` (the known failure is gone: remove the entry);
  a count above hi -> `fail` (worse than the known failure); a count below lo ->
  `unexpected_pass` (tighten); else `expected_fail`.

A more specific entry (exact scene name) wins over a "*" one; two entries for the same
(scene, backend, buffer) are an error. Every problem is reported as one
ExpectationsError naming the file, the entry (1-based, in file order) and the key.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

BUFFERS = ("id", "Z", "RGB")
COUNT_KEYS = ("edge_mismatches", "interior_mismatches")
ENTRY_KEYS = frozenset({"scene", "backend", "buffer", "status", "reason", *COUNT_KEYS})
TOP_KEYS = frozenset({"expect"})
STATUSES = ("bound", "expected_fail")
INF = math.inf

Bound = tuple[int, float]  # (lo, hi); hi may be inf for expected_fail defaults


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
class Verdict:
    status: str  # pass | fail | expected_fail | unexpected_pass
    reason: str


@dataclass
class Expectations:
    path: Path | None
    entries: list[Expectation] = field(default_factory=list)
    used: set[int] = field(default_factory=set)

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
        parts = [str(entry.get(k, "?")) for k in ("scene", "backend", "buffer")]
        label = f" ({'/'.join(parts)})"
    return f"{path}: [[expect]] entry {index}{label}"


def _bound(value: Any, where: str, key: str) -> Bound:
    if (
        not isinstance(value, list)
        or len(value) != 2
        or not all(isinstance(v, int) and not isinstance(v, bool) for v in value)
    ):
        raise ExpectationsError(f"{where}: key {key!r} must be a list of two integers [lo, hi], got {value!r}")
    lo, hi = value
    if lo < 0 or hi < lo:
        raise ExpectationsError(f"{where}: key {key!r} must satisfy 0 <= lo <= hi, got [{lo}, {hi}]")
    return (lo, hi)


def _string(entry: Mapping[str, Any], key: str, where: str, required: bool = True) -> str | None:
    if key not in entry:
        if required:
            raise ExpectationsError(f"{where}: key {key!r} is required")
        return None
    value = entry[key]
    if not isinstance(value, str) or not value.strip():
        raise ExpectationsError(f"{where}: key {key!r} must be a non-empty string, got {value!r}")
    return value


def parse(data: Mapping[str, Any], path: Path | str) -> list[Expectation]:
    """Validate the TOML document `data` (from `path`, for messages) into entries."""
    unknown = sorted(set(data) - TOP_KEYS)
    if unknown:
        raise ExpectationsError(f"{path}: unknown top-level key(s) {unknown}; only [[expect]] entries are allowed")
    raw = data.get("expect", [])
    if not isinstance(raw, list):
        raise ExpectationsError(f"{path}: 'expect' must be an array of tables ([[expect]])")
    entries: list[Expectation] = []
    seen: dict[tuple[str, str, str], int] = {}
    for i, entry in enumerate(raw, start=1):
        if not isinstance(entry, dict):
            raise ExpectationsError(f"{_where(path, i)}: must be a table")
        where = _where(path, i, entry)
        extra = sorted(set(entry) - ENTRY_KEYS)
        if extra:
            raise ExpectationsError(
                f"{where}: unknown key {extra[0]!r} (allowed: {', '.join(sorted(ENTRY_KEYS))})"
            )
        scene = _string(entry, "scene", where)
        backend = _string(entry, "backend", where)
        buffer = _string(entry, "buffer", where)
        reason = _string(entry, "reason", where)
        assert scene is not None and backend is not None and buffer is not None and reason is not None
        if buffer not in BUFFERS:
            raise ExpectationsError(f"{where}: key 'buffer' must be one of {list(BUFFERS)}, got {buffer!r}")
        if backend == "*":
            raise ExpectationsError(f"{where}: key 'backend' must name one backend ('*' is for scenes only)")
        status = _string(entry, "status", where, required=False) or "bound"
        if status not in STATUSES:
            raise ExpectationsError(
                f"{where}: key 'status' must be \"expected_fail\" (or absent), got {status!r}"
            )
        bounds = {k: _bound(entry[k], where, k) for k in COUNT_KEYS if k in entry}
        if status == "bound" and not bounds:
            raise ExpectationsError(
                f"{where}: give at least one bound ({', '.join(COUNT_KEYS)}) or status = \"expected_fail\""
            )
        key = (scene, backend, buffer)
        if key in seen:
            raise ExpectationsError(f"{where}: duplicates entry {seen[key]} for the same scene/backend/buffer")
        seen[key] = i
        entries.append(
            Expectation(i, scene, backend, buffer, reason, status == "expected_fail", bounds)
        )
    return entries


def load(path: str | Path | None) -> Expectations:
    """Read and validate an expectations file; None gives an empty set (every mismatch fails)."""
    if path is None:
        return Expectations(None)
    path = Path(path)
    try:
        text = path.read_bytes()
    except FileNotFoundError:
        raise ExpectationsError(f"{path}: expectations file not found") from None
    except OSError as exc:
        raise ExpectationsError(f"{path}: cannot read expectations file: {exc.strerror or exc}") from None
    try:
        data = tomllib.loads(text.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ExpectationsError(f"{path}: not UTF-8 text: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ExpectationsError(f"{path}: invalid TOML: {exc}") from None
    return Expectations(path, parse(data, path))


def _counts_text(counts: Mapping[str, int]) -> str:
    return ", ".join(f"{k.replace('_mismatches', '')} {v}" for k, v in counts.items())


def _fmt_bound(b: Bound) -> str:
    lo, hi = b
    return f"[{lo}, {'inf' if hi == INF else int(hi)}]"


def evaluate(counts: Mapping[str, int], expectation: Expectation | None) -> Verdict:
    """Verdict for one result's counts (keys edge_mismatches, interior_mismatches)."""
    if expectation is None:
        over = {k: v for k, v in counts.items() if v > 0}
        if not over:
            return Verdict("pass", "")
        return Verdict("fail", f"{_counts_text(over)} mismatches; no expectation allows any")

    e = expectation
    above = [k for k in COUNT_KEYS if counts.get(k, 0) > e.bound(k)[1]]
    below = [k for k in COUNT_KEYS if counts.get(k, 0) < e.bound(k)[0]]
    tag = f"expectation {e.index} ({e.label()}): {e.reason}"
    if above:
        detail = "; ".join(f"{k} {counts.get(k, 0)} above bound {_fmt_bound(e.bound(k))}" for k in above)
        worse = " (worse than the known failure)" if e.expected_fail else ""
        return Verdict("fail", f"{detail}{worse} [{tag}]")
    if e.expected_fail and all(counts.get(k, 0) == 0 for k in COUNT_KEYS):
        return Verdict("unexpected_pass", f"no mismatches: the known failure is gone, remove the expectation [{tag}]")
    if below:
        detail = "; ".join(f"{k} {counts.get(k, 0)} below bound {_fmt_bound(e.bound(k))}" for k in below)
        return Verdict("unexpected_pass", f"{detail}: better than recorded, tighten the bound [{tag}]")
    if e.expected_fail:
        return Verdict("expected_fail", f"known failure ({_counts_text(counts)}): {tag}")
    return Verdict("pass", tag)
