"""Style and type gates: ruff (lint and format) and mypy, as configured in pyproject.toml.

They run here so that the harness's test command (scripts/test.sh, CI) fails when the code
drifts from them. The tools are the venv's own (next to sys.executable), pinned in
requirements.txt, which scripts/setup.sh installs.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

HARNESS = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent  # not resolved: the venv's bin/, where pip put the tools
REQUIREMENTS = HARNESS / "requirements.txt"
TOOLS = ("ruff", "mypy", "mutmut")

GATES = {
    "ruff check": ("ruff", "check", "."),
    "ruff format": ("ruff", "format", "--check", "."),
    "mypy": ("mypy", "rendiff_harness"),
}


def _pins() -> dict[str, str]:
    """requirements.txt as {normalized name: version}."""
    pins = {}
    for line in REQUIREMENTS.read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, version = line.split("==")
            pins[re.sub(r"[-_.]+", "-", name).lower()] = version
    return pins


def _tool(name: str) -> Path:
    exe = BIN / name
    if not exe.is_file():
        pytest.fail(f"{exe} missing: run scripts/setup.sh (it installs harness/requirements.txt)")
    return exe


@pytest.mark.parametrize("gate", sorted(GATES))
def test_gate_passes(gate: str) -> None:
    tool, *args = GATES[gate]
    proc = subprocess.run(
        [str(_tool(tool)), *args], cwd=HARNESS, capture_output=True, text=True, timeout=600, check=False
    )
    assert proc.returncode == 0, (
        f"`{' '.join(GATES[gate])}` (in harness/) reports problems:\n{proc.stdout}{proc.stderr}"
        + ("\n(fix the layout with `../.venv/bin/ruff format .`)" if gate == "ruff format" else "")
    )


@pytest.mark.parametrize("tool", TOOLS)
def test_installed_tools_are_the_pinned_ones(tool: str) -> None:
    """Another version may judge the same code differently: then re-run scripts/setup.sh."""
    want = _pins()[tool]
    out = subprocess.run(
        [str(_tool(tool)), "--version"], capture_output=True, text=True, timeout=120, check=True
    ).stdout
    assert re.match(rf"{tool},? (version )?{re.escape(want)}\b", out), (
        f"{tool}: installed {out.strip()!r}, pinned {want}"
    )


def test_pyproject_pins_are_the_requirements() -> None:
    """pyproject.toml's dependencies and dev extra are requirements.txt's pins, nothing else."""
    project = tomllib.loads((HARNESS / "pyproject.toml").read_text())["project"]
    declared = [*project["dependencies"], *project["optional-dependencies"]["dev"]]
    as_pins = {}
    for spec in declared:
        name, version = spec.split("==")
        as_pins[re.sub(r"[-_.]+", "-", name).lower()] = version
    assert as_pins == _pins()
    assert sorted(project["optional-dependencies"]["dev"]) == sorted(f"{t}=={_pins()[t]}" for t in TOOLS)
