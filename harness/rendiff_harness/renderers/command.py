"""Renderers declared by a command: any program becomes a backend through a TOML file.

A user lists renderers in a TOML file (docs/your-renderer.md has the format, with every key,
and a worked example) and names it in the environment variable `RENDIFF_RENDERERS` (an
absolute path; `rendiff check --renderers FILE` sets it for every harness invocation). Every
harness command then knows them exactly like the built-in backends: the registry lists and
runs them, each as a `BackendSpec` (renderers/declared.py) whose render is `CommandBackend`'s
here, and the comparison, the verifier and calibration judge them with the precision they
declare (the spec's models, built from it).

    [[renderer]]
    name = "myrender"
    command = ["./bin/myrender", "--scene", "{scene}", "--out", "{out}"]
    version = ["./bin/myrender", "--version"]
    features = ["depth", "ids"]
    buffers = ["Z", "id"]
    timeout_s = 60
    [renderer.precision]
    edge_px = 0.004
    depth_relative = 1e-6

Loading is strict, and light (tomllib, no numpy, no OpenImageIO): a malformed file is one
`RenderersError` line naming the file and the entry, so `info` fails instead of silently
dropping a renderer. Whether the program exists is *not* a load error: a renderer whose
program is missing is listed as unavailable, with that reason.

Running (`CommandBackend.render`): the command is an argument vector, never a shell, with
the placeholders expanded in each argument after the first (`{here}`, the renderers file's
folder, in every argument, the program's included), and each argument after the first that
is written `./...` or `../...` taken from the renderers file's folder, so an interpreter-run
`["python", "./my_renderer.py", "{scene}", "{out}"]` finds its script; it runs in a process group of
its own (children.run_in_group: stdin /dev/null; the group is killed on the timeout, when
the renderer ends, and when the harness dies), in a scratch working folder inside the
`workdir` it is given (`render` puts that beside its `--out`, in the run folder). What it
prints is drained while it runs, and only the first and the last `children.OUTPUT_KEEP_BYTES`
of each stream are kept (in its scratch folder's stdout.log and stderr.log, a line marking
what was dropped). {out} is a temporary name in the scratch folder; the EXR found there is
checked (size, channels, pixel types) and only then written to the real output, atomically,
so no half-written EXR ever survives. Exit status:
0 = rendered, 3 = skipped (the last non-empty stderr line is the reason), anything else an
error carrying the status or signal and the tail of stderr.

The version command runs in the renderers file's folder (the one place every entry point
has that is the user's own, so nothing is created under /tmp, where an interrupted harness
would leave it) and only the first `VERSION_MAX_BYTES` of its stdout are read.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import signal
import tempfile
import tomllib
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..contract import vocab
from ..contract.userfile import UserFileError, read_regular
from .children import Capture, run_in_group
from .errors import BackendError, BackendSkipped, BackendUnavailable

if TYPE_CHECKING:
    from ..contract.resolved import ResolvedScene

ENV_VAR = "RENDIFF_RENDERERS"
# The copy of that file `rendiff check` takes as its run begins (RUN/renderers.toml): the
# declarations (precision above all) are read from the copy, while the file's own path names
# it and resolves its commands, so that editing the file during a run changes no later render
# or comparison, and the run keeps what it was judged with.
SNAPSHOT_ENV_VAR = "RENDIFF_RENDERERS_SNAPSHOT"

# Largest renderers file read: 1 MiB. A declaration is a few hundred bytes
# (the worked example's two renderers are 2 KiB with comments), so this is
# thousands of renderers; a bigger file is a mistake, and reading it whole
# would only fill memory.
MAX_FILE_BYTES = 1 << 20
"""The environment variable naming the renderers file (an absolute path)."""
EXIT_SKIP = vocab.EXIT_SKIPPED
"""A renderer's exit status for "cannot render this here" (the reason on its last stderr line)."""
PLACEHOLDERS = ("scene", "out", "width", "height")
HERE = "here"
"""The placeholder for the renderers file's folder, allowed in every argument (the program included)."""
RELATIVE_PREFIXES = ("./", "../")
"""An argument after the program written with one of these is relative to the renderers file's folder."""
BUFFERS = ("Z", "id", "N", "RGB")
NAME_PATTERN = re.compile(r"[a-z][a-z0-9_-]*\Z")
# Longest renderer name: 64 characters. The name becomes file and folder names (the run's
# `<name>.exr`, the harness's scratch `<name>-XXXXXXXX/<name>.exr`, rendiff check's
# `scratch/<scene>-<name>/`), each at most 255 bytes (NAME_MAX), and a column of the
# results table; a 300-character name loaded fine and then failed every render with
# "File name too long". 64 leaves room for a scene's name beside it.
MAX_NAME_CHARS = 64
RENDERER_KEYS = frozenset({"name", "command", "version", "features", "buffers", "timeout_s", "precision"})
REQUIRED_KEYS = ("name", "command", "features", "buffers", "precision")
PRECISION_NUMBERS = ("edge_px", "depth_relative", "depth_absolute", "normal_relative", "rgb_relative", "rgb_absolute")
PRECISION_KEYS = frozenset({*PRECISION_NUMBERS, "depth_grazing"})
# The largest number each precision key may declare: above it, the tolerance can no longer
# tell a right answer from the smallest wrong one the contract names, so the renderer would
# pass whatever it wrote there (issue: `edge_px = 1e6` passed a renderer writing triangle 0
# everywhere). A declaration at or above its bound is refused. Derivations (docs/your-renderer.md,
# "What can be judged"):
# - edge_px < 1/2: a renderer whose pixel centers are half a pixel off along an axis (centers
#   at integer coordinates, the commonest camera bug) differs from the right answer only at
#   centers within 1/2 px of an edge; a band of 1/2 would class every one of them "edge".
# - depth_relative < MAX_REL (1e-3): the cap the judge puts on every relative depth tolerance
#   (with depth_grazing a larger number is silently that cap already). At 1e-3 Z a radial
#   depth (planar / cos of the ray's angle off axis, relative error ~ d^2 / (2 f^2) at d px
#   from the principal point, f the focal length in px) still fails outside a disc of radius
#   f * sqrt(2e-3) ~ 0.045 f, and surfaces over 0.2% of Z apart (a tie allows it on each) stay ordered, not a tie.
# - normal_relative < 1 rad: |N| must be 1 within it; at 1 a zero normal (a buffer never
#   written) passes that check, and so does a normal 57 degrees off.
# - rgb_relative < 1 - 1/pi (~0.68): Lambert's 1/pi, the factor most often dropped or applied
#   twice, changes L by (1 - 1/pi) L or (pi - 1) L; at 1 - 1/pi the first passes, at 1 a black
#   image passes (|0 - L| = L).
# The absolute terms (depth_absolute, rgb_absolute) are in the scene's units and have no bound
# that holds for every scene; they are judged as declared.
PRECISION_BOUNDS: dict[str, tuple[float, str]] = {
    "edge_px": (0.5, "a half-pixel offset of the pixel centers would pass as edge mismatches"),
    "depth_relative": (1e-3, "the cap on every relative depth tolerance (MAX_REL); radial depth would pass"),
    "normal_relative": (1.0, "a zero (unwritten) normal would pass the |N| = 1 check"),
    "rgb_relative": (1.0 - 1.0 / math.pi, "a dropped or doubled Lambert 1/pi would pass"),
}
"""The bound (exclusive) on each bounded precision number, and what passes at it."""
NEEDS = {"id": "edge_px", "Z": "depth_relative", "N": "normal_relative", "RGB": "rgb_relative"}
"""The precision key each declared buffer requires."""
CHANNELS: dict[str, tuple[tuple[str, str], ...]] = {
    "Z": (("Z", "float"),),
    "id": (("id.prim", "uint"), ("id.object", "uint")),
    "N": (("N.x", "float"), ("N.y", "float"), ("N.z", "float")),
    "RGB": (("R", "float"), ("G", "float"), ("B", "float")),
}
"""The EXR channels (and pixel types) each buffer must have (docs/resolved-scene.md)."""
# The version command's time limit: 5 s. It prints one line; the slowest common starts
# (an interpreter importing a package, a JVM, a renderer loading its plugins) take a second
# or two. Every harness process that renders probes it once (the version goes into each
# render's EXR and line), so a hanging version command costs this per render: it was 30 s,
# which made a run of N scenes wait N * 30 s for a line of provenance. A version command
# that needs longer is reported "unknown (timed out)", and the renderer still runs.
VERSION_TIMEOUT_S = 5.0


# Versions a run already asked for, by renderer name (`assume_version`).
_ASSUMED_VERSIONS: dict[str, str] = {}


def assume_version(name: str, version: str | None) -> None:
    """Takes `version` as renderer `name`'s answer for this process: `rendiff check` asks each
    renderer once (`info --json`) and passes that answer to every render (`render
    --known-version`), so a version command runs, and a hanging one costs its timeout, once
    per run rather than once per render. None forgets it (a render not told asks again)."""
    if version is None:
        _ASSUMED_VERSIONS.pop(name, None)
    else:
        _ASSUMED_VERSIONS[name] = version


# Most of the version command's stdout read: 4 KiB. The version is its first non-empty line,
# a few dozen characters; the rest is drained unread, so a version command printing 1 GB
# (which once took `info` to 3.2 GB of memory) costs 4 KiB.
VERSION_MAX_BYTES = 4096
STDERR_TAIL_LINES = 5
STDERR_TAIL_CHARS = 1000


class RenderersError(Exception):
    """A renderers file that cannot be used; the message is one line naming the file and the entry."""


# --------------------------------------------------------------------------- placeholders

_TOKEN = re.compile(r"\{\{|\}\}|\{([^{}]*)\}|[{}]")


def expand(text: str, values: Mapping[str, str]) -> str:
    """Replace `{name}` by values[name], `{{` by `{` and `}}` by `}`; ValueError for anything else."""

    def sub(m: re.Match[str]) -> str:
        token = m.group(0)
        if token == "{{":
            return "{"
        if token == "}}":
            return "}"
        name = m.group(1)
        if name is None:
            raise ValueError(f"unmatched {token!r} (write {{{{ or }}}} for a literal brace)")
        if name not in values:
            known = ", ".join("{" + p + "}" for p in values) or "none here"
            raise ValueError(f"unknown placeholder {{{name}}} (known: {known}; write {{{{ or }}}} for a brace)")
        return values[name]

    return _TOKEN.sub(sub, text)


# --------------------------------------------------------------------------- the declaration


@dataclass(frozen=True)
class Precision:
    """The declared precision (docs/your-renderer.md, "Choosing precision numbers")."""

    edge_px: float | None = None
    depth_relative: float | None = None
    depth_absolute: float = 0.0
    depth_grazing: bool = False
    normal_relative: float | None = None
    rgb_relative: float | None = None
    rgb_absolute: float = 0.0


@dataclass(frozen=True)
class Renderer:
    """One validated `[[renderer]]` entry."""

    name: str
    command: tuple[str, ...]
    version_command: tuple[str, ...] | None
    features: frozenset[str]
    buffers: frozenset[str]
    timeout_s: float | None
    precision: Precision
    source: Path  # the renderers file (absolute)
    index: int  # position among its [[renderer]] entries

    @property
    def declared(self) -> str:
        """Where it comes from, for reasons and tolerance texts."""
        return f"{self.source} (renderer {self.name!r})"

    @property
    def here(self) -> str:
        """The folder of its renderers file: the value of `{here}`, and what `./` and `../` start from."""
        return str(self.source.parent)

    def arguments(self, argv: Sequence[str], values: Mapping[str, str]) -> list[str]:
        """The arguments after the program: placeholders expanded (`{here}` among them), and an
        argument written as `./...` or `../...` made a path in the renderers file's folder.

        Decided on the text as written, before expansion, so a placeholder's value (a scene
        path, `{here}` itself) is never re-read as a path, a brace or a second argument."""
        out = []
        for arg in argv:
            text = expand(arg, {**values, "here": self.here})
            out.append(os.path.join(self.here, text) if arg.startswith(RELATIVE_PREFIXES) else text)
        return out

    def program(self, argv0: str | None = None) -> tuple[str | None, str | None]:
        """(the executable for `argv0` (default command[0]), None) or (None, why it cannot run)."""
        word = expand(self.command[0] if argv0 is None else argv0, {"here": self.here})
        what = "command" if argv0 is None else "version command"
        if "/" in word:
            path = Path(word)
            if not path.is_absolute():
                path = self.source.parent / path
            if not path.exists():
                problem = f"{path} does not exist"
            elif not path.is_file():
                problem = f"{path} is not a file"
            elif not os.access(path, os.X_OK):
                problem = f"{path} is not executable (chmod +x)"
            else:
                return str(path), None
        else:
            found = shutil.which(word)
            if found is not None:
                return found, None
            problem = f"{word!r} not found on PATH"
        return None, f"{self.declared}: {what} {problem}"


def _where(path: Path, i: int, name: str | None) -> str:
    return f"{path}: [[renderer]] #{i + 1}" + (f" ({name})" if name else "")


def _strings(value: object, key: str, where: str, *, empty: bool = False) -> list[str]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise RenderersError(f"{where}: {key} must be an array of strings, got {value!r}")
    if not value and not empty:
        raise RenderersError(f"{where}: {key} must not be empty")
    return list(value)


def _argv(value: object, key: str, where: str, placeholders: Sequence[str]) -> tuple[str, ...]:
    argv = _strings(value, key, where)
    if not argv[0]:
        raise RenderersError(f"{where}: {key}[0] (the program) must not be empty")
    for i, arg in enumerate(argv):
        if "\0" in arg:
            raise RenderersError(f"{where}: {key}[{i}] contains a NUL character")
        allowed = (HERE,) if i == 0 else (*placeholders, HERE)
        try:
            expand(arg, dict.fromkeys(allowed, ""))
        except ValueError as exc:
            note = " (the program takes only {here})" if i == 0 else ""
            raise RenderersError(f"{where}: {key}[{i}] {arg!r}: {exc}{note}") from None
    return tuple(argv)


def _number(value: object, key: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RenderersError(f"{where}: {key} must be a number, got {value!r}")
    if isinstance(value, int) and not -(2**63) <= value < 2**63:  # TOML integers are 64-bit; tomllib's are not
        raise RenderersError(
            f"{where}: {key} must be a finite number >= 0, got an integer of {value.bit_length()} bits"
        )
    f = float(value)
    if not math.isfinite(f) or f < 0:
        raise RenderersError(f"{where}: {key} must be a finite number >= 0, got {value!r}")
    return f


def _precision(value: object, buffers: frozenset[str], where: str) -> Precision:
    if not isinstance(value, dict):
        raise RenderersError(f"{where}: precision must be a table ([renderer.precision]), got {value!r}")
    unknown = sorted(set(value) - PRECISION_KEYS)
    if unknown:
        raise RenderersError(
            f"{where}: unknown precision key {unknown[0]!r} (allowed: {', '.join(sorted(PRECISION_KEYS))})"
        )
    numbers = {k: _number(value[k], f"precision.{k}", where) for k in PRECISION_NUMBERS if k in value}
    for key, (bound, why) in PRECISION_BOUNDS.items():
        if numbers.get(key, 0.0) >= bound:
            raise RenderersError(
                f"{where}: precision.{key} = {numbers[key]:g} is not below {bound:.4g}, the most that can be "
                f"judged ({why}; docs/your-renderer.md, 'What can be judged')"
            )
    for buffer in sorted(buffers):
        key = NEEDS[buffer]
        if key not in numbers:
            raise RenderersError(f"{where}: it writes {buffer} but precision has no {key} (docs/your-renderer.md)")
    grazing = value.get("depth_grazing", False)
    if not isinstance(grazing, bool):
        raise RenderersError(f"{where}: precision.depth_grazing must be true or false, got {grazing!r}")
    return Precision(
        edge_px=numbers.get("edge_px"),
        depth_relative=numbers.get("depth_relative"),
        depth_absolute=numbers.get("depth_absolute", 0.0),
        depth_grazing=grazing,
        normal_relative=numbers.get("normal_relative"),
        rgb_relative=numbers.get("rgb_relative"),
        rgb_absolute=numbers.get("rgb_absolute", 0.0),
    )


def _entry(path: Path, i: int, entry: object, taken: dict[str, int], reserved: Collection[str]) -> Renderer:
    where = _where(path, i, None)
    if not isinstance(entry, dict):
        raise RenderersError(f"{where}: must be a table, got {entry!r}")
    name = entry.get("name")
    if not isinstance(name, str) or not NAME_PATTERN.match(name):
        raise RenderersError(f"{where}: name must be a string matching [a-z][a-z0-9_-]*, got {name!r}")
    if len(name) > MAX_NAME_CHARS:
        raise RenderersError(
            f"{where}: name {name[:20] + '...'!r} is {len(name)} characters long; at most {MAX_NAME_CHARS} are allowed"
        )
    where = _where(path, i, name)
    if name in reserved:
        raise RenderersError(f"{where}: name {name!r} is taken by a built-in backend")
    if name in taken:
        raise RenderersError(f"{where}: name {name!r} is already declared by [[renderer]] #{taken[name] + 1}")
    unknown = sorted(set(entry) - RENDERER_KEYS)
    if unknown:
        raise RenderersError(f"{where}: unknown key {unknown[0]!r} (allowed: {', '.join(sorted(RENDERER_KEYS))})")
    for key in REQUIRED_KEYS:
        if key not in entry:
            raise RenderersError(f"{where}: missing key {key!r}")
    command = _argv(entry["command"], "command", where, PLACEHOLDERS)
    version = _argv(entry["version"], "version", where, ()) if "version" in entry else None
    features = _strings(entry["features"], "features", where, empty=True)
    known_features = {f.value for f in vocab.Feature}
    bad = [f for f in features if f not in known_features]
    if bad:
        raise RenderersError(f"{where}: unknown feature {bad[0]!r} (known: {', '.join(sorted(known_features))})")
    buffers = _strings(entry["buffers"], "buffers", where)
    bad = [b for b in buffers if b not in BUFFERS]
    if bad:
        raise RenderersError(f"{where}: unknown buffer {bad[0]!r} (known: {', '.join(BUFFERS)})")
    timeout: float | None = None
    if "timeout_s" in entry:
        timeout = _number(entry["timeout_s"], "timeout_s", where)
        if timeout == 0:
            raise RenderersError(f"{where}: timeout_s must be > 0")
    precision = _precision(entry["precision"], frozenset(buffers), where)
    taken[name] = i
    return Renderer(
        name=name,
        command=command,
        version_command=version,
        features=frozenset(features),
        buffers=frozenset(buffers),
        timeout_s=timeout,
        precision=precision,
        source=path,
        index=i,
    )


def parse(path: Path, text: str, reserved: Collection[str]) -> tuple[Renderer, ...]:
    """Validate the renderers file's content; RenderersError (one line) on the first problem.
    `reserved`: the names a declared renderer cannot take (the registry's `RESERVED_NAMES`)."""
    try:
        data = tomllib.loads(text)
    except ValueError as exc:  # tomllib.TOMLDecodeError, or an integer of over 4300 digits
        raise RenderersError(f"{path}: not valid TOML: {str(exc).split(';')[0]}") from None
    except RecursionError:  # arrays or inline tables nested some 500 deep
        raise RenderersError(f"{path}: not valid TOML: nested too deeply") from None
    unknown = sorted(set(data) - {"renderer"})
    if unknown:
        raise RenderersError(f"{path}: unknown top-level key {unknown[0]!r}; declare renderers as [[renderer]] tables")
    entries = data.get("renderer")
    if not isinstance(entries, list) or not entries:
        raise RenderersError(f"{path}: declares no renderer (expected one or more [[renderer]] tables)")
    taken: dict[str, int] = {}
    return tuple(_entry(path, i, e, taken, reserved) for i, e in enumerate(entries))


def load(path: str | Path, reserved: Collection[str], text_from: str | Path | None = None) -> tuple[Renderer, ...]:
    """Read and validate a renderers file (relative paths are taken from the current folder).
    With `text_from`, the declarations are read from that copy of it (`SNAPSHOT_ENV_VAR`),
    while `path` still names the file and resolves its relative commands."""
    path = Path(path).absolute()
    source = Path(text_from).absolute() if text_from is not None else path
    try:
        raw = read_regular(source, MAX_FILE_BYTES)
    except UserFileError as exc:
        raise RenderersError(f"{source}: the renderers file {exc}") from None
    except OSError as exc:
        raise RenderersError(f"{source}: cannot read the renderers file: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RenderersError(f"{source}: not UTF-8 text: {exc}") from None
    return parse(path, text, reserved)


@lru_cache(maxsize=8)
def _load_cached(
    path: str, reserved: frozenset[str], text_from: str | None, mtime_ns: int, size: int
) -> tuple[Renderer, ...]:
    return load(path, reserved, text_from)


def from_env(reserved: frozenset[str]) -> tuple[Renderer, ...]:
    """The renderers declared in the file `RENDIFF_RENDERERS` names (none when unset or empty);
    `reserved` as in `parse`."""
    value = os.environ.get(ENV_VAR, "")
    if not value:
        return ()
    path = Path(value)
    if not path.is_absolute():
        raise RenderersError(f"{ENV_VAR}={value}: must be an absolute path to a renderers TOML file")
    snapshot = os.environ.get(SNAPSHOT_ENV_VAR, "")
    read_from = Path(snapshot) if snapshot else path
    if not read_from.is_absolute():
        raise RenderersError(f"{SNAPSHOT_ENV_VAR}={snapshot}: must be an absolute path")
    try:
        st = read_from.stat()
    except OSError as exc:
        raise RenderersError(
            f"{read_from}: cannot read the renderers file ({ENV_VAR}): {exc.strerror or exc}"
        ) from None
    return _load_cached(str(path), reserved, snapshot or None, st.st_mtime_ns, st.st_size)


# --------------------------------------------------------------------------- running it


def _tail(stream: Capture) -> list[str]:
    """The non-empty lines at the end of a captured stream (its last 8 * STDERR_TAIL_CHARS bytes)."""
    end = (stream.head + stream.tail)[-8 * STDERR_TAIL_CHARS :]
    text = end.decode("utf-8", "replace")
    return [line.strip() for line in text.splitlines() if line.strip()]


def _tail_text(lines: list[str], stream: Capture) -> str:
    if not lines:
        return "; nothing on stderr"
    text = " | ".join(lines[-STDERR_TAIL_LINES:])
    if len(text) > STDERR_TAIL_CHARS:
        text = "..." + text[-STDERR_TAIL_CHARS:]
    if stream.omitted:
        return f"; stderr ({stream.total} bytes, only its first and last {stream.tail_limit} kept), last lines: {text}"
    return f"; stderr: {text}"


def _save_log(path: Path, stream: Capture) -> None:
    """Keep what was captured of a stream in the scratch folder (the omission marked)."""
    try:
        path.write_bytes(stream.kept())
    except OSError:
        pass


def _how(returncode: int) -> str:
    if returncode < 0:
        try:
            name = signal.Signals(-returncode).name
        except ValueError:
            name = f"signal {-returncode}"
        return f"killed by {name}"
    return f"exited with status {returncode}"


def check_exr(path: Path, width: int, height: int, channels: Sequence[tuple[str, str]]) -> list[str]:
    """What is wrong with a renderer's EXR (empty: acceptable), each problem a short phrase.

    It must exist, be an OpenEXR file OpenImageIO can open, be `width` x `height` with its
    data window at the origin, and have each of `channels` (name, "float" | "uint") with that
    pixel type.
    """
    if not path.is_file():
        return ["wrote no file at {out}"]
    try:
        import OpenImageIO as oiio
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise BackendUnavailable(f"OpenImageIO Python module missing ({exc}); run scripts/setup.sh") from exc
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        why = " ".join((oiio.geterror() or "OpenImageIO cannot open it").split())
        return [f"wrote an unreadable image at {{out}}: {why}"]
    try:
        if inp.format_name() != "openexr":
            return [f"wrote a {inp.format_name()} file at {{out}}, expected OpenEXR"]
        spec = inp.spec()
        if spec.deep:
            return ["wrote a deep EXR, expected a flat one"]
        if (spec.width, spec.height) != (width, height):
            return [f"its EXR is {spec.width}x{spec.height}, expected {width}x{height} (the scene camera's size)"]
        if (spec.x, spec.y) != (0, 0):
            return [f"its EXR's data window starts at ({spec.x}, {spec.y}), expected (0, 0)"]
        names = list(spec.channelnames)
        formats = list(spec.channelformats) or [spec.format] * len(names)
        problems = []
        for cname, kind in channels:
            if cname not in names:
                problems.append(f"wrote no {cname} channel")
                continue
            got = str(formats[names.index(cname)])
            if got != kind:
                problems.append(f"{cname} is {got}, expected {kind}")
        return problems
    finally:
        inp.close()


class CommandBackend:
    """How a declared renderer runs: its version, availability and render (renderers/declared.py
    makes the `BackendSpec` that points at them)."""

    def __init__(self, spec: Renderer) -> None:
        self.spec = spec
        self.NAME = spec.name
        self._version: str | None = None

    def unavailable_reason(self) -> str | None:
        """None when its program exists and is executable, else one line naming the file."""
        return self.spec.program()[1]

    def version(self) -> str:
        """The first non-empty line of its version command's stdout; "unknown" without one.
        A version `assume_version` was told (the run's `info` answer) is taken as it is."""
        assumed = _ASSUMED_VERSIONS.get(self.NAME)
        if assumed is not None:
            return assumed
        if self._version is None:
            self._version = self._probe_version()
        return self._version

    def _probe_version(self) -> str:
        argv = self.spec.version_command
        if argv is None:
            return "unknown"
        program, problem = self.spec.program(argv[0])
        if program is None:
            return f"unknown ({problem})"
        try:
            ran = run_in_group(
                [program, *self.spec.arguments(argv[1:], {})],
                cwd=self.spec.source.parent,
                env=os.environ,
                timeout_s=VERSION_TIMEOUT_S,
                stdout=Capture(head_limit=VERSION_MAX_BYTES, tail_limit=0),
                stderr=Capture(head_limit=0, tail_limit=0),
            )
        except OSError as exc:
            return f"unknown (cannot run the version command: {exc.strerror or exc})"
        if ran.timed_out:
            return f"unknown (the version command timed out after {VERSION_TIMEOUT_S:g} s)"
        if ran.returncode != 0:
            return f"unknown (the version command {_how(ran.returncode or 0)})"
        lines = [line.strip() for line in ran.stdout.head.decode("utf-8", "replace").splitlines()]
        first = next((line for line in lines if line), None)
        return first if first is not None else "unknown (the version command printed nothing)"

    def render(
        self, scene: ResolvedScene, out_exr: Path, workdir: Path, timeout_s: float, /, *, visibility_only: bool = False
    ) -> dict[str, object]:
        """Run the command on `scene`, check its EXR, write the declared buffers to `out_exr` atomically.

        `visibility_only` (registry.plan): RGB is neither required nor kept, so a scene that needs
        a shading feature the renderer lacks is still compared on Z, ids and N.
        Raises BackendUnavailable (program missing), BackendSkipped (exit 3), BackendError.
        """
        spec = self.spec
        program, problem = spec.program()
        if program is None:
            raise BackendUnavailable(f"{self.NAME}: {problem}")
        cam = scene.camera
        limit = float(timeout_s) if spec.timeout_s is None else min(float(timeout_s), spec.timeout_s)
        wanted = [b for b in BUFFERS if b in spec.buffers and not (visibility_only and b == "RGB")]
        workdir.mkdir(parents=True, exist_ok=True)
        scratch = Path(tempfile.mkdtemp(prefix=f"{self.NAME}-", dir=workdir)).absolute()
        try:
            cwd = scratch / "work"
            cwd.mkdir()
            temp_out = scratch / f"{self.NAME}.exr"
            values = {
                "scene": str(Path(scene.directory).absolute()),
                "out": str(temp_out),
                "width": str(cam.width),
                "height": str(cam.height),
            }
            argv = [program, *spec.arguments(spec.command[1:], values)]
            try:
                ran = run_in_group(argv, cwd=cwd, env=os.environ, timeout_s=limit)
            except OSError as exc:
                raise BackendUnavailable(f"{self.NAME}: cannot start {program}: {exc.strerror or exc}") from None
            _save_log(scratch / "stdout.log", ran.stdout)
            _save_log(scratch / "stderr.log", ran.stderr)
            lines = _tail(ran.stderr)
            said = _tail_text(lines, ran.stderr)
            if ran.timed_out:
                raise BackendError(f"{self.NAME}: timed out after {limit:g} s; its process group was killed{said}")
            rc = ran.returncode or 0
            if rc == EXIT_SKIP:
                raise BackendSkipped(lines[-1] if lines else "exit status 3 (skipped) without a reason on stderr")
            if rc != 0:
                raise BackendError(f"{self.NAME}: {_how(rc)}{said}")
            channels = [c for b in wanted for c in CHANNELS[b]]
            problems = check_exr(temp_out, cam.width, cam.height, channels)
            if problems:
                raise BackendError(f"{self.NAME}: exited 0 but {'; '.join(problems)} ({spec.declared})")
            self._write(temp_out, out_exr, wanted)
        finally:
            shutil.rmtree(scratch, ignore_errors=True)
        info: dict[str, object] = {
            "command": argv,
            "declared_in": str(spec.source),
            "exit_status": rc,
            "renderer_s": ran.elapsed_s,
            "timeout_s": limit,
            "stdout_bytes": ran.stdout.total,
            "stderr_bytes": ran.stderr.total,
        }
        if visibility_only:
            info["visibility_only"] = True
        return info

    def _write(self, src: Path, out_exr: Path, wanted: Sequence[str]) -> None:
        """Copy the wanted buffers (and the renderer's own rendiff: attributes) to `out_exr` atomically."""
        from ..contract import exrbuf

        try:
            bufs = exrbuf.read_buffers(src)
            attrs: dict[str, Any] = dict(exrbuf.read_attrs(src))
        except exrbuf.BufferError as exc:
            raise BackendError(f"{self.NAME}: its EXR cannot be read as buffers: {exc}") from None
        rgb = "RGB" in wanted
        attrs.update(backend=self.NAME, version=self.version(), declared_in=str(self.spec.source))
        exrbuf.write_buffers(
            out_exr,
            Z=bufs["Z"] if "Z" in wanted else None,
            prim=bufs["id.prim"] if "id" in wanted else None,
            obj=bufs["id.object"] if "id" in wanted else None,
            N=bufs["N"] if "N" in wanted else None,
            RGB=bufs["RGB"] if rgb else None,
            var=bufs.get("var") if rgb else None,
            attrs=attrs,
        )


__all__ = [
    "ENV_VAR",
    "SNAPSHOT_ENV_VAR",
    "CommandBackend",
    "Precision",
    "Renderer",
    "RenderersError",
    "check_exr",
    "expand",
    "from_env",
    "load",
    "parse",
]
