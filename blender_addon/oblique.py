"""The grazing-light correction in nodes: the node group **Spectral Skin SSS Grazing**, per-channel factors on the
mixture's weights and radii that grow with the view's facing angle (exporters.oblique_correction, whose ``factors``
the nodes follow operation for operation).

Inputs ``Color`` (the painted colour, linear; clamped to [0, 1] here) and ``Normal`` (unlinked: the shading
normal); outputs ``Weight`` and ``Radius`` (the factors f and s per channel R, G, B) and ``Color`` (the colour
clamped to [0, 1], which the live group reads instead of clamping it again).  1 - mu = 1 - |N . I| is
Layer Weight's Facing (Blend 0.5); h a Map Range (Smooth Step) of it; Y the luminance of the colour; the slopes
a_c(Y), b_c(Y) one Vector Curves node each (fed (Y, Y, Y); per channel the piecewise linear curve through the knots,
vector handles, constant beyond the first and the last knot); f = 1 + a h_w, s = 1 + b h_r.  Where h = 0 (face-on
views) both are 1 exactly.  The live group (blender_addon.live) multiplies its components' weights and radii by
them before the mixture group.

Why curves and not a Map Range per knot interval (a sum of clamped ramps, exact): the group is evaluated at every
shading point, and its node count is a cost Principled does not pay (docs/user/live_group.md, render cost); the
group holds eleven nodes where it held thirty-six.  The curves' tables (blender_addon.curves) cut the corners at
the knots by up to a quarter of a table step times the change of slope there: :data:`CURVE_ERROR` bounds it for
the shipped correction.
"""

from __future__ import annotations

import hashlib

import bpy

from . import curves
from .core import colorimetry, oblique_correction

GROUP_NAME = "Spectral Skin SSS Grazing"
#: Custom property on the group: the SHA-256 of the correction (its JSON) the nodes were built from.
CORRECTION_PROP = "spectral_skin_sss_oblique"
#: Custom property on the group: how its nodes compute the correction (a group of another version is rebuilt).
VERSION_PROP = "spectral_skin_sss_grazing_version"
GRAZING_VERSION = 4
#: Largest difference of a slope a_c or b_c between the curves' tables and the knots' piecewise linear function
#: (both tables' interpolation, measured in Cycles by tests/test_oblique_correction.py).
CURVE_ERROR = 5e-3


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


def _map_range(tree, value, lo: float, hi: float, x: float, y: float, interpolation: str = "LINEAR"):
    """Vector Map Range (clamped) of ``value`` (a float, read as (v, v, v)) from [lo, hi] to [0, 1] in every
    component; its Vector socket (a vector, so that the Vector Math fed by it converts nothing)."""
    node = _node(tree, "ShaderNodeMapRange", x, y, data_type="FLOAT_VECTOR", interpolation_type=interpolation,
                 clamp=True)
    sockets = {s.identifier: s for s in node.inputs}
    tree.links.new(value, sockets["Vector"])
    for name, bound in (("From_Min_FLOAT3", lo), ("From_Max_FLOAT3", hi), ("To_Min_FLOAT3", 0.0),
                        ("To_Max_FLOAT3", 1.0)):
        sockets[name].default_value = (float(bound),) * 3
    return next(s for s in node.outputs if s.identifier == "Vector")


def build_group(corr: oblique_correction.ObliqueCorrection) -> bpy.types.NodeTree:
    """A new group of ``corr`` (module docstring)."""
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
    lum = dot.outputs["Value"]
    for row, (slope, ramp, name) in enumerate(((corr.weight_slope, corr.weight_ramp, "Weight"),
                                               (corr.radius_slope, corr.radius_ramp, "Radius"))):
        y = 300.0 - 400.0 * row
        h = _map_range(tree, layer.outputs["Facing"], *ramp, -300.0, y + 150.0, interpolation="SMOOTHSTEP")
        a = curves.vector_curve(tree, lum, corr.luminance, slope, (-300.0, y))
        out = _node(tree, "ShaderNodeVectorMath", 0.0, y, operation="MULTIPLY_ADD")
        tree.links.new(a, out.inputs[0])
        tree.links.new(h, out.inputs[1])
        out.inputs[2].default_value = (1.0, 1.0, 1.0)
        tree.links.new(out.outputs["Vector"], gout.inputs[name])
    return tree


def wire_baked(material: bpy.types.Material, gnode: bpy.types.Node) -> bpy.types.Node | None:
    """Put the correction between a baked material's maps and its mixture group node ``gnode`` (blender_addon.baker):
    the Grazing group's weight factors into its Weight Scale (once for every component) and each ``k Radius`` map
    multiplied by its radius factors, the group fed the colour that fed the artist's Principled BSDF's Base Color (the
    baked albedo) and the mixture's Normal.  The new nodes are tagged (Remove Skin SSS removes them).  Returns the
    Grazing node, or None when the material has no Principled BSDF behind the group (nothing is changed then)."""
    from . import nodes, wiring

    tree = material.node_tree
    source = tree.nodes.get(material.get(nodes.PREVIOUS_SURFACE_PROP, ""))
    if source is None or source.bl_idname != "ShaderNodeBsdfPrincipled":
        return None
    grazing = wiring.tag(tree.nodes.new("ShaderNodeGroup"))
    grazing.node_tree = ensure_group()
    grazing.label, grazing.parent = GROUP_NAME, gnode.parent
    grazing.location = (gnode.location.x - 700.0, gnode.location.y + 200.0)
    colour = nodes._feeding_socket(source.inputs["Base Color"])
    if colour is not None:
        tree.links.new(colour, grazing.inputs["Color"])
    else:
        grazing.inputs["Color"].default_value = tuple(source.inputs["Base Color"].default_value)
    normal = nodes._feeding_socket(gnode.inputs["Normal"])
    if normal is not None:
        tree.links.new(normal, grazing.inputs["Normal"])
    tree.links.new(grazing.outputs["Weight"], gnode.inputs["Weight Scale"])
    for socket in gnode.inputs:
        feed = nodes._feeding_socket(socket) if socket.name.startswith("k") and socket.name.endswith(" Radius") \
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
