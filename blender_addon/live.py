"""The live node group **Spectral Skin SSS Live**: the inversion inside the shader, no maps to bake.

It takes a colour from any node (the artist's albedo image, UDIM tiles, vertex colour, attribute, painting,
procedural) and looks the K media up in the fast-path table (exporters.texel_table) packed into nine small
float images (exporters.live_table: "slice atlases", trilinear interpolation in nodes), then feeds them to the
mixture group (blender_addon.nodes, SVM) exactly where baked maps would go.

Interface (docs/contracts.md §5):

* inputs ``Color`` (linear, what fed the Principled BSDF's Base Color), ``Unit Scale`` (metres per Blender unit:
  the radii are in Blender units), ``Roughness``, ``Normal`` and the Principled BSDF's specular inputs
  (blender_addon.nodes.SPECULAR_INPUTS: IOR Level, tint, coat, sheen), passed to the mixture group and to the
  EEVEE closure, and ``Principled Convention`` (0: the body renders the colour, the coat on top; 1: the body
  renders it darkened as a Principled BSDF's base under its specular layer, :data:`PRINCIPLED_BASE_SHARE_CYCLES`);
* outputs ``Cycles`` (the mixture with its specular coat, for a Material Output of target All or Cycles),
  ``EEVEE`` (one Principled BSDF with Subsurface Weight 1 at the colour (body at the painted colour, as in Cycles:
  :data:`PRINCIPLED_BASE_SHARE`) and the mixture's effective radius
  sum_k w_k r_k per channel, for a Material Output of target EEVEE: EEVEE and Material Preview) and
  ``Outside`` (distance of the colour from the table's box in skin space, 0 inside: where the answer is the
  projection onto the nearest skin colour).

The images are shared by every material of the file (one set per table, tagged with the table's SHA-256) and
packed into the .blend (8.0 MB with the shipped table), so the file renders anywhere, render farms included.
The group's math follows exporters.live_table step by step; ``exporters.live_table.lookup`` is its reference.
"""

from __future__ import annotations

import os
from pathlib import Path

import bpy
import numpy as np

from . import nodes
from .core import bake as core_bake
from .core import colorimetry, image_input, live_table, maps, texel_table

GROUP_NAME = "Spectral Skin SSS Live"
#: Custom properties: on the group and the images, the SHA-256 of the table they were made from.
TABLE_PROP = "spectral_skin_sss_table"
#: Layout version of the live group (bump when the generated nodes change).
LIVE_VERSION = 3
IMAGE_PREFIX = "Spectral Skin SSS Table"
#: sRGB encoding (IEC 61966-2-1): linear segment below this value, slope 12.92 there.
_SRGB_KNEE, _SRGB_SLOPE = 0.0031308, 12.92
#: The share of the light the Principled BSDF's specular layer leaves to its base colour in EEVEE, at skin's IOR 1.4
#: and Roughness 0.5, straight above under a white world: a Principled BSDF rendered in EEVEE keeps 0.965-0.968 of
#: three skin colours by luminance (tests/test_live_group.py, which holds this value within 0.015 of it).  The
#: EEVEE output's Base Color is the colour divided by it: the body at the painted colour, as in Cycles, within
#: ΔE76 1 of the painted colour plus the coat's F0 (the same test file).
PRINCIPLED_BASE_SHARE = 0.957
#: The same share in Cycles: 0.972 (0.9717-0.9727 at Roughness 0.3-0.5, IOR 1.4; a Principled BSDF rendered in
#: Cycles by tests/test_live_specular.py).  With ``Principled Convention`` 1 the colour is multiplied by it before
#: the table, so the Cycles body is as much darker than the painted colour as a Principled BSDF's base.
PRINCIPLED_BASE_SHARE_CYCLES = 0.972
#: Texels read (at most) to count the share of a texture outside the table's domain.
OUTSIDE_SAMPLE = 1 << 18


class LiveInputError(ValueError):
    """A material the live group cannot be wired into; the message says what to do."""


def table_for_model(model_path: str) -> texel_table.TexelTable:
    """The shipped table beside ``model_path`` (exporters.bake.table_cache.default_table_path), checked to be
    made from that model and for the painted colour."""
    path = core_bake.default_table_path(model_path)
    if not os.path.isfile(model_path):
        raise LiveInputError(f"model not found at {model_path}: train/export it or set the path in preferences")
    table = _load_table(path)
    if table.model_sha256 != maps.sha256_file(model_path):
        raise LiveInputError(f"the table {path.name} was made from another model than {Path(model_path).name}: "
                             f"rebuild it (python -m training texel-table --model {model_path} --out {path} "
                             "--overwrite) or choose Bake")
    if not table.options.painted:
        raise LiveInputError(f"the table {path.name} holds the model's own colour: the live group needs the painted "
                             "colour's table (rebuild it without --model-colour)")
    return table


def _load_table(path: Path) -> texel_table.TexelTable:
    """The table at ``path``, loaded once per file version (its size and modification time) for this session."""
    stat = path.stat() if path.is_file() else None
    key = (str(path), stat.st_size, stat.st_mtime_ns) if stat else None
    if key is None or key not in _TABLES:
        table = texel_table.load(path)  # TableError when missing or not a table
        _TABLES.clear()
        _TABLES[key] = table
    return _TABLES[key]


_TABLES: dict[tuple, texel_table.TexelTable] = {}


# -- images ----------------------------------------------------------------------------------------------------
def image_name(name: str) -> str:
    return f"{IMAGE_PREFIX} {name}"


def ensure_images(table: texel_table.TexelTable) -> tuple[live_table.AtlasLayout, dict[str, bpy.types.Image]]:
    """The table's atlas images, packed, one set per file: reused when images of this table exist, else made."""
    layout = live_table.layout_of(table)
    width, height = layout.size
    names = [f"k{k} {kind}" for k in range(1, table.k + 1) for kind in live_table.IMAGE_KINDS]
    found = {}
    for name in names:
        image = bpy.data.images.get(image_name(name))
        if image is not None and image.get(TABLE_PROP) == table.sha256 and tuple(image.size) == (width, height):
            found[name] = image
    if len(found) == len(names):
        return layout, found
    _, atlases = live_table.atlases(table)
    images = {}
    for name in names:
        old = bpy.data.images.get(image_name(name))
        if old is not None and old.users == 0:
            bpy.data.images.remove(old)
        image = bpy.data.images.new(image_name(name), width, height, alpha=True, float_buffer=True)
        image.colorspace_settings.name = "Non-Color"
        image.alpha_mode = "CHANNEL_PACKED"  # A holds the anisotropy, not coverage
        image.pixels.foreach_set(atlases[name].ravel())
        image.pack()
        image[TABLE_PROP] = table.sha256
        images[name] = image
    return layout, images


# -- the group -------------------------------------------------------------------------------------------------
class _Builder:
    """Places nodes in a group left to right (x by stage, y by a running counter)."""

    def __init__(self, group: bpy.types.NodeTree) -> None:
        self.group = group
        self.rows: dict[int, int] = {}

    def node(self, kind: str, stage: int, **props) -> bpy.types.Node:
        node = self.group.nodes.new(kind)
        row = self.rows.get(stage, 0)
        self.rows[stage] = row + 1
        node.location = (-1600.0 + 220.0 * stage, 600.0 - 160.0 * row)
        for key, value in props.items():
            setattr(node, key, value)
        return node

    def link(self, value, socket: bpy.types.NodeSocket) -> None:
        if isinstance(value, bpy.types.NodeSocket):
            self.group.links.new(value, socket)
        else:
            socket.default_value = value

    def math(self, op: str, stage: int, a, b=None, c=None, clamp: bool = False) -> bpy.types.NodeSocket:
        node = self.node("ShaderNodeMath", stage, operation=op, use_clamp=clamp)
        for i, value in enumerate((a, b, c)):
            if value is not None:
                self.link(value if isinstance(value, bpy.types.NodeSocket) else float(value), node.inputs[i])
        return node.outputs[0]

    def mix(self, data_type: str, stage: int, fac, a, b) -> bpy.types.NodeSocket:
        node = self.node("ShaderNodeMix", stage, data_type=data_type, clamp_factor=False)
        sockets = [s for s in node.inputs if s.enabled]
        self.link(fac, sockets[0])
        self.link(a, sockets[1])
        self.link(b, sockets[2])
        return next(s for s in node.outputs if s.enabled)


def _srgb_encode(b: _Builder, linear: bpy.types.NodeSocket, stage: int) -> bpy.types.NodeSocket:
    """e = sRGB encoding of clamp(linear, 0, 1), piecewise as exporters.colorimetry.srgb_encode."""
    c = b.math("ADD", stage, linear, 0.0, clamp=True)
    lin = b.math("MULTIPLY", stage + 1, c, _SRGB_SLOPE)
    curve = b.math("MULTIPLY_ADD", stage + 2, b.math("POWER", stage + 1, c, 1.0 / 2.4), 1.055, -0.055)
    low = b.math("LESS_THAN", stage + 1, c, _SRGB_KNEE)
    return b.math("MULTIPLY_ADD", stage + 3, low, b.math("SUBTRACT", stage + 2, lin, curve), curve)


def _grid_coords(b: _Builder, gin: bpy.types.Node, layout: live_table.AtlasLayout):
    """Clamped grid coordinates x0, x1, x2 of the input colour and its distance from the box (skin space)."""
    sep = b.node("ShaderNodeSeparateColor", 0)
    b.link(_convention(b, gin, 1.0, PRINCIPLED_BASE_SHARE_CYCLES), sep.inputs[0])
    e = [_srgb_encode(b, sep.outputs[i], 1) for i in range(3)]
    coords = [b.math("MULTIPLY", 6, b.math("ADD", 5, b.math("ADD", 5, e[0], e[1]), e[2]), 1.0 / 3.0),
              b.math("SUBTRACT", 6, e[0], e[1]), b.math("SUBTRACT", 6, e[1], e[2])]
    clamped, outside = [], None
    for d, coord in enumerate(coords):
        raw = b.math("MULTIPLY_ADD", 7, coord, 1.0 / layout.step, -layout.origin[d] / layout.step)
        x = b.math("MINIMUM", 9, b.math("MAXIMUM", 8, raw, 0.0), layout.shape[d] - 1.0)
        gap = b.math("ABSOLUTE", 11, b.math("SUBTRACT", 10, raw, x))
        outside = gap if outside is None else b.math("ADD", 12, outside, gap)
        clamped.append(x)
    return clamped, b.math("MULTIPLY", 13, outside, layout.step)


def _slice_uv(b: _Builder, layout: live_table.AtlasLayout, s, x1, x2, stage: int) -> bpy.types.NodeSocket:
    """UV (vector) of grid point (slice s, x1, x2) in the atlas (exporters.live_table layout)."""
    width, height = layout.size
    tile_w, tile_h = layout.tile
    row = b.math("FLOOR", stage + 1, b.math("DIVIDE", stage, b.math("ADD", stage, s, 0.5), float(layout.columns)))
    col = b.math("MULTIPLY_ADD", stage + 2, row, -float(layout.columns), s)
    px = b.math("MULTIPLY_ADD", stage + 3, col, float(tile_w), b.math("ADD", stage + 2, x1,
                                                                      live_table.BORDER + 0.5))
    py = b.math("MULTIPLY_ADD", stage + 3, row, float(tile_h), b.math("ADD", stage + 2, x2,
                                                                      live_table.BORDER + 0.5))
    comb = b.node("ShaderNodeCombineXYZ", stage + 5)
    b.link(b.math("DIVIDE", stage + 4, px, float(width)), comb.inputs[0])
    b.link(b.math("DIVIDE", stage + 4, py, float(height)), comb.inputs[1])
    return comb.outputs[0]


def _lookup(b: _Builder, image: bpy.types.Image, uvs, frac, stage: int):
    """Trilinear value of one atlas: two bilinear lookups (slices s, s + 1) mixed by ``frac``; (RGB, alpha)."""
    colours, alphas = [], []
    for uv in uvs:
        tex = b.node("ShaderNodeTexImage", stage, image=image, interpolation="Linear", extension="EXTEND")
        tex.label = image.name
        b.link(uv, tex.inputs["Vector"])
        colours.append(tex.outputs["Color"])
        alphas.append(tex.outputs["Alpha"])
    return (b.mix("RGBA", stage + 1, frac, colours[0], colours[1]),
            b.mix("FLOAT", stage + 1, frac, alphas[0], alphas[1]))


def _radius(b: _Builder, log_radius, metres_per_unit, stage: int) -> bpy.types.NodeSocket:
    """Radius in Blender units: exp(log r / m - ln(metres per unit)) per channel."""
    sep = b.node("ShaderNodeSeparateColor", stage)
    b.link(log_radius, sep.inputs[0])
    log_unit = b.math("LOGARITHM", stage, metres_per_unit, float(np.e))
    comb = b.node("ShaderNodeCombineColor", stage + 3)
    for c in range(3):
        b.link(b.math("EXPONENT", stage + 2, b.math("SUBTRACT", stage + 1, sep.outputs[c], log_unit)),
               comb.inputs[c])
    return comb.outputs[0]


def _new_group(k_count: int, table_sha: str) -> tuple[bpy.types.NodeTree, bpy.types.Node, bpy.types.Node]:
    group = bpy.data.node_groups.new(GROUP_NAME, "ShaderNodeTree")
    group["spectral_skin_sss_k"] = k_count
    group["spectral_skin_sss_backend"] = "LIVE"
    group["spectral_skin_sss_version"] = LIVE_VERSION
    group[TABLE_PROP] = table_sha
    iface = group.interface
    iface.new_socket("Color", in_out="INPUT", socket_type="NodeSocketColor").default_value = (0.6, 0.4, 0.3, 1.0)
    unit = iface.new_socket("Unit Scale", in_out="INPUT", socket_type="NodeSocketFloat")
    unit.default_value, unit.min_value = 1.0, 1e-6
    rough = iface.new_socket("Roughness", in_out="INPUT", socket_type="NodeSocketFloat")
    rough.default_value, rough.min_value, rough.max_value = nodes.SKIN_ROUGHNESS, 0.0, 1.0
    iface.new_socket("Normal", in_out="INPUT", socket_type="NodeSocketVector").hide_value = True
    nodes.add_specular_inputs(group)
    convention = iface.new_socket("Principled Convention", in_out="INPUT", socket_type="NodeSocketFloat")
    convention.default_value, convention.min_value, convention.max_value = 0.0, 0.0, 1.0
    iface.new_socket("Cycles", in_out="OUTPUT", socket_type="NodeSocketShader")
    iface.new_socket("EEVEE", in_out="OUTPUT", socket_type="NodeSocketShader")
    iface.new_socket("Outside", in_out="OUTPUT", socket_type="NodeSocketFloat")
    gin = group.nodes.new("NodeGroupInput")
    gout = group.nodes.new("NodeGroupOutput")
    gin.location, gout.location = (-1900.0, 0.0), (4400.0, 0.0)
    return group, gin, gout


def build_live_group(table: texel_table.TexelTable, layout: live_table.AtlasLayout,
                     images: dict[str, bpy.types.Image]) -> bpy.types.NodeTree:
    """A new live group reading ``images`` (from :func:`ensure_images`) of ``table``; see the module docstring."""
    group, gin, gout = _new_group(table.k, table.sha256)
    b = _Builder(group)
    (x0, x1, x2), outside = _grid_coords(b, gin, layout)
    s = b.math("MINIMUM", 11, b.math("FLOOR", 10, x0), layout.shape[0] - 2.0)
    frac = b.math("SUBTRACT", 12, x0, s)
    uvs = (_slice_uv(b, layout, s, x1, x2, 12), _slice_uv(b, layout, b.math("ADD", 12, s, 1.0), x1, x2, 12))
    mixture = b.node("ShaderNodeGroup", 26, node_tree=nodes.ensure_group(table.k, "SVM"))
    effective = None
    for k in range(1, table.k + 1):
        colour, g = _lookup(b, images[f"k{k} Color"], uvs, frac, 18)
        log_r, _ = _lookup(b, images[f"k{k} Log Radius"], uvs, frac, 18)
        weight, _ = _lookup(b, images[f"k{k} Weight"], uvs, frac, 18)
        radius = _radius(b, log_r, gin.outputs["Unit Scale"], 20)
        for kind, value in (("Color", colour), ("Radius", radius), ("Weight", weight), ("Anisotropy", g)):
            b.link(value, mixture.inputs[nodes.socket_name(k, kind)])
        term = b.node("ShaderNodeVectorMath", 24, operation="MULTIPLY")
        b.link(weight, term.inputs[0])
        b.link(radius, term.inputs[1])
        if effective is None:
            effective = term.outputs[0]
        else:
            add = b.node("ShaderNodeVectorMath", 25, operation="ADD")
            b.link(effective, add.inputs[0])
            b.link(term.outputs[0], add.inputs[1])
            effective = add.outputs[0]
    mixture.inputs["IOR"].default_value = table.options.ior
    for name in ("Roughness", "Normal", *nodes.SPECULAR_INPUTS):
        b.link(gin.outputs[name], mixture.inputs[name])
    b.link(mixture.outputs["BSSRDF"], gout.inputs["Cycles"])
    b.link(_eevee_surface(b, gin, effective, table.options.ior), gout.inputs["EEVEE"])
    b.link(outside, gout.inputs["Outside"])
    return group


def _convention(b: _Builder, gin: bpy.types.Node, painted: float, principled: float) -> bpy.types.NodeSocket:
    """The input colour times ``painted`` (Principled Convention 0) or ``principled`` (1), mixed in between."""
    gain = b.math("MULTIPLY_ADD", 0, gin.outputs["Principled Convention"], principled - painted, painted)
    scale = b.node("ShaderNodeVectorMath", 0, operation="SCALE")
    b.link(gin.outputs["Color"], scale.inputs[0])
    b.link(gain, scale.inputs["Scale"])
    return scale.outputs[0]


def _eevee_surface(b: _Builder, gin: bpy.types.Node, radius, ior: float) -> bpy.types.NodeSocket:
    """One Principled BSDF: the colour (over PRINCIPLED_BASE_SHARE in the painted convention) as Base Color,
    Subsurface Weight 1 at the effective radius."""
    bsdf = b.node("ShaderNodeBsdfPrincipled", 27)
    b.link(_convention(b, gin, 1.0 / PRINCIPLED_BASE_SHARE, 1.0), bsdf.inputs["Base Color"])
    bsdf.inputs["Subsurface Weight"].default_value = 1.0
    bsdf.inputs["Subsurface Scale"].default_value = 1.0
    bsdf.inputs["IOR"].default_value = ior
    b.link(radius, bsdf.inputs["Subsurface Radius"])
    for name in ("Roughness", "Normal", *nodes.SPECULAR_INPUTS):
        b.link(gin.outputs[name], bsdf.inputs[name])
    return bsdf.outputs[0]


def ensure_live_group(table: texel_table.TexelTable) -> bpy.types.NodeTree:
    """The live group of ``table``: an existing one of this table and version is reused (every material shares
    it and its images), else one is built."""
    for group in bpy.data.node_groups:
        if (group.name.startswith(GROUP_NAME) and group.get(TABLE_PROP) == table.sha256
                and group.get("spectral_skin_sss_version") == LIVE_VERSION):
            return group
    layout, images = ensure_images(table)
    return build_live_group(table, layout, images)


# -- wiring ----------------------------------------------------------------------------------------------------
def colour_source(material: bpy.types.Material) -> tuple[bpy.types.Node, bpy.types.NodeSocket | None, tuple]:
    """The surface node feeding the active Material Output (a Principled BSDF, or a live group wired before),
    the output socket feeding its colour (None when unlinked) and its colour value."""
    tree = material.node_tree
    out = nodes._material_output(tree)
    links = [ln for ln in out.inputs["Surface"].links if not ln.is_muted]
    surface = links[0].from_node if links else None
    name = "Base Color" if surface is not None and surface.bl_idname == "ShaderNodeBsdfPrincipled" else "Color"
    is_live = (surface is not None and surface.bl_idname == "ShaderNodeGroup" and surface.node_tree is not None
               and surface.node_tree.get("spectral_skin_sss_backend") == "LIVE")
    if surface is None or not (is_live or name == "Base Color"):
        raise LiveInputError(f"material '{material.name}': no Principled BSDF feeds its Material Output's Surface; "
                             "connect one (its Base Color is the skin's albedo) or choose Bake")
    socket = surface.inputs[name]
    return surface, nodes._feeding_socket(socket), tuple(socket.default_value)


def wire_live(material: bpy.types.Material, group: bpy.types.NodeTree, unit_scale_m: float) -> bpy.types.Node:
    """Insert the live group into ``material``: fed by what fed the Principled BSDF's Base Color (or its value),
    its Normal and Roughness (nodes.wire_into_material), its Cycles output into the active Material Output and its
    EEVEE output into a Material Output of target EEVEE (added, or the one wired before).  Every node of the
    artist's is kept; the name of the surface node it replaces goes to ``material[PREVIOUS_SURFACE_PROP]``."""
    surface, colour, value = colour_source(material)
    tree = material.node_tree
    gnode = nodes.wire_into_material(material, group, output="Cycles")
    gnode.inputs["Unit Scale"].default_value = unit_scale_m
    if colour is not None:
        tree.links.new(colour, gnode.inputs["Color"])
    else:
        gnode.inputs["Color"].default_value = value
    eevee = _eevee_output(tree, gnode)
    tree.links.new(gnode.outputs["EEVEE"], eevee.inputs["Surface"])
    if surface.bl_idname == "ShaderNodeGroup":  # a re-wire: the old live node is left in place, unlinked
        material[nodes.PREVIOUS_SURFACE_PROP] = surface.name
    return gnode


def _eevee_output(tree: bpy.types.NodeTree, gnode: bpy.types.Node) -> bpy.types.Node:
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeOutputMaterial" and node.target == "EEVEE":
            return node
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    out.target = "EEVEE"
    out.label = "EEVEE (Spectral Skin SSS Live)"
    out.location = (gnode.location.x + 300.0, gnode.location.y - 250.0)
    out.parent = gnode.parent
    return out


# -- outside the domain ----------------------------------------------------------------------------------------
def image_colours(image: bpy.types.Image, colorspace: str, limit: int = OUTSIDE_SAMPLE) -> np.ndarray:
    """Linear colours (N, 3) of about ``limit`` texels of ``image`` (every tile of a UDIM image; an even grid when
    larger), decoded as ``colorspace`` ("srgb", "linear" or "auto": sRGB for 8/16-bit, linear for float).  Files
    are read directly (a few rows, never the whole float buffer) where OpenImageIO's Python module is there;
    packed and generated images, and every image in a Blender without that module (4.2), from Blender's own
    pixel buffer (a tiled image's first tile only)."""
    try:
        image_input.openimageio()
    except image_input.ImageError:
        return _decoded([(_pixels(image, limit), image.is_float)], colorspace)
    if image.source == "TILED":
        paths = [_file_of(image, tile.number) for tile in image.tiles]
        parts = [image_input.sample_texels(p, limit // len(paths)) for p in paths if os.path.isfile(p)]
    elif image.source == "FILE" and image.packed_file is None and os.path.isfile(_file_of(image)):
        parts = [image_input.sample_texels(_file_of(image), limit)]
    else:
        parts = [(_pixels(image, limit), image.is_float)]
    return _decoded(parts, colorspace)


def _decoded(parts: list[tuple[np.ndarray, bool]], colorspace: str) -> np.ndarray:
    """Linear colours (N, 3) of sampled texels ((values as stored, whether the image stores floats) per part)."""
    decode = [colorspace == "srgb" or (colorspace == "auto" and not is_float) for _, is_float in parts]
    decoded = [colorimetry.srgb_decode(np.clip(rgb, 0.0, None)) if srgb else rgb
               for (rgb, _), srgb in zip(parts, decode, strict=True)]
    return np.concatenate(decoded) if decoded else np.zeros((0, 3))


def _file_of(image: bpy.types.Image, tile: int | None = None) -> str:
    path = bpy.path.abspath(image.filepath, library=image.library)
    return path.replace("<UDIM>", str(tile)) if tile is not None else path


def _pixels(image: bpy.types.Image, limit: int) -> np.ndarray:
    """Up to ``limit`` texels (an even stride) of a Blender image's pixel buffer, as stored."""
    width, height = image.size
    channels = image.channels
    if width * height == 0:
        return np.zeros((0, 3))
    px = np.empty(width * height * channels, np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(-1, channels)[::max(1, -(-width * height // limit))]
    rgb = px[:, :3] if channels >= 3 else np.repeat(px[:, :1], 3, axis=1)
    return np.nan_to_num(rgb.astype(np.float64), nan=0.0, posinf=1.0, neginf=0.0)


# -- the operator's live path ----------------------------------------------------------------------------------
def apply(context: bpy.types.Context, model_path: str, unit_scale_m: float, colorspace: str = "FROM_IMAGE",
          principled_convention: bool = False) -> str:
    """Wire the live group into the active object's active material (Invert Skin Albedo's default); returns the
    one-line report.  Bad input raises LiveInputError before anything changes; a failure while wiring removes
    what was made (call from an operator with UNDO for Ctrl+Z)."""
    obj = context.object
    material = obj.active_material if obj is not None else None
    if material is None or material.node_tree is None:
        raise LiveInputError("no active material with nodes: select the skin object (its material's Principled "
                             "BSDF gives the albedo)")
    table = table_for_model(model_path)
    surface, colour, _ = colour_source(material)
    if surface.bl_idname == "ShaderNodeGroup" and surface.node_tree.get(TABLE_PROP) == table.sha256 \
            and surface.node_tree.get("spectral_skin_sss_version") == LIVE_VERSION:
        surface.inputs["Unit Scale"].default_value = unit_scale_m
        surface.inputs["Principled Convention"].default_value = float(principled_convention)
        material.node_tree.links.new(surface.outputs["EEVEE"],
                                     _eevee_output(material.node_tree, surface).inputs["Surface"])
        return (f"up to date: '{material.name}' already renders through the live group (Unit Scale {unit_scale_m:g} m "
                "per Blender unit)")
    before = _state(material)
    try:
        group = ensure_live_group(table)
        gnode = wire_live(material, group, unit_scale_m)
        gnode.inputs["Principled Convention"].default_value = float(principled_convention)
    except BaseException:
        _restore(material, before)
        raise
    report = f"live group wired into '{material.name}' (K={table.k}; no maps baked)"
    image_node = colour.node if colour is not None and colour.node.bl_idname == "ShaderNodeTexImage" else None
    if image_node is not None and image_node.image is not None:
        report += "; " + outside_report(table, image_node.image, colorspace)
    gnode.select = True
    return report


def outside_report(table: texel_table.TexelTable, image: bpy.types.Image, colorspace: str) -> str:
    """How much of ``image`` lies outside the table's domain (a warning when any does)."""
    from .baker import _image_colorspace  # the bake's reading of Blender's colour-space setting

    rgb = image_colours(image, _image_colorspace(image, colorspace))
    if len(rgb) == 0:
        return f"image '{image.name}' has no pixels to check"
    share = live_table.outside_fraction(table, rgb)
    if share == 0.0:
        return f"every texel of '{image.name}' lies inside the table's domain"
    return (f"warning: {100 * share:.2f} % of the texels of '{image.name}' lie outside the table's domain (not skin "
            "colours: they render as the nearest skin colour; docs/user/live_group.md)")


def _state(material: bpy.types.Material) -> dict:
    tree = material.node_tree
    return {"groups": set(bpy.data.node_groups.keys()), "images": set(bpy.data.images.keys()),
            "nodes": {n.name for n in tree.nodes},
            "links": [(ln.from_node.name, ln.from_socket.identifier, ln.to_node.name, ln.to_socket.identifier)
                      for ln in tree.links],
            "previous": material.get(nodes.PREVIOUS_SURFACE_PROP)}


def _restore(material: bpy.types.Material, state: dict) -> None:
    """Undo a failed wiring: new nodes, groups and images removed, the links as they were."""
    tree = material.node_tree
    for node in [n for n in tree.nodes if n.name not in state["nodes"]]:
        tree.nodes.remove(node)
    for link in list(tree.links):
        tree.links.remove(link)
    for from_node, from_id, to_node, to_id in state["links"]:
        src = next(s for s in tree.nodes[from_node].outputs if s.identifier == from_id)
        dst = next(s for s in tree.nodes[to_node].inputs if s.identifier == to_id)
        tree.links.new(src, dst)
    for name in set(bpy.data.node_groups.keys()) - state["groups"]:
        bpy.data.node_groups.remove(bpy.data.node_groups[name])
    for name in set(bpy.data.images.keys()) - state["images"]:
        bpy.data.images.remove(bpy.data.images[name])
    if state["previous"] is None:
        material.pop(nodes.PREVIOUS_SURFACE_PROP, None)
    else:
        material[nodes.PREVIOUS_SURFACE_PROP] = state["previous"]
