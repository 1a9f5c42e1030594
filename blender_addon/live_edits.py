"""The live group's skin edits: inputs **Melanin**, **Blood** and **Oxygenation** (exporters.skin_edits) in nodes.

The edit table (exporters.edit_table) is packed into three small float images (one per control: its levels' slice
atlases, as exporters.live_table's, stacked with a zero atlas for the neutral level).  For the painted colour c the
nodes compute, as exporters.edit_table.shift and edited_colour:

* control coordinates s = (log2 clamp(Melanin), log2 clamp(Blood), clamp(Oxygenation)); per control the two
  levels around s, read by trilinear lookups at c and interpolated linearly (the hat weights of
  exporters.edit_table.shift); the shift D is their sum over the controls;
* the edited colour c exp(D_RGB) (what the rest of the group reads instead of c: the table's lookup, the EEVEE
  colour) and the radius factor exp(D_A) (every component's radius is multiplied by it).

At neutral inputs each control reads its zero atlas with weight exactly 1 (its neighbour with weight exactly 0), so
D = 0, c exp(0) = c and r x exp(0) = r: the group renders its unedited result bit for bit.  Each input takes a value
or any node (a painted mask through a Mix node, an attribute, a driver); its keyframes animate it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import bpy

from . import wiring
from .core import edit_table, live_table, maps, skin_edits

#: Custom property on the edit images and the group: the SHA-256 of the edit table they were made from.
EDIT_TABLE_PROP = wiring.EDIT_TABLE_PROP
IMAGE_PREFIX = "Spectral Skin SSS Edits"
#: The group's inputs, in order: (name, default, soft minimum, soft maximum, tooltip).
INPUTS = tuple(
    (name.title(), skin_edits.NEUTRAL[j], *skin_edits.CONTROL_RANGES[name], tip)
    for j, (name, tip) in enumerate((
        ("melanin", "Multiplies the epidermis's melanin fraction (1 = as painted): tan above 1, lighter below"),
        ("blood", "Multiplies the dermis's blood fraction (1 = as painted): flush above 1, pallor below"),
        ("oxygenation", "Shifts the blood's oxygen saturation (0 = as painted): below 0 cold, bluish skin"))))


def table_for_model(model_path: str, texel_sha256: str) -> edit_table.EditTable | None:
    """The edit table beside ``model_path`` made from that model and the texel table of SHA-256 ``texel_sha256``, or
    None (the group is then built without the edit inputs)."""
    path = edit_table.default_path(model_path)
    try:
        table = edit_table.load(path)
    except edit_table.EditTableError:
        return None
    if table.meta.get("model_sha256") != maps.sha256_file(model_path) or \
            table.meta.get("texel_table_sha256") != texel_sha256:
        return None
    return table


def ensure_images(table: edit_table.EditTable) -> dict[str, bpy.types.Image]:
    """The edit table's images (one per control, its levels' atlases stacked), packed, one set per file (reused
    when images of this table exist)."""
    atlases = None
    images = {}
    for j in range(len(skin_edits.CONTROLS)):
        name = edit_table.image_name(j)
        full = f"{IMAGE_PREFIX} {name}"
        image = bpy.data.images.get(full)
        if image is not None and image.get(EDIT_TABLE_PROP) == table.sha256:
            images[name] = image
            continue
        atlases = atlases if atlases is not None else table.atlases()
        pixels = atlases[name]
        if image is not None and image.users == 0:
            bpy.data.images.remove(image)
        image = bpy.data.images.new(full, pixels.shape[1], pixels.shape[0], alpha=True, float_buffer=True)
        image.colorspace_settings.name = "Non-Color"
        image.alpha_mode = "CHANNEL_PACKED"  # A holds the log-radius correction, not coverage
        image.pixels.foreach_set(pixels.ravel())
        image.pack()
        image[EDIT_TABLE_PROP] = table.sha256
        images[name] = image
    return images


def add_inputs(group: bpy.types.NodeTree) -> None:
    """The Melanin, Blood and Oxygenation inputs of the group interface (neutral defaults)."""
    for name, default, lo, hi, tip in INPUTS:
        socket = group.interface.new_socket(name, in_out="INPUT", socket_type="NodeSocketFloat")
        socket.default_value, socket.min_value, socket.max_value = default, lo, hi
        socket.description = tip


@dataclass
class EditBranch:
    """What the edit nodes give the group: the edited ``colour`` and the ``radius_factor`` exp(D_A)."""

    colour: bpy.types.NodeSocket
    radius_factor: bpy.types.NodeSocket


EDIT_GROUP_NAME = "Spectral Skin SSS Edits"


def ensure_edit_group(table: edit_table.EditTable, images: dict[str, bpy.types.Image]) -> bpy.types.NodeTree:
    """The edit nodes as their own group (inputs Color, Melanin, Blood, Oxygenation; outputs Color, Radius Factor),
    one per edit table and file: Blender adds nodes to a tree in time growing with its size, so the edit nodes in a
    group of their own keep the live group's build (the operator) fast."""
    from . import live

    for group in bpy.data.node_groups:
        if group.name.startswith(EDIT_GROUP_NAME) and group.get(EDIT_TABLE_PROP) == table.sha256 \
                and group.get("spectral_skin_sss_version") == live.LIVE_VERSION:
            return group
    group = bpy.data.node_groups.new(EDIT_GROUP_NAME, "ShaderNodeTree")
    group[EDIT_TABLE_PROP] = table.sha256
    group["spectral_skin_sss_version"] = live.LIVE_VERSION
    group.interface.new_socket("Color", in_out="INPUT", socket_type="NodeSocketColor")
    add_inputs(group)
    group.interface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")
    group.interface.new_socket("Radius Factor", in_out="OUTPUT", socket_type="NodeSocketFloat")
    gin = group.nodes.new("NodeGroupInput")
    gout = group.nodes.new("NodeGroupOutput")
    gin.location, gout.location = (-1900.0, 0.0), (4400.0, 0.0)
    branch = add_edit_branch(live._Builder(group), gin, table, images)
    group.links.new(branch.colour, gout.inputs["Color"])
    group.links.new(branch.radius_factor, gout.inputs["Radius Factor"])
    return group


def edit_node(b, gin, table: edit_table.EditTable, images: dict[str, bpy.types.Image]) -> EditBranch:
    """A node of the edit group (:func:`ensure_edit_group`) in the live group, fed by its Color and edit inputs."""
    node = b.node("ShaderNodeGroup", 1, node_tree=ensure_edit_group(table, images))
    for name in ("Color", *(spec[0] for spec in INPUTS)):
        b.link(gin.outputs[name], node.inputs[name])
    return EditBranch(colour=node.outputs["Color"], radius_factor=node.outputs["Radius Factor"])


def _coordinate(b, gin, j: int, stage: int):
    """Control coordinate s_j: log2 of the clamped multiplier, or the clamped shift."""
    name = skin_edits.CONTROLS[j]
    lo, hi = skin_edits.CONTROL_RANGES[name]
    x = b.math("MINIMUM", stage + 1, b.math("MAXIMUM", stage, gin.outputs[INPUTS[j][0]], lo), hi)
    return x if name == "oxygenation" else b.math("LOGARITHM", stage + 2, x, 2.0)


def add_edit_branch(b, gin, table: edit_table.EditTable, images: dict[str, bpy.types.Image]) -> EditBranch:
    """The edit nodes (module docstring) on the group's Color input; ``b`` the group's builder (blender_addon.live)."""
    from . import live

    layout = table.layout()
    colour = gin.outputs["Color"]
    e = [live._srgb_encode(b, b.math("ADD", 30, _channel(b, colour, c), 0.0, clamp=True), 31) for c in range(3)]
    coords = [b.math("MULTIPLY", 36, b.math("ADD", 35, b.math("ADD", 35, e[0], e[1]), e[2]), 1.0 / 3.0),
              b.math("SUBTRACT", 36, e[0], e[1]), b.math("SUBTRACT", 36, e[1], e[2])]
    x = [b.math("MINIMUM", 39, b.math("MAXIMUM", 38, b.math("MULTIPLY_ADD", 37, coord, 1.0 / layout.step,
                                                                        -layout.origin[d] / layout.step), 0.0),
                layout.shape[d] - 1.0) for d, coord in enumerate(coords)]
    s = b.math("MINIMUM", 41, b.math("FLOOR", 40, x[0]), layout.shape[0] - 2.0)
    frac = b.math("SUBTRACT", 42, x[0], s)
    bases = [_stacked_uv(b, layout, slice_index, x[1], x[2], 42)
             for slice_index in (s, b.math("ADD", 42, s, 1.0))]
    shift_rgb, shift_a = None, None
    for j, name in enumerate(skin_edits.CONTROLS):
        levels = edit_table.LEVELS[name]
        h = edit_table.SPACING[name]
        t = b.math("MULTIPLY_ADD", 47, _coordinate(b, gin, j, 44), 1.0 / h, -levels[0] / h)
        lower = b.math("MINIMUM", 49, b.math("FLOOR", 48, t), edit_table.STACKED - 2.0)
        fraction = b.math("SUBTRACT", 50, t, lower)
        found = []
        for step in (0.0, 1.0):  # the two levels around the control's value
            uvs = []
            for u, v in bases:
                offset = b.math("MULTIPLY_ADD", 51, lower, 1.0 / edit_table.STACKED, v)
                uv = b.node("ShaderNodeCombineXYZ", 52)
                b.link(u, uv.inputs[0])
                b.link(b.math("ADD", 51, offset, step / edit_table.STACKED) if step else offset, uv.inputs[1])
                uvs.append(uv.outputs[0])
            found.append(live._lookup(b, images[edit_table.image_name(j)], uvs, frac, 53))
        rgb = b.mix("RGBA", 55, fraction, found[0][0], found[1][0])
        alpha = b.mix("FLOAT", 55, fraction, found[0][1], found[1][1])
        if shift_rgb is None:
            shift_rgb, shift_a = rgb, alpha
        else:
            add = b.node("ShaderNodeVectorMath", 56, operation="ADD")
            b.link(shift_rgb, add.inputs[0])
            b.link(rgb, add.inputs[1])
            shift_rgb = add.outputs[0]
            shift_a = b.math("ADD", 56, shift_a, alpha)
    sep = b.node("ShaderNodeSeparateColor", 55)
    b.link(shift_rgb, sep.inputs[0])
    factor = b.node("ShaderNodeCombineColor", 57)
    for c in range(3):
        b.link(b.math("EXPONENT", 56, sep.outputs[c]), factor.inputs[c])
    edited = b.node("ShaderNodeVectorMath", 58, operation="MULTIPLY")
    b.link(colour, edited.inputs[0])
    b.link(factor.outputs[0], edited.inputs[1])
    return EditBranch(colour=edited.outputs[0], radius_factor=b.math("EXPONENT", 56, shift_a))


def _stacked_uv(b, layout, slice_index, x1, x2, stage: int):
    """(u, v) of grid point (slice, x1, x2) in the lowest atlas of a control's image (edit_table.STACKED atlases
    stacked bottom to top): level k lies at v + k / STACKED (the slice atlas of exporters.live_table)."""
    width, height = layout.size
    tile_w, tile_h = layout.tile
    border = live_table.BORDER + 0.5
    row = b.math("FLOOR", stage + 1, b.math("DIVIDE", stage, b.math("ADD", stage, slice_index, 0.5),
                                            float(layout.columns)))
    col = b.math("MULTIPLY_ADD", stage + 2, row, -float(layout.columns), slice_index)
    px = b.math("MULTIPLY_ADD", stage + 3, col, float(tile_w), b.math("ADD", stage + 2, x1, border))
    py = b.math("MULTIPLY_ADD", stage + 3, row, float(tile_h), b.math("ADD", stage + 2, x2, border))
    return (b.math("DIVIDE", stage + 4, px, float(width)),
            b.math("DIVIDE", stage + 4, py, float(edit_table.STACKED * height)))


def _channel(b, colour, c: int):
    sep = b.node("ShaderNodeSeparateColor", 30)
    b.link(colour, sep.inputs[0])
    return sep.outputs[c]


def scale_radius(b, radius, factor) -> bpy.types.NodeSocket:
    """``radius`` (vector) times the scalar ``factor``."""
    node = b.node("ShaderNodeVectorMath", 22, operation="SCALE")
    b.link(radius, node.inputs[0])
    b.link(factor, node.inputs["Scale"])
    return node.outputs[0]


def live_node(material: bpy.types.Material) -> bpy.types.Node | None:
    """The live group node feeding ``material``'s output that has the edit inputs, or None."""
    if material is None or material.node_tree is None:
        return None
    for node in material.node_tree.nodes:
        if (node.bl_idname == "ShaderNodeGroup" and node.node_tree is not None
                and node.node_tree.get("spectral_skin_sss_backend") == "LIVE" and "Melanin" in node.inputs):
            return node
    return None


def apply_preset(node: bpy.types.Node, preset: str) -> None:
    """Set the node's Melanin, Blood and Oxygenation to a preset of exporters.skin_edits.PRESETS (linked inputs are
    left as they are)."""
    edit = skin_edits.PRESETS[preset]
    for (name, *_), value in zip(INPUTS, edit.row(), strict=True):
        if not node.inputs[name].is_linked:
            node.inputs[name].default_value = float(value)


def model_has_edits(model_path: str | os.PathLike) -> bool:
    """Whether an edit table is shipped beside the model."""
    return edit_table.default_path(Path(model_path)).is_file()


#: Presets of the panel: exporters.skin_edits.PRESETS and "as painted".
PRESET_ITEMS = [(name.upper(), name.title(),
                 f"Melanin {p.melanin:g}, Blood {p.blood:g}, Oxygenation {p.oxygenation:+g}")
                for name, p in skin_edits.PRESETS.items()]
PRESET_ITEMS.append(("NEUTRAL", "As painted", "Melanin 1, Blood 1, Oxygenation 0"))


class SPECTRAL_SKIN_OT_skin_edit_preset(bpy.types.Operator):
    """Set the live group's Melanin, Blood and Oxygenation to a preset (inputs fed by a node are left as they are)"""

    bl_idname = "spectral_skin.skin_edit_preset"
    bl_label = "Skin Edit Preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: bpy.props.EnumProperty(name="Preset", items=PRESET_ITEMS, default="NEUTRAL")

    @classmethod
    def poll(cls, context):
        return live_node(getattr(context, "material", None)) is not None

    def execute(self, context):
        node = live_node(context.material)
        if self.preset == "NEUTRAL":
            for name, default, *_ in INPUTS:
                if not node.inputs[name].is_linked:
                    node.inputs[name].default_value = default
        else:
            apply_preset(node, self.preset.lower())
        self.report({"INFO"}, f"'{context.material.name}': skin edit {self.preset.lower()}")
        return {"FINISHED"}


def draw_controls(layout, context) -> None:
    """The selected material's Melanin, Blood and Oxygenation (its live group node's inputs) and the presets."""
    node = live_node(getattr(context, "material", None))
    if node is None:
        return
    box = layout.box()
    box.label(text="Skin edits (live)")
    for name, *_ in INPUTS:
        socket = node.inputs[name]
        if socket.is_linked:
            box.label(text=f"{name}: from node '{socket.links[0].from_node.name}'", icon="LINKED")
        else:
            box.prop(socket, "default_value", text=name)
    row = box.row(align=True)
    for key, label, _ in PRESET_ITEMS:
        row.operator(SPECTRAL_SKIN_OT_skin_edit_preset.bl_idname, text=label).preset = key


classes = (SPECTRAL_SKIN_OT_skin_edit_preset,)
