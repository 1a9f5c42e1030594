"""Vector Curves as piecewise linear functions (blender_addon.curves): the live group's exponential of the log
radius and inverse body fit, evaluated by Blender's curve mapping (the table Cycles samples), against the functions
they stand for (real bpy)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import bpy  # noqa: E402

from blender_addon import curves  # noqa: E402
from exporters import painted_gain, texel_table  # noqa: E402

TABLE = Path(__file__).resolve().parents[1] / "blender_addon" / "models" / "skin_inversion_table.npz"


def _evaluate(socket, xs: np.ndarray) -> np.ndarray:
    """Blender's evaluation (N, 3) of the curves of the Vector Curves node behind ``socket`` at ``xs``."""
    mapping = socket.node.mapping
    return np.array([[mapping.evaluate(mapping.curves[c], float(x)) for c in range(3)] for x in xs])


def _tree():
    tree = bpy.data.node_groups.new("curves test", "ShaderNodeTree")
    return tree, tree.nodes.new("ShaderNodeValue").outputs[0]


def test_the_exponential_of_the_tables_log_radii_is_within_2e4_relative():
    table = texel_table.load(TABLE)
    names = texel_table.channel_names(table.k)
    log_r = table.values[..., [i for i, n in enumerate(names) if n.startswith("log_radius_m_")]]
    lo, hi = float(np.nanmin(log_r)), float(np.nanmax(log_r))
    tree, value = _tree()
    out = curves.vector_curve(tree, value, *curves.smooth_points(np.exp, lo, hi))
    xs = np.linspace(lo, hi, 1501)
    got = _evaluate(out, xs)
    assert np.max(np.abs(got / np.exp(xs)[:, None] - 1.0)) < 2e-4
    assert _evaluate(out, [lo - 1.0, hi + 1.0]) == pytest.approx(np.exp([[lo] * 3, [hi] * 3]), rel=1e-5)


def test_the_inverse_body_fit_is_within_1e4_over_its_range():
    fit = painted_gain.body_fit(1.4)
    tree, value = _tree()
    out = curves.vector_curve(tree, value, *curves.smooth_points(lambda r: painted_gain.body_colour(r, fit),
                                                                 fit.low, 1.0))
    xs = np.linspace(fit.low, 1.0, 1501)
    assert np.max(np.abs(_evaluate(out, xs) - painted_gain.body_colour(xs, fit)[:, None])) < 1e-4


def test_bad_points_are_refused_in_one_line():
    tree, value = _tree()
    for xs, ys in (([0.0], [1.0]), ([0.0, 0.0], [1.0, 2.0]), ([0.0, 1.0], [np.nan, 1.0])):
        with pytest.raises(ValueError, match="increasing x"):
            curves.vector_curve(tree, value, np.array(xs), np.array(ys))
