"""The harness's layout is its architecture: who may import whom (ARCHITECTURE.md, "Python harness").

* `contract/` (what rendiff and every renderer agree on) imports nothing of ours but itself;
* `judge/` (what decides a verdict) imports the contract, itself and the spec types
  (renderers/spec.py), never the registry or a backend: specs reach it through a lookup passed in;
* `renderers/` imports the contract, itself and the judge's tolerance types (judge/tolerance.py,
  judge/camera_budget.py), which a spec's precision models are made of;
* no module imports itself back through any chain (no cycle), lazy imports inside functions and
  `if TYPE_CHECKING:` blocks included: a cycle broken only by import order is still a cycle.

The top-level modules (`__main__.py`, `compare.py`) are the commands that wire the three together
and may import any of them. The graph is read from the source with `ast`, nothing is imported.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from pathlib import Path

PACKAGE = "rendiff_harness"
ROOT = Path(__file__).resolve().parents[1] / PACKAGE

ALLOWED: dict[str, tuple[str, ...]] = {
    f"{PACKAGE}.contract": (f"{PACKAGE}.contract",),
    f"{PACKAGE}.judge": (f"{PACKAGE}.contract", f"{PACKAGE}.judge", f"{PACKAGE}.renderers.spec"),
    f"{PACKAGE}.renderers": (
        f"{PACKAGE}.contract",
        f"{PACKAGE}.renderers",
        f"{PACKAGE}.judge.tolerance",
        f"{PACKAGE}.judge.camera_budget",
    ),
}
"""Each seam and the module prefixes it may import (a prefix covers the module and everything under it)."""


def module_name(path: Path, root: Path = ROOT, package: str = PACKAGE) -> str:
    rel = path.relative_to(root).with_suffix("")
    parts = [package, *rel.parts]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules(root: Path = ROOT, package: str = PACKAGE) -> dict[str, Path]:
    """Every module of the package, by dotted name."""
    return {module_name(p, root, package): p for p in sorted(root.rglob("*.py"))}


def imports(name: str, path: Path, known: Iterable[str]) -> set[str]:
    """The package's modules that module `name` imports anywhere in its source (dotted names).

    `from X import y` counts as importing X.y when that is a module, else X itself."""
    known = set(known)
    is_package = path.name == "__init__.py"
    here = name.split(".") if is_package else name.split(".")[:-1]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[: len(here) - (node.level - 1)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            targets = [f"{source}.{a.name}" if f"{source}.{a.name}" in known else source for a in node.names]
        else:
            continue
        for target in targets:
            # the deepest module of ours that the dotted name starts with
            parts = target.split(".")
            for k in range(len(parts), 0, -1):
                candidate = ".".join(parts[:k])
                if candidate in known:
                    if candidate != name:
                        out.add(candidate)
                    break
    return out


def graph(root: Path = ROOT, package: str = PACKAGE) -> dict[str, set[str]]:
    mods = modules(root, package)
    return {name: imports(name, path, mods) for name, path in mods.items()}


def _under(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def violations(edges: Mapping[str, set[str]], allowed: Mapping[str, tuple[str, ...]] = ALLOWED) -> list[str]:
    """'a imports b' for every import that crosses a seam it may not cross."""
    out = []
    for name, targets in sorted(edges.items()):
        for seam, prefixes in allowed.items():
            if not _under(name, seam):
                continue
            for target in sorted(targets):
                if not any(_under(target, p) for p in prefixes):
                    out.append(f"{name} imports {target}")
    return out


def cycles(edges: Mapping[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


# --------------------------------------------------------------------------- the package


def test_every_seam_is_a_package_with_modules() -> None:
    mods = modules()
    for seam in ALLOWED:
        assert seam in mods, f"{seam} has no __init__.py"
        assert sum(_under(m, seam) for m in mods) > 2, seam


def test_no_module_crosses_a_seam_it_may_not() -> None:
    assert violations(graph()) == []


def test_no_import_cycle() -> None:
    assert cycles(graph()) == []


def test_the_judge_reaches_backends_only_through_specs() -> None:
    """The registry and the backend folders are the renderers' own: no judge module names them."""
    edges = graph()
    judge = {m for m in edges if _under(m, f"{PACKAGE}.judge")}
    reached = set().union(*(edges[m] for m in judge))
    assert f"{PACKAGE}.renderers.spec" in reached  # the rule is about something real
    assert not {m for m in reached if _under(m, f"{PACKAGE}.renderers") and m != f"{PACKAGE}.renderers.spec"}


# --------------------------------------------------------------------------- the checker itself


def _write(root: Path, files: Mapping[str, str]) -> None:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def test_the_checker_sees_relative_lazy_and_type_checking_imports(tmp_path: Path) -> None:
    root = tmp_path / "pkg"
    _write(
        root,
        {
            "__init__.py": "",
            "contract/__init__.py": "",
            "contract/camera.py": "def f():\n    from ..judge import ids\n",  # lazy, crosses a seam
            "judge/__init__.py": "",
            "judge/ids.py": (
                "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from ..renderers import registry\n"
            ),
            "renderers/__init__.py": "",
            "renderers/spec.py": "from ..contract.camera import f\n",
            "renderers/registry.py": "from . import spec\nimport pkg.contract.camera\n",
        },
    )
    edges = graph(root, "pkg")
    assert edges["pkg.contract.camera"] == {"pkg.judge.ids"}
    assert edges["pkg.judge.ids"] == {"pkg.renderers.registry"}
    assert edges["pkg.renderers.registry"] == {"pkg.renderers.spec", "pkg.contract.camera"}
    allowed = {f"pkg.{k.split('.', 1)[1]}": tuple(f"pkg.{p.split('.', 1)[1]}" for p in v) for k, v in ALLOWED.items()}
    assert violations(edges, allowed) == [
        "pkg.contract.camera imports pkg.judge.ids",
        "pkg.judge.ids imports pkg.renderers.registry",
    ]
    assert cycles(edges) == [["pkg.contract.camera", "pkg.judge.ids", "pkg.renderers.registry", "pkg.renderers.spec"]]
