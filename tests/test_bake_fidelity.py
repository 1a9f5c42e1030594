"""Render fidelity: baked maps rendered by Cycles reproduce the colour they were baked for.

For three skin tones a uniform albedo image is baked by the operator (the real model, maps packed as
images, the node group wired into the probe slab's material), and the slab (blender_addon/probe.py: a
100-unit block, uniform white world, orthographic camera) is rendered from 4 view angles combined with
the cosine weight (Gauss-Jacobi): the slab's diffuse reflectance.  With *Model's own colour* the reference is
computed here from the ONNX model alone: its ``reflectance`` spectrum (376 samples) in linear sRGB under D65
(exporters.colorimetry.spectrum_to_linear_srgb), i.e. what a viewer of the spectral skin sees; by default
(the painted colour) it is the albedo itself, in every view as on average (tests/test_bake_painted_colour.py
checks the view from straight above against a Diffuse BSDF).  Tolerance 3 % per channel, for the SVM and
the OSL node groups (the medium tone in the opt-in ``make validate``).  1 Blender unit = 5 mm, so the slab is
semi-infinite for every component and Cycles' float32 walk resolves the shortest mean free path.

The group layers a specular coat over the mixture (blender_addon/nodes.py): the render is the model's colour
(its reflectance excludes the specular part) plus the coat's reflection of the white world.  The coat is a
Principled BSDF's specular layer, so the reference for it is Blender's own Principled BSDF with a black base
(same roughness and IOR), rendered at the same view angles and combined with the same quadrature weights
(0.035 at roughness 0.63, IOR 1.4).  The test subtracts it and holds the rest to the model's colour.  The
coat's 1 - F weighting of the mixture is normalised to a cosine-weighted mean of 1, so it leaves the diffuse
colour unchanged to < 1 % (the baked walk's reflectance varies a little with the view angle;
exporters.cycles.coat_body_scale).
"""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
import numpy as np
import onnxruntime as ort
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import blender_addon  # noqa: E402
from blender_addon import nodes, preferences, probe  # noqa: E402
from exporters.colorimetry import spectrum_to_linear_srgb  # noqa: E402
from tests.addon_scene import principled_coat_reflectance, run_invert, write_image  # noqa: E402

TONES = {  # linear sRGB albedo (light, medium, dark skin)
    "light": np.array([0.70, 0.45, 0.33]),
    "medium": np.array([0.40, 0.20, 0.12]),
    "dark": np.array([0.12, 0.055, 0.033]),
}
SAMPLES = 1024
TOLERANCE = 0.03


def model_colour(albedo_rgb: np.ndarray) -> np.ndarray:
    """The spectral model's colour for one texel: linear sRGB (D65) of its reflectance spectrum."""
    session = ort.InferenceSession(preferences.DEFAULT_MODEL, providers=["CPUExecutionProvider"])
    refl = session.run(["reflectance"], {"albedo_rgb": albedo_rgb[None].astype(np.float32)})[0]
    return spectrum_to_linear_srgb(refl.astype(np.float64))[0]


def coat_reflection(scene, n: int = 4) -> np.ndarray:
    """The coat's share of the probe's hemispherical render (3,): a plain Principled BSDF with a black base at the
    group's default roughness and IOR, rendered at the probe's view angles and combined with their weights."""
    mus, weights = probe.hemispherical_nodes(n)
    spec = principled_coat_reflectance(scene, mus, nodes.SKIN_ROUGHNESS, nodes.DEFAULT_IOR)
    return np.sum(weights[:, None] * spec, axis=0)


def render_tone(tmp_path: Path, tone: str, backend: str, own_colour: bool):
    scene = probe.new_scene(samples=SAMPLES, resolution=16, seed=7)
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 0.005
    blender_addon.register()
    try:
        albedo = write_image(tmp_path / f"{tone}.exr", np.broadcast_to(TONES[tone], (2, 2, 3)).astype(np.float32),
                             "float")
        probe.slab_material()
        slab = bpy.data.objects["ProbeSlab"]
        assert run_invert(slab, filepath=str(albedo), backend=backend, model_colour=own_colour) == {"FINISHED"}
        scene.cycles.shading_system = backend == "OSL"  # the artist's step: the add-on never turns OSL on
        return probe.render_hemispherical(scene, 4), coat_reflection(scene)
    finally:
        blender_addon.unregister()


#: The lightest and the darkest tone in make test; the medium one (between them, the same code path) in the opt-in
#: full validation (make validate).
CASES = [(tone, backend, True) if tone != "medium" else pytest.param(tone, backend, True, marks=pytest.mark.validation)
         for backend in ("SVM", "OSL") for tone in TONES] + [("dark", "OSL", False)]


@pytest.mark.slow
@pytest.mark.parametrize("tone, backend, own_colour", CASES)
def test_cycles_reproduces_the_baked_colour(tmp_path, tone, backend, own_colour):
    target = model_colour(TONES[tone]) if own_colour else TONES[tone]
    (mean, err, seconds), coat = render_tone(tmp_path, tone, backend, own_colour)
    rel = (mean - coat) / target - 1.0  # the render less the coat's reflection, against the baked-for colour
    print(f"\n{backend} {tone}{'' if own_colour else ' (painted)'}: cycles {np.round(mean, 5)} = "
          f"coat {np.round(coat, 5)} + "
          f"{np.round(mean - coat, 5)}, model {np.round(target, 5)} rel {np.round(rel * 100, 2)} % (stderr "
          f"{np.round(err / target * 100, 2)} %, {seconds:.1f} s)")
    assert np.all(err / target < 0.01), "too noisy to test 3 %"
    assert np.all(np.abs(rel) <= TOLERANCE), rel
