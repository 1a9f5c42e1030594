"""Cycles' random walk vs an independent reference (iadpython adding-doubling), with the real bpy.

The probe (blender_addon/probe.py) renders the top face of a semi-infinite block under a white world with an
orthographic camera looking straight down.  Cycles' RANDOM_WALK entry has no Fresnel weight and the exit
has no Fresnel/refraction (kernel integrator/subsurface.h), so the medium is index-matched: the reference is
iadpython UR1 (normal-incidence total reflectance) with n = 1.  Each channel carries its own medium
(alpha_c, sigma_t,c); g is one per closure.  Tolerances: 1% + 4 standard errors where Cycles' walk is
accurate (g <= 0.7, and g = 0 where the shipped collapse moves skin's g), and the measured bias of Cycles'
anisotropic walk where it is not.
"""

from __future__ import annotations

import sys
from pathlib import Path

import iadpython
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from blender_addon import probe  # noqa: E402
from exporters import collapse, cycles  # noqa: E402

SAMPLES = 1024
UNIT_SCALE_M = 0.01  # 1 BU = 1 cm, so sigma_t in cm^-1 equals sigma_t per BU
SIGMA_T_CM = np.array([20.0, 50.0, 120.0])


def reference_ur1(alpha: float, g: float) -> float:
    """Normal-incidence reflectance of an index-matched semi-infinite HG medium (adding-doubling)."""
    return float(iadpython.Sample(a=alpha, b=np.inf, g=g, n=1.0, quad_pts=16).rt()[0])


def render_medium(alpha, g, g_max=cycles.RECOMMENDED_G_MAX):
    inputs = cycles.medium_to_cycles(alpha, SIGMA_T_CM, g, unit_scale_m=UNIT_SCALE_M, g_max=g_max)
    assert np.all(inputs.g == inputs.g[0])
    scene = probe.new_scene(samples=SAMPLES, resolution=16, seed=3)
    mat = probe.slab_material()
    node = probe.add_sss_node(mat.node_tree, inputs.color, inputs.radius, float(inputs.g[0]))
    mat.node_tree.links.new(node.outputs["BSSRDF"], probe.material_output(mat).inputs["Surface"])
    return probe.render_mean(scene)


def report(label, mean, err, ref, seconds):
    rel = mean / ref - 1.0
    print(f"{label}: cycles={np.round(mean, 4)} ref={np.round(ref, 4)} rel_err={np.round(rel * 100, 2)}% "
          f"stderr={np.round(err / ref * 100, 2)}% render={seconds:.2f}s")
    return rel


@pytest.mark.parametrize(
    "alpha, g",
    [
        ((0.6, 0.9, 0.995), 0.0),
        ((0.7, 0.95, 0.99), 0.5),
        ((0.9, 0.99, 0.999), 0.7),
    ],
)
def test_cycles_matches_adding_doubling(alpha, g):
    alpha = np.array(alpha)
    mean, err, seconds = render_medium(alpha, np.full(3, g))
    ref = np.array([reference_ur1(a, g) for a in alpha])
    rel = report(f"g={g} alpha={alpha}", mean, err, ref, seconds)
    assert np.all(np.abs(rel) <= 0.01 + 4 * err / ref), rel


def test_skin_like_high_g_through_the_isotropic_collapse():
    # Skin g(lambda) ~ 0.75-0.9: the shipped collapse (exporters.collapse.G_MAX = 0) hands Cycles each medium's
    # similar isotropic medium.  The reference is that medium computed here from the similarity relation
    # (van de Hulst: mu_a and the reduced scattering mu_s (1 - g) kept), alpha* = alpha (1 - g) / (1 - alpha g),
    # through adding-doubling at g = 0: Cycles' isotropic walk must render it within 1 % + 4 standard errors.
    alpha, g = np.array([0.95, 0.99, 0.998]), 0.85
    mean, err, seconds = render_medium(alpha, np.full(3, g), g_max=collapse.G_MAX)
    assert cycles.medium_to_cycles(alpha, SIGMA_T_CM, np.full(3, g), g_max=collapse.G_MAX).g.max() == 0.0
    alpha_iso = alpha * (1.0 - g) / (1.0 - alpha * g)
    ref = np.array([reference_ur1(a, 0.0) for a in alpha_iso])
    rel = report(f"g={g} as the isotropic alpha*={np.round(alpha_iso, 4)}", mean, err, ref, seconds)
    assert np.all(np.abs(rel) <= 0.01 + 4 * err / ref), rel


def test_raw_high_g_walk_is_biased_which_is_why_g_is_capped():
    # Cycles 5.0.1 at its own limit g = 0.9 over-estimates the reflectance by far more than the
    # similarity cap costs.  If a future Cycles fixes its walk this test fails: then revisit the cap.
    alpha, g = np.array([0.9, 0.99, 0.999]), np.full(3, 0.9)
    mean, err, seconds = render_medium(alpha, g, g_max=cycles.G_MAX)
    ref = np.array([reference_ur1(a, 0.9) for a in alpha])
    rel = report("g=0.9 raw", mean, err, ref, seconds)
    assert np.all(rel > 0.05), rel
