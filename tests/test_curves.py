"""RGB Curves as piecewise linear functions (blender_addon.curves): the live group's exponential of the log radius
and inverse body fit, evaluated by Blender's curve mapping (the table Cycles samples), against the functions they
stand for, and rendered by Cycles with SVM and with OSL (real bpy)."""

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
    """Blender's evaluation (N, 3) of the curves of the RGB Curves node behind ``socket`` at ``xs``: the combined
    curve C (the mapping's fourth), then R, G or B, as Blender hands the table to Cycles."""
    mapping = socket.node.mapping
    combined = mapping.curves[3]
    return np.array([[mapping.evaluate(mapping.curves[c], mapping.evaluate(combined, float(x))) for c in range(3)]
                     for x in xs])


def _tree():
    tree = bpy.data.node_groups.new("curves test", "ShaderNodeTree")
    return tree, tree.nodes.new("ShaderNodeValue").outputs[0]


def test_the_exponential_of_the_tables_log_radii_is_within_2e4_relative():
    table = texel_table.load(TABLE)
    names = texel_table.channel_names(table.k)
    log_r = table.values[..., [i for i, n in enumerate(names) if n.startswith("log_radius_m_")]]
    lo, hi = float(np.nanmin(log_r)), float(np.nanmax(log_r))
    tree, value = _tree()
    out = curves.channel_curves(tree, value, *curves.smooth_points(np.exp, lo, hi))
    xs = np.linspace(lo, hi, 1501)
    got = _evaluate(out, xs)
    assert np.max(np.abs(got / np.exp(xs)[:, None] - 1.0)) < 2e-4
    assert _evaluate(out, [lo - 1.0, hi + 1.0]) == pytest.approx(np.exp([[lo] * 3, [hi] * 3]), rel=1e-5)


def test_the_inverse_body_fit_is_within_1e4_over_its_range():
    fit = painted_gain.body_fit(1.4)
    tree, value = _tree()
    out = curves.channel_curves(tree, value, *curves.smooth_points(lambda r: painted_gain.body_colour(r, fit),
                                                                 fit.low, 1.0))
    xs = np.linspace(fit.low, 1.0, 1501)
    assert np.max(np.abs(_evaluate(out, xs) - painted_gain.body_colour(xs, fit)[:, None])) < 1e-4


def test_bad_points_are_refused_in_one_line():
    tree, value = _tree()
    for xs, ys in (([0.0], [1.0]), ([0.0, 0.0], [1.0, 2.0]), ([0.0, 1.0], [np.nan, 1.0])):
        with pytest.raises(ValueError, match="increasing x"):
            curves.channel_curves(tree, value, np.array(xs), np.array(ys))


def _render_curves(osl: bool, path: Path) -> np.ndarray:
    """A 16 x 16 px render (1 sample, Standard view) of a plane emitting the curves of exp over [0, 1] at three
    different inputs per pixel (the generated coordinates x, y and x / 2 + 1 / 4), with OSL or SVM."""
    scene = bpy.data.scenes.new(f"curves osl {osl}")
    scene.render.engine = "CYCLES"
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = "CPU", 1, False
    scene.cycles.shading_system = osl
    scene.render.resolution_x = scene.render.resolution_y = 16
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format, scene.render.image_settings.color_depth = "OPEN_EXR", "32"
    scene.render.filepath = str(path)
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    camera.data.type, camera.data.ortho_scale, camera.location = "ORTHO", 2.0, (0.0, 0.0, 5.0)
    scene.collection.objects.link(camera)
    scene.camera = camera
    mesh = bpy.data.meshes.new("plane")
    mesh.from_pydata([(-1.0, -1.0, 0.0), (1.0, -1.0, 0.0), (1.0, 1.0, 0.0), (-1.0, 1.0, 0.0)], [], [(0, 1, 2, 3)])
    plane = bpy.data.objects.new("plane", mesh)
    scene.collection.objects.link(plane)
    material = bpy.data.materials.new("curves")
    material.use_nodes = True
    tree = material.node_tree
    tree.nodes.clear()
    split = tree.nodes.new("ShaderNodeSeparateXYZ")
    tree.links.new(tree.nodes.new("ShaderNodeTexCoord").outputs["Generated"], split.inputs[0])
    inputs = tree.nodes.new("ShaderNodeCombineColor")
    tree.links.new(split.outputs[0], inputs.inputs[0])
    tree.links.new(split.outputs[1], inputs.inputs[1])
    half = tree.nodes.new("ShaderNodeMath")
    half.operation, half.inputs[1].default_value, half.inputs[2].default_value = "MULTIPLY_ADD", 0.5, 0.25
    tree.links.new(split.outputs[0], half.inputs[0])
    tree.links.new(half.outputs[0], inputs.inputs[2])
    emission = tree.nodes.new("ShaderNodeEmission")
    tree.links.new(curves.channel_curves(tree, inputs.outputs[0], *curves.smooth_points(np.exp, 0.0, 1.0)),
                   emission.inputs["Color"])
    tree.links.new(emission.outputs[0], tree.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    mesh.materials.append(material)
    bpy.ops.render.render(write_still=True, scene=scene.name)
    import OpenImageIO as oiio

    return oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)


def test_each_channel_follows_its_own_input_with_svm_and_with_osl(tmp_path):
    """Cycles' OSL shader for Vector Curves looks every channel up at the first input, so the group's curves are RGB
    Curves: rendered with OSL they give what SVM gives, each channel the curve of its own input."""
    svm, osl = (_render_curves(flag, tmp_path / f"curves_{flag}.exr") for flag in (False, True))
    assert np.all(svm > 0.99) and np.all(svm < np.e + 1e-3)
    assert np.max(np.abs(svm[..., 0] - svm[..., 1])) > 0.5  # the channels' inputs differ: the test can tell
    assert np.max(np.abs(osl - svm)) < 1e-4
