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
  renders it darkened as a Principled BSDF's base under its specular layer, :data:`PRINCIPLED_BASE_SHARE_CYCLES`),
  ``Translucency`` (scales every mean free path: 1 is the physical skin) and the Principled BSDF's
  ``Subsurface Weight`` (0: a diffuse body of the painted colour under the coat; 1: the skin; a mask blends),
  ``Alpha`` and ``Emission Color`` / ``Strength`` (blender_addon.nodes.ARTIST_INPUTS);
* outputs ``Cycles`` (the mixture with its specular coat, for a Material Output of target Cycles: wiring.py; the
  components' weights and radii times the grazing-light factors of blender_addon.oblique),
  ``EEVEE`` (one Principled BSDF with the group's Subsurface Weight, Alpha and Emission at the colour (body at
  the painted colour, as in Cycles: :data:`PRINCIPLED_BASE_SHARE`) and the mixture's effective radius
  sum_k w_k r_k per channel, for a Material Output of target EEVEE: EEVEE and Material Preview) and
  ``Outside`` (distance of the colour from the table's box of skin colours in skin space, 0 inside: how far
  the colour is from skin; it renders as painted all the same, with the translucency of the skin colour it was
  projected onto).

Every colour renders as painted: the media looked up for the nearest skin colour are brought to the painted
colour per channel in the reflectance domain (exporters.painted_gain, step 5 of exporters.live_table), the
radii kept, so a gradient leaving the skin colours changes its translucency continuously.

The images are shared by every material of the file (one set per table, tagged with the table's SHA-256) and
packed into the .blend (7.8 MB with the shipped table), so the file renders anywhere, render farms included.
The group's math follows exporters.live_table step by step; ``exporters.live_table.lookup`` and
``exporters.live_table.group_media`` are its reference.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

import bpy
import numpy as np

from . import curves, live_edits, nodes, oblique, wiring
from .core import bake as core_bake
from .core import colorimetry, image_input, live_table, maps, painted_gain, skin_edits, texel_table

GROUP_NAME = "Spectral Skin SSS Live"
#: Custom properties: on the group and the images, the SHA-256 of the table they were made from.
TABLE_PROP = "spectral_skin_sss_table"
#: Layout version of the live group (bump when the generated nodes change).
LIVE_VERSION = 29
IMAGE_PREFIX = "Spectral Skin SSS Table"
#: Custom property on the group: whether it holds the grazing-light correction (blender_addon.oblique).
GRAZING_PROP = "spectral_skin_sss_grazing"
#: sRGB encoding (IEC 61966-2-1): linear segment below this value, slope 12.92 there.
_SRGB_KNEE, _SRGB_SLOPE = 0.0031308, 12.92
#: sRGB's power segment 1.055 c^(1/2.4) - 0.055: its scale and offset (IEC 61966-2-1).
_SRGB_SCALE, _SRGB_OFFSET = 1.055, 0.055
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
    if table.model_sha256 != file_sha256(model_path):
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


def file_key(path: str | os.PathLike) -> tuple | None:
    """(path, size, modification time in ns) of a file, None when there is none: a version of the file."""
    try:
        stat = os.stat(path)
    except OSError:
        return None
    return str(path), stat.st_size, stat.st_mtime_ns


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 of a file (exporters.maps.sha256_file), computed once per file version for this session."""
    key = file_key(path)
    if key is None or key not in _HASHES:
        digest = maps.sha256_file(path)  # OSError when missing
        if key is None:
            return digest
        _HASHES[key] = digest
    return _HASHES[key]


_HASHES: dict[tuple, str] = {}


# -- images ----------------------------------------------------------------------------------------------------
def image_name(name: str) -> str:
    return f"{IMAGE_PREFIX} {name}"


def _image_names(table: texel_table.TexelTable) -> list[str]:
    return [f"k{k} {kind}" for k in range(1, table.k + 1) for kind in live_table.IMAGE_KINDS]


def _found_images(table: texel_table.TexelTable) -> dict[str, bpy.types.Image]:
    """The images of ``table`` this file holds already (by name, or the name with Blender's ".001" suffix where an
    older live group still holds an image of another layout under the name; made from this table, of its size)."""
    width, height = live_table.layout_of(table).size
    found = {}
    for name in _image_names(table):
        base = image_name(name)
        for image in bpy.data.images:
            if (image.name == base or image.name.startswith(base + ".")) and image.get(TABLE_PROP) == table.sha256 \
                    and tuple(image.size) == (width, height):
                found[name] = image
                break
    return found


def ensure_images(table: texel_table.TexelTable, atlases: Callable[[], dict[str, np.ndarray]] | None = None
                  ) -> tuple[live_table.AtlasLayout, dict[str, bpy.types.Image]]:
    """The table's atlas images, packed, one set per file: reused when images of this table exist, else made
    (``atlases``: gives the table's atlases, made elsewhere meanwhile; default: made here)."""
    layout = live_table.layout_of(table)
    names = _image_names(table)
    found = _found_images(table)
    if len(found) == len(names):
        return layout, found
    atlases = atlases() if atlases is not None else live_table.atlases(table)[1]
    images = {}
    for name in names:  # A holds the anisotropy, not coverage
        images[name] = wiring.packed_table_image(image_name(name), atlases[name], TABLE_PROP, table.sha256)
    return layout, images


# -- the group -------------------------------------------------------------------------------------------------
class _Builder:
    """Places nodes in a group left to right (x by stage, y by a running counter).

    Blender updates the whole tree after each property it sets from Python, so a set costs time growing with the
    tree: the builder sets no value a node already holds, and the locations all at once (:meth:`place`, which the
    caller calls when done: ``foreach_set`` updates nothing)."""

    def __init__(self, group: bpy.types.NodeTree) -> None:
        self.group = group
        self.rows: dict[int, int] = {}
        self.locations: list[tuple[int, float, float]] = []
        #: A zero vector computed at each shading point (blender_addon.nodes.computed_zero), once the group has one.
        self.zero: bpy.types.NodeSocket | None = None
        #: The parts of the Environment Textures' directions made so far (:meth:`direction`), by what they depend on.
        self._direction_parts: dict[tuple, object] = {}

    def node(self, kind: str, stage: int, **props) -> bpy.types.Node:
        self._locate(len(self.group.nodes), stage)
        node = self.group.nodes.new(kind)
        for key, value in props.items():
            if getattr(node, key) != value:
                setattr(node, key, value)
        return node

    def curve(self, stage: int, socket: bpy.types.NodeSocket, xs: np.ndarray, ys: np.ndarray) -> bpy.types.NodeSocket:
        """An RGB Curves node of ``socket`` through (xs, ys) (blender_addon.curves.channel_curves); its output."""
        self._locate(len(self.group.nodes), stage)
        return curves.channel_curves(self.group, socket, xs, ys)

    def _locate(self, index: int, stage: int) -> None:
        row = self.rows.get(stage, 0)
        self.rows[stage] = row + 1
        self.locations.append((index, -1600.0 + 220.0 * stage, 600.0 - 160.0 * row))

    def place(self) -> None:
        """Move the nodes made to their locations (one call for the whole tree)."""
        tree_nodes = self.group.nodes
        xy = np.empty(2 * len(tree_nodes), np.float32)
        tree_nodes.foreach_get("location", xy)
        for index, x, y in self.locations:
            xy[2 * index:2 * index + 2] = x, y
        tree_nodes.foreach_set("location", xy)

    def link(self, value, socket: bpy.types.NodeSocket) -> None:
        if isinstance(value, bpy.types.NodeSocket):
            self.group.links.new(value, socket)
        else:
            set_default(socket, value)

    def math(self, op: str, stage: int, a, b=None, c=None, clamp: bool = False) -> bpy.types.NodeSocket:
        node = self.node("ShaderNodeMath", stage, operation=op, use_clamp=clamp)
        for i, value in enumerate((a, b, c)):
            if value is not None:
                self.link(value if isinstance(value, bpy.types.NodeSocket) else float(value), node.inputs[i])
        return node.outputs[0]

    def vec(self, op: str, stage: int, a, b=None, c=None) -> bpy.types.NodeSocket:
        """A Vector Math node ``op`` of a, b, c (sockets, numbers (the same in every component) or 3-tuples); its
        output (the Value of a dot product, else the Vector)."""
        node = self.node("ShaderNodeVectorMath", stage, operation=op)
        for i, value in enumerate((a, b, c)):
            if isinstance(value, bpy.types.NodeSocket):
                self.group.links.new(value, node.inputs[i])
            elif value is not None:
                set_default(node.inputs[i], tuple(float(v) for v in np.broadcast_to(value, 3)))
        return node.outputs["Value"] if op == "DOT_PRODUCT" else node.outputs["Vector"]

    def product(self, stage: int, factor, value: bpy.types.NodeSocket) -> bpy.types.NodeSocket:
        """``factor`` x ``value`` per channel as a Mix node from the group's computed zero (blender_addon.nodes.product:
        half the instructions of a Vector Math Multiply); for products of values computed at each shading point (a
        Vector Math Multiply by a constant 1 is folded away by Cycles, a Mix is not)."""
        self._locate(len(self.group.nodes), stage)
        return nodes.product(self.group, factor, value, self.zero)

    def direction(self, uv: bpy.types.NodeSocket, stage: int, offset: tuple[float, float] = (0.0, 0.0),
                  scale: tuple[float, float] = (1.0, 1.0)) -> bpy.types.NodeSocket:
        """The direction an equirectangular Environment Texture maps to the image point (u', v') = ``uv`` x
        ``scale`` + ``offset``: longitude phi = pi - 2 pi u', latitude lam = pi (v' - 1/2), the vector
        (1, 0, tan lam) turned by phi about Z (the texture normalises it).  Each part is made once per group: the
        lookups of one point at other offsets share its components, longitudes and latitudes."""
        (du, dv), (su, sv) = offset, scale
        key = uv.as_pointer()
        parts = self._made(("parts", key), lambda: self._separate(uv, stage))
        phi = self._made(("phi", key, su, du), lambda: self.math(
            "MULTIPLY_ADD", stage, parts.outputs[0], -2.0 * np.pi * su, np.pi * (1.0 - 2.0 * du)))

        def base() -> bpy.types.Node:
            node = self.node("ShaderNodeCombineXYZ", stage + 1)
            set_default(node.inputs[0], 1.0)
            lam = self.math("MULTIPLY_ADD", stage, parts.outputs[1], np.pi * sv, np.pi * (dv - 0.5))
            self.group.links.new(self.math("TANGENT", stage + 1, lam), node.inputs[2])
            return node

        meridian = self._made(("base", key, sv, dv), base)

        def turn() -> bpy.types.NodeSocket:
            node = self.node("ShaderNodeVectorRotate", stage + 1, rotation_type="Z_AXIS")
            self.group.links.new(meridian.outputs[0], node.inputs["Vector"])
            self.group.links.new(phi, node.inputs["Angle"])
            return node.outputs[0]

        return self._made(("turn", key, tuple(offset), tuple(scale)), turn)

    def _separate(self, vector: bpy.types.NodeSocket, stage: int) -> bpy.types.Node:
        node = self.node("ShaderNodeSeparateXYZ", stage)
        self.group.links.new(vector, node.inputs[0])
        return node

    def _made(self, key: tuple, make: Callable):
        """What ``make()`` made for ``key`` in this group (made on the first call)."""
        if key not in self._direction_parts:
            self._direction_parts[key] = make()
        return self._direction_parts[key]

    def environment(self, image: bpy.types.Image, uv: bpy.types.NodeSocket, stage: int,
                    offset: tuple[float, float] = (0.0, 0.0),
                    scale: tuple[float, float] = (1.0, 1.0)) -> bpy.types.NodeSocket:
        """``image`` (RGB) interpolated bilinearly at ``uv`` x ``scale`` + ``offset`` through an Environment Texture,
        for the EEVEE output.  EEVEE reads an Image Texture's Linear lookups from the mipmap level that the screen-space
        derivatives of its coordinates select; a table's coordinates, computed from a textured colour, jump between
        neighbouring pixels (from one slice to the next), so its lookups there read blurred levels: on the demo's skin
        texture the effective radius came out 36 % off in the median.  An equirectangular Environment Texture with
        Linear interpolation reads the full-resolution level in EEVEE (Cycles, which reads no mipmaps, never runs these
        nodes: they feed the EEVEE output only)."""
        tex = self.node("ShaderNodeTexEnvironment", stage + 2, image=image, interpolation="Linear",
                        projection="EQUIRECTANGULAR")
        tex.label = image.name
        self.group.links.new(self.direction(uv, stage, offset, scale), tex.inputs["Vector"])
        return tex.outputs["Color"]

    def mix(self, data_type: str, stage: int, fac, a, b) -> bpy.types.NodeSocket:
        node = self.node("ShaderNodeMix", stage, data_type=data_type, clamp_factor=False)
        sockets = [s for s in node.inputs if s.enabled]
        self.link(fac, sockets[0])
        self.link(a, sockets[1])
        self.link(b, sockets[2])
        return next(s for s in node.outputs if s.enabled)


def set_default(socket: bpy.types.NodeSocket, value) -> None:
    """``socket.default_value = value`` unless it holds that value already (as stored: float32)."""
    current = np.asarray(socket.default_value, np.float32)
    if current.shape != np.shape(value) or not np.array_equal(current, np.asarray(value, np.float32)):
        socket.default_value = value


class GridPoint(NamedTuple):
    """Where a colour lies in a table's grid (:func:`grid_vector`): ``uv`` the UV of its texel in the first slice of a
    one-row atlas, the grid coordinates clamped to the grid (its z the slice coordinate x0), ``x0`` that slice
    coordinate, ``coords`` the grid coordinates (x1, x2, x0) plus the origin of :func:`_grid_frame`, each over its
    factor of :func:`_skin_axes`, before the clamp (the atlas' u, v axes first) and ``painted`` the colour clamped to
    [0, 1] (vector sockets, ``x0`` a float socket)."""

    uv: bpy.types.NodeSocket
    x0: bpy.types.NodeSocket
    coords: bpy.types.NodeSocket
    painted: bpy.types.NodeSocket


def _map_range(b: _Builder, stage: int, value: bpy.types.NodeSocket, low, high, to_low,
               to_high) -> bpy.types.NodeSocket:
    """A vector Map Range (linear, clamped) of ``value`` from [low, high] to [to_low, to_high] (3-tuples): one node
    for an affine map per component and the clamp to its range."""
    node = b.node("ShaderNodeMapRange", stage, data_type="FLOAT_VECTOR", clamp=True)
    b.group.links.new(value, node.inputs["Vector"])
    for name, bound in (("From_Min_FLOAT3", low), ("From_Max_FLOAT3", high), ("To_Min_FLOAT3", to_low),
                        ("To_Max_FLOAT3", to_high)):
        set_default(next(s for s in node.inputs if s.identifier == name), tuple(float(v) for v in bound))
    return next(s for s in node.outputs if s.identifier == "Vector")


#: The skin-space axes (exporters.texel_table.COORDS) in the order of the grid vector: the atlas' u, v axes, then the
#: slice axis.
_GRID_ORDER = (1, 2, 0)


def _grid_frame(layout: live_table.AtlasLayout) -> tuple[np.ndarray, np.ndarray]:
    """Where the grid lies in the coordinates :func:`grid_vector` combines, along the axes of the grid vector
    (:data:`_GRID_ORDER`), and its largest index: a colour's coordinates less the first lie in [0, the second] inside
    the table's box.  The nodes take skin space (exporters.texel_table.COORDS) of e' = (e + 0.055) / 1.055 times 1.055
    over the step, which is the grid coordinate plus 0.055 COORDS.sum(axis=1) / step: the origin carries that offset."""
    offset = _SRGB_OFFSET * texel_table.COORDS.sum(axis=1) / layout.step
    return (np.array([layout.origin[d] / layout.step + offset[d] for d in _GRID_ORDER]),
            np.array([layout.shape[d] - 1.0 for d in _GRID_ORDER]))


def _skin_axes(layout: live_table.AtlasLayout) -> tuple[list[list[tuple[int, float]]], np.ndarray]:
    """Per axis of the grid vector (:data:`_GRID_ORDER`): the channels of e' = (e + 0.055) / 1.055 and their signs
    (+1, -1; the first +1) whose sum the nodes form, and the factor alpha taking that sum to the grid coordinate
    (plus the origin of :func:`_grid_frame`): 1.055 m / step, m the row's one magnitude (exporters.texel_table.COORDS:
    the mean of R, G, B; R - G; G - B).  ValueError for a row of other coefficients."""
    terms, alpha = [], []
    for d in _GRID_ORDER:
        row = texel_table.COORDS[d]
        channels = np.flatnonzero(row)
        magnitude = abs(float(row[channels[0]]))
        if row[channels[0]] < 0.0 or not np.all(np.abs(row[channels]) == magnitude):
            raise ValueError(f"skin-space row {row} is not a sum of channels with signs: grid_vector cannot form it")
        terms.append([(int(j), float(np.sign(row[j]))) for j in channels])
        alpha.append(_SRGB_SCALE * magnitude / layout.step)
    return terms, np.array(alpha)


def grid_vector(b: _Builder, colour: bpy.types.NodeSocket, layout: live_table.AtlasLayout,
                size: tuple[float, float], clamped: bpy.types.NodeSocket | None = None) -> GridPoint:
    """Grid point of ``colour`` (linear RGB): clamped to [0, 1], sRGB encoded piecewise as
    exporters.colorimetry.srgb_encode, in skin space (exporters.texel_table.COORDS), on the grid of ``layout``, and
    its texel in an atlas of ``size`` (width, height) px whose slices of ``layout`` lie in one row from the bottom
    left, the layout's border px in.  Every node costs each shading point its time, so: the clamp is a Mix node's
    (factor 0, result clamped: NaN reads as 0, +Inf as 1); the encoding is max(1.055 c^(1/2.4) - 0.055,
    min(12.92 c, 12.92 knee)) (below the knee the line lies above the power curve and under its cap, from the knee up
    the power curve lies above the cap, so this is the piecewise encoding except within 3e-7 above the knee, where
    the two pieces differ by 4e-6), computed as 1.055 e' - 0.055 with e' = max(c^(1/2.4), (min(12.92 c, 12.92 knee) +
    0.055) / 1.055): the power by a Gamma node, the capped line by a Map Range, and the factor and offset go to the
    grid's frame (:func:`_grid_frame`); the skin-space coordinates are sums and differences of e''s channels in Math
    nodes (:func:`_skin_axes`: a Math node runs in a third of the instructions of a Vector Math dot product), their
    factors in the frame too; one Map Range takes them to the atlas' UV and clamps them to the grid.  ``clamped``: the
    colour clamped to [0, 1] already (the grazing-light group's), read instead of clamping it here."""
    if clamped is None:
        mix = b.node("ShaderNodeMix", 1, data_type="RGBA", clamp_result=True, clamp_factor=False)
        sockets = [s for s in mix.inputs if s.enabled]
        set_default(sockets[0], 0.0)
        b.group.links.new(colour, sockets[1])
        clamped = next(s for s in mix.outputs if s.enabled)
    gamma = b.node("ShaderNodeGamma", 2)
    b.group.links.new(clamped, gamma.inputs["Color"])
    set_default(gamma.inputs["Gamma"], 1.0 / 2.4)
    line = _map_range(b, 3, clamped, (0.0,) * 3, (_SRGB_KNEE,) * 3, (_SRGB_OFFSET / _SRGB_SCALE,) * 3,
                      ((_SRGB_SLOPE * _SRGB_KNEE + _SRGB_OFFSET) / _SRGB_SCALE,) * 3)
    encoded = b.node("ShaderNodeSeparateColor", 6)
    b.group.links.new(b.vec("MAXIMUM", 5, gamma.outputs[0], line), encoded.inputs[0])  # e' = (e + 0.055) / 1.055
    comb = b.node("ShaderNodeCombineColor", 7)  # one SVM node where a Combine XYZ runs three
    terms, alpha = _skin_axes(layout)
    for slot, row in enumerate(terms):
        (first, _), *rest = row
        total = encoded.outputs[first]
        for channel, sign in rest:
            total = b.math("ADD" if sign > 0 else "SUBTRACT", 6, total, encoded.outputs[channel])
        b.group.links.new(total, comb.inputs[slot])
    origin, extent = _grid_frame(layout)
    border = layout.border + 0.5
    width, height = size
    to_low = (border / width, border / height, 0.0)
    to_high = ((extent[0] + border) / width, (extent[1] + border) / height, extent[2])
    uv = _map_range(b, 8, comb.outputs[0], origin / alpha, (origin + extent) / alpha, to_low, to_high)
    sep = b.node("ShaderNodeSeparateColor", 9)
    b.group.links.new(uv, sep.inputs[0])
    return GridPoint(uv=uv, x0=sep.outputs[2], coords=comb.outputs[0], painted=clamped)


def _grid_coords(b: _Builder, layout: live_table.AtlasLayout, colour: bpy.types.NodeSocket,
                 clamped: bpy.types.NodeSocket | None = None):
    """The grid point (:class:`GridPoint`) of ``colour`` (the input colour with the Principled convention's gain;
    ``clamped``: the same clamped to [0, 1], when made elsewhere), and its distance from the box (skin space)."""
    point = grid_vector(b, colour, layout, layout.size, clamped)
    origin, extent = _grid_frame(layout)
    alpha = _skin_axes(layout)[1]
    raw = b.vec("SUBTRACT", 10, point.coords, origin / alpha)
    x = b.vec("MINIMUM", 11, b.vec("MAXIMUM", 10, raw, 0.0), extent / alpha)
    gap = b.vec("ABSOLUTE", 11, b.vec("SUBTRACT", 11, raw, x))
    return point, b.vec("DOT_PRODUCT", 12, gap, alpha * layout.step)


def _slice_uvs(b: _Builder, layout: live_table.AtlasLayout, point: GridPoint, stage: int) -> tuple:
    """UVs (vectors) of the grid point's slices s and s + 1 in the one-row atlas of ``layout``
    (exporters.live_table), and the fraction of x0 between them."""
    if layout.rows != 1:
        raise ValueError("the live group reads one-row atlases (exporters.live_table.layout_of)")
    tile_u = layout.tile[0] / layout.size[0]
    s = b.math("FLOOR", stage, point.x0)  # up to n0 - 1 (x0 is clamped): the atlas' copy of the last slice follows
    frac = b.math("SUBTRACT", stage + 2, point.x0, s)
    uv = b.vec("MULTIPLY_ADD", stage + 2, s, (tile_u, 0.0, 0.0), point.uv)
    return (uv, b.vec("ADD", stage + 3, uv, (tile_u, 0.0, 0.0))), frac


def _lookup(b: _Builder, image: bpy.types.Image, uvs, frac, stage: int):
    """Trilinear value of one atlas: two bilinear lookups (slices s, s + 1) mixed by ``frac``; (RGB, alpha)."""
    colours, alphas = [], []
    for uv in uvs:
        tex = b.node("ShaderNodeTexImage", stage, image=image, interpolation="Linear", extension="EXTEND")
        tex.label = image.name
        b.link(uv, tex.inputs["Vector"])
        colours.append(tex.outputs["Color"])
        alphas.append(tex.outputs["Alpha"])
    return (b.mix("VECTOR", stage + 1, frac, colours[0], colours[1]),
            b.mix("FLOAT", stage + 1, frac, alphas[0], alphas[1]))


#: The group of the EEVEE output's effective radius (:func:`ensure_eevee_radius_group`).
EEVEE_RADIUS_GROUP_NAME = "Spectral Skin SSS EEVEE Radius"


def ensure_eevee_radius_group(table: texel_table.TexelTable, layout: live_table.AtlasLayout,
                              images: dict[str, bpy.types.Image]) -> bpy.types.NodeTree:
    """The group (one per table and file) of the EEVEE output's effective radius: input Color (the colour entering
    the table), output Radius, sum_k w_k r_k per channel in metres, the table's weights and log radii read through
    Environment Textures (:meth:`_Builder.environment`).  A group of its own: Blender adds a node in time growing
    with the tree, and the live group is the largest."""
    for group in bpy.data.node_groups:
        if (group.name.startswith(EEVEE_RADIUS_GROUP_NAME) and group.get(TABLE_PROP) == table.sha256
                and group.get("spectral_skin_sss_version") == LIVE_VERSION):
            return group
    group = bpy.data.node_groups.new(EEVEE_RADIUS_GROUP_NAME, "ShaderNodeTree")
    group[TABLE_PROP] = table.sha256
    group["spectral_skin_sss_version"] = LIVE_VERSION
    group["spectral_skin_sss_backend"] = "EEVEE RADIUS"
    group.interface.new_socket("Color", in_out="INPUT", socket_type="NodeSocketColor")
    group.interface.new_socket("Radius", in_out="OUTPUT", socket_type="NodeSocketVector")
    gin, gout = group.nodes.new("NodeGroupInput"), group.nodes.new("NodeGroupOutput")
    gin.location, gout.location = (-1900.0, 0.0), (4000.0, 0.0)
    b = _Builder(group)
    uvs, frac = _slice_uvs(b, layout, grid_vector(b, gin.outputs["Color"], layout, layout.size), 12)
    tile_u = layout.tile[0] / layout.size[0]
    ranges = live_table.atlas_ranges(table)
    total = None
    for k in range(1, table.k + 1):
        weight = _environment_pair(b, images[f"k{k} Weight"], uvs[0], tile_u, frac, 14)
        metres = _metres(b, _environment_pair(b, images[f"k{k} Log Radius"], uvs[0], tile_u, frac, 14),
                         ranges.log_radius, 18)
        total = b.vec("MULTIPLY", 19, weight, metres) if total is None \
            else b.vec("MULTIPLY_ADD", 19, weight, metres, total)
    b.link(total, gout.inputs["Radius"])
    b.place()
    return group


def _environment_pair(b: _Builder, image: bpy.types.Image, uv, tile_u: float, frac,
                      stage: int) -> bpy.types.NodeSocket:
    """:func:`_lookup`'s RGB for the EEVEE output: slices s (at ``uv``) and s + 1 (``tile_u`` further) read through
    Environment Textures (:meth:`_Builder.environment`), mixed by ``frac``."""
    found = [b.environment(image, uv, stage, (du, 0.0)) for du in (0.0, tile_u)]
    return b.mix("VECTOR", stage + 3, frac, found[0], found[1])


def _metres(b: _Builder, log_radius, log_range: tuple[float, float], stage: int) -> bpy.types.NodeSocket:
    """exp(log r) per channel: the radius in metres, a curve through exp over ``log_range`` (the table's log radii:
    blender_addon.curves, within 2e-4 relative)."""
    return b.curve(stage, log_radius, *curves.smooth_points(np.exp, *log_range))


def _per_unit(b: _Builder, units_per_metre, *factors) -> bpy.types.NodeSocket:
    """The product of the vector ``factors`` (None: left out) scaled by ``units_per_metre`` (the Translucency over
    the Unit Scale): what turns a radius in metres into Blender units with its factors (an edit's, the grazing-light
    correction's), computed once for every component (a Scale, which Cycles drops where the scale is a constant 1:
    Unit Scale 1, Translucency 1)."""
    product = None
    for factor in factors:
        if factor is not None:
            product = factor if product is None else b.vec("MULTIPLY", 19, product, factor)
    scale = b.node("ShaderNodeVectorMath", 20, operation="SCALE")
    b.link(product if product is not None else (1.0, 1.0, 1.0), scale.inputs[0])
    b.link(units_per_metre, scale.inputs["Scale"])
    return scale.outputs[0]


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
    translucency = iface.new_socket("Translucency", in_out="INPUT", socket_type="NodeSocketFloat")
    translucency.default_value, translucency.min_value, translucency.max_value = 1.0, nodes.TRANSLUCENCY_MIN, 100.0
    nodes.add_specular_inputs(group, nodes.ARTIST_INPUTS)
    iface.new_socket("Cycles", in_out="OUTPUT", socket_type="NodeSocketShader")
    iface.new_socket("EEVEE", in_out="OUTPUT", socket_type="NodeSocketShader")
    iface.new_socket("Outside", in_out="OUTPUT", socket_type="NodeSocketFloat")
    gin = group.nodes.new("NodeGroupInput")
    gout = group.nodes.new("NodeGroupOutput")
    gin.location, gout.location = (-1900.0, 0.0), (6400.0, 0.0)
    return group, gin, gout


def build_live_group(table: texel_table.TexelTable, layout: live_table.AtlasLayout,
                     images: dict[str, bpy.types.Image], edits=None, grazing: bool = True) -> bpy.types.NodeTree:
    """A new live group reading ``images`` (from :func:`ensure_images`) of ``table``; see the module docstring.
    ``edits``: (edit table, its images from live_edits.ensure_images) for the Melanin, Blood and Oxygenation inputs
    (blender_addon.live_edits), or None; ``grazing``: with the grazing-light correction of the Cycles output's
    weights and radii (blender_addon.oblique; False: the mixture as fitted at every angle)."""
    group, gin, gout = _new_group(table.k, table.sha256)
    group[GRAZING_PROP] = grazing
    b = _Builder(group)
    branch = eevee_branch = None
    if edits is not None:
        live_edits.add_inputs(group)
        group[live_edits.EDIT_TABLE_PROP] = edits[0].sha256
        branch = live_edits.edit_node(b, gin, *edits)
        eevee_branch = live_edits.edit_node(b, gin, *edits, eevee=True)
    edited = branch.colour if branch is not None else None
    eevee_edited = eevee_branch.colour if eevee_branch is not None else None
    colour = _convention(b, gin, 1.0, PRINCIPLED_BASE_SHARE_CYCLES, edited)
    factors = clamped = None
    if grazing:
        factors = b.node("ShaderNodeGroup", 26, node_tree=oblique.ensure_group(), name="Grazing")
        b.link(colour, factors.inputs["Color"])
        b.link(gin.outputs["Normal"], factors.inputs["Normal"])
        clamped = factors.outputs["Color"]
    point, outside = _grid_coords(b, layout, colour, clamped)
    b.zero = nodes.computed_zero(group, point.x0).vector  # x0 is clamped to the grid: finite
    painted = point.painted
    uvs, frac = _slice_uvs(b, layout, point, 12)
    mixture = b.node("ShaderNodeGroup", 34, node_tree=nodes.ensure_group(table.k, "SVM"))
    unit = b.math("DIVIDE", 19, b.math("MAXIMUM", 18, gin.outputs["Translucency"], nodes.TRANSLUCENCY_MIN),
                  gin.outputs["Unit Scale"])  # Blender units per metre of radius
    unit.node.name = "Translucency"
    weight_share = b.math("ADD", 24, gin.outputs["Subsurface Weight"], 0.0, clamp=True)
    media = []
    ranges = live_table.atlas_ranges(table)
    edit_factor = branch.radius_factor if branch is not None else None
    per_unit = _per_unit(b, unit, eevee_branch.radius_factor if eevee_branch is not None else None)  # EEVEE's
    per_unit_cycles = _per_unit(b, unit, edit_factor, factors.outputs["Radius"] if factors is not None else None)
    eevee_radius = b.node("ShaderNodeGroup", 20, node_tree=ensure_eevee_radius_group(table, layout, images))
    b.link(colour if eevee_edited is None else _convention(b, gin, 1.0, PRINCIPLED_BASE_SHARE_CYCLES, eevee_edited),
           eevee_radius.inputs["Color"])
    for k in range(1, table.k + 1):
        # the colour's body reflectance, and the anisotropy from the same reads: linked, it costs one mix per
        # component, where a constant is written to the stack by each of the component's three closures
        rho, g = _lookup(b, images[f"k{k} Color"], uvs, frac, 18)
        log_r, _ = _lookup(b, images[f"k{k} Log Radius"], uvs, frac, 18)
        weight, _ = _lookup(b, images[f"k{k} Weight"], uvs, frac, 18)
        metres = _metres(b, log_r, ranges.log_radius, 20)
        media.append((rho, weight))
        radius = b.product(21, per_unit_cycles, metres) if grazing else b.vec("MULTIPLY", 21, metres, per_unit_cycles)
        b.link(radius, mixture.inputs[nodes.socket_name(k, "Radius")])
        b.link(g, mixture.inputs[nodes.socket_name(k, "Anisotropy")])
    fit = painted_gain.body_fit(table.options.ior)
    for k, (colour, weight) in enumerate(_painted_media(b, painted, media, fit, ranges.rho_max, 23), start=1):
        b.link(colour, mixture.inputs[nodes.socket_name(k, "Color")])
        b.link(weight, mixture.inputs[nodes.socket_name(k, "Weight")])
    b.link(_weight_scale(b, weight_share, factors), mixture.inputs["Weight Scale"])
    b.link(_diffuse_body(b, gin, painted, weight_share), mixture.inputs["Body"])
    mixture.inputs["IOR"].default_value = table.options.ior
    for name in ("Roughness", "Normal", *nodes.SPECULAR_INPUTS):
        b.link(gin.outputs[name], mixture.inputs[name])
    b.link(_alpha_emission(b, gin, mixture.outputs["BSSRDF"]), gout.inputs["Cycles"])
    effective = b.vec("MULTIPLY", 24, eevee_radius.outputs["Radius"], per_unit)
    b.link(_eevee_surface(b, gin, effective, table.options.ior, eevee_edited), gout.inputs["EEVEE"])
    b.link(outside, gout.inputs["Outside"])
    b.place()
    return group


def _weight_scale(b: _Builder, weight_share, factors: bpy.types.Node | None) -> bpy.types.NodeSocket:
    """The mixture's Weight Scale: the Subsurface Weight ``weight_share`` times the grazing-light weight factors (the
    Grazing group node ``factors``; without one the share alone), one node for every component (the mixture
    multiplies each component's weights by it).  The radii take their factors in :func:`_per_unit`."""
    if factors is None:
        return weight_share
    scale = b.node("ShaderNodeVectorMath", 30, operation="SCALE", name="Subsurface Weight")
    b.link(factors.outputs["Weight"], scale.inputs[0])
    b.link(weight_share, scale.inputs["Scale"])
    return scale.outputs[0]


def _painted_media(b: _Builder, painted, media: list, fit: painted_gain.BodyFit, rho_max: float,
                   stage: int) -> list[tuple]:
    """Each component's (colour, weight) from its looked-up (body reflectance rho, weight), brought to the
    ``painted`` colour: exporters.painted_gain.painted_media with nodes, the inverse fit
    (exporters.painted_gain.body_colour) a curve through it (blender_addon.curves: within 1e-4) over [low, reach]
    when the table's rho never exceeds ``reach`` (``rho_max``: the curve's end is then the cap at reach), else over
    [low, 1] after a minimum with reach.  The gain G = P / Q is one node for every component (Cycles' divide: 0 where
    Q is 0); per component the scaled weight w G, the weight min(w G, 1) and the lifted reflectance
    max(rho, w G rho) are vector nodes with at most one constant, the products Mix nodes from the group's computed zero
    (:meth:`_Builder.product`): a Map Range would do two of them in one node but loads its four bounds and its steps
    at every shading point (training.bench.instructions counts the dispatches)."""
    capped = rho_max <= fit.reach  # then max(rho, min(x, reach)) = min(max(rho, x), reach): the curve's cap
    body_points = curves.smooth_points(lambda rho: painted_gain.body_colour(rho, fit), fit.low,
                                       fit.reach if capped else 1.0)
    total = None
    for rho, weight in media:
        total = b.product(stage, weight, rho) if total is None \
            else b.vec("MULTIPLY_ADD", stage + 1, weight, rho, total)
    gain = b.vec("DIVIDE", stage + 3, painted, total)  # G; Cycles' divide: 0 where the media render black
    out = []
    for rho, weight in media:
        scaled = b.product(stage + 4, weight, gain)
        lifted = b.vec("MAXIMUM", stage + 6, rho, b.product(stage + 5, scaled, rho))
        if not capped:
            lifted = b.vec("MINIMUM", stage + 7, lifted, fit.reach)
        colour = b.curve(stage + 8, lifted, *body_points)
        out.append((colour, b.vec("MINIMUM", stage + 9, scaled, 1.0)))
    return out


def _diffuse_body(b: _Builder, gin: bpy.types.Node, painted, weight_share) -> bpy.types.NodeSocket:
    """A Diffuse BSDF of the painted colour weighted 1 - Subsurface Weight (the mixture's Body: under its coat, which
    takes 1 - Coat Weight x F of its light; tinted here by the coat's Coat Tint, nodes.coat_tint, as the mixture is
    tinted inside its group: at Coat Weight 0 the factor is constant 1 and Cycles folds the product away)."""
    diffuse = b.node("ShaderNodeBsdfDiffuse", 32)
    b.link(b.vec("MULTIPLY", 31, painted, nodes.coat_tint(b.group, gin)), diffuse.inputs["Color"])
    diffuse.inputs["Roughness"].default_value = 0.0
    b.link(gin.outputs["Normal"], diffuse.inputs["Normal"])
    mix = b.node("ShaderNodeMixShader", 33, name="Diffuse body")
    b.link(b.math("SUBTRACT", 32, 1.0, weight_share), mix.inputs["Fac"])
    b.link(diffuse.outputs[0], mix.inputs[2])
    return mix.outputs[0]


def _alpha_emission(b: _Builder, gin: bpy.types.Node, surface) -> bpy.types.NodeSocket:
    """The Principled BSDF's Emission (added) and Alpha (a Transparent BSDF mixed in) over ``surface``."""
    emission = b.node("ShaderNodeEmission", 35)
    b.link(gin.outputs["Emission Color"], emission.inputs["Color"])
    b.link(gin.outputs["Emission Strength"], emission.inputs["Strength"])
    add = b.node("ShaderNodeAddShader", 36, name="Emission")
    b.link(surface, add.inputs[0])
    b.link(emission.outputs[0], add.inputs[1])
    transparent = b.node("ShaderNodeBsdfTransparent", 36)
    mix = b.node("ShaderNodeMixShader", 37, name="Alpha")
    b.link(b.math("ADD", 36, gin.outputs["Alpha"], 0.0, clamp=True), mix.inputs["Fac"])
    b.link(transparent.outputs[0], mix.inputs[1])
    b.link(add.outputs[0], mix.inputs[2])
    return mix.outputs[0]


def _convention(b: _Builder, gin: bpy.types.Node, painted: float, principled: float,
                colour=None) -> bpy.types.NodeSocket:
    """The input colour (or ``colour``) times ``painted`` (Principled Convention 0) or ``principled`` (1), mixed in
    between."""
    gain = b.math("MULTIPLY_ADD", 0, gin.outputs["Principled Convention"], principled - painted, painted)
    scale = b.node("ShaderNodeVectorMath", 0, operation="SCALE")
    b.link(colour if colour is not None else gin.outputs["Color"], scale.inputs[0])
    b.link(gain, scale.inputs["Scale"])
    return scale.outputs[0]


def _eevee_surface(b: _Builder, gin: bpy.types.Node, radius, ior: float, colour=None) -> bpy.types.NodeSocket:
    """One Principled BSDF: the colour (over PRINCIPLED_BASE_SHARE in the painted convention) as Base Color,
    the group's Subsurface Weight (1 by default), Alpha and Emission, the effective radius."""
    bsdf = b.node("ShaderNodeBsdfPrincipled", 35)
    b.link(_convention(b, gin, 1.0 / PRINCIPLED_BASE_SHARE, 1.0, colour), bsdf.inputs["Base Color"])
    bsdf.inputs["Subsurface Scale"].default_value = 1.0
    bsdf.inputs["IOR"].default_value = ior
    b.link(radius, bsdf.inputs["Subsurface Radius"])
    for name in ("Roughness", "Normal", *nodes.SPECULAR_INPUTS, *nodes.ARTIST_INPUTS):
        b.link(gin.outputs[name], bsdf.inputs[name])
    return bsdf.outputs[0]


def ensure_live_group(table: texel_table.TexelTable, edits=None, grazing: bool = True) -> bpy.types.NodeTree:
    """The live group of ``table`` (and of the edit table ``edits``, or None: no edit inputs; ``grazing``: with the
    grazing-light correction): an existing one of these tables, this version and this choice is reused (every
    material shares it and its images), else one is built."""
    edit_sha = edits.sha256 if edits is not None else None
    for group in bpy.data.node_groups:
        if (group.name.startswith(GROUP_NAME) and group.get(TABLE_PROP) == table.sha256
                and group.get("spectral_skin_sss_version") == LIVE_VERSION
                and group.get(live_edits.EDIT_TABLE_PROP) == edit_sha
                and group.get(GRAZING_PROP, False) == grazing):
            return group
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="spectral-skin-atlases") as pool:
        atlases = _start_atlases(pool, table, edits)
        nodes.ensure_group(table.k, "SVM")  # the groups that need no images, built while the atlases are made
        if grazing:
            oblique.ensure_group()
        edit_images = None
        if edits is not None:  # the edit atlases come first: the edit group is built while the table's are made
            edit_images = (edits, live_edits.ensure_images(edits, atlases.get("edits")))
            live_edits.ensure_edit_group(*edit_images)
            live_edits.ensure_edit_group(*edit_images, eevee=True)
        layout, images = ensure_images(table, atlases.get("live"))
    return build_live_group(table, layout, images, edit_images, grazing)


def _start_atlases(pool: Executor, table: texel_table.TexelTable, edits) -> dict[str, Callable[[], dict]]:
    """The atlases the file lacks (the table's, the edit table's), made on ``pool`` (numpy only, no Blender data):
    name -> the function that waits for them."""
    started: dict[str, Future] = {}
    if edits is not None and not live_edits.has_images(edits):
        started["edits"] = pool.submit(edits.atlases)
    if len(_found_images(table)) < len(_image_names(table)):
        started["live"] = pool.submit(lambda: live_table.atlases(table)[1])
    return {name: future.result for name, future in started.items()}


# -- wiring ----------------------------------------------------------------------------------------------------
def colour_source(material: bpy.types.Material) -> tuple[bpy.types.Node, bpy.types.NodeSocket | None, tuple]:
    """The artist's Principled BSDF (the one feeding the active Material Output, straight or under Mix Shader and
    Add Shader layers: wiring.shader_chain; or in a material wired before the per-target outputs the one named in
    ``material[PREVIOUS_SURFACE_PROP]``), the output socket feeding its Base Color (None when unlinked) and its Base
    Color value."""
    surface = wiring.artist_principled(material)
    grouped = wiring.grouped_principled(material.node_tree) if surface is None else None
    if grouped is not None:
        raise LiveInputError(f"material '{material.name}': its Principled BSDF sits in the node group "
                             f"'{grouped.node_tree.name}' where the live group cannot reach it (it follows group "
                             "outputs and Mix and Add Shader layers, not other nodes such as Shader to RGB); link "
                             "the Principled BSDF to the group's output that way, or ungroup the group that holds "
                             "it (Tab into the group, select its node, Ctrl+Alt+G), and run this again")
    if surface is None:
        raise LiveInputError(f"material '{material.name}': no Principled BSDF feeds its Material Output's Surface "
                             "(straight or through Mix Shader and Add Shader nodes); connect one (its Base Color is "
                             "the skin's albedo) or choose Bake")
    socket = surface.inputs["Base Color"]
    return surface, wiring.feeding_socket(socket), tuple(socket.default_value)


def wire_live(material: bpy.types.Material, group: bpy.types.NodeTree, unit_scale_m: float) -> bpy.types.Node:
    """Insert the live group into ``material``: fed by what fed the Principled BSDF's Base Color (or its value),
    its Normal and Roughness (nodes.wire_into_material), its Cycles output into a Material Output of target Cycles
    and its EEVEE output into one of target EEVEE; the artist's Principled BSDF keeps feeding the active Material
    Output, which Blender's exporters read (blender_addon.wiring).  Every node of the artist's is kept."""
    principled = colour_source(material)[0]
    gnode = nodes.wire_into_material(material, group, output="Cycles", eevee_output="EEVEE")
    gnode.inputs["Unit Scale"].default_value = unit_scale_m
    wiring.take_input(gnode.id_data, principled.inputs["Base Color"], gnode.inputs["Color"])
    return gnode


# -- outside the domain ----------------------------------------------------------------------------------------
def image_colours(image: bpy.types.Image, colorspace: str, limit: int = OUTSIDE_SAMPLE) -> np.ndarray:
    """Linear colours (N, 3) of about ``limit`` texels of ``image`` (every tile of a UDIM image; an even grid when
    larger), decoded as ``colorspace`` ("srgb", "linear" or "auto": sRGB for 8/16-bit, linear for float).  Files
    are read directly (a few rows, never the whole float buffer) where OpenImageIO's Python module is there;
    packed and generated images, and every image in a Blender without that module (4.2), from Blender's own
    pixel buffer (a tiled image's first tile only)."""
    return _decoded([read() for read in _texel_sources(image, limit)[0]], colorspace)


def _texel_sources(image: bpy.types.Image, limit: int) -> tuple[list[Callable[[], tuple[np.ndarray, bool]]],
                                                                   tuple | None]:
    """What :func:`image_colours` reads: one function per part giving (values as stored (N, 3), whether the image
    stores floats), none of which touches Blender data (Blender's pixel buffer is copied here), and the versions of
    the files read (:func:`file_key`; None when a part is no file)."""
    try:
        image_input.openimageio()
    except image_input.ImageError:
        paths = None
    else:
        if image.source == "TILED":
            paths = [p for p in (_file_of(image, tile.number) for tile in image.tiles) if os.path.isfile(p)]
            share = limit // max(len(image.tiles), 1)
        elif image.source == "FILE" and image.packed_file is None and os.path.isfile(_file_of(image)):
            paths, share = [_file_of(image)], limit
        else:
            paths = None
    if paths is None:
        pixels = (_pixels(image, limit), image.is_float)
        return [lambda: pixels], None
    keys = tuple(file_key(p) for p in paths)
    return ([lambda path=p: image_input.sample_texels(path, share) for p in paths],
            (keys, share) if None not in keys else None)


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
          principled_convention: bool = False, edit: tuple[float, float, float] | None = None,
          material_name: str = "") -> str:
    """Wire the live group into the active object's active material, or its material ``material_name`` (Invert
    Skin Albedo's default); returns the one-line report. ``edit``: (Melanin, Blood, Oxygenation) set on the group
    node's inputs (None or neutral: left as they are, so an edit made on the node stays; LiveInputError when the
    model has no edit table). Bad input
    raises LiveInputError before anything changes; a failure while wiring removes what was made (call from an
    operator with UNDO for Ctrl+Z)."""
    from . import follow  # it reads this module's wiring (colour_source)

    try:
        material = wiring.object_material(context.object, material_name)
    except ValueError as exc:
        raise LiveInputError(str(exc)) from None
    if material is not None and material.node_tree is None:
        raise LiveInputError(f"material '{material.name}' uses no nodes: turn on Use Nodes and give it a Principled "
                             "BSDF fed by the albedo, then run this again")
    if material is None:
        raise LiveInputError("no active material with nodes: select the skin object (its material's Principled "
                             "BSDF gives the albedo)")
    error = wiring.linked_error(material)
    if error:
        raise LiveInputError(error)
    if edit is not None and skin_edits.SkinEdit(*edit).neutral:
        edit = None
    table = table_for_model(model_path)
    edits = live_edits.table_for_model(model_path, table.sha256)
    if edits is None and edit is not None:
        raise LiveInputError(f"no edit table beside {model_path}: the live group takes no Melanin, Blood or "
                             "Oxygenation; build it with python -m training edit-table, or bake with the edit")
    wired = wiring.wired_group_node(material)
    if wired is not None and wiring.is_added(wired) and wired.node_tree.get(TABLE_PROP) == table.sha256 \
            and wired.node_tree.get("spectral_skin_sss_version") == LIVE_VERSION \
            and wired.node_tree.get(live_edits.EDIT_TABLE_PROP) == (edits.sha256 if edits is not None else None):
        wired.inputs["Unit Scale"].default_value = unit_scale_m
        wired.inputs["Principled Convention"].default_value = float(principled_convention)
        live_edits.set_edit(wired, edit)
        follow.follow(material, unit_scale_m)  # what changed on the Principled BSDF while no handler ran
        return (f"up to date: '{material.name}' already renders through the live group (Unit Scale {unit_scale_m:g} m "
                "per Blender unit)")
    _, colour, _ = colour_source(material)
    image_node = colour.node if colour is not None and colour.node.bl_idname == "ShaderNodeTexImage" else None
    image = image_node.image if image_node is not None else None
    before = _state(material)
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="spectral-skin-outside") as pool:
        outside = outside_check(table, image, colorspace, pool) if image is not None else None
        try:
            group = ensure_live_group(table, edits)
            gnode = wire_live(material, group, unit_scale_m)
            gnode.inputs["Principled Convention"].default_value = float(principled_convention)
            live_edits.set_edit(gnode, edit)
            follow.record(material, unit_scale_m)
        except BaseException:
            _restore(material, before)
            raise
        report = (f"live group wired into '{material.name}'{wiring.grouped_text(material, gnode)} "
                  f"(K={table.k}; no maps baked)")
        if outside is not None:
            report += "; " + outside()
    gnode.select = True
    return report


def outside_report(table: texel_table.TexelTable, image: bpy.types.Image, colorspace: str) -> str:
    """How much of ``image`` lies outside the table's domain of skin colours (it renders as painted all the same)."""
    return outside_check(table, image, colorspace)()


def outside_check(table: texel_table.TexelTable, image: bpy.types.Image, colorspace: str,
                  pool: Executor | None = None) -> Callable[[], str]:
    """:func:`outside_report`, started: the files are read and the colours located on ``pool`` (no Blender data is
    touched there), so that the operator builds its nodes meanwhile; returns the function that waits for the
    report.  A file version checked before (path, size, modification time: :func:`file_key`) with this table and
    colour space is not read again."""
    from .baker import _image_colorspace  # the bake's reading of Blender's colour-space setting

    name, used = image.name, _image_colorspace(image, colorspace)
    sources, files = _texel_sources(image, OUTSIDE_SAMPLE)
    key = (files, used, table.sha256) if files is not None else None
    if key in _OUTSIDE:
        return lambda: _outside_text(name, _OUTSIDE[key])

    def share() -> float | None:
        rgb = _decoded([read() for read in sources], used)
        return live_table.outside_fraction(table, rgb) if len(rgb) else None

    future = pool.submit(share) if pool is not None else None

    def report() -> str:
        value = future.result() if future is not None else share()
        if key is not None:
            if len(_OUTSIDE) >= 64:
                _OUTSIDE.clear()
            _OUTSIDE[key] = value
        return _outside_text(name, value)

    return report


#: The share outside the skin colours (None: no pixels) per (file versions, colour space, table SHA-256).
_OUTSIDE: dict[tuple, float | None] = {}


def _outside_text(name: str, share: float | None) -> str:
    if share is None:
        return f"image '{name}' has no pixels to check"
    if share == 0.0:
        return f"every texel of '{name}' is a skin colour of the table"
    return (f"{100 * share:.2f} % of the texels of '{name}' lie outside the table's skin colours (make-up, "
            "ink, paint: they render as painted, with the translucency of the nearest skin colour; "
            "docs/user/non_skin_colours.md)")


def _state(material: bpy.types.Material) -> dict:
    tree = material.node_tree
    return {"groups": set(bpy.data.node_groups.keys()), "images": set(bpy.data.images.keys()),
            "nodes": {n.name for n in tree.nodes},
            "links": [(ln.from_node.name, ln.from_socket.identifier, ln.to_node.name, ln.to_socket.identifier)
                      for ln in tree.links],
            "props": {p: material[p] for p in wiring.MATERIAL_PROPS if p in material},
            "thickness_from_shadow": material.use_thickness_from_shadow}


def _restore(material: bpy.types.Material, state: dict) -> None:
    """Undo a failed wiring: new nodes, groups and images removed, the links, the add-on's material properties and
    EEVEE's Thickness From Shadow as they were (links to nodes no longer there are skipped), the add-on's nodes
    taken out of an artist's node group that no material renders through."""
    tree = material.node_tree
    for node in [n for n in tree.nodes if n.name not in state["nodes"]]:
        tree.nodes.remove(node)
    for link in list(tree.links):
        tree.links.remove(link)
    for link in state["links"]:
        wiring.relink(tree, *link)
    for name in set(bpy.data.node_groups.keys()) - state["groups"]:
        bpy.data.node_groups.remove(bpy.data.node_groups[name])
    for name in set(bpy.data.images.keys()) - state["images"]:
        bpy.data.images.remove(bpy.data.images[name])
    for prop in wiring.MATERIAL_PROPS:
        material.pop(prop, None)
    for prop, value in state["props"].items():
        material[prop] = value
    if material.use_thickness_from_shadow != state["thickness_from_shadow"]:
        material.use_thickness_from_shadow = state["thickness_from_shadow"]
    wiring.unwire_unused_groups()  # an artist's node group wired for this material alone
