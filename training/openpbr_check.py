"""The OpenPBR maps (``--target openpbr``) checked in a renderer: Blender's Principled BSDF, which follows OpenPBR
Surface, reads them in Cycles and is compared with the live group (the K-media mixture) on the same scenes.

* :func:`principled_material` — the OpenPBR maps through a Principled BSDF: Base Color = subsurface_color,
  Subsurface Weight, Radius = subsurface_radius_scale, Scale = subsurface_radius x 4 pi (Cycles walks
  sigma_t = 4 pi / (Radius x Scale); OpenPBR's radius is the mean free path 1 / sigma_t: exporters.openpbr),
  Subsurface Anisotropy, Random Walk; Roughness and IOR of the written material.
* :func:`shadow_edge` — a flat skin box (1 unit = 1 cm) lit straight from above by a sun whose light a hidden
  plate stops over half of it: the light that bleeds under the plate, integrated across the shadow and divided by
  the lit level, is the *bleed width* (mm, per channel).
* :func:`ear` — the demo head (training.demo_subject, metres) with the demo's back light behind the ear: the mean
  linear colour over the ear's pixels.

``python -m training.openpbr_check --out DIR`` measures both for the live group and the Principled BSDF and writes
the figure of docs/user/other_renderers.md and the numbers as JSON.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: The box of :func:`shadow_edge`: size (units), unit scale (m per unit), plate height above the box (units).
BOX_UNIT_M, BOX_VIEW, PLATE_HEIGHT = 0.01, 1.0, 0.02


def _bpy():
    import bpy

    return bpy


def image_node(tree, path: Path, coords=None):
    """An Image Texture node reading ``path`` (Non-Color, closest texel), fed by ``coords`` when given."""
    bpy = _bpy()
    node = tree.nodes.new("ShaderNodeTexImage")
    node.image = bpy.data.images.load(str(path), check_existing=True)
    node.image.colorspace_settings.name = "Non-Color"
    node.interpolation, node.extension = "Closest", "EXTEND"
    if coords is not None:
        tree.links.new(coords, node.inputs["Vector"])
    return node


def principled_material(name: str, maps_dir: Path, stem: str, roughness: float, ior: float, coords=None):
    """A material whose Principled BSDF reads the OpenPBR maps ``<stem>_openpbr_*.exr`` of ``maps_dir`` (module
    docstring); ``coords``: a function (tree) -> the texture coordinate socket (None: the UV map)."""
    from exporters import openpbr

    bpy = _bpy()
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    vec = coords(tree) if coords is not None else None

    def read(kind: str):
        return image_node(tree, maps_dir / f"{stem}_openpbr_{kind}.exr", vec).outputs["Color"]

    bsdf.subsurface_method = "RANDOM_WALK"
    tree.links.new(read("subsurface_color"), bsdf.inputs["Base Color"])
    tree.links.new(read("subsurface_weight"), bsdf.inputs["Subsurface Weight"])
    tree.links.new(read("subsurface_radius_scale"), bsdf.inputs["Subsurface Radius"])
    scale = tree.nodes.new("ShaderNodeMath")
    scale.operation = "MULTIPLY"
    scale.inputs[1].default_value = openpbr.CYCLES_RADIUS_SCALE
    tree.links.new(read("subsurface_radius"), scale.inputs[0])
    tree.links.new(scale.outputs[0], bsdf.inputs["Subsurface Scale"])
    tree.links.new(read("subsurface_anisotropy"), bsdf.inputs["Subsurface Anisotropy"])
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["IOR"].default_value = ior
    return mat
