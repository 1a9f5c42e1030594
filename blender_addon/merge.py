"""One copy of the add-on's node groups and tables per file.

Every material of a file shares the add-on's node groups (the live group, its edit, grazing-light and EEVEE
groups, the mixture group) and the packed float images they read (the live group's tables, about 15 MB).  A skin
material appended from another file (File ▸ Append, an asset library's character dragged in from the Asset
Browser) brings that file's copies along: Blender suffixes their names (``Spectral Skin SSS Live.001``) and the
file then holds, and each render loads, a second set of the same tables for every file a skin came from.

:func:`merge_copies` gives each user of such a copy the file's own group (``ID.user_remap``) and removes the copy,
and the images only it read.  A group is a copy of another where it came from another file (Blender keeps a weak
reference to the file it was appended from: a copy the artist made in the file, to change it for one material, is
theirs), both are local, and they carry the same name but for Blender's numeric suffix, the same add-on properties
(version, table digests, K, backend: what the add-on's own reuse compares, ``live.ensure_live_group`` and the
others) and the same nodes and links: they render alike.  The state a group keeps per file is not compared: the
edit caches' values and the order they were filled in (blender_addon.live_edits).  A material moved onto the file's
group has its edit cached there again; until then it renders through the table, which gives the same answer.  A
group the artist changed by hand (other nodes or links) is left as it is, and so is a group linked from a library
(read-only).

Run on opening a file and on each depsgraph update where the number of node groups changed (an append makes one;
:func:`merge_on_update`, :func:`merge_on_load`, registered by the package).  Blender reports a depsgraph update
with the data it changed, so the handler only moves the users; the copies, unused, are removed by a timer just
after (:func:`remove_merged`), and are not saved in any case.
"""

from __future__ import annotations

import re

import bpy

from . import live_edits, wiring

#: Blender's suffix on a data-block name already taken in the file: ``.001``, ``.002`` …
_SUFFIX = re.compile(r"\.\d{3,}$")
#: Group properties holding per-file state, not how the group was built (blender_addon.live_edits).
_STATE_PROPS = ("spectral_skin_sss_cache_order",)


def _value(value) -> object:
    """A custom property's value, comparable (ID property arrays as tuples)."""
    return tuple(value) if hasattr(value, "to_list") else value


def _uses(node: bpy.types.Node) -> str:
    """The name, without Blender's suffix, of the node group or image ``node`` uses; "" where none."""
    used = getattr(node, "node_tree", None) or getattr(node, "image", None)
    return _SUFFIX.sub("", used.name) if used is not None else ""


def _build(group: bpy.types.NodeTree) -> tuple:
    """What makes two of the add-on's groups render alike: the name without Blender's suffix, the add-on's
    properties but per-file state, the nodes (name, type, the node group or image each one uses by its name
    without suffix) and the links (node and socket identifiers at both ends)."""
    props = tuple(sorted((key, _value(group[key])) for key in group.keys()
                         if key.startswith("spectral_skin_sss") and key not in _STATE_PROPS))
    nodes = tuple(sorted((n.name, n.bl_idname, _uses(n)) for n in group.nodes))
    links = tuple(sorted((link.from_node.name, link.from_socket.identifier, link.to_node.name,
                          link.to_socket.identifier) for link in group.links))
    return _SUFFIX.sub("", group.name), props, nodes, links


def _images(group: bpy.types.NodeTree) -> set[bpy.types.Image]:
    """The images the Image and Environment Texture nodes of ``group`` read."""
    return {n.image for n in group.nodes if getattr(n, "image", None) is not None}


def merge_copies() -> list[str]:
    """Move every user of a copy of one of the add-on's groups onto the group it copies (module docstring) and
    cache the edits of the materials moved (any whose cache input no longer names its edit's cache); returns the
    names of the copies, which nothing uses any more (:func:`remove_copies` removes them).  The group kept is the one
    whose name is shortest (the file's own, unsuffixed)."""
    kept: dict[tuple, bpy.types.NodeTree] = {}
    copies: list[tuple[bpy.types.NodeTree, bpy.types.NodeTree]] = []
    for group in sorted(bpy.data.node_groups, key=lambda g: (len(g.name), g.name)):
        if not group.is_editable or not wiring.is_addon_group(group):
            continue
        build = _build(group)
        if build not in kept:
            kept[build] = group
        elif group.library_weak_reference is not None:  # appended: a copy made in the file is the artist's
            copies.append((group, kept[build]))
    for copy, original in copies:
        copy.user_remap(original)
    if copies:
        live_edits.cache_edits(bpy.data.materials)
    return [copy.name for copy, _ in copies]


def remove_copies(names: list[str]) -> int:
    """Remove the add-on's node groups ``names`` that nothing uses (copies :func:`merge_copies` moved every user
    off) and the add-on's images they alone read; returns the number of groups removed.  Not from a depsgraph
    handler: the update it reports would name removed data."""
    removed, images = 0, set()
    for name in names:
        group = bpy.data.node_groups.get(name)
        if group is not None and group.users == 0 and wiring.is_addon_group(group):
            images |= _images(group)
            bpy.data.node_groups.remove(group)
            removed += 1
    wiring.remove_unused_images(images)
    return removed


#: The number of node groups at the last depsgraph update (:func:`merge_on_update`).
_groups_seen = -1
#: Copies merged by the depsgraph handler, removed by the next timer call (:func:`remove_merged`).
_merged: list[str] = []


def remove_merged() -> None:
    """Timer (Blender's main loop, after the depsgraph update that merged them): :func:`remove_copies` of the
    copies :func:`merge_on_update` merged.  Without a main loop (a script in ``blender -b``, the bpy module) it does
    not run: the copies are left unused, and Blender does not save unused data."""
    names = list(_merged)
    _merged.clear()
    remove_copies(names)


@bpy.app.handlers.persistent
def merge_on_update(scene=None, depsgraph=None) -> None:
    """depsgraph_update_post handler: :func:`merge_copies` where the file's number of node groups changed; the
    copies are removed by a timer (:func:`remove_merged`)."""
    global _groups_seen
    count = len(bpy.data.node_groups)
    if count == _groups_seen:
        return
    _groups_seen = count
    _merged.extend(merge_copies())
    if _merged and not bpy.app.timers.is_registered(remove_merged):
        bpy.app.timers.register(remove_merged, first_interval=0.0)


@bpy.app.handlers.persistent
def merge_on_load(_filepath=None) -> None:
    """load_post handler: :func:`merge_copies` in the file just opened, and :func:`remove_copies`."""
    global _groups_seen
    remove_copies(merge_copies())
    _groups_seen = len(bpy.data.node_groups)


_HANDLERS = (("depsgraph_update_post", merge_on_update), ("load_post", merge_on_load))


def register_handlers() -> None:
    """Put the handlers first in their lists: the add-on's other handlers then see the merged groups."""
    for kind, handler in _HANDLERS:
        handlers = getattr(bpy.app.handlers, kind)
        if handler not in handlers:
            handlers.insert(0, handler)


def unregister_handlers() -> None:
    """Take the handlers out, and the timer where it is waiting (a timer left at exit crashes Blender 4.2)."""
    if bpy.app.timers.is_registered(remove_merged):
        bpy.app.timers.unregister(remove_merged)
    _merged.clear()
    for kind, handler in _HANDLERS:
        handlers = getattr(bpy.app.handlers, kind)
        while handler in handlers:
            handlers.remove(handler)
