"""What judging one buffer leaves for its verdict: examples, notes and the heat map (`Judged`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

EXAMPLES = 3  # example pixels quoted in a failure's reason


@dataclass
class Judged:
    """A buffer compared, its counts already in its entry: what the verdict and the heat map need."""

    details: list[str]  # examples of mismatches, for the reason of a failing verdict
    notes: list[str] = field(default_factory=list)  # always added to the reason, after the verdict
    heat_map: Callable[[Path], None] | None = None  # writes the diff PNG at the path given
