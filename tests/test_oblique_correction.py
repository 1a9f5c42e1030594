"""The grazing-light correction: its reference (exporters.oblique_correction), its nodes (blender_addon.oblique)
rendered in Cycles against that reference, and the live group with it against the live group without (real bpy,
tiny probe renders)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from blender_addon import live, oblique, probe  # noqa: E402
from exporters import oblique_correction as oc  # noqa: E402

MODEL = Path(__file__).resolve().parents[1] / "blender_addon" / "models" / "skin_inversion.onnx"
#: Painted colours (linear): the representative tones R08 and R09 (dark: where the correction acts most; their
#: decoder's colour), a light skin and a non-skin colour.
COLOURS = ((0.0963, 0.0363, 0.0175), (0.036, 0.0148, 0.008), (0.55, 0.36, 0.27), (0.10, 0.50, 0.90))


def test_the_correction_is_one_at_normal_incidence_and_wherever_the_ramps_have_not_started():
    corr = oc.shipped()
    rng = np.random.default_rng(0)
    colours = rng.uniform(0.0, 1.0, (200, 3))
    f, s = oc.factors(corr, colours, 1.0)
    assert np.all(f == 1.0) and np.all(s == 1.0)
    start = min(corr.weight_ramp[0], corr.radius_ramp[0])
    f, s = oc.factors(corr, colours, 1.0 - 0.999 * start)
    assert np.all(f == 1.0) and np.all(s == 1.0)
    f, s = oc.factors(corr, colours, 0.05)
    assert np.all(np.isfinite(f)) and np.all(s > 0.0)
    assert not np.all(f == 1.0)


def test_the_shipped_correction_darkens_dark_skin_and_narrows_its_profile_at_grazing_light():
    """What the Monte Carlo found (docs/validation/oblique.md): at 70-85 degrees the mixture of dark skin is too
    bright and too wide; the fitted factors say so."""
    mu = np.cos(np.radians(80.0))
    f, _ = oc.factors(oc.shipped(), np.array(COLOURS[0]), mu)
    _, s = oc.factors(oc.shipped(), np.array(COLOURS[1]), mu)
    assert f[0] < 0.97 and np.all(s[:2] < 0.9)


def test_slopes_are_constant_beyond_the_knots_and_bad_coefficients_are_refused():
    corr = oc.shipped()
    a_lo, b_lo = oc.slopes(corr, np.zeros(3))
    a_hi, b_hi = oc.slopes(corr, np.ones(3))
    assert a_lo == pytest.approx(corr.weight_slope[0]) and b_hi == pytest.approx(corr.radius_slope[-1])
    text = corr.to_json()
    back = oc.from_json(text)
    assert np.array_equal(back.weight_slope, corr.weight_slope) and back.weight_ramp == corr.weight_ramp
    bad = text.replace(str(corr.luminance.tolist()[0]), "2.0", 1)
    with pytest.raises(ValueError, match="increase"):
        oc.from_json(bad)


def _emission_material(socket_name: str, colour) -> None:
    """The probe slab emitting the Grazing group's output ``socket_name`` for ``colour``."""
    import bpy

    mat = probe.slab_material("Grazing factors")
    tree = mat.node_tree
    group = tree.nodes.new("ShaderNodeGroup")
    group.node_tree = oblique.ensure_group()
    group.inputs["Color"].default_value = (*colour, 1.0)
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    tree.links.new(group.outputs[socket_name], emission.inputs["Color"])
    tree.links.new(emission.outputs[0], probe.material_output(mat).inputs["Surface"])
    assert bpy.data.node_groups[group.node_tree.name].get("spectral_skin_sss_backend") == "GRAZING"


def test_the_grazing_nodes_compute_the_reference_factors_in_cycles():
    scene = probe.new_scene(samples=1, resolution=4, seed=1)
    corr = oc.shipped()
    for colour in COLOURS:
        for theta in (0.0, 50.0, 70.0, 85.0):
            mu = float(np.cos(np.radians(theta)))
            f, s = oc.factors(corr, np.array(colour), mu)
            for name, want in (("Weight", f), ("Radius", s)):
                _emission_material(name, colour)
                probe.view_from(scene, mu)
                got = probe.render_mean(scene)[0]
                assert got == pytest.approx(want, abs=oblique.TABLE_ERROR), (colour, theta, name)


def test_the_tables_follow_the_reference_factors_within_the_stated_bound():
    """The Grazing group's images, interpolated bilinearly at their UVs as Cycles does, against the reference factors
    on a dense grid of luminances (the knots included, where the filter cuts the corners most) and facings; the
    bound is what the Cycles render above uses.  Face-on, the images hold 1 exactly."""
    corr = oc.shipped()
    group = oblique.ensure_group()
    assert len(group.nodes) <= 12
    images = {n.image.name.rpartition(" ")[2]: n.image for n in group.nodes if n.bl_idname == "ShaderNodeTexImage"}
    scale, offset = oblique._texel_map(corr)
    lum = np.concatenate([np.linspace(0.0, 0.5, 1001), corr.luminance])
    facing = np.linspace(0.0, 1.0, 401)
    y, f = np.meshgrid(lum, facing, indexing="ij")
    want_f, want_s = oc.factors(corr, np.repeat(y[..., None], 3, axis=-1), 1.0 - f)
    for name, want in (("Weight", want_f), ("Radius", want_s)):
        image = images[name]
        cols, rows = image.size
        pixels = np.empty(cols * rows * 4, np.float32)
        image.pixels.foreach_get(pixels)
        pixels = pixels.reshape(rows, cols, 4)[..., :3].astype(np.float64)  # row 0 at the bottom, as the UV's v
        u = np.clip((y * scale[0] + offset[0]) * cols - 0.5, 0.0, cols - 1.0)  # Extend: the edge texel beyond
        v = np.clip((f * scale[1] + offset[1]) * rows - 0.5, 0.0, rows - 1.0)
        i0, j0 = np.minimum(u.astype(int), cols - 2), np.minimum(v.astype(int), rows - 2)
        tu, tv = (u - i0)[..., None], (v - j0)[..., None]
        got = ((1 - tv) * ((1 - tu) * pixels[j0, i0] + tu * pixels[j0, i0 + 1])
               + tv * ((1 - tu) * pixels[j0 + 1, i0] + tu * pixels[j0 + 1, i0 + 1]))
        assert np.abs(got - want).max() < oblique.TABLE_ERROR, name
        assert np.all(pixels[0] == 1.0), name  # face-on and up to the earlier ramp's start: exactly 1


def _live_renders(colour, mu: float, samples: int = 32) -> dict[str, np.ndarray]:
    """Probe renders (mean RGB) of the live group without and with the correction, and of the coat alone (the
    group painted black), seen at view cosine ``mu``."""
    scene = probe.new_scene(samples=samples, resolution=8, seed=2)
    probe.view_from(scene, mu)
    table = live.table_for_model(str(MODEL))
    out = {}
    for label, grazing, paint in (("without", False, colour), ("with", True, colour), ("coat", False, (0, 0, 0))):
        mat = probe.slab_material(f"Live {label}")
        node = mat.node_tree.nodes.new("ShaderNodeGroup")
        node.node_tree = live.ensure_live_group(table, None, grazing=grazing)
        node.inputs["Color"].default_value = (*map(float, paint), 1.0)
        node.inputs["Unit Scale"].default_value = 0.01
        mat.node_tree.links.new(node.outputs["Cycles"], probe.material_output(mat).inputs["Surface"])
        out[label] = probe.render_mean(scene)[0]
    return out


def test_the_live_group_with_the_correction_renders_normal_incidence_bit_for_bit():
    got = _live_renders(COLOURS[0], 1.0, samples=16)
    assert np.array_equal(got["with"], got["without"])


def test_the_live_group_with_the_correction_darkens_grazing_dark_skin_by_the_reference_factor():
    mu = float(np.cos(np.radians(80.0)))
    got = _live_renders(COLOURS[0], mu, samples=64)
    body = {k: got[k] - got["coat"] for k in ("with", "without")}
    f, _ = oc.factors(oc.shipped(), np.array(COLOURS[0]), mu)
    assert body["with"][0] / body["without"][0] == pytest.approx(f[0], abs=0.03)
    assert body["with"][0] < body["without"][0]
