"""Make docs/figures/metal_layer.png: a finger with a gold ring, lit from behind and the side, in Cycles.

The artist's material is one Principled BSDF: a medium skin colour, and gold with Metallic 1 on a band (a mask from
the object's coordinates mixes the colour and feeds Metallic), as a character's texture set paints a ring into the
skin's material.  Panels, left to right: that Principled BSDF (Blender's default Subsurface Radius and Scale); the
live group after Invert Skin Albedo, with the add-on's metal layer (blender_addon.wiring, "Metal and glass"); the
live group without the layer, which rendered the ring as gold-coloured skin.  The finger is 1.6 cm across, the ring
4 mm wide; Unit Scale 1.  Run from the repository root (about a minute on two cores)::

    .venv/bin/python docs/figures/metal_layer.py
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import bpy  # noqa: E402
from figure_cycles import area_light, before_after_without, cycles_scene, look_from, skin_material  # noqa: E402

from blender_addon import wiring  # noqa: E402
from exporters.colorimetry import srgb_decode  # noqa: E402

OUT = ROOT / "docs" / "figures" / "metal_layer.png"
WIDTH, HEIGHT, SAMPLES = 240, 120, 96
SKIN, GOLD = (198, 140, 112), (255, 196, 90)  # 8-bit sRGB
RADIUS, RING = 0.008, 0.004  # metres: the finger's radius, the ring's width


def scene() -> bpy.types.Object:
    """The finger (a capped cylinder along x), a camera, a back light and a dim side light; returns the finger."""
    sc = cycles_scene(WIDTH, HEIGHT, SAMPLES, 2, (0.02, 0.02, 0.025))
    bpy.ops.mesh.primitive_cylinder_add(vertices=64, radius=RADIUS, depth=0.06, rotation=(0.0, math.pi / 2, 0.0))
    finger = bpy.context.object
    bpy.ops.object.shade_smooth()
    look_from(sc, (0.0, -0.09, 0.012), 82)
    area_light((0.0, 0.05, 0.02), 0.6, 0.02, (-70.0, 0.0, 0.0))  # behind
    area_light((0.06, -0.05, 0.05), 0.25, 0.05, (45.0, 40.0, 0.0))  # a dim side light
    return finger


def artist_material(obj: bpy.types.Object) -> bpy.types.Material:
    """Skin with a gold band: a mask (|x| < RING / 2, object coordinates) mixes the Base Color and feeds Metallic."""
    mat = skin_material(obj, "Finger")
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    coords, split = tree.nodes.new("ShaderNodeTexCoord"), tree.nodes.new("ShaderNodeSeparateXYZ")
    tree.links.new(coords.outputs["Object"], split.inputs[0])
    distance = tree.nodes.new("ShaderNodeMath")
    distance.operation = "ABSOLUTE"
    tree.links.new(split.outputs["Z"], distance.inputs[0])  # the cylinder's axis is its local z
    band = tree.nodes.new("ShaderNodeMath")
    band.operation = "LESS_THAN"
    band.inputs[1].default_value = RING / 2
    tree.links.new(distance.outputs[0], band.inputs[0])
    colour = tree.nodes.new("ShaderNodeMix")
    colour.data_type = "RGBA"
    colour.inputs["A"].default_value = (*srgb_decode(np.array(SKIN) / 255.0), 1.0)
    colour.inputs["B"].default_value = (*srgb_decode(np.array(GOLD) / 255.0), 1.0)
    tree.links.new(band.outputs[0], colour.inputs["Factor"])
    tree.links.new(colour.outputs["Result"], principled.inputs["Base Color"])
    tree.links.new(band.outputs[0], principled.inputs["Metallic"])
    principled.inputs["Roughness"].default_value = 0.35
    return mat


def _has_layer(mat: bpy.types.Material) -> None:
    assert any(wiring.BASE_LAYER_PROP in n for n in mat.node_tree.nodes)


def main() -> None:
    finger = scene()
    artist_material(finger)
    before_after_without(finger, OUT, _has_layer, lambda mat: wiring.remove_base_layers(mat.node_tree))


if __name__ == "__main__":
    main()
