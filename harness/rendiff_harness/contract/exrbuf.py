"""Read and write the buffer EXRs of docs/DESIGN.md ("Buffers", docs/resolved-scene.md).

Layout: one single-part scanline EXR per (scene, renderer) with channels
`Z` (f32 planar depth, +inf = background), `id.prim` / `id.object` (u32,
0xFFFFFFFF = background), optional `N.x N.y N.z` and `R G B` (f32), and for Monte Carlo
radiance `var.R var.G var.B` (f32: the variance of each pixel's mean estimate,
docs/radiance.md).

Why this module writes EXR itself instead of through OpenImageIO
-----------------------------------------------------------------
OpenImageIO's Python binding (3.2.2) takes one numpy buffer of one type per
`write_image` call and converts it to each channel's file type with *normalized,
float-precision* conversions (measured: a uint32 buffer turns Z=5 into
1.16e-9; a float64 buffer turns id 16777217 into 16777218). A file that mixes
f32 and exact u32 channels therefore cannot be written through it. The EXR
scanline format is small and fully specified, so the writer below emits it
directly with numpy (uncompressed or ZIP); OpenImageIO remains the *reader*,
and the tests check every written file by reading it back through OpenImageIO.

Reading IDs: only `ImageInput.read_image(0, 0, c, c + 1, oiio.UINT32)` returns
u32 channels exactly. Note that the *string* "uint32" is not a TypeDesc name in
OIIO 3.2.2: it parses as `unknown` and silently falls back to normalized float.
Use the `oiio.UINT32` constant (or the string "uint").
"""

from __future__ import annotations

import builtins
import struct
import zlib
from collections.abc import Iterable, Mapping
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from . import atomic
from .vocab import BACKGROUND_ID

if TYPE_CHECKING:
    import OpenImageIO


def depth_hits(z: np.ndarray) -> np.ndarray:
    """The pixels a depth buffer reports as hit: every value but +inf, the background's depth
    (docs/DESIGN.md, "Buffers"). NaN or -inf is a hit with a depth no renderer may report, never
    background: read as "not finite = background", a renderer that wrote NaN or -inf where it
    saw nothing passed."""
    hits: np.ndarray = np.asarray(z) != np.inf
    return hits


ATTR_PREFIX = "rendiff:"
"""User attributes are stored as `rendiff:<key>` so that `read_attrs` returns exactly
what `write_buffers` was given, never the EXR/OIIO standard attributes, and so
that no key can collide with a standard attribute that OIIO renames on read."""

BUFFER_KEYS = ("Z", "id.prim", "id.object", "N", "RGB", "var")
_GROUPS: dict[str, tuple[str, ...]] = {
    "N": ("N.x", "N.y", "N.z"),
    "RGB": ("R", "G", "B"),
    "var": ("var.R", "var.G", "var.B"),
}
_UINT_CHANNELS = frozenset({"id.prim", "id.object"})

_EXR_MAGIC = 20000630
_EXR_VERSION = 2
_LONG_NAMES_FLAG = 0x400
_PIXEL_UINT, _PIXEL_FLOAT = 0, 2
_COMPRESSION = {"none": (0, 1), "zip": (3, 16)}  # name -> (EXR code, scanlines per chunk)

AttrValue = str | float | int


class BufferError(builtins.BufferError):
    """A buffer file that cannot be written or read as docs/DESIGN.md specifies.

    Subclasses the builtin of the same name so that `except BufferError` works
    whether or not the caller imported this one. The message starts with the path.
    """


# --------------------------------------------------------------------------- writing


def _as_plane(path: Path, name: str, a: object, kind: str) -> np.ndarray:
    """Validate one (H, W) plane and return it as little-endian 4-byte words."""
    arr = np.asarray(a)
    if arr.ndim != 2:
        raise BufferError(f"{path}: {name} must be 2-D (H, W), got shape {arr.shape}")
    if kind == "uint":
        if arr.dtype.kind not in "ui":
            raise BufferError(f"{path}: {name} must be an integer array (ids are exact), got {arr.dtype}")
        if arr.size and (int(arr.min()) < 0 or int(arr.max()) > BACKGROUND_ID):
            raise BufferError(f"{path}: {name} has values outside [0, 2^32)")
        return np.ascontiguousarray(arr, dtype="<u4")
    if arr.dtype.kind not in "fiu":
        raise BufferError(f"{path}: {name} must be numeric, got {arr.dtype}")
    return np.ascontiguousarray(arr, dtype="<f4").view("<u4")


def _collect_channels(
    path: Path,
    Z: object | None,
    prim: object | None,
    obj: object | None,
    N: object | None,
    RGB: object | None,
    var: object | None = None,
) -> dict[str, tuple[int, np.ndarray]]:
    """Map EXR channel name -> (pixel type, (H, W) '<u4' words), checking shapes agree."""
    chans: dict[str, tuple[int, np.ndarray]] = {}
    if Z is not None:
        chans["Z"] = (_PIXEL_FLOAT, _as_plane(path, "Z", Z, "float"))
    if prim is not None:
        chans["id.prim"] = (_PIXEL_UINT, _as_plane(path, "prim", prim, "uint"))
    if obj is not None:
        chans["id.object"] = (_PIXEL_UINT, _as_plane(path, "obj", obj, "uint"))
    for key, value in (("N", N), ("RGB", RGB), ("var", var)):
        if value is None:
            continue
        arr = np.asarray(value)
        if arr.ndim != 3 or arr.shape[2] != 3:
            raise BufferError(f"{path}: {key} must be (H, W, 3), got shape {arr.shape}")
        for i, cname in enumerate(_GROUPS[key]):
            chans[cname] = (_PIXEL_FLOAT, _as_plane(path, cname, arr[:, :, i], "float"))
    if not chans:
        raise BufferError(f"{path}: no buffer given (pass at least one of Z, prim, obj, N, RGB, var)")
    shapes = {c: p.shape for c, (_, p) in chans.items()}
    if len(set(shapes.values())) != 1:
        raise BufferError(f"{path}: buffers differ in size: {shapes}")
    h, w = next(iter(shapes.values()))
    if h == 0 or w == 0:
        raise BufferError(f"{path}: empty image ({w}x{h})")
    return chans


def _attr(name: str, type_name: str, payload: bytes) -> bytes:
    return name.encode("ascii") + b"\0" + type_name.encode("ascii") + b"\0" + struct.pack("<i", len(payload)) + payload


def _user_attr(path: Path, key: str, value: AttrValue) -> bytes:
    """Encode one user attribute; floats as EXR `double` so timings and settings survive."""
    if not key or not key.isascii() or "\0" in key or len(ATTR_PREFIX + key) > 255:
        raise BufferError(f"{path}: attribute name {key!r} must be 1-{255 - len(ATTR_PREFIX)} ASCII characters")
    name = ATTR_PREFIX + key
    if isinstance(value, bool):
        raise BufferError(f"{path}: attribute {key!r}: bool is ambiguous, store an int or a string")
    if isinstance(value, int):
        if not -(2**31) <= value < 2**31:
            raise BufferError(f"{path}: attribute {key!r}: int {value} does not fit in 32 bits")
        return _attr(name, "int", struct.pack("<i", value))
    if isinstance(value, float):
        return _attr(name, "double", struct.pack("<d", value))
    if isinstance(value, str):
        return _attr(name, "string", value.encode("utf-8"))
    raise BufferError(f"{path}: attribute {key!r} has unsupported type {type(value).__name__}")


def _header(
    path: Path,
    names: list[str],
    types: list[int],
    w: int,
    h: int,
    comp_code: int,
    attrs: Mapping[str, AttrValue],
) -> tuple[bytes, bool]:
    chlist = b"".join(
        n.encode("ascii") + b"\0" + struct.pack("<iB3xii", t, 0, 1, 1) for n, t in zip(names, types, strict=True)
    )
    box = struct.pack("<iiii", 0, 0, w - 1, h - 1)
    parts = [
        _attr("channels", "chlist", chlist + b"\0"),
        _attr("compression", "compression", struct.pack("<B", comp_code)),
        _attr("dataWindow", "box2i", box),
        _attr("displayWindow", "box2i", box),
        _attr("lineOrder", "lineOrder", struct.pack("<B", 0)),
        _attr("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
        _attr("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
        _attr("screenWindowWidth", "float", struct.pack("<f", 1.0)),
    ]
    parts += [_user_attr(path, k, v) for k, v in sorted(attrs.items())]
    long_names = any(len(ATTR_PREFIX + k) > 31 for k in attrs)
    return b"".join(parts) + b"\0", long_names


def _zip_chunk(raw: bytes) -> bytes:
    """OpenEXR ZIP: split even/odd bytes, delta-predict, deflate; keep raw if that is smaller."""
    src = np.frombuffer(raw, dtype=np.uint8)
    half = (src.size + 1) // 2
    t = np.empty_like(src)
    t[:half] = src[0::2]
    t[half:] = src[1::2]
    d = t.copy()
    d[1:] = (t[1:].astype(np.int16) - t[:-1].astype(np.int16) + 128).astype(np.uint8)
    packed = zlib.compress(d.tobytes(), 6)
    return packed if len(packed) < len(raw) else raw


def _encode(
    path: Path, chans: dict[str, tuple[int, np.ndarray]], attrs: Mapping[str, AttrValue], compression: str
) -> bytes:
    if compression not in _COMPRESSION:
        raise BufferError(f"{path}: compression must be one of {sorted(_COMPRESSION)}, got {compression!r}")
    comp_code, lines_per_chunk = _COMPRESSION[compression]
    names = sorted(chans)  # EXR requires channels sorted by name (byte order)
    h, w = chans[names[0]][1].shape
    header, long_names = _header(path, names, [chans[n][0] for n in names], w, h, comp_code, attrs)
    version = _EXR_VERSION | (_LONG_NAMES_FLAG if long_names else 0)
    # Scanline layout: for each line, each channel's W samples in channel order.
    words = np.empty((h, len(names), w), dtype="<u4")
    for i, n in enumerate(names):
        words[:, i, :] = chans[n][1]
    chunks: list[bytes] = []
    for y0 in range(0, h, lines_per_chunk):
        raw = words[y0 : y0 + lines_per_chunk].tobytes()
        data = _zip_chunk(raw) if comp_code else raw
        chunks.append(struct.pack("<ii", y0, len(data)) + data)
    table_start = 8 + len(header)
    offset = table_start + 8 * len(chunks)
    offsets = []
    for c in chunks:
        offsets.append(offset)
        offset += len(c)
    return (
        struct.pack("<ii", _EXR_MAGIC, version) + header + struct.pack(f"<{len(offsets)}Q", *offsets) + b"".join(chunks)
    )


def write_buffers(
    path: str | Path,
    *,
    Z: object | None = None,
    prim: object | None = None,
    obj: object | None = None,
    N: object | None = None,
    RGB: object | None = None,
    var: object | None = None,
    attrs: Mapping[str, AttrValue] | None = None,
    compression: str = "zip",
) -> None:
    """Write the given buffers to `path` atomically (temp file in the same folder + os.replace).

    Z, N, RGB, var are stored as f32; prim/obj as exact u32 (`id.prim`, `id.object`).
    `var` ((H, W, 3)) becomes channels var.R var.G var.B.
    A failure at any point leaves no file at `path` (an existing file stays as it was)
    and no temp file behind, so a crashed backend can never be mistaken for a result.
    """
    path = Path(path)
    chans = _collect_channels(path, Z, prim, obj, N, RGB, var)
    blob = _encode(path, chans, dict(attrs or {}), compression)
    directory = path.parent if str(path.parent) else Path(".")
    try:
        temp = atomic.AtomicFile(path)  # .<name>.XXXXXXXX.tmp in `directory`
    except OSError as exc:
        raise BufferError(f"{path}: cannot create a temp file in {directory}: {exc.strerror}") from exc
    try:
        temp.commit(blob)  # removes the temp file on any failure
    except OSError as exc:
        raise BufferError(f"{path}: write failed: {exc.strerror or exc}") from exc


# --------------------------------------------------------------------------- reading


def _oiio() -> ModuleType:
    """Import OpenImageIO lazily so that `info` works (and says why) without it."""
    try:
        import OpenImageIO as oiio
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise BufferError(
            f"OpenImageIO Python module missing ({exc}); run scripts/setup.sh or "
            "`pip install -r harness/requirements.txt`"
        ) from exc
    return oiio


def _open(path: Path) -> tuple[ModuleType, OpenImageIO.ImageInput]:
    oiio = _oiio()
    if not path.is_file():
        raise BufferError(f"{path}: missing (no such file)")
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise BufferError(f"{path}: unreadable: {oiio.geterror() or 'OpenImageIO could not open it'}")
    return oiio, inp


def read_buffers(path: str | Path, require: Iterable[str] = ()) -> dict[str, np.ndarray]:
    """Read every known buffer in `path`; keys among 'Z', 'id.prim', 'id.object', 'N', 'RGB', 'var'.

    Z/N/RGB/var come back as float32 ((H, W) or (H, W, 3)), IDs as exact uint32 (H, W).
    `require` lists keys that must be present; a missing one raises BufferError.
    A u32 ID channel stored as anything but uint is refused: it cannot be exact.
    """
    path = Path(path)
    unknown = set(require) - set(BUFFER_KEYS)
    if unknown:
        raise BufferError(f"{path}: unknown buffer keys required: {sorted(unknown)}")
    oiio, inp = _open(path)
    try:
        spec = inp.spec()
        names = list(spec.channelnames)
        formats = list(spec.channelformats) or [spec.format] * len(names)
        if spec.deep:
            raise BufferError(f"{path}: deep EXR is not a buffer file")

        def read(cname: str) -> np.ndarray:
            c = names.index(cname)
            is_uint = cname in _UINT_CHANNELS
            if is_uint and formats[c].basetype != oiio.UINT32:
                raise BufferError(f"{path}: channel {cname} is stored as {formats[c]}, expected uint (exact ids)")
            pix = inp.read_image(0, 0, c, c + 1, oiio.UINT32 if is_uint else oiio.FLOAT)
            if pix is None:
                raise BufferError(f"{path}: cannot read channel {cname}: {inp.geterror()}")
            arr = np.asarray(pix)
            return arr.reshape(spec.height, spec.width)

        out: dict[str, np.ndarray] = {}
        for key in ("Z", "id.prim", "id.object"):
            if key in names:
                out[key] = read(key)
        for key, group in _GROUPS.items():
            present = [c for c in group if c in names]
            if present and len(present) != len(group):
                raise BufferError(f"{path}: incomplete {key}: has {present}, needs {list(group)}")
            if present:
                out[key] = np.stack([read(c) for c in group], axis=-1)
    finally:
        inp.close()
    missing = [k for k in require if k not in out]
    if missing:
        raise BufferError(f"{path}: missing channels for {missing} (file has {names})")
    return out


def read_attrs(path: str | Path) -> dict[str, AttrValue]:
    """The attributes given to `write_buffers(attrs=...)`, keys without the storage prefix."""
    path = Path(path)
    _, inp = _open(path)
    try:
        result: dict[str, AttrValue] = {}
        for p in inp.spec().extra_attribs:
            if p.name.startswith(ATTR_PREFIX):
                value = p.value
                result[p.name[len(ATTR_PREFIX) :]] = value if isinstance(value, (str, int, float)) else str(value)
        return result
    finally:
        inp.close()


def read_render(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, AttrValue]]:
    """A render's buffers (`read_buffers`, whose BufferError it raises) and its attributes: none
    where they cannot be read, since what is judged is the buffers."""
    buffers = read_buffers(path)
    try:
        attrs = read_attrs(path)
    except BufferError:
        attrs = {}
    return buffers, attrs
