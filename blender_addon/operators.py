"""Operators: Invert Skin Albedo (the live group by default, or baked maps) and Add Skin SSS Mixture.

Invert Skin Albedo's default (``mode`` AUTO without a named albedo file or image, or LIVE) wires the live
node group (blender_addon.live): the inversion in the shader, fed by whatever fed the Principled BSDF's Base
Color; it computes nothing per texel and takes well under two seconds on any texture.  ``mode`` BAKE (or AUTO
with an albedo file or image named) bakes maps (below).

The bake runs synchronously when called from a script or in background mode (``execute``), and
from the UI as a modal operator driven by a timer: one inference chunk per timer event, a progress bar
in the panel and the cursor, the rest of the UI usable meanwhile, Esc cancels (nothing is changed).
Both paths use blender_addon.baker.AddonBake; the whole operation is one undo step.
"""

from __future__ import annotations

import bpy

from . import baker, follow, live, live_edits, nodes, preferences, real_size, wiring
from .core import bake as _core_bake

one_line = _core_bake.one_line

_COLORSPACES = [
    ("FROM_IMAGE", "From Image", "The image's colour space setting in Blender (sRGB, Non-Color, Linear ...)"),
    ("auto", "Auto", "sRGB unless the file says linear/Non-Color or stores floats"),
    ("srgb", "sRGB", "sRGB-encoded"),
    ("linear", "Linear", "Linear sRGB / Rec.709"),
]
_STORAGE = [
    ("PACK", "Pack into .blend", "The maps become images packed into the .blend file"),
    ("FILES", "Save as files", "EXR maps in the output folder (default: a folder beside the saved .blend)"),
]
MODES = [
    ("AUTO", "Auto", "The live group, unless an albedo file or image is named (Albedo file, Image): naming one asks "
     "for its maps to be baked"),
    ("LIVE", "Live group", "The inversion inside the shader: fed by what feeds the Principled BSDF's Base Color "
     "(image, UDIM, painting, vertex colour, attribute, procedural); nothing is baked, paint strokes show at once"),
    ("BAKE", "Bake maps", "Bake the K media into image maps (for other renderers, OSL, or the model's own colour)"),
]
#: Shading paths, numbered as when "Auto" was item 0, so that a scene saved then keeps its choice.
_BACKENDS = [
    ("SVM", "SVM nodes", "Up to 3K Subsurface Scattering nodes (per component: RGB, then the channels of larger "
                         "weight): every Cycles device (the default)", 1),
    ("OSL", "OSL", "One OSL Script node with K bssrdf closures: CPU and OptiX only, and only where the scene has "
                   "Open Shading Language turned on (this operator never turns it on)", 2),
]
#: The model-colour option's tooltip (operator and panel).
MODEL_COLOUR_HELP = ("Render the model's own reflectance (the colour of the biophysical skin the network found, "
                     "physically consistent, often darker than painted) instead of the painted albedo, which the "
                     "maps reproduce per channel by default")
#: The convention option's tooltip (operator and panel).
PRINCIPLED_CONVENTION_HELP = ("Live group: render the colour as a Principled BSDF renders its Base Color, under its "
                              "specular layer (about 4 % darker), instead of the painted colour with the coat on top")
#: The material option's tooltip (Invert Skin Albedo, Remove Skin SSS).
MATERIAL_HELP = ("The active object's material to work on, by name (one of its material slots; empty: the active "
                 "material): a character's head, body and limbs each in a material of their own")
#: Exceptions that mean bad input or a failed bake (reported, nothing changed).
_EXPECTED = (OSError, ValueError, RuntimeError)
#: The tooltip of Bake's Edit from the live group.
EDIT_FROM_LIVE_HELP = ("Where the material renders through the live group with a skin edit, bake that edit (its "
                       "values, and masks painted by Image Textures) instead of the values below")


class SPECTRAL_SKIN_OT_invert_albedo(bpy.types.Operator):
    """Invert an RGB skin albedo texture into spectral subsurface maps and wire the Spectral Skin SSS Mixture
    into the material (the active Image Texture node's image, else that feeding the Principled BSDF's Base Color,
    or a chosen image or file)"""

    bl_idname = "spectral_skin.invert_albedo"
    bl_label = "Invert Skin Albedo"
    bl_options = {"REGISTER", "UNDO"}

    mode: bpy.props.EnumProperty(name="Mode", items=MODES, default="AUTO")
    material: bpy.props.StringProperty(name="Material", default="", description=MATERIAL_HELP)

    filepath: bpy.props.StringProperty(name="Albedo file", subtype="FILE_PATH", default="",
                                       description="Read this file instead of an image datablock")
    image_name: bpy.props.StringProperty(name="Image", default="",
                                         description="Image datablock to invert (empty: the active Image "
                                                     "Texture node of the active material)")
    storage: bpy.props.EnumProperty(name="Maps", items=_STORAGE, default="PACK")
    output_dir: bpy.props.StringProperty(name="Output folder", subtype="DIR_PATH", default="")
    colorspace: bpy.props.EnumProperty(name="Colour space", items=_COLORSPACES, default="FROM_IMAGE")
    backend: bpy.props.EnumProperty(name="Shading", items=_BACKENDS, default="SVM")
    overwrite: bpy.props.BoolProperty(name="Overwrite files", default=False)
    openpbr: bpy.props.BoolProperty(
        name="OpenPBR, MaterialX and USD", default=False,
        description="Bake maps mode, maps as files: also write the OpenPBR maps, a MaterialX document and a USD "
                    "layer for other renderers (needs the materialx and usd-core packages in Blender's Python)")
    model_colour: bpy.props.BoolProperty(
        name="Model's own colour", default=False, description=MODEL_COLOUR_HELP)
    #: Scripts written before the painted colour became the default passed match_exposure=True (the painted
    #: brightness): the default now renders the painted brightness and hue, so it is accepted and ignored.
    match_exposure: bpy.props.BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})

    principled_convention: bpy.props.BoolProperty(
        name="Principled's convention", default=False, description=PRINCIPLED_CONVENTION_HELP)
    exact: bpy.props.BoolProperty(
        name="Exact (slow)", default=False,
        description="Evaluate every distinct colour with the network instead of the fast-path table shipped with the "
                    "model (the table is within ~0.1 ΔE of it on skin; outside the table's skin colours it renders "
                    "the painted colour with the nearest skin colour's translucency, as the live group does)")
    uv_coverage: bpy.props.BoolProperty(
        name="Only UV-covered texels", default=True,
        description="Evaluate only the texels the active mesh's UVs cover; the others get the maps of the most "
                    "common covered colour")
    melanin: bpy.props.FloatProperty(**live_edits.edit_property("Melanin"))
    blood: bpy.props.FloatProperty(**live_edits.edit_property("Blood"))
    oxygenation: bpy.props.FloatProperty(**live_edits.edit_property("Oxygenation"))
    edit_from_live: bpy.props.BoolProperty(name="Edit from the live group", default=True,
                                           description=EDIT_FROM_LIVE_HELP)

    _bake = None
    _timer = None

    def _settings(self, context) -> baker.BakeSettings:
        """The operator's options, the add-on preferences and the scene's unit scale (radii in its units)."""
        return baker.BakeSettings(model_path=preferences.model_path(context), filepath=self.filepath,
                                  image_name=self.image_name, storage=self.storage, output_dir=self.output_dir,
                                  colorspace=self.colorspace, backend=self.backend, overwrite=self.overwrite,
                                  model_colour=self.model_colour, threads=preferences.threads(context),
                                  exact=self.exact, uv_coverage=self.uv_coverage, openpbr=self.openpbr,
                                  unit_scale_m=follow.scene_unit_scale(context.scene), edit=self._edit(),
                                  edit_from_live=self.edit_from_live, material=self.material)

    def _edit(self) -> tuple[float, float, float]:
        """The skin edit asked for: (Melanin, Blood, Oxygenation).  The live mode sets a non-neutral one on the group
        node's inputs and leaves them as they are otherwise (an edit made there stays); the bake mode's maps carry
        it."""
        return (self.melanin, self.blood, self.oxygenation)

    def _live(self, context):
        """The live group (mode LIVE): options that only a bake can honour are refused, not ignored."""
        refused = [("an albedo file", self.filepath), ("an image", self.image_name),
                   ("the model's own colour", self.model_colour), ("OSL", self.backend == "OSL"),
                   ("OpenPBR files", self.openpbr)]
        asked = [what for what, value in refused if value]
        if asked:
            self.report({"ERROR"}, f"the live group reads the colour that feeds the Principled BSDF and runs as SVM "
                                   f"nodes: {', '.join(asked)} needs mode Bake")
            return {"CANCELLED"}
        try:
            message = live.apply(context, preferences.model_path(context), follow.scene_unit_scale(context.scene),
                                 self.colorspace, self.principled_convention, self._edit(), self.material)
        except _EXPECTED as exc:
            self.report({"ERROR"}, one_line(exc))
            return {"CANCELLED"}
        message = _size_checked(context, message)
        self.report(_level(message), message)
        return {"FINISHED"}

    def _mode(self) -> str:
        """LIVE or BAKE: AUTO bakes when an albedo file or image is named, else wires the live group."""
        if self.mode != "AUTO":
            return self.mode
        return "BAKE" if self.filepath or self.image_name else "LIVE"

    def execute(self, context):
        if _refused_linked(self, context):
            return {"CANCELLED"}
        if self._mode() == "LIVE":
            return self._live(context)
        if self.principled_convention:
            self.report({"ERROR"}, "Principled's convention is an option of the live group: bake without it, or "
                                   "choose mode Live group")
            return {"CANCELLED"}
        try:
            bake = baker.AddonBake(context, self._settings(context))
        except _EXPECTED as exc:
            self.report({"ERROR"}, one_line(exc))
            return {"CANCELLED"}
        try:
            bake.run()
            message = bake.apply(context)
        except _EXPECTED as exc:
            bake.cancel()
            self.report({"ERROR"}, one_line(exc))
            return {"CANCELLED"}
        message = _size_checked(context, message)
        self.report(_level(message), message)
        return {"FINISHED"}

    def invoke(self, context, event):
        if self._mode() == "LIVE" or bpy.app.background or context.window is None:
            return self.execute(context)
        if _refused_linked(self, context):
            return {"CANCELLED"}
        try:
            self._bake = baker.AddonBake(context, self._settings(context))
        except _EXPECTED as exc:
            self.report({"ERROR"}, one_line(exc))
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, 100)
        _set_progress(context, 0.0, running=True)
        self._timer = wm.event_timer_add(0.02, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC" and event.value == "PRESS":
            self._bake.cancel()
            self._stop(context)
            self.report({"WARNING"}, "Invert Skin Albedo cancelled: nothing was changed")
            return {"CANCELLED"}
        if event.type != "TIMER" or event.timer is not self._timer:
            return {"PASS_THROUGH"}
        try:
            more = self._bake.step()
            if more:
                _set_progress(context, self._bake.fraction, running=True)
                context.window_manager.progress_update(int(100 * self._bake.fraction))
                return {"RUNNING_MODAL"}
            message = self._bake.apply(context)
        except _EXPECTED as exc:
            self._bake.cancel()
            self._stop(context)
            self.report({"ERROR"}, one_line(exc))
            return {"CANCELLED"}
        self._stop(context)
        message = _size_checked(context, message)
        self.report(_level(message), message)
        return {"FINISHED"}

    def _stop(self, context) -> None:
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        _set_progress(context, 0.0, running=False)


def _active_material(context, name: str = "") -> bpy.types.Material | None:
    """The active object's material ``name`` (empty: its active material; wiring.object_material), or None where
    there is none or no such material (the operator reports that on its own)."""
    try:
        return wiring.object_material(context.object, name)
    except ValueError:
        return None


def _refused_linked(operator: bpy.types.Operator, context) -> bool:
    """Report and return True when the material the operator works on (its ``material`` option, else the active
    one) is linked from a library (its node changes would vanish on reload: blender_addon.wiring.linked_error)."""
    material = _active_material(context, getattr(operator, "material", ""))
    error = wiring.linked_error(material) if material is not None else None
    if error:
        operator.report({"ERROR"}, error)
    return bool(error)


def _size_checked(context, message: str) -> str:
    """The operator's report ``message``, with the warning that the active object is not at skin's real size in the
    scene's units where it is not (blender_addon.real_size)."""
    warning = real_size.warning(context.object, follow.scene_unit_scale(context.scene))
    return f"{message}; warning: {warning}" if warning else message


def _level(message: str) -> set[str]:
    """WARNING when the report carries a warning (e.g. painted colours that had to be clamped), else INFO."""
    return {"WARNING"} if "warning: " in message else {"INFO"}


def _set_progress(context, fraction: float, running: bool) -> None:
    """Progress shown by the panels (WindowManager properties), and the status bar text."""
    wm = context.window_manager
    if hasattr(wm, "spectral_skin_progress"):
        wm.spectral_skin_progress = fraction
        wm.spectral_skin_running = running
    if context.workspace is not None:
        context.workspace.status_text_set(f"Invert Skin Albedo: {100 * fraction:.0f} % (Esc to cancel)"
                                          if running else None)
    if context.screen is not None:
        for area in context.screen.areas:
            if area.type in ("NODE_EDITOR", "PROPERTIES"):
                area.tag_redraw()


class SPECTRAL_SKIN_OT_add_mixture(bpy.types.Operator):
    """Add the Spectral Skin SSS Mixture node group to the active material (existing nodes are kept)"""

    bl_idname = "spectral_skin.add_mixture"
    bl_label = "Add Skin SSS Mixture"
    bl_options = {"REGISTER", "UNDO"}

    components: bpy.props.IntProperty(name="Components (K)", default=3, min=1, max=7)
    backend: bpy.props.EnumProperty(
        name="Backend",
        items=[("SVM", "SVM (all devices)", "Up to 3K Subsurface Scattering nodes over nested channel sets"),
               ("OSL", "OSL (CPU/OptiX)", "One OSL Script node with K bssrdf closures")],
        default="SVM",
    )

    @classmethod
    def poll(cls, context):
        obj = context.object
        return obj is not None and obj.active_material is not None

    def execute(self, context):
        mat = context.object.active_material
        if _refused_linked(self, context):
            return {"CANCELLED"}
        if mat.node_tree is None:
            self.report({"ERROR"}, f"material '{mat.name}' has no node tree: turn on Use Nodes and run this again")
            return {"CANCELLED"}
        if self.backend == "OSL":
            group = nodes.build_osl_group(self.components)
        else:
            group = nodes.build_svm_group(self.components)
        nodes.wire_into_material(mat, group)
        message = f"added {group.name} (K={self.components}) to {mat.name}" + baker.osl_warning(context.scene,
                                                                                                self.backend)
        self.report(_level(message), message)
        return {"FINISHED"}


class SPECTRAL_SKIN_OT_remove(bpy.types.Operator):
    """Remove Spectral Skin SSS from the active material: its nodes go and the links it replaced come back, so the
    material is again what it was before (blender_addon.wiring); the add-on's node groups and images go too when no
    material uses them any more"""

    bl_idname = "spectral_skin.remove"
    bl_label = "Remove Skin SSS"
    bl_options = {"REGISTER", "UNDO"}

    material: bpy.props.StringProperty(name="Material", default="", description=MATERIAL_HELP)

    @classmethod
    def poll(cls, context):
        return _active_material(context) is not None

    def execute(self, context):
        try:
            material = wiring.object_material(context.object, self.material)
        except ValueError as exc:
            self.report({"ERROR"}, one_line(exc))
            return {"CANCELLED"}
        if material is None:
            self.report({"ERROR"}, "no active object with a material: select the skin object")
            return {"CANCELLED"}
        if _refused_linked(self, context):
            return {"CANCELLED"}
        removed = wiring.unwire(material) if material.node_tree is not None else 0
        if not removed:
            self.report({"INFO"}, f"nothing to remove: '{material.name}' holds no Spectral Skin SSS nodes")
            return {"CANCELLED"}
        groups, images = wiring.purge_unused()
        self.report({"INFO"}, f"removed Spectral Skin SSS from '{material.name}' ({groups} node groups and {images} "
                              "images no material used any more went too)")
        return {"FINISHED"}


classes = (SPECTRAL_SKIN_OT_invert_albedo, SPECTRAL_SKIN_OT_add_mixture, SPECTRAL_SKIN_OT_remove)
