"""`python -m rendiff_harness compare --run RUN [--expectations FILE] [--references DIR] [--jobs N] [--stream]`:
a check run's buffers -> RUN/results.json.

Reads RUN/manifest.json (docs/run-format.md, written by `rendiff check`; contract/manifest.py),
judges every scene (judge/scene.py: every backend's buffers against the reference's, normally
"raster", buffer by buffer as judge/buffers.py's `BUFFER_TABLE` says), the scenes spread over
`--jobs` processes (with `--stream`, each scene from the moment `rendiff check` has its last render
in, while others still render), then the camera calibration and its consequences (judge/calibration.py),
writes RUN/results.json atomically (contract/results.py) and RUN/scenes/<scene>/diff/*.png, and
prints a compact table. Each backend is judged with its `BackendSpec` (renderers/registry.py's
`spec`, the one lookup this module hands the judge).

What each buffer's verdict means (docs/DESIGN.md "Comparing", docs/verifier.md): an ID mismatch
is classed by the verifier as edge, tie, crack or interior (judge/ids.py, judge/verify.py); Z is
compared where both sides see the same prim, within the backend's tolerance model
(judge/depth.py); N against the winding convention (judge/normals.py); RGB deterministically
or statistically (judge/rgb.py, judge/radiance.py); expectations turn the counts into pass /
fail / expected_fail / unexpected_pass (judge/expectations.py). Skipped and error renders are
copied through; a missing reference makes every entry of its scene an error.

The Rust side decides pass/fail from results.json, so this exits 0 whenever it could write
results; 2 when the manifest (or the expectations file, or results.json itself) cannot be
read/written, with one line naming the file.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from pathlib import Path
from typing import Any

from .contract.manifest import ManifestError, load_manifest
from .contract.results import Entry, document, format_table, write_results
from .contract.text import printable
from .judge import calibration, expectations, scene
from .renderers import registry

EXIT_OK, EXIT_ERROR = 0, 2


_PROCESS_EXPECTATIONS: dict[str, expectations.Expectations] = {}
"""A comparing process's own copy of the expectations, loaded once per process (`_scene_task`)."""


def _scene_task(
    run: Path,
    scene_entry: Mapping[str, Any],
    reference: str,
    expectations_path: str | Path | None,
    images: bool,
    references_dir: Path | None,
) -> tuple[list[Entry], set[int]]:
    """One scene in a pool process: its entries and the expectations it used."""
    key = str(expectations_path)
    if key not in _PROCESS_EXPECTATIONS:
        _PROCESS_EXPECTATIONS[key] = expectations.load(expectations_path)
    exps = _PROCESS_EXPECTATIONS[key]
    exps.used.clear()
    entries = scene.compare_scene(run, scene_entry, reference, exps, registry.spec, images, references_dir)
    return entries, set(exps.used)


def _scene_cost(scene_entry: Mapping[str, Any]) -> float:
    """How long a scene took to render (all backends): its comparison grows with the same size."""
    return float(sum(float(r.get("time_s") or 0.0) for r in scene_entry.get("renders", [])))


Comparison = Future[tuple[list[Entry], set[int]]]
"""One scene's comparison: its entries and the expectations it used."""


class Comparer:
    """Scenes judged as they are handed in: in this process when `jobs` <= 1, else in that many
    processes (fresh interpreters: `spawn`, never a fork of a process holding OpenImageIO's
    threads). Scenes are independent, so the order they are handed in changes no verdict."""

    def __init__(
        self,
        run: Path,
        expectations_path: str | Path | None,
        exps: expectations.Expectations,
        images: bool,
        references_dir: Path | None,
        jobs: int,
    ) -> None:
        self.run, self.expectations_path, self.exps = run, expectations_path, exps
        self.images, self.references_dir = images, references_dir
        context = multiprocessing.get_context("spawn")
        self.pool = ProcessPoolExecutor(max_workers=jobs, mp_context=context) if jobs > 1 else None

    def __enter__(self) -> Comparer:
        return self

    def __exit__(self, *_: object) -> None:
        if self.pool is not None:
            self.pool.shutdown(cancel_futures=True)

    def submit(self, scene_entry: Mapping[str, Any], reference: str) -> Comparison:
        """Starts judging one scene (in this process: judges it now, into `exps` itself)."""
        args = (self.run, scene_entry, reference)
        if self.pool is not None:
            opts = (self.expectations_path, self.images, self.references_dir)
            return self.pool.submit(_scene_task, *args, *opts)
        done: Comparison = Future()
        try:
            entries = scene.compare_scene(*args, self.exps, registry.spec, self.images, self.references_dir)
            done.set_result((entries, set()))
        except Exception as exc:  # noqa: BLE001 - raised again by `result()`, as a pool's would be
            done.set_exception(exc)
        return done


def compare_scenes(
    scenes: Sequence[Mapping[str, Any]],
    reference: str,
    comparer: Comparer,
    early: Mapping[str, tuple[str, Mapping[str, Any], Comparison]] | None = None,
) -> list[Entry]:
    """Every scene's entries, in manifest order; the scenes not judged yet are handed in the
    costliest first. `early` holds comparisons started while the run was still rendering
    (`read_stream`), by scene name: one is used only when its reference and scene entry are
    exactly the manifest's, so a verdict always judges what the manifest records. `exps.used`
    gathers what each comparison matched, so unused expectations are reported as in a
    sequential run."""
    early = early or {}
    order = sorted(range(len(scenes)), key=lambda i: -_scene_cost(scenes[i]))
    futures: dict[int, Comparison] = {}
    for i in order:
        got = early.get(scenes[i]["scene"])
        if got is not None and got[0] == reference and got[1] == scenes[i]:
            futures[i] = got[2]
        else:
            futures[i] = comparer.submit(scenes[i], reference)
    done: dict[int, list[Entry]] = {}
    for i in range(len(scenes)):
        entries, used = futures[i].result()
        done[i] = entries
        comparer.exps.used |= used
    return [e for i in range(len(scenes)) for e in done[i]]


def read_stream(lines: Iterable[str], comparer: Comparer) -> dict[str, tuple[str, Mapping[str, Any], Comparison]]:
    """Scenes handed in before manifest.json exists, one JSON object a line,
    `{"reference": NAME, "scene": SCENE_ENTRY}` (`rendiff check` writes one as soon as a scene's
    last render is in), each judged at once: by scene name, what `compare_scenes` may use."""
    early: dict[str, tuple[str, Mapping[str, Any], Comparison]] = {}
    for k, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            item = json.loads(line)
        except ValueError as exc:
            raise ManifestError(f"stdin line {k}: not JSON ({exc})") from None
        ref = item.get("reference") if isinstance(item, dict) else None
        entry = item.get("scene") if isinstance(item, dict) else None
        if not isinstance(ref, str) or not isinstance(entry, dict) or not isinstance(entry.get("scene"), str):
            raise ManifestError(f'stdin line {k}: expected {{"reference": NAME, "scene": {{"scene": NAME, ...}}}}')
        early[entry["scene"]] = (ref, entry, comparer.submit(entry, ref))
    return early


def run_compare(
    run: Path,
    expectations_path: str | Path | None,
    images: bool = True,
    references_dir: str | Path | None = None,
    jobs: int = 1,
    stream: Iterable[str] | None = None,
) -> dict[str, Any]:
    """Compare everything in RUN and write results.json; returns the results document.
    With `stream`, scenes read from it are judged first, before manifest.json is read
    (`read_stream`).

    Raises ManifestError / expectations.ExpectationsError for unusable inputs.
    """
    manifest = load_manifest(run) if stream is None else None
    exps = expectations.load(expectations_path)
    refs = Path(references_dir) if references_dir is not None else None
    # One scene is judged in this process: a fresh interpreter would only add its start-up.
    jobs = min(jobs, len(manifest["scenes"])) if manifest is not None else jobs
    with Comparer(run, expectations_path, exps, images, refs, jobs) as comparer:
        early = read_stream(stream, comparer) if stream is not None else None
        manifest = load_manifest(run) if manifest is None else manifest
        reference = manifest.get("reference", "raster")
        entries = compare_scenes(manifest["scenes"], reference, comparer, early)
    summary, camera = calibration.calibrate_and_blame(run, manifest, entries, registry.spec)
    doc = document(reference, summary, expectations_path, exps.unused(), [e.to_json() for e in entries] + camera)
    write_results(run, doc)
    return doc


# --------------------------------------------------------------------------- CLI


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m rendiff_harness compare",
        description="Compare a check run's buffers with the reference; write RUN/results.json.",
    )
    p.add_argument("--run", required=True, help="run folder holding manifest.json (written by `rendiff check`)")
    p.add_argument(
        "--expectations", default=None, help="expectations TOML (e.g. tests/expectations.toml); default: none"
    )
    p.add_argument("--no-images", action="store_true", help="do not write diff PNGs")
    p.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="compare this many scenes at a time, in processes of their own (default 1: all in this "
        "process; `rendiff check` passes its --jobs)",
    )
    p.add_argument(
        "--stream",
        action="store_true",
        help="before reading manifest.json, judge the scenes written to stdin as the run renders, one JSON "
        'object a line: {"reference": NAME, "scene": SCENE_ENTRY} (`rendiff check` writes them); one is '
        "used only if exactly the manifest's entry",
    )
    p.add_argument(
        "--references",
        default=None,
        help="folder of cached Mitsuba references (<scene>.exr + <scene>.json, e.g. tests/references): "
        "global-illumination scenes are also compared with them, as backend mitsuba_ref",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args_in = list(sys.argv[1:] if argv is None else argv)
    if args_in[:1] == ["--"]:  # `python -m rendiff_harness compare -- --run RUN`
        args_in = args_in[1:]
    args = build_parser().parse_args(args_in)
    run = Path(args.run)
    t0 = time.monotonic()
    if not run.is_dir():
        print(f"rendiff_harness compare: {printable(str(run))}: run folder does not exist", file=sys.stderr)
        return EXIT_ERROR
    try:
        doc = run_compare(
            run,
            args.expectations,
            images=not args.no_images,
            references_dir=args.references,
            jobs=max(args.jobs, 1),
            stream=sys.stdin if args.stream else None,
        )
    except (ManifestError, expectations.ExpectationsError) as exc:
        print(f"rendiff_harness compare: {printable(str(exc))}", file=sys.stderr)
        return EXIT_ERROR
    except OSError as exc:
        where = run / "results.json"
        print(f"rendiff_harness compare: {printable(f'{where}: cannot write: {exc}')}", file=sys.stderr)
        return EXIT_ERROR
    print(format_table(doc["results"]))
    # Only an expectation about a scene this run compared is news: one about a
    # scene the user did not give (rendiff's own found scenes, say, on a check of
    # the user's model) is left to results.json, where every unused one is listed.
    ran = {r["scene"] for r in doc["results"]}
    unused = [u for u in doc["unused_expectations"] if u["scene"] in ran or u["scene"] == "*"]
    if unused:
        listed = ", ".join(f"{u['entry']} ({u['scene']}/{u['backend']}/{u['buffer']})" for u in unused)
        print(f"note: expectations matched by no compared result: {listed}", file=sys.stderr)
    # stdout holds the verdict table alone (`rendiff check` prints it); this line is a message.
    print(f"results: {run / 'results.json'} ({time.monotonic() - t0:.1f} s)", file=sys.stderr)
    return EXIT_OK
