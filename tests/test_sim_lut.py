"""The homogeneous LUT builder: against adding-doubling, against direct absorbing runs, the file format.

Which adding-doubling quantity: the LUT illuminates with a cosine-weighted lobe of directions from
air (the flux of a uniform diffuse radiance), so its R is iadpython's URU (reflection for diffuse
incidence) minus the hemispherical specular reflection of the boundary (URU of a non-scattering
half-space), since the LUT excludes the specular part.
"""

from __future__ import annotations

import math

import iadpython as iad
import numpy as np
import pytest
import torch

from exporters.constants import R_EDGES_MFP
from training.commands.lut import main as lut_main
from training.sim.lut import CountBins, albedo_grid, simulate_columns
from training.sim.medium import LayeredMedium
from training.sim.transport import simulate, simulate_records

TOL_ABS = 0.002


def _uru_minus_specular(a: float, g: float, n: float = 1.4) -> float:
    # the specular part must use the same quadrature: at 32 points vs 16 it differs by 7e-4
    quad = 32 if g > 0.8 else 16
    uru = iad.Sample(a=a, b=math.inf, g=g, n=n, n_above=1.0, n_below=1.0, quad_pts=quad).rt()[2]
    spec = iad.Sample(a=0.0, b=math.inf, g=0.0, n=n, n_above=1.0, n_below=1.0, quad_pts=quad).rt()[2]
    return float(uru - spec)


@pytest.fixture(scope="module")
def columns() -> tuple[np.ndarray, np.ndarray, list[dict[str, np.ndarray]]]:
    """Two g columns, 20k photons each, shared by the tests below (~10 s)."""
    torch.set_num_threads(1)
    albedo = np.array([0.3, 0.9, 0.99, 0.999])
    gs = np.array([0.0, 0.8])
    return albedo, gs, simulate_columns(gs, albedo, 20_000, seed=1, max_steps=20_000)


def test_lut_reflectance_against_adding_doubling(columns) -> None:
    albedo, gs, cols = columns
    for g, col in zip(gs, cols, strict=True):
        ref = np.array([_uru_minus_specular(a, g) for a in albedo])
        bad = np.abs(col["R"] - ref) > 4 * col["R_stderr"] + TOL_ABS
        assert not bad.any(), (g, col["R"], col["R_stderr"], ref)
        assert np.all(col["R_trunc_bound"] < 1e-6)  # the walk cap is harmless at albedo <= 0.999


def test_lut_reweighting_matches_direct_absorbing_run(columns) -> None:
    """R and the coarse shape of P from reweighting equal a direct run at the same albedo."""
    albedo, gs, cols = columns
    sel_a = [1, 2]  # albedo 0.9 and 0.99 (0.999 is checked against adding-doubling above)
    col = cols[1]  # g = 0.8
    a = albedo[sel_a]
    m = LayeredMedium.homogeneous(1.0 - a, a, gs[1], n_medium=1.4)  # sigma_t = 1 cm^-1: cm == mfp
    direct = simulate(m, 15_000, seed=3, illumination="diffuse", r_edges_cm=R_EDGES_MFP)
    r_lut, se_lut = col["R"][sel_a], col["R_stderr"][sel_a]
    bad = np.abs(r_lut - direct.R_d) > 4 * np.hypot(se_lut, direct.R_d_stderr) + TOL_ABS
    assert not bad.any(), (r_lut, direct.R_d)
    edges = direct.r_edges_cm
    area = math.pi * np.diff(edges**2)
    bands = [(0.0, 0.3), (0.3, 1.0), (1.0, 5.0)]  # mean free paths
    for k, i in enumerate(sel_a):
        inside = (direct.profile[k] * area).sum()
        for lo, hi in bands:
            sel = (edges[:-1] >= lo) & (edges[1:] <= hi + 1e-12)
            f_lut = (col["P"][i] * area)[sel].sum()
            f_dir = (direct.profile[k] * area)[sel].sum() / inside
            se_dir = math.sqrt(((direct.profile_stderr[k] * area)[sel] ** 2).sum()) / inside
            # the LUT's band fraction has a similar standard error: sqrt(2) for the difference
            assert abs(f_lut - f_dir) < 4 * math.sqrt(2) * se_dir + TOL_ABS, (a[k], lo, hi, f_lut, f_dir)
        assert abs(col["frac_inside"][i] - inside / direct.R_d[k]) < 0.02


def test_count_binning_matches_exact_reweighting() -> None:
    """Histogram reweighting (count bins, first-order correction) vs exact sum of w a^n over records."""
    albedo = np.array([0.5, 0.99, 0.998])
    g = 0.5
    cols = simulate_columns(np.array([g]), albedo, 3000, seed=7, max_steps=2000, path_c=None)
    free = LayeredMedium.homogeneous(0.0, 1.0, g, n_medium=1.4)
    rec = simulate_records(free, 3000, seed=7, max_steps=2000, chunk_photons=1 << 18)
    refl = rec.kind == 1
    exact = np.array([(rec.w[refl] * a ** rec.ncoll[refl].astype(float)).sum() / 3000 for a in albedo])
    np.testing.assert_allclose(cols[0]["R"], exact, rtol=1e-4)
    assert CountBins(2001).n_bins < 500


def test_cli_builds_resumes_and_normalises(tmp_path) -> None:
    out = tmp_path / "lut.npz"
    args = ["--albedo-n", "6", "--g-n", "2", "--photons", "1500", "--out", str(out), "--seed", "2",
            "--albedo-max", "0.99", "--max-steps", "1500", "--no-progress"]
    assert lut_main(args) == 0
    d = dict(np.load(out))
    assert d["albedo"].shape == (6,) and d["g"].shape == (2,) and d["r_edges_mfp"].shape == (513,)
    assert d["R"].shape == (6, 2) and d["P"].shape == (6, 2, 512)
    np.testing.assert_allclose(d["albedo"], albedo_grid(6, 0.01, 0.99))
    area = math.pi * np.diff(d["r_edges_mfp"] ** 2)
    np.testing.assert_allclose((d["P"] * area).sum(-1), 1.0, rtol=1e-9)
    assert np.all(np.diff(d["R"], axis=0) > 0)  # R increases with albedo (same photons: exact)
    assert np.all(np.isfinite(d["P"])) and np.all(d["P"] >= 0)
    # resume: drop one column and rebuild: identical result, the other column is not recomputed
    (tmp_path / "lut.npz.parts" / "g_0001.npz").unlink()  # the batch holding it is walked again
    assert lut_main(args) == 0
    d2 = dict(np.load(out))
    np.testing.assert_array_equal(d["R"], d2["R"])
    # a different build into the same parts folder is refused
    assert lut_main(args[:-3] + ["--photons", "1000", "--no-progress"]) == 2
    assert lut_main(["--albedo-n", "1", "--g-n", "2", "--photons", "10", "--out", str(tmp_path / "x.npz")]) == 2


def test_interpolated_g_columns_between_simulated_nodes(tmp_path) -> None:
    """g columns between simulated nodes (PCHIP along g) against adding-doubling at their own g."""
    from training.sim.lut import build_lut

    out = build_lut(tmp_path / "lut.npz", 5, 5, 6000, g_range=(0.3, 0.7), g_nodes=3, seed=4,
                    albedo_range=(0.3, 0.99), max_steps=6000, log=lambda s: None)
    d = dict(np.load(out))
    np.testing.assert_allclose(d["g_nodes"], [0.3, 0.5, 0.7])
    np.testing.assert_allclose(d["g"], [0.3, 0.4, 0.5, 0.6, 0.7])
    nodes = [dict(np.load(tmp_path / "lut.npz.parts" / f"g_{j:04d}.npz")) for j in range(3)]
    for j, col in zip((0, 2, 4), nodes, strict=True):  # columns at a node are that node's simulation
        np.testing.assert_array_equal(d["R"][:, j], col["R"])
        np.testing.assert_array_equal(d["P"][:, j], col["P"])
    area = math.pi * np.diff(d["r_edges_mfp"] ** 2)
    np.testing.assert_allclose((d["P"] * area).sum(-1), 1.0, rtol=1e-9)
    assert np.all(d["P"] >= 0) and np.all(np.isfinite(d["P"]))
    for j in (1, 3):  # interpolated: within the nodes' noise plus a small interpolation error
        ref = np.array([_uru_minus_specular(a, d["g"][j]) for a in d["albedo"]])
        bad = np.abs(d["R"][:, j] - ref) > 4 * d["R_stderr"][:, j] + 0.004
        assert not bad.any(), (d["g"][j], d["R"][:, j], ref)


def test_profile_at_g_midpoints_matches_direct_walk(tmp_path) -> None:
    """P(r | alpha, g) of the columns interpolated between simulated g nodes against a direct walk of the
    homogeneous medium at that g: band fractions within 4 combined standard errors (noise stated in
    ``training.sim.lut_check``), while the nearest simulated node, half a node spacing away, is not."""
    from training.sim.lut import build_lut
    from training.sim.lut_check import compare, direct_profiles

    torch.set_num_threads(1)
    photons = 12_000
    out = build_lut(tmp_path / "lut.npz", 3, 5, photons, g_range=(0.3, 0.7), g_nodes=3, seed=5,
                    albedo_range=(0.5, 0.99), max_steps=20_000, log=lambda s: None)
    d = dict(np.load(out))
    mids = [1, 3]  # g = 0.4 and 0.6, between the nodes 0.3, 0.5, 0.7
    a = np.repeat(d["albedo"], len(mids))
    g = np.tile(d["g"][mids], d["albedo"].size)
    direct = direct_profiles(a, g, photons, seed=6, max_steps=20_000, compile=False)
    p_mid = np.stack([d["P"][i, j] for i in range(d["albedo"].size) for j in mids])
    res = compare(p_mid, photons, direct)
    # bands holding < 0.1 % of the energy are left out: there the direct walk has a handful of photons, so its
    # standard error (and the LUT's, taken equal) is itself mostly noise
    held = res["f_dir"] > 1e-3
    assert np.all(np.abs(res["z"][held]) < 4.0), np.round(np.where(held, res["z"], 0.0), 1)
    # the control: at albedo >= 0.9 the node 0.1 below each midpoint (0.3, 0.5) differs from the walk at
    # the midpoint (at albedo 0.5 the profile hardly depends on g at this noise)
    p_node = np.stack([d["P"][i, j - 1] for i in range(d["albedo"].size) for j in mids])
    z_node = np.abs(compare(p_node, photons, direct)["z"]).max(-1).reshape(d["albedo"].size, len(mids))
    assert np.all(z_node[d["albedo"] > 0.9] > 4.0), z_node
