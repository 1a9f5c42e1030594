"""Panels: Shader Editor sidebar tab "Skin SSS" and Material properties, with the bake settings (stored per
scene in ``scene.spectral_skin``) and the progress of a running bake."""

from __future__ import annotations

import os

import bpy

from . import baker, edit_masks, follow, live_edits, operators, preferences, real_size, wiring


class SpectralSkinSettings(bpy.types.PropertyGroup):
    """Bake settings shown in the panels and passed to Invert Skin Albedo."""

    mode: bpy.props.EnumProperty(name="Mode", items=operators.MODES[1:], default="LIVE")
    image: bpy.props.PointerProperty(name="Image", type=bpy.types.Image,
                                     description="Albedo to invert (empty: the active Image Texture node, else "
                                                 "the one feeding the Principled BSDF's Base Color)")
    storage: bpy.props.EnumProperty(name="Maps", items=operators._STORAGE, default="PACK")
    output_dir: bpy.props.StringProperty(name="Folder", subtype="DIR_PATH", default="",
                                         description="Output folder for saved maps (empty: beside the .blend)")
    colorspace: bpy.props.EnumProperty(name="Colour space", items=operators._COLORSPACES, default="FROM_IMAGE")
    backend: bpy.props.EnumProperty(name="Shading", items=operators._BACKENDS, default="SVM")
    overwrite: bpy.props.BoolProperty(name="Overwrite files", default=False)
    model_colour: bpy.props.BoolProperty(name="Model's own colour", default=False,
                                         description=operators.MODEL_COLOUR_HELP)
    principled_convention: bpy.props.BoolProperty(name="Principled's convention", default=False,
                                                  description=operators.PRINCIPLED_CONVENTION_HELP)
    exact: bpy.props.BoolProperty(name="Exact (slow)", default=False,
                                  description="Every distinct colour through the network, not the fast-path table")
    uv_coverage: bpy.props.BoolProperty(name="Only UV-covered texels", default=True,
                                        description="Evaluate only the texels the active mesh's UVs cover")
    melanin: bpy.props.FloatProperty(**live_edits.edit_property("Melanin"))
    blood: bpy.props.FloatProperty(**live_edits.edit_property("Blood"))
    oxygenation: bpy.props.FloatProperty(**live_edits.edit_property("Oxygenation"))
    edit_from_live: bpy.props.BoolProperty(name="Edit from the live group", default=True,
                                           description=operators.EDIT_FROM_LIVE_HELP)


def _draw(layout, context) -> None:
    model = preferences.model_path(context)
    box = layout.box()
    if os.path.isfile(model):
        box.label(text=f"Model: {os.path.basename(model)}", icon="CHECKMARK")
    else:
        box.label(text="Model not found: train/export it", icon="ERROR")
        box.label(text=model)
    settings = getattr(context.scene, "spectral_skin", None)
    wm = context.window_manager
    if getattr(wm, "spectral_skin_running", False):
        layout.progress(factor=wm.spectral_skin_progress, type="BAR",
                        text=f"Inverting {100 * wm.spectral_skin_progress:.0f} % (Esc to cancel)")
        return
    if settings is not None:
        layout.prop(settings, "mode", expand=True)
        if settings.mode == "LIVE":
            layout.prop(settings, "principled_convention")
    _draw_live_node(layout, getattr(context, "material", None))
    _draw_stale_units(layout, context)
    _draw_real_size(layout, context)
    if settings is not None and settings.mode == "BAKE":
        col = layout.column()
        col.prop(settings, "image")
        if settings.image is None:
            node = baker.albedo_image_node(getattr(context, "material", None))
            col.label(text=f"Albedo: {node.image.name}" if node else "No albedo Image Texture node",
                      icon="IMAGE_DATA" if node else "INFO")
        col.prop(settings, "colorspace")
        col.prop(settings, "storage")
        if settings.storage == "FILES":
            col.prop(settings, "output_dir")
            col.prop(settings, "overwrite")
        col.prop(settings, "backend")
        col.prop(settings, "model_colour")
        col.prop(settings, "exact")
        col.prop(settings, "uv_coverage")
        edit = col.column(heading="Skin edit", align=True)
        edit.prop(settings, "edit_from_live")
        values = edit.column(align=True)
        values.active = not (settings.edit_from_live and edit_masks.has_live_edit(getattr(context, "material", None)))
        for name in ("melanin", "blood", "oxygenation"):
            values.prop(settings, name)
    op = layout.operator("spectral_skin.invert_albedo", icon="IMAGE_DATA")
    _set_options(op, settings)
    if settings is not None and settings.mode == "BAKE":
        op.image_name = settings.image.name if settings.image is not None else ""
    _draw_slots(layout, context, settings)
    layout.operator("spectral_skin.add_mixture", icon="NODETREE")
    live_edits.draw_controls(layout, context)
    layout.operator("spectral_skin.remove", icon="TRASH")


def _set_options(op, settings: SpectralSkinSettings | None) -> None:
    """Give an Invert Skin Albedo button the scene's settings (all but the image to bake)."""
    if settings is None:
        return
    op.mode, op.principled_convention = settings.mode, settings.principled_convention
    if settings.mode == "BAKE":
        op.storage, op.output_dir = settings.storage, settings.output_dir
        op.colorspace, op.backend = settings.colorspace, shading_of(settings)
        op.overwrite, op.model_colour = settings.overwrite, settings.model_colour
        op.exact, op.uv_coverage = settings.exact, settings.uv_coverage
        op.melanin, op.blood, op.oxygenation = settings.melanin, settings.blood, settings.oxygenation
        op.edit_from_live = settings.edit_from_live


def slot_materials(obj: bpy.types.Object | None) -> list[tuple[bpy.types.Material, bool]]:
    """The materials of ``obj``'s slots (each once, in slot order) that hold a Principled BSDF the add-on can render
    for, and whether it does (wired)."""
    found: list[tuple[bpy.types.Material, bool]] = []
    for slot in obj.material_slots if obj is not None else ():
        material = slot.material
        if material is None or material.node_tree is None or any(m == material for m, _ in found):
            continue
        if wiring.artist_principled(material) is not None:
            found.append((material, wiring.wired_group_node(material) is not None))
    return found


def _draw_slots(layout: bpy.types.UILayout, context, settings: SpectralSkinSettings | None) -> None:
    """Where the active object has several materials with a Principled BSDF (a character's head, body and limbs):
    one row each, with whether the add-on renders it and a button to invert (or update) and to remove it."""
    obj = getattr(context, "object", None)
    materials = slot_materials(obj)
    if len(materials) < 2:
        return
    box = layout.box()
    box.label(text=f"Materials of '{obj.name}'", icon="MATERIAL")
    for material, wired in materials:
        row = box.row(align=True)
        row.label(text=material.name, icon="CHECKMARK" if wired else "BLANK1")
        op = row.operator("spectral_skin.invert_albedo", text="Update" if wired else "Invert")
        _set_options(op, settings)
        op.material = material.name
        if wired:
            row.operator("spectral_skin.remove", text="", icon="TRASH").material = material.name


class SPECTRAL_SKIN_PT_shader_editor(bpy.types.Panel):
    bl_label = "Spectral Skin SSS"
    bl_space_type = "NODE_EDITOR"
    bl_region_type = "UI"
    bl_category = "Skin SSS"

    @classmethod
    def poll(cls, context):
        return getattr(context.space_data, "tree_type", "") == "ShaderNodeTree"

    def draw(self, context):
        _draw(self.layout, context)


class SPECTRAL_SKIN_PT_material(bpy.types.Panel):
    bl_label = "Spectral Skin SSS"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return context.material is not None

    def draw(self, context):
        _draw(self.layout, context)


classes = (SpectralSkinSettings, SPECTRAL_SKIN_PT_shader_editor, SPECTRAL_SKIN_PT_material)


def live_node(material: bpy.types.Material | None) -> bpy.types.Node | None:
    """The live group node (blender_addon.live) of ``material`` with a Translucency input, or None."""
    return live_edits.live_node(material, "Translucency")


def _draw_live_node(layout: bpy.types.UILayout, material: bpy.types.Material | None) -> None:
    """The active material's group inputs an artist tunes: the live group's Translucency (and its Subsurface Weight
    when it is a value, not a mask), or the Translucency of the mixture group of baked maps."""
    node = live_node(material)
    baked = None if node is not None or material is None or material.node_tree is None \
        else wiring.wired_group_node(material)
    if baked is not None and "Translucency" in baked.inputs and not baked.inputs["Translucency"].is_linked:
        box = layout.box()
        box.label(text="Baked maps", icon="NODETREE")
        box.prop(baked.inputs["Translucency"], "default_value", text="Translucency")
    if node is None:
        return
    box = layout.box()
    box.label(text="Live group", icon="NODETREE")
    box.prop(node.inputs["Translucency"], "default_value", text="Translucency")
    weight = node.inputs["Subsurface Weight"]
    if not weight.is_linked:
        box.prop(weight, "default_value", text="Subsurface Weight")


def _draw_stale_units(layout: bpy.types.UILayout, context) -> None:
    """Where the active material's baked maps hold their radii in other units than the scene's: say so, and what
    to do."""
    baked = follow.baked_unit_scale_stale(getattr(context, "material", None), context.scene)
    if baked is not None:
        box = layout.box()
        box.label(text=f"Maps baked at Unit Scale {baked:g}, the scene's is {follow.scene_unit_scale(context.scene):g}",
                  icon="ERROR")
        box.label(text="The radii are off by their ratio: run Invert Skin Albedo again")


def _draw_real_size(layout: bpy.types.UILayout, context) -> None:
    """Where the active material renders the add-on's skin and the active object is not at skin's real size in the
    scene's units (blender_addon.real_size): say so, and what to set."""
    obj, material = getattr(context, "object", None), getattr(context, "material", None)
    if obj is None or material is None or material.node_tree is None or wiring.wired_group_node(material) is None:
        return
    size = real_size.extent_m(obj, follow.scene_unit_scale(context.scene))
    if not real_size.plausible(size):
        box = layout.box()
        box.label(text=f"'{obj.name}' is {real_size.describe(size)} across: skin will look {real_size.look(size)}",
                  icon="ERROR")
        box.label(text="Not that size? Set Scene > Units > Unit Scale (0.01 for centimetres)")


def shading_of(settings: SpectralSkinSettings) -> str:
    """The scene's shading choice for the operator: SVM where the scene was saved with the former "Auto", a value
    no item has any more (Blender reads it as "")."""
    return settings.backend or "SVM"


def register_properties() -> None:
    bpy.types.Scene.spectral_skin = bpy.props.PointerProperty(type=SpectralSkinSettings)
    bpy.types.WindowManager.spectral_skin_progress = bpy.props.FloatProperty(min=0.0, max=1.0, default=0.0)
    bpy.types.WindowManager.spectral_skin_running = bpy.props.BoolProperty(default=False)


def unregister_properties() -> None:
    for owner, name in ((bpy.types.Scene, "spectral_skin"), (bpy.types.WindowManager, "spectral_skin_progress"),
                        (bpy.types.WindowManager, "spectral_skin_running")):
        if hasattr(owner, name):
            delattr(owner, name)
