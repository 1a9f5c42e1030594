"""The Spectral Skin SSS Mixture node group (SVM and OSL) rendered in Cycles with the real bpy.

Linearity: a 2-component mixture with per-channel weights must render as the weight-sum of the
single-component renders (the closure-pick argument in blender_addon/nodes.py), the OSL group must match
the SVM group, and a single component through the group must match an independent adding-doubling
reference (iadpython UR1, n = 1: see tests/test_cycles_render.py for why).  The group's specular coat is
part of every render: seen face-on under the white world it adds what a Principled BSDF with a black base
reflects (rendered here in the same scene, tests/addon_scene.principled_coat_reflectance) and scales the
mixture by (1 - F(1))/(1 - F_dr) = 1.053 (exporters.cycles.coat_body_scale), so the reference is
coat + 1.053 x UR1; the weight-sum relation holds with the coat as it is (the weights sum to 1 per channel).
"""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
import iadpython
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from blender_addon import nodes, osl, probe  # noqa: E402
from exporters import cycles  # noqa: E402
from tests.addon_scene import principled_coat_reflectance  # noqa: E402

SAMPLES = 1024
UNIT_SCALE_M = 0.01
MEDIA = [  # (alpha per channel, sigma_t cm^-1 per channel, g)
    (np.array([0.95, 0.9, 0.8]), np.array([20.0, 40.0, 80.0]), 0.5),
    (np.array([0.995, 0.99, 0.97]), np.array([50.0, 30.0, 20.0]), 0.0),
]
W1 = np.array([0.3, 0.6, 0.8])


def component(alpha, sigma_t, g, weight) -> dict:
    cin = cycles.medium_to_cycles(alpha, sigma_t, np.full(3, g), unit_scale_m=UNIT_SCALE_M)
    return {"Color": cin.color, "Radius": cin.radius, "Weight": weight, "Anisotropy": float(cin.g[0])}


def render_group(weights, backend="SVM", design="nested"):
    scene = probe.new_scene(samples=SAMPLES, resolution=16, seed=5)
    if backend == "OSL":
        scene.cycles.shading_system = True
        group = nodes.build_osl_group(2)
    else:
        group = nodes.build_svm_group(2, design=design)
    mat = probe.slab_material()
    gnode = nodes.wire_into_material(mat, group)
    nodes.set_constant_inputs(gnode, [component(*m, w) for m, w in zip(MEDIA, weights, strict=True)])
    result = probe.render_mean(scene)
    coat = principled_coat_reflectance(scene, [1.0], nodes.SKIN_ROUGHNESS, nodes.DEFAULT_IOR)[0]
    return (*result, coat)


def close(a, ea, b, eb, tol=0.01):
    rel = a / b - 1.0
    bound = tol + 4.0 * np.hypot(ea / b, eb / b)
    return bool(np.all(np.abs(rel) <= bound)), rel


def test_mixture_is_weighted_sum_svm_and_osl():
    ones, zeros = np.ones(3), np.zeros(3)
    r1, e1, t1, coat = render_group([ones, zeros])
    r2, e2, t2, _ = render_group([zeros, ones])
    mix, emix, tmix, _ = render_group([W1, 1.0 - W1])
    mix_osl, emix_osl, tosl, _ = render_group([W1, 1.0 - W1], backend="OSL")
    expect = W1 * r1 + (1.0 - W1) * r2
    eexp = np.hypot(W1 * e1, (1.0 - W1) * e2)
    ok_svm, rel_svm = close(mix, emix, expect, eexp)
    ok_osl, rel_osl = close(mix_osl, emix_osl, expect, eexp)
    ok_pair, rel_pair = close(mix_osl, emix_osl, mix, emix)
    scale = cycles.coat_body_scale(1.0, nodes.DEFAULT_IOR)
    refs = [coat + scale * np.array([iadpython.Sample(a=a, b=np.inf, g=m[2], n=1.0, quad_pts=16).rt()[0]
                                     for a in m[0]]) for m in MEDIA]
    ok_r1, rel_r1 = close(r1, e1, refs[0], 0.0)
    ok_r2, rel_r2 = close(r2, e2, refs[1], 0.0)
    print(f"\nsingle k1={np.round(r1, 4)} vs coat + iad {np.round(refs[0], 4)} "
          f"rel={np.round(rel_r1 * 100, 2)}% ({t1:.1f}s)")
    print(f"single k2={np.round(r2, 4)} vs coat + iad {np.round(refs[1], 4)} "
          f"rel={np.round(rel_r2 * 100, 2)}% ({t2:.1f}s)")
    print(f"SVM mix={np.round(mix, 4)} vs sum {np.round(expect, 4)} rel={np.round(rel_svm * 100, 2)}% ({tmix:.1f}s)")
    print(f"OSL mix={np.round(mix_osl, 4)} rel={np.round(rel_osl * 100, 2)}% vs SVM {np.round(rel_pair * 100, 2)}%"
          f" ({tosl:.1f}s)")
    assert ok_r1 and ok_r2, (rel_r1, rel_r2)
    assert ok_svm, rel_svm
    assert ok_osl, rel_osl
    assert ok_pair, rel_pair


def test_nested_closures_render_as_single_channel_closures():
    """The nested closures (three channel sets per component) render the per-channel weights exactly: as the
    single-channel design renders them, for weights with a tie at the top, a tie at the bottom, one channel at
    0 and every order of channels, with the weight sums over components unequal per channel (the painted gain)."""
    weights = [np.array([0.3, 0.3, 0.1]), np.array([0.2, 0.0, 0.2])]
    nested, e_nested, t_nested, _ = render_group(weights)
    single, e_single, t_single, _ = render_group(weights, design="per_channel")
    ok, rel = close(nested, e_nested, single, e_single)
    print(f"\nnested {np.round(nested, 4)} ({t_nested:.1f}s) vs single-channel {np.round(single, 4)} "
          f"({t_single:.1f}s): rel={np.round(rel * 100, 2)}%")
    assert ok, rel
    for order in ([0.5, 0.1, 0.3], [0.1, 0.3, 0.5], [0.3, 0.5, 0.1]):
        w = [np.array(order), np.array(order[::-1]) * 0.5]
        mixed, err, _, _ = render_group(w)
        expect = render_group(w, design="per_channel")
        ok, rel = close(mixed, err, expect[0], expect[1])
        assert ok, (order, rel)
    with pytest.raises(ValueError, match="design"):
        nodes.build_svm_group(2, design="one closure")


def test_wiring_keeps_user_nodes_and_records_previous_surface():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mat = bpy.data.materials.new("UserSkin")  # comes with Principled BSDF -> Material Output
    before = {n.name for n in mat.node_tree.nodes}
    links_before = len(mat.node_tree.links)
    image = bpy.data.images.new("k1_color", 4, 4, float_buffer=True)
    gnode = nodes.wire_into_material(mat, nodes.build_svm_group(1), images={(1, "Color"): image})
    tree = mat.node_tree
    assert before <= {n.name for n in tree.nodes}
    assert mat[nodes.PREVIOUS_SURFACE_PROP] == "Principled BSDF"
    out = tree.nodes["Material Output"]  # the user's output keeps its Principled BSDF (what exporters read)
    assert out.is_active_output and out.inputs["Surface"].links[0].from_node == tree.nodes["Principled BSDF"]
    fed = {n.target: n.inputs["Surface"].links[0].from_node for n in tree.nodes
           if n.bl_idname == "ShaderNodeOutputMaterial" and n != out}
    assert fed == {"CYCLES": gnode, "EEVEE": gnode}  # what each renderer renders
    assert len(tree.links) == links_before + 3  # the image link and the two outputs' links added
    assert image.colorspace_settings.name == "Non-Color"
    assert gnode.inputs["k1 Color"].links[0].from_node.image == image


def test_osl_source_compiles_for_several_k():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    for k in (1, 3):
        group = nodes.build_osl_group(k)
        script = next(n for n in group.nodes if n.bl_idname == "ShaderNodeScript")
        assert script.bytecode
        assert {osl.param_name(k, "Radius"), "ior", "coat_ior", "Normal"} <= set(script.inputs.keys())


def test_translucency_scales_every_radius():
    """The mixture's Translucency (the artist's control over baked maps) renders as radii scaled by it: on a thin plate
    (0.05 Blender units, lit from both sides by the white world, so the radius matters) Translucency 3 renders what
    radii three times as long render (SVM and OSL, the same paths and seed), and differs from Translucency 1."""
    for backend in ("SVM", "OSL"):
        means = []
        for translucency, factor in ((3.0, 1.0), (1.0, 3.0), (1.0, 1.0)):
            scene = probe.new_scene(samples=64, resolution=16, seed=5)
            scene.cycles.shading_system = backend == "OSL"
            group = nodes.build_osl_group(2) if backend == "OSL" else nodes.build_svm_group(2)
            gnode = nodes.wire_into_material(probe.slab_material(), group)
            comps = [component(*m, w) for m, w in zip(MEDIA, [W1, 1.0 - W1], strict=True)]
            nodes.set_constant_inputs(gnode, [{**c, "Radius": np.asarray(c["Radius"]) * factor} for c in comps])
            gnode.inputs["Translucency"].default_value = translucency
            bpy.data.objects["ProbeSlab"].scale.z = 0.0005
            means.append(probe.render_mean(scene)[0])
        scaled, longer, plain = means
        print(f"\n{backend}: Translucency 3 {np.round(scaled, 4)}, radii x3 {np.round(longer, 4)}, "
              f"Translucency 1 {np.round(plain, 4)}")
        np.testing.assert_allclose(scaled, longer, rtol=1e-3)
        assert np.max(np.abs(scaled / plain - 1.0)) > 0.01
