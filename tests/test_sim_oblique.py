"""A collimated beam at a polar angle: total reflectance against adding-doubling (iadpython), energy, the profile
in the plane of incidence, and normal incidence unchanged bit for bit.

iadpython 0.5.3 stops short of oblique incidence (``Sample.rt_matrices`` returns zeros for ``nu_0 != 1``), but its
quadrature already places the refracted beam's cosine among its angles (``update_quadrature``: "conical
incidence"); the oracle below runs the same adding and boundary steps ``rt_matrices`` runs at normal incidence and
reads the reflection matrix's column of that angle, as Prahl's C code does for a cone.  It is itself checked
against Chandrasekhar's H-function (isotropic, index-matched half-space) and against ``rt()`` at normal incidence.
"""

from __future__ import annotations

import hashlib
import json
import math
import subprocess
import sys
from pathlib import Path

import iadpython as iad
import numpy as np
import pytest
from iadpython.fresnel import cos_snell

from training.sim.compiled_transport import simulate_compiled, walk_tables
from training.sim.illumination import parse_illumination
from training.sim.packet_loop import walk_compiled

ROOT = Path(__file__).resolve().parents[1]


def iad_oblique(a: float, b: float, g: float, n: float, cos_in: float, quad_pts: int = 24) -> float:
    """Total reflectance (specular included) of a slab (albedo a, optical thickness b, HG g, index n, air above and
    below) for a collimated beam whose polar cosine in air is ``cos_in``; quad_pts a multiple of 6."""
    s = iad.Sample(a=a, b=b, g=g, n=n, n_above=1.0, n_below=1.0, quad_pts=quad_pts)
    s.nu_0 = cos_in
    s.update_quadrature()
    r12, t12 = iad.simple_layer_matrices(s)
    if n == 1.0:
        r = r12
    else:
        r01, r10, t01, t10 = iad.start.boundary_layer(s, top=True)
        r, _ = iad.add_same_slides(s, r01, r10, t01, t10, r12, t12)
    nu_in = cos_in if n == 1.0 else cos_snell(1.0, cos_in, n)
    j = int(np.argmin(np.abs(s.nu - nu_in)))
    assert abs(s.nu[j] - nu_in) < 1e-9
    k = int(np.min(np.where(s.nu > s.nu_c())))
    return float(np.dot(s.twonuw[k:], r[k:, j]))


def h_function_reflectance(a: float, mu0: float, nodes: int = 400) -> float:
    """Chandrasekhar: R(mu0) = 1 - H(mu0) sqrt(1 - a) of an isotropic, index-matched half-space (H by iteration)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    x, w = 0.5 * (x + 1), 0.5 * w
    h = np.ones(nodes)
    for _ in range(500):
        h = 1.0 / (1.0 - 0.5 * a * x * np.sum(w * h / (x[:, None] + x[None, :]), axis=1))
    return 1.0 - math.sqrt(1.0 - a) / (1.0 - 0.5 * a * mu0 * np.sum(w * h / (mu0 + x)))


def fresnel(theta_deg: float, n: float) -> float:
    ci = math.cos(math.radians(theta_deg))
    ct = math.sqrt(1.0 - (1.0 - ci * ci) / (n * n))
    rs = (ci - n * ct) / (ci + n * ct)
    rp = (n * ci - ct) / (n * ci + ct)
    return 0.5 * (rs * rs + rp * rp)


def test_the_oracle_is_chandrasekhars_half_space_and_iadpythons_normal_incidence():
    for mu0 in (1.0, 0.5, 0.1):
        assert iad_oblique(0.9, np.inf, 0.0, 1.0, mu0) == pytest.approx(h_function_reflectance(0.9, mu0), abs=1e-6)
    ur1 = iad.Sample(a=0.9, b=2.0, g=0.75, n=1.4, n_above=1.0, n_below=1.0, quad_pts=24).rt()[0]
    assert iad_oblique(0.9, 2.0, 0.75, 1.4, 1.0) == pytest.approx(ur1, abs=1e-12)


def _slab(a: float, b: float, g: float, thickness: float) -> tuple[np.ndarray, ...]:
    mut = b / thickness if math.isfinite(thickness) else 100.0
    return (np.array([[(1 - a) * mut]]), np.array([[a * mut]]), np.array([[g]]), np.array([thickness]))


@pytest.mark.parametrize(("a", "b", "g", "n", "thickness"), [
    (0.9, 2.0, 0.75, 1.4, 0.02),  # the MCML slab, refractive
    (0.95, np.inf, 0.8, 1.4, np.inf),  # a half-space
    (0.9, 2.0, 0.75, 1.0, 0.02),  # the MCML slab, index-matched
])
def test_total_reflectance_matches_adding_doubling_up_to_85_degrees(a, b, g, n, thickness):
    for theta in (0.0, 45.0, 70.0, 85.0):
        res = simulate_compiled(*_slab(a, b, g, thickness), 20_000, n_medium=n, illumination=f"collimated:{theta:g}",
                                seed=3, r_edges_cm=np.array([0.0, 1.0]))
        spec = float(res.get("specular", [((n - 1) / (n + 1)) ** 2])[0])
        assert spec == pytest.approx(fresnel(theta, n), abs=1e-12)
        cos_in = math.cos(math.radians(theta))
        ref, ref_fine = iad_oblique(a, b, g, n, cos_in, 24), iad_oblique(a, b, g, n, cos_in, 30)
        tol = 4.0 * float(res["R_d_stderr"][0]) + abs(ref_fine - ref) + 1e-4
        assert float(res["R_d"][0]) + spec == pytest.approx(ref, abs=tol), theta


def test_energy_is_conserved_on_both_engines_and_they_agree():
    from training.sim.medium import LayeredMedium
    from training.sim.transport import simulate

    medium = LayeredMedium(np.array([[2.0], [0.3]]), np.array([[150.0], [120.0]]), np.array([[0.8], [0.8]]),
                           np.array([0.01, 0.05]), n_medium=1.4, n_below=1.0)
    runs = {e: simulate(medium, 4000, illumination="collimated:70", seed=2, engine=e, r_edges_cm=None)
            for e in ("numba", "torch")}
    for res in runs.values():
        assert np.abs(res.energy_residual()).max() < 1e-5
        assert res.specular[0] == pytest.approx(fresnel(70.0, 1.4), rel=1e-5)
    a, b = runs["numba"], runs["torch"]
    for key in ("R_d", "T_d"):
        se = math.hypot(getattr(a, f"{key}_stderr")[0], getattr(b, f"{key}_stderr")[0])
        assert abs(getattr(a, key)[0] - getattr(b, key)[0]) < 4 * se, key


def test_the_profile_in_the_plane_of_incidence():
    mua, mus, g, th = _slab(0.95, np.inf, 0.8, np.inf)
    r_edges = np.array([0.0, 0.01, 0.03, 0.1, 1e4])
    x_edges = np.array([-1e4, -0.03, -0.01, 0.0, 0.01, 0.03, 1e4])
    res = {t: simulate_compiled(mua, mus, g, th, 20_000, illumination=f"collimated:{t}", seed=5, r_edges_cm=r_edges,
                                x_edges_cm=x_edges) for t in (0, 70)}
    for r in res.values():  # the histograms hold all the reflected light
        assert np.sum(r["profile"] * np.pi * np.diff(r_edges**2)) == pytest.approx(r["R_d"][0], rel=1e-9)
        assert np.sum(r["profile_plane"] * np.diff(x_edges)) == pytest.approx(r["R_d"][0], rel=1e-9)
    plane0, plane70 = (res[t]["profile_plane"][0] * np.diff(x_edges) for t in (0, 70))  # R_d per x bin
    # normal incidence: symmetric about the entry point; 70 degrees: the light goes forward (+x), by about the
    # refracted beam's horizontal reach (sin 42.2 deg / (1 - g a) ~ 0.03 cm here)
    assert abs(res[0]["shift_cm"][0]) < 0.002
    assert plane0[3:].sum() == pytest.approx(plane0[:3].sum(), rel=0.05)
    assert res[70]["shift_cm"][0] > 0.01
    assert plane70[3:].sum() > 1.3 * plane70[:3].sum()


# The unchanged code path (the commit before oblique incidence) on this medium, seed and photons gave these.
GOLDEN = {
    "normal": ([0.5677557283014365, 0.19770044145886664, 0.6522298022468955],
               "7d9f3294fe4375984e50bd0819c865baa720b57fe405729ff0910dd82a3ac903"),
    "diffuse": ([0.5480380845687819, 0.18827097728616524, 0.623914226006109],
                "d5b8873d3a567927ad0e363ffdca99c3f80ec9b9d43484188a19e0a771c46ec3"),
}
GOLDEN_CLI = {"R_d": 0.46411799442722584, "R_d_stderr": 0.005416228117762868, "T_d": 0.0, "photons": 4000}
GOLDEN_MEDIUM = (np.array([[2.0, 20.0, 0.5], [0.3, 1.0, 0.05]]), np.array([[200.0, 150.0, 90.0], [180.0, 120.0, 80.0]]),
                 np.array([[0.8, 0.75, 0.9], [0.8, 0.75, 0.9]]), np.array([0.01, np.inf]))


def _records_sha256(illumination: str) -> str:
    h = hashlib.sha256()

    def sink(ch, pid, out):
        for k in ("kind", "w", "x", "y", "ncoll", "absorbed", "specular", "roulette", "steps"):
            h.update(np.ascontiguousarray(out[k]).tobytes())

    light = parse_illumination(illumination)
    walk_compiled(walk_tables(*GOLDEN_MEDIUM), 1.4, 1.0, 2, 3, photons=3000, order="interleaved", seed=11,
                  diffuse=light.diffuse, pool_packets=4096, max_steps=100_000, roulette_threshold=1e-4,
                  roulette_boost=10.0, path_n0=np.full(3, np.inf), path_keep=1.0, record_paths=False, threads=2,
                  sink=sink, cos_in=light.cos_in)
    return h.hexdigest()


@pytest.mark.parametrize("illumination", ["normal", "collimated:0", "diffuse"])
def test_normal_and_diffuse_light_walk_the_same_packets_as_before(illumination):
    r_d, sha = GOLDEN["diffuse" if illumination == "diffuse" else "normal"]
    res = simulate_compiled(*GOLDEN_MEDIUM, 3000, illumination=illumination, seed=11, threads=2)
    assert res["R_d"].tolist() == r_d
    assert _records_sha256(illumination) == sha


def test_the_command_lines_normal_json_is_unchanged_and_oblique_adds_its_fields():
    def cli(illumination: str) -> dict:
        out = subprocess.run([sys.executable, "-m", "training", "simulate-layers", "--layer", "1", "100", "0.9", "0.02",
                              "--layer", "0.2", "50", "0.8", "inf", "--illumination", illumination, "--photons", "4000",
                              "--seed", "5", "--json"], capture_output=True, text=True, cwd=ROOT, check=True)
        return json.loads(out.stdout)

    normal = cli("normal")
    assert {k: v for k, v in normal.items() if k != "seconds"} == GOLDEN_CLI
    oblique = cli("collimated:60")
    assert oblique["specular"] == pytest.approx(fresnel(60.0, 1.4), abs=1e-12)
    assert oblique["shift_cm"] > 0.0 and oblique["R_d"] != normal["R_d"]
