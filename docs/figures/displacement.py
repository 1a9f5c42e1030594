"""Make docs/figures/displacement.png: a patch of skin whose pores and fine lines come from the Material Output's
Displacement, under a grazing light, in Cycles.

The artist's material is one Principled BSDF (a medium skin colour, Subsurface Weight 1) and a Displacement node
(pores: a Voronoi texture's distance; fine lines: a stretched noise) linked to the Material Output's Displacement,
which Cycles renders as a bump (the material's default Displacement setting).  Panels, left to right: that Principled
BSDF (Blender's default Subsurface Radius and Scale); the live group after Invert Skin Albedo, whose Cycles output
takes the artist's Displacement (blender_addon.wiring.take_output_inputs); the same without it, as the live group
rendered it before its outputs took the Displacement: flat.  The patch is 3 cm wide; Unit Scale 1.  Run from the
repository root (about half a minute on two cores)::

    .venv/bin/python docs/figures/displacement.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import bpy  # noqa: E402
from figure_cycles import area_light, before_after_without, cycles_scene, look_from, skin_material  # noqa: E402

from blender_addon import wiring  # noqa: E402
from exporters.colorimetry import srgb_decode  # noqa: E402

OUT = ROOT / "docs" / "figures" / "displacement.png"
WIDTH, HEIGHT, SAMPLES = 200, 140, 64
SKIN = (198, 140, 112)  # 8-bit sRGB
SIDE = 0.03  # metres: the patch's width
DEPTH = 0.00015  # metres: the displacement's scale (pores a tenth of a millimetre deep)


def scene() -> bpy.types.Object:
    """The patch (a plane), a camera looking down at it obliquely and a grazing area light; returns the patch."""
    sc = cycles_scene(WIDTH, HEIGHT, SAMPLES, 3, (0.03, 0.03, 0.035))
    bpy.ops.mesh.primitive_cube_add(size=1.0, scale=(SIDE, SIDE, 0.01), location=(0.0, 0.0, -0.005))
    patch = bpy.context.object
    look_from(sc, (0.0, -0.028, 0.022), 52)
    area_light((0.06, 0.01, 0.006), 0.4, 0.01, (0.0, 84.0, 0.0))
    return patch


def artist_material(obj: bpy.types.Object) -> bpy.types.Material:
    """Skin with pores and fine lines in the Material Output's Displacement."""
    mat = skin_material(obj, "Skin")
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    principled.inputs["Base Color"].default_value = (*srgb_decode(np.array(SKIN) / 255.0), 1.0)
    principled.inputs["Roughness"].default_value = 0.45
    pores = tree.nodes.new("ShaderNodeTexVoronoi")
    pores.feature = "F1"
    pores.inputs["Scale"].default_value = 900.0
    lines = tree.nodes.new("ShaderNodeTexNoise")
    lines.inputs["Scale"].default_value = 120.0
    stretch = tree.nodes.new("ShaderNodeMapping")
    stretch.inputs["Scale"].default_value = (1.0, 8.0, 1.0)
    coords = tree.nodes.new("ShaderNodeTexCoord")
    tree.links.new(coords.outputs["Object"], pores.inputs["Vector"])
    tree.links.new(coords.outputs["Object"], stretch.inputs["Vector"])
    tree.links.new(stretch.outputs["Vector"], lines.inputs["Vector"])
    height = tree.nodes.new("ShaderNodeMath")
    height.operation = "MULTIPLY_ADD"
    height.inputs[1].default_value = 0.5
    tree.links.new(lines.outputs["Fac"], height.inputs[0])
    tree.links.new(pores.outputs["Distance"], height.inputs[2])
    displacement = tree.nodes.new("ShaderNodeDisplacement")
    displacement.inputs["Scale"].default_value = DEPTH
    tree.links.new(height.outputs[0], displacement.inputs["Height"])
    tree.links.new(displacement.outputs[0], tree.nodes["Material Output"].inputs["Displacement"])
    return mat


def _output(mat: bpy.types.Material) -> bpy.types.Node:
    """The Material Output Cycles renders (the add-on's, after Invert Skin Albedo)."""
    return wiring.render_output(mat.node_tree, "CYCLES")


def _takes_displacement(mat: bpy.types.Material) -> None:
    assert _output(mat).inputs["Displacement"].is_linked


def main() -> None:
    patch = scene()
    artist_material(patch)
    before_after_without(patch, OUT, _takes_displacement,
                         lambda mat: mat.node_tree.links.remove(_output(mat).inputs["Displacement"].links[0]))


if __name__ == "__main__":
    main()
