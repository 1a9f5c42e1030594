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
An input with keyframes or a driver is recorded by a digest of them: the group's input carries a copy
(blender_addon.wiring.copy_animation), which Blender animates with the frame where no handler runs, and which is
made again when the keys change.

The scene's Unit Scale (metres per Blender unit, Scene ▸ Units) is followed the same way: the record holds the one
the group's radii were given (``record[UNIT_SCALE]``), and where the scene's changes (a model set to centimetres
after inverting, a skin material appended from a library into a scene of other units) the live group's Unit Scale
input takes it.  A material used in scenes of different Unit Scales takes that of the scene last changed.  Baked
maps hold their radii in the units they were baked for: :func:`baked_unit_scale_stale` says when the scene's differs
(the panel asks for another bake).

The layers for what the group does not render (blender_addon.wiring, "Metal and glass": metal and glass, and over
baked maps the diffuse body, emission and alpha) take the Principled BSDF's inputs: the record holds what they took
(``record[BASE_LAYERS]``, every input), and where that changes, or an input starts or stops asking for a layer,
they are renewed, put in or taken out.

The add-on's copies of the artist's Mix Shader and Add Shader layers over the Principled BSDF (a sweat layer, a
glow) follow the artist's (``record[LAYERS]``): a factor changed or a mask linked goes to the same copies; a layer
added, removed or reordered is copied again.

Where the Principled BSDF sits in an artist's node group (blender_addon.wiring, "Grouped skin shaders"), the group
node and the layers over it are in that node group, where its inputs are taken; the copies of the artist's layers
between the skin and each node group's output follow the same way (``record[GROUP_LAYERS]``).

The Material Outputs the add-on added for Cycles and EEVEE take the Displacement, Volume and Thickness of the
artist's output (``record[OUTPUT]``): a displacement map linked, or a Thickness changed, after wiring reaches them.
"""

from __future__ import annotations

import hashlib
import json

import bpy

from . import live, nodes, wiring

#: The Principled BSDF's inputs the live group takes, by the group input each feeds.
FOLLOWED = {"Color": "Base Color", **{name: name for name in nodes.TAKEN_INPUTS}}
#: The record's entry for the scene's Unit Scale, and the live group's input that takes it.
UNIT_SCALE = "Unit Scale"
#: The record's entry for what the layers over the group took from the Principled BSDF (blender_addon.wiring,
#: "Metal and glass"): every input of it, by identifier.
BASE_LAYERS = "Base layers"
#: The record's entry for what the add-on's Material Outputs took from the artist's (blender_addon.wiring,
#: OUTPUT_INPUTS: Displacement, Volume, Thickness), by the output's target and input name.
OUTPUT = "Material Output"
#: The record's entry for the artist's Mix Shader and Add Shader layers over the Principled BSDF, which the add-on's
#: copies follow (blender_addon.wiring, "Layered materials"): per layer, output side first, its node's name, the
#: index of its input the Principled BSDF's side comes in, and what each other input gives.
LAYERS = "Layers"
#: The record's entry for the artist's layers inside the node groups holding the Principled BSDF, between the skin and
#: each group's output (blender_addon.wiring, "Grouped skin shaders"): by node group name, as :data:`LAYERS`.
GROUP_LAYERS = "Group layers"


def scene_unit_scale(scene: bpy.types.Scene) -> float:
    """Metres per Blender unit: the scene's Unit Scale (Scene ▸ Units), 1 when the unit system is None (Blender
    then greys the Unit Scale out and lengths are plain numbers)."""
    units = scene.unit_settings
    return float(units.scale_length or 1.0) if units.system != "NONE" else 1.0


def _unit_state(unit_scale_m: float) -> list:
    """The record's entry for a Unit Scale (metres per Blender unit), rounded like a recorded value."""
    return ["value", round(float(unit_scale_m), 6)]


def _state(socket: bpy.types.NodeSocket) -> list:
    """What an input of the Principled BSDF gives: ["link", node, socket identifier], ["animated", digest of its
    keyframes and driver] or ["value", value]."""
    feed = wiring.feeding_socket(socket)
    if feed is not None:
        return ["link", feed.node.name, feed.identifier]
    if not hasattr(socket, "default_value"):  # a shader input: linked or nothing
        return ["value", None]
    curves = wiring.animation(socket)
    if curves:
        return ["animated", hashlib.sha256(repr([_curve_state(curve) for curve in curves]).encode()).hexdigest()]
    value = socket.default_value
    value = [round(float(v), 6) for v in value] if hasattr(value, "__len__") else round(float(value), 6)
    return ["value", value]


def _curve_state(curve: bpy.types.FCurve) -> tuple:
    """What an F-curve animates a value by: its index, extrapolation and keyframes, or its driver."""
    if curve.driver is not None:
        driver = curve.driver
        return (curve.array_index, driver.type, driver.expression,
                [(v.name, v.type, [(t.id_type, t.id.name if t.id else "", t.data_path, t.transform_type)
                                   for t in v.targets]) for v in driver.variables])
    return (curve.array_index, curve.extrapolation,
            [(tuple(k.co), tuple(k.handle_left), tuple(k.handle_right), k.interpolation, k.easing)
             for k in curve.keyframe_points])


def _principled_and_group(material: bpy.types.Material) -> tuple[bpy.types.Node, bpy.types.Node] | None:
    """The artist's Principled BSDF and the group node that renders in its place (the live group, or the mixture
    group of baked maps, which takes the same inputs but Base Color), or None (not wired, or either gone)."""
    gnode = wiring.wired_group_node(material)
    if gnode is None or not (live.TABLE_PROP in gnode.node_tree or "spectral_skin_sss_k" in gnode.node_tree):
        return None
    principled = wiring.artist_principled(material)  # in the group node's tree, or maps baked over a node group
    return (principled, gnode) if principled is not None and principled.id_data == gnode.id_data else None


def record(material: bpy.types.Material, unit_scale_m: float) -> None:
    """Record what the group took from the Principled BSDF and the Unit Scale (metres per Blender unit) its radii
    were given (called when it is wired, live or baked)."""
    found = _principled_and_group(material)
    if found is not None:
        principled, gnode = found
        taken = {ours: _state(nodes.taken_socket(principled, theirs)) for ours, theirs in FOLLOWED.items()
                 if ours in gnode.inputs and theirs in principled.inputs}
        taken[UNIT_SCALE] = _unit_state(unit_scale_m)
        if wiring.base_layers(principled, gnode):
            taken[BASE_LAYERS] = _base_state(principled)
        taken[OUTPUT] = _output_state(material.node_tree)
        layers = _layers_state(material.node_tree)
        if layers is not None:
            taken[LAYERS] = layers
        groups = _wired_groups(_grouped(material, gnode), gnode)
        if groups:
            taken[GROUP_LAYERS] = {tree.name: _layers_state(tree) for tree, _ in groups}
        material[wiring.TAKEN_INPUTS_PROP] = json.dumps(taken)


def _grouped(material: bpy.types.Material, gnode: bpy.types.Node) -> wiring.GroupedSkin | None:
    """The artist's node group node holding the skin that the add-on's group node ``gnode`` sits in
    (wiring.grouped_skin), or None where ``gnode`` is in the material's own tree."""
    return wiring.grouped_skin(material.node_tree) if gnode.id_data != material.node_tree else None


def _wired_groups(skin: wiring.GroupedSkin | None,
                  gnode: bpy.types.Node) -> list[tuple[bpy.types.NodeTree, bpy.types.Node]]:
    """The artist's node groups the add-on wired for the grouped ``skin`` (:func:`_grouped`), outermost first, each
    with the node beside which its copies of the artist's layers go (the nested node group node holding the skin, or
    in the innermost ``gnode``, the add-on's group node); empty for a flat material (``skin`` None)."""
    if skin is None:
        return []
    trees = [skin.node.node_tree, *(level.node.node_tree for level in skin.levels)]
    return list(zip(trees, [*(level.node for level in skin.levels), gnode], strict=True))


def _layers_state(tree: bpy.types.NodeTree) -> list | None:
    """The artist's layers over the skin in ``tree`` (wiring.skin_chain) as the record holds them (:data:`LAYERS`);
    None where the add-on's nodes feed the active output (the chain there is not the artist's to read)."""
    if tree.is_embedded_data and wiring.addon_feeds_active_output(tree):
        return None
    return [[node.name, index, [_state(s) for i, s in enumerate(node.inputs) if i != index]]
            for node, index in wiring.skin_chain(tree)]


def _follow_layers(tree: bpy.types.NodeTree, near: bpy.types.Node, taken: dict, key: str = LAYERS) -> bool:
    """Give the add-on's copies of the artist's layers in ``tree`` what changed on the artist's since ``taken[key]``
    (updated): in place where the same layers are there, else copied again beside ``near``; whether anything
    changed."""
    now = _layers_state(tree)
    if now is None or taken.get(key) == now:
        return False
    before = taken.get(key)
    if before is not None and [layer[:2] for layer in before] == [layer[:2] for layer in now]:
        wiring.retake_chain(tree)
    else:
        wiring.recopy_chain(tree, wiring.skin_chain(tree), near)
    taken[key] = now
    return True


def _output_state(tree: bpy.types.NodeTree) -> dict[str, dict[str, list]]:
    """What the artist's Material Outputs that the add-on's take from give at wiring.OUTPUT_INPUTS (:func:`_state`),
    by the target of the add-on's output (wiring.output_sources); empty where the add-on added none."""
    return {out.target: {name: _state(source.inputs[name]) for name in wiring.OUTPUT_INPUTS if name in source.inputs}
            for out, source in wiring.output_sources(tree)}


def _base_state(principled: bpy.types.Node) -> dict[str, list]:
    """What every input of the Principled BSDF gives (:func:`_state`), by identifier: what its copies take."""
    return {socket.identifier: _state(socket) for socket in principled.inputs}


def _follow_base_layers(tree: bpy.types.NodeTree, principled: bpy.types.Node, gnode: bpy.types.Node,
                        taken: dict) -> bool:
    """Put in, take out or renew the layers over the group (blender_addon.wiring, "Metal and glass") where the
    Principled BSDF's inputs changed since ``taken`` (updated); whether anything changed."""
    needed = {layer.name for layer in wiring.base_layers(principled, gnode)}
    present = wiring.present_layers(tree)
    if not needed and not present:
        return False
    state = _base_state(principled)
    if needed == present:  # the same layers: their inputs follow in place (an animated Metallic makes no nodes)
        if taken.get(BASE_LAYERS) == state:
            return False
        wiring.retake_base_layers(tree, principled, gnode)
    else:
        wiring.remove_base_layers(tree)
        if needed:
            wiring.insert_base_layers(tree, principled, gnode)
    if needed:
        taken[BASE_LAYERS] = state
    else:
        taken.pop(BASE_LAYERS, None)
    return True


def follow(material: bpy.types.Material, unit_scale_m: float | None = None) -> list[str]:
    """Give the group of ``material`` every input that changed on the Principled BSDF since it was recorded, and the
    live group the scene's Unit Scale ``unit_scale_m`` (metres per Blender unit; None: not followed) where it
    differs from the recorded one (module docstring); returns the group inputs changed."""
    found = _principled_and_group(material)
    if found is None or wiring.TAKEN_INPUTS_PROP not in material or not material.is_editable:
        return []
    principled, gnode = found
    taken = json.loads(material[wiring.TAKEN_INPUTS_PROP])
    tree = material.node_tree
    inner = gnode.id_data  # where the group node and the Principled BSDF are: the material's tree or a node group
    changed = []
    unit = gnode.inputs.get(UNIT_SCALE)  # the live group's; the maps of a bake hold theirs
    if unit_scale_m is not None and unit is not None and taken.get(UNIT_SCALE) != _unit_state(unit_scale_m):
        unit.default_value = unit_scale_m
        taken[UNIT_SCALE] = _unit_state(unit_scale_m)
        changed.append(UNIT_SCALE)
    for ours, theirs in FOLLOWED.items():
        if ours not in gnode.inputs or theirs not in principled.inputs:
            continue
        source = nodes.taken_socket(principled, theirs)
        now = _state(source)
        if taken.get(ours) == now:
            continue
        wiring.take_input(inner, source, gnode.inputs[ours],
                          animated=taken.get(ours, [None])[0] == "animated")
        taken[ours] = now
        changed.append(ours)
    if _follow_base_layers(inner, principled, gnode, taken):
        changed.append(BASE_LAYERS)
    skin = _grouped(material, gnode)  # the material's copies sit beside its group node
    near = gnode if inner == tree else skin.node if skin is not None else None
    if near is not None and _follow_layers(tree, near, taken):
        changed.append(LAYERS)
    inside = taken.setdefault(GROUP_LAYERS, {})
    if any([_follow_layers(group, beside, inside, group.name) for group, beside in _wired_groups(skin, gnode)]):
        changed.append(GROUP_LAYERS)
    if not inside:
        del taken[GROUP_LAYERS]
    outputs = _output_state(tree)
    if taken.get(OUTPUT, {}) != outputs:
        wiring.retake_output_inputs(tree)
        taken[OUTPUT] = outputs
        changed.append(OUTPUT)
    if changed:
        material[wiring.TAKEN_INPUTS_PROP] = json.dumps(taken)
    return changed


def baked_unit_scale_stale(material: bpy.types.Material | None, scene: bpy.types.Scene) -> float | None:
    """The Unit Scale (metres per Blender unit) the baked maps of ``material`` hold their radii in, where the
    scene's differs from it (the radii are then off by their ratio until the next bake); None otherwise (not
    baked, no record, or the same units)."""
    if material is None or wiring.TAKEN_INPUTS_PROP not in material:
        return None
    found = _principled_and_group(material)
    if found is None or UNIT_SCALE in found[1].inputs:
        return None
    baked = json.loads(material[wiring.TAKEN_INPUTS_PROP]).get(UNIT_SCALE)
    if baked is None or baked == _unit_state(scene_unit_scale(scene)):
        return None
    return float(baked[1])


_following = False
#: The Unit Scale each scene had at the handler's last call (by the scene's full name): a scene update (a selection
#: makes one) looks at every recorded material only where the units changed.
_units_seen: dict[str, float] = {}


@bpy.app.handlers.persistent
def follow_principled(scene=None, depsgraph=None) -> None:
    """depsgraph_update_post handler: :func:`follow` each changed material, or every recorded one where the
    scene's Unit Scale changed; its own writes do not call it again."""
    global _following
    if _following or depsgraph is None:
        return
    _following = True
    try:
        updated = {u.id.original for u in depsgraph.updates}
        materials = [update for update in updated if isinstance(update, bpy.types.Material)]
        unit_scale_m = scene_unit_scale(scene) if scene is not None else None
        if scene is not None and _units_seen.get(scene.name_full) != unit_scale_m:
            _units_seen[scene.name_full] = unit_scale_m
            materials = [m for m in bpy.data.materials if wiring.TAKEN_INPUTS_PROP in m]
        for material in materials:
            follow(material, unit_scale_m)
    finally:
        _following = False


@bpy.app.handlers.persistent
def follow_on_load(_filepath=None) -> None:
    """load_post handler: :func:`follow` every recorded material of the file just opened, in its scene's units, so
    what changed while the add-on was off renders at once.  A material wired by a version that kept no record gets
    one of its Principled BSDF as it is now (:func:`record`; its group is left as it is, values set on the group
    node included), so that what changes from now on follows."""
    _units_seen.clear()
    scene = bpy.context.scene
    unit_scale_m = scene_unit_scale(scene) if scene is not None else None
    for material in bpy.data.materials:
        if wiring.TAKEN_INPUTS_PROP in material:
            follow(material, unit_scale_m)
        elif material.node_tree is not None and material.is_editable and (found := _principled_and_group(material)):
            unit = found[1].inputs.get(UNIT_SCALE)
            record(material, unit.default_value if unit is not None else unit_scale_m or 1.0)


_HANDLERS = (("depsgraph_update_post", follow_principled), ("load_post", follow_on_load))


def register_handlers() -> None:
    for kind, handler in _HANDLERS:
        handlers = getattr(bpy.app.handlers, kind)
        if handler not in handlers:
            handlers.append(handler)


def unregister_handlers() -> None:
    for kind, handler in _HANDLERS:
        handlers = getattr(bpy.app.handlers, kind)
        while handler in handlers:
            handlers.remove(handler)
