"""Command line: `python -m rendiff_harness COMMAND ...` (info, where, render, serve, compare, reference,
metamorphic, expectations, import).

The Rust core drives this as a subprocess, so the contract is machine-readable:
one JSON line on stdout for results, messages on stderr, and exit codes
0 = rendered, 2 = error (backend failed or unavailable, bad input),
3 = skipped (the backend cannot model a feature the scene requires; with
`render --visibility-only`, only a missing visibility feature skips, a missing
shading feature drops RGB alone: registry.plan; or a renderer declared by a command
exited 3, renderers/command.py). Renderers declared in the file RENDIFF_RENDERERS names
are listed and run like the built-in backends; a malformed file fails every command.
Expected failures print one line naming the backend and the problem, never a
traceback; a traceback means a bug in rendiff.

`expectations FILE` checks an expectations file exactly as `compare --expectations FILE`
loads it (expectations.load), before anything renders: nothing on stdout or stderr and
exit 0 when it is valid, else one line `rendiff_harness: FILE: problem` on stderr and
exit 2.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from .contract import exrbuf, resolved, vocab
from .contract.text import printable
from .renderers import command, registry
from .renderers.errors import BackendError, BackendSkipped

EXIT_OK, EXIT_ERROR = 0, 2
EXIT_SKIPPED = vocab.EXIT_SKIPPED


def _fail(message: str) -> int:
    # One line, whatever paths or names it quotes (a newline in --scene forged a second line).
    print(f"rendiff_harness: {printable(message)}", file=sys.stderr)
    return EXIT_ERROR


def _describe(backend: registry.Backend) -> dict[str, Any]:
    reason = backend.unavailable_reason()
    version: str | None = None
    if reason is None:
        try:
            version = backend.version()
        except BackendError as exc:
            reason = str(exc)
    return {
        "name": backend.name,
        "module": backend.key,
        "version": version,
        "features": sorted(backend.features),
        "buffers": sorted(backend.buffers),
        "peak_memory": list(backend.peak_memory),
        "waits_below": backend.waits_below,
        "available": reason is None,
        "reason": reason,
        "declared_in": str(backend.declared_in) if backend.declared_in is not None else None,
    }


def cmd_info(args: argparse.Namespace) -> int:
    """List every registered backend with its version, capabilities and availability."""
    rows = [_describe(b) for b in registry.all_backends()]
    if args.json:
        print(json.dumps({"backends": rows}))
        return EXIT_OK
    for row in rows:
        status = "available" if row["available"] else f"UNAVAILABLE: {row['reason']}"
        print(f"{row['name']}: {row['version'] or '-'}  [{status}]")
        features = ", ".join(row["features"]) or "-"
        buffers = ", ".join(row["buffers"]) or "-"
        print(f"    features: {features}   buffers: {buffers}")
        if row["declared_in"]:
            print(f"    declared in {row['declared_in']}")
    return EXIT_OK


def _settings(args: argparse.Namespace) -> dict[str, Any]:
    return {k: getattr(args, k) for k in SETTINGS if getattr(args, k, None) is not None}


def cmd_render(args: argparse.Namespace) -> int:
    """Render one resolved scene with one backend into one buffer EXR."""
    try:
        backend = registry.get(args.backend)
    except KeyError:
        return _fail(f"unknown backend {args.backend!r}; known: {', '.join(registry.known_names())}")
    if args.variant is not None:
        if backend.name != "mitsuba":
            return _fail(f"{backend.name}: --variant is not a setting of this backend (Mitsuba only)")
        # The backend's own selection mechanism, read when mitsuba is first imported (below).
        os.environ["RENDIFF_MITSUBA_VARIANT"] = args.variant
    try:
        scene = resolved.load(args.scene)
    except resolved.SceneError as exc:
        return _fail(f"{backend.name}: cannot load scene: {exc}")
    plan = registry.plan(backend, scene, visibility_only=args.visibility_only)
    if not plan.render:
        print(
            json.dumps(
                {
                    "backend": backend.name,
                    "status": vocab.RenderStatus.SKIPPED,
                    "reason": plan.reason,
                    "missing": list(plan.missing),
                }
            )
        )
        return EXIT_SKIPPED
    reason = backend.unavailable_reason()
    if reason is not None:
        return _fail(f"{backend.name} unavailable: {reason}")
    out = Path(args.out)
    if not out.parent.is_dir():
        return _fail(f"{backend.name}: output folder {out.parent} does not exist")
    settings = _settings(args)
    refused = sorted(k for k in settings if not backend.accepts(k))
    if refused:
        flags = ", ".join("--" + k.replace("_", "-") for k in refused)
        return _fail(f"{backend.name}: {flags} is not a setting of this backend (see `render --help`)")
    own_workdir = args.workdir is None
    # Scratch space beside the output, never under /tmp: `rendiff check` writes outputs into
    # its staging run folder, which it removes when interrupted (and which replaces the run
    # folder otherwise), so a harness killed before its `finally` leaves nothing behind.
    try:
        workdir = (
            Path(tempfile.mkdtemp(prefix=f".{out.name}.work-", dir=out.parent.absolute()))
            if own_workdir
            else Path(args.workdir)
        )
    except OSError as exc:
        return _fail(f"{backend.name}: cannot create a scratch folder in {out.parent}: {exc.strerror or exc}")
    command.assume_version(backend.name, args.known_version)
    try:
        version = backend.version()
        t0 = time.monotonic()
        options: dict[str, Any] = {k: v for k, v in (("spp", args.spp), ("seed", args.seed)) if v is not None}
        if plan.visibility_only:
            options[registry.VISIBILITY_ONLY] = True
        info = backend.render(scene, out, workdir, float(args.timeout), **options, **settings)
        elapsed = time.monotonic() - t0
    except BackendSkipped as exc:  # the renderer declined (a command renderer's exit 3)
        skip = {"backend": backend.name, "status": vocab.RenderStatus.SKIPPED, "reason": str(exc), "missing": []}
        print(json.dumps(skip))
        return EXIT_SKIPPED
    except BackendError as exc:  # includes BackendUnavailable
        msg = str(exc)
        return _fail(msg if msg.startswith(f"{backend.name}:") else f"{backend.name}: {msg}")
    except exrbuf.BufferError as exc:
        return _fail(f"{backend.name}: {exc}")
    finally:
        if own_workdir:
            shutil.rmtree(workdir, ignore_errors=True)
    buffers = backend.buffers & registry.VISIBILITY_BUFFERS if plan.visibility_only else backend.buffers
    result: dict[str, Any] = {
        "backend": backend.name,
        "status": vocab.RenderStatus.OK,
        "version": version,
        "time_s": elapsed,
        "info": info,
        "buffers": sorted(buffers),
        "visibility_only": plan.visibility_only,
    }
    if plan.reason:
        result["reason"] = plan.reason
    print(json.dumps(result, default=str))
    return EXIT_OK


def cmd_compare(args: argparse.Namespace) -> int:
    """Delegates to compare.py (a run's buffers -> results.json), which owns its options."""
    from .compare import main as compare_main

    return int(compare_main(list(args.rest)) or 0)


def cmd_reference(args: argparse.Namespace) -> int:
    """Delegates to renderers/mitsuba/reference.py (cached Mitsuba references), which owns its options."""
    from .renderers.mitsuba.reference import main as reference_main

    return int(reference_main(list(args.rest)) or 0)


def cmd_metamorphic(args: argparse.Namespace) -> int:
    """Delegates to judge/metamorphic.py (relations per backend), which owns its options."""
    from .judge.metamorphic import main as metamorphic_main

    return int(metamorphic_main(list(args.rest), registry.spec) or 0)


def cmd_expectations(args: argparse.Namespace) -> int:
    """Load and validate an expectations file as the comparison will; silent when it is valid."""
    from .judge import expectations

    try:
        expectations.load(args.file)
    except expectations.ExpectationsError as exc:
        return _fail(str(exc))
    return EXIT_OK


def where() -> dict[str, str]:
    """Where this harness lives: what `rendiff doctor` prints and where `rendiff check` finds
    rendiff's own data (calibration probes, expectations, references) when the harness is an
    installed package rather than a checkout (`data/` mirrors the checkout's layout)."""
    from importlib import metadata

    package = Path(__file__).resolve().parent
    try:
        version = metadata.version("rendiff-harness")
    except metadata.PackageNotFoundError:
        version = "not installed (run from a checkout)"
    return {
        "package": str(package),
        "version": version,
        "data": str(package / "data"),
        "python": sys.executable,
        "python_version": sys.version.split()[0],
    }


def cmd_where(args: argparse.Namespace) -> int:
    """Print where this harness, its data and its Python are (one JSON line with --json)."""
    found = where()
    if args.json:
        print(json.dumps(found))
    else:
        for key, value in found.items():
            print(f"{key}: {printable(value)}")
    return EXIT_OK


def cmd_import(args: argparse.Namespace) -> int:
    """Delegates to judge/importcheck (a resolved scene against independent decodes of its mesh files)."""
    from .judge.importcheck import main as import_main

    return import_main([args.resolved])


def cmd_serve(args: argparse.Namespace) -> int:
    """Answer `render` requests on stdin until it closes (worker.py: one process, many scenes)."""
    from .renderers.worker import serve

    return serve(main)


HANDLERS: dict[str, Callable[[argparse.Namespace], int]] = {
    "info": cmd_info,
    "render": cmd_render,
    "compare": cmd_compare,
    "reference": cmd_reference,
    "metamorphic": cmd_metamorphic,
    "serve": cmd_serve,
    "expectations": cmd_expectations,
    "where": cmd_where,
    "import": cmd_import,
}


def _bounded(kind: Callable[[str], Any], lo: float, hi: float) -> Callable[[str], Any]:
    """argparse type: a number of `kind` in [lo, hi], else a clear error naming the range."""

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {kind.__name__}, got {text!r}") from None
        if not (lo <= value <= hi):  # also rejects nan
            raise argparse.ArgumentTypeError(f"must be in {lo:g}..{hi:g}, got {text!r}")
        return value

    return parse


def _max_depth(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value == 0 or value < -1:
        raise argparse.ArgumentTypeError(f"must be -1 (unlimited) or >= 1, got {text!r}")
    return value


SETTINGS: dict[str, tuple[Callable[[str], Any], str]] = {
    "aa_method": (
        _bounded(int, 1, 2),
        "POV-Ray antialiasing method (+AM1 adaptive, +AM2 recursive) for the radiance passes only; "
        "IDs and depth are never antialiased (default: off, one sample at the pixel center)",
    ),
    "aa_threshold": (
        _bounded(float, 0.0, 3.0),
        "POV-Ray antialiasing threshold +A (0..3, default 0.3; needs --aa-method)",
    ),
    "aa_depth": (_bounded(int, 1, 9), "POV-Ray antialiasing depth +R (1..9, default 3; needs --aa-method)"),
    "quality": (
        _bounded(int, 0, 11),
        "POV-Ray quality level +Q for the radiance passes (0..11, default POV-Ray's 9)",
    ),
    "max_depth": (
        _max_depth,
        "Mitsuba path length limit for path-traced scenes (-1 = unlimited, or >= 1; "
        "default: the scene's integrator.max_depth)",
    ),
}
"""Backend-specific speed/quality settings (render's option `--NAME` with `_` as `-`: its parser and
help): passed only when given, refused by a backend without them. The one list of them."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m rendiff_harness", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    p_info = sub.add_parser("info", help="list backends, versions, capabilities, availability")
    p_info.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p_render = sub.add_parser("render", help="render a resolved scene into a buffer EXR")
    p_render.add_argument("--backend", required=True, help="backend name, see `info`")
    p_render.add_argument("--scene", required=True, help="resolved scene folder (rendiff export)")
    p_render.add_argument("--out", required=True, help="output EXR path (written atomically)")
    p_render.add_argument(
        "--timeout",
        type=float,
        default=600.0,
        help="seconds before a renderer process (POV-Ray, a declared command) is killed; the in-process "
        "backends (pyrender, Mitsuba) are bounded by their caller, as `rendiff check` kills the harness",
    )
    p_render.add_argument(
        "--workdir",
        default=None,
        help="scratch folder (default: a new hidden folder beside --out, removed at the end)",
    )
    p_render.add_argument(
        "--spp",
        type=int,
        default=None,
        help="samples per pixel for path-traced scenes (default: the scene's integrator.spp); "
        "ignored by backends without Monte Carlo",
    )
    p_render.add_argument("--seed", type=int, default=None, help="random seed for path-traced scenes (default 0)")
    p_render.add_argument(
        "--known-version",
        default=None,
        help="the version `info` already reported for this backend (rendiff check passes it), "
        "so a declared renderer's version command runs once per run, not once per render",
    )
    p_render.add_argument(
        "--visibility-only",
        action="store_true",
        help="render the visibility buffers (Z, id, N) but no RGB, so that a scene needing a shading feature "
        "the backend lacks is still rendered for depth and IDs (`rendiff check` passes it then); a backend "
        "whose render() has no visibility_only keyword is skipped on such scenes, as without the flag",
    )
    q = p_render.add_argument_group(
        "quality settings (speed/accuracy knobs; defaults keep the conformance contract; "
        "a backend refuses a setting it does not have)"
    )
    for name, (kind, text) in SETTINGS.items():
        q.add_argument("--" + name.replace("_", "-"), type=kind, default=None, help=text)
    q.add_argument(
        "--variant",
        choices=("scalar_rgb", "llvm_ad_rgb"),
        default=None,
        help="Mitsuba variant (default scalar_rgb; llvm_ad_rgb needs libLLVM 19: DRJIT_LIBLLVM_PATH or Debian's)",
    )
    p_where = sub.add_parser(
        "where", help="where this harness, its data (probes, expectations, references) and its Python are"
    )
    p_where.add_argument("--json", action="store_true", help="one JSON object on stdout")
    sub.add_parser(
        "serve",
        help="answer render requests, one JSON line each on stdin, until stdin closes (worker.py; "
        "`rendiff check` keeps one such worker per backend and job slot)",
    )
    p_exp = sub.add_parser(
        "expectations",
        help="check an expectations file as `compare --expectations` will read it: silent and exit 0 when "
        "it is valid, else one line naming the file and the problem, exit 2",
    )
    p_exp.add_argument("file", help="expectations TOML (e.g. tests/expectations.toml)")
    p_imp = sub.add_parser(
        "import",
        help="check a resolved scene's triangles against independent decodes of its mesh files (the `import` "
        "verdict, judge/importcheck): one line per decoder, exit 1 when one departs, 2 when DIR is unreadable",
    )
    p_imp.add_argument("resolved", help="resolved scene folder (`rendiff export SCENE -o DIR`)")
    p_compare = sub.add_parser(
        "compare", help="compare a check run's buffers, write RUN/results.json (see compare.py)", add_help=False
    )
    p_compare.add_argument("rest", nargs=argparse.REMAINDER)
    p_ref = sub.add_parser(
        "reference", help="render a cached Mitsuba reference (see renderers/mitsuba/reference.py)", add_help=False
    )
    p_ref.add_argument("rest", nargs=argparse.REMAINDER)
    p_meta = sub.add_parser(
        "metamorphic",
        help="compare variant renders with base renders per backend (see judge/metamorphic.py)",
        add_help=False,
    )
    p_meta.add_argument("rest", nargs=argparse.REMAINDER)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        # Renderers declared in RENDIFF_RENDERERS: a malformed file fails every command clearly.
        command.from_env(registry.RESERVED_NAMES)
    except command.RenderersError as exc:
        return _fail(str(exc))
    if argv[:1] == ["compare"]:
        # compare.py owns its own options; argparse.REMAINDER would reject "--run".
        return cmd_compare(argparse.Namespace(rest=argv[1:]))
    if argv[:1] == ["reference"]:
        return cmd_reference(argparse.Namespace(rest=argv[1:]))
    if argv[:1] == ["metamorphic"]:
        return cmd_metamorphic(argparse.Namespace(rest=argv[1:]))
    args = build_parser().parse_args(argv)
    return HANDLERS[args.cmd](args)


if __name__ == "__main__":
    sys.exit(main())
