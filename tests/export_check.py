"""Run by tests/test_addon_export.py with the Python of each supported Blender (bpy 4.2, 5.0.1, 5.3): Blender's own
glTF 2.0, FBX, OBJ and USD exporters on an artist's material before and after Invert Skin Albedo (live group and
baked maps), through the extension zip installed in Blender's extension system.

    python tests/export_check.py ZIP WORKDIR

The material: an albedo PNG in an Image Texture feeding the Principled BSDF's Base Color, a roughness PNG
(Non-Color) feeding Roughness, a metallic PNG (Non-Color, 0) feeding Metallic (so the add-on's metal layer, a copy
of the Principled BSDF, is in the tree the exporters read), a normal-map PNG through a Normal Map node feeding
Normal.  For each mode the scene is
exported before and after the operator, each into its own folder; which node each renderer's Material Output takes
after it, whether Remove Skin SSS then gives back the material's nodes, values and links, and what each exporter
wrote about the material is
printed as one line ``RESULT{json}`` for the caller to compare: glTF's materials, textures and images; OBJ's .mtl
(less its comment lines); the names of the three PNGs found in the FBX file's bytes; USD's shader inputs (the
``inputs:`` lines of the .usda's Material prims, sorted).  BLENDER_USER_RESOURCES must point into WORKDIR.  Imports
only the standard library and bpy (what Blender's own Python has).

The process ends with ``os._exit(0)`` once the line is printed: bpy 4.2's module crashes at interpreter exit
(segmentation fault) after any glTF export, with or without this add-on (a bare UV sphere exported does it);
the add-on's own clean exit is tests/test_addon_versions.py's.
"""

from __future__ import annotations

import json
import os
import sys

import bpy

EXTENSION = "bl_ext.user_default.spectral_skin_sss"
#: The artist's textures: (file name, RGB 0..1 of a 4 x 4 image, colour space).
TEXTURES = {"albedo": ("albedo.png", (0.80, 0.55, 0.45), "sRGB"),
            "rough": ("rough.png", (0.45, 0.45, 0.45), "Non-Color"),
            "normal": ("normal.png", (0.5, 0.5, 1.0), "Non-Color"),
            "metal": ("metal.png", (0.0, 0.0, 0.0), "Non-Color")}


def write_png(folder: str, name: str, rgb) -> str:
    path = os.path.join(folder, name)
    image = bpy.data.images.new(name, 4, 4)
    image.pixels.foreach_set([*rgb, 1.0] * 16)
    image.filepath_raw, image.file_format = path, "PNG"
    image.save()
    bpy.data.images.remove(image)
    return path


def artist_scene(folder: str):
    """An empty scene holding a UV sphere whose material is the artist's (module docstring); returns the sphere."""
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    for material in list(bpy.data.materials):
        bpy.data.materials.remove(material)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=6, radius=1.0)
    obj = bpy.context.active_object
    material = bpy.data.materials.new("Skin")
    material.use_nodes = True
    obj.data.materials.append(material)
    tree = material.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    texs = {}
    for i, (key, (name, rgb, colorspace)) in enumerate(TEXTURES.items()):
        tex = tree.nodes.new("ShaderNodeTexImage")
        tex.image = bpy.data.images.load(write_png(folder, name, rgb), check_existing=True)
        tex.image.colorspace_settings.name = colorspace
        tex.location = (-700.0, 300.0 - 300.0 * i)
        texs[key] = tex
    tree.links.new(texs["albedo"].outputs["Color"], bsdf.inputs["Base Color"])
    tree.links.new(texs["rough"].outputs["Color"], bsdf.inputs["Roughness"])
    tree.links.new(texs["metal"].outputs["Color"], bsdf.inputs["Metallic"])
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(texs["normal"].outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], bsdf.inputs["Normal"])
    tree.nodes.active = texs["albedo"]
    return obj


def export_all(folder: str) -> dict:
    """Export the scene with each exporter into ``folder``; returns what each wrote about the material."""
    os.makedirs(folder, exist_ok=True)
    bpy.ops.export_scene.gltf(filepath=os.path.join(folder, "s.gltf"), export_format="GLTF_SEPARATE")
    bpy.ops.wm.obj_export(filepath=os.path.join(folder, "s.obj"))
    bpy.ops.export_scene.fbx(filepath=os.path.join(folder, "s.fbx"))
    bpy.ops.wm.usd_export(filepath=os.path.join(folder, "s.usda"))
    with open(os.path.join(folder, "s.gltf")) as f:
        gltf = json.load(f)
    with open(os.path.join(folder, "s.mtl")) as f:
        mtl = [ln.rstrip() for ln in f if ln.strip() and not ln.startswith("#")]
    with open(os.path.join(folder, "s.fbx"), "rb") as f:
        fbx = f.read()
    with open(os.path.join(folder, "s.usda")) as f:
        usda = f.read()
    return {"gltf": {key: gltf.get(key) for key in ("materials", "textures", "images")},
            "mtl": mtl,
            "fbx": sorted(name for name, _, _ in TEXTURES.values() if name.encode() in fbx),
            "usd": usd_material_inputs(usda)}


def usd_material_inputs(usda: str) -> list[str]:
    """The ``inputs:`` lines inside the .usda's Material prims (sorted, stripped)."""
    lines, depth, inside = [], 0, False
    for line in usda.splitlines():
        text = line.strip()
        if text.startswith("def Material "):
            inside, depth = True, 0
        if inside:
            depth += text.count("{") - text.count("}")
            if "inputs:" in text:
                lines.append(text)
            if depth == 0 and "}" in text:
                inside = False
    return sorted(lines)


def tree_state(material) -> tuple:
    """The material's nodes (name, type, location, socket values) and links, and its custom properties."""
    def value(socket):
        v = getattr(socket, "default_value", None)
        return None if v is None else (tuple(v) if hasattr(v, "__len__") and not isinstance(v, str) else v)
    tree = material.node_tree
    nodes = sorted((n.name, n.bl_idname, tuple(n.location), tuple(value(s) for s in n.inputs)) for n in tree.nodes)
    links = sorted((ln.from_node.name, ln.from_socket.identifier, ln.to_node.name, ln.to_socket.identifier)
                   for ln in tree.links)
    return nodes, links, sorted(material.keys())


def renders(tree) -> dict:
    """For each target (All: what exporters read; Cycles; EEVEE) the node feeding the Material Output Blender picks
    for it (``ShaderNodeTree.get_output_node``), through the add-on's metal layer (a Mix Shader whose input
    ``spectral_skin_sss_inner`` is the group's side): a node group's name, else the node's type."""
    out = {}
    for target in ("ALL", "CYCLES", "EEVEE"):
        links = tree.get_output_node(target).inputs["Surface"].links
        node = links[0].from_node if links else None
        while node is not None and node.get("spectral_skin_sss_base_layer"):
            node = node.inputs[node["spectral_skin_sss_inner"]].links[0].from_node
        out[target] = None if node is None else (node.node_tree.name if node.bl_idname == "ShaderNodeGroup"
                                                 else node.bl_idname)
    return out


def main() -> dict:
    work = sys.argv[2]
    bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default", enable_on_install=True)
    bpy.context.preferences.addons[EXTENSION].preferences.threads = 1
    out: dict = {"blender": bpy.app.version_string}
    for mode in ("LIVE", "BAKE"):
        folder = os.path.join(work, mode.lower())
        os.makedirs(folder, exist_ok=True)
        obj = artist_scene(folder)
        original = tree_state(obj.active_material)
        before = export_all(os.path.join(folder, "before"))
        try:
            with bpy.context.temp_override(object=obj, active_object=obj):
                result = sorted(bpy.ops.spectral_skin.invert_albedo(mode=mode, exact=(mode == "BAKE")))
        except RuntimeError as exc:
            result = [f"ERROR {exc}"]
        tree = obj.active_material.node_tree
        groups = sorted(n.node_tree.name for n in tree.nodes if n.bl_idname == "ShaderNodeGroup")
        out[mode] = {"invert": result, "groups": groups, "before": before, "renders": renders(tree),
                     "after": export_all(os.path.join(folder, "after"))}
        with bpy.context.temp_override(object=obj, active_object=obj):
            out[mode]["remove"] = sorted(bpy.ops.spectral_skin.remove())
        out[mode]["restored"] = tree_state(obj.active_material) == original
    return out


if __name__ == "__main__":
    print("RESULT" + json.dumps(main()), flush=True)
    sys.stderr.flush()
    os._exit(0)
