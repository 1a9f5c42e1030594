"""Which texels of a texture a mesh's UV triangles cover (so a bake evaluates only those).

Texel (row y, column x) of an H x W image has its centre at u = (x + 0.5) / W, v = 1 - (y + 0.5) / H
(rows top to bottom, as the maps are written; Blender's v = 0 is the bottom row).  A texel is covered
when its centre lies inside or on a triangle; the mask is then dilated by ``margin`` texels so that
texture filtering and mip-mapping at island borders read baked texels too.

Hand-written (no library of the add-on's runtime rasterises triangles into a numpy mask): scanline
conversion, vectorised over all scanlines of a batch of triangles (each scanline's covered span lies
between its crossings with the triangle's edges).
"""

from __future__ import annotations

import numpy as np

#: Default dilation of the covered area, texels.
DEFAULT_MARGIN = 2


def uv_coverage(tri_uv: np.ndarray, width: int, height: int, margin: int = DEFAULT_MARGIN) -> np.ndarray:
    """(height, width) bool: texels whose centre lies in one of the triangles ``tri_uv`` (T, 3, 2) (u, v in
    UV space, [0, 1] is the texture), dilated by ``margin`` texels (a square neighbourhood).

    Degenerate (zero-area) triangles cover nothing.  Triangles may have either orientation.  Non-finite UVs
    raise ValueError; parts of triangles outside [0, 1]^2 are ignored (wrapping is the caller's choice).
    """
    uv = np.asarray(tri_uv, np.float64)
    if uv.ndim != 3 or uv.shape[1:] != (3, 2):
        raise ValueError(f"triangles must have shape (T, 3, 2), got {uv.shape}")
    if width < 1 or height < 1:
        raise ValueError(f"image size must be at least 1 x 1, got {width} x {height}")
    if margin < 0:
        raise ValueError("margin must be >= 0 texels")
    if not np.all(np.isfinite(uv)):
        raise ValueError("UV coordinates contain NaN/Inf")
    if len(uv) == 0:
        return np.zeros((height, width), bool)
    # texel-centre space: x = u W - 0.5, y = (1 - v) H - 0.5; texel (y, x) sits at integer (y, x)
    px = uv[..., 0] * width - 0.5
    py = (1.0 - uv[..., 1]) * height - 0.5
    area2 = (px[:, 1] - px[:, 0]) * (py[:, 2] - py[:, 0]) - (px[:, 2] - px[:, 0]) * (py[:, 1] - py[:, 0])
    y0 = np.clip(np.ceil(py.min(axis=1) - _EPS), 0, height).astype(np.int64)  # first and last scanline
    y1 = np.clip(np.floor(py.max(axis=1) + _EPS), -1, height - 1).astype(np.int64)
    rows = np.maximum(y1 - y0 + 1, 0) * (np.abs(area2) > 1e-12)
    ends = np.cumsum(rows)
    edges = np.zeros(height * (width + 1), np.int32)
    start = 0
    while start < len(rows):  # batches of about _BATCH_ROWS scanlines
        stop = int(np.searchsorted(ends, (ends[start - 1] if start else 0) + _BATCH_ROWS, side="right"))
        stop = max(stop, start + 1)
        _scanlines(edges, px[start:stop], py[start:stop], y0[start:stop], rows[start:stop], width)
        start = stop
    mask = np.cumsum(edges.reshape(height, width + 1), axis=1, dtype=np.int32)[:, :width] > 0
    return _dilate(mask, margin) if margin else mask


#: Tolerance (texels) for centres on a triangle's edge or vertex.
_EPS = 1e-9
#: Scanlines per batch (bounds the temporaries).
_BATCH_ROWS = 1 << 20


def _scanlines(edges, px, py, y0, rows, width) -> None:
    """Add each triangle's covered spans to ``edges`` ((H, W + 1) flat int32: +1 where a span starts, -1 after
    it ends).  With the vertices sorted by y (top t, middle m, bottom b), a scanline's span lies between the
    long edge t-b and the short edge t-m (above m) or m-b (from m down)."""
    order = np.argsort(py, axis=1, kind="stable")
    ys = np.take_along_axis(py, order, axis=1)
    xs = np.take_along_axis(px, order, axis=1)

    def slope(a: int, b: int) -> np.ndarray:
        dy = ys[:, b] - ys[:, a]
        return np.where(dy > 0, (xs[:, b] - xs[:, a]) / np.where(dy > 0, dy, 1.0), 0.0)

    s_long, s_top, s_bottom = slope(0, 2), slope(0, 1), slope(1, 2)
    tri = np.repeat(np.arange(len(rows)), rows)
    if tri.size == 0:
        return
    y = (y0[tri] + np.arange(tri.size) - np.repeat(np.cumsum(rows) - rows, rows)).astype(np.float64)
    x_long = xs[tri, 0] + (y - ys[tri, 0]) * s_long[tri]
    upper = y < ys[tri, 1]
    x_short = np.where(upper, xs[tri, 0] + (y - ys[tri, 0]) * s_top[tri], xs[tri, 1] + (y - ys[tri, 1]) * s_bottom[tri])
    lo, hi = np.minimum(x_long, x_short), np.maximum(x_long, x_short)
    x_lo = np.clip(np.ceil(lo - _EPS), 0, width).astype(np.int64)
    x_hi = np.clip(np.floor(hi + _EPS), -1, width - 1).astype(np.int64)
    span = x_hi >= x_lo
    row = y[span].astype(np.int64) * (width + 1)
    size = edges.size
    edges += np.bincount(row + x_lo[span], minlength=size)[:size].astype(np.int32)
    edges -= np.bincount(row + x_hi[span] + 1, minlength=size)[:size].astype(np.int32)


def _dilate(mask: np.ndarray, margin: int) -> np.ndarray:
    """Square dilation by ``margin`` texels (separable: rows, then columns)."""
    out = mask.copy()
    for _ in range(margin):
        grown = out.copy()
        grown[:, 1:] |= out[:, :-1]
        grown[:, :-1] |= out[:, 1:]
        out = grown
    for _ in range(margin):
        grown = out.copy()
        grown[1:] |= out[:-1]
        grown[:-1] |= out[1:]
        out = grown
    return out
