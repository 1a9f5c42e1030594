"""The grazing-light correction in nodes: the node group **Spectral Skin SSS Grazing**, per-channel factors on the
mixture's weights and radii that grow with the view's facing angle (exporters.oblique_correction, whose ``factors``
the nodes follow).

Inputs ``Color`` (the painted colour, linear; clamped to [0, 1] here) and ``Normal`` (unlinked: the shading
normal); outputs ``Weight`` and ``Radius`` (the factors f and s per channel R, G, B) and ``Color`` (the colour
clamped to [0, 1], which the live group reads instead of clamping it again).  1 - mu = 1 - |N . I| is Layer
Weight's Facing (Blend 0.5) and Y the luminance of the colour; f = 1 + a(Y) h_w(mu) and s = 1 + b(Y) h_r(mu) are
read, bilinearly, from two small float images over (Y, 1 - mu) (exporters.oblique_correction.tables, packed in the
file: ``Spectral Skin SSS Grazing Weight`` and ``... Radius``, holding f and s), at one UV for both.  Where h = 0
(face-on views) the images hold 1 exactly, so both factors are 1 exactly.  The live group (blender_addon.live)
multiplies its components' weights and radii by them before the mixture group.

Why images and not nodes: the group is evaluated at every shading point, and its node count is a cost Principled
does not pay (docs/user/live_group.md, render cost); two texture lookups replace the two smooth steps, the two slope
curves and the two multiply-adds (and the conversions between them) that computed the same, and the images hold the
factors themselves, so no node follows the lookups.  The images' bilinear filter cuts the slopes' corners at the
knots by up to a quarter of a texel times the change of slope, and the smooth step's curvature over a texel adds a
little: :data:`TABLE_ERROR` bounds both for the shipped correction.
"""

from __future__ import annotations

import hashlib

import bpy

from . import wiring
from .core import colorimetry, oblique_correction

GROUP_NAME = "Spectral Skin SSS Grazing"
#: Custom property on the group: the SHA-256 of the correction (its JSON) the nodes were built from.
CORRECTION_PROP = wiring.OBLIQUE_PROP
#: Custom property on the group: how its nodes compute the correction (a group of another version is rebuilt).
VERSION_PROP = "spectral_skin_sss_grazing_version"
GRAZING_VERSION = 6
#: Largest difference of a factor f_c or s_c between the nodes (the images' bilinear filter) and the reference
#: (exporters.oblique_correction.factors), measured in Cycles by tests/test_oblique_correction.py.
TABLE_ERROR = 2e-3


def correction_sha(corr: oblique_correction.ObliqueCorrection) -> str:
    return hashlib.sha256(corr.to_json().encode()).hexdigest()


def ensure_group(corr: oblique_correction.ObliqueCorrection | None = None) -> bpy.types.NodeTree:
    """The group of ``corr`` (default: the shipped correction): reused when one of that correction exists."""
    corr = corr or oblique_correction.shipped()
    sha = correction_sha(corr)
    for group in bpy.data.node_groups:
        if (group.name.startswith(GROUP_NAME) and group.get(CORRECTION_PROP) == sha
                and group.get(VERSION_PROP) == GRAZING_VERSION):
            return group
    return build_group(corr)


def _node(tree, kind: str, x: float, y: float, **props):
    node = tree.nodes.new(kind)
    node.location = (x, y)
    for key, value in props.items():
        setattr(node, key, value)
    return node


def ensure_images(corr: oblique_correction.ObliqueCorrection) -> dict[str, bpy.types.Image]:
    """The correction's two tables (exporters.oblique_correction.tables) as packed float images, ``"Weight"`` and
    ``"Radius"``, reused when images of this correction exist (tagged: Remove Skin SSS removes them when unused)."""
    sha = correction_sha(corr)
    images, tables = {}, None
    for name in ("Weight", "Radius"):
        full = f"{GROUP_NAME} {name}"
        image = bpy.data.images.get(full)
        if image is not None and image.get(CORRECTION_PROP) == sha:
            images[name] = image
            continue
        tables = tables if tables is not None else oblique_correction.tables(corr)
        images[name] = wiring.packed_table_image(full, tables[name], CORRECTION_PROP, sha)
    return images


def build_group(corr: oblique_correction.ObliqueCorrection) -> bpy.types.NodeTree:
    """A new group of ``corr`` (module docstring)."""
    images = ensure_images(corr)
    tree = bpy.data.node_groups.new(GROUP_NAME, "ShaderNodeTree")
    tree[CORRECTION_PROP] = correction_sha(corr)
    tree[VERSION_PROP] = GRAZING_VERSION
    tree["spectral_skin_sss_backend"] = "GRAZING"  # an add-on group: Remove Skin SSS purges it when unused
    iface = tree.interface
    iface.new_socket("Color", in_out="INPUT", socket_type="NodeSocketColor").default_value = (0.6, 0.4, 0.3, 1.0)
    iface.new_socket("Normal", in_out="INPUT", socket_type="NodeSocketVector").hide_value = True
    iface.new_socket("Weight", in_out="OUTPUT", socket_type="NodeSocketVector")
    iface.new_socket("Radius", in_out="OUTPUT", socket_type="NodeSocketVector")
    iface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")
    gin = _node(tree, "NodeGroupInput", -900.0, 0.0)
    gout = _node(tree, "NodeGroupOutput", 300.0, 0.0)
    layer = _node(tree, "ShaderNodeLayerWeight", -700.0, 300.0, name="Facing")
    layer.inputs["Blend"].default_value = 0.5
    tree.links.new(gin.outputs["Normal"], layer.inputs["Normal"])
    dot = _node(tree, "ShaderNodeVectorMath", -700.0, -100.0, operation="DOT_PRODUCT")
    clamp = _node(tree, "ShaderNodeMix", -850.0, -100.0, data_type="RGBA", clamp_result=True)
    clamp.inputs["Factor"].default_value = 0.0
    tree.links.new(gin.outputs["Color"], clamp.inputs[6])  # A: the colour, clamped to [0, 1] on the way out
    tree.links.new(clamp.outputs[2], dot.inputs[0])
    tree.links.new(clamp.outputs[2], gout.inputs["Color"])
    dot.inputs[1].default_value = tuple(float(v) for v in colorimetry.SRGB_LUMINANCE)
    point = _node(tree, "ShaderNodeCombineColor", -500.0, 100.0)  # one SVM node where a Combine XYZ runs three
    tree.links.new(dot.outputs["Value"], point.inputs[0])
    tree.links.new(layer.outputs["Facing"], point.inputs[1])
    point.inputs[2].default_value = 0.0
    uv = _node(tree, "ShaderNodeVectorMath", -350.0, 100.0, operation="MULTIPLY_ADD")
    tree.links.new(point.outputs[0], uv.inputs[0])
    scale, offset = _texel_map(corr)
    uv.inputs[1].default_value, uv.inputs[2].default_value = scale, offset
    for row, name in enumerate(("Weight", "Radius")):
        y = 300.0 - 400.0 * row
        tex = _node(tree, "ShaderNodeTexImage", -200.0, y, image=images[name], interpolation="Linear",
                    extension="EXTEND")
        tree.links.new(uv.outputs["Vector"], tex.inputs["Vector"])
        tree.links.new(tex.outputs["Color"], gout.inputs[name])
    return tree


def _texel_map(corr: oblique_correction.ObliqueCorrection) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Scale and offset taking (luminance, facing, 0) to the UV of the tables' texels (Blender's pixel centres at
    (i + 0.5) / n): the first and last of exporters.oblique_correction.table_axes land on the first and last texel
    centres, beyond them the image's Extend repeats the edge."""
    (n_lum, n_facing), (lum, facing) = oblique_correction.TABLE_SIZE, oblique_correction.table_axes(corr)
    scale, offset = [], []
    for n, axis in ((n_lum, lum), (n_facing, facing)):
        step = (n - 1.0) / n / (axis[-1] - axis[0])
        scale.append(step)
        offset.append(0.5 / n - axis[0] * step)
    return (*scale, 0.0), (*offset, 0.0)


def wire_baked(material: bpy.types.Material, gnode: bpy.types.Node) -> bpy.types.Node | None:
    """Put the correction between a baked material's maps and its mixture group node ``gnode`` (blender_addon.baker):
    the Grazing group's weight factors into its Weight Scale (once for every component) and each ``k Radius`` map
    multiplied by its radius factors, the group fed the colour that fed the artist's Principled BSDF's Base Color (the
    baked albedo) and the mixture's Normal.  The new nodes are tagged (Remove Skin SSS removes them).  Returns the
    Grazing node, or None when the material has no Principled BSDF behind the group (wiring.artist_principled:
    straight or under Mix Shader and Add Shader layers; nothing is changed then)."""
    tree = gnode.id_data  # the material's tree, or the artist's node group it went into
    source = wiring.artist_principled(material)
    if source is None or source.id_data != tree:
        return None
    grazing = wiring.tag(tree.nodes.new("ShaderNodeGroup"))
    grazing.node_tree = ensure_group()
    grazing.label, grazing.parent = GROUP_NAME, gnode.parent
    grazing.location = (gnode.location.x - 700.0, gnode.location.y + 200.0)
    wiring.take_input(tree, source.inputs["Base Color"], grazing.inputs["Color"])
    wiring.take_input(tree, gnode.inputs["Normal"], grazing.inputs["Normal"])
    tree.links.new(grazing.outputs["Weight"], gnode.inputs["Weight Scale"])
    for socket in gnode.inputs:
        feed = wiring.feeding_socket(socket) if socket.name.startswith("k") and socket.name.endswith(" Radius") \
            else None
        if feed is None:
            continue
        scale = wiring.tag(tree.nodes.new("ShaderNodeVectorMath"))
        scale.operation, scale.parent = "MULTIPLY", gnode.parent
        scale.location = (gnode.location.x - 200.0, feed.node.location.y)
        tree.links.new(feed, scale.inputs[0])
        tree.links.new(grazing.outputs["Radius"], scale.inputs[1])
        tree.links.new(scale.outputs["Vector"], socket)
    return grazing


def map_node(socket: bpy.types.NodeSocket) -> bpy.types.Node | None:
    """The node feeding a mixture group's input ``socket`` in a baked material: the map's Image Texture behind the
    correction's Multiply (:func:`wire_baked`), else whatever feeds it directly (None when unlinked)."""
    links = [ln for ln in socket.links if not ln.is_muted]
    if not links:
        return None
    node = links[0].from_node
    if node.bl_idname == "ShaderNodeVectorMath" and node.operation == "MULTIPLY" and node.inputs[1].is_linked \
            and node.inputs[1].links[0].from_node.bl_idname == "ShaderNodeGroup" \
            and node.inputs[1].links[0].from_node.node_tree is not None \
            and node.inputs[1].links[0].from_node.node_tree.get(CORRECTION_PROP) and node.inputs[0].is_linked:
        return node.inputs[0].links[0].from_node
    return node
