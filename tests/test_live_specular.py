"""The artist's specular inputs keep their effect through Invert Skin Albedo's live group, in real Cycles.

The probe box (blender_addon/probe.py: white world, camera straight above) carries medium skin through the artist's
Principled BSDF; the operator wires the live group after one specular input of that Principled BSDF was changed, and
the render (same seed as the default's) moves as the physics of a layer seen at normal incidence under a uniform
white world predicts, within 30 % of the predicted change:

* **Specular IOR Level** 1 doubles F0: the coat reflects F0' = 2 F0 and the skin below is weighted
  (1 - F0') / (1 - F_dr(n')) instead of (1 - F0) / (1 - F_dr(n)) (blender_addon/nodes.py), with F_dr the
  cosine-weighted mean of the Fresnel reflectance, here by quadrature; level 0 switches the coat off;
* **Specular Tint** (1, 0.2, 0.2) takes 0.8 F0 from green and blue;
* **Coat Weight** 1 (IOR 1.5, nearly smooth) reflects F0(1.5) on top and leaves the rest 1 - F0(1.5) of the skin;
* **Sheen Weight** 1 adds light (a Sheen BSDF over the skin);
and a link into one of them (a Value node) is taken over as a link.  The operator's *Principled's convention* darkens
the body as a Principled BSDF's specular layer darkens its base, measured by rendering a Principled BSDF in the same
scene.
"""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import blender_addon  # noqa: E402
from blender_addon import nodes, probe  # noqa: E402
from exporters.colorimetry import srgb_decode, srgb_encode  # noqa: E402
from exporters.cycles import fresnel_dielectric  # noqa: E402
from tests.addon_scene import write_image  # noqa: E402

MEDIUM = np.array([0.40, 0.20, 0.12])
SAMPLES = 64


def _f0(n: float) -> float:
    return ((n - 1.0) / (n + 1.0)) ** 2


def _f_dr(n: float) -> float:
    """Cosine-weighted mean of the Fresnel reflectance, 2 int F(mu) mu dmu (midpoint rule, 4000 steps)."""
    mu = (np.arange(4000) + 0.5) / 4000
    return float(2.0 * np.mean(fresnel_dielectric(mu, n) * mu))


def _level_ior(n: float, level: float) -> float:
    root = np.sqrt(_f0(n) * 2.0 * level)
    return float((1.0 + root) / (1.0 - root))


def _render(tmp_path: Path, convention: bool = False, **inputs) -> tuple[np.ndarray, bpy.types.Node]:
    """Mean linear RGB of the probe after the operator, the artist's Principled BSDF set to ``inputs``."""
    scene = probe.new_scene(samples=SAMPLES, resolution=16, seed=4)
    scene.unit_settings.system, scene.unit_settings.scale_length = "METRIC", 0.005
    codes = np.round(255 * srgb_encode(MEDIUM)).astype(np.uint8)
    png = write_image(tmp_path / "medium.png", np.broadcast_to(codes, (2, 2, 3)).copy(), "uint8")
    mat = probe.slab_material("Skin")
    tree = mat.node_tree
    bsdf = tree.nodes.new("ShaderNodeBsdfPrincipled")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(png))
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    tree.links.new(bsdf.outputs[0], probe.material_output(mat).inputs["Surface"])
    bsdf.inputs["Roughness"].default_value = 0.3
    for name, value in inputs.items():
        bsdf.inputs[name].default_value = value
    slab = bpy.data.objects["ProbeSlab"]
    blender_addon.register()
    try:
        with bpy.context.temp_override(object=slab, active_object=slab):
            assert bpy.ops.spectral_skin.invert_albedo(principled_convention=convention) == {"FINISHED"}
        gnode = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeGroup")
        mean, _, _ = probe.render_mean(scene)
    finally:
        blender_addon.unregister()
    return mean, gnode


@pytest.fixture(scope="module")
def default(tmp_path_factory):
    return _render(tmp_path_factory.mktemp("default"))[0]


def _painted() -> np.ndarray:
    return srgb_decode(np.round(255 * srgb_encode(MEDIUM)) / 255.0)


def _layer(n: float) -> np.ndarray:
    """Coat plus skin straight above under the white world, for a coat of index n (the live group's layering)."""
    return _f0(n) + _painted() * (1.0 - _f0(n)) / (1.0 - _f_dr(n))


def _check(measured: np.ndarray, predicted: np.ndarray) -> None:
    print(f"\nchange {np.round(measured, 4).tolist()} predicted {np.round(predicted, 4).tolist()}")
    assert np.all(np.abs(measured - predicted) <= 0.3 * np.abs(predicted)), (measured, predicted)


@pytest.mark.parametrize("level", [1.0, 0.0])
def test_specular_ior_level(tmp_path, default, level):
    mean, gnode = _render(tmp_path, **{"Specular IOR Level": level})
    assert gnode.inputs["Specular IOR Level"].default_value == pytest.approx(level)
    n = nodes.DEFAULT_IOR
    _check(mean - default, _layer(_level_ior(n, level)) - _layer(n))


def test_specular_tint(tmp_path, default):
    mean, _ = _render(tmp_path, **{"Specular Tint": (1.0, 0.2, 0.2, 1.0)})
    drop = 0.8 * _f0(nodes.DEFAULT_IOR)
    assert abs(mean[0] - default[0]) < 0.2 * drop
    _check((mean - default)[1:], np.array([-drop, -drop]))


def test_coat(tmp_path, default):
    mean, _ = _render(tmp_path, **{"Coat Weight": 1.0, "Coat IOR": 1.5, "Coat Roughness": 0.03})
    f = _f0(1.5)
    _check(mean - default, f - f * default)


def test_sheen_and_linked_inputs(tmp_path, default):
    mean, gnode = _render(tmp_path, **{"Sheen Weight": 1.0})
    assert np.all(mean - default > 0.003), (mean, default)
    tree = gnode.id_data
    bsdf = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    value = tree.nodes.new("ShaderNodeValue")
    tree.links.new(value.outputs[0], bsdf.inputs["Coat Weight"])
    nodes._take_surface_inputs(tree, bsdf, gnode)
    assert gnode.inputs["Coat Weight"].links[0].from_node == value


def _principled(color, **inputs) -> tuple[np.ndarray, np.ndarray]:
    """Mean linear RGB and its standard error of the probe with a plain Principled BSDF (no subsurface) at the
    test's roughness and the live group's IOR, Base Color ``color``, set to ``inputs``: Blender's own renderer, no
    add-on."""
    scene = probe.new_scene(samples=SAMPLES, resolution=16, seed=4)
    mat = probe.slab_material("Principled")
    bsdf = mat.node_tree.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.inputs["Base Color"].default_value = (*map(float, color), 1.0)
    bsdf.inputs["Roughness"].default_value = 0.3
    bsdf.inputs["IOR"].default_value = nodes.DEFAULT_IOR
    for name, value in inputs.items():
        bsdf.inputs[name].default_value = value
    mat.node_tree.links.new(bsdf.outputs[0], probe.material_output(mat).inputs["Surface"])
    mean, err, _ = probe.render_mean(scene)
    return mean, err


def test_principled_convention_darkens_the_body_as_principled_does(tmp_path, default):
    """With *Principled's convention* the body renders as dark as a Principled BSDF's base under its specular
    layer.  The reference is a plain Principled BSDF rendered in the same scene (no add-on): its base's share
    (render of the painted base - render of a black base) / painted.  The live group's body share is its render
    less the Principled coat's reflection, over the default's (body at the painted colour): they agree within
    0.005 (the renders' noise is ~0.001)."""
    mean, gnode = _render(tmp_path, convention=True)
    assert gnode.inputs["Principled Convention"].default_value == 1.0
    painted = _painted()
    with_base, err_base = _principled(painted)
    coat, err_coat = _principled((0.0, 0.0, 0.0))
    reference = (with_base - coat) / painted
    share = (mean - coat) / (default - coat)
    print(f"\nbody under Principled's convention / painted: {np.round(share, 4).tolist()}; a Principled BSDF's base: "
          f"{np.round(reference, 4).tolist()} (stderr {np.round(np.hypot(err_base, err_coat) / painted, 4).tolist()})")
    assert np.all(reference < 0.99), reference  # the Principled BSDF's specular layer does darken its base
    assert np.all(np.abs(share - reference) <= 0.005), (share, reference)
    blender_addon.register()
    try:
        with pytest.raises(RuntimeError, match="Principled's convention is an option of the live group"):
            bpy.ops.spectral_skin.invert_albedo(mode="BAKE", principled_convention=True)
    finally:
        blender_addon.unregister()


def test_thin_film(tmp_path, default):
    """A thin film (300 nm of index 1.6) on the Principled BSDF colours the coat's reflection as it colours the
    Principled BSDF's specular layer: the render's change equals that of a black-based Principled BSDF (Blender's
    own, no add-on) within 10 % per channel; the light the film's stronger reflection takes from the skin below
    is not modelled (the body keeps its weight)."""
    film = {"Thin Film Thickness": 300.0, "Thin Film IOR": 1.6}
    mean, gnode = _render(tmp_path, **film)
    assert gnode.inputs["Thin Film Thickness"].default_value == pytest.approx(300.0)
    reference = _principled((0.0, 0.0, 0.0), **film)[0] - _principled((0.0, 0.0, 0.0))[0]
    print(f"\nthin film: change {np.round(mean - default, 4).tolist()} Principled's {np.round(reference, 4).tolist()}")
    np.testing.assert_allclose(mean - default, reference, rtol=0.1)
    assert np.ptp(reference) > 0.03  # the film colours the reflection


def test_anisotropy_tangent_and_coat_normal_are_taken(tmp_path):
    """Anisotropic, Anisotropic Rotation, a Tangent and a Coat Normal reach the group (and so its coat, and the
    EEVEE output's Principled BSDF); an unlinked Coat Normal takes the Principled BSDF's Normal, as the Principled
    BSDF's coat does; what changes afterwards follows."""
    probe.new_scene(samples=1, resolution=4, seed=4)
    codes = np.round(255 * srgb_encode(MEDIUM)).astype(np.uint8)
    png = write_image(tmp_path / "medium.png", np.broadcast_to(codes, (2, 2, 3)).copy(), "uint8")
    mat = probe.slab_material("Skin")
    tree = mat.node_tree
    bsdf, tex = tree.nodes.new("ShaderNodeBsdfPrincipled"), tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(str(png))
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    tree.links.new(bsdf.outputs[0], probe.material_output(mat).inputs["Surface"])
    normal_map, tangent = tree.nodes.new("ShaderNodeNormalMap"), tree.nodes.new("ShaderNodeTangent")
    tree.links.new(normal_map.outputs[0], bsdf.inputs["Normal"])
    tree.links.new(tangent.outputs[0], bsdf.inputs["Tangent"])
    bsdf.inputs["Anisotropic"].default_value, bsdf.inputs["Anisotropic Rotation"].default_value = 0.8, 0.25
    slab = bpy.data.objects["ProbeSlab"]
    blender_addon.register()
    try:
        with bpy.context.temp_override(object=slab, active_object=slab):
            assert bpy.ops.spectral_skin.invert_albedo() == {"FINISHED"}
        gnode = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeGroup")
        assert gnode.inputs["Anisotropic"].default_value == pytest.approx(0.8)
        assert gnode.inputs["Anisotropic Rotation"].default_value == pytest.approx(0.25)
        assert gnode.inputs["Tangent"].links[0].from_node == tangent
        assert gnode.inputs["Coat Normal"].links[0].from_node == normal_map  # the Principled BSDF's Normal
        coat_map = tree.nodes.new("ShaderNodeNormalMap")
        tree.links.new(coat_map.outputs[0], bsdf.inputs["Coat Normal"])
        bpy.context.view_layer.update()
        assert gnode.inputs["Coat Normal"].links[0].from_node == coat_map
        tree.links.remove(bsdf.inputs["Coat Normal"].links[0])
        tree.links.remove(bsdf.inputs["Normal"].links[0])
        bpy.context.view_layer.update()
        assert not gnode.inputs["Coat Normal"].is_linked and not gnode.inputs["Normal"].is_linked
        eevee = next(n for n in gnode.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
        assert all(eevee.inputs[name].is_linked for name in ("Coat Normal", "Tangent", "Thin Film Thickness"))
    finally:
        blender_addon.unregister()


@pytest.mark.parametrize("weight", [1.0, 0.001])  # an exact 0 is Blender's default, which the operator reads as skin
def test_coat_tint(tmp_path, weight):
    """Coat Tint (1, 0.5, 0.5) under a Coat Weight 1 colours what is under the coat as it does under the Principled
    BSDF's: the render over the untinted coat's, per channel, equals that of a Principled BSDF of the painted base
    colour with the same coat (Blender's own, no add-on) within 3 %; red, which the tint leaves, within 1 %.  The
    same over the skin (Subsurface Weight 1) and over the diffuse body (Subsurface Weight 0.001)."""
    coat = {"Coat Weight": 1.0, "Coat IOR": 1.5, "Coat Roughness": 0.03}
    tint = (1.0, 0.5, 0.5, 1.0)
    clear, _ = _render(tmp_path, **coat, **{"Subsurface Weight": weight})
    tinted, gnode = _render(tmp_path, **coat, **{"Coat Tint": tint, "Subsurface Weight": weight})
    assert tuple(gnode.inputs["Coat Tint"].default_value) == pytest.approx(tint)
    reference = _principled(_painted(), **coat, **{"Coat Tint": tint})[0] / _principled(_painted(), **coat)[0]
    ratio = tinted / clear
    print(f"\ncoat tint: {np.round(ratio, 4).tolist()} Principled's {np.round(reference, 4).tolist()}")
    np.testing.assert_allclose(ratio, reference, rtol=0.03)
    assert abs(ratio[0] - 1.0) < 0.01 and np.all(ratio[1:] < 0.7)
