"""The live group follows the artist's Principled BSDF.

After Invert Skin Albedo the artist keeps working on their Principled BSDF: a make-up or tattoo layer mixed into
Base Color, a colour correction, another texture, a normal map, a new roughness, a specular input, a painted
Subsurface Weight, Alpha or Emission.  Blender's exporters read the Principled BSDF, Cycles and EEVEE render the
group (blender_addon.wiring), so each such change reaches the group as well: the render and the export stay the
same material.

At wiring the group takes the Principled BSDF's inputs (blender_addon.nodes: a link stays a link, a value is
copied; Base Color feeds the live group's Color, baked maps hold it for the mixture group of a bake) and the
material records what it took, input by input
(``material[wiring.TAKEN_INPUTS_PROP]``, JSON: the feeding node and socket, or the value).  On each depsgraph
update of a wired material (:func:`follow_principled`, a handler) the Principled BSDF's inputs are compared with
that record, and each input that changed there is given to the group the same way, then recorded.  An input the
artist set on the group node itself stays as they set it until the same input changes on the Principled BSDF.
"""

from __future__ import annotations

import json

import bpy

from . import live, nodes, wiring

#: The Principled BSDF's inputs the live group takes, by the group input each feeds.
FOLLOWED = {"Color": "Base Color", **{name: name for name in nodes.TAKEN_INPUTS}}


def _state(socket: bpy.types.NodeSocket) -> list:
    """What an input of the Principled BSDF gives: ["link", node, socket identifier] or ["value", value]."""
    feed = wiring.feeding_socket(socket)
    if feed is not None:
        return ["link", feed.node.name, feed.identifier]
    value = socket.default_value
    value = [round(float(v), 6) for v in value] if hasattr(value, "__len__") else round(float(value), 6)
    return ["value", value]


def _principled_and_group(material: bpy.types.Material) -> tuple[bpy.types.Node, bpy.types.Node] | None:
    """The artist's Principled BSDF and the group node that renders in its place (the live group, or the mixture
    group of baked maps, which takes the same inputs but Base Color), or None (not wired, or either gone)."""
    gnode = wiring.wired_group_node(material)
    if gnode is None or not (live.TABLE_PROP in gnode.node_tree or "spectral_skin_sss_k" in gnode.node_tree):
        return None
    try:
        principled = live.colour_source(material)[0]
    except live.LiveInputError:
        return None
    return principled, gnode


def record(material: bpy.types.Material) -> None:
    """Record what the group took from the Principled BSDF (called when it is wired, live or baked)."""
    found = _principled_and_group(material)
    if found is not None:
        principled, gnode = found
        material[wiring.TAKEN_INPUTS_PROP] = json.dumps(
            {ours: _state(principled.inputs[theirs]) for ours, theirs in FOLLOWED.items()
             if ours in gnode.inputs and theirs in principled.inputs})


def follow(material: bpy.types.Material) -> list[str]:
    """Give the group of ``material`` every input that changed on the Principled BSDF since it was recorded (module
    docstring); returns the group inputs changed."""
    found = _principled_and_group(material)
    if found is None or wiring.TAKEN_INPUTS_PROP not in material or not material.is_editable:
        return []
    principled, gnode = found
    taken = json.loads(material[wiring.TAKEN_INPUTS_PROP])
    tree = material.node_tree
    changed = []
    for ours, theirs in FOLLOWED.items():
        if ours not in gnode.inputs or theirs not in principled.inputs:
            continue
        now = _state(principled.inputs[theirs])
        if taken.get(ours) == now:
            continue
        wiring.take_input(tree, principled.inputs[theirs], gnode.inputs[ours])
        taken[ours] = now
        changed.append(ours)
    if changed:
        material[wiring.TAKEN_INPUTS_PROP] = json.dumps(taken)
    return changed


_following = False


@bpy.app.handlers.persistent
def follow_principled(scene=None, depsgraph=None) -> None:
    """depsgraph_update_post handler: :func:`follow` each changed material (its own writes do not call it again)."""
    global _following
    if _following or depsgraph is None:
        return
    _following = True
    try:
        for material in {u.id.original for u in depsgraph.updates if isinstance(u.id, bpy.types.Material)}:
            follow(material)
    finally:
        _following = False


def register_handlers() -> None:
    if follow_principled not in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.append(follow_principled)


def unregister_handlers() -> None:
    while follow_principled in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(follow_principled)
