"""Embree's edge functions' own f32 products, bounded per edge (docs/verifier.md, "Embree's arithmetic").

Both of Embree 3.13.5's triangle tests decide coverage by the sign of edge functions f(D) = D . n
computed in f32, where D is the ray direction and n the normal of the plane through the ray origin
and one edge of the triangle moved to that origin (tolerance.embree_moved bounds that move). The
products' rounding errs by at most a bound Df on f, so the answer may flip wherever |D . n| <= Df:
within Df / |n| (in the plane's angle) of the edge's plane, which is a band around the edge's image.
|n| is about |v_a| |v_b| sin(angle at which the edge is seen from the eye), so the band grows without
bound for an edge that points at the eye: it is taken per edge and per pixel, never as one number.

* ROBUST (Pluecker, kernels/geometry/triangle_intersector_pluecker.h): U = dot(cross(e, s), D) with
  e = v_b' - v_a', s = v_b' + v_a' (v' = fl(v - org)). cross is msub(a.y, b.z, a.z * b.y) per component
  (common/math/vec3.h): <= gamma2 (|a_y b_z| + |a_z b_y|) off; dot is madd(a.x, b.x, madd(a.y, b.y,
  a.z * b.z)): <= gamma3 of the sum of |terms|. Together |fl(U) - U| <= gamma5 sum_c |D_c| (|e| x |s|)_c
  <= gamma5 sqrt(2) |D| |e| |s| (gamma_k = k u / (1 - k u); a fused multiply-add only rounds less).
  n = e x s = 2 x_b x x_a for the endpoints x = (e + s) / 2, y = (s - e) / 2 Embree effectively tests.
  Its margin eps = 2^-23 |fl(fl(U + V) + W)| is computed from the rounded U, V, W: 2^-23 times their
  errors and gamma3 of itself, at most 2^-21 (Df_U + Df_V + Df_W) more on each edge (the margin's own
  relative rounding is tolerance.EMBREE_ROBUST_EPS's (1 + 2^-21)).
* default (Moeller-Trumbore, kernels/geometry/triangle_intersector_moeller.h): R = cross(C, D) with
  C = fl(v0 - org), then U = dot(R, e2) (edge v0 v2), V = dot(R, e1) (edge v0 v1), den = dot(Ng, D) with
  Ng = cross(e2, e1), and the third edge is U + V <= |den|. Each of U, V is one cross and one dot:
  <= gamma5 sqrt(2) |D| |C| |e| off; the third edge's function |den| - fl(U + V) adds den's own gamma5
  sqrt(2) |D| |e1| |e2| and the sum's u |U + V| <= u (1 + gamma5 sqrt(2)) |D| |C| (|e1| + |e2|). Where
  |den| itself is within its error the ray runs along the plane within rounding: every edge of that
  triangle is unbounded at that pixel (inf).

From the band to pixels: the f32 ray D' (|D' - D| <= u |D|, D = (q, 1) in camera axes, forward
component >= 1 - u |D|) meets the image plane at P = D' / D'_f, and P's distance from the plane's
trace on the image plane is |P . n^| / |n^_perp|, with 1 / |n^_perp| <= |P0| for any point P0 of that
trace (P0 = (p, 1): n^_f = -p . n^_perp). With k = Df / |n| and c = 1 / (1 - u |D|) that distance is
<= k c ((1 + u) c |D| + distance), i.e. <= k c^2 (1 + u) |D| / (1 - k c): unbounded when k c >= 1.
At leading order gamma5 sqrt(2) |D|^2 |e| |s| / (|e x s| pixel): 7 u (1 + |q|^2) / pixel for an edge
seen broadside, which is what the measured 1e-4 px was.

The moved endpoints x differ from the exact v - org by at most `vertex_move` each, so |n| is bounded
below from the exact vectors: |x_a x x_b| >= |w_a x w_b| - m (|w_a| + |w_b| + m).
"""

from __future__ import annotations

import math

import numpy as np

U = 2.0**-24
"""f32's unit roundoff."""

MARGIN_ROUNDING = 2.0**-21
"""How much more than its exact value the ROBUST margin may be, relative, from its own f32 evaluation
(2^-23 (1 + gamma3) |U + V + W| plus 2^-23 of the products' errors: module docstring)."""

ROBUST_MOVE = (1.0 + math.sqrt(2.0) * (1.0 + U)) * U
"""ROBUST: each vertex rounded to the ray origin (u |v - org|), then the edge and sum vectors rounded
(sqrt(2) u (1 + u) |v - org|): how far the endpoints Embree tests are from v - org, per |v - org|."""


def gamma(k: int) -> float:
    """gamma_k = k u / (1 - k u): the relative error of k f32 roundings (Higham, Accuracy and Stability)."""
    return k * U / (1.0 - k * U)


def _cross_norm(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out: np.ndarray = np.linalg.norm(np.cross(a, b), axis=-1)
    return out


def _to_px(df: np.ndarray, n_lower: np.ndarray, d_norm: np.ndarray, pixel: float) -> np.ndarray:
    """A bound `df` on an edge function's error -> px on the image (module docstring), inf where none."""
    c = 1.0 / (1.0 - U * d_norm)
    with np.errstate(all="ignore"):
        k = np.where(n_lower > 0.0, df / n_lower, np.inf)
        img = k * c * c * (1.0 + U) * d_norm / (1.0 - k * c)
    px: np.ndarray = np.where((k * c < 1.0) & np.isfinite(img), img / pixel, np.inf)
    return px


def product_px(tris: np.ndarray, origin: np.ndarray, d: np.ndarray, pixel: float, robust: bool) -> np.ndarray:
    """(M, 3) px: how far the rounding of Embree's edge-function products may move each edge's image at
    each pixel, edge j running from corner j to corner j + 1 (verify.Side's order); inf where unbounded.

    `tris` (M, 3, 3) world vertices (the f32 scene's, in f64), `origin` the f32 ray origin, `d` (M, 3)
    the exact pixel ray direction in world axes (forward component 1), `pixel` one pixel on the image
    plane at distance 1."""
    w = np.asarray(tris, dtype=np.float64) - np.asarray(origin, dtype=np.float64)[None, None, :]
    dn = np.linalg.norm(np.asarray(d, dtype=np.float64), axis=1)
    dn32 = (1.0 + U) * dn  # |fl(D)|
    wn = np.linalg.norm(w, axis=2)  # (M, 3)
    out = np.full(w.shape[:2], np.inf)
    g5 = math.sqrt(2.0) * gamma(5)
    if robust:
        dfs, lows = [], []
        for j in range(3):
            a, b = j, (j + 1) % 3
            r = np.maximum(wn[:, a], wn[:, b])
            m = ROBUST_MOVE * r
            e_n = np.linalg.norm(w[:, b] - w[:, a], axis=1) + 2.0 * m
            s_n = np.linalg.norm(w[:, b] + w[:, a], axis=1) + 2.0 * m
            dfs.append(g5 * dn32 * e_n * s_n)
            lows.append(2.0 * (_cross_norm(w[:, a], w[:, b]) - m * (wn[:, a] + wn[:, b] + m)))
        total = dfs[0] + dfs[1] + dfs[2]
        for j in range(3):
            out[:, j] = _to_px(dfs[j] + MARGIN_ROUNDING * total, lows[j], dn, pixel)
        return out
    # Moeller: every tested vertex within u (|v0 - org| + longest edge) of v - org (tolerance.embree_moved).
    e1 = np.linalg.norm(w[:, 0] - w[:, 1], axis=1)
    e2 = np.linalg.norm(w[:, 2] - w[:, 0], axis=1)
    m = U * (wn[:, 0] + np.maximum(np.maximum(e1, e2), np.linalg.norm(w[:, 1] - w[:, 2], axis=1)))
    c_n = wn[:, 0] + m  # |fl(v0 - org)|
    e1n, e2n = (1.0 + U) * e1, (1.0 + U) * e2  # the stored fl(v0 - v1), fl(v2 - v0)

    def low(a: int, b: int) -> np.ndarray:
        lo: np.ndarray = _cross_norm(w[:, a], w[:, b]) - m * (wn[:, a] + wn[:, b] + m)
        return lo

    df_u = g5 * dn32 * c_n * e2n  # edge v0 v2: local edge 2
    df_v = g5 * dn32 * c_n * e1n  # edge v0 v1: local edge 0
    df_den = g5 * dn32 * e1n * e2n
    df_3 = df_u + df_v + df_den + U * (1.0 + g5) * dn32 * c_n * (e1n + e2n)  # edge v1 v2: local edge 1
    # den = D . (e2 x e1). Embree's is fl(dot(fl(cross(e2', e1')), fl(D))) with |e' - e| <= u |e|:
    # <= df_den + ((2u + u^2) |fl(D)| + u |D|) |e1| |e2| <= df_den + 4u |fl(D)| |e1| |e2| from it. Where
    # that reaches |den| its sign may flip, and every edge test with it: the ray runs along the plane.
    den = np.abs(np.einsum("ij,ij->i", np.asarray(d, dtype=np.float64), np.cross(w[:, 2] - w[:, 0], w[:, 0] - w[:, 1])))
    edge_on = den <= df_den + 4.0 * U * dn32 * e1 * e2
    out[:, 0] = _to_px(df_v, low(0, 1), dn, pixel)
    out[:, 1] = _to_px(df_3, low(1, 2), dn, pixel)
    out[:, 2] = _to_px(df_u, low(2, 0), dn, pixel)
    out[edge_on] = np.inf
    return out


def plane_move(tris: np.ndarray, origin: np.ndarray, robust: bool) -> np.ndarray:
    """(M,) world distance by which Embree's copy of each triangle at the ray origin may lie off the
    exact one (so its plane relative to the eye): the vertices moved to the f32 origin and rounded
    (tolerance.embree_moved's vertex terms, here per triangle). The crack test adds it to the eye's
    uncertainty for that triangle: an eye this near the plane may see it edge-on.

    default: C = fl(v0 - org) and the stored fl(v0 - v1), fl(v2 - v0): <= u (|v0 - org| + longest edge).
    ROBUST: fl(v - org), then the edge and sum vectors: <= (1 + sqrt(2) (1 + u)) u max |v - org|."""
    w = np.asarray(tris, dtype=np.float64) - np.asarray(origin, dtype=np.float64)[None, None, :]
    wn = np.linalg.norm(w, axis=2)
    if robust:
        moved: np.ndarray = ROBUST_MOVE * wn.max(axis=1)
        return moved
    longest = np.linalg.norm(w[:, [1, 2, 0]] - w, axis=2).max(axis=1)
    out: np.ndarray = U * (wn[:, 0] + longest)
    return out
