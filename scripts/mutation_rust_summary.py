#!/usr/bin/env python3
"""Counts a cargo-mutants run of the gate and the core's judge (docs/mutation.md).

cargo-mutants writes one `outcomes.json` per run; this reads each run's, counts the
outcomes per mutated file and writes `reports/mutation/rust.json`: per file the mutants
tested, caught, missed, timed out and unviable (a mutant that does not compile tests
nothing), the score (caught + timed out) / (tested - unviable), and every missed mutant
by name. Equivalent mutants never reach the run: `.cargo/mutants.toml` excludes them, each
with its reason, and the summary copies that list.

A missed mutant is answered by a new test (or a rewrite that removes an equivalent form),
and only the functions that changed are run again (`cargo mutants -F`): `NAME+=FOLDER`
names such a rerun of run NAME. Its outcomes replace the full run's for every function it
tested (the same file and function), and the summary keeps both: `runs` as measured, and
`after_reruns`, the per file counts with the reruns' outcomes in place.

    scripts/mutation_rust_summary.py core=OUT/core core+=OUT/core-rerun gate=OUT/gate \
        [--out FILE] [--goal 0.9]

Exit 1 when a file's score is under the goal, or a run did not finish (a partial run's
score is no measurement of the modules it did not reach).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tomllib
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
OUTCOME_KEYS = {
    "CaughtMutant": "caught",
    "MissedMutant": "missed",
    "Timeout": "timeout",
    "Unviable": "unviable",
}


def read_outcomes(
    folder: Path,
) -> tuple[dict[str, Any], list[tuple[dict[str, Any], str]]]:
    """One run's record and its (mutant, outcome kind) pairs, the baseline left out."""
    path = folder / "mutants.out" / "outcomes.json"
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise SystemExit(f"mutation_rust_summary: {path}: {e}") from None
    pairs = []
    for o in data["outcomes"]:
        scenario = o["scenario"]
        if not isinstance(scenario, dict) or "Mutant" not in scenario:
            continue  # the baseline
        kind = OUTCOME_KEYS.get(o["summary"])
        if kind is None:
            raise SystemExit(
                f"mutation_rust_summary: {path}: unknown outcome {o['summary']!r}"
            )
        pairs.append((scenario["Mutant"], kind))
    return data, pairs


def function_of(mutant: dict[str, Any]) -> tuple[str, str]:
    """The (file, function) a mutant is in: what a rerun replaces."""
    return mutant["file"], (mutant.get("function") or {}).get("function_name", "")


def count(pairs: list[tuple[dict[str, Any], str]]) -> dict[str, dict[str, Any]]:
    """Per file counts and scores of (mutant, outcome kind) pairs."""
    per_file: dict[str, dict[str, Any]] = {}
    for mutant, kind in pairs:
        row = per_file.setdefault(
            mutant["file"],
            {
                "tested": 0,
                "caught": 0,
                "missed": 0,
                "timeout": 0,
                "unviable": 0,
                "missed_mutants": [],
            },
        )
        row["tested"] += 1
        row[kind] += 1
        if kind == "missed":
            row["missed_mutants"].append(mutant["name"])
        elif kind == "timeout":
            row.setdefault("timeout_mutants", []).append(mutant["name"])
    for row in per_file.values():
        viable = row["tested"] - row["unviable"]
        row["score"] = (
            round((row["caught"] + row["timeout"]) / viable, 4) if viable else None
        )
    return dict(sorted(per_file.items()))


def describe(
    folder: Path, data: dict[str, Any], pairs: list[tuple[dict[str, Any], str]]
) -> dict[str, Any]:
    """A run as measured: its times, whether it finished, its counts per file."""
    return {
        "folder": folder.name,
        "cargo_mutants_version": data.get("cargo_mutants_version"),
        "start_time": data.get("start_time"),
        "end_time": data.get("end_time"),
        "finished": data.get("end_time") is not None,
        "total_mutants": data.get("total_mutants"),
        "per_file": count(pairs),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "runs", nargs="+", metavar="NAME[+]=FOLDER", help="a run's -o folder"
    )
    ap.add_argument("--out", type=Path, default=REPO / "reports/mutation/rust.json")
    ap.add_argument("--goal", type=float, default=0.9)
    ap.add_argument(
        "--environment", default="", help="how and where the runs were made"
    )
    args = ap.parse_args()
    config = tomllib.loads((REPO / ".cargo/mutants.toml").read_text())
    runs: dict[str, Any] = {}
    reruns: dict[str, list[dict[str, Any]]] = {}
    after: dict[str, list[tuple[dict[str, Any], str]]] = {}
    failures: list[str] = []
    for spec in args.runs:
        name, sep, folder = spec.partition("=")
        rerun = name.endswith("+")
        name = name.rstrip("+")
        if not sep or not re.fullmatch(r"[a-z0-9_-]+", name):
            raise SystemExit(
                f"mutation_rust_summary: {spec!r}: expected NAME=FOLDER or NAME+=FOLDER"
            )
        data, pairs = read_outcomes(Path(folder))
        record = describe(Path(folder), data, pairs)
        if not record["finished"]:
            failures.append(
                f"{name}{'+' if rerun else ''}: the run in {folder} did not finish"
            )
        if not rerun:
            if name in runs:
                raise SystemExit(f"mutation_rust_summary: run {name!r} given twice")
            runs[name] = record
            after[name] = pairs
            continue
        if name not in runs:
            raise SystemExit(
                f"mutation_rust_summary: {spec!r}: a rerun of {name!r} comes after its run"
            )
        redone = {function_of(m) for m, _ in pairs}
        record["functions"] = sorted(f"{file}: {fn}" for file, fn in redone)
        reruns.setdefault(name, []).append(record)
        after[name] = [
            p for p in after[name] if function_of(p[0]) not in redone
        ] + pairs
    after_counts = {name: count(pairs) for name, pairs in after.items()}
    for rows in after_counts.values():
        for file, row in rows.items():
            if row["score"] is not None and row["score"] < args.goal:
                failures.append(
                    f"{file}: {row['score']:.1%} under the goal {args.goal:.0%}"
                )
    summary = {
        "tool": "cargo-mutants",
        "environment": args.environment,
        "score": "(caught + timeout) / (tested - unviable); equivalent mutants are excluded "
        "before the run (.cargo/mutants.toml, each with its reason)",
        "goal": args.goal,
        "equivalent_excluded": config.get("exclude_re", []),
        "runs": runs,
        "reruns": reruns,
        "after_reruns": after_counts,
        "goal_met": not failures,
        "failures": failures,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(".tmp")
    tmp.write_text(json.dumps(summary, indent=1) + "\n")
    tmp.replace(args.out)
    for title, table in [
        ("as run", {n: r["per_file"] for n, r in runs.items()}),
        ("after reruns", after_counts),
    ]:
        print(f"== {title}")
        for name, rows in table.items():
            for file, row in rows.items():
                score = "n/a" if row["score"] is None else f"{row['score']:.1%}"
                print(
                    f"{name:5} {file:40} tested {row['tested']:4} caught {row['caught']:4} "
                    f"missed {row['missed']:3} timeout {row['timeout']:2} unviable {row['unviable']:3} "
                    f"score {score}"
                )
                for m in row["missed_mutants"]:
                    print(f"      missed: {m}")
    for f in failures:
        print(f"mutation_rust_summary: {f}", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
