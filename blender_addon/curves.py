"""Piecewise linear functions as RGB Curves nodes: one node where Math nodes would need a chain.

Every node of a shader group costs each shading point its time (docs/user/live_group.md, render cost), so a smooth
function of a value the group computes (the exponential of a log radius, the inverse of the body reflectance, an
edit's exponential) is evaluated as a curve: an RGB Curves node whose three curves (R, G, B) are the piecewise
linear interpolation (vector handles) through given points, constant beyond the first and the last, and whose
combined curve C (applied first) is the identity over the points' range.  Why RGB Curves and not Vector Curves,
which Cycles' SVM evaluates with the same node: Cycles' OSL shader for Vector Curves looks every channel up at the
input's first component (node_vector_curves.osl, Cycles 5.0 and later: ``rgb_ramp_lookup(ramp, c[0], ...)`` for
all three), so under OSL the green and blue channels came out as functions of the red input (the live group's
radii and colours: 4.5 % greener than under SVM on the demo head); RGB Curves looks each channel up at its own.

How exact: Blender tabulates each curve at 257 points over its clip range (set here to the points' range) and
Cycles samples that table at 256 points (RAMP_TABLE_SIZE), both interpolated linearly.  Through points that lie
closer than the tables' step the curve follows the function to within about f'' h^2 / 4 (h the range over 256); at
a kink (the slopes' knots) the tables cut the corner by up to a quarter of a step times the change of slope.
Rendered in Blender 4.2, 5.0 and 5.3 the exponential over the shipped table's log radii comes out within 4e-5
relative; only where the curve's input is a constant (a plain colour, no texture), which Cycles folds when it
compiles the shader, Blender 4.2 evaluates it less exactly (within 2.4e-3 relative).
"""

from __future__ import annotations

import bpy
import numpy as np

#: Points of a curve tabulating a smooth function: as many as Blender's own table holds.
SMOOTH_POINTS = 257


def channel_curves(tree: bpy.types.NodeTree, socket: bpy.types.NodeSocket, xs: np.ndarray, ys: np.ndarray,
                   location: tuple[float, float] = (0.0, 0.0)) -> bpy.types.NodeSocket:
    """An RGB Curves node in ``tree`` of ``socket`` (a vector or colour, or a float read as (v, v, v)) through the
    points (xs[i], ys[i, c]) for channel c (``ys`` (N, 3), or (N,) for the same curve in every channel; ``xs`` (N,)
    increasing), its combined curve the identity; returns its colour output (linked to a vector input it is read
    as is)."""
    xs = np.asarray(xs, np.float64)
    ys = np.broadcast_to(np.asarray(ys, np.float64).reshape(len(xs), -1), (len(xs), 3))
    _check(xs, ys)
    node = tree.nodes.new("ShaderNodeRGBCurve")
    node.location = location
    tree.links.new(socket, node.inputs["Color"])
    _set_points(node.mapping, [(xs, ys[:, c]) for c in range(3)] + [(xs[[0, -1]], xs[[0, -1]])])
    return node.outputs["Color"]


def set_float_curve(node: bpy.types.Node, xs: np.ndarray, ys: np.ndarray) -> None:
    """Make a Float Curve node the piecewise linear function through the points (xs[i], ys[i]) (``xs`` increasing;
    constant beyond the first and the last), of factor 1."""
    xs, ys = np.asarray(xs, np.float64), np.asarray(ys, np.float64)
    _check(xs, ys)
    node.inputs["Factor"].default_value = 1.0
    _set_points(node.mapping, [(xs, ys)])


def _check(xs: np.ndarray, ys: np.ndarray) -> None:
    if len(xs) < 2 or np.any(np.diff(xs) <= 0.0) or not (np.all(np.isfinite(xs)) and np.all(np.isfinite(ys))):
        raise ValueError("a curve needs two or more finite points with increasing x")


def _set_points(mapping: bpy.types.CurveMapping, points_of: list[tuple[np.ndarray, np.ndarray]]) -> None:
    """Set each curve of ``mapping`` to the points (x, y) of ``points_of``, with vector handles (straight lines), the
    clip range the first curve's x range, constant beyond it."""
    xs = points_of[0][0]
    mapping.use_clip = False
    mapping.clip_min_x, mapping.clip_max_x = float(xs[0]), float(xs[-1])
    mapping.extend = "HORIZONTAL"
    for curve, (cx, cy) in zip(mapping.curves, points_of, strict=True):
        points = curve.points
        while len(points) > len(cx):
            points.remove(points[-1])
        while len(points) < len(cx):
            points.new(float(cx[-1]), float(cy[-1]))
        points.foreach_set("location", np.stack([cx, cy], axis=1).astype(np.float32).ravel())
        for point in points:
            point.handle_type = "VECTOR"
    mapping.update()


def smooth_points(function, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """:data:`SMOOTH_POINTS` points (xs, function(xs)) evenly over [lo, hi] (a range of zero width is widened by
    1e-6 on each side)."""
    if not hi > lo:
        lo, hi = lo - 1e-6, hi + 1e-6
    xs = np.linspace(lo, hi, SMOOTH_POINTS)
    return xs, np.asarray(function(xs), np.float64)
