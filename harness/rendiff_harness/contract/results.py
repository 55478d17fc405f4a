"""RUN/results.json: one typed record per verdict (`Entry`), the document, writing it, the table.

Every entry has the fields of `Entry` up to `images` (`COMMON_FIELDS`, docs/run-format.md),
then the fields only its buffer has (`Entry.own_fields`, from judge/buffers.py's buffer table:
`explanations` on id, Z and N, `max_angle_rad` on N, the radiance fields on RGB), then any
further fields (`Entry.extra`: calibration's measurements on `camera` entries).
`Entry.to_json()` is the entry exactly as results.json holds it.

Skipped and error entries carry null counts (`blank_if_not_compared`): "not compared",
never "0 mismatches".
"""

from __future__ import annotations

import json
import math
import unicodedata
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from . import atomic, vocab
from .text import printable
from .vocab import FAILING_STATUSES, Buffer, Status

RESULTS_FORMAT = vocab.RESULTS_FORMAT

COMMON_FIELDS = (
    "scene",
    "backend",
    "buffer",
    "status",
    "reason",
    "pixels",
    "edge_mismatches",
    "tie_mismatches",
    "crack_mismatches",
    "interior_mismatches",
    "mask_mismatches",
    "max_abs_error",
    "mean_abs_error",
    "max_rel_error",
    "compared_pixels",
    "tolerance",
    "bound",
    "time_s",
    "version",
    "command",
    "images",
)
"""The fields every entry has, in results.json's order."""

NUMERIC_FIELDS = COMMON_FIELDS[COMMON_FIELDS.index("pixels") : COMMON_FIELDS.index("compared_pixels") + 1]
"""The counts and errors that are null on an entry that was not compared."""

RGB_FIELDS = ("failing_pixels", "min_p", "alpha", "cluster_failures", "flip_mean")
"""The RGB fields that are null on an RGB entry that was not compared."""

OPTIONAL_FIELDS = frozenset({"explanations"})
"""Buffer fields written only when set (id: when compared; Z: when some pixel is interior; N: when some normal
is off)."""

NOT_COMPARED = (Status.SKIPPED, Status.ERROR)


def finite(x: float) -> float | None:
    """x as a float, or None when it is inf or nan (results.json holds no non-finite numbers)."""
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass
class Entry:
    """One results.json entry: a (scene, backend, buffer) verdict and what it was judged on."""

    scene: str
    backend: str
    buffer: str
    status: str = Status.ERROR
    reason: str = ""
    pixels: int | None = 0
    edge_mismatches: int | None = 0
    tie_mismatches: int | None = 0
    crack_mismatches: int | None = 0
    interior_mismatches: int | None = 0
    mask_mismatches: int | None = 0
    max_abs_error: float | None = 0.0
    mean_abs_error: float | None = 0.0
    max_rel_error: float | None = 0.0
    compared_pixels: int | None = 0
    tolerance: str = ""
    bound: Any = None
    time_s: float | None = None
    version: str | None = None
    command: str | None = None
    images: dict[str, str] = field(default_factory=dict)
    # Buffer-specific fields: written after `images`, those in `own_fields` only, in that order.
    own_fields: tuple[str, ...] = field(default=(), repr=False)
    max_angle_rad: float | None = None  # N
    explanations: list[dict[str, Any]] | None = None  # id, Z, N (OPTIONAL_FIELDS)
    mode: str | None = None  # RGB: "deterministic" | "statistical"
    failing_pixels: int | None = 0
    min_p: float | None = None
    alpha: float | None = None
    cluster_failures: int | None = None
    flip_mean: float | None = None
    flip_note: str = ""
    interior_max_abs_error: float | None = None  # RGB: largest |test - reference| at an interior failing pixel
    extra: dict[str, Any] = field(default_factory=dict)  # written last (calibration's measured fields)

    def record_classes(self, edge: int, tie: int, crack: int, interior: int) -> None:
        """The mismatch counts of the verifier's classes, as a comparison found them."""
        self.edge_mismatches, self.tie_mismatches = edge, tie
        self.crack_mismatches, self.interior_mismatches = crack, interior

    def record_errors(self, max_abs: float, mean_abs: float, max_rel: float) -> None:
        """The error fields, as a comparison measured them (a non-finite one is null)."""
        self.max_abs_error, self.mean_abs_error = finite(max_abs), finite(mean_abs)
        self.max_rel_error = finite(max_rel)

    @classmethod
    def for_render(
        cls,
        scene: str,
        backend: str,
        buffer: str,
        render: Mapping[str, Any],
        own_fields: tuple[str, ...] = (),
        *,
        status: str = Status.ERROR,
        reason: str = "",
    ) -> Entry:
        """An entry with the render's time/version/command; counts start at 0, status `error`.

        `blank_if_not_compared` nulls the counts when the entry ends skipped/error.
        """
        t = render.get("time_s")
        version = render.get("version")
        command = render.get("command")
        return cls(
            scene,
            backend,
            buffer,
            status=status,
            reason=reason,
            time_s=finite(t) if isinstance(t, (int, float)) and not isinstance(t, bool) else None,
            version=version if isinstance(version, str) else None,
            command=command if isinstance(command, str) else None,
            own_fields=own_fields,
        )

    def to_json(self) -> dict[str, Any]:
        """The entry as results.json holds it: COMMON_FIELDS, then own_fields, then extra."""
        out = {name: getattr(self, name) for name in COMMON_FIELDS}
        for name in self.own_fields:
            value = getattr(self, name)
            if value is None and name in OPTIONAL_FIELDS:
                continue
            out[name] = value
        out.update(self.extra)
        return out

    def add_reason(self, note: str) -> None:
        self.reason = f"{self.reason}; {note}" if self.reason else note

    def blank_if_not_compared(self) -> Entry:
        """Skipped and error entries carry null counts: "not compared", never "0 mismatches"."""
        if self.status in NOT_COMPARED:
            for k in NUMERIC_FIELDS:
                setattr(self, k, None)
            if self.buffer == Buffer.RGB:
                for k in RGB_FIELDS:
                    setattr(self, k, None)
        return self


def base_entry(scene: str, backend: str, buffer: str, render: Mapping[str, Any]) -> dict[str, Any]:
    """`Entry.for_render(...).to_json()`: a results.json entry with every common field present."""
    return Entry.for_render(scene, backend, buffer, render).to_json()


def blank_if_not_compared(entry: dict[str, Any]) -> dict[str, Any]:
    """`Entry.blank_if_not_compared` for an entry already in its JSON form."""
    if entry["status"] in NOT_COMPARED:
        for k in NUMERIC_FIELDS:
            entry[k] = None
        if entry["buffer"] == Buffer.RGB:
            for k in RGB_FIELDS:
                entry[k] = None
    return entry


# --------------------------------------------------------------------------- the document


class UnusedExpectation(Protocol):
    """An expectation that matched no compared result, as results.json lists it (expectations.py)."""

    @property
    def index(self) -> int: ...
    @property
    def scene(self) -> str: ...
    @property
    def backend(self) -> str: ...
    @property
    def buffer(self) -> str: ...


def document(
    reference: str,
    calibration: Mapping[str, Any],
    expectations_path: str | Path | None,
    unused: Sequence[UnusedExpectation],
    results: list[dict[str, Any]],
) -> dict[str, Any]:
    """RUN/results.json's top level (docs/run-format.md)."""
    return {
        "format": RESULTS_FORMAT,
        "reference": reference,
        "calibration": calibration,
        "expectations": str(expectations_path) if expectations_path is not None else None,
        "unused_expectations": [
            {"entry": e.index, "scene": e.scene, "backend": e.backend, "buffer": e.buffer} for e in unused
        ],
        "results": results,
    }


def write_results(run: Path, doc: Mapping[str, Any], name: str = "results.json") -> Path:
    """Write RUN/<name> (default results.json) atomically (temp file in RUN + os.replace)."""
    path = run / name
    text = json.dumps(doc, indent=1, allow_nan=False) + "\n"
    atomic.write_text_atomically(path, text, prefix=".results.", suffix=".json.tmp")
    return path


def fixed_width(header: Sequence[str], rows: Sequence[Sequence[str]], numeric: range) -> list[str]:
    """Rows as aligned text: columns in `numeric` right-aligned, others left-aligned, the last
    column, when it is free text, not padded. The one table layout of the project: `rendiff check`'s
    verdict table (`format_table`) and the metamorphic table use it. Every cell is shown through
    `text.printable`: scene, backend and buffer names come from file names and, in a merge, from
    other runs' results.json, and a newline there once split a row and an escape sequence
    reached the terminal."""
    n = len(header)
    header = [printable(c) for c in header]
    rows = [[printable(c) for c in row] for row in rows]
    widths = [max(len(header[i]), *(len(row[i]) for row in rows)) if rows else len(header[i]) for i in range(n)]
    lines = []
    for row in [header, *rows]:
        cells = [
            row[i]
            if i == n - 1 and i not in numeric
            else row[i].rjust(widths[i])
            if i in numeric
            else row[i].ljust(widths[i])
            for i in range(n)
        ]
        lines.append("  ".join(cells).rstrip())
    return lines


def count_line(results: Sequence[Mapping[str, Any]], what: str = "entries") -> str:
    """`N entries: fail 1, pass 3`: the count per status under a table."""
    counts: dict[str, int] = {}
    for r in results:
        status = printable(str(r["status"]))
        counts[status] = counts.get(status, 0) + 1
    return f"{len(results)} {what}: " + (", ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "none")


def _table_order(r: Mapping[str, Any]) -> tuple[bool, bool, str, str, str]:
    """Failures first, then skips, then the rest, each by scene, backend and buffer."""
    return (
        r["status"] not in FAILING_STATUSES,
        r["status"] != Status.SKIPPED,
        str(r["scene"]),  # str: a tampered results.json may hold a number; sorting must not raise
        str(r["backend"]),
        str(r["buffer"]),
    )


def format_table(results: Sequence[Mapping[str, Any]]) -> str:
    """The verdict table `rendiff check`, `merge` and `compare` print: one row per entry,
    failures first, then a count per status. Mismatch counts by class (docs/verifier.md), Z's
    mask mismatches and the largest relative error where they mean something, and the reason."""
    header = ("scene", "backend", "buf", "status", "edge", "tie", "crack", "interior", "mask", "max_rel", "note")
    rows = []
    for r in sorted(results, key=_table_order):
        compared = r["status"] not in NOT_COMPARED

        def count(key: str, r: Mapping[str, Any] = r, compared: bool = compared) -> str:
            v = r.get(key)
            return str(v) if compared and isinstance(v, int) else "-"

        rel = r.get("max_rel_error")
        if r["buffer"] == Buffer.RGB and r.get("mode") == "statistical":
            rel = None  # the means' relative difference is noise here; min_p is in results.json
        rows.append(
            (
                str(r["scene"]),
                str(r["backend"]),
                str(r["buffer"]),
                str(r["status"]),
                count("edge_mismatches"),
                count("tie_mismatches"),
                count("crack_mismatches"),
                count("interior_mismatches"),
                count("mask_mismatches") if r["buffer"] == Buffer.Z else "-",
                f"{rel:.2g}" if compared and r["buffer"] in (Buffer.Z, Buffer.RGB) and rel is not None else "-",
                _short(str(r.get("reason", "")).split("\n", 1)[0]),
            )
        )
    return "\n".join([*fixed_width(header, rows, range(4, 10)), count_line(results)])


def _short(text: str, limit: int = 90) -> str:
    """A verdict's reason for the table: control characters escaped (reasons carry renderers'
    stderr, which may hold any text, terminal escapes included), cut to `limit` characters
    with "..." when longer."""
    clean = "".join(c.encode("unicode_escape").decode("ascii") if unicodedata.category(c) == "Cc" else c for c in text)
    return clean if len(clean) <= limit else clean[: limit - 3] + "..."
