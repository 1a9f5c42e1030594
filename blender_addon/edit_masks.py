"""The skin edit a material's live group renders, as a bake takes it (exporters.bake.BakeOptions ``edit`` and
``edit_masks``): its controls' values (:func:`blender_addon.live_edits.input_value`) and, where a mask paints them,
the mask's texels read from the Image Texture that paints it, at the albedo's texels.

A mask paints the edit through the group's Edit Mask (every control), or paints one control fed neutral + mask x
(value - neutral) by one node of the material (live_edits.masked_control: a Math Multiply Add, a Map Range from
0-1, a float Mix).  The mask is an Image Texture's Alpha, a channel of its Color split by a Separate Color (RGB), or
its Color where the image is grey (R = G = B, where any weighting of the channels gives that value), mapped as the
albedo is (the same vector, the same size).  Where the live group sits in an artist's node group and a
mask reaches it through the group's input, it is read where the one group node using the group is fed
(wiring.source_socket).  The group clamps the Edit Mask to [0, 1] and a bake clamps every mask
so (exporters.bake.edits), so the two agree wherever the masks lie in [0, 1].  Anything else feeding a control
(an attribute, a procedural texture, a mask on other UVs) cannot be read per texel: :class:`EditMaskError` says so.
"""

from __future__ import annotations

import bpy
import numpy as np

from . import live_edits, wiring
from .core import image_input, skin_edits

#: Separate Color's outputs in RGB mode, by name: the channel of the image's colour each gives.
_CHANNELS = {"Red": 0, "Green": 1, "Blue": 2}


class EditMaskError(ValueError):
    """A live group's edit that a bake cannot take; the message says what to change."""


def has_live_edit(material: bpy.types.Material | None) -> bool:
    """Whether the material's live group renders a skin edit (a control off its neutral value, or fed by a node):
    then a bake from the live group takes it (:func:`live_bake_edit`).  Cheap: reads no mask."""
    node = live_edits.live_node(material)
    return node is not None and any(live_edits.input_value(node, name) != neutral for name, neutral in
                                    zip(live_edits.CONTROL_NAMES, skin_edits.NEUTRAL, strict=True))


def live_bake_edit(material: bpy.types.Material | None, albedo_node: bpy.types.Node | None,
                   shape: tuple[int, int] | None) -> tuple[tuple[float, float, float], dict[str, np.ndarray]] | None:
    """(edit, masks) the material's live group renders: the controls' values (Melanin, Blood, Oxygenation) and
    per control it paints a mask (H, W) = ``shape`` in [0, 1], rows top down as the bake reads the albedo (the Edit
    Mask's texels times the control's own mask); None where the material has no live group or its edit is neutral
    and unpainted.  ``albedo_node``: the Image Texture a bake inverts (None: an albedo file, read through the default
    UV map); ``shape`` None: an albedo of UDIM tiles, which takes no masks.  :class:`EditMaskError` for a control or
    mask a bake cannot read."""
    node = live_edits.live_node(material)
    if node is None:
        return None
    painted = live_edits.MASK_INPUT in node.inputs and live_edits.input_value(node, live_edits.MASK_INPUT) is None
    weight = 1.0 if painted or live_edits.MASK_INPUT not in node.inputs else \
        float(np.clip(live_edits.input_value(node, live_edits.MASK_INPUT), 0.0, 1.0))
    edit, sources = [], {}
    for name, neutral in zip(live_edits.CONTROL_NAMES, skin_edits.NEUTRAL, strict=True):
        value = live_edits.input_value(node, name)
        if value is None:
            value, socket = _control_mask(node, name, neutral, material)
            if value != neutral:
                sources[name] = socket
        elif painted and value != neutral:
            sources[name] = None  # painted by the Edit Mask alone
        else:
            value = neutral + weight * (value - neutral)
        edit.append(value)
    if not sources and all(v == n for v, n in zip(edit, skin_edits.NEUTRAL, strict=True)):
        return None
    if sources and shape is None:
        raise EditMaskError("an albedo of UDIM tiles takes no edit masks: bake the edit's values, or paint it on a "
                            "single image")
    edit_mask = _mask_texels(wiring.source_socket(node.inputs[live_edits.MASK_INPUT]), albedo_node, shape,
                             live_edits.MASK_INPUT) if painted and sources else None
    masks = {}
    for name, socket in sources.items():
        own = _mask_texels(socket, albedo_node, shape, name) if socket is not None else None
        if own is None:
            masks[name.lower()] = edit_mask
        else:
            masks[name.lower()] = own * (edit_mask if edit_mask is not None else weight)
    return (edit[0], edit[1], edit[2]), masks


def _control_mask(node: bpy.types.Node, name: str, neutral: float,
                  material: bpy.types.Material) -> tuple[float, bpy.types.NodeSocket]:
    """(value, mask socket) of control ``name`` fed neutral + mask x (value - neutral)
    (:func:`blender_addon.live_edits.masked_control`); :class:`EditMaskError` where another node feeds it."""
    feed = wiring.source_socket(node.inputs[name])
    masked = live_edits.masked_control(feed, neutral)
    if masked is None:
        raise EditMaskError(f"{name} of '{material.name}' is fed by node '{feed.node.name}', which a bake cannot read "
                            "per texel: feed it neutral + mask x (value - neutral) from an Image Texture, paint the "
                            "edit through Edit Mask, or turn off Edit from the live group")
    return masked[1], masked[0]


def _mask_texels(socket: bpy.types.NodeSocket, albedo_node: bpy.types.Node | None, shape: tuple[int, int],
                 what: str) -> np.ndarray:
    """The texels (H, W) = ``shape`` float64, rows top down, of the mask output ``socket`` (module docstring: an
    Image Texture's Alpha, a Separate Color channel of its Color, or its Color where the image is grey), in the
    values the renderers read (an 8-bit sRGB image decoded; Non-Color and float images as they are).
    :class:`EditMaskError` for any other source, or an image not mapped as the albedo (``albedo_node``) is."""
    node, channel = socket.node, None
    if node.bl_idname == "ShaderNodeSeparateColor" and node.mode == "RGB" and socket.name in _CHANNELS:
        channel = _CHANNELS[socket.name]
        socket = wiring.source_socket(node.inputs[0])
        node = socket.node if socket is not None else None
        if node is not None and socket.name != "Color":
            node = None
    elif node.bl_idname == "ShaderNodeTexImage" and socket.name == "Alpha":
        channel = 3
    image = node.image if node is not None and node.bl_idname == "ShaderNodeTexImage" else None
    if image is None:
        raise EditMaskError(f"the {what} mask comes from node '{socket.node.name if socket else '?'}': a bake reads "
                            "masks from an Image Texture (its Alpha, or its Color through Separate Color)")
    _check_mapping(node, albedo_node, shape, what)
    w, h = image.size
    px = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, image.channels)[::-1].astype(np.float64)  # Blender stores rows bottom-up
    rgb = px[..., :3] if image.channels >= 3 else np.repeat(px[..., :1], 3, axis=-1)
    if channel == 3:
        return px[..., 3] if image.channels in (2, 4) else np.ones((h, w))
    if not image.is_float:
        space = image_input.colorspace_of_name(image.colorspace_settings.name, f"image '{image.name}'")
        rgb = image_input.to_linear(rgb, space or "srgb")
    if channel is None:
        if np.ptp(rgb, axis=-1).max(initial=0.0) > 1e-6:
            raise EditMaskError(f"the {what} mask is the colour of image '{image.name}', which is not grey: take one "
                                "channel of it through Separate Color")
        channel = 0
    return rgb[..., channel]


def _check_mapping(node: bpy.types.Node, albedo_node: bpy.types.Node | None, shape: tuple[int, int],
                   what: str) -> None:
    """:class:`EditMaskError` unless the mask's Image Texture ``node`` reads its image at the albedo's texels: the
    albedo's size, the same vector (both the default UV map, or the same UV Map node's map)."""
    w, h = node.image.size
    if (h, w) != tuple(shape):
        raise EditMaskError(f"the {what} mask image '{node.image.name}' is {w} x {h} px, the albedo {shape[1]} x "
                            f"{shape[0]}: a bake reads masks of the albedo's size")
    if _vector_source(node) != _vector_source(albedo_node):
        raise EditMaskError(f"the {what} mask image '{node.image.name}' is not mapped as the albedo is (another "
                            "vector or UV map): a bake reads masks on the albedo's UVs")


def _vector_source(node: bpy.types.Node | None) -> str | int:
    """How an Image Texture ``node`` (None: an albedo file) is mapped: "" for the default UV map, a UV Map node's
    map name, else the address of the output feeding its vector (the same output maps two images alike)."""
    feed = wiring.feeding_socket(node.inputs["Vector"]) if node is not None else None
    if feed is None:
        return ""
    return feed.node.uv_map if feed.node.bl_idname == "ShaderNodeUVMap" else feed.as_pointer()


def describe(edit: tuple[float, float, float], masks: dict[str, np.ndarray]) -> str:
    """``edit`` in the report's words: each control not neutral, and "painted" where a mask paints it."""
    words = [f"{name} {value:g}" + (" painted" if name.lower() in masks else "")
             for name, value, neutral in zip(live_edits.CONTROL_NAMES, edit, skin_edits.NEUTRAL, strict=True)
             if value != neutral]
    return ", ".join(words) or "as painted"
