"""The Blender side of a bake: find the albedo, run an exporters.bake.BakeJob, turn the maps into images
and wire the node group into the material.

:class:`AddonBake` is what the operator drives, synchronously (``execute``, scripts and tests) or one
inference chunk per timer event (``modal``, so a 4K texture never freezes the UI).  Construction checks
the inputs and reads the image; :meth:`AddonBake.step` does one chunk; :meth:`AddonBake.cancel` undoes
everything; :meth:`AddonBake.apply` creates the images, the group and the links.  Until ``apply`` nothing
in the .blend or on disk has changed (the maps are streamed to hidden temporary files), and if ``apply``
fails it removes what it created.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np

from . import edit_masks, follow, nodes, oblique, tiles, wiring
from .core import bake, image_input, inference, maps, skin_edits, uv_coverage

AlbedoImage, IndexedAlbedo = image_input.AlbedoImage, image_input.IndexedAlbedo

#: Custom properties on baked images: the bake key (exporters.bake.bake_key), component, map kind, K of the bake.
KEY_PROP, K_PROP = "spectral_skin_sss_bake_key", "spectral_skin_sss_k"
KIND_PROP, KCOUNT_PROP = "spectral_skin_sss_kind", "spectral_skin_sss_k_count"
#: Channel names of Blender's pixel buffers by channel count (for exporters.image_input.albedo_texels).
_BUFFER_CHANNELS = {1: ("Y",), 2: ("Y", "A"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}


class BakeInputError(ValueError):
    """Bad input for Invert Skin Albedo; the message tells the user what to change."""


def missing_model_message(path: str) -> str:
    return f"model not found at {path}: train/export it or set the path in preferences"


@dataclass
class BakeSettings:
    """What the operator asks for.  ``filepath`` (a file on disk) wins over ``image_name`` (an image
    datablock), which wins over the material's albedo Image Texture node (:func:`albedo_image_node`).  ``storage``:
    "PACK" (images packed into the .blend) or "FILES" (EXR files in ``output_dir``, default a folder
    beside the saved .blend).  ``backend``: "SVM" (the default) or "OSL" (only on request).  ``model_colour``:
    the maps render the model's own reflectance instead of the painted albedo.  ``exact``: every distinct colour through
    the model instead of the fast-path table; ``uv_coverage``: evaluate only the texels the active mesh's UVs
    cover (the others take the maps of the most common covered colour); ``unit_scale_m``: metres per Blender
    unit for the radii (None: the scene's, :func:`follow.scene_unit_scale`); ``openpbr``: also the OpenPBR maps,
    MaterialX document and USD layer of ``--target openpbr`` (storage "FILES" only: other renderers read files);
    ``edit``: the skin edit (Melanin, Blood, Oxygenation: exporters.skin_edits) every texel's maps carry;
    ``edit_from_live``: where the material renders through the live group with an edit, the maps carry that edit
    instead, its masks too (blender_addon.edit_masks.live_bake_edit: what the live group renders);
    ``material``: the active object's material to wire, by name (empty: its active material)."""

    model_path: str
    filepath: str = ""
    image_name: str = ""
    storage: str = "PACK"
    output_dir: str = ""
    colorspace: str = "FROM_IMAGE"
    backend: str = "SVM"
    overwrite: bool = False
    model_colour: bool = False
    threads: int = 0
    chunk: int = 2048
    exact: bool = False
    uv_coverage: bool = True
    unit_scale_m: float | None = None
    openpbr: bool = False
    edit: tuple[float, float, float] = skin_edits.NEUTRAL
    edit_from_live: bool = False
    material: str = ""


def _image_node(node: bpy.types.Node | None) -> bpy.types.Node | None:
    return node if node is not None and node.bl_idname == "ShaderNodeTexImage" and node.image is not None else None


def albedo_image_node(material: bpy.types.Material | None) -> bpy.types.Node | None:
    """The Image Texture node whose image a bake inverts: the material's active node where it is an Image Texture
    with an image (the artist's choice), else the one feeding the artist's Principled BSDF's Base Color (through
    Reroute nodes: wiring.feeding_socket; what the live group reads), else None."""
    if material is None or material.node_tree is None:
        return None
    active = _image_node(material.node_tree.nodes.active)
    if active is not None:
        return active
    principled = wiring.artist_principled(material)
    feed = wiring.feeding_socket(principled.inputs["Base Color"]) if principled is not None else None
    return _image_node(feed.node if feed is not None else None)


def pick_backend(scene: bpy.types.Scene, requested: str) -> str:
    """SVM or OSL, as requested: SVM is the default on every device, OSL is used only when asked for.  Asking for
    OSL on a device that cannot run it (a GPU other than OptiX) is an error."""
    device = scene.cycles.device if hasattr(scene, "cycles") else "CPU"
    compute = "NONE"
    cycles_addon = bpy.context.preferences.addons.get("cycles")
    if cycles_addon is not None:
        compute = getattr(cycles_addon.preferences, "compute_device_type", "NONE")
    osl_ok = device == "CPU" or compute == "OPTIX"
    if requested == "OSL" and not osl_ok:
        raise BakeInputError(f"OSL does not run on the scene's device ({compute} GPU): choose SVM")
    if requested not in ("SVM", "OSL"):
        raise BakeInputError(f"unknown shading path {requested!r}")
    return requested


def osl_warning(scene: bpy.types.Scene, backend: str) -> str:
    """The report's warning when an OSL group was made for a scene that has Open Shading Language off (the add-on
    never changes the scene's shading system: that would change how every material of the scene renders)."""
    if backend != "OSL" or not hasattr(scene, "cycles") or scene.cycles.shading_system:
        return ""
    return ("; warning: the OSL group renders only with Open Shading Language on (Render Properties > Render > Open "
            "Shading Language), which this scene has off and the add-on leaves as it is; or choose Shading SVM")


def _image_colorspace(image: bpy.types.Image, requested: str) -> str:
    """The colour space to read ``image`` in: the operator's choice, or (FROM_IMAGE) what Blender's colour-space
    setting says (exporters.image_input.colorspace_of_name; "auto" when it says neither sRGB nor linear)."""
    if requested != "FROM_IMAGE":
        return requested
    return image_input.colorspace_of_name(image.colorspace_settings.name, f"image '{image.name}'") or "auto"


def _albedo_from_pixels(image: bpy.types.Image, colorspace: str) -> AlbedoImage:
    """An image that has no file on disk (generated or packed): read Blender's pixel buffer, with the checks of
    a file (exporters.image_input: channel layout, NaN/Inf and negative texels)."""
    w, h = image.size
    ch = image.channels
    if w < 1 or h < 1 or ch not in _BUFFER_CHANNELS:
        raise BakeInputError(f"image '{image.name}' has no pixels (is its file missing?)")
    px = np.empty(w * h * ch, dtype=np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, ch)[::-1].astype(np.float64)  # Blender stores rows bottom-up
    rgb, alpha, _ = image_input.albedo_texels(px, _BUFFER_CHANNELS[ch], f"image '{image.name}'")
    used = colorspace if colorspace in ("srgb", "linear") else ("linear" if image.is_float else "srgb")
    rgb = image_input.to_linear(rgb, used)
    if alpha is not None and np.all(alpha >= 1.0):
        alpha = None  # Blender gives every buffer an alpha channel; an opaque one is no alpha at all
    return AlbedoImage(rgb=rgb, alpha=alpha, colorspace=used, source_format="float" if image.is_float else "uint8",
                       n_clamped=0, n_channels=3 if ch >= 3 else ch)


def _has_openimageio() -> bool:
    """Whether OpenImageIO's Python module is importable (Blender 4.5 and later bundle it, 4.2 does not)."""
    try:
        image_input.openimageio()
    except image_input.ImageError:
        return False
    return True


def read_albedo_file(path: str, colorspace: str) -> AlbedoImage | IndexedAlbedo:
    """An albedo file, read with OpenImageIO, or through Blender where its module is missing."""
    if not _has_openimageio():
        return _albedo_through_blender(path, colorspace)
    return image_input.read_albedo_indexed(path, colorspace=colorspace)


def _albedo_through_blender(path: str, colorspace: str) -> AlbedoImage:
    """An albedo file read by Blender itself, where OpenImageIO's module is missing: its pixel buffer, as for an
    image without a file (a float buffer is linear already; an 8-bit one is in the file's encoding)."""
    try:
        image = bpy.data.images.load(path, check_existing=False)
    except RuntimeError as exc:
        raise BakeInputError(f"cannot read image {path}: {exc}") from exc
    try:
        return _albedo_from_pixels(image, "linear" if image.is_float else colorspace)
    finally:
        bpy.data.images.remove(image)


def mesh_uv_mask(obj, source_node, width: int, height: int) -> tuple[np.ndarray | None, str]:
    """Texels of a width x height texture that ``obj``'s UVs cover (exporters.uv_coverage), with the UV map the
    albedo's Image Texture node reads (a UV Map node, else the mesh's active render UV map); (None, why) when
    there is no mesh, no UV map, a non-UV texture vector, or UVs outside [0, 1] (tiles: everything is baked)."""
    if obj is None or obj.type != "MESH" or not obj.data.uv_layers:
        return None, "no mesh with a UV map"
    mesh = obj.data
    name = ""
    feed = wiring.feeding_socket(source_node.inputs["Vector"]) if source_node is not None else None
    if feed is not None:
        src = feed.node
        if src.bl_idname != "ShaderNodeUVMap":
            return None, "the albedo is not mapped by UVs"
        name = src.uv_map
    layer = mesh.uv_layers.get(name) if name else next((u for u in mesh.uv_layers if u.active_render),
                                                        mesh.uv_layers.active)
    if layer is None:
        return None, f"UV map '{name}' not found"
    mesh.calc_loop_triangles()
    n = len(mesh.loop_triangles)
    loops = np.empty(3 * n, np.int64)
    mesh.loop_triangles.foreach_get("loops", loops)
    uv = np.empty(2 * len(layer.data), np.float64)
    layer.data.foreach_get("uv", uv)
    tri = uv.reshape(-1, 2)[loops].reshape(n, 3, 2)
    if tri.size and (tri.min() < -1e-4 or tri.max() > 1.0 + 1e-4):
        return None, "UVs outside [0, 1]"
    return uv_coverage.uv_coverage(tri, width, height), layer.name


def _wired_to(material: bpy.types.Material, images: dict[tuple[int, str], bpy.types.Image]) -> bool:
    """Whether Cycles renders the material through a mixture group node of the add-on's current layout whose
    inputs read exactly ``images`` (so re-applying them would change nothing)."""
    gnode = wiring.wired_group_node(material)
    if gnode is None or not wiring.is_added(gnode):
        return False
    for (k, kind), image in images.items():
        sock = gnode.inputs.get(nodes.socket_name(k, kind))
        if sock is None or getattr(oblique.map_node(sock), "image", None) != image:
            return False
    return True


def _image_file(image: bpy.types.Image) -> str | None:
    """Absolute path of the image's file if it has one on disk (not packed/generated)."""
    if image.source not in ("FILE", "SEQUENCE", "TILED") or image.packed_file is not None or not image.filepath:
        return None
    return bpy.path.abspath(image.filepath, library=image.library)


class AddonBake:
    """One Invert Skin Albedo run (see the module docstring)."""

    def __init__(self, context: bpy.types.Context, settings: BakeSettings) -> None:
        self.settings = settings
        if settings.openpbr and settings.storage != "FILES":
            raise BakeInputError("the OpenPBR, MaterialX and USD files are for other renderers, which read files: "
                                 "choose Maps: Files (an output folder) to write them")
        self.scene = context.scene
        obj = context.object
        try:
            self.material = wiring.object_material(obj, settings.material)
        except ValueError as exc:
            raise BakeInputError(str(exc)) from None
        if self.material is not None and self.material.node_tree is None:
            self.material = None  # a material without nodes: the maps and the group are made, nothing is wired
        self.source_node = None
        if not os.path.isfile(settings.model_path):
            raise BakeInputError(missing_model_message(settings.model_path))
        self.image_id = None
        self.albedo, self.stem, self.input_name = self._read_albedo()
        self.backend = pick_backend(self.scene, settings.backend)
        self.model = inference.ModelFile(settings.model_path, threads=settings.threads)  # loaded if needed
        self.tiled = isinstance(self.albedo, tiles.TiledAlbedo)
        shape = None
        if self.tiled:
            mask, self.uv_note = None, "UDIM: every texel of every tile"
        else:
            height, width = shape = (self.albedo.shape if isinstance(self.albedo, IndexedAlbedo) else
                                     self.albedo.rgb.shape[:2])
            mask, self.uv_note = (mesh_uv_mask(obj, self.source_node, width, height) if settings.uv_coverage
                                  else (None, "off"))
        edit, masks, self.edit_note = self._edit(shape)
        self.out_dir, self._temp_dir = self._output_folder()
        scale = follow.scene_unit_scale(self.scene) if settings.unit_scale_m is None else float(settings.unit_scale_m)
        self.options = bake.BakeOptions(targets=("cycles", "openpbr") if settings.openpbr else ("cycles",),
                                        unit_scale_m=scale,
                                        threads=settings.threads, chunk=settings.chunk,
                                        model_colour=settings.model_colour, overwrite=settings.overwrite,
                                        exact=settings.exact, texel_mask=mask,
                                        edit=skin_edits.SkinEdit(*edit), edit_masks=masks,
                                        **({"prune_share": 0.0} if self.tiled else {}))
        try:
            if self.tiled:
                self.job = tiles.TiledJob(self.albedo, self.out_dir, self.model, self.options, read=read_albedo_file)
                self.key, self.reused_images = self.job.key, None
            else:
                self.albedo = bake.BakeJob.index(self.albedo)
                image_id = self.image_id or bake.pixels_id(self.albedo)
                self.key = bake.job_key(image_id, self.model.sha256, self.stem, self.options, self.albedo.shape)
                self.reused_images = self._packed_up_to_date() if settings.storage == "PACK" else None
                self.job = None if self.reused_images is not None else bake.BakeJob(
                    self.albedo, self.out_dir, self.stem, self.model, self.options, input_image=self.input_name,
                    image_id=image_id)
        except BaseException:
            self._remove_temp_dir()
            raise
        self._steps = None
        self.fraction = 0.0
        self.result: bake.BakeResult | None = None

    # -- inputs --------------------------------------------------------------------------------------------
    def _edit(self, shape: tuple[int, int] | None) -> tuple[tuple[float, float, float], dict | None, str]:
        """(edit, masks, the report's note) the maps carry: the live group's (``edit_from_live``, where the material
        has one with an edit) or the settings' values."""
        s = self.settings
        found = edit_masks.live_bake_edit(self.material, self.source_node, shape) if s.edit_from_live else None
        if found is None:
            return s.edit, None, ""
        return found[0], found[1] or None, "; skin edit from the live group: " + edit_masks.describe(*found)

    def _read_file(self, path: str, colorspace: str) -> IndexedAlbedo | AlbedoImage:
        if not os.path.isfile(path):
            raise FileNotFoundError(f"albedo image not found: {path}")
        self.image_id = bake.file_id(path, colorspace)
        return read_albedo_file(path, colorspace)

    def _read_albedo(self) -> tuple[AlbedoImage | IndexedAlbedo, str, str]:
        s = self.settings
        if s.filepath:
            path = bpy.path.abspath(s.filepath)
            cs = s.colorspace if s.colorspace in ("auto", "srgb", "linear") else "auto"
            return self._read_file(path, cs), Path(path).stem, path
        if s.image_name:
            image = bpy.data.images.get(s.image_name)
            if image is None:
                raise BakeInputError(f"no image named '{s.image_name}' in this file")
        else:
            node = albedo_image_node(self.material)
            if node is None:
                raise BakeInputError("no albedo image: no Image Texture with an image feeds the Principled BSDF's "
                                     "Base Color and none is the active node; select one, or choose an image")
            self.source_node, image = node, node.image
        cs = _image_colorspace(image, s.colorspace)
        if image.source == "TILED":
            albedo = tiles.tiled_albedo(image, cs)
            return albedo, albedo.stem, albedo.pattern
        stem = Path(image.name).stem or "albedo"
        path = _image_file(image)
        if path is not None:
            if not os.path.isfile(path):
                raise BakeInputError(f"the file of image '{image.name}' is missing: {path}")
            return self._read_file(path, cs), stem, path
        return _albedo_from_pixels(image, cs), stem, f"<image {image.name}>"

    def _packed_up_to_date(self) -> dict[tuple[int, str], bpy.types.Image] | None:
        """Images this add-on packed from a bake with the same key (same image content, model, options), if a
        complete set of them is still in the file: then nothing needs to be computed."""
        found: dict[tuple[int, str], bpy.types.Image] = {}
        k_count = None
        for image in bpy.data.images:
            if image.get(KEY_PROP) == self.key and image.packed_file is not None:
                found[(int(image.get(K_PROP, 0)), str(image.get(KIND_PROP, "")))] = image
                k_count = int(image.get(KCOUNT_PROP, 0))
        if not k_count or any((k, kind) not in found for k in range(1, k_count + 1) for kind in nodes.KINDS):
            return None
        return {(k, kind): found[(k, kind)] for k in range(1, k_count + 1) for kind in nodes.KINDS}

    def _output_folder(self) -> tuple[Path, Path | None]:
        s = self.settings
        if s.storage == "PACK":
            tmp = Path(tempfile.mkdtemp(prefix="spectral_skin_sss_"))
            return tmp, tmp
        if s.storage != "FILES":
            raise BakeInputError(f"unknown storage {s.storage!r}")
        if s.output_dir:
            folder = Path(bpy.path.abspath(s.output_dir))
        elif bpy.data.filepath:
            folder = Path(bpy.path.abspath("//")) / f"{self.stem}_skin_maps"
        else:
            raise BakeInputError("save the .blend first (the maps go beside it) or choose an output folder")
        if maps.make_output_folder(folder):
            return folder, folder  # a folder we made: removed again (if still empty) on cancel or error
        return folder, None

    # -- running -------------------------------------------------------------------------------------------
    def step(self) -> bool:
        """Do one inference chunk; False when all texels are done."""
        if self.reused_images is not None:
            self.fraction = 1.0
            return False
        if self._steps is None:
            self._steps = self.job.steps()
        try:
            self.fraction = next(self._steps)
            return True
        except StopIteration:
            self.fraction = 1.0
            return False
        except BaseException:
            self._remove_temp_dir()
            raise

    def run(self) -> None:
        while self.step():
            pass

    def cancel(self) -> None:
        """Stop: temporary files and folders removed, nothing else was changed."""
        if self.job is not None:
            self.job.cancel()
        self._remove_temp_dir()

    def _remove_temp_dir(self) -> None:
        if self._temp_dir is not None and self._temp_dir.exists():
            if self.settings.storage == "PACK":
                shutil.rmtree(self._temp_dir, ignore_errors=True)
            else:
                try:
                    self._temp_dir.rmdir()
                except OSError:
                    pass

    # -- applying ------------------------------------------------------------------------------------------
    def apply(self, context: bpy.types.Context) -> str:
        """Publish the maps, create the images and the node group, wire it into the material.

        An up-to-date bake (packed images of the same key, or an up-to-date folder) is reused: no image is
        made again, and a material already wired to those images is left as it is.  Returns a one-line
        report; on failure everything created here is removed again."""
        created_images: list[bpy.types.Image] = []
        created_nodes: list[str] = []
        group_existed = set(bpy.data.node_groups.keys())
        osl_before = getattr(self.scene.cycles, "shading_system", False)
        previous_surface = None
        previous_prop = self.material.get(nodes.PREVIOUS_SURFACE_PROP) if self.material is not None else None
        try:
            if self.reused_images is not None:
                images, k_count, reused = dict(self.reused_images), max(k for k, _ in self.reused_images), True
                self.result = None
            else:
                self.result = self.job.finish()
                reused = self.result.reused
                images, k_count = self._images(created_images), self.result.k
            if reused and self.material is not None and _wired_to(self.material, images):
                return (f"up to date: the maps of this image, model and options are already in '{self.material.name}'"
                        "; nothing was recomputed or changed")
            group = nodes.ensure_group(k_count, self.backend)
            report = f"{'reused' if reused else 'baked'} {len(images)} maps (K={k_count})"
            if self.material is not None:
                wiring.unwire(self.material)  # first: a failure below leaves the artist's own material
                before = {n.name for n in self.material.node_tree.nodes}
                out_links = [ln for ln in self.material.node_tree.links
                             if ln.to_node.bl_idname == "ShaderNodeOutputMaterial" and ln.to_socket.name == "Surface"]
                previous_surface = [(ln.from_socket, ln.to_socket) for ln in out_links]
                skin, why_not = wiring.bake_into_group(self.material, self.source_node)
                gnode = nodes.wire_into_material(self.material, group, images, into_group=skin is not None)
                oblique.wire_baked(self.material, gnode)
                created_nodes = [n.name for n in self.material.node_tree.nodes if n.name not in before]
                gnode.inputs["IOR"].default_value = self.options.ior  # the IOR the maps were baked for
                self._follow_source_uv(gnode)
                follow.record(self.material, self.options.unit_scale_m)
                report += (f", {self.backend} node group wired into '{self.material.name}'"
                           f"{wiring.grouped_text(self.material, gnode)}" + wiring.grouped_warning(why_not))
            else:
                report += f", {self.backend} node group '{group.name}' built (no active material to wire)"
        except BaseException:
            self._undo_apply(created_images, created_nodes, group_existed, osl_before, previous_surface,
                             previous_prop)
            raise
        finally:
            if self.settings.storage == "PACK":
                self._remove_temp_dir()
        if self.settings.storage == "FILES":
            report += f"; files in {self.out_dir}"
        report += self.edit_note + osl_warning(self.scene, self.backend)
        notes = list(self.result.notes) if self.result is not None else []
        return report + ("; note: " + "; ".join(notes) if notes else "")

    def _images(self, created: list[bpy.types.Image]) -> dict[tuple[int, str], bpy.types.Image]:
        """Blender images of the written maps, tagged with the bake key (packed, or loaded from the files; a
        file already loaded is reused and reloaded)."""
        images = {}
        k_count = self.result.k
        for spec in self.job.specs or bake.map_specs(self.stem, k_count, ("cycles",)):
            if spec.target == "openpbr":  # files for other renderers (the report names the folder)
                continue
            path = str(self.out_dir / spec.name)
            name = self._tile_pattern(spec.name)
            if self.settings.storage == "PACK":
                image = tiles.load_tiled(path) if self.tiled else bpy.data.images.load(path, check_existing=False)
                created.append(image)
                image.pack()
                image.filepath_raw = f"//{self.stem}_skin_maps/{name}"
                image.name = name
            else:
                count = len(bpy.data.images)
                image = bpy.data.images.load(path, check_existing=True)
                if len(bpy.data.images) > count:
                    created.append(image)
                    if self.tiled:
                        image.source = "TILED"
                elif not self.result.reused:
                    image.reload()
            image.colorspace_settings.name = "Non-Color"
            image[KEY_PROP], image[K_PROP], image[KIND_PROP], image[KCOUNT_PROP] = (
                self.key, spec.k, spec.kind.capitalize(), k_count)
            images[(spec.k, spec.kind.capitalize())] = image
        return images

    def _tile_pattern(self, name: str) -> str:
        """A map's name as a UDIM pattern for a tiled bake (``skin.1001_k1_color.exr`` -> ``skin.<UDIM>_k1_...``)."""
        if not self.tiled:
            return name
        first = self.albedo.tiles[0][0]
        return name.replace(f"{first:04d}", image_input.UDIM_TOKEN, 1)

    def _follow_source_uv(self, gnode: bpy.types.Node) -> None:
        """New texture nodes read the same UVs as the albedo's Image Texture node (when it has a link)."""
        src = self.source_node
        if src is None or self.material is None:
            return
        tree = gnode.id_data
        feed = wiring.feeding_socket(src.inputs["Vector"])
        if feed is not None and tree != src.id_data:  # inside the artist's node group: a UV Map node of its own
            uv = wiring.tag(tree.nodes.new("ShaderNodeUVMap"))  # (wiring.bake_into_group: the albedo reads a UV map)
            uv.uv_map, uv.parent = feed.node.uv_map, gnode.parent
            uv.location = (gnode.location.x - 700.0, gnode.location.y - 300.0)
            feed = uv.outputs["UV"]
        for sock in gnode.inputs:
            tex = oblique.map_node(sock)  # a map, also behind the grazing-light correction's Multiply
            if tex is None or tex.bl_idname != "ShaderNodeTexImage":
                continue
            tex.projection, tex.extension = src.projection, src.extension
            if feed is not None:
                tree.links.new(feed, tex.inputs["Vector"])

    def _undo_apply(self, images, node_names, groups_before, osl_before, previous_surface, previous_prop) -> None:
        if self.material is not None:
            tree = self.material.node_tree
            for name in node_names:
                node = tree.nodes.get(name)
                if node is not None:
                    tree.nodes.remove(node)
            for from_socket, to_socket in previous_surface or []:
                tree.links.new(from_socket, to_socket)
            if previous_prop is not None:
                self.material[nodes.PREVIOUS_SURFACE_PROP] = previous_prop
            elif nodes.PREVIOUS_SURFACE_PROP in self.material:
                del self.material[nodes.PREVIOUS_SURFACE_PROP]
            wiring.restore_shadow_thickness(self.material)  # recorded by this wiring (unwire removed the last)
            self.material.pop(wiring.TAKEN_INPUTS_PROP, None)
            wiring.unwire_unused_groups()  # a node group the maps went into, its material's nodes gone
        for image in images:
            bpy.data.images.remove(image)
        for name in set(bpy.data.node_groups.keys()) - groups_before:
            bpy.data.node_groups.remove(bpy.data.node_groups[name])
        if hasattr(self.scene, "cycles"):
            self.scene.cycles.shading_system = osl_before
        if self.result is not None and not self.result.reused and self.settings.storage == "FILES":
            for f in [*self.result.files, self.result.json_path]:
                Path(f).unlink(missing_ok=True)
