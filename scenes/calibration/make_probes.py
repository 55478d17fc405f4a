"""Writes the camera calibration probes in this folder (docs/calibration.md).

    .venv/bin/python scenes/calibration/make_probes.py

Each probe is a 5 x 4 grid of image regions, 2 px apart and 2.25 px from the border (no
region edge on a row or column of pixel centers, nothing clipped by the view). Region k
holds one plane, tilted by TILT degrees towards azimuth 90 k degrees in the camera's
(right, up) plane (the cycle of 4 over 5 columns shifts by one per row, so every part of
the image sees planes tilted every way), at a planar depth of 4 to 6 at its center, as two
separate triangles (one object each) with a diagonal gap of SPLIT px between them: no
shared edges, so no renderer can crack them apart. On such a plane 1/Z is affine in the
image-plane point sampled, so the Z buffers reveal where each backend sampled every pixel
(harness/rendiff_harness/judge/calibration.py). Vertices are intersections of pixel-corner rays
with the plane, computed here in float64 and written with 12 significant digits; the core
rounds them to f32 when it resolves the scene and the calibration uses those f32
vertices, so nothing here needs to be exact.

Two probes: `camera_near` (eye 7.7 from the origin: every backend at its best precision)
and `camera_far` (the same view moved by (20000, -12000, 8000): float32 camera transforms
lose about one float32 step of |eye| there, which the near probe cannot see). Eyes and
translations are float32-exact. near is 1e-4, and 1e-5 in the far probe, below half a
float32 step of the eye there, so that a ray origin moved to the near plane rounds back
onto the eye instead of anywhere within a float32 step of it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

WIDTH, HEIGHT, VFOV = 96, 72, 50.0
COLS, ROWS, GAP, BORDER = 5, 4, 2.0, 2.25
TILT = 35.0
SPLIT = 2.0
DEPTHS = (4.0, 4.5, 5.0, 5.5, 6.0)
EYE = np.array([4.75, 2.625, 5.5])
LOOK_AT = np.array([0.375, 0.25, -0.5])
UP = np.array([0.0, 1.0, 0.0])
FAR_OFFSET = np.array([20000.0, -12000.0, 8000.0])


def basis(eye: np.ndarray, look_at: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    f = look_at - eye
    f = f / np.linalg.norm(f)
    r = np.cross(f, up)
    r = r / np.linalg.norm(r)
    return f, r, np.cross(r, f)


def triangles(eye: np.ndarray, look_at: np.ndarray) -> list[list[np.ndarray]]:
    f, r, u = basis(eye, look_at, UP)
    t = math.tan(math.radians(VFOV) / 2.0)
    a = t * WIDTH / HEIGHT

    def ray(px: float, py: float) -> np.ndarray:
        return f + (2.0 * px / WIDTH - 1.0) * a * r + (1.0 - 2.0 * py / HEIGHT) * t * u

    cw = (WIDTH - 2 * BORDER - (COLS - 1) * GAP) / COLS
    ch = (HEIGHT - 2 * BORDER - (ROWS - 1) * GAP) / ROWS
    out = []
    for j in range(ROWS):
        for i in range(COLS):
            k = j * COLS + i
            x0, y0 = BORDER + i * (cw + GAP), BORDER + j * (ch + GAP)
            x1, y1 = x0 + cw, y0 + ch
            center = eye + DEPTHS[k % len(DEPTHS)] * ray((x0 + x1) / 2.0, (y0 + y1) / 2.0)
            az, tilt = math.radians(90.0 * (k % 4)), math.radians(TILT)
            n = -math.cos(tilt) * f + math.sin(tilt) * (math.cos(az) * r + math.sin(az) * u)
            corners = {}
            for key, (px, py) in {
                "tl": (x0, y0),
                "tr": (x1, y0),
                "br": (x1, y1),
                "bl": (x0, y1),
                "tl_x": (x0 + SPLIT, y0),
                "br_y": (x1, y1 - SPLIT),
                "tl_y": (x0, y0 + SPLIT),
                "br_x": (x1 - SPLIT, y1),
            }.items():
                d = ray(px, py)
                corners[key] = eye + (n @ (center - eye)) / (n @ d) * d
            out.append([corners["tl_x"], corners["tr"], corners["br_y"]])
            out.append([corners["tl_y"], corners["br_x"], corners["bl"]])
    return out


def number(x: float) -> str:
    return repr(float(f"{x:.12g}"))


def vec(v: np.ndarray) -> str:
    return "[" + ", ".join(number(float(c)) for c in v) + "]"


def probe(name: str, description: str, offset: np.ndarray, near: float) -> str:
    eye, look_at = EYE + offset, LOOK_AT + offset
    assert np.all(eye.astype(np.float32) == eye), "the eye must be float32-exact"
    lines = [
        "# Camera calibration probe, written by make_probes.py (docs/calibration.md). Do not edit by hand.",
        f'description = "{description}"',
        'requires = ["depth", "ids"]',
        "",
        "[camera]",
        f"eye = {vec(eye)}",
        f"look_at = {vec(look_at)}",
        f"up = {vec(UP)}",
        f"vfov = {VFOV!r}",
        f"width = {WIDTH}",
        f"height = {HEIGHT}",
        f"near = {near!r}",
        "far = 50.0",
    ]
    for k, tri in enumerate(triangles(eye, look_at)):
        verts = ", ".join(vec(v) for v in tri)
        lines += [
            "",
            "[[objects]]",
            f'name = "plane{k // 2:02d}{"ab"[k % 2]}"',
            f'shape = {{ kind = "triangles", vertices = [{verts}] }}',
        ]
    return "\n".join(lines) + "\n"


def main() -> None:
    here = Path(__file__).resolve().parent
    (here / "camera_near.toml").write_text(
        probe(
            "camera_near",
            "camera calibration probe: 20 tilted planes, eye 7.7 from the origin",
            np.zeros(3),
            1e-4,
        )
    )
    (here / "camera_far.toml").write_text(
        probe(
            "camera_far",
            "camera calibration probe: the near probe moved 2.5e4 from the origin (f32 camera transforms)",
            FAR_OFFSET,
            1e-5,
        )
    )


if __name__ == "__main__":
    main()
