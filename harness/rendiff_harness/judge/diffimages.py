"""Diff images for people: per (scene, backend), written with OpenImageIO's ImageBufAlgo.color_map.

* `<backend>.id.png`: the ID-mismatch map. Background in both: black; same ID: dark
  gray; edge mismatch: amber; interior mismatch: magenta.
* `<backend>.RGB.png`: per pixel the largest channel's |a - b| / tolerance (deterministic)
  or |z| / critical z (Monte Carlo) through `inferno`, 1 = at the limit (clipped above);
  failing edge pixels amber, failing interior pixels magenta.
* `<backend>.Z.png`: |Z_test - Z_ref| over pixels both sides hit, through the
  `inferno` map, normalized so that the largest error over the depth-compared pixels
  (same prim on both sides: the entry's max_abs_error) is 1 (clipped above); background
  in both: black; hit/miss mask mismatches: cyan.

PNGs are written to a temp name in the same folder and renamed, so a reader never sees a
half-written file. Any failure raises DiffImageError; the caller records it and keeps the
numbers (an image is never worth losing a result).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import numpy as np

from ..contract import atomic, exrbuf
from ..contract.vocab import BACKGROUND_ID

BG, MATCH, EDGE, INTERIOR = 0, 1, 2, 3
ID_COLORS = (
    (0.0, 0.0, 0.0),  # background in both
    (0.22, 0.22, 0.22),  # same ID
    (1.0, 0.75, 0.0),  # edge mismatch (amber)
    (1.0, 0.0, 1.0),  # interior mismatch (magenta)
)
MASK_MISMATCH_COLOR = (0.0, 1.0, 1.0)  # cyan


class DiffImageError(Exception):
    """A diff image that could not be written; the message names the file."""


def _oiio() -> ModuleType:
    try:
        import OpenImageIO as oiio
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise DiffImageError(f"OpenImageIO Python module missing ({exc})") from exc
    return oiio


def _write_png(path: Path, rgb: np.ndarray) -> None:
    """Write an (H, W, 3) float image in [0, 1] as 8-bit PNG, atomically."""
    oiio = _oiio()
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = oiio.ImageBuf(np.ascontiguousarray(rgb, dtype=np.float32))
    # OIIO creates the file (ordinary permissions) and picks the format from the .png suffix.
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.png")
    try:
        with atomic.renamed_into_place(tmp, path):
            if not buf.write(str(tmp), oiio.UINT8):
                raise DiffImageError(f"{path}: OpenImageIO cannot write it: {buf.geterror() or oiio.geterror()}")
    except OSError as exc:
        raise DiffImageError(f"{path}: {exc.strerror or exc}") from exc


def _color_map_knots(values: np.ndarray, colors: tuple[tuple[float, float, float], ...]) -> np.ndarray:
    """color_map with evenly spaced knots: value k/(n-1) maps exactly to colors[k]."""
    oiio = _oiio()
    from OpenImageIO import ImageBufAlgo

    src = oiio.ImageBuf(np.ascontiguousarray(values, dtype=np.float32)[..., None])
    knots = [c for color in colors for c in color]
    out = ImageBufAlgo.color_map(src, 0, len(colors), 3, knots)
    if out.has_error:
        raise DiffImageError(f"color_map failed: {out.geterror()}")
    return np.asarray(out.get_pixels(oiio.FLOAT)).reshape(values.shape + (3,))


def _color_map_named(values: np.ndarray, name: str) -> np.ndarray:
    oiio = _oiio()
    from OpenImageIO import ImageBufAlgo

    src = oiio.ImageBuf(np.ascontiguousarray(values, dtype=np.float32)[..., None])
    out = ImageBufAlgo.color_map(src, 0, name)
    if out.has_error:
        raise DiffImageError(f"color_map {name!r} failed: {out.geterror()}")
    return np.asarray(out.get_pixels(oiio.FLOAT)).reshape(values.shape + (3,))


def id_classes(
    ref_prim: np.ndarray, test_prim: np.ndarray, edge: np.ndarray, interior: np.ndarray, background: int
) -> np.ndarray:
    """(H, W) class per pixel: BG, MATCH, EDGE, INTERIOR (interior wins over edge)."""
    cls = np.full(ref_prim.shape, MATCH, dtype=np.uint8)
    cls[(ref_prim == background) & (test_prim == background)] = BG
    cls[edge] = EDGE
    cls[interior] = INTERIOR
    return cls


@contextlib.contextmanager
def _one_message(path: Path) -> Iterator[None]:
    """Anything from OIIO or numpy while writing `path` becomes one DiffImageError naming it."""
    try:
        yield
    except DiffImageError:
        raise
    except Exception as exc:  # noqa: BLE001 - anything from OIIO/numpy becomes one message
        raise DiffImageError(f"{path}: {type(exc).__name__}: {exc}") from exc


def write_id_diff(
    path: str | Path,
    ref_prim: np.ndarray,
    test_prim: np.ndarray,
    edge: np.ndarray,
    interior: np.ndarray,
    background: int = BACKGROUND_ID,
) -> Path:
    """Write the ID-mismatch map; `edge`/`interior` are (H, W) boolean masks of mismatches."""
    path = Path(path)
    with _one_message(path):
        cls = id_classes(ref_prim, test_prim, edge, interior, background)
        rgb = _color_map_knots(cls.astype(np.float32) / (len(ID_COLORS) - 1), ID_COLORS)
        _write_png(path, rgb)
    return path


def write_depth_diff(path: str | Path, ref_z: np.ndarray, test_z: np.ndarray, scale: float) -> Path:
    """Write the |dZ| heat map (inferno), normalized by `scale` (> 0; else by 1)."""
    path = Path(path)
    with _one_message(path):
        zr = np.asarray(ref_z, dtype=np.float64)
        zt = np.asarray(test_z, dtype=np.float64)
        hr, ht = exrbuf.depth_hits(zr), exrbuf.depth_hits(zt)
        both = hr & ht
        err = np.zeros(zr.shape)
        err[both] = np.abs(zt[both] - zr[both])
        s = scale if (np.isfinite(scale) and scale > 0.0) else 1.0
        err[~np.isfinite(err)] = s  # a NaN or infinite depth on a hit: the scale's full color
        rgb = _color_map_named(np.clip(err / s, 0.0, 1.0), "inferno")
        rgb[~hr & ~ht] = 0.0
        rgb[hr != ht] = MASK_MISMATCH_COLOR
        _write_png(path, rgb)
    return path


def write_rgb_diff(path: str | Path, score: np.ndarray, edge: np.ndarray, interior: np.ndarray) -> Path:
    """Write the radiance heat map: `score` (H, W) 1 = at the tolerance; failing pixels colored."""
    path = Path(path)
    with _one_message(path):
        sc = np.nan_to_num(np.asarray(score, dtype=np.float64), nan=1.0, posinf=1.0)
        rgb = _color_map_named(np.clip(sc, 0.0, 1.0), "inferno")
        rgb[edge] = ID_COLORS[EDGE]
        rgb[interior] = ID_COLORS[INTERIOR]
        _write_png(path, rgb)
    return path
