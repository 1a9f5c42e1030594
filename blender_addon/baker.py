"""The Blender side of a bake: find the albedo, run an exporters.baking.BakeJob, turn the maps into images
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

from exporters import baking, inference, maps

from . import nodes

#: Colour-space names of Blender's OCIO config that mean "not sRGB-encoded" (data or linear).
_LINEAR_SPACES = ("non-color", "linear", "raw", "acescg", "aces2065", "filmic log", "agx log", "xyz")


class BakeInputError(ValueError):
    """Bad input for Invert Skin Albedo; the message tells the user what to change."""


def missing_model_message(path: str) -> str:
    return f"model not found at {path}: train/export it or set the path in preferences"


@dataclass
class BakeSettings:
    """What the operator asks for.  ``filepath`` (a file on disk) wins over ``image_name`` (an image
    datablock), which wins over the active Image Texture node of the active material.  ``storage``:
    "PACK" (images packed into the .blend) or "FILES" (EXR files in ``output_dir``, default a folder
    beside the saved .blend).  ``backend``: "AUTO", "SVM" or "OSL"."""

    model_path: str
    filepath: str = ""
    image_name: str = ""
    storage: str = "PACK"
    output_dir: str = ""
    colorspace: str = "FROM_IMAGE"
    backend: str = "AUTO"
    overwrite: bool = False
    match_exposure: bool = False
    threads: int = 0
    chunk: int = 2048


def active_image_node(material: bpy.types.Material | None) -> bpy.types.Node | None:
    """The material's active node if it is an Image Texture with an image, else None."""
    if material is None or material.node_tree is None:
        return None
    node = material.node_tree.nodes.active
    if node is not None and node.bl_idname == "ShaderNodeTexImage" and node.image is not None:
        return node
    return None


def pick_backend(scene: bpy.types.Scene, requested: str) -> str:
    """SVM or OSL.  AUTO: OSL where Cycles can run it (scene device CPU, or GPU with OptiX), SVM elsewhere
    (CUDA, HIP, Metal, oneAPI).  Asking for OSL on a device that cannot run it is an error."""
    device = scene.cycles.device if hasattr(scene, "cycles") else "CPU"
    compute = "NONE"
    cycles_addon = bpy.context.preferences.addons.get("cycles")
    if cycles_addon is not None:
        compute = getattr(cycles_addon.preferences, "compute_device_type", "NONE")
    osl_ok = device == "CPU" or compute == "OPTIX"
    if requested == "AUTO":
        return "OSL" if osl_ok else "SVM"
    if requested == "OSL" and not osl_ok:
        raise BakeInputError(f"OSL does not run on the scene's device ({compute} GPU): choose SVM")
    if requested not in ("SVM", "OSL"):
        raise BakeInputError(f"unknown shading path {requested!r}")
    return requested


def _image_colorspace(image: bpy.types.Image, requested: str) -> str:
    if requested != "FROM_IMAGE":
        return requested
    name = image.colorspace_settings.name.lower()
    if name.startswith("srgb") or name == "filmic srgb":
        return "srgb"
    if any(name.startswith(p) for p in _LINEAR_SPACES):
        return "linear"
    return "auto"


def _albedo_from_pixels(image: bpy.types.Image, colorspace: str) -> maps.AlbedoImage:
    """An image that has no file on disk (generated or packed): read Blender's pixel buffer."""
    w, h = image.size
    ch = image.channels
    if w < 1 or h < 1 or ch < 1:
        raise BakeInputError(f"image '{image.name}' has no pixels (is its file missing?)")
    px = np.empty(w * h * ch, dtype=np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, ch)[::-1].astype(np.float64)  # Blender stores rows bottom-up
    bad = ~np.isfinite(px)
    if bad.any():
        y, x, _ = np.argwhere(bad)[0]
        raise BakeInputError(f"image '{image.name}': {int(bad.any(axis=2).sum())} texel(s) with NaN/Inf, first at "
                             f"(x={x}, y={y})")
    rgb = np.repeat(px[..., :1], 3, axis=2) if ch < 3 else px[..., :3]
    alpha = px[..., 3] if ch == 4 else (px[..., 1] if ch == 2 else None)
    if np.any(rgb < 0):
        raise BakeInputError(f"image '{image.name}' has negative texels; an albedo cannot be negative")
    used = colorspace if colorspace in ("srgb", "linear") else ("linear" if image.is_float else "srgb")
    if used == "srgb":
        from exporters.colorimetry import srgb_decode

        rgb = np.asarray(srgb_decode(rgb), dtype=np.float64)
    if alpha is not None and np.all(alpha >= 1.0):
        alpha = None  # Blender gives every buffer an alpha channel; an opaque one is no alpha at all
    return maps.AlbedoImage(rgb=rgb, alpha=alpha, colorspace=used, source_format="float" if image.is_float else
                            "uint8", n_clamped=0, n_channels=3 if ch >= 3 else ch)


def _image_file(image: bpy.types.Image) -> str | None:
    """Absolute path of the image's file if it has one on disk (not packed/generated)."""
    if image.source not in ("FILE", "SEQUENCE", "TILED") or image.packed_file is not None or not image.filepath:
        return None
    return bpy.path.abspath(image.filepath, library=image.library)


class AddonBake:
    """One Invert Skin Albedo run (see the module docstring)."""

    def __init__(self, context: bpy.types.Context, settings: BakeSettings) -> None:
        self.settings = settings
        self.scene = context.scene
        obj = context.object
        self.material = obj.active_material if obj is not None else None
        if self.material is not None and self.material.node_tree is None:
            self.material = None  # a material without nodes: the maps and the group are made, nothing is wired
        self.source_node = None
        if not os.path.isfile(settings.model_path):
            raise BakeInputError(missing_model_message(settings.model_path))
        self.albedo, self.stem, self.input_name = self._read_albedo()
        self.backend = pick_backend(self.scene, settings.backend)
        self.model = inference.load_model(settings.model_path, threads=settings.threads)
        self.out_dir, self._temp_dir = self._output_folder()
        scale = self.scene.unit_settings.scale_length if self.scene.unit_settings.system != "NONE" else 1.0
        self.options = baking.BakeOptions(targets=("cycles",), unit_scale_m=float(scale or 1.0),
                                          threads=settings.threads, chunk=settings.chunk,
                                          match_exposure=settings.match_exposure, overwrite=settings.overwrite)
        try:
            self.job = baking.BakeJob(self.albedo, self.out_dir, self.stem, self.model, self.options,
                                      input_image=self.input_name)
        except BaseException:
            self._remove_temp_dir()
            raise
        self._steps = None
        self.fraction = 0.0
        self.result: baking.BakeResult | None = None

    # -- inputs --------------------------------------------------------------------------------------------
    def _read_albedo(self) -> tuple[maps.AlbedoImage, str, str]:
        s = self.settings
        if s.filepath:
            path = bpy.path.abspath(s.filepath)
            cs = s.colorspace if s.colorspace in ("auto", "srgb", "linear") else "auto"
            return maps.read_albedo(path, colorspace=cs), Path(path).stem, path
        if s.image_name:
            image = bpy.data.images.get(s.image_name)
            if image is None:
                raise BakeInputError(f"no image named '{s.image_name}' in this file")
        else:
            node = active_image_node(self.material)
            if node is None:
                raise BakeInputError("no active image: select an Image Texture node with an image in the active "
                                     "material, or choose an image")
            self.source_node, image = node, node.image
        cs = _image_colorspace(image, s.colorspace)
        stem = Path(image.name).stem or "albedo"
        path = _image_file(image)
        if path is not None:
            if not os.path.isfile(path):
                raise BakeInputError(f"the file of image '{image.name}' is missing: {path}")
            return maps.read_albedo(path, colorspace=cs), stem, path
        return _albedo_from_pixels(image, cs), stem, f"<image {image.name}>"

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
        if not folder.exists():
            if not folder.parent.is_dir() or not os.access(folder.parent, os.W_OK):
                raise BakeInputError(f"cannot create the output folder {folder}")
            folder.mkdir()
            return folder, folder  # a folder we made: removed again (if still empty) on cancel or error
        return folder, None

    # -- running -------------------------------------------------------------------------------------------
    def step(self) -> bool:
        """Do one inference chunk; False when all texels are done."""
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

        Returns a one-line report; on failure everything created here is removed again."""
        created_images: list[bpy.types.Image] = []
        created_nodes: list[str] = []
        group_existed = set(bpy.data.node_groups.keys())
        osl_before = getattr(self.scene.cycles, "shading_system", False)
        previous_surface = None
        previous_prop = self.material.get(nodes.PREVIOUS_SURFACE_PROP) if self.material is not None else None
        try:
            self.result = self.job.finish()
            images = {}
            for spec in baking.map_specs(self.stem, self.model.k, ("cycles",)):
                image = bpy.data.images.load(str(self.out_dir / spec.name), check_existing=False)
                created_images.append(image)
                image.colorspace_settings.name = "Non-Color"
                if self.settings.storage == "PACK":
                    image.pack()
                    image.filepath_raw = f"//{self.stem}_skin_maps/{spec.name}"
                    image.name = spec.name
                images[(spec.k, spec.kind.capitalize())] = image
            if self.backend == "OSL":
                self.scene.cycles.shading_system = True
            group = nodes.ensure_group(self.model.k, self.backend)
            report = f"baked {len(images)} maps (K={self.model.k})"
            if self.material is not None:
                before = {n.name for n in self.material.node_tree.nodes}
                out_links = [ln for ln in self.material.node_tree.links
                             if ln.to_node.bl_idname == "ShaderNodeOutputMaterial" and ln.to_socket.name == "Surface"]
                previous_surface = [(ln.from_socket, ln.to_socket) for ln in out_links]
                gnode = nodes.wire_into_material(self.material, group, images)
                created_nodes = [n.name for n in self.material.node_tree.nodes if n.name not in before]
                gnode.inputs["IOR"].default_value = self.options.ior
                gnode.inputs["Roughness"].default_value = 0.0
                self._follow_source_uv(gnode)
                report += f", {self.backend} node group wired into '{self.material.name}'"
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
        if self.backend == "OSL" and not osl_before:
            report += "; Open Shading Language enabled for the scene"
        notes = self.result.notes + ([f"{self.result.stats['unreachable_channels']} texel channel(s) brighter than "
                                      "Cycles can show"] if self.result.stats["unreachable_channels"] else [])
        return report + ("; note: " + "; ".join(notes) if notes else "")

    def _follow_source_uv(self, gnode: bpy.types.Node) -> None:
        """New texture nodes read the same UVs as the albedo's Image Texture node (when it has a link)."""
        src = self.source_node
        if src is None or self.material is None:
            return
        tree = self.material.node_tree
        vec = src.inputs["Vector"]
        for sock in gnode.inputs:
            for link in sock.links:
                tex = link.from_node
                if tex.bl_idname != "ShaderNodeTexImage":
                    continue
                tex.projection, tex.extension = src.projection, src.extension
                if vec.is_linked:
                    tree.links.new(vec.links[0].from_socket, tex.inputs["Vector"])

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
        for image in images:
            bpy.data.images.remove(image)
        for name in set(bpy.data.node_groups.keys()) - groups_before:
            bpy.data.node_groups.remove(bpy.data.node_groups[name])
        if hasattr(self.scene, "cycles"):
            self.scene.cycles.shading_system = osl_before
        if self.result is not None and self.settings.storage == "FILES":
            for f in [*self.result.files, self.result.json_path]:
                Path(f).unlink(missing_ok=True)
