"""EEVEE reads the live group's tables at their full resolution on a textured skin.

EEVEE picks the mipmap level of an Image Texture's Linear lookup from the screen-space derivatives of its coordinates.
The live group's table coordinates are computed from the painted colour, and on a textured skin they jump between
neighbouring pixels (from one slice of the table to the next), so Image Texture lookups there read blurred levels:
before the EEVEE output read its tables through Environment Textures (blender_addon.live._Builder.environment), the
effective radius it hands EEVEE's Principled BSDF was 36 % off in the median on this texture and an edit's colour
up to ΔE76 8.8 (speckles in Material Preview).  Uniform colours, as the other EEVEE tests paint, hide it.

One EEVEE process per supported Blender (software OpenGL where there is no GPU: Mesa, EGL surfaceless) renders the
demo's medium skin texture one texel per pixel after Invert Skin Albedo, and emits what the group's EEVEE output
takes: the effective radius (at neutral inputs and under Blood 2.5) and the edited colour.  The references are
numpy's (exporters.edit_table: table_records, effective_radius, shift), at the texels EEVEE read.  Mesa's bilinear
weights are coarse (a lookup a quarter of the way between two texels lands 0.04 texel off), which leaves up to
0.7 % on the radius: the bounds allow 2 % in the median and 3 % anywhere.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from exporters import edit_table, texel_table
from exporters.bake.table_cache import default_table_path
from exporters.colorimetry import delta_e76, linear_srgb_to_lab, srgb_decode
from tests.addon_scene import write_image
from tests.blender_versions import BLENDERS, IDS

ROOT = Path(__file__).resolve().parents[1]
SIZE = 48  # texels and pixels per side
EDIT = (1.0, 2.5, 0.0)  # Melanin, Blood, Oxygenation

SCRIPT = """
import json, sys
sys.path.insert(0, {root!r})
import bpy, numpy as np
import blender_addon
from blender_addon import probe, live_edits
from pathlib import Path
size = {size}
scene = probe.new_scene(samples=1, resolution=size, seed=1)
engines = {{item.identifier for item in scene.render.bl_rna.properties["engine"].enum_items}}
scene.render.engine = "BLENDER_EEVEE_NEXT" if "BLENDER_EEVEE_NEXT" in engines else "BLENDER_EEVEE"  # 4.2-4.5: Next
scene.eevee.taa_render_samples = 1
scene.render.filter_size = 0.0
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
blender_addon.register()
mat = probe.slab_material("skin")  # the texture over the top face, one texel per pixel, into a Principled BSDF
tree = mat.node_tree
coords, mapping = tree.nodes.new("ShaderNodeTexCoord"), tree.nodes.new("ShaderNodeMapping")
mapping.inputs["Location"].default_value = (0.5, 0.5, 0.0)
texture = tree.nodes.new("ShaderNodeTexImage")
texture.image, texture.interpolation = bpy.data.images.load({texture!r}), "Closest"
bsdf = tree.nodes.new("ShaderNodeBsdfPrincipled")
tree.links.new(coords.outputs["Object"], mapping.inputs["Vector"])
tree.links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
tree.links.new(texture.outputs["Color"], bsdf.inputs["Base Color"])
tree.links.new(bsdf.outputs[0], probe.material_output(mat).inputs["Surface"])
slab = bpy.data.objects["ProbeSlab"]
with bpy.context.temp_override(object=slab, active_object=slab):
    assert bpy.ops.spectral_skin.invert_albedo() == {{"FINISHED"}}
node = live_edits.live_node(mat)
group = node.node_tree
gout = next(n for n in group.nodes if n.bl_idname == "NodeGroupOutput")
edits = next(n for n in group.nodes if n.bl_idname == "ShaderNodeGroup" and n.node_tree.get("spectral_skin_sss_eevee"))
bsdf = next(n for n in group.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
for name, socket in (("Check EEVEE Color", edits.outputs["Color"]),
                     ("Check EEVEE Radius", bsdf.inputs["Subsurface Radius"].links[0].from_socket)):
    group.interface.new_socket(name, in_out="OUTPUT", socket_type="NodeSocketColor")
    group.links.new(socket, gout.inputs[name])
emission = tree.nodes.new("ShaderNodeEmission")
for out in [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]:
    tree.links.new(emission.outputs[0], out.inputs["Surface"])

def render(name, socket):
    tree.links.new(socket, emission.inputs["Color"])
    scene.render.filepath = str(Path({tmp!r}) / name)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(scene.render.filepath, check_existing=False)
    px = np.empty(size * size * 4, np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(size, size, 4)[::-1, :, :3].tolist()  # rows top to bottom, as the texture file

result = {{"painted": render("painted.exr", texture.outputs["Color"]),
          "radius": render("radius.exr", node.outputs["Check EEVEE Radius"]),
          "unit": node.inputs["Translucency"].default_value / node.inputs["Unit Scale"].default_value}}
live_edits.set_edit(node, {edit!r})
result["edited radius"] = render("edited_radius.exr", node.outputs["Check EEVEE Radius"])
result["edited colour"] = render("edited_colour.exr", node.outputs["Check EEVEE Color"])
print("RESULT" + json.dumps(result))
"""


@pytest.fixture(scope="module", params=BLENDERS, ids=IDS)
def eevee(request, tmp_path_factory):
    """The painted texels (SIZE, SIZE, 3) linear, and the EEVEE process's renders (module docstring), in the oldest,
    the project's and the newest Blender (tests/blender_versions.py): the add-on from this checkout."""
    from training.demo_subject import TONES, skin_albedo_texture

    python = request.param[1]
    if not python.is_file():
        pytest.skip(f"{python.parent.parent.name} is missing: `make blender-envs` creates it (make test does)")
    tmp = tmp_path_factory.mktemp("eevee_lookups")
    codes = skin_albedo_texture(SIZE, seed=0, base=TONES["medium"])
    texture = write_image(tmp / "skin.png", codes, "uint8")
    script = SCRIPT.format(root=str(ROOT), size=SIZE, texture=str(texture), tmp=str(tmp), edit=EDIT)
    env = dict(os.environ, EGL_PLATFORM=os.environ.get("EGL_PLATFORM", "surfaceless"), PYTHONPATH=str(ROOT))
    env.pop("PYTHONHOME", None)
    done = subprocess.run([str(python), "-c", script], capture_output=True, text=True, env=env, timeout=1200)
    line = next((ln for ln in done.stdout.splitlines() if ln.startswith("RESULT")), None)
    assert line is not None, done.stdout[-2000:] + done.stderr[-2000:]
    result = {name: np.asarray(value, np.float64) for name, value in json.loads(line[len("RESULT"):]).items()}
    painted = srgb_decode(codes.astype(np.float64) / 255.0)
    # the texels, one per pixel, in order; EEVEE holds the decoded texture at half precision, which the group reads
    np.testing.assert_allclose(result["painted"], painted, rtol=1e-2, atol=1e-3)
    return result["painted"].reshape(-1, 3), result


def _tables():
    """The shipped model's texel table and edit table."""
    model = ROOT / "blender_addon" / "models" / "skin_inversion.onnx"
    return texel_table.load(default_table_path(model)), edit_table.load(edit_table.default_path(model))


def _effective_radius(texels: texel_table.TexelTable, rgb: np.ndarray) -> np.ndarray:
    """sum_k w_k r_k (N, 3), metres, of the table's media at ``rgb`` as the live group looks them up (numpy)."""
    return edit_table.effective_radius(edit_table.table_records(texels, rgb, ("cycles",)))


@pytest.mark.slow
def test_eevee_reads_the_tables_at_full_resolution_on_a_textured_skin(eevee):
    painted, result = eevee
    texels, edits = _tables()
    d = edit_table.shift(edits, painted, np.array([EDIT]))
    edited = edit_table.edited_colour(painted, d)
    cases = {"neutral": (result["radius"], _effective_radius(texels, painted)),
             "blood 2.5": (result["edited radius"], _effective_radius(texels, edited) * np.exp(d[:, 3:6]))}
    for name, (rendered, metres) in cases.items():
        rel = np.abs(rendered.reshape(-1, 3) / (metres * result["unit"]) - 1).max(axis=1)
        print(f"\nEEVEE radius, {name}: relative error median {np.median(rel):.4f}, max {rel.max():.4f}")
        assert np.median(rel) < 0.02 and rel.max() < 0.03, name
    de = delta_e76(linear_srgb_to_lab(result["edited colour"].reshape(-1, 3)), linear_srgb_to_lab(edited))
    print(f"EEVEE edited colour ΔE76 mean {de.mean():.3f}, max {de.max():.3f}")
    assert np.abs(edited / painted - 1).max() > 0.1  # the edit moves the colour
    assert de.max() < 0.5
