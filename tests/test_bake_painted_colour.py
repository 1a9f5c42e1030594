"""What the artist painted is what renders: the artist's check, in real Cycles.

Three skin colours — the lightest and the darkest subject of the NIST skin reflectance data shipped in
training/realskin/data (measured spectra under D65 -> 8-bit sRGB) and a dark skin colour — are painted as
vertical stripes of one 8-bit sRGB texture on the top of a flat box (blender_addon/probe.py: 100-unit box,
orthographic camera straight above, uniform white world).  The material is the artist's: Image Texture
-> Principled BSDF.  Invert Skin Albedo runs at its default (the live group **Spectral Skin SSS Live**, nothing
baked) and in mode Bake (painted colour, fast-path table; the Spectral Skin SSS Mixture, SVM, then OSL); the
reference is the same texture through a Diffuse BSDF.  Each stripe's mean over its inner texels is compared in
CIE Lab: mean ΔE76 <= 0.5, max <= 1.0.

The group's specular coat (a Principled BSDF's specular layer) reflects the white world: straight above, what
Blender's own Principled BSDF with a black base reflects at the material's roughness and the group's IOR 1.4
(about 0.026 at roughness 0.5; the Fresnel F0 is 0.028), rendered in the same scene
(tests/addon_scene.principled_coat_reflectance); the test subtracts it from the skin render before comparing, as
tests/test_bake_fidelity.py does for its view angles.  1 Blender unit = 10 cm, so the stripes (3.3 cm) are far
wider than the skin's diffusion lengths and light bleeding between stripes stays out of the inner texels.
"""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import blender_addon  # noqa: E402
from blender_addon import live, nodes, probe  # noqa: E402
from exporters.colorimetry import (  # noqa: E402
    delta_e76,
    linear_srgb_to_lab,
    spectrum_to_linear_srgb,
    srgb_decode,
    srgb_encode,
)
from exporters.constants import WAVELENGTHS_NM  # noqa: E402
from tests.addon_scene import principled_coat_reflectance, render_linear, run_invert, write_image  # noqa: E402

NIST = ROOT / "training" / "realskin" / "data" / "nist_skin_reflectance_odd_subjects.csv"
#: Dark skin, linear sRGB (the dark tone of tests/test_bake_fidelity.py; darker than every NIST subject).
DARK = np.array([0.12, 0.055, 0.033])
STRIPE = 16  # texels per stripe (and pixels: the render has one pixel per texel)
EDGE = 3  # pixels left out at each stripe edge
SAMPLES = 320


def painted_codes() -> np.ndarray:
    """8-bit sRGB codes (3, 3): lightest and darkest NIST subject (L* of the measured spectrum under D65), dark."""
    rows = [line.split(",") for line in NIST.read_text().splitlines() if line and not line.startswith("#")]
    values = np.array(rows[1:], np.float64)  # header row: wavelength_nm, subject_001, ...
    spectra = np.array([np.interp(WAVELENGTHS_NM, values[:, 0], col) for col in values[:, 1:].T])
    rgb = spectrum_to_linear_srgb(spectra)
    order = np.argsort(linear_srgb_to_lab(rgb)[:, 0])
    picked = np.stack([rgb[order[-1]], rgb[order[0]], DARK])
    return np.round(255.0 * srgb_encode(np.clip(picked, 0.0, 1.0))).astype(np.uint8)


def stripes_texture(path: Path, codes: np.ndarray) -> Path:
    pixels = np.repeat(np.repeat(codes[None], STRIPE, axis=0), STRIPE, axis=1)  # (16, 48, 3)
    return write_image(path, pixels, "uint8")


def box_material(image: bpy.types.Image, shader: str) -> bpy.types.Material:
    """The probe box's material: Image Texture (object coordinates of the top face mapped onto [0, 1]) -> shader."""
    mat = probe.slab_material(f"Painted_{shader}")
    tree = mat.node_tree
    coords = tree.nodes.new("ShaderNodeTexCoord")
    mapping = tree.nodes.new("ShaderNodeMapping")
    mapping.inputs["Location"].default_value = (0.5, 0.5, 0.0)  # the view, x and y in [-0.5, 0.5], onto [0, 1]
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation, tex.extension = image, "Closest", "EXTEND"
    tree.links.new(coords.outputs["Object"], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    bsdf = tree.nodes.new("ShaderNodeBsdfPrincipled" if shader == "principled" else "ShaderNodeBsdfDiffuse")
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color" if shader == "principled" else "Color"])
    tree.links.new(bsdf.outputs[0], probe.material_output(mat).inputs["Surface"])
    tree.nodes.active = tex
    return mat


def render_stripes(scene: bpy.types.Scene, tmp: Path, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Mean linear RGB (3, 3) of each stripe's inner pixels and its standard error."""
    rgb = render_linear(scene, tmp / f"{name}.exr")
    cells = [rgb[:, i * STRIPE + EDGE:(i + 1) * STRIPE - EDGE].reshape(-1, 3) for i in range(3)]
    return (np.array([c.mean(axis=0) for c in cells]),
            np.array([c.std(axis=0, ddof=1) / np.sqrt(len(c)) for c in cells]))


@pytest.fixture(scope="module")
def diffuse_reference(tmp_path_factory):
    """The Diffuse BSDF of the painted texture, straight above (the artist's reference)."""
    tmp = tmp_path_factory.mktemp("painted_ref")
    scene = _scene()
    codes = painted_codes()
    image = bpy.data.images.load(str(stripes_texture(tmp / "painted.png", codes)))
    box_material(image, "diffuse")
    mean, _ = render_stripes(scene, tmp, "diffuse")
    # Blender decodes the 8-bit sRGB texture as the bake does (IEC 61966-2-1): the reference is the painted albedo
    np.testing.assert_allclose(mean, srgb_decode(codes / 255.0), rtol=2e-3, atol=1e-4)
    return mean


def _scene() -> bpy.types.Scene:
    scene = probe.new_scene(samples=SAMPLES, resolution=3 * STRIPE, seed=11)
    scene.render.resolution_y = STRIPE  # orthographic width 1 unit = the texture's width; height 1/3
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 0.1
    return scene


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["LIVE", "SVM", "OSL"])
def test_cycles_renders_the_painted_colour(tmp_path, backend, diffuse_reference):
    """LIVE: the operator as an artist first meets it (no option given: the live group); SVM, OSL: mode Bake."""
    codes = painted_codes()
    lab_codes = linear_srgb_to_lab(diffuse_reference)
    assert np.all(np.diff(lab_codes[:, 0]) < -10)  # light, medium, dark: distinct colours
    scene = _scene()
    blender_addon.register()
    try:
        png = stripes_texture(tmp_path / "painted.png", codes)
        mat = box_material(bpy.data.images.load(str(png)), "principled")
        slab = bpy.data.objects["ProbeSlab"]
        if backend == "LIVE":
            with bpy.context.temp_override(object=slab, active_object=slab):
                assert bpy.ops.spectral_skin.invert_albedo() == {"FINISHED"}
            assert any(n.bl_idname == "ShaderNodeGroup" and n.node_tree.name.startswith(live.GROUP_NAME)
                       for n in mat.node_tree.nodes)
        else:
            assert run_invert(slab, backend=backend) == {"FINISHED"}
        scene.cycles.shading_system = backend == "OSL"  # the artist's step: the add-on never turns OSL on
        assert mat.node_tree.nodes.active is not None
        skin, err = render_stripes(scene, tmp_path, f"skin_{backend}")
        roughness = mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value
        coat = principled_coat_reflectance(scene, [1.0], roughness, nodes.DEFAULT_IOR)[0]
    finally:
        blender_addon.unregister()
    body = skin - coat  # the coat's reflection of the white world, seen straight above
    de = delta_e76(linear_srgb_to_lab(body), lab_codes)
    rel = body / diffuse_reference - 1.0
    print(f"\n{backend}: painted {np.round(diffuse_reference, 4).tolist()}\n  skin - coat {np.round(coat, 4).tolist()} "
          f"= {np.round(body, 4).tolist()} "
          f"(stderr {np.round(err / diffuse_reference * 100, 2).tolist()} %)\n  rel {np.round(rel * 100, 2).tolist()} %"
          f", ΔE76 {np.round(de, 2).tolist()}")
    assert np.all(err / diffuse_reference < 0.01), "too noisy to test"
    assert de.mean() <= 0.5 and de.max() <= 1.0, de
