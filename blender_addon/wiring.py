"""How the add-on's nodes sit in an artist's material, and how they leave it again.

**Per-target outputs.**  The artist's Principled BSDF stays linked to the artist's active Material Output (target
All): Blender's exporters (glTF 2.0 reads the Principled BSDF linked to the active output, FBX's
node_shader_utils and OBJ the first Principled BSDF linked straight into a Material Output, USD the first
Principled BSDF of the tree) keep writing its base colour texture, roughness and normal map.  The renderers prefer
a Material Output whose target is exactly theirs over one of target All (``ShaderNodeTree.get_output_node``), so
a Material Output of target **Cycles** fed by the add-on's group renders in Cycles and one of target **EEVEE** in
EEVEE and Material Preview: the render is that of the group, the export that of the artist's Principled.  An output
the add-on adds takes the artist's Displacement (a pore or wrinkle map, as bump or true displacement), Volume and
Thickness from the output the renderer used before, and follows them (blender_addon.follow).

Where the artist already has an output of one of those targets (the active one, or an inactive one the renderer
would take first), its Surface link is replaced instead of adding a node, and the replaced link is recorded in
``material[REPLACED_LINKS_PROP]`` (JSON) so that it comes back on removal.

**Removal.**  Every node the add-on adds is tagged ``node[ADDED_PROP]``; the artist's nodes are never changed (only
links from their outputs into the add-on's nodes are added).  :func:`unwire` removes the tagged nodes (their links
go with them), relinks the recorded links and drops the add-on's material properties, so the material is again
exactly what the artist had; everything lives in the .blend, so this holds after save and reopen.  Materials wired
before the tags existed (the group fed the active output; the node it replaced named in
``material[PREVIOUS_SURFACE_PROP]``) are recognised by the add-on's frame, groups and EEVEE output and restored the
same way.  :func:`purge_unused` then removes the add-on's node groups and images that no material uses any more.

**Layered materials.**  Where the artist's Principled BSDF reaches the Material Output through Mix Shader and Add
Shader nodes (a sweat or oil layer, a glow, a second coat), the renderers' outputs are fed by a copy of that chain
(tagged like every node the add-on adds) with the add-on's group in the Principled BSDF's place: the other layers
render over the skin as they did over the Principled BSDF, their factors and shaders linked from the artist's own
nodes (:func:`shader_chain`, :func:`feed_render_outputs`).  The copies follow the artist's nodes: a factor changed
or a mask linked afterwards goes to the same copies, a layer added, removed or reordered is copied again
(:func:`retake_chain`, :func:`recopy_chain`; blender_addon.follow).

**Metal and glass.**  The group renders the Principled BSDF's opaque dielectric base (skin, or what is painted over
it) and its specular, coat and sheen layers.  The Principled BSDF mixes a metal base over all that by Metallic, and
a glass base by Transmission Weight; where either is linked (a character's texture set with a metallic map for
jewellery or armour) or above 0, each renderer's output gets a tagged copy of the artist's Principled BSDF with that
input at 1, mixed over the group by the artist's Metallic or Transmission Weight (a Mix Shader, inner Transmission,
outer Metallic, as the Principled BSDF layers them), so those parts render as the Principled BSDF renders them
(:data:`LAYERS`, :func:`insert_base_layers`).  The mixture group of baked maps has no Subsurface Weight, Alpha or
Emission inputs (the live group has): over it the same way come a copy with Subsurface Weight 0 (the diffuse body
where a mask lowers the weight), an Emission added and a Transparent BSDF mixed by Alpha, each only where the
artist's input asks for it.  A material that asks for none gets no such node.

**EEVEE's thickness.**  EEVEE takes an object's thickness, for the light its subsurface passes through thin parts,
from the Material Output's Thickness or else from the object's smallest dimension: the whole head for an ear.  At
the skin's millimetre radii that leaves back-lit ears and nostrils dark in EEVEE where Cycles, which follows the
light through the real geometry, shows them glowing.  Wiring therefore turns on the material's EEVEE setting
*Thickness From Shadow* (``use_thickness_from_shadow``: the shadow maps of shadow-casting lights give the thickness
the light crossed), the artist's value recorded in ``material[THICKNESS_FROM_SHADOW_PROP]`` and put back on
removal.

**Grouped skin shaders.**  Where the Principled BSDF sits in an artist's node group (an asset's or a character
pipeline's skin shader) that reaches the active Material Output, straight or through layers, and reaches that node
group's Group Output itself, straight or through layers there, or through a node group nested there that holds it
the same way (:func:`grouped_skin`), the add-on's group node goes inside the node group the Principled BSDF sits
in, beside it, taking its inputs there (:func:`take_input` links within one tree only); the layers inside each node
group are copied there, and two shader outputs are added to each one's interface (:data:`GROUP_OUTPUTS`,
:func:`feed_group_outputs`), passed up to the material's Cycles and EEVEE outputs (through copies of the material's
layers over the group node).  The node group's own output, and the material's, still give the
artist's Principled BSDF to the exporters; a material that does not use the added outputs renders as before (the
renderers compile only what reaches an output).  Every material using the node group renders through the one group
node in it.  :func:`unwire` takes the add-on's nodes and outputs out of a node group once no material renders
through it (:func:`unwire_unused_groups`).  A Principled BSDF that reaches its group's output through other
nodes is refused (:func:`grouped_principled` names the group).  Baked maps go in the same way where the node group
is the material's alone and the albedo reads a UV map (:func:`bake_into_group`), else over the group node, with a
warning (:func:`grouped_warning`).

**Linked data.**  A material linked from another .blend, or a library override of one, cannot keep node edits
(they are not saved: the library's material comes back on reload), so :func:`linked_error` says so and what to do.
"""

from __future__ import annotations

import json
import os
from typing import NamedTuple

import bpy
import numpy as np

#: Custom property on every node the add-on adds to a material.
ADDED_PROP = "spectral_skin_sss_added"
#: Custom property (JSON list) on a material: the artist's links the add-on replaced, to put back on removal.
REPLACED_LINKS_PROP = "spectral_skin_sss_replaced_links"
#: Custom property remembering what fed the Material Output before wiring (the node's name).
PREVIOUS_SURFACE_PROP = "spectral_skin_sss_previous_surface"
#: Label of the frame holding the add-on's nodes.
FRAME_LABEL = "Spectral Skin SSS"
#: Labels of the per-target Material Outputs the add-on adds.
OUTPUT_LABELS = {"CYCLES": "Cycles (Spectral Skin SSS)", "EEVEE": "EEVEE (Spectral Skin SSS)"}
#: The EEVEE output's label in files wired before the per-target outputs.
_LEGACY_OUTPUT_LABEL = "EEVEE (Spectral Skin SSS Live)"
#: Custom properties the add-on puts on node groups and images it makes (what :func:`purge_unused` may remove).
_GROUP_TAG = "spectral_skin_sss_backend"
#: Custom property on the skin-edit group and its images (blender_addon.live_edits): the edit table's SHA-256.
EDIT_TABLE_PROP = "spectral_skin_sss_edit_table"
#: Custom property on the grazing-light group and its images (blender_addon.oblique): the correction's SHA-256.
OBLIQUE_PROP = "spectral_skin_sss_oblique"
IMAGE_TAGS = ("spectral_skin_sss_table", "spectral_skin_sss_bake_key", EDIT_TABLE_PROP, OBLIQUE_PROP)
#: Custom property on a material: its EEVEE setting Thickness From Shadow before wiring (1 or 0), put back on removal.
THICKNESS_FROM_SHADOW_PROP = "spectral_skin_sss_thickness_from_shadow"
#: Custom property (JSON) on a wired material: what the group took from the Principled BSDF (blender_addon.follow).
TAKEN_INPUTS_PROP = "spectral_skin_sss_taken_inputs"
#: Material properties the add-on sets (removed by :func:`unwire`).
MATERIAL_PROPS = (PREVIOUS_SURFACE_PROP, REPLACED_LINKS_PROP, THICKNESS_FROM_SHADOW_PROP, TAKEN_INPUTS_PROP)


def linked_error(material: bpy.types.Material) -> str | None:
    """A one-line message when ``material`` cannot keep the add-on's nodes (linked from a library, or a library
    override), else None."""
    library = material.library
    if library is not None:
        name = os.path.basename(bpy.path.abspath(library.filepath)) or library.name
        return (f"material '{material.name}' is linked from {name} and read-only (node changes are lost on reload): "
                f"make it local (Object > Relations > Make Local > Selected Objects, Data and Materials) and run "
                f"this again, or run it in {name}")
    if material.override_library is not None:
        return (f"material '{material.name}' is a library override, whose nodes are not saved: make it local "
                "(Object > Relations > Make Local > Selected Objects, Data and Materials) and run this again")
    return None


def group_linked_error(tree: bpy.types.NodeTree) -> str | None:
    """A one-line message when the artist's node group ``tree`` (holding the skin's Principled BSDF) cannot keep
    the add-on's nodes (linked from a library), else None."""
    if tree.library is None and tree.override_library is None:
        return None
    return (f"node group '{tree.name}' is linked from a library and read-only: make it local (Object > Relations > "
            "Make Local > All) and run this again")


def object_material(obj: bpy.types.Object | None, name: str = "") -> bpy.types.Material | None:
    """The material of ``obj`` named ``name`` (one in its material slots), or its active material where ``name``
    is empty; None without an object.  Raises ValueError (one line: what is there to choose) for a name that is
    not in its slots."""
    if obj is None:
        return None
    if not name:
        return obj.active_material
    slots = [slot.material for slot in obj.material_slots if slot.material is not None]
    found = next((m for m in slots if m.name == name), None)
    if found is None:
        choices = ", ".join(f"'{m.name}'" for m in slots) or "none"
        raise ValueError(f"material '{name}' is not in the slots of '{obj.name}' (its materials: {choices}): name one "
                         "of them, or leave Material empty for the active one")
    return found


def tag(node: bpy.types.Node) -> bpy.types.Node:
    """Mark ``node`` as the add-on's (removed by :func:`unwire`)."""
    node[ADDED_PROP] = True
    return node


def is_added(node: bpy.types.Node) -> bool:
    return bool(node.get(ADDED_PROP))


def _outputs(tree: bpy.types.NodeTree) -> list[bpy.types.Node]:
    return [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]


def active_output(tree: bpy.types.NodeTree) -> bpy.types.Node | None:
    """The tree's active Material Output (the first one when none is flagged), or None."""
    outputs = _outputs(tree)
    return next((n for n in outputs if n.is_active_output), outputs[0] if outputs else None)


def render_output(tree: bpy.types.NodeTree, target: str) -> bpy.types.Node | None:
    """The Material Output the renderer of ``target`` ("CYCLES", "EEVEE"; "ALL" for the exporters' view) uses, as
    Blender picks it (``ShaderNodeTree.get_output_node``: one of exactly that target, the active one first, else
    one of target All)."""
    return tree.get_output_node(target)


#: The Material Output's inputs besides Surface: Volume, Displacement (a displacement or bump map: Cycles displaces or
#: bumps by it as the material's Displacement setting says, EEVEE bumps) and EEVEE's Thickness.  An output the add-on
#: adds takes them from the artist's output that renderer used (:func:`take_output_inputs`).
OUTPUT_INPUTS = ("Volume", "Displacement", "Thickness")


def artist_output(tree: bpy.types.NodeTree, target: str) -> bpy.types.Node | None:
    """The artist's Material Output that renders ``target`` ("CYCLES", "EEVEE", "ALL") with the add-on's outputs
    left aside, picked as Blender picks (:func:`render_output`): one of exactly that target, the active one first,
    else one of target All; None where the artist has none."""
    outputs = [n for n in _outputs(tree) if not is_added(n)]
    for wanted in dict.fromkeys((target, "ALL")):
        found = [n for n in outputs if n.target == wanted]
        if found:
            return next((n for n in found if n.is_active_output), found[0])
    return None


def output_sources(tree: bpy.types.NodeTree) -> list[tuple[bpy.types.Node, bpy.types.Node]]:
    """Each Material Output the add-on added, with the artist's output of its target (:func:`artist_output`) that it
    takes :data:`OUTPUT_INPUTS` from; the pairs without such an output of the artist's left out."""
    pairs = [(out, artist_output(tree, out.target)) for out in _outputs(tree) if is_added(out)]
    return [(out, source) for out, source in pairs if source is not None]


def take_output_inputs(tree: bpy.types.NodeTree, source: bpy.types.Node, out: bpy.types.Node) -> None:
    """Give the add-on's Material Output ``out`` what the artist's ``source`` has at :data:`OUTPUT_INPUTS`
    (:func:`take_input`: a link stays a link, a value and its animation are copied)."""
    for name in OUTPUT_INPUTS:
        theirs, ours = source.inputs.get(name), out.inputs.get(name)
        if theirs is not None and ours is not None:
            take_input(tree, theirs, ours, animated=bool(animation(ours)))


def retake_output_inputs(tree: bpy.types.NodeTree) -> None:
    """:func:`take_output_inputs` for each Material Output the add-on added, from the artist's output of its target
    (blender_addon.follow: the artist linked a displacement map, or changed a Thickness, after wiring)."""
    for out, source in output_sources(tree):
        take_output_inputs(tree, source, out)


def _record_replaced(material: bpy.types.Material, link: bpy.types.NodeLink) -> None:
    links = json.loads(material.get(REPLACED_LINKS_PROP, "[]"))
    links.append({"from_node": link.from_node.name, "from_socket": link.from_socket.identifier,
                  "to_node": link.to_node.name, "to_socket": link.to_socket.identifier})
    material[REPLACED_LINKS_PROP] = json.dumps(links)


def feeding_socket(socket: bpy.types.NodeSocket) -> bpy.types.NodeSocket | None:
    """The output socket whose value reaches ``socket``, as the renderers evaluate the tree: the one linked into it,
    followed back through Reroute nodes and muted nodes (a muted node passes an input through its internal link);
    muted links ignored; None where nothing reaches it (no link, or a muted node passing nothing to that output)."""
    seen: set[int] = set()
    while True:
        source = next((link.from_socket for link in socket.links if not link.is_muted), None)
        if source is None or source.as_pointer() in seen:
            return None
        seen.add(source.as_pointer())
        node = source.node
        if node.bl_idname == "NodeReroute":
            socket = node.inputs[0]
        elif node.mute:
            socket = next((link.from_socket for link in node.internal_links if link.to_socket == source), None)
            if socket is None:
                return None
        else:
            return source


def source_socket(socket: bpy.types.NodeSocket, depth: int = 1) -> bpy.types.NodeSocket | None:
    """:func:`feeding_socket`, followed out of a node group where its Group Input feeds ``socket`` and one group node
    alone uses the group (through the output linked into that node's matching input, in turn): what reaches
    ``socket`` from the material.  The Group Input's output where several group nodes use the group, or that one's
    input is unlinked."""
    source = feeding_socket(socket)
    if source is None or source.node.bl_idname != "NodeGroupInput" or depth > MAX_GROUP_DEPTH:
        return source
    given = group_node_inputs(source)
    return source_socket(given[0], depth + 1) if len(given) == 1 and given[0].is_linked else source


def take_input(tree: bpy.types.NodeTree, theirs: bpy.types.NodeSocket, ours: bpy.types.NodeSocket,
               animated: bool = False) -> None:
    """Give the add-on's input ``ours`` what the artist's input ``theirs`` has: the same link, or (unlinked) no link,
    its value and a copy of its keyframes and driver (:func:`copy_animation`); an unlinked Normal's value means
    nothing (the shading normal) and a shader input has none.  ``animated``: ``ours`` holds such a copy from an
    earlier call, removed first (as it is wherever ``theirs`` is animated now)."""
    if animated or animation(theirs):
        clear_animation(ours)
    feed = feeding_socket(theirs)
    if feed is not None:
        tree.links.new(feed, ours)
        return
    for link in list(ours.links):
        tree.links.remove(link)
    if theirs.name != "Normal" and hasattr(theirs, "default_value"):
        ours.default_value = theirs.default_value
        copy_animation(theirs, ours)


# -- animated inputs --------------------------------------------------------------------------------------------
# An input the artist keyframed or drove changes with the frame, where no handler runs: the add-on's input gets a
# copy of the F-curves (or the driver) in the same node tree, so Blender animates both alike.  A driver reading the
# artist's input instead would make the node tree depend on itself (Blender reports a dependency cycle).
def _action_fcurves(tree: bpy.types.NodeTree):
    """The F-curves of the node tree's action (its slot's, where actions have slots), or None without an action."""
    anim = tree.animation_data
    action = anim.action if anim is not None else None
    if action is None:
        return None
    if hasattr(action, "fcurves"):  # Blender 4.2-4.5
        return action.fcurves
    from bpy_extras import anim_utils  # Blender 5: slotted actions only

    bag = anim_utils.action_get_channelbag_for_slot(action, anim.action_slot)
    return bag.fcurves if bag is not None else None


def animation(socket: bpy.types.NodeSocket) -> list[bpy.types.FCurve]:
    """The F-curves (keyframes, then drivers) that animate the value of ``socket`` in its node tree."""
    tree = socket.id_data
    anim = tree.animation_data
    if anim is None or not hasattr(socket, "default_value"):
        return []
    path = socket.path_from_id("default_value")
    keyed = [fc for fc in (_action_fcurves(tree) or ()) if fc.data_path == path]
    return keyed + [fc for fc in anim.drivers if fc.data_path == path]


def copy_animation(theirs: bpy.types.NodeSocket, ours: bpy.types.NodeSocket) -> None:
    """Give ``ours`` (a socket of the same node tree) a copy of the keyframes and the driver of ``theirs``."""
    path = ours.path_from_id("default_value")
    for curve in animation(theirs):
        if curve.driver is not None:
            _copy_driver(curve.driver, ours.driver_add("default_value", *_index(ours, curve)).driver)
            continue
        copy = _action_fcurves(theirs.id_data).new(path, index=curve.array_index)
        copy.keyframe_points.add(len(curve.keyframe_points))
        for source, target in zip(curve.keyframe_points, copy.keyframe_points, strict=True):
            for name in ("co", "handle_left", "handle_right", "interpolation", "handle_left_type",
                         "handle_right_type", "easing", "back", "amplitude", "period"):
                setattr(target, name, getattr(source, name))
        copy.extrapolation = curve.extrapolation
        copy.update()


def _index(socket: bpy.types.NodeSocket, curve: bpy.types.FCurve) -> tuple[int, ...]:
    """The index argument of ``driver_add`` / ``driver_remove`` for ``curve`` on ``socket``: its array index
    where the value is an array, none for a single value (which refuses one)."""
    return (curve.array_index,) if hasattr(socket.default_value, "__len__") else ()


def _copy_driver(source: bpy.types.Driver, target: bpy.types.Driver) -> None:
    """Make ``target`` compute what ``source`` does: its type, expression and variables."""
    target.type, target.expression, target.use_self = source.type, source.expression, source.use_self
    for variable in source.variables:
        copy = target.variables.new()
        copy.name, copy.type = variable.name, variable.type
        for theirs, ours in zip(variable.targets, copy.targets, strict=False):
            if variable.type == "SINGLE_PROP":
                ours.id_type = theirs.id_type
            ours.id = theirs.id
            for name in ("data_path", "bone_target", "transform_type", "transform_space", "rotation_mode"):
                setattr(ours, name, getattr(theirs, name))


def clear_animation(socket: bpy.types.NodeSocket) -> None:
    """Remove the keyframes and the driver of ``socket``'s value."""
    fcurves = _action_fcurves(socket.id_data)
    for curve in animation(socket):
        if curve.driver is not None:
            socket.driver_remove("default_value", *_index(socket, curve))
        elif fcurves is not None:
            fcurves.remove(curve)


#: The shader nodes a layered material may pass its Principled BSDF through on the way to the Material Output.
LAYER_NODES = ("ShaderNodeMixShader", "ShaderNodeAddShader")


Chain = list[tuple[bpy.types.Node, int]]


def _chains_to(socket: bpy.types.NodeSocket | None, accept) -> list[tuple[bpy.types.NodeSocket, Chain]]:
    """Each output socket that ``accept`` takes, reaching the input ``socket`` straight or through Mix Shader and
    Add Shader nodes (:data:`LAYER_NODES`), with the chain between: (layer node, index of its input that side comes
    in), ``socket``'s side first; in input order."""
    found: list[tuple[bpy.types.NodeSocket, Chain]] = []

    def walk(feed: bpy.types.NodeSocket, chain: Chain) -> None:
        if accept(feed):
            found.append((feed, chain))
        elif feed.node.bl_idname in LAYER_NODES:
            for i, input_socket in enumerate(feed.node.inputs):
                below = feeding_socket(input_socket) if input_socket.type == "SHADER" else None
                if below is not None:
                    walk(below, [*chain, (feed.node, i)])

    top = feeding_socket(socket) if socket is not None else None
    if top is not None:
        walk(top, [])
    return found


def _principled_chain(socket: bpy.types.NodeSocket | None) -> tuple[bpy.types.Node | None, Chain]:
    """The Principled BSDF reaching ``socket`` (:func:`_chains_to`) and the chain between; where several do, the one
    whose Base Color is linked (the albedo), the first such in input order; (None, []) where none does."""
    found = [(feed.node, chain) for feed, chain in _chains_to(
        socket, lambda feed: feed.node.bl_idname == "ShaderNodeBsdfPrincipled")]
    albedo = [f for f in found if f[0].inputs["Base Color"].is_linked]
    return (albedo or found or [(None, [])])[0]


def shader_chain(tree: bpy.types.NodeTree) -> tuple[bpy.types.Node | None, Chain]:
    """The Principled BSDF feeding the active Material Output's Surface, straight or through Mix Shader and Add
    Shader nodes (:data:`LAYER_NODES`), and the chain between them: (layer node, index of its input the Principled
    BSDF's side comes in), output side first.  Where several Principled BSDFs are reached the one whose Base Color
    is linked (the albedo) is taken, the first such in input order; (None, []) where there is none."""
    out = active_output(tree)
    return _principled_chain(out.inputs["Surface"] if out is not None else None)


#: The shader outputs the add-on adds to the interface of an artist's node group that holds the skin's Principled
#: BSDF (module docstring, "Grouped skin shaders"), by the renderer whose Material Output they feed.
GROUP_OUTPUTS = {"CYCLES": "Cycles (Spectral Skin SSS)", "EEVEE": "EEVEE (Spectral Skin SSS)"}


class GroupLevel(NamedTuple):
    """A node group node ``node`` inside an artist's node group, whose output ``output`` reaches that node group's
    Group Output through the layers ``chain`` there, and whose own node group holds the skin, at some depth."""
    node: bpy.types.Node
    output: bpy.types.NodeSocket
    chain: Chain


class GroupedSkin(NamedTuple):
    """An artist's node group node ``node`` whose output ``output`` reaches the active Material Output through the
    layers ``outer`` (:func:`shader_chain`'s form); its node group holds the Principled BSDF ``principled`` straight
    (``levels`` empty) or in node groups nested there, each a :class:`GroupLevel` of ``levels``, outermost first;
    ``principled`` reaches the Group Output of the node group it sits in through the layers ``inner``."""
    node: bpy.types.Node
    output: bpy.types.NodeSocket
    principled: bpy.types.Node
    inner: Chain
    outer: Chain
    levels: list[GroupLevel]

    @property
    def skin_output(self) -> bpy.types.NodeSocket:
        """The output of the group node whose node group the Principled BSDF sits in (the innermost, nested)."""
        return self.levels[-1].output if self.levels else self.output


def group_output(tree: bpy.types.NodeTree) -> bpy.types.Node | None:
    """The node group's active Group Output node (the first one when none is flagged), or None."""
    found = [n for n in tree.nodes if n.bl_idname == "NodeGroupOutput"]
    return next((n for n in found if n.is_active_output), found[0] if found else None)


#: How deep in nested node groups the skin's Principled BSDF is looked for (Blender forbids a group in itself, so
#: the search ends anyway; this bounds it for trees nested absurdly deep).
MAX_GROUP_DEPTH = 8


def _inside(feed: bpy.types.NodeSocket, depth: int = 1) -> tuple[bpy.types.Node | None, Chain, list[GroupLevel]]:
    """The Principled BSDF reaching the Group Output's input behind the group node output ``feed`` inside its own
    node group, straight or through layers or through node groups nested there (at most :data:`MAX_GROUP_DEPTH`
    deep), with the layers between it and the Group Output of the node group it sits in and the nested levels
    (:class:`GroupedSkin`); (None, [], []) where there is none."""
    node = feed.node
    tree = node.node_tree if node.bl_idname == "ShaderNodeGroup" else None
    if tree is None or is_addon_group(tree) or feed.name in GROUP_OUTPUTS.values() or depth > MAX_GROUP_DEPTH:
        return None, [], []
    gout = group_output(tree)
    socket = next((s for s in gout.inputs if s.identifier == feed.identifier), None) if gout is not None else None
    principled, inner = _principled_chain(socket)
    if principled is not None:
        return principled, inner, []
    found = _group_reaching(socket, depth + 1)
    if found is None:
        return None, [], []
    below, chain, (principled, inner, levels) = found
    return principled, inner, [GroupLevel(below.node, below, chain), *levels]


def _group_reaching(socket: bpy.types.NodeSocket | None, depth: int
                    ) -> tuple[bpy.types.NodeSocket, Chain, tuple[bpy.types.Node, Chain, list[GroupLevel]]] | None:
    """The first group node output reaching ``socket`` (:func:`_chains_to`) whose node group holds the skin
    (:func:`_inside` at ``depth``): (it, the layers between, what :func:`_inside` found there); None where none
    does.  Each node group is looked into once."""
    inside: dict[int, tuple] = {}

    def holds(feed: bpy.types.NodeSocket) -> bool:
        inside[feed.as_pointer()] = _inside(feed, depth)
        return inside[feed.as_pointer()][0] is not None

    found = _chains_to(socket, holds)
    if not found:
        return None
    feed, chain = found[0]
    return feed, chain, inside[feed.as_pointer()]


def grouped_skin(tree: bpy.types.NodeTree) -> GroupedSkin | None:
    """Where no Principled BSDF reaches the active Material Output at the material's level (:func:`shader_chain`):
    the artist's node group node that does (an asset's skin shader), its Principled BSDF inside its own group or in
    node groups nested there (straight or under layers at each level); the first in input order.  None where there
    is none."""
    out = active_output(tree)
    found = _group_reaching(out.inputs["Surface"] if out is not None else None, 1)
    if found is None:
        return None
    feed, outer, (principled, inner, levels) = found
    return GroupedSkin(feed.node, feed, principled, inner, outer, levels)


def grouped_principled(tree: bpy.types.NodeTree) -> bpy.types.Node | None:
    """The node group node feeding the active Material Output's Surface (straight or through Mix Shader and Add
    Shader nodes) that holds a Principled BSDF, at any depth (an asset's skin shader), or None."""
    out = active_output(tree)
    feed = feeding_socket(out.inputs["Surface"]) if out is not None else None
    stack, seen = [feed.node] if feed is not None else [], set()
    while stack:
        node = stack.pop()
        if node.name in seen:
            continue
        seen.add(node.name)
        if node.bl_idname == "ShaderNodeGroup" and _holds_principled(node.node_tree, set()):
            return node
        if node.bl_idname in LAYER_NODES:
            stack += [f.node for s in node.inputs if s.type == "SHADER" and (f := feeding_socket(s)) is not None]
    return None


def uses_group(tree: bpy.types.NodeTree, group: bpy.types.NodeTree, depth: int = 1) -> bool:
    """Whether ``tree`` uses the node group ``group``, in a group node of its own or of the node groups it uses."""
    return depth <= MAX_GROUP_DEPTH and any(
        node.bl_idname == "ShaderNodeGroup" and node.node_tree is not None
        and (node.node_tree == group or uses_group(node.node_tree, group, depth + 1)) for node in tree.nodes)


def group_instances(group: bpy.types.NodeTree) -> list[bpy.types.Node]:
    """The group nodes using the node group ``group`` directly, in materials' trees and in node groups."""
    trees = [m.node_tree for m in bpy.data.materials if m.node_tree is not None] + list(bpy.data.node_groups)
    return [n for tree in trees for n in tree.nodes if n.bl_idname == "ShaderNodeGroup" and n.node_tree == group]


def group_node_inputs(group_input: bpy.types.NodeSocket) -> list[bpy.types.NodeSocket]:
    """The inputs that the Group Input output ``group_input`` passes on: the matching input of every group node
    using its node group (:func:`group_instances`)."""
    return [s for gnode in group_instances(group_input.id_data) for s in gnode.inputs
            if s.identifier == group_input.identifier]


def group_users(group: bpy.types.NodeTree) -> list[bpy.types.Material]:
    """The materials using the node group ``group`` (:func:`uses_group`)."""
    return [m for m in bpy.data.materials if m.node_tree is not None and uses_group(m.node_tree, group)]


def grouped_text(material: bpy.types.Material, gnode: bpy.types.Node) -> str:
    """For a report: where the add-on's group node ``gnode`` sits in the artist's node group (:func:`grouped_skin`),
    which, and the other materials using it (they share its inputs: Melanin, Blood, Oxygenation, Translucency); else
    ""."""
    tree = gnode.id_data
    if tree == material.node_tree:
        return ""
    others = sorted(m.name for m in group_users(tree) if m != material)
    shared = f", shared with {', '.join(repr(name) for name in others)}" if others else ""
    return f" inside its node group '{tree.name}'{shared}"


def bake_into_group(material: bpy.types.Material,
                    albedo: bpy.types.Node | None) -> tuple[GroupedSkin | None, str]:
    """Whether baked maps can render inside the artist's node group that holds the Principled BSDF
    (:func:`grouped_skin`), as the live group does: (the grouped skin, "") where they can, (None, why not) where the
    Principled BSDF sits in a node group they cannot go into, (None, "") where it sits in none.  They cannot where
    that node group is also another material's (the maps are this material's) or where the albedo's Image Texture
    ``albedo`` reads other coordinates than a UV map (the maps must read the same ones, from inside the group)."""
    tree = material.node_tree
    if shader_chain(tree)[0] is not None:
        return None, ""
    skin = grouped_skin(tree)
    grouped = skin.principled.id_data if skin is not None else None  # the node group the Principled BSDF sits in
    if grouped is None:
        found = grouped_principled(tree)
        return None, (f"the Principled BSDF inside node group '{found.node_tree.name}' is not reached"
                      if found is not None else "")
    others = [m.name for m in group_users(grouped) if m != material]
    if others:
        names = ", ".join(f"'{name}'" for name in sorted(others))
        return None, f"node group '{grouped.name}', which holds the Principled BSDF, is also used by {names}"
    feed = feeding_socket(albedo.inputs["Vector"]) if albedo is not None else None
    if feed is not None and feed.node.bl_idname != "ShaderNodeUVMap":
        return None, f"the albedo's Image Texture reads other coordinates than a UV map (from '{feed.node.name}')"
    return skin, ""


def grouped_warning(why: str) -> str:
    """The report's warning where baked maps render over a node group holding the Principled BSDF instead of inside
    it (``why``, :func:`bake_into_group`): they render the skin alone, none of the inputs it has in there; "" where
    ``why`` is empty."""
    if not why:
        return ""
    return (f"; warning: {why}, so the maps render over the group, without its normal map, roughness, specular, "
            "coat, metal or alpha: choose the live group, which reads it there")


def _holds_principled(tree: bpy.types.NodeTree | None, seen: set[str]) -> bool:
    """Whether ``tree`` or a node group inside it (at any depth) has a Principled BSDF."""
    if tree is None or tree.name in seen:
        return False
    seen.add(tree.name)
    return any(n.bl_idname == "ShaderNodeBsdfPrincipled"
               or (n.bl_idname == "ShaderNodeGroup" and _holds_principled(n.node_tree, seen)) for n in tree.nodes)


def addon_feeds_active_output(tree: bpy.types.NodeTree) -> bool:
    """Whether the add-on's nodes feed the active Material Output's Surface (a material wired before the per-target
    outputs, or whose active output has the target Cycles or EEVEE the operator fed)."""
    out = active_output(tree)
    feed = feeding_socket(out.inputs["Surface"]) if out is not None else None
    return feed is not None and (is_added(feed.node) or (feed.node.bl_idname == "ShaderNodeGroup"
                                                         and is_addon_group(feed.node.node_tree)))


def artist_principled(material: bpy.types.Material) -> bpy.types.Node | None:
    """The artist's Principled BSDF that the add-on's group renders for: the one of :func:`shader_chain`, or where
    the add-on's nodes feed the active output (a material wired before the per-target outputs, or whose active
    output has the target Cycles or EEVEE the operator fed) the node named in ``material[PREVIOUS_SURFACE_PROP]``
    when it is one; None where there is none."""
    tree = material.node_tree
    if addon_feeds_active_output(tree):
        node = tree.nodes.get(material.get(PREVIOUS_SURFACE_PROP, ""))
        return node if node is not None and node.bl_idname == "ShaderNodeBsdfPrincipled" else None
    principled = shader_chain(tree)[0]
    skin = grouped_skin(tree) if principled is None else None
    return skin.principled if skin is not None else principled


def skin_chain(tree: bpy.types.NodeTree) -> Chain:
    """The artist's layers over the skin in ``tree`` (:func:`shader_chain`'s form): in a material's tree those over
    its Principled BSDF, or over the node group node holding it (:func:`grouped_skin`); in such a node group, wired,
    those between its Group Output and the Principled BSDF, or the node group node nested there that holds it
    (:func:`_skin_output`)."""
    if not tree.is_embedded_data:
        found = _skin_output(tree)
        return found[1] if found is not None else []
    principled, chain = shader_chain(tree)
    skin = grouped_skin(tree) if principled is None else None
    return skin.outer if skin is not None else chain


def _skin_output(tree: bpy.types.NodeTree, depth: int = 1) -> tuple[bpy.types.NodeSocket, Chain] | None:
    """The Group Output input of the artist's node group ``tree`` through which the skin leaves it (what the add-on's
    outputs there render instead) and the layers between it and the skin: the input that the add-on's group node
    there records (:data:`SKIN_OUTPUT_PROP`), else the one reaching the nested node group node whose added outputs
    feed this group's (found the same way inside it); None where the add-on wired nothing there."""
    gout = group_output(tree)
    if gout is None or depth > MAX_GROUP_DEPTH:
        return None
    marker = grouped_group_node(tree)
    if marker is not None:
        socket = next((s for s in gout.inputs if s.identifier == marker[SKIN_OUTPUT_PROP]), None)
        principled, chain = _principled_chain(socket)
        return (socket, chain) if principled is not None else None
    sockets = render_sockets(tree)
    bottom = _copies_below(sockets[0])[1] if sockets else None
    nested = bottom.node.node_tree if bottom is not None and bottom.node.bl_idname == "ShaderNodeGroup" else None
    below = _skin_output(nested, depth + 1) if nested is not None else None
    if below is None:
        return None
    artists = next((o for o in bottom.node.outputs if o.identifier == below[0].identifier), None)
    for socket in gout.inputs:
        found = _chains_to(socket, lambda feed: artists is not None and feed.as_pointer() == artists.as_pointer())
        if socket.name not in GROUP_OUTPUTS.values() and found:
            return socket, found[0][1]
    return None


#: Custom property on the add-on's group node inside an artist's node group: the identifier of the Group Output's
#: input that the artist's Principled BSDF reaches (what the add-on's outputs there render instead).
SKIN_OUTPUT_PROP = "spectral_skin_sss_skin_output"


#: Custom property on the add-on's copy of an artist's Mix Shader or Add Shader layer (:func:`_copy_chain`): the name
#: of the artist's node it copies (its Principled BSDF side, the index in ``INNER_PROP``, is the group's).
LAYER_OF_PROP = "spectral_skin_sss_layer_of"


def _copy_chain(tree: bpy.types.NodeTree, chain: list[tuple[bpy.types.Node, int]], socket: bpy.types.NodeSocket,
                near: bpy.types.Node, row: int) -> bpy.types.NodeSocket:
    """A tagged copy of the layer nodes of ``chain`` (:func:`shader_chain`), the Principled BSDF's side fed by
    ``socket`` and every other input linked from, or set to, what the artist's node has; its top output."""
    feed = socket
    for depth, (node, index) in enumerate(reversed(chain)):
        copy = tag(tree.nodes.new(node.bl_idname))
        copy[LAYER_OF_PROP], copy[INNER_PROP] = node.name, index
        copy.label = f"{node.label or node.name} (Spectral Skin SSS)"
        copy.location = (near.location.x + 220.0 * (depth + 1), near.location.y - 220.0 * row - 120.0)
        copy.parent = near.parent
        for i, (theirs, ours) in enumerate(zip(node.inputs, copy.inputs, strict=True)):
            if i == index:
                tree.links.new(feed, ours)
            else:
                take_input(tree, theirs, ours)
        feed = copy.outputs[0]
    return feed


def _copies_below(socket: bpy.types.NodeSocket) -> tuple[list[bpy.types.Node], bpy.types.NodeSocket | None]:
    """The add-on's copies of the artist's layers (:func:`_copy_chain`) feeding the render output's input
    ``socket``, top first, and the socket under the lowest (what the group's side of the chain is: the group, or
    the layers over it; :func:`_group_side`), a copy being any of the add-on's Mix or Add Shaders there but its base
    layers'."""
    copies, feed = [], feeding_socket(socket)
    while feed is not None and is_added(feed.node) and feed.node.bl_idname in LAYER_NODES \
            and BASE_LAYER_PROP not in feed.node:
        copies.append(feed.node)
        feed = _group_side(feed.node)
    return copies, feed


def render_sockets(tree: bpy.types.NodeTree) -> list[bpy.types.NodeSocket]:
    """What Cycles and EEVEE render in ``tree``: in a material's tree the Surface of the Material Output of each
    target (those of exactly that target), in an artist's node group the Group Output's inputs the add-on added
    (:data:`GROUP_OUTPUTS`)."""
    if not tree.is_embedded_data:
        gout = group_output(tree)
        return [s for s in gout.inputs if s.name in GROUP_OUTPUTS.values()] if gout is not None else []
    outputs = [render_output(tree, target) for target in ("CYCLES", "EEVEE")]
    return [out.inputs["Surface"] for out, target in zip(outputs, ("CYCLES", "EEVEE"), strict=True)
            if out is not None and out.target == target]


def chain_copies(tree: bpy.types.NodeTree) -> list[bpy.types.Node]:
    """The add-on's copies of the artist's layers (:func:`_copy_chain`) that feed what Cycles and EEVEE render."""
    copies = []
    for socket in render_sockets(tree):
        copies += [n for n in _copies_below(socket)[0] if n not in copies]
    return copies


def retake_chain(tree: bpy.types.NodeTree) -> None:
    """Give each copy of the artist's layers what the artist's node has now, but its group side (a Mix Shader's
    factor changed, a mask linked): values and links in place, no node made or removed."""
    for copy in chain_copies(tree):
        original = tree.nodes.get(copy.get(LAYER_OF_PROP, ""))
        if original is None or original.bl_idname != copy.bl_idname:
            continue
        for i, (theirs, ours) in enumerate(zip(original.inputs, copy.inputs, strict=True)):
            if i != copy.get(INNER_PROP):
                take_input(tree, theirs, ours, animated=bool(animation(ours)))


def _ours(socket: bpy.types.NodeSocket) -> bool:
    """Whether ``socket`` is an output of the add-on's: of a node it added, or one it added to an artist's node
    group (:data:`GROUP_OUTPUTS`)."""
    return is_added(socket.node) or (socket.node.bl_idname == "ShaderNodeGroup"
                                     and socket.name in GROUP_OUTPUTS.values())


def recopy_chain(tree: bpy.types.NodeTree, chain: Chain, near: bpy.types.Node) -> None:
    """Replace the copies of the artist's layers over what Cycles and EEVEE render (:func:`render_sockets`) with
    copies of ``chain`` (:func:`skin_chain`: the artist added, removed or reordered a layer over the skin since
    wiring), placed beside ``near``."""
    for row, socket in enumerate(render_sockets(tree)):
        copies, bottom = _copies_below(socket)
        if bottom is None or not _ours(bottom):
            continue  # not the add-on's: nothing of it to put layers over
        for node in copies:
            tree.nodes.remove(node)
        tree.links.new(_copy_chain(tree, chain, bottom, near, row) if chain else bottom, socket)


def feed_render_outputs(material: bpy.types.Material, sockets: dict[str, bpy.types.NodeSocket],
                        near: bpy.types.Node, chain: list[tuple[bpy.types.Node, int]] | None = None
                        ) -> list[bpy.types.Node]:
    """Make ``sockets[target]`` ("CYCLES", "EEVEE") what that renderer renders (module docstring): a new, tagged
    Material Output of that target beside ``near`` (the group node), taking the Volume, Displacement and Thickness of
    the artist's output that renderer used (:func:`take_output_inputs`), or the artist's output of that target with
    its Surface link replaced (and recorded); through a copy of the layers of ``chain`` (:func:`shader_chain`) where the
    artist's Principled BSDF reaches the output through some.  Returns the outputs fed."""
    tree = material.node_tree
    fed = []
    for i, (target, socket) in enumerate(sockets.items()):
        if chain:
            socket = _copy_chain(tree, chain, socket, near, i)
        exact = [n for n in _outputs(tree) if n.target == target and not is_added(n)]
        source = artist_output(tree, target)  # what renders now: its displacement, volume and thickness stay
        if exact:
            out = render_output(tree, target)
            for link in list(out.inputs["Surface"].links):
                _record_replaced(material, link)
                tree.links.remove(link)
        else:
            out = tag(tree.nodes.new("ShaderNodeOutputMaterial"))
            out.target = target
            out.label = OUTPUT_LABELS[target]
            out.location = (near.location.x + 300.0, near.location.y - 220.0 * i)
            out.parent = near.parent
            out.is_active_output = False
            if source is not None:
                take_output_inputs(tree, source, out)
        tree.links.new(socket, out.inputs["Surface"])
        fed.append(out)
    return fed


def feed_group_outputs(tree: bpy.types.NodeTree, sockets: dict[str, bpy.types.NodeSocket], near: bpy.types.Node,
                       chain: Chain | None = None) -> None:
    """Make ``sockets[target]`` ("CYCLES", "EEVEE") what the artist's node group ``tree`` gives at its output
    :data:`GROUP_OUTPUTS` ``[target]`` (added to its interface where it has none), through a copy of the layers of
    ``chain`` (its layers between the skin and the Group Output) placed beside ``near``.  An output already fed
    (the node group wired for another material) is left as it is."""
    gout = group_output(tree)
    for i, (target, socket) in enumerate(sockets.items()):
        name = GROUP_OUTPUTS[target]
        if gout.inputs.get(name) is None:
            tree.interface.new_socket(name, in_out="OUTPUT", socket_type="NodeSocketShader")
        elif gout.inputs[name].is_linked:
            continue
        tree.links.new(_copy_chain(tree, chain, socket, near, i) if chain else socket, gout.inputs[name])


def added_outputs_of(node: bpy.types.Node) -> dict[str, bpy.types.NodeSocket]:
    """The outputs the add-on added to the node group of the group node ``node`` (:data:`GROUP_OUTPUTS`), by the
    renderer whose output each feeds."""
    return {target: node.outputs[name] for target, name in GROUP_OUTPUTS.items()}


def _added_outputs(tree: bpy.types.NodeTree) -> list:
    """The interface outputs of the node group ``tree`` that the add-on added (:data:`GROUP_OUTPUTS`)."""
    return [item for item in tree.interface.items_tree if item.item_type == "SOCKET" and item.in_out == "OUTPUT"
            and item.name in GROUP_OUTPUTS.values()]


def _group_in_use(tree: bpy.types.NodeTree) -> bool:
    """Whether a material, or a node group holding it, renders an output the add-on added to the node group
    ``tree`` (a link from it)."""
    trees = [m.node_tree for m in bpy.data.materials if m.node_tree is not None] + list(bpy.data.node_groups)
    return any(node.bl_idname == "ShaderNodeGroup" and node.node_tree == tree
               and any(out.is_linked for out in node.outputs if out.name in GROUP_OUTPUTS.values())
               for holder in trees for node in holder.nodes)


def grouped_group_node(tree: bpy.types.NodeTree) -> bpy.types.Node | None:
    """The add-on's group node inside the artist's node group ``tree`` (:func:`feed_group_outputs`), or None."""
    return next((n for n in tree.nodes if is_added(n) and SKIN_OUTPUT_PROP in n), None)


def unwire_group(tree: bpy.types.NodeTree) -> int:
    """Take the add-on's nodes and outputs out of the artist's node group ``tree`` (the group is then exactly the
    artist's again); returns how many nodes were removed."""
    ours = [n for n in tree.nodes if is_added(n)]
    for node in ours:
        tree.nodes.remove(node)
    for item in _added_outputs(tree):
        tree.interface.remove(item)
    return len(ours)


def unwire_unused_groups() -> int:
    """:func:`unwire_group` for each artist's node group that the add-on wired and nothing renders through any more
    (its last material's add-on nodes removed, its group node deleted, or the node group around it unwired: until
    none is left); returns the nodes removed."""
    removed = 0
    while unused := [tree for tree in bpy.data.node_groups
                     if tree.is_editable and _added_outputs(tree) and not _group_in_use(tree)]:
        removed += sum(unwire_group(tree) for tree in unused)
    return removed


#: Custom property on a layer's nodes (module docstring, "Metal and glass"): the Principled BSDF input it is for.
BASE_LAYER_PROP = "spectral_skin_sss_base_layer"
#: Custom property on a layer's Mix or Add Shader: the index of its input that the group's side comes in.
INNER_PROP = "spectral_skin_sss_inner"


class Layer(NamedTuple):
    """A part of the Principled BSDF that a group does not render, put over it in the material: ``name`` the
    Principled BSDF input that weights it; ``node`` the shader node that mixes it in ("ShaderNodeMixShader" by
    ``name``, or "ShaderNodeAddShader"); ``inner`` that node's input the group's side comes in; ``shader`` what
    is mixed in (a copy of the Principled BSDF with ``settings``, a Transparent BSDF or an Emission);
    ``baked_only``: for the mixture group of baked maps alone (the live group renders it itself)."""

    name: str
    node: str
    inner: int
    shader: str
    settings: dict
    baked_only: bool

    def needed(self, principled: bpy.types.Node) -> bool:
        """Whether ``principled`` asks for this layer: its input linked, or away from where the layer is nothing
        (Subsurface Weight 0 unlinked is Blender's default, never switched on: the skin, as the operator asks)."""
        socket = principled.inputs.get(self.name)
        if socket is None:
            return False
        if feeding_socket(socket) is not None or animation(socket):
            return True
        value = socket.default_value
        return {"Subsurface Weight": 0.0 < value < 1.0, "Alpha": value < 1.0}.get(self.name, value > 0.0)


_OPAQUE = {"Metallic": 0.0, "Transmission Weight": 0.0, "Subsurface Weight": 0.0}
#: The layers, innermost first, in the Principled BSDF's order: its diffuse body (Subsurface Weight below 1), its
#: glass and metal bases, then its emission and alpha on top.
LAYERS = (Layer("Subsurface Weight", "ShaderNodeMixShader", 2, "ShaderNodeBsdfPrincipled", _OPAQUE, True),
          Layer("Transmission Weight", "ShaderNodeMixShader", 1, "ShaderNodeBsdfPrincipled",
                {**_OPAQUE, "Transmission Weight": 1.0}, False),
          Layer("Metallic", "ShaderNodeMixShader", 1, "ShaderNodeBsdfPrincipled", {**_OPAQUE, "Metallic": 1.0}, False),
          Layer("Emission Strength", "ShaderNodeAddShader", 0, "ShaderNodeEmission", {}, True),
          Layer("Alpha", "ShaderNodeMixShader", 2, "ShaderNodeBsdfTransparent", {}, True))


#: The input of a layer's Mix or Add Shader that takes what is mixed in, by the one the group's side comes in.
_OTHER_SIDE = {0: 1, 1: 2, 2: 1}


def _baked(gnode: bpy.types.Node) -> bool:
    """Whether the group node ``gnode`` is the mixture group of baked maps, which has no Subsurface Weight, Alpha or
    Emission inputs (the live group has them)."""
    return "Alpha" not in gnode.inputs


def base_layers(principled: bpy.types.Node, gnode: bpy.types.Node) -> list[Layer]:
    """The :data:`LAYERS` that ``principled`` asks for and the group node ``gnode`` does not render itself."""
    return [layer for layer in LAYERS if (_baked(gnode) or not layer.baked_only) and layer.needed(principled)]


def _layer_shader(tree: bpy.types.NodeTree, principled: bpy.types.Node, layer: Layer, baked: bool,
                  near: bpy.types.Node, row: int) -> bpy.types.Node:
    """The tagged shader node that ``layer`` mixes in (:func:`_take_layer_inputs`)."""
    node = tag(tree.nodes.new(layer.shader))
    node[BASE_LAYER_PROP] = layer.name
    node.label = f"{layer.name} (Spectral Skin SSS)"
    node.location = (near.location.x, near.location.y - 700.0 - 620.0 * row)
    node.parent = near.parent
    _take_layer_inputs(tree, principled, node, baked)
    return node


def _take_layer_inputs(tree: bpy.types.NodeTree, principled: bpy.types.Node, node: bpy.types.Node,
                       baked: bool) -> None:
    """Give a layer's node what the artist's Principled BSDF has: a copy of it takes its layer's settings (and,
    over baked maps, no emission and full alpha: their own layers add them once) and every other input, linked
    from or set to what the artist's node has; an Emission its Emission Color and Strength; a Mix Shader its
    input's value or link as Fac; a Transparent BSDF or an Add Shader nothing."""
    layer = next(layer for layer in LAYERS if layer.name == node[BASE_LAYER_PROP])
    if node.bl_idname == "ShaderNodeEmission":
        take_input(tree, principled.inputs["Emission Color"], node.inputs["Color"], animated=True)
        take_input(tree, principled.inputs["Emission Strength"], node.inputs["Strength"], animated=True)
    elif node.bl_idname == "ShaderNodeMixShader":
        take_input(tree, principled.inputs[layer.name], node.inputs["Fac"], animated=True)
    elif node.bl_idname == "ShaderNodeBsdfPrincipled":
        node.distribution, node.subsurface_method = principled.distribution, principled.subsurface_method
        settings = {**layer.settings, **({"Emission Strength": 0.0, "Alpha": 1.0} if baked else {})}
        for theirs, ours in zip(principled.inputs, node.inputs, strict=True):
            if ours.name in settings:
                clear_animation(ours)
                ours.default_value = settings[ours.name]
            else:
                take_input(tree, theirs, ours, animated=True)


def _layer_nodes(tree: bpy.types.NodeTree) -> list[bpy.types.Node]:
    """The nodes of the layers (:func:`insert_base_layers`) in ``tree``."""
    return [node for node in tree.nodes if BASE_LAYER_PROP in node and is_added(node)]


def present_layers(tree: bpy.types.NodeTree) -> set[str]:
    """The names of the layers (:data:`LAYERS`) whose nodes are in ``tree``."""
    return {node[BASE_LAYER_PROP] for node in _layer_nodes(tree)}


def retake_base_layers(tree: bpy.types.NodeTree, principled: bpy.types.Node, gnode: bpy.types.Node) -> None:
    """Give the nodes of the layers in ``tree`` what the artist's Principled BSDF has now (an input changed, the
    same layers still asked for): values and links in place, no node made or removed."""
    for node in _layer_nodes(tree):
        _take_layer_inputs(tree, principled, node, _baked(gnode))


def insert_base_layers(tree: bpy.types.NodeTree, principled: bpy.types.Node, gnode: bpy.types.Node) -> int:
    """Put each of :func:`base_layers` over every shader output link of the group node ``gnode``, innermost first
    (module docstring, "Metal and glass"); returns how many layers were inserted."""
    layers, baked = base_layers(principled, gnode), _baked(gnode)
    shaders = {layer.name: _layer_shader(tree, principled, layer, baked, gnode, row)
               for row, layer in enumerate(layers)}
    shader_links = [ln for out in gnode.outputs if out.type == "SHADER" for ln in out.links if not ln.is_muted]
    for index, link in enumerate(shader_links):
        feed, target = link.from_socket, link.to_socket
        tree.links.remove(link)
        for depth, layer in enumerate(layers):
            node = tag(tree.nodes.new(layer.node))
            node[BASE_LAYER_PROP], node[INNER_PROP] = layer.name, layer.inner
            node.label = f"{layer.name} (Spectral Skin SSS)"
            node.location = (gnode.location.x + 200.0 * (depth + 1), gnode.location.y - 700.0 - 150.0 * index)
            node.parent = gnode.parent
            _take_layer_inputs(tree, principled, node, baked)
            tree.links.new(feed, node.inputs[layer.inner])
            tree.links.new(shaders[layer.name].outputs[0], node.inputs[_OTHER_SIDE[layer.inner]])
            feed = node.outputs[0]
        tree.links.new(feed, target)
    return len(layers)


def layer_inner(node: bpy.types.Node) -> bpy.types.NodeSocket | None:
    """The input of a layer's Mix or Add Shader (:func:`insert_base_layers`) that the group's side comes in, or
    None for any other node."""
    index = node.get(INNER_PROP) if is_added(node) else None
    return node.inputs[index] if index is not None else None


def _group_side(node: bpy.types.Node) -> bpy.types.NodeSocket | None:
    """What feeds the group's side of one of the add-on's Mix or Add Shaders (a layer's, :func:`insert_base_layers`,
    or a copy of the artist's layers, :func:`_copy_chain`): the input its ``INNER_PROP`` names, else (a copy made
    before copies were marked) its shader input fed by another of the add-on's nodes; None where no output of the
    add-on's (:func:`_ours`) feeds it."""
    inner = layer_inner(node)
    sockets = [inner] if inner is not None else [s for s in node.inputs if s.type == "SHADER"]
    return next((feed for socket in sockets if (feed := feeding_socket(socket)) is not None and _ours(feed)), None)


def remove_base_layers(tree: bpy.types.NodeTree) -> int:
    """Take the layers of :func:`insert_base_layers` out again, each Mix or Add Shader's group side linked where it
    fed; returns how many nodes were removed."""
    ours = _layer_nodes(tree)
    joins = [n for n in ours if INNER_PROP in n]
    shaders = [n for n in ours if INNER_PROP not in n]
    for join in joins:
        inner = feeding_socket(layer_inner(join))
        targets = [ln.to_socket for ln in join.outputs[0].links]
        tree.nodes.remove(join)
        for target in targets if inner is not None else ():
            tree.links.new(inner, target)
    for shader in shaders:
        tree.nodes.remove(shader)
    return len(ours)


# -- finding and removing the add-on's nodes --------------------------------------------------------------------
def is_addon_group(tree: bpy.types.NodeTree | None) -> bool:
    return tree is not None and (_GROUP_TAG in tree or "spectral_skin_sss_k" in tree or EDIT_TABLE_PROP in tree)


def _legacy_nodes(tree: bpy.types.NodeTree) -> set[str]:
    """Names of the add-on's nodes in a material wired before the tags: its frames, the nodes in them, its group
    nodes and its EEVEE output."""
    frames = {n.name for n in tree.nodes if n.bl_idname == "NodeFrame" and n.label == FRAME_LABEL}
    names = set(frames)
    for node in tree.nodes:
        if node.parent is not None and node.parent.name in frames:
            names.add(node.name)
        elif node.bl_idname == "ShaderNodeGroup" and is_addon_group(node.node_tree):
            names.add(node.name)
        elif node.bl_idname == "ShaderNodeOutputMaterial" and node.label == _LEGACY_OUTPUT_LABEL:
            names.add(node.name)
    return names


def added_nodes(material: bpy.types.Material) -> list[bpy.types.Node]:
    """The add-on's nodes in ``material`` (tagged, or those of an earlier layout)."""
    tree = material.node_tree
    if tree is None:
        return []
    names = {n.name for n in tree.nodes if is_added(n)} | _legacy_nodes(tree)
    return [n for n in tree.nodes if n.name in names]


def wired_group_node(material: bpy.types.Material) -> bpy.types.Node | None:
    """The add-on's group node that Cycles renders in ``material`` (through its Cycles output, straight or through
    the add-on's copy of the artist's layers, or inside the artist's node group holding the skin through the output
    the add-on added there: :data:`GROUP_OUTPUTS`), or None."""
    tree = material.node_tree
    out = render_output(tree, "CYCLES") if tree is not None else None
    return _group_below(out.inputs["Surface"]) if out is not None else None


def material_nodes(material: bpy.types.Material) -> list[bpy.types.Node]:
    """The nodes of ``material``'s tree, and the add-on's group node that renders it from inside an artist's node
    group (:func:`wired_group_node`), where it is there."""
    found = list(material.node_tree.nodes)
    wired = wired_group_node(material)
    if wired is not None and wired.id_data != material.node_tree:
        found.append(wired)
    return found


def _group_below(socket: bpy.types.NodeSocket) -> bpy.types.Node | None:
    """The add-on's group node feeding ``socket`` through the add-on's Mix and Add Shaders (:func:`_group_side`), and
    into an artist's node group through an output the add-on added there; None where there is none."""
    links = [ln for ln in socket.links if not ln.is_muted]
    feed = links[0].from_socket if links else None
    while feed is not None:
        node = feed.node
        if node.bl_idname in LAYER_NODES and is_added(node):
            feed = _group_side(node)
        elif node.bl_idname == "ShaderNodeGroup" and is_addon_group(node.node_tree):
            return node
        elif node.bl_idname == "ShaderNodeGroup" and feed.name in GROUP_OUTPUTS.values() and node.node_tree:
            gout = group_output(node.node_tree)
            inner = gout.inputs.get(feed.name) if gout is not None else None
            feed = feeding_socket(inner) if inner is not None else None
        else:
            return None
    return None


def unwire(material: bpy.types.Material) -> int:
    """Remove the add-on's nodes from ``material`` and put back the links they replaced (module docstring); returns
    how many nodes and material properties of the add-on's were removed (0: none was there, nothing changed)."""
    tree = material.node_tree
    ours = added_nodes(material)
    if not ours and not any(p in material for p in MATERIAL_PROPS):
        return 0
    out = active_output(tree)
    legacy_fed = out is not None and any(ln.from_node in ours for ln in out.inputs["Surface"].links)
    previous = material.get(PREVIOUS_SURFACE_PROP)
    replaced = json.loads(material.get(REPLACED_LINKS_PROP, "[]"))
    for node in ours:
        tree.nodes.remove(node)
    for link in replaced:
        relink(tree, link["from_node"], link["from_socket"], link["to_node"], link["to_socket"])
    if legacy_fed and previous in tree.nodes and not out.inputs["Surface"].is_linked:
        tree.links.new(tree.nodes[previous].outputs[0], out.inputs["Surface"])
    restore_shadow_thickness(material)
    props = [p for p in MATERIAL_PROPS if p in material]
    for prop in props:
        del material[prop]
    return len(ours) + len(props) + unwire_unused_groups()


def use_shadow_thickness(material: bpy.types.Material) -> None:
    """Turn on EEVEE's Thickness From Shadow for ``material`` (module docstring, "EEVEE's thickness"), the artist's
    value recorded for :func:`unwire` (the first one: wiring again keeps it)."""
    if THICKNESS_FROM_SHADOW_PROP not in material:
        material[THICKNESS_FROM_SHADOW_PROP] = int(material.use_thickness_from_shadow)
    if not material.use_thickness_from_shadow:
        material.use_thickness_from_shadow = True


def restore_shadow_thickness(material: bpy.types.Material) -> None:
    """Put back the artist's Thickness From Shadow that :func:`use_shadow_thickness` recorded, and drop the record."""
    if THICKNESS_FROM_SHADOW_PROP in material:
        material.use_thickness_from_shadow = bool(material.pop(THICKNESS_FROM_SHADOW_PROP))


def relink(tree: bpy.types.NodeTree, from_node: str, from_id: str, to_node: str, to_id: str) -> None:
    """The link (from_node.from_id -> to_node.to_id), when both nodes and sockets still exist."""
    source, target = tree.nodes.get(from_node), tree.nodes.get(to_node)
    if source is None or target is None:
        return
    src = next((s for s in source.outputs if s.identifier == from_id), None)
    dst = next((s for s in target.inputs if s.identifier == to_id), None)
    if src is not None and dst is not None:
        tree.links.new(src, dst)


def purge_unused() -> tuple[int, int]:
    """Remove the add-on's node groups and images (the live group's table images, baked maps) that nothing uses
    any more; returns (groups, images) removed."""
    groups = 0
    removed = True
    while removed:  # a live group holds the mixture group: free the outer one first
        removed = False
        for group in [g for g in bpy.data.node_groups if is_addon_group(g) and g.users == 0]:
            bpy.data.node_groups.remove(group)
            groups += 1
            removed = True
    return groups, remove_unused_images(bpy.data.images)


def remove_unused_images(images) -> int:
    """Remove those of ``images`` that the add-on made (tagged: :data:`IMAGE_TAGS`) and nothing uses; returns how
    many."""
    unused = [im for im in images if any(t in im for t in IMAGE_TAGS) and im.users == 0]
    for image in unused:
        bpy.data.images.remove(image)
    return len(unused)


def packed_table_image(name: str, pixels: np.ndarray, tag_prop: str, tag_value: str) -> bpy.types.Image:
    """A new packed float RGBA image ``name`` holding ``pixels`` (shape (height, width, 4), rows bottom to top, data:
    Non-Color, alpha a fourth channel of data), tagged ``image[tag_prop] = tag_value`` so that :func:`purge_unused`
    removes it when no material uses it; an unused image of that name is removed first (one in use is kept and the
    new image gets Blender's next free name)."""
    old = bpy.data.images.get(name)
    if old is not None and old.users == 0:
        bpy.data.images.remove(old)
    image = bpy.data.images.new(name, pixels.shape[1], pixels.shape[0], alpha=True, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.alpha_mode = "CHANNEL_PACKED"
    image.pixels.foreach_set(pixels.ravel())
    image.pack()
    image[tag_prop] = tag_value
    return image


def rewrite_table_image(image: bpy.types.Image, pixels: np.ndarray) -> None:
    """Replace the pixels of a float RGBA image of :func:`packed_table_image` with ``pixels`` (height, width, 4),
    resized to them, and pack it again (the .blend keeps the new pixels)."""
    height, width = pixels.shape[:2]
    if tuple(image.size) != (width, height):
        image.scale(width, height)
    image.pixels.foreach_set(np.ascontiguousarray(pixels, np.float32).ravel())
    image.pack()
