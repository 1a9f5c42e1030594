"""The live group's skin edits: inputs **Melanin**, **Blood** and **Oxygenation** (exporters.skin_edits) in nodes,
weighed by **Edit Mask**.

The edit table (exporters.edit_table) is packed into six small float images (per control, one of the colour shift
and one of the radius correction: its levels' slice atlases, every slice in one row, stacked in the order of
exporters.edit_table.BLOCK_LEVELS; the neutral level's shift is 0 and not stored: it lies outside the image).
For the painted colour c the nodes compute, as exporters.edit_table.shift and edited_colour:

* each control weighed by the Edit Mask m (clamped to [0, 1]): neutral + m (value - neutral), bake masks'
  convention (exporters.bake.edits);
* control coordinates s = (log2 clamp(Melanin), log2 clamp(Blood), clamp(Oxygenation)); per control the two
  levels around s, read by trilinear lookups at c and interpolated linearly (the hat weights of
  exporters.edit_table.shift); the shift D is their sum over the controls;
* the edited colour c exp(D_RGB) (what the rest of the group reads instead of c: the table's lookup, the EEVEE
  colour) and the radius factor exp(D_radius) per channel (every component's radius is multiplied by it); each
  exponential is a curve through exp over the table's range of shifts (blender_addon.curves: one node where a
  Separate, three Math nodes and a Combine would be), behind a Mix that gives exactly 1 where every control is
  neutral.

At neutral inputs the Mixes give exactly 1: c 1 = c and r 1 = r, the group renders its unedited result bit for bit.
Each control's shift is also switched to exactly 0 where its input is neutral: an unlinked control at its neutral
value (whatever the mask) then folds to a constant 0 when Cycles compiles the shader, which drops that control's
texture lookups (a neutral group evaluates none of the edit nodes).  Each input takes a value or any node
(a painted mask, an attribute, a driver); its keyframes animate it.

**Edit caches.** An edit of constant controls needs D at the painted colour only, for one set of level weights (or,
painted by a linked Edit Mask, along one line of them): the edit group holds :data:`CACHE_SLOTS` caches of constant
edits (:data:`CONSTANT_SLOTS`), each an image pair of one atlas (the table's shift of that edit at the grid's nodes,
exporters.edit_table.combined_atlas of the control images: the lookups are linear, so reading it gives the same D),
read at two slices (4 lookups where the table takes up to 24), and one **mask cache** (:data:`MASK_SLOT`): an edit's
shift at :data:`MASK_POINTS` masks on its line (exporters.edit_table.MaskLine), read at two points and two slices (8
lookups, however many controls the edit moves). While the mask cache holds no line in use, its images' atlases serve
as :data:`SPARE_SLOTS` more caches of constant edits (fifteen constant edits at once); a line, when one is needed,
takes them back. The caches' nodes form groups of their own nested in the edit group
(:data:`CACHES_GROUP_NAME`).  A constant edit's cache is used where the node's hidden
input **Edit Cache** names it and its inputs equal the values the cache holds (Compare nodes in the group: the
controls and the mask's value); the mask cache wherever the node's controls lie on the line from neutral to the edit
it holds, at the mask times their place on it (:func:`_on_line`): an edit painted by the Edit Mask (the controls at
the line's end), and each frame of an edit keyframed along that line (:func:`hold_line`), which Blender's interface
renders outside the main thread, where no frame's edit can be cached.  Then a Mix takes the cache's shift instead of
the table's (a constant edit's own cache before the mask cache's).  For constant inputs the test
folds when Cycles compiles the shader, to 1 (the table's nodes and images drop out) or to 0 (the cache's do); the
test reads values, so a cache never gives another edit's answer: changed values, keyframes and controls fed by
nodes render through the table, as without caches.  A control fed by a Value node, or by the input of an artist's
node group that every group node using it sets to one value, is a value (:func:`input_value`): Cycles folds it as
it does an unlinked input, so its edit is cached.  :func:`cache_edit` fills a cache
(:func:`set_edit`: the operator, the presets, the API); the add-on's handlers cache an edit set on the node or the
panel's sliders (:func:`refresh_caches`) and each frame's keyframed values (:func:`refresh_frame_caches`).  For an
edit not cached they set the cache input to minus the controls fed by nodes (:func:`linked_flags`), which folds
those controls' neutral tests away (:func:`_unfed`).

**Drawn texels.** Where no cache holds the edit, Cycles reads the table at one texel pair per control and shading
evaluation instead of four: the control's upper level with probability its level fraction, slice s + 1 with
probability the slice fraction (:func:`_chances`, numbers drawn from a White Noise Texture of the shading point's
position, which each sample of a pixel moves), so the samples of a pixel average to the interpolated table's answer,
the draws' spread adding to the render's own noise (2 lookups per control where interpolation reads 8).  The caches
interpolate (their answers are exact: a cache is what most edits render from); EEVEE interpolates always.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np

from . import curves, wiring
from .core import edit_table, skin_edits

#: Custom property on the edit images and the group: the SHA-256 of the edit table they were made from.
EDIT_TABLE_PROP = wiring.EDIT_TABLE_PROP
IMAGE_PREFIX = "Spectral Skin SSS Edits"
#: Constant edits the edit group holds precombined at once (module docstring, "Edit caches").
CACHE_SLOTS = edit_table.CACHE_SLOTS
#: The group input naming the cache that holds the node's edit (0: none); set by :func:`cache_edit`.
CACHE_INPUT = "Edit Cache"
#: The group input weighing the edit per shading point (a painted mask), as a bake's masks weigh it.
MASK_INPUT = "Edit Mask"
#: The cache of an edit painted by a linked Edit Mask: the value of the Edit Cache input naming it.
MASK_SLOT = 4
#: The height of one level's block in the control images' UV (exporters.edit_table.BLOCK_LEVELS: they stack
#: exporters.edit_table.STACKED blocks).
LEVEL_V = 1.0 / edit_table.STACKED
#: Points of the mask cache along its edit's line (exporters.edit_table.MaskLine).
MASK_POINTS = edit_table.MASK_POINTS
#: Caches of constant edits held in the mask cache's images while it holds no line (:func:`_line_in_use`): cache
#: ``SPARE_SLOTS[a]`` is the images' atlas a, read as a constant edit's cache is (the same memory: three constant
#: edits more where no edit needs the mask cache).
SPARE_SLOTS = tuple(range(MASK_SLOT + 1, MASK_SLOT + 1 + MASK_POINTS))
#: The caches of constant edits with images of their own, in the order they are filled: 1 to 3, then numbered after
#: the spare caches (the numbers of the mask cache and the spares stay those a group of an earlier add-on uses).
CONSTANT_SLOTS = (*range(1, MASK_SLOT),
                  *range(SPARE_SLOTS[-1] + 1, SPARE_SLOTS[-1] + 1 + CACHE_SLOTS - (MASK_SLOT - 1)))
#: The Float Curve of the mask cache: the mask's position on its line (exporters.edit_table.MaskLine.position).
MASK_CURVE = "Mask Cache Position"
#: The group's inputs, in order: (name, default, soft minimum, soft maximum, tooltip).
INPUTS = tuple(
    (name.title(), skin_edits.NEUTRAL[j], *skin_edits.CONTROL_RANGES[name], tip)
    for j, (name, tip) in enumerate((
        ("melanin", "Multiplies the epidermis's melanin fraction (1 = as painted): tan above 1, lighter below"),
        ("blood", "Multiplies the dermis's blood fraction (1 = as painted): flush above 1, pallor below"),
        ("oxygenation", "Shifts the blood's oxygen saturation (0 = as painted): below 0 cold, bluish skin"))))
#: The names of the control inputs (:data:`INPUTS`), in order.
CONTROL_NAMES = tuple(spec[0] for spec in INPUTS)


def table_for_model(model_path: str, texel_sha256: str) -> edit_table.EditTable | None:
    """The edit table beside ``model_path`` made from that model and the texel table of SHA-256 ``texel_sha256``, or
    None (the group is then built without the edit inputs)."""
    from .live import file_key, file_sha256

    path = edit_table.default_path(model_path)
    key = file_key(path)
    if key is None:
        return None
    if key not in _TABLES:  # loaded once per file version for this session
        try:
            table = edit_table.load(path)
        except edit_table.EditTableError:
            return None
        _TABLES.clear()
        _TABLES[key] = table
    table = _TABLES[key]
    if table.meta.get("model_sha256") != file_sha256(model_path) or \
            table.meta.get("texel_table_sha256") != texel_sha256:
        return None
    return table


def has_images(table: edit_table.EditTable) -> bool:
    """Whether the file holds every image of the edit table ``table``."""
    for j in range(len(skin_edits.CONTROLS)):
        for kind in edit_table.KINDS:
            if not _image_of(bpy.data.images.get(f"{IMAGE_PREFIX} {edit_table.image_name(j, kind)}"), table):
                return False
    return True


#: Custom property on the edit images: the layout they were made in (exporters.edit_table.IMAGE_LAYOUT).
IMAGE_LAYOUT_PROP = "spectral_skin_sss_edit_layout"


def _image_of(image: bpy.types.Image | None, table: edit_table.EditTable) -> bool:
    """Whether ``image`` was made from ``table`` in today's layout (an image of an older add-on is made again)."""
    return image is not None and image.get(EDIT_TABLE_PROP) == table.sha256 \
        and image.get(IMAGE_LAYOUT_PROP) == edit_table.IMAGE_LAYOUT


_TABLES: dict[tuple, edit_table.EditTable] = {}


def ensure_images(table: edit_table.EditTable, atlases: Callable[[], dict[str, np.ndarray]] | None = None
                  ) -> dict[str, bpy.types.Image]:
    """The edit table's images (per control, its colour shift and its radius correction, the levels' atlases
    stacked), packed, one set per file (reused when images of this table exist; ``atlases``: gives the table's
    atlases, made elsewhere meanwhile; default: made here)."""
    make = atlases if atlases is not None else table.atlases
    made: dict[str, np.ndarray] = {}
    images = {}

    def table_atlas(name: str) -> np.ndarray:  # the table's atlases, made once and only if an image is missing
        if not made:
            made.update(make())
        return made[name]

    def ensure(name: str, pixels: Callable[[], np.ndarray]) -> None:
        full = f"{IMAGE_PREFIX} {name}"
        image = bpy.data.images.get(full)
        if not _image_of(image, table):
            image = wiring.packed_table_image(full, pixels(), EDIT_TABLE_PROP, table.sha256)
            image[IMAGE_LAYOUT_PROP] = edit_table.IMAGE_LAYOUT
        if image.get(IMAGE_KEY_PROP) != name:
            image[IMAGE_KEY_PROP] = name
        images[name] = image

    for j in range(len(skin_edits.CONTROLS)):
        for kind in edit_table.KINDS:
            name = edit_table.image_name(j, kind)
            ensure(name, lambda name=name: table_atlas(name))
    for slot in (*CONSTANT_SLOTS, MASK_SLOT):
        for kind in edit_table.KINDS:  # empty until an edit is cached
            ensure(cache_image_name(slot, kind), lambda: np.zeros((1, 1, 4), np.float32))
    return images


#: Custom property on each edit image: its name within the edit group (:func:`exporters.edit_table.image_name`,
#: :func:`cache_image_name`), whatever name Blender gave the image.
IMAGE_KEY_PROP = "spectral_skin_sss_edit_image"


def edit_property(name: str) -> dict:
    """Keyword arguments of a FloatProperty for the control ``name`` (Melanin, Blood, Oxygenation): its neutral
    default, soft range and tooltip (:data:`INPUTS`), for the operator's and the panel's edit options."""
    _, default, lo, hi, tip = next(spec for spec in INPUTS if spec[0] == name)
    return {"name": name, "default": default, "soft_min": lo, "soft_max": hi, "description": tip}


def set_edit(node: bpy.types.Node, edit: tuple[float, float, float] | None, cache: bool = True) -> None:
    """Set the live group node's Melanin, Blood and Oxygenation to ``edit`` (None, or a node without the inputs:
    nothing; inputs fed by a node are left as they are) and cache it (:func:`cache_edit`; ``cache`` False: leave the
    node's cache input at 0, the edit read from the table, as a node renders whose cache is not current)."""
    if edit is None or "Melanin" not in node.inputs:
        return
    for name, value in zip(CONTROL_NAMES, edit, strict=True):
        if not node.inputs[name].is_linked:
            node.inputs[name].default_value = float(value)
    if cache:
        cache_edit(node)
    elif CACHE_INPUT in node.inputs:
        _point(node, 0)


def input_value(node: bpy.types.Node, name: str) -> float | None:
    """The value the live group node's input ``name`` takes at every shading point (:func:`socket_value`), or None
    where it may vary."""
    return socket_value(node.inputs[name])


def socket_value(socket: bpy.types.NodeSocket) -> float | None:
    """The value the float input ``socket`` takes at every shading point: the one value of its
    :func:`value_sockets`; None where a node feeds it (it may vary) or the group nodes give it different values.
    Cycles folds a Value node and a group node's unlinked input into the shader as it does an unlinked input, so a
    control fed so is a constant edit: its cache's test folds the same way."""
    return _one_value(value_sockets(socket))


def _one_value(sockets: list[bpy.types.NodeSocket] | None) -> float | None:
    """The float value every one of ``sockets`` holds, or None (none given, not floats, or values apart)."""
    values = [s.default_value for s in sockets or ()]
    if not values or not all(isinstance(v, float) for v in values) or len(set(values)) != 1:
        return None
    return values[0]


def value_sockets(socket: bpy.types.NodeSocket, depth: int = 1) -> list[bpy.types.NodeSocket] | None:
    """The sockets whose own values (and keyframes) reach the input ``socket``: itself where nothing reaches it
    (unlinked, or a muted link: wiring.feeding_socket), a Value node's output where one feeds it (through Reroutes
    and muted nodes), and where the Group Input of the node group holding ``socket`` feeds it (an artist's skin
    shader group exposing a control), those of the matching input of every group node using the group, each read so
    in turn; None where another node feeds it, or no group node uses the group."""
    source = wiring.feeding_socket(socket) if socket.is_linked else None
    if source is None:
        return [socket]
    if source.node.bl_idname == "ShaderNodeValue":
        return [source]
    if source.node.bl_idname != "NodeGroupInput" or depth > wiring.MAX_GROUP_DEPTH:
        return None
    found = []
    for given in wiring.group_node_inputs(source):
        sockets = value_sockets(given, depth + 1)
        if sockets is None:
            return None
        found += sockets
    return found or None


def constant_edit(node: bpy.types.Node) -> tuple[float, float, float] | None:
    """The live group node's (Melanin, Blood, Oxygenation) where each is a value (:func:`input_value`: its own, or a
    Value node's), else None (a control fed by another node)."""
    values = tuple(input_value(node, name) for name in CONTROL_NAMES)
    return None if None in values else values


def cache_key(node: bpy.types.Node) -> tuple[float, ...] | None:
    """The values a cache holding the live group node's edit tests (module docstring, "Edit caches"): (Melanin,
    Blood, Oxygenation, Edit Mask) for a constant edit that is not neutral (each a value: :func:`input_value`),
    (Melanin, Blood, Oxygenation) for one painted by an Edit Mask fed by a node that the mask cache can hold
    (exporters.edit_table.mask_line); None for any other (a control fed by a node, a neutral edit)."""
    edit = constant_edit(node)
    if edit is None:
        return None
    weight = input_value(node, MASK_INPUT) if MASK_INPUT in node.inputs else 1.0
    if weight is None:
        return edit if edit_table.mask_line(edit) is not None else None
    effective = edit_table.masked_edits(edit, [weight])[0]
    if not (np.all(np.isfinite(effective)) and np.isfinite(weight)) or skin_edits.neutral_rows(effective[None])[0]:
        return None
    return (*edit, weight)


def _slots(key: tuple[float, ...]) -> tuple[int, ...]:
    """The caches that can hold an edit of cache key ``key`` (:func:`cache_key`): the mask cache for an edit painted
    by a linked Edit Mask, else the constant edits' caches and the spare ones (:data:`SPARE_SLOTS`)."""
    return (MASK_SLOT,) if len(key) == len(CONTROL_NAMES) else (*CONSTANT_SLOTS, *SPARE_SLOTS)


def cache_edit(node: bpy.types.Node) -> int:
    """Hold the live group node's edit precombined in one of its edit group's caches (module docstring, "Edit
    caches") and point the node's cache input at it; returns that cache (one of :data:`CONSTANT_SLOTS` or
    :data:`SPARE_SLOTS` for a constant edit, :data:`MASK_SLOT` for one painted by a linked Edit Mask), or 0 where
    the edit is not cached (:func:`cache_key` None), the group has no caches, the material or group is linked from a
    library (read-only) or the group misses one of its images.  A cache of the same values is reused; else a free one
    (no other node's edit in it: the twelve caches first, then the spare ones while the mask cache holds no line in
    use), else the one filled longest ago (the nodes that used it then render through the table, as before)."""
    if node is None or CACHE_INPUT not in node.inputs or node.node_tree is None or not node.id_data.is_editable:
        return 0
    group = _edit_group(node.node_tree)
    key = cache_key(node)
    slot = 0
    if group is not None and key is not None:
        images = _group_images(node.node_tree)
        slot = _slot_for(group, images, key, node) if images is not None else 0
    _point(node, slot if slot else _uncached(node))
    return slot


#: Custom property on the edit group: its caches, the one filled last at the end.
_CACHE_ORDER_PROP = "spectral_skin_sss_cache_order"


def _edit_group(live_group: bpy.types.NodeTree) -> bpy.types.NodeTree | None:
    """The group holding the edit caches' nodes inside a live group (its Compare nodes, the mask cache's curve: the
    edit group's nested :data:`CACHES_GROUP_NAME`, or the edit group itself as an older add-on built it), or None."""
    trees = _cache_trees(live_group)
    return trees[1] if trees is not None else None


def _cache_trees(live_group: bpy.types.NodeTree) -> tuple[bpy.types.NodeTree, bpy.types.NodeTree] | None:
    """(the edit group, the group holding its caches' nodes: :func:`_edit_group`) inside a live group, or None."""
    for tree in _nested(live_group):
        if not tree.get(EDIT_TABLE_PROP):
            continue
        for inner in (*_nested(tree), tree):
            if _cache_node_name(MASK_SLOT, CONTROL_NAMES[0]) in inner.nodes:
                return tree, inner
    return None


def _nested(tree: bpy.types.NodeTree) -> list[bpy.types.NodeTree]:
    """The node groups the group nodes of ``tree`` use."""
    return [n.node_tree for n in tree.nodes if n.bl_idname == "ShaderNodeGroup" and n.node_tree is not None]


def _cached_values(group: bpy.types.NodeTree, slot: int) -> tuple[float, ...]:
    """The values cache ``slot`` of the edit group holds (:func:`cache_key`; NaN: none)."""
    nodes = _slot_tree(group, slot).nodes
    return tuple(float(nodes[_cache_node_name(slot, name)].inputs[1].default_value) for name in _cache_inputs(slot))


def _slot_trees(group: bpy.types.NodeTree) -> tuple[bpy.types.NodeTree, ...]:
    """The trees holding caches' nodes: the caches group ``group`` (:func:`_edit_group`) and the one nested in it
    (:data:`MORE_CACHES_GROUP_NAME`; a group of an earlier add-on has none)."""
    return (group, *_nested(group))


def _slot_tree(group: bpy.types.NodeTree, slot: int) -> bpy.types.NodeTree | None:
    """The tree of :func:`_slot_trees` holding cache ``slot``'s nodes; None where the group has no such cache (one of
    an earlier add-on)."""
    return next((t for t in _slot_trees(group) if _cache_node_name(slot, CONTROL_NAMES[0]) in t.nodes), None)


def empty_mask_cache(live_group: bpy.types.NodeTree) -> None:
    """Make the live group's mask cache hold no edit (its line's end at neutral, as in a new group), so that what it
    served reads the table: how the tests and the benches compare the two paths."""
    _set_cached_values(_edit_group(live_group), MASK_SLOT, skin_edits.NEUTRAL)


def _point(node: bpy.types.Node, slot: int) -> None:
    socket = node.inputs[CACHE_INPUT]
    if socket.default_value != slot:
        socket.default_value = float(slot)


#: The flags of every control fed by a node (:func:`linked_flags`).
_ALL_LINKED = 2 ** len(CONTROL_NAMES) - 1


def linked_flags(node: bpy.types.Node) -> int:
    """Sum of 2^j over the controls j (Melanin, Blood, Oxygenation) of the live group node fed by a node (other than
    a Value node: :func:`input_value`); 0 where its group predates the flags (its cache input takes no negative
    value)."""
    socket = node.node_tree.interface.items_tree.get(CACHE_INPUT) if node.node_tree is not None else None
    if socket is None or socket.min_value > -_ALL_LINKED:
        return 0
    return sum(2 ** j for j, name in enumerate(CONTROL_NAMES) if input_value(node, name) is None)


def _uncached(node: bpy.types.Node) -> int:
    """The cache input of a node whose edit is not cached: minus its :func:`linked_flags` (module docstring)."""
    return -linked_flags(node)


def _group_images(live_group: bpy.types.NodeTree) -> dict[str, bpy.types.Image] | None:
    """The images of the live group's edit group and its caches groups by their key (:data:`IMAGE_KEY_PROP`), or None
    where one is missing or one it would write (a cache's) or a group is not editable (linked from a library): the
    edit is then not cached."""
    found = _cache_trees(live_group)
    trees = (found[0], *_slot_trees(found[1])) if found is not None else ()
    if not trees or not all(t.is_editable for t in trees):
        return None
    images = {}
    for tree in trees:
        for n in tree.nodes:
            image = getattr(n, "image", None)
            if n.bl_idname == "ShaderNodeTexImage" and image is not None and image.get(IMAGE_KEY_PROP):
                images[image[IMAGE_KEY_PROP]] = image
    wanted = [edit_table.image_name(j, kind) for j in range(len(skin_edits.CONTROLS)) for kind in edit_table.KINDS]
    caches = [cache_image_name(slot, kind) for slot in (*CONSTANT_SLOTS, MASK_SLOT) if _has_slot(found[1], slot)
              for kind in edit_table.KINDS]
    if any(key not in images for key in wanted + caches) or not all(images[key].is_editable for key in caches):
        return None
    return images


def _slot_for(group: bpy.types.NodeTree, images: dict[str, bpy.types.Image], key: tuple[float, ...],
              node: bpy.types.Node) -> int:
    """The cache of ``group`` holding the edit of cache key ``key``, filled here if none does (:func:`cache_edit`).
    The spare caches (:data:`SPARE_SLOTS`) are free only while the mask cache holds no line in use
    (:func:`_line_in_use`): an edit painted by the Edit Mask or a keyframed line comes first.  Where every cache is
    in use and the edit lies on the mask cache's line (:func:`_line_serves`: a frame of the keyframed edit whose line
    it holds), the mask cache: the frames of an animation then give up no other material's cache."""
    slots = tuple(k for k in _slots(key) if _has_slot(group, k))  # a group of an earlier add-on has fewer
    if any(k in SPARE_SLOTS for k in slots) and _line_in_use(group):
        slots = tuple(k for k in slots if k not in SPARE_SLOTS)
    held = {k: _cached_values(group, k) for k in slots}
    for k, values in held.items():
        if values == key:
            return k
    others = [n for n in _group_nodes(group) if n != node]
    used = {int(n.inputs[CACHE_INPUT].default_value) for n in others
            if cache_key(n) == held.get(int(n.inputs[CACHE_INPUT].default_value))}
    order = list(group.get(_CACHE_ORDER_PROP, []))
    free = [k for k in slots if k not in used]
    if not free and len(key) > len(CONTROL_NAMES) and _line_serves(group, key):
        return MASK_SLOT  # every cache in use, and the mask cache's line holds the edit: no other edit given up
    slot = free[0] if free else next((k for k in order if k in slots), slots[0])
    _fill(group, images, slot, key)
    group[_CACHE_ORDER_PROP] = [k for k in order if k != slot] + [slot]
    _unpoint(others, (slot,))  # nodes that pointed at the cache before: it holds other values now
    return slot


def _group_nodes(group: bpy.types.NodeTree) -> list[bpy.types.Node]:
    """The live nodes of every material whose live group holds the edit group ``group``."""
    return [n for n in map(live_node, bpy.data.materials)
            if n is not None and n.node_tree is not None and _edit_group(n.node_tree) == group]


def _unpoint(nodes, slots) -> None:
    """Point those of ``nodes`` whose cache input names one of ``slots`` at no cache (they render through the
    table until their edit is cached again)."""
    for n in nodes:
        if int(n.inputs[CACHE_INPUT].default_value) in slots and n.id_data.is_editable:
            _point(n, 0)


def _line_serves(group: bpy.types.NodeTree, key: tuple[float, ...]) -> bool:
    """Whether the mask cache's line holds the constant edit of cache key ``key``: its controls lie on the line
    between neutral and the line's end (:func:`_line_through`, within a quarter of the group's tolerance), where the
    group reads the mask cache at the mask times their place on it (:func:`_on_line`)."""
    held = _cached_values(group, MASK_SLOT)
    return _line_through(np.array([held, key[:len(CONTROL_NAMES)]], np.float64)) == held


def _has_slot(group: bpy.types.NodeTree, slot: int) -> bool:
    """Whether the edit group reads cache ``slot`` (a group of an earlier add-on has fewer caches)."""
    return _slot_tree(group, slot) is not None


def _line_in_use(group: bpy.types.NodeTree) -> bool:
    """Whether the mask cache's line is in use: it holds one (not neutral) that a node of the group renders from,
    painted by its Edit Mask, a constant edit on it (:func:`_line_serves`) or keyframed along it
    (:func:`animated_line` over the context's scene)."""
    held = _cached_values(group, MASK_SLOT)
    if held == tuple(float(v) for v in skin_edits.NEUTRAL):
        return False
    scene = getattr(bpy.context, "scene", None)
    for n in _group_nodes(group):
        if int(n.inputs[CACHE_INPUT].default_value) == MASK_SLOT and cache_is_current(n):
            return True
        if scene is not None and animated_line(n, scene) == held:
            return True
    return False


def _fill(group: bpy.types.NodeTree, images: dict[str, bpy.types.Image], slot: int, key: tuple[float, ...]) -> None:
    """Write cache ``slot`` for the edit of cache key ``key``: its images (exporters.edit_table.combined_atlas of the
    control images, ``images`` from :func:`_group_images`, for a constant edit; line_atlas for the mask
    cache, and its curve), then the values its Compare nodes test the inputs against.  The mask cache and the spare
    caches share images: the mask cache's line gives up the spare caches, a spare cache empties the line."""
    line = edit_table.mask_line(key) if slot == MASK_SLOT else None
    if slot == MASK_SLOT and _has_slot(group, SPARE_SLOTS[0]):
        for spare in SPARE_SLOTS:
            _set_cached_values(group, spare, (_EMPTY_CACHE,) * len(_cache_inputs(spare)))
        _unpoint(_group_nodes(group), SPARE_SLOTS)
    elif slot in SPARE_SLOTS:
        _set_cached_values(group, MASK_SLOT, skin_edits.NEUTRAL)
    for kind in edit_table.KINDS:
        stacked = [_pixels(images[edit_table.image_name(j, kind)]) for j in range(len(skin_edits.CONTROLS))]
        pixels = (edit_table.line_atlas(stacked, line) if line is not None
                  else edit_table.combined_atlas(stacked, edit_table.masked_edits(key[:3], [key[3]])[0]))
        if slot in SPARE_SLOTS:
            pixels = _with_atlas(images[cache_image_name(MASK_SLOT, kind)], SPARE_SLOTS.index(slot), pixels)
        wiring.rewrite_table_image(images[cache_image_name(_image_slot(slot), kind)], pixels)
    if line is not None:
        xs = np.linspace(0.0, 1.0, curves.SMOOTH_POINTS)
        curves.set_float_curve(group.nodes[MASK_CURVE], xs, line.position(xs))
    _set_cached_values(group, slot, key)


def _image_slot(slot: int) -> int:
    """The cache whose images hold cache ``slot``: the mask cache's for a spare one (:data:`SPARE_SLOTS`)."""
    return MASK_SLOT if slot in SPARE_SLOTS else slot


def _set_cached_values(group: bpy.types.NodeTree, slot: int, values) -> None:
    """Make cache ``slot``'s Compare (Math) nodes test the inputs against ``values`` (:func:`_cached_values`)."""
    nodes = _slot_tree(group, slot).nodes
    for name, value in zip(_cache_inputs(slot), values, strict=True):
        nodes[_cache_node_name(slot, name)].inputs[1].default_value = value


def _with_atlas(image: bpy.types.Image, index: int, atlas: np.ndarray) -> np.ndarray:
    """The mask cache's image's pixels (:data:`MASK_POINTS` atlases stacked bottom to top; zeros where it holds
    fewer rows, as a new group's) with atlas ``index`` replaced by ``atlas`` (height, width, 4)."""
    height, width = atlas.shape[:2]
    current = _pixels(image)
    if current.shape != (MASK_POINTS * height, width, 4):
        current = np.zeros((MASK_POINTS * height, width, 4), np.float32)
    current[index * height:(index + 1) * height] = atlas
    return current


def cache_is_current(node: bpy.types.Node) -> bool:
    """Whether the node's cache input is what :func:`cache_edit` would set: its edit's cache (for a constant edit,
    the mask cache too where its line holds the edit: :func:`_slot_for`), or 0 where the edit is not cached
    (:func:`cache_key` None) or its group has no caches."""
    if CACHE_INPUT not in node.inputs or node.node_tree is None:
        return True
    slot = int(node.inputs[CACHE_INPUT].default_value)
    group = _edit_group(node.node_tree)
    key = cache_key(node)
    if group is None or key is None:
        return slot == _uncached(node)
    if slot == MASK_SLOT and len(key) > len(CONTROL_NAMES):
        return _line_serves(group, key)
    return slot in _slots(key) and _cached_values(group, slot) == key


_refreshing = False


@bpy.app.handlers.persistent
def refresh_caches(scene=None, depsgraph=None) -> None:
    """depsgraph_update_post handler: cache the edit of each changed material's live node whose cache input is not
    current (an edit set in the panel or on the node), so that a constant edit renders from a cache whoever set
    it.  Rendering never depends on it: a node whose cache is not current renders through the table."""
    if _refreshing or depsgraph is None:
        return
    cache_edits({u.id.original for u in depsgraph.updates if isinstance(u.id, bpy.types.Material)})


@bpy.app.handlers.persistent
def refresh_frame_caches(scene=None, depsgraph=None) -> None:
    """frame_change_post handler: cache the edit of every live node whose cache input is not current once the frame's
    keyframed values are in (Blender evaluates the frame again when a post handler changed data, so the frame renders
    from the cache).  Skipped while a render job runs in Blender's interface, whose frames are evaluated outside the
    main thread: those frames read the table."""
    if not _refreshing and not bpy.app.is_job_running("RENDER"):
        cache_edits(bpy.data.materials)


def cache_edits(materials, scene: bpy.types.Scene | None = None) -> None:
    """Cache the edit of each of ``materials``' live nodes whose cache input is not current, and hold the line of each
    keyframed edit in the mask cache (:func:`hold_line`, over ``scene``'s frames; default: the context's scene): the
    handlers' work; the writes it makes do not call it again."""
    global _refreshing
    _refreshing = True
    scene = scene or getattr(bpy.context, "scene", None)
    try:
        for material in materials:
            node = live_node(material)
            if node is None:
                continue
            if not cache_is_current(node):
                cache_edit(node)
            if scene is not None:
                hold_line(node, scene)
    finally:
        _refreshing = False


def _keyframes(node: bpy.types.Node) -> list[list[bpy.types.FCurve]] | None:
    """Per control, the F-curves keyframing the value reaching the node's input (:func:`value_sockets`: its own, a
    Value node's, the artist's group node's; none: a constant), where a control or the Edit Mask is keyframed (a
    preset's amount animated on the mask), and none of them is fed by a node, driven, or given by several group
    nodes that disagree or are keyframed; else None."""
    found = []
    for name in (*CONTROL_NAMES, MASK_INPUT):
        socket = node.inputs.get(name)
        sockets = value_sockets(socket) if socket is not None else None
        if sockets is None:
            return None
        curves_ = [c for s in sockets for c in wiring.animation(s)]
        if any(c.driver is not None for c in curves_) or (len(sockets) > 1 and curves_) \
                or (not curves_ and _one_value(sockets) is None):
            return None
        found.append(curves_)
    return found[:-1] if any(found) else None


#: The line of each keyframed node last found (:func:`animated_line`), by the node's address: (what it was found
#: from, the line's end or None).
_LINES: dict[int, tuple[tuple, tuple[float, float, float] | None]] = {}


def animated_line(node: bpy.types.Node, scene: bpy.types.Scene) -> tuple[float, float, float] | None:
    """The edit E at the end of the line from neutral along which the node's keyframed controls move over the scene's
    frames (every frame's controls V = n + t (E - n), 0 <= t <= 1, within :data:`LINE_TOLERANCE` / 4; E the frame's
    edit farthest from neutral), where the mask cache can hold it (exporters.edit_table.mask_line); else None: not
    keyframed (:func:`_keyframes`), or moving otherwise.  A blush keyframed on Blood alone, a preset faded in on all
    its controls with the same keys, or a preset whose Edit Mask is keyframed (its controls at the line's end) moves
    along one line."""
    keyed = _keyframes(node)
    if keyed is None:
        return None
    state = (scene.frame_start, scene.frame_end, scene.frame_step,
             tuple(tuple(_curve_key(c) for c in cs) if cs else input_value(node, name)
                   for name, cs in zip(CONTROL_NAMES, keyed, strict=True)))
    found = _LINES.get(node.as_pointer())
    if found is not None and found[0] == state:
        return found[1]
    frames = np.arange(scene.frame_start, scene.frame_end + 1, max(1, scene.frame_step), dtype=np.float64)
    rows = np.empty((len(frames), len(CONTROL_NAMES)))
    for j, (name, cs) in enumerate(zip(CONTROL_NAMES, keyed, strict=True)):
        rows[:, j] = [cs[0].evaluate(f) for f in frames] if cs else input_value(node, name)
    rows = rows.astype(np.float32).astype(np.float64)  # as the node's inputs hold them
    line = _line_through(rows)
    _LINES[node.as_pointer()] = (state, line)
    return line


def _curve_key(curve: bpy.types.FCurve) -> tuple:
    """What an F-curve's values depend on: its extrapolation, its modifiers (their types and whether they are on; a
    modifier's settings changed alone are seen at the next change of these) and its keyframes."""
    return (curve.extrapolation, tuple((m.type, m.mute, m.active) for m in curve.modifiers),
            tuple((tuple(k.co), tuple(k.handle_left), tuple(k.handle_right), k.interpolation, k.easing)
                  for k in curve.keyframe_points))


def _line_through(rows: np.ndarray) -> tuple[float, float, float] | None:
    """The end E of the line from neutral through every edit of ``rows`` (N, 3) (:func:`animated_line`), or None."""
    v = rows - np.asarray(skin_edits.NEUTRAL, np.float64)
    far = int(np.argmax(np.sum((v / np.ptp(np.array(list(skin_edits.CONTROL_RANGES.values())), axis=1)) ** 2,
                               axis=1)))
    d = v[far]
    if not np.any(d):
        return None
    t = v @ d / (d @ d)
    if np.any(t < -1e-6) or np.any(t > 1.0 + 1e-6) or np.abs(v - t[:, None] * d).max() > LINE_TOLERANCE / 4:
        return None
    edit = tuple(float(x) for x in rows[far])
    return edit if edit_table.mask_line(edit) is not None else None


def hold_line(node: bpy.types.Node, scene: bpy.types.Scene) -> bool:
    """Hold the line of the node's keyframed edit (:func:`animated_line`) in its edit group's mask cache, unless that
    holds the edit of another node rendering from it (painted by its Edit Mask, or a constant edit on the line) or
    another keyframed node's line: the frames Blender's interface renders (outside the main thread, where the
    handlers cache no frame's edit) then read the mask cache instead of the table (module docstring, "Edit caches").
    Constant edits held in the spare caches give them up (:func:`_fill`).  Returns whether the mask cache holds the
    line."""
    line = animated_line(node, scene) if node.node_tree is not None and node.id_data.is_editable else None
    group = _edit_group(node.node_tree) if line is not None else None
    if group is None:
        return False
    held = _cached_values(group, MASK_SLOT)
    if held == line:
        return True
    images = _group_images(node.node_tree)
    if images is None:
        return False
    for other in _group_nodes(group):
        if other == node:
            continue
        served = int(other.inputs[CACHE_INPUT].default_value) == MASK_SLOT and cache_is_current(other)
        if served or animated_line(other, scene) == held:
            return False
    _fill(group, images, MASK_SLOT, line)
    return True


#: The add-on's handlers: (list of bpy.app.handlers, function).
_HANDLERS = (("depsgraph_update_post", refresh_caches), ("frame_change_post", refresh_frame_caches))


def register_handlers() -> None:
    for name, function in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if function not in handlers:
            handlers.append(function)


def unregister_handlers() -> None:
    for name, function in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        while function in handlers:
            handlers.remove(function)


def _pixels(image: bpy.types.Image) -> np.ndarray:
    """(height, width, 4) float32 pixels of an image."""
    width, height = image.size
    out = np.empty(width * height * 4, np.float32)
    image.pixels.foreach_get(out)
    return out.reshape(height, width, 4)


def add_inputs(group: bpy.types.NodeTree) -> None:
    """The Melanin, Blood and Oxygenation inputs of the group interface (neutral defaults)."""
    for name, default, lo, hi, tip in INPUTS:
        socket = group.interface.new_socket(name, in_out="INPUT", socket_type="NodeSocketFloat")
        socket.default_value, socket.min_value, socket.max_value = default, lo, hi
        socket.description = tip
    socket = group.interface.new_socket(MASK_INPUT, in_out="INPUT", socket_type="NodeSocketFloat")
    socket.subtype = "FACTOR"
    socket.default_value, socket.min_value, socket.max_value = 1.0, 0.0, 1.0
    socket.description = ("Where the edit applies (link a painted mask, 0 to 1): each control becomes neutral + mask x "
                          "(its value - neutral), as a bake's masks weigh an edit")
    socket = group.interface.new_socket(CACHE_INPUT, in_out="INPUT", socket_type="NodeSocketFloat")
    socket.default_value, socket.min_value, socket.max_value = 0.0, -float(_ALL_LINKED), float(CONSTANT_SLOTS[-1])
    socket.hide_value = True
    socket.description = ("Set by the add-on: which of the edit group's caches holds this node's edit precombined "
                          "(0: none; a cache of other values is never used), or minus the controls fed by nodes")


@dataclass
class EditBranch:
    """What the edit nodes give the group: the edited ``colour`` and the ``radius_factor`` exp(D_radius) (a vector:
    one factor per channel)."""

    colour: bpy.types.NodeSocket
    radius_factor: bpy.types.NodeSocket


EDIT_GROUP_NAME = "Spectral Skin SSS Edits"
#: The edit group of the live group's EEVEE output (:func:`ensure_edit_group`).
EEVEE_EDIT_GROUP_NAME = "Spectral Skin SSS Edits EEVEE"


def ensure_edit_group(table: edit_table.EditTable, images: dict[str, bpy.types.Image],
                      eevee: bool = False) -> bpy.types.NodeTree:
    """The edit nodes as their own group (inputs Color, Melanin, Blood, Oxygenation; outputs Color, Radius Factor),
    one per edit table and file: Blender adds nodes to a tree in time growing with its size, so the edit nodes in a
    group of their own keep the live group's build (the operator) fast.  ``eevee``: the EEVEE output's group,
    :data:`EEVEE_EDIT_GROUP_NAME` (:func:`add_edit_branch`)."""
    from . import live

    name = EEVEE_EDIT_GROUP_NAME if eevee else EDIT_GROUP_NAME
    for group in bpy.data.node_groups:
        if group.name.startswith(name) and group.get(EDIT_TABLE_PROP) == table.sha256 \
                and group.get("spectral_skin_sss_version") == live.LIVE_VERSION \
                and group.get("spectral_skin_sss_eevee", False) == eevee:
            return group
    group = bpy.data.node_groups.new(name, "ShaderNodeTree")
    group["spectral_skin_sss_eevee"] = eevee
    group[EDIT_TABLE_PROP] = table.sha256
    group["spectral_skin_sss_version"] = live.LIVE_VERSION
    group.interface.new_socket("Color", in_out="INPUT", socket_type="NodeSocketColor")
    add_inputs(group)
    group.interface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")
    group.interface.new_socket("Radius Factor", in_out="OUTPUT", socket_type="NodeSocketVector")
    gin = group.nodes.new("NodeGroupInput")
    gout = group.nodes.new("NodeGroupOutput")
    gin.location, gout.location = (-1900.0, 0.0), (4400.0, 0.0)
    builder = live._Builder(group)
    branch = add_edit_branch(builder, gin, table, images, eevee)
    builder.place()
    group.links.new(branch.colour, gout.inputs["Color"])
    group.links.new(branch.radius_factor, gout.inputs["Radius Factor"])
    return group


def edit_node(b, gin, table: edit_table.EditTable, images: dict[str, bpy.types.Image],
              eevee: bool = False) -> EditBranch:
    """A node of the edit group (:func:`ensure_edit_group`; ``eevee``: the EEVEE output's) in the live group, fed by
    its Color and edit inputs."""
    node = b.node("ShaderNodeGroup", 1, node_tree=ensure_edit_group(table, images, eevee))
    for name in ("Color", *CONTROL_NAMES, MASK_INPUT, CACHE_INPUT):
        b.link(gin.outputs[name], node.inputs[name])
    return EditBranch(colour=node.outputs["Color"], radius_factor=node.outputs["Radius Factor"])


def _steps(b, gin, j: int, stage: int):
    """Control ``j``'s coordinate weighed by the Edit Mask, in level steps from neutral (exporters.edit_table.LEVELS:
    -4 .. 4 for eight levels): log2 of the clamped multiplier, or the clamped shift, over the levels' spacing.  The
    mask weighs the control in a Mix node of clamped factor from the neutral value to the input's: Cycles folds it to
    the input at mask 1 (unlinked: the group without a mask).  The clamp is a Map Range's (one node where Maximum
    and Minimum nodes each write two constants at every shading point); the multipliers' logarithm takes base
    2^spacing, which gives the steps in one node."""
    name = skin_edits.CONTROLS[j]
    lo, hi = skin_edits.CONTROL_RANGES[name]
    h = edit_table.SPACING[name]
    weighed = b.node("ShaderNodeMix", stage, data_type="FLOAT", clamp_factor=True)
    sockets = [s for s in weighed.inputs if s.enabled]
    b.link(gin.outputs[MASK_INPUT], sockets[0])
    b.link(skin_edits.NEUTRAL[j], sockets[1])
    b.link(gin.outputs[CONTROL_NAMES[j]], sockets[2])
    value = next(s for s in weighed.outputs if s.enabled)
    if name == "oxygenation":
        return _clamp(b, stage + 1, value, (lo, hi), (lo / h, hi / h))
    return b.math("LOGARITHM", stage + 2, _clamp(b, stage + 1, value, (lo, hi), (lo, hi)), 2.0 ** h)


def _clamp(b, stage: int, value, bounds: tuple[float, float], to: tuple[float, float]) -> bpy.types.NodeSocket:
    """A float Map Range (linear, clamped) of ``value`` from ``bounds`` to ``to``."""
    node = b.node("ShaderNodeMapRange", stage, data_type="FLOAT", clamp=True)
    b.link(value, node.inputs["Value"])
    for name, bound in zip(("From Min", "From Max", "To Min", "To Max"), (*bounds, *to), strict=True):
        b.link(float(bound), next(s for s in node.inputs if s.name == name and s.enabled))
    return next(s for s in node.outputs if s.enabled)


def add_edit_branch(b, gin, table: edit_table.EditTable, images: dict[str, bpy.types.Image],
                    eevee: bool = False) -> EditBranch:
    """The edit nodes (module docstring) on the group's Color input; ``b`` the group's builder (blender_addon.live).
    Every control image has one row of slice tiles (:func:`exporters.edit_table.EditTable.layout`) and its levels'
    atlases stacked in the blocks of :data:`exporters.edit_table.BLOCK_LEVELS`: at a coordinate of k level steps,
    w = k mod (STACKED + 1) (a Wrap node) puts the lower level at block floor(w) - 1 and the upper one at floor(w),
    neutral outside the image (read as 0 by the lookups' Clip extension), so the four texels a control reads (slices
    s, s + 1; the two levels) lie at fixed offsets from one UV, and the upper level's weight is w - floor(w).
    Cycles reads one texel pair its draws pick (:func:`_drawn`; module docstring, "Drawn texels") where no cache
    holds the edit.  ``eevee``: the nodes of the EEVEE output instead, the four texels interpolated and read through
    Environment Textures (blender_addon.live._Builder.environment, which EEVEE samples at full resolution), with no
    caches (they are for Cycles' cost) and the neutral levels made 0 explicitly (an Environment Texture has no Clip
    extension)."""
    layout = table.layout()
    width, height = layout.size
    tall = float(edit_table.STACKED * height)
    tile_u = layout.tile[0] / width
    from . import live

    colour = gin.outputs["Color"]
    base, x0 = live.grid_vector(b, colour, layout, (width, tall))[:2]
    s = b.math("FLOOR", 41, x0)  # up to n0 - 1 (x0 is clamped): the image's copy of the last slice follows
    frac = b.math("SUBTRACT", 43, x0, s)
    slice_uv = b.vec("MULTIPLY_ADD", 52, s, (tile_u, 0.0, 0.0), base)  # slice s, the images' first block
    shifts = {kind: None for kind in edit_table.KINDS}
    still = None  # 1 where every control is neutral, else 0
    flags = None if eevee else b.math("MAXIMUM", 55, b.math("MULTIPLY", 54, gin.outputs[CACHE_INPUT], -1.0), 0.0)
    chance = None if eevee else _chances(b, x0, base, tile_u)
    for j in range(len(skin_edits.CONTROLS)):
        unfed = 1.0 if eevee else _unfed(b, flags, j)
        neutral = b.math("COMPARE", 58, gin.outputs[CONTROL_NAMES[j]], skin_edits.NEUTRAL[j], 0.0)
        neutral = neutral if eevee else b.math("MULTIPLY", 59, neutral, unfed)
        still = neutral if still is None else b.math("MULTIPLY", 59, still, neutral)
        wrapped = b.math("WRAP", 47, _steps(b, gin, j, 43), edit_table.STACKED + 1.0, 0.0)
        place = _levels(b, wrapped, slice_uv) if eevee else _drawn(b, wrapped, chance.slice_uv, chance.levels[j])
        for kind in edit_table.KINDS:
            image = images[edit_table.image_name(j, kind)]
            value = _interpolated(b, image, place, frac, tile_u) if eevee \
                else _lookup(b, image, place, (0.0, -LEVEL_V), 57)
            shifts[kind] = (value if shifts[kind] is None else b.vec("ADD", 59, shifts[kind], value)) if eevee \
                else _gated_sum(b, neutral, shifts[kind], value)
    if not eevee:
        shifts = _caches_node(b, gin, table, images, {"Base": base, "Slice": s, "Fraction": frac, "Slice UV": slice_uv},
                              tile_u, shifts)
    active = b.math("SUBTRACT", 60, 1.0, still)
    bounds = table.shift_bounds()
    factor = {kind: _exp(b, shifts[kind], active, bounds[kind], 61) for kind in edit_table.KINDS}
    return EditBranch(colour=b.vec("MULTIPLY", 63, colour, factor["colour"]), radius_factor=factor["radius"])


#: The group holding the edit caches' nodes, nested in the edit group (:func:`_caches_node`).
CACHES_GROUP_NAME = "Spectral Skin SSS Edit Caches"
#: The group holding the constant caches past the first three (:data:`CONSTANT_SLOTS`), nested in the caches group.
MORE_CACHES_GROUP_NAME = "Spectral Skin SSS Edit Caches More"
#: The caches group's inputs besides the edit group's (name, socket type): the painted colour's place on the images.
_PLACE_INPUTS = (("Base", "NodeSocketVector"), ("Slice", "NodeSocketFloat"), ("Fraction", "NodeSocketFloat"),
                 ("Slice UV", "NodeSocketVector"))
#: The inputs the caches groups take from the edit group.
_EDIT_INPUTS = (*CONTROL_NAMES, MASK_INPUT, CACHE_INPUT)


def _caches_node(b, gin, table: edit_table.EditTable, images: dict[str, bpy.types.Image], place: dict, tile_u: float,
                 shifts: dict) -> dict:
    """``shifts`` (the table's), or the caches' where one holds the node's edit: a node of a new group
    :data:`CACHES_GROUP_NAME` (a constant edit's own cache before the mask cache's line: :func:`_mask_cached`, then
    :func:`_cached` for caches 1 to 3 and the spares, then the group :data:`MORE_CACHES_GROUP_NAME` nested in it for
    the other constant caches), fed by the edit group's inputs, the painted colour's place on the images (``place``,
    :data:`_PLACE_INPUTS`) and the table's shifts.  In groups of their own, at most about 150 nodes each, because
    Blender adds each node to a tree in time growing with its size: the edit group builds in about a third of the
    time it takes with every cache in it.  Cycles compiles nested groups inline, so the shader is the same."""
    first = tuple(k for k in CONSTANT_SLOTS if k < MASK_SLOT)
    more = _caches_group(MORE_CACHES_GROUP_NAME, table, images, tile_u, CONSTANT_SLOTS[len(first):], None)
    group = _caches_group(CACHES_GROUP_NAME, table, images, tile_u, (MASK_SLOT, *first, *SPARE_SLOTS), more)
    return _group_node(b, group, {name: gin.outputs[name] for name in _EDIT_INPUTS} | place, shifts)


def _group_node(b, group: bpy.types.NodeTree, sources: dict, shifts: dict) -> dict:
    """The shifts out of a node of the caches group ``group`` (:func:`_caches_group`) added by builder ``b``, its
    inputs fed by ``sources`` (input name -> socket: the edit group's inputs and the place's) and ``shifts``."""
    node = b.node("ShaderNodeGroup", 60, node_tree=group)
    for name in (*_EDIT_INPUTS, *(p for p, _ in _PLACE_INPUTS)):
        b.link(sources[name], node.inputs[name])
    for kind in edit_table.KINDS:
        b.link(shifts[kind], node.inputs[f"{kind.title()} Shift"])
    return {kind: node.outputs[f"{kind.title()} Shift"] for kind in edit_table.KINDS}


def _caches_group(name: str, table: edit_table.EditTable, images: dict[str, bpy.types.Image], tile_u: float,
                  slots: tuple[int, ...], more: bpy.types.NodeTree | None) -> bpy.types.NodeTree:
    """A group of caches (:func:`_caches_node`): inputs the edit group's, the place's and the table's shifts, outputs
    the shifts; in turn each of ``slots`` (:func:`_mask_cached` for :data:`MASK_SLOT`, else :func:`_cached`), then a
    node of ``more`` (a group of the same inputs) where given."""
    from . import live

    group = bpy.data.node_groups.new(name, "ShaderNodeTree")
    group[EDIT_TABLE_PROP] = table.sha256
    group["spectral_skin_sss_version"] = live.LIVE_VERSION
    for socket in _EDIT_INPUTS:
        group.interface.new_socket(socket, in_out="INPUT", socket_type="NodeSocketFloat")
    for socket, kind in _PLACE_INPUTS:
        group.interface.new_socket(socket, in_out="INPUT", socket_type=kind)
    for kind in edit_table.KINDS:
        group.interface.new_socket(f"{kind.title()} Shift", in_out="INPUT", socket_type="NodeSocketVector")
        group.interface.new_socket(f"{kind.title()} Shift", in_out="OUTPUT", socket_type="NodeSocketVector")
    inner_in = group.nodes.new("NodeGroupInput")
    inner_out = group.nodes.new("NodeGroupOutput")
    inner_in.location, inner_out.location = (-1900.0, 0.0), (2400.0, 0.0)
    inner = live._Builder(group)
    place = {socket: inner_in.outputs[socket] for socket, _ in _PLACE_INPUTS}
    out = {kind: inner_in.outputs[f"{kind.title()} Shift"] for kind in edit_table.KINDS}
    for slot in slots:
        if slot == MASK_SLOT:
            out = _mask_cached(inner, inner_in, images, place["Base"], place["Slice"], place["Fraction"], tile_u, out)
        else:
            out = _cached(inner, inner_in, slot, images, place["Slice UV"], place["Fraction"], tile_u, out)
    if more is not None:
        out = _group_node(inner, more, {socket: inner_in.outputs[socket] for socket in _EDIT_INPUTS} | place, out)
    inner.place()
    for kind in edit_table.KINDS:
        group.links.new(out[kind], inner_out.inputs[f"{kind.title()} Shift"])
    return group


@dataclass
class Chances:
    """Where a control reads the table in Cycles (:func:`_chances`): ``slice_uv`` the slice drawn (s or
    s + 1, s + 1 with probability the slice fraction), the images' first block; ``levels`` per control a number drawn
    uniformly in [0, 1), which draws its upper level with probability its fraction."""

    slice_uv: bpy.types.NodeSocket
    levels: tuple[bpy.types.NodeSocket, ...]


def _chances(b, x0, base, tile_u: float) -> Chances:
    """The draws of the table's texels in Cycles (module docstring, "Drawn texels"): four numbers uniform in
    [0, 1) from a White Noise Texture of the shading point's position, which every sample of a pixel moves (its
    place in the pixel, the random walk's exit), so a pixel's samples average the draws to the trilinear answer; one
    picks the slice (floor(x0 + u)), one each control's level.  The levels' are a 3D White Noise's Color, which
    Cycles hashes from the position and from (position, 1) and (position, 2); its Value is the Color's red, so the
    slice's is the Value of a 4D White Noise of (position, 3): four independent draws."""
    position = b.node("ShaderNodeNewGeometry", 39).outputs["Position"]
    noise = b.node("ShaderNodeTexWhiteNoise", 40, noise_dimensions="3D")
    b.link(position, noise.inputs["Vector"])
    split = b.node("ShaderNodeSeparateColor", 41)
    b.link(noise.outputs["Color"], split.inputs["Color"])
    other = b.node("ShaderNodeTexWhiteNoise", 40, noise_dimensions="4D")
    b.link(position, other.inputs["Vector"])
    other.inputs["W"].default_value = float(len(skin_edits.CONTROLS))
    drawn = b.math("FLOOR", 42, b.math("ADD", 41, x0, other.outputs["Value"]))
    return Chances(slice_uv=b.vec("MULTIPLY_ADD", 52, drawn, (tile_u, 0.0, 0.0), base),
                   levels=tuple(split.outputs[i] for i in range(len(skin_edits.CONTROLS))))


def _lookup(b, image: bpy.types.Image, uv, offset: tuple[float, float], stage: int,
            scale: tuple[float, float, float] | None = None, extension: str = "CLIP") -> bpy.types.NodeSocket:
    """One bilinear lookup of ``image`` at ``uv`` + ``offset`` (du, dv), ``scale`` applied first.  The offset is the
    image node's own texture mapping (a translation, which Cycles applies as x 1 + t, exactly the sum a vector node
    would form): one small SVM node per lookup where an Add shared by the two kinds' lookups ran a Vector Math node
    and wrote its two constants at each shading point."""
    tex = b.node("ShaderNodeTexImage", stage, image=image, interpolation="Linear", extension=extension)
    tex.label = image.name
    tex.texture_mapping.translation = (*offset, 0.0)
    if scale is not None:
        tex.texture_mapping.scale = scale
    b.group.links.new(uv, tex.inputs["Vector"])
    return tex.outputs["Color"]


@dataclass
class Levels:
    """Where EEVEE reads a control's two levels (:func:`_levels`): ``uv`` the upper level's block at slice s,
    ``fraction`` the upper level's weight, ``outside`` per level (lower, upper) 1 where it is the neutral one."""

    uv: bpy.types.NodeSocket
    fraction: bpy.types.NodeSocket
    outside: tuple[bpy.types.NodeSocket, bpy.types.NodeSocket]


def _levels(b, wrapped, slice_uv) -> Levels:
    """The two levels a control reads in EEVEE at ``wrapped`` level steps (:func:`add_edit_branch`)."""
    block = b.math("FLOOR", 48, wrapped)  # the upper level's block
    outside = tuple(b.math("COMPARE", 50, block, edge, 0.5) for edge in (0.0, float(edit_table.STACKED)))
    return Levels(uv=_block_uv(b, block, slice_uv), fraction=b.math("SUBTRACT", 49, wrapped, block), outside=outside)


def _interpolated(b, image: bpy.types.Image, levels: Levels, frac, tile_u: float) -> bpy.types.NodeSocket:
    """A control's shift in EEVEE: its two ``levels`` (the neutral one exactly 0: an Environment Texture has no Clip
    extension), each slices s and s + 1 mixed by ``frac``, mixed by the level fraction; read through Environment
    Textures (blender_addon.live._Builder.environment)."""
    found = [_unless_zero(b, zero, b.mix("VECTOR", 56, frac, b.environment(image, levels.uv, 53, (0.0, dv)),
                                         b.environment(image, levels.uv, 53, (tile_u, dv))), 57)
             for dv, zero in zip((-LEVEL_V, 0.0), levels.outside, strict=True)]
    return b.mix("VECTOR", 58, levels.fraction, found[0], found[1])


def _drawn(b, wrapped, slice_uv, chance) -> bpy.types.NodeSocket:
    """Where a control reads its one texel pair in Cycles (module docstring, "Drawn texels"): the upper level's block
    at ``wrapped`` level steps plus the draw ``chance`` (uniform in [0, 1): the upper level with probability its
    fraction), at the drawn slice ``slice_uv``; the lookup's offset of one level down reads the level drawn."""
    return _block_uv(b, b.math("FLOOR", 48, b.math("ADD", 47, wrapped, chance)), slice_uv)


def _block_uv(b, block, slice_uv) -> bpy.types.NodeSocket:
    """The UV of level block ``block`` (a whole number) at ``slice_uv`` (a slice in the images' first block)."""
    return b.vec("MULTIPLY_ADD", 52, block, (0.0, LEVEL_V, 0.0), slice_uv)


def _unfed(b, flags, j: int) -> bpy.types.NodeSocket:
    """0 where ``flags`` (max(0, -Edit Cache): :func:`linked_flags`) flag control ``j`` as fed by a node, else 1: a
    constant when Cycles compiles the shader (the cache input is never linked).  The test that lets Cycles fold a
    neutral control's lookups (its input neutral) is multiplied by it, so a control fed by a node does not evaluate
    it: it folds to 0 whatever the control's value.  A stale flag costs time or, for a neutral
    group flagged as fed, bit-for-bit exactness (the exp curves' 1e-4 at 0), never the edit."""
    flag = b.math("FLOORED_MODULO", 57, b.math("FLOOR", 56, b.math("MULTIPLY", 56, flags, 0.5 ** j)), 2.0)
    return b.math("SUBTRACT", 58, 1.0, flag)


def _unless_zero(b, zero, value, stage: int) -> bpy.types.NodeSocket:
    """``value`` (a shift read from a control's image), or exactly 0 where ``zero`` is 1 (in EEVEE a level that is
    the neutral one, outside the image, which an Environment Texture, having no Clip extension, does not read as 0;
    in Cycles a neutral control: :func:`_gated_sum`): a Mix of that factor.  For an unlinked control the factor
    folds to a constant and the Mix to one of its inputs, so a neutral level's or control's lookups drop from the
    compiled shader."""
    return b.mix("VECTOR", stage, zero, value, (0.0, 0.0, 0.0))


def _gated_sum(b, neutral, total, value) -> bpy.types.NodeSocket:
    """``total`` + ``value`` (``total`` None: 0), or ``total`` where the control is neutral (``neutral`` 1): a Mix of
    that factor.  The sum is the same everywhere (a neutral control's levels read 0); but when the control's input is
    unlinked Cycles folds the factor to a constant and the Mix to one of its inputs, so a neutral control's lookups
    are dropped from the compiled shader."""
    if total is None:
        return _unless_zero(b, neutral, value, 59)
    return b.mix("VECTOR", 59, neutral, b.vec("ADD", 59, total, value), total)


def _match(b, gin, slot: int) -> bpy.types.NodeSocket:
    """1 where the node's cache input is ``slot`` and its inputs equal the values cache ``slot`` holds (Compare
    nodes, named :func:`_cache_node_name`, whose second value the add-on sets: :data:`_EMPTY_CACHE` while empty),
    else 0.  The cache input's Compare comes first: where it is another cache the product folds to 0 even when the
    inputs are linked (Cycles folds X x 0)."""
    match = b.math("COMPARE", 56, gin.outputs[CACHE_INPUT], float(slot), 0.0)
    for name in _cache_inputs(slot):
        test = b.math("COMPARE", 56, gin.outputs[name], _EMPTY_CACHE, 0.0)
        test.node.name = _cache_node_name(slot, name)
        match = b.math("MULTIPLY", 57, match, test)
    return match


def _cache_inputs(slot: int) -> tuple[str, ...]:
    """The inputs whose values cache ``slot`` holds: the controls, and the Edit Mask's value for a constant edit."""
    return CONTROL_NAMES if slot == MASK_SLOT else (*CONTROL_NAMES, MASK_INPUT)


def _cached(b, gin, slot: int, images: dict[str, bpy.types.Image], uv, frac, tile_u: float,
            shifts: dict) -> dict:
    """``shifts`` where cache ``slot`` holds the node's edit, the cache's shifts where it does (module docstring,
    "Edit caches"): a Mix per kind from the table's shift to the cache's, of factor :func:`_match`.  The cache holds
    one atlas (the shift of that edit at the grid's nodes): each kind's image read at slices s and s + 1, its v
    scaled from the stacked images' (the images' texture mapping); a spare cache (:data:`SPARE_SLOTS`) reads its
    atlas of the mask cache's images, where :func:`_mask_cached` reads that point."""
    match = _match(b, gin, slot)
    atlases, dv = 1, 0.0
    if slot in SPARE_SLOTS:
        atlases, dv = MASK_POINTS, SPARE_SLOTS.index(slot) / MASK_POINTS
    out = {}
    for kind in edit_table.KINDS:
        image = images[cache_image_name(_image_slot(slot), kind)]
        found = _bilinear_pair(b, image, uv, [(0.0, dv), (tile_u, dv)], frac, 55,
                               scale=(1.0, float(edit_table.STACKED) / atlases, 1.0))
        out[kind] = b.mix("VECTOR", 59, match, shifts[kind], found)
    return out


def _on_line(b, gin) -> tuple[bpy.types.NodeSocket, bpy.types.NodeSocket]:
    """(match, mask): where the node's controls V lie on the mask cache's line from neutral n to the edit E it holds
    (Math nodes named :func:`_cache_node_name` of :data:`MASK_SLOT`, whose second value the add-on sets: n while
    empty), at t = (V - n).(E - n) / |E - n|^2 clamped to [0, 1] (each control within :data:`LINE_TOLERANCE` of
    n + t (E - n)), match is 1 and mask is the Edit Mask times t; else match is 0.  With the controls at E (an edit
    painted by the Edit Mask) t is exactly 1 (the two dot products are the same operations on the same values), and
    Cycles folds the product away.  The cache input's test comes first: for controls fed by nodes (flagged,
    :func:`linked_flags`) the match folds to 0 even though the controls are linked."""
    neutral = skin_edits.NEUTRAL
    held = []
    for name, n in zip(CONTROL_NAMES, neutral, strict=True):
        node = b.node("ShaderNodeMath", 53, operation="ADD")
        node.name = _cache_node_name(MASK_SLOT, name)
        b.link(0.0, node.inputs[0])
        b.link(float(n), node.inputs[1])
        held.append(node.outputs[0])
    d = [b.math("SUBTRACT", 54, e, n) for e, n in zip(held, neutral, strict=True)]
    v = [b.math("SUBTRACT", 54, gin.outputs[name], n) for name, n in zip(CONTROL_NAMES, neutral, strict=True)]

    def dot(a: list, c: list) -> bpy.types.NodeSocket:
        return b.math("MULTIPLY_ADD", 55, a[2], c[2], b.math("MULTIPLY_ADD", 55, a[1], c[1],
                                                              b.math("MULTIPLY", 55, a[0], c[0])))

    t = b.math("DIVIDE", 56, dot(v, d), dot(d, d), clamp=True)
    match = b.math("GREATER_THAN", 56, gin.outputs[CACHE_INPUT], -0.5)
    for name, dj, n in zip(CONTROL_NAMES, d, neutral, strict=True):
        on = b.math("COMPARE", 57, gin.outputs[name], b.math("MULTIPLY_ADD", 56, t, dj, n), LINE_TOLERANCE)
        match = b.math("MULTIPLY", 57, match, on)
    return match, b.math("MULTIPLY", 57, gin.outputs[MASK_INPUT], t)


#: How far a control may lie from the mask cache's line and still read it (the Compare nodes' epsilon of
#: :func:`_on_line`): keyframed controls moving together differ from the line by float rounding.
LINE_TOLERANCE = 1e-4


def _mask_cached(b, gin, images: dict[str, bpy.types.Image], base, s, frac, tile_u: float, shifts: dict) -> dict:
    """``shifts``, or where the node's controls lie on the mask cache's line (:func:`_on_line`) the shift it holds at
    the mask there: the mask's position u on the line (a Float Curve through exporters.edit_table.MaskLine.position,
    set with the cache), the points floor(u) and floor(u) + 1 read at slices s and s + 1 and interpolated linearly.
    Point p is the image's atlas p - 1; point 0 (mask 0, no shift) lies below the image, where the lookups' Clip
    extension reads 0."""
    match, mask = _on_line(b, gin)
    curve = b.node("ShaderNodeFloatCurve", 58)
    curve.name = curve.label = MASK_CURVE
    b.link(mask, curve.inputs["Value"])
    curves.set_float_curve(curve, np.array([0.0, 1.0]), np.array([0.0, 1.0]))
    position = curve.outputs["Value"]
    lower = b.math("MINIMUM", 54, b.math("FLOOR", 53, position), MASK_POINTS - 1.0)
    fraction = b.math("SUBTRACT", 54, position, lower)
    corner = b.node("ShaderNodeCombineColor", 54)
    b.link(s, corner.inputs[0])
    b.link(lower, corner.inputs[1])
    uv = b.vec("MULTIPLY_ADD", 55, corner.outputs[0], (tile_u, LEVEL_V, 0.0), base)
    scale = (1.0, edit_table.STACKED / MASK_POINTS, 1.0)
    step = 1.0 / MASK_POINTS
    out = {}
    for kind in edit_table.KINDS:
        image = images[cache_image_name(MASK_SLOT, kind)]
        found = [_bilinear_pair(b, image, uv, [(0.0, dv), (tile_u, dv)], frac, 55, scale=scale, extension="CLIP")
                 for dv in (-step, 0.0)]  # points lower, lower + 1
        value = b.mix("VECTOR", 58, fraction, found[0], found[1])
        out[kind] = b.mix("VECTOR", 59, match, shifts[kind], value)
    return out


#: The value an unused cache's Compare nodes hold: never an input's (a Compare with NaN gives 0).
_EMPTY_CACHE = float("nan")


def _cache_node_name(slot: int, control: str) -> str:
    return f"Cache {slot} {control}"


def cache_image_name(slot: int, kind: str) -> str:
    """``"Cache 1 Colour"``, ...: the image of one kind (:data:`exporters.edit_table.KINDS`) of cache ``slot``."""
    return f"Cache {slot} {kind.title()}"


def _bilinear_pair(b, image: bpy.types.Image, uv: bpy.types.NodeSocket, offsets, frac, stage: int,
                   scale: tuple[float, float, float] | None = None, extension: str = "EXTEND") -> bpy.types.NodeSocket:
    """Trilinear RGB of one level: bilinear lookups (:func:`_lookup`) at ``uv`` plus each of ``offsets`` (two (du,
    dv): slices s, s + 1) mixed by ``frac``."""
    colours = [_lookup(b, image, uv, offset, stage, scale, extension) for offset in offsets]
    return b.mix("VECTOR", stage + 1, frac, colours[0], colours[1])


def _exp(b, vector, active, bounds: tuple[float, float], stage: int) -> bpy.types.NodeSocket:
    """exp of each component of ``vector`` (within ``bounds``): a curve through exp (blender_addon.curves) behind a
    Mix of factor ``active`` (0 where every control is neutral) from 1.  Where the factor is 0 the result is 1
    exactly; Cycles folds a Mix of constant factor to one of its inputs, so at neutral unlinked controls all of it
    is the constant 1 (the group renders its unedited result bit for bit) and with edits of constant value the
    curve alone is evaluated."""
    curve = b.curve(stage, vector, *curves.smooth_points(np.exp, *bounds))
    return b.mix("RGBA", stage + 1, active, (1.0, 1.0, 1.0, 1.0), curve)


def live_node(material: bpy.types.Material | None, needs: str = "Melanin") -> bpy.types.Node | None:
    """The live group node of ``material`` (in its tree, or in the artist's node group it renders through:
    wiring.material_nodes) that has the input ``needs`` (default: the edit inputs, which groups of earlier layouts
    lack), or None."""
    if material is None or material.node_tree is None:
        return None
    for node in wiring.material_nodes(material):
        if (node.bl_idname == "ShaderNodeGroup" and node.node_tree is not None
                and node.node_tree.get("spectral_skin_sss_backend") == "LIVE" and needs in node.inputs):
            return node
    return None


def apply_preset(node: bpy.types.Node, preset: str) -> None:
    """Set the node's Melanin, Blood and Oxygenation to a preset of exporters.skin_edits.PRESETS (linked inputs are
    left as they are)."""
    set_edit(node, tuple(skin_edits.PRESETS[preset].row()))


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
            set_edit(node, skin_edits.NEUTRAL)
        else:
            apply_preset(node, self.preset.lower())
        self.report({"INFO"}, f"'{context.material.name}': skin edit {self.preset.lower()}")
        return {"FINISHED"}


def cache_status(node: bpy.types.Node) -> str | None:
    """The panel's line on how the live node's edit renders: from which cache, or from the table and why; None at
    neutral."""
    edit = constant_edit(node)
    if edit is None:
        if all(value_sockets(node.inputs[name]) is not None for name in CONTROL_NAMES):
            return "Read from the edit table: the node group's users give a control different values"
        return "Read from the edit table: a control is fed by a node"
    masked = MASK_INPUT in node.inputs and input_value(node, MASK_INPUT) is None
    if cache_key(node) is None:
        if masked and not skin_edits.neutral_rows(np.array([edit]))[0]:
            return f"Read from the edit table: the mask cache holds edits within {MASK_POINTS} levels of neutral"
        return None
    slot = int(node.inputs[CACHE_INPUT].default_value)
    if slot and cache_is_current(node):
        return "Rendered from the mask cache" if slot == MASK_SLOT else f"Rendered from edit cache {slot}"
    return "Read from the edit table (not cached)"


def line_status(node: bpy.types.Node, scene: bpy.types.Scene) -> str | None:
    """The panel's line on how the frames of a keyframed edit render from Blender's interface (Render Animation,
    whose frames the handlers do not cache): from the mask cache, or from the table and why; None where no control
    is keyframed."""
    if _keyframes(node) is None:
        return None
    line = animated_line(node, scene)
    if line is None:
        return "Animation render: read from the edit table (the keyframes do not move along one line from neutral)"
    group = _edit_group(node.node_tree) if node.node_tree is not None else None
    if group is not None and _cached_values(group, MASK_SLOT) == line:
        return "Animation render: from the mask cache"
    return "Animation render: read from the edit table (the mask cache holds another edit)"


#: The panel's hint for an edit whose controls are fed by nodes while the Edit Mask is not: one mask painting the
#: whole edit renders from the mask cache, its points interpolated at every sample (8 lookups), where each control
#: fed by a node draws its texels (2 lookups each: module docstring, "Drawn texels"), at about the same cost.
EDIT_MASK_HINT = "One mask for the whole edit? Plug it into Edit Mask"
#: The panel's second line with :data:`EDIT_MASK_HINT`: a bake takes masks of their own per control at a baked
#: material's cost (blender_addon.edit_masks).
BAKE_HINT = "Masks of their own? For final renders, Bake takes them"


def _constant(socket: bpy.types.NodeSocket | None) -> float | None:
    """The value of an unlinked float input, else None."""
    return None if socket is None or socket.is_linked else float(socket.default_value)


def masked_control(source: bpy.types.NodeSocket, neutral: float) -> tuple[bpy.types.NodeSocket, float] | None:
    """(mask, value) where the output ``source`` feeding a control is neutral + mask x (value - neutral) in one node
    of the material: a Math Multiply Add (mask, value - neutral, neutral), a float Map Range (linear) of the mask
    from [0, 1] to [neutral, value], or a float Mix of factor mask from neutral to value; else None."""
    node = source.node
    enabled = [s for s in node.inputs if s.enabled]
    if node.bl_idname == "ShaderNodeMath" and node.operation == "MULTIPLY_ADD" and not node.use_clamp:
        linked = [s for s in enabled[:2] if s.is_linked]
        slope = [_constant(s) for s in enabled[:2] if not s.is_linked]
        if len(linked) == 1 and _constant(enabled[2]) == neutral:
            mask = wiring.feeding_socket(linked[0])
            return (mask, neutral + slope[0]) if mask is not None else None
    if node.bl_idname == "ShaderNodeMapRange" and node.data_type == "FLOAT" and node.interpolation_type == "LINEAR":
        ends = [_constant(next(s for s in enabled if s.name == name))
                for name in ("From Min", "From Max", "To Min", "To Max")]
        mask = wiring.feeding_socket(next(s for s in enabled if s.name == "Value"))
        if mask is not None and ends[:3] == [0.0, 1.0, neutral] and ends[3] is not None:
            return mask, ends[3]
    if node.bl_idname == "ShaderNodeMix" and node.data_type == "FLOAT" and source == node.outputs[0]:
        mask = wiring.feeding_socket(enabled[0])
        value = _constant(enabled[2])
        if mask is not None and _constant(enabled[1]) == neutral and value is not None:
            return mask, value
    return None


def mask_feeding(node: bpy.types.Node) -> tuple[bpy.types.NodeSocket, tuple[float, float, float]] | None:
    """(mask, edit) where one mask paints the live node's whole edit through nodes of the material: every control
    fed by a node is fed neutral + mask x (value - neutral) (:func:`masked_control`) by the same mask, the others are
    at neutral (:func:`input_value`), the Edit Mask is unlinked, and the mask cache can hold the edit
    (exporters.edit_table.mask_line); ``edit`` is the values at mask 1.  Else None.  The same mask through Edit Mask
    paints the same edit (the group clamps it to [0, 1], as a painted mask is) from the mask cache:
    :class:`SPECTRAL_SKIN_OT_use_edit_mask`."""
    mask = node.inputs.get(MASK_INPUT)
    if mask is None or mask.is_linked or constant_edit(node) is not None:
        return None
    masks, edit = {}, []
    for name, neutral in zip(CONTROL_NAMES, skin_edits.NEUTRAL, strict=True):
        value = input_value(node, name)
        if value is not None:
            if value != neutral:
                return None
            edit.append(neutral)
            continue
        masked = masked_control(wiring.feeding_socket(node.inputs[name]), neutral)
        if masked is None:
            return None
        masks[masked[0].as_pointer()] = masked[0]
        edit.append(float(np.float32(masked[1])))
    if len(masks) != 1 or edit_table.mask_line(tuple(edit)) is None:
        return None
    return next(iter(masks.values())), tuple(edit)


class SPECTRAL_SKIN_OT_use_edit_mask(bpy.types.Operator):
    """Paint the edit with its mask through the group's Edit Mask instead of nodes feeding each control: the same
    picture where the mask lies in 0-1 (Edit Mask clamps it there), from the mask cache, faster (the controls' nodes
    are kept, unlinked)"""

    bl_idname = "spectral_skin.use_edit_mask"
    bl_label = "Use Edit Mask"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        node = live_node(getattr(context, "material", None))
        return node is not None and mask_feeding(node) is not None

    def execute(self, context):
        node = live_node(context.material)
        mask, edit = mask_feeding(node)
        tree = node.id_data
        for name in CONTROL_NAMES:
            for link in list(node.inputs[name].links):
                tree.links.remove(link)
        tree.links.new(mask, node.inputs[MASK_INPUT])
        set_edit(node, edit)
        self.report({"INFO"}, f"'{context.material.name}': the edit is painted by '{mask.node.name}' through "
                              "Edit Mask")
        return {"FINISHED"}


def edit_mask_hint(node: bpy.types.Node) -> str | None:
    """:data:`EDIT_MASK_HINT` where a control of the live node is fed by a node and its Edit Mask is not, else None."""
    mask = node.inputs.get(MASK_INPUT)
    if mask is None or mask.is_linked or constant_edit(node) is not None:
        return None
    return EDIT_MASK_HINT


def draw_controls(layout, context) -> None:
    """The selected material's Melanin, Blood, Oxygenation and Edit Mask (its live group node's inputs), how the
    edit renders and the presets."""
    node = live_node(getattr(context, "material", None))
    if node is None:
        return
    box = layout.box()
    box.label(text="Skin edits (live)")
    for name in (*CONTROL_NAMES, MASK_INPUT):
        socket = node.inputs.get(name)
        if socket is None:
            continue
        if socket.is_linked:
            box.label(text=f"{name}: from node '{socket.links[0].from_node.name}'", icon="LINKED")
        else:
            box.prop(socket, "default_value", text=name)
    for status in (cache_status(node), line_status(node, context.scene)):
        if status is not None:
            box.label(text=status, icon="INFO")
    if mask_feeding(node) is not None:
        box.operator(SPECTRAL_SKIN_OT_use_edit_mask.bl_idname, text="One mask paints the edit: Use Edit Mask")
    elif (hint := edit_mask_hint(node)) is not None:
        box.label(text=hint)
        box.label(text=BAKE_HINT)
    row = box.row(align=True)
    for key, label, _ in PRESET_ITEMS:
        row.operator(SPECTRAL_SKIN_OT_skin_edit_preset.bl_idname, text=label).preset = key


classes = (SPECTRAL_SKIN_OT_skin_edit_preset, SPECTRAL_SKIN_OT_use_edit_mask)
