"""The mixture group's specular coat, its Normal and Roughness taken from the user's Principled BSDF, and the
scene's unit scale in Invert Skin Albedo: real bpy, real Cycles (CPU, 48 x 48 px, a few samples), real bakes.

(a) a smooth-shaded sphere under a small point light shows a highlight where the mirror direction meets the
    light, far above the same render with the coat off (IOR 1), for the SVM and the OSL group;
(b) a bump map connected to the user's Principled BSDF changes the render of the wired material, with the coat
    on and with it off (the subsurface closures take the normal too), well beyond the Monte Carlo noise;
(c) wiring keeps every user node and link, takes the Principled BSDF's Roughness (value or link) and Normal
    link, and gives the documented skin roughness when there is no Principled BSDF;
(d) Invert Skin Albedo bakes radii in the scene's units: unit scale 0.01 gives 100 x the radii of 1.0, and
    the maps' JSON records 0.01;
and the coat alone (no skin) reflects exactly the Fresnel reflectance F(mu) at any roughness (the energy
argument of blender_addon/nodes.py), and the F_dr polynomial matches the quadrature.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from blender_addon import nodes, oblique, probe, wiring  # noqa: E402
from exporters import cycles  # noqa: E402
from tests.addon_scene import (  # noqa: E402
    image_pixels,
    principled_coat_reflectance,
    run_invert,
    skin_codes,
    skin_object,
    write_image,
)

SIZE = 48
CAMERA = Vector((0.0, -5.0, 0.0))
LIGHT = Vector((2.5, -4.0, 2.0))
#: One skin-like medium (1 BU = 1 cm): Subsurface inputs of the group, uniform.
MEDIUM = cycles.medium_to_cycles(np.array([0.99, 0.97, 0.93]), np.array([30.0, 60.0, 90.0]), np.zeros(3),
                                 unit_scale_m=0.01)
COMPONENT = {"Color": MEDIUM.color, "Radius": MEDIUM.radius, "Weight": np.ones(3), "Anisotropy": 0.0}


def sphere_scene(samples: int = 16, seed: int = 1) -> tuple[bpy.types.Object, bpy.types.Material]:
    """Empty factory scene: a smooth unit sphere with a fresh material (Principled BSDF -> Output), a camera
    on -Y looking at it, a small point light up and to the right, a black world."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    cyc = scene.cycles
    cyc.device, cyc.samples, cyc.seed = "CPU", samples, seed
    cyc.use_denoising = cyc.use_adaptive_sampling = False
    scene.render.resolution_x = scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.world = bpy.data.worlds.new("Black")
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    bpy.ops.mesh.primitive_uv_sphere_add(segments=48, ring_count=24, radius=1.0)
    obj = bpy.context.active_object
    obj.data.shade_smooth()
    mat = bpy.data.materials.new("Skin")
    obj.data.materials.append(mat)
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    cam.location, cam.rotation_euler = CAMERA, (np.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    light = bpy.data.lights.new("Key", "POINT")
    light.energy, light.shadow_soft_size = 300.0, 0.05
    lamp = bpy.data.objects.new("Key", light)
    lamp.location = LIGHT
    scene.collection.objects.link(lamp)
    return obj, mat


def wire_constant(mat: bpy.types.Material, backend: str = "SVM") -> bpy.types.Node:
    """The mixture group (K = 1, the constant MEDIUM) wired into ``mat`` like the add-on does."""
    if backend == "OSL":
        bpy.context.scene.cycles.shading_system = True
    group = nodes.build_osl_group(1) if backend == "OSL" else nodes.build_svm_group(1)
    gnode = nodes.wire_into_material(mat, group)
    nodes.set_constant_inputs(gnode, [COMPONENT])
    return gnode


def render() -> np.ndarray:
    """Render the scene; linear RGB (SIZE, SIZE, 3), row 0 at the bottom (Blender's order)."""
    scene = bpy.context.scene
    with tempfile.TemporaryDirectory() as tmp:
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.filepath = os.path.join(tmp, "r.exr")
        bpy.ops.render.render(write_still=True)
        image = bpy.data.images.load(scene.render.filepath)
        px = np.empty(SIZE * SIZE * 4, np.float32)
        image.pixels.foreach_get(px)
        bpy.data.images.remove(image)
    return px.reshape(SIZE, SIZE, 4)[..., :3].astype(np.float64)


def highlight_pixel() -> tuple[int, int]:
    """(row, column) where the unit sphere mirrors LIGHT into the camera (point p = n with n bisecting the
    directions to light and camera, solved by fixed-point iteration), in Blender's bottom-up rows."""
    p = (LIGHT.normalized() + CAMERA.normalized()).normalized()
    for _ in range(50):
        p = ((LIGHT - p).normalized() + (CAMERA - p).normalized()).normalized()
    ndc = world_to_camera_view(bpy.context.scene, bpy.context.scene.camera, p)
    return int(ndc.y * SIZE), int(ndc.x * SIZE)


@pytest.mark.parametrize("backend", ["SVM", "OSL"])
def test_highlight_where_the_mirror_direction_meets_the_light(backend):
    _, mat = sphere_scene()
    mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.3  # the user's roughness
    gnode = wire_constant(mat, backend)
    assert gnode.inputs["Roughness"].default_value == pytest.approx(0.3)
    coat = render().mean(axis=2)
    gnode.inputs["IOR"].default_value = 1.0  # no coat: F = 0, the mixture's weight is 1
    bare = render().mean(axis=2)
    row, col = highlight_pixel()
    peak = np.unravel_index(np.argmax(coat - bare), coat.shape)
    window = (slice(row - 1, row + 2), slice(col - 1, col + 2))
    ratio = coat[window].max() / bare[window].max()
    far = (slice(SIZE // 2 - 2, SIZE // 2 + 2), slice(SIZE // 2 - 2, SIZE // 2 + 2))  # lit skin, no highlight
    print(f"\n{backend}: highlight predicted at {(row, col)}, largest coat - bare at {tuple(map(int, peak))}; "
          f"peak {coat[window].max():.3f} vs {bare[window].max():.3f} without the coat ({ratio:.2f}x); "
          f"centre {coat[far].mean() / bare[far].mean():.3f}x; image mean {coat.mean():.4f} vs {bare.mean():.4f}")
    assert abs(int(peak[0]) - row) <= 2 and abs(int(peak[1]) - col) <= 2
    assert ratio > 1.5  # measured 1.87 (SVM), 1.89 (OSL)
    assert abs(coat[far].mean() / bare[far].mean() - 1.0) < 0.15  # the coat takes what it reflects, no more


def blocks(image: np.ndarray, size: int = 4) -> np.ndarray:
    """Means over size x size pixel blocks (the bump's bands are wider; the noise averages down)."""
    h, w, c = image.shape
    return image.reshape(h // size, size, w // size, size, c).mean(axis=(1, 3))


def test_bump_on_the_users_principled_changes_the_render():
    _, mat = sphere_scene(samples=64)
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    waves = tree.nodes.new("ShaderNodeTexWave")  # bands: wrinkles, 1 mm deep on a 1 cm sphere
    bump = tree.nodes.new("ShaderNodeBump")
    bump.inputs["Distance"].default_value = 0.1
    tree.links.new(waves.outputs["Fac"], bump.inputs["Height"])
    tree.links.new(bump.outputs["Normal"], principled.inputs["Normal"])
    gnode = wire_constant(mat)  # the Principled BSDF no longer reaches the output: only the group can show it
    assert gnode.inputs["Normal"].links[0].from_node == bump
    diffs = {}
    for ior in (nodes.DEFAULT_IOR, 1.0):  # coat on; coat off (the subsurface closures alone)
        gnode.inputs["IOR"].default_value = ior
        bumped = blocks(render())
        bump.inputs["Strength"].default_value = 0.0
        flat = blocks(render())
        bpy.context.scene.cycles.seed = 2
        flat_again = blocks(render())  # the same image, another seed: the Monte Carlo noise
        bpy.context.scene.cycles.seed = 1
        bump.inputs["Strength"].default_value = 1.0
        diffs[ior] = (np.abs(bumped - flat).mean(), np.abs(flat_again - flat).mean())
    print("\nmean |bumped - flat| vs |flat (seed 2) - flat| (4 x 4 blocks): "
          + ", ".join(f"IOR {ior}: {d:.4f} vs {n:.4f} ({d / n:.1f}x)" for ior, (d, n) in diffs.items()))
    for d, noise_level in diffs.values():
        assert d > 3.0 * noise_level


def link_set(tree: bpy.types.NodeTree) -> set[tuple[str, str, str, str]]:
    """Every link of ``tree`` as (from node, from socket, to node, to socket)."""
    return {(ln.from_node.name, ln.from_socket.identifier, ln.to_node.name, ln.to_socket.identifier)
            for ln in tree.links}


def test_wiring_keeps_user_nodes_and_takes_their_roughness_and_normal():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mat = bpy.data.materials.new("UserSkin")
    tree = mat.node_tree
    principled = tree.nodes["Principled BSDF"]
    principled.inputs["Roughness"].default_value = 0.27
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(normal_map.outputs["Normal"], principled.inputs["Normal"])
    nodes_before, links_before = {n.name for n in tree.nodes}, link_set(tree)
    gnode = nodes.wire_into_material(mat, nodes.build_svm_group(1))
    assert nodes_before < {n.name for n in tree.nodes}
    assert links_before < link_set(tree)  # every link of the user's stays (the group feeds its own outputs)
    assert gnode.inputs["Roughness"].default_value == pytest.approx(0.27)
    assert not gnode.inputs["Roughness"].is_linked
    assert gnode.inputs["Normal"].links[0].from_node == normal_map
    assert principled.inputs["Normal"].links[0].from_node == normal_map  # the user's link stays

    value = tree.nodes.new("ShaderNodeValue")  # a roughness map: the link is taken, not the value
    tree.links.new(value.outputs[0], principled.inputs["Roughness"])
    tree.links.new(principled.outputs["BSDF"], tree.nodes["Material Output"].inputs["Surface"])
    gnode2 = nodes.wire_into_material(mat, nodes.build_svm_group(1))
    assert gnode2.inputs["Roughness"].links[0].from_node == value
    again = nodes.wire_into_material(mat, nodes.build_svm_group(1))  # re-wiring over our own group
    assert again.inputs["Roughness"].links[0].from_node == value
    assert again.inputs["Normal"].links[0].from_node == normal_map
    assert nodes_before < {n.name for n in tree.nodes}  # the user's nodes all stay; the earlier groups went
    assert [n.name for n in tree.nodes if n.bl_idname == "ShaderNodeGroup"] == [again.name]

    bare = bpy.data.materials.new("NoPrincipled")
    bare.node_tree.nodes.remove(bare.node_tree.nodes["Principled BSDF"])
    plain = nodes.wire_into_material(bare, nodes.build_svm_group(1))
    assert plain.inputs["Roughness"].default_value == pytest.approx(nodes.SKIN_ROUGHNESS)
    assert nodes.SKIN_ROUGHNESS == pytest.approx(np.sqrt(nodes.SKIN_FACET_SLOPE))
    assert not plain.inputs["Normal"].is_linked


@pytest.mark.parametrize("backend", ["SVM", "OSL"])
def test_coat_alone_reflects_as_a_principled_specular_layer(backend):
    # Weights 0 (no skin): on the probe slab under the white world (radiance 1) the group renders the coat's
    # reflectance, which must be that of Blender's own Principled BSDF with a black base (its specular layer)
    # at every view angle and roughness; at roughness 0 that is the Fresnel reflectance F(mu).
    scene = probe.new_scene(samples=64, resolution=8, seed=3)
    if backend == "OSL":
        scene.cycles.shading_system = True
    group = nodes.build_osl_group(1) if backend == "OSL" else nodes.build_svm_group(1)
    gnode = nodes.wire_into_material(probe.slab_material(), group)
    nodes.set_constant_inputs(gnode, [{"Weight": np.zeros(3)}])
    mus = probe.hemispherical_nodes(4)[0]
    for roughness in (0.0, nodes.SKIN_ROUGHNESS):
        gnode.inputs["Roughness"].default_value = roughness
        got = []
        for mu in mus:
            probe.view_from(scene, float(mu))
            got.append(probe.render_mean(scene)[0])
        expected = principled_coat_reflectance(scene, mus, roughness, nodes.DEFAULT_IOR)
        print(f"\n{backend} roughness {roughness:.2f}: mu {np.round(mus, 3)} coat {np.round(np.mean(got, axis=1), 4)} "
              f"Principled {np.round(expected.mean(axis=1), 4)}")
        np.testing.assert_allclose(np.array(got), expected, rtol=0.01, atol=2e-4)
        if roughness == 0.0:
            fresnel = cycles.fresnel_dielectric(mus, nodes.DEFAULT_IOR)
            np.testing.assert_allclose(np.array(got), fresnel[:, None] * np.ones(3), rtol=0.01)


def test_diffuse_fresnel_fit_and_coat_scale():
    from training.sim.physics import diffuse_specular

    for n in (1.05, 1.2, 1.33, 1.4, 1.5, 1.7, 2.0, 3.0, 3.8):
        assert cycles.diffuse_fresnel(n) == pytest.approx(diffuse_specular(n), abs=1.1e-3)
    assert cycles.diffuse_fresnel(1.4) == pytest.approx(0.0768115, abs=1e-6)
    assert cycles.diffuse_fresnel(1.0) == 0.0 and cycles.coat_body_scale(0.3, 1.0) == 1.0
    x, w = np.polynomial.legendre.leggauss(64)
    mu = 0.5 * (x + 1.0)
    mean = np.sum(w * mu * cycles.coat_body_scale(mu, 1.4))  # 2 int scale(mu) mu dmu
    assert mean == pytest.approx(1.0, abs=1e-6)


def test_invert_takes_the_scene_unit_scale(addon, tmp_path):
    albedo = write_image(tmp_path / "albedo.png", skin_codes(), "uint8")
    radii = {}
    for scale in (1.0, 0.01):
        units = bpy.context.scene.unit_settings
        units.system, units.scale_length = "METRIC", scale
        obj, mat, _ = skin_object(albedo)
        out = tmp_path / f"maps_{scale}"
        assert run_invert(obj, backend="SVM", storage="FILES", output_dir=str(out)) == {"FINISHED"}
        (record,) = out.glob("*_maps.json")  # the second image is "albedo.png.001": its stem differs
        assert json.loads(record.read_text())["unit_scale_m_per_blender_unit"] == pytest.approx(scale, rel=1e-6)
        gnode = wiring.wired_group_node(mat)
        radii[scale] = image_pixels(oblique.map_node(gnode.inputs["k1 Radius"]).image)[..., :3]
    ratio = radii[0.01] / radii[1.0]
    print(f"\nk1 radius at unit scale 0.01 / at 1.0: {ratio.min():.6f} .. {ratio.max():.6f}")
    np.testing.assert_allclose(ratio, 100.0, rtol=1e-3)  # fast-path radius maps are half floats (2^-11 each)
