"""Independent form-factor references for the core tests: closed forms (REFERENCE.md
section 3) and a brute-force midpoint quadrature, written here, not taken from raytrad."""

from __future__ import annotations

import math

import numpy as np

from raytrad.core.kernels import polygon_form_factor

UP = np.array([0.0, 0.0, 1.0])


def corner_factor(a: float, b: float, c: float) -> float:
    """dA parallel to an a x b rectangle, on the normal through a corner, at distance c."""
    ra, rb = math.hypot(a, c), math.hypot(b, c)
    return (a / ra * math.atan(b / ra) + b / rb * math.atan(a / rb)) / (2.0 * math.pi)


def quadrature_factor(
    origin: np.ndarray,
    edge_u: np.ndarray,
    edge_v: np.ndarray,
    point: np.ndarray,
    normal: np.ndarray,
    triangle: bool = False,
    n: int = 2000,
) -> float:
    """Midpoint rule for F(point <- parallelogram or triangle), upper half-space only.

    The surface is ``origin + u edge_u + v edge_v`` for (u, v) in [0, 1]^2, or the triangle
    u + v <= 1 (cells on the diagonal count half). Directions below the receiver's horizon
    contribute nothing (the integrand is ``max(cos_x, 0) |cos_y| / (pi r^2)``).
    """
    cross = np.cross(edge_u, edge_v)
    area = float(np.linalg.norm(cross))
    surface_normal = cross / area
    s = (np.arange(n) + 0.5) / n
    total = 0.0
    for start in range(0, n, 250):  # rows in blocks keep the temporaries small
        u, v = np.meshgrid(s[start : start + 250], s, indexing="ij")
        y = origin + u[..., None] * edge_u + v[..., None] * edge_v
        d = y - point
        r2 = np.einsum("...j,...j", d, d)
        r = np.sqrt(r2)
        cos_x = np.clip(d @ normal / r, 0.0, None)
        cos_y = np.abs(d @ surface_normal) / r
        f = cos_x * cos_y / (math.pi * r2)
        if triangle:
            w = u + v
            f = np.where(np.isclose(w, 1.0), 0.5 * f, np.where(w < 1.0, f, 0.0))
        total += float(f.sum())
    return total * area / (n * n)


def square(x0: float, x1: float, y0: float, y1: float, z: float, up: bool = True) -> list:
    """Corners of an axis-aligned rectangle in the plane z, facing +z (or -z)."""
    corners = [(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)]
    return corners if up else corners[::-1]


def two_triangles(quad: list) -> np.ndarray:
    """The two triangles (corners 0-1-2, 0-2-3) of a quad."""
    q = np.asarray(quad, dtype=np.float64)
    return np.stack([q[[0, 1, 2]], q[[0, 2, 3]]])


def polygon_factor(triangles: np.ndarray, point: np.ndarray, normal: np.ndarray) -> float:
    """The kernel's factor from ``point`` to a polygon given as triangles (summed)."""
    k = len(triangles)
    return float(
        polygon_form_factor(triangles, np.tile(point, (k, 1)), np.tile(normal, (k, 1))).sum()
    )
