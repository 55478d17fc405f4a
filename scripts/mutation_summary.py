"""Mutation score of the judge per module, from a mutmut run (scripts/mutation.sh, docs/mutation.md).

Reads mutmut's per-file results (MUTANTS/<module path>.py.meta: every mutant's test exit code)
and the mutants recorded as equivalent (a TOML table `mutant name = "reason"`), and writes
{"modules": {module: {mutants, killed, survived, no_tests, timeout, equivalent, score}}, ...}
where score = (killed + timeout) / (mutants - equivalent): a mutant that makes a test hang (mutmut
stops it at its time limit) is detected like one that fails it. A mutant with no test reaching it
counts as not killed. Exits 1 when a module is under the goal or an equivalent entry is stale (its mutant no
longer exists, or did not survive: a test kills it now), naming them.
"""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from pathlib import Path
from typing import Any

GOAL = 0.9
"""Issue 37: at least 90% of the non-equivalent mutants killed, per module."""

# mutmut 3's exit codes (mutmut/stats.py `status_by_exit_code`); anything else is "suspicious".
STATUS = {
    1: "killed",
    3: "killed",
    0: "survived",
    5: "no_tests",
    33: "no_tests",
    34: "skipped",
    36: "timeout",
}
STATUS.update({c: "timeout" for c in (-24, 24, 152, 255)})


def status(code: int | None) -> str:
    """What mutmut's exit code for one mutant means."""
    if code is None:
        return "not_checked"
    return STATUS.get(code, "suspicious")


def summarize(
    mutants: Path, equivalent: dict[str, str]
) -> tuple[dict[str, Any], list[str]]:
    """Per-module counts and the problems (stale entries, modules under the goal)."""
    modules: dict[str, Any] = {}
    problems: list[str] = []
    seen: set[str] = set()
    for meta in sorted(mutants.rglob("*.py.meta")):
        exit_codes: dict[str, int | None] = json.loads(meta.read_text())[
            "exit_code_by_key"
        ]
        if not exit_codes:
            continue
        module = meta.relative_to(mutants).as_posix().removesuffix(".meta")
        counts = {
            "mutants": len(exit_codes),
            "killed": 0,
            "survived": 0,
            "no_tests": 0,
            "timeout": 0,
        }
        other: dict[str, int] = {}
        survivors: list[str] = []
        equivalent_here: dict[str, str] = {}
        for name, code in sorted(exit_codes.items()):
            seen.add(name)
            s = status(code)
            if name in equivalent:
                if s not in ("survived", "no_tests"):
                    problems.append(
                        f"{name} is recorded as equivalent but was {s}: drop its entry"
                    )
                else:
                    equivalent_here[name] = equivalent[name]
                continue
            if s in counts:
                counts[s] += 1
            else:
                other[s] = other.get(s, 0) + 1
            if s in ("survived", "no_tests"):
                survivors.append(name)
        # Equivalent mutants survive by nature: they are counted apart, not as survivors.
        counts["equivalent"] = len(equivalent_here)
        judged = counts["mutants"] - counts["equivalent"]
        score = (counts["killed"] + counts["timeout"]) / judged if judged else 1.0
        modules[module] = {
            **counts,
            **other,
            "score": round(score, 4),
            "not_killed": survivors,
            "equivalent_mutants": equivalent_here,
        }
        if score < GOAL:
            problems.append(
                f"{module}: {score:.1%} of {judged} non-equivalent mutants killed, under {GOAL:.0%}"
            )
    for name in sorted(set(equivalent) - seen):
        problems.append(
            f"{name} is recorded as equivalent but mutmut made no such mutant: drop its entry"
        )
    return modules, problems


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--mutants", type=Path, required=True, help="mutmut's mutants/ folder"
    )
    ap.add_argument(
        "--equivalent",
        type=Path,
        required=True,
        help="TOML: [equivalent] mutant = reason",
    )
    ap.add_argument("-o", "--output", type=Path, required=True)
    args = ap.parse_args(argv)
    try:
        equivalent = tomllib.loads(args.equivalent.read_text())["equivalent"]
    except (OSError, tomllib.TOMLDecodeError, KeyError) as e:
        print(
            f"mutation_summary: {args.equivalent}: cannot read its [equivalent] table: {e}",
            file=sys.stderr,
        )
        return 2
    if not args.mutants.is_dir():
        print(
            f"mutation_summary: {args.mutants}: no mutmut results (run scripts/mutation.sh)",
            file=sys.stderr,
        )
        return 2
    modules, problems = summarize(args.mutants, equivalent)
    total = {
        k: sum(m[k] for m in modules.values())
        for k in ("mutants", "killed", "timeout", "survived", "no_tests", "equivalent")
    }
    out = {
        "tool": "mutmut 3.8.1",
        "goal": GOAL,
        "modules": modules,
        "total": total,
        "problems": problems,
    }
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(out, indent=1) + "\n")
    for module, m in modules.items():
        print(
            f"{module}: {m['mutants']} mutants, {m['killed']} killed, {m['survived']} survived, "
            f"{m['timeout']} timed out, {m['no_tests']} without a test, {m['equivalent']} equivalent: {m['score']:.1%}"
        )
    for p in problems:
        print(f"mutation_summary: {p}", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
