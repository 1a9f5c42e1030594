"""The LUT above its last albedo (training/sim/lut_extend.py): R against adding-doubling, P against direct
walks of the homogeneous medium at an albedo above the table's last node, and the loader's behaviour."""

from __future__ import annotations

import math

import iadpython as iad
import numpy as np
import torch

from exporters.constants import R_EDGES_MFP
from training.sim.lut import simulate_columns
from training.sim.lut_check import compare, direct_profiles
from training.sim.lut_extend import extend_albedo, extension_albedos
from training.sim.lut_interp import LookupTables


def _ad_reflectance(a: float, g: float, n: float = 1.4) -> float:
    """Adding-doubling R of the LUT's medium (diffuse light, specular excluded; see test_sim_lut.py); 32
    quadrature points: with 16, R at albedo -> 1 is 8e-4 above 1 - the boundary's specular reflection."""
    quad = 32
    uru = iad.Sample(a=a, b=math.inf, g=g, n=n, n_above=1.0, n_below=1.0, quad_pts=quad).rt()[2]
    spec = iad.Sample(a=0.0, b=math.inf, g=0.0, n=n, n_above=1.0, n_below=1.0, quad_pts=quad).rt()[2]
    return float(uru - spec)


def test_reflectance_above_the_last_node_against_adding_doubling() -> None:
    """The R rows from the table's last two relevant nodes (here exact adding-doubling values, as the
    paper-scale table's are within 7e-4 of them) follow adding-doubling up to albedo 1."""
    albedo = 1.0 - np.array([4e-4, 1e-4])
    gs = np.array([0.0, 0.5, 0.85])
    R = np.array([[_ad_reflectance(a, g) for g in gs] for a in albedo])
    P = np.ones((2, gs.size, 512)) / (math.pi * R_EDGES_MFP[-1] ** 2)
    ext = extend_albedo(albedo, gs, R_EDGES_MFP, R, P)
    new = ext["albedo"][2:]
    assert np.all(np.diff(ext["albedo"]) > 0) and ext["albedo"][-1] == 1.0
    for i in (0, 4, 8, len(new) - 2, len(new) - 1):  # 1 - albedo = 7e-5, 1.8e-5, 4.4e-6, 1.1e-6, 0
        a = min(new[i], 1.0 - 1e-13)
        ref = np.array([_ad_reflectance(a, g) for g in gs])
        # the paper-scale table itself is within 7e-4 of adding-doubling at its last node
        np.testing.assert_allclose(ext["R"][2 + i], ref, atol=8e-4, err_msg=f"1 - albedo = {1 - new[i]:.1e}")
    # holding the edge instead is off by far more near albedo 1
    assert np.all(np.abs(R[-1] - [_ad_reflectance(1 - 1e-13, g) for g in gs]) > 0.03)


def test_profile_above_the_last_node_against_a_direct_walk(tmp_path) -> None:
    """A tiny table ending at albedo 0.999, extended to 1 - 2.5e-4, against a direct walk there: band
    fractions within 4 standard errors (``training.sim.lut_check``) where the held edge row is not."""
    torch.set_num_threads(1)
    albedo = 1.0 - np.geomspace(0.1, 1e-3, 4)
    g = 0.6
    col = simulate_columns(np.array([g]), albedo, 6000, seed=8, max_steps=10_000)[0]
    ext = extend_albedo(albedo, np.array([g]), R_EDGES_MFP, col["R"][:, None], col["P"][:, None])
    i = albedo.size + 3  # 1 - albedo = 1e-3 x 2^-2 = 2.5e-4
    a = ext["albedo"][i]
    assert math.isclose(1.0 - a, 2.5e-4, rel_tol=1e-9)
    direct = direct_profiles(np.array([a]), np.array([g]), 6000, seed=9, max_steps=10_000, compile=False)
    assert abs(ext["R"][i, 0] - direct.R_d[0]) < 4 * math.hypot(direct.R_d_stderr[0], col["R_stderr"][-1]) + 2e-3
    z_ext = compare(ext["P"][i], 6000, direct)["z"]
    z_held = compare(col["P"][-1][None], 6000, direct)["z"]
    assert np.all(np.abs(z_ext) < 4.0), np.round(z_ext, 1)
    assert np.abs(z_held).max() > 4.0, np.round(z_held, 1)
    assert abs(col["R"][-1] - direct.R_d[0]) > 0.02  # the held edge's R is too low


def test_loader_extends_paper_like_tables_and_keeps_others(tmp_path) -> None:
    gs = np.array([0.0, 0.9])
    c = np.sqrt(R_EDGES_MFP[:-1] * R_EDGES_MFP[1:])
    area = math.pi * np.diff(R_EDGES_MFP**2)

    def write(name: str, albedo: np.ndarray) -> LookupTables:
        R = np.tile(0.9 - 3 * np.sqrt(1 - albedo)[:, None], (1, gs.size))
        P = np.exp(-c)[None, None] * np.ones((albedo.size, gs.size, 1))
        P = P / (P * area).sum(-1, keepdims=True)
        np.savez(tmp_path / name, albedo=albedo, g=gs, r_edges_mfp=R_EDGES_MFP, R=R, P=P)
        return LookupTables.load(tmp_path / name)

    lut = write("paper.npz", 1.0 - np.geomspace(0.99, 1e-4, 40))
    assert lut.albedo_extended and float(lut.albedo[-1]) == 1.0 and lut.to(dtype=torch.float32).albedo_extended
    rows = extension_albedos(0.9999).size
    np.testing.assert_allclose(lut.albedo[-rows:].numpy(), extension_albedos(0.9999))
    assert torch.all(torch.diff(lut.R[:, 0]) >= 0)  # R keeps rising to albedo 1
    np.testing.assert_allclose((lut.P[-rows:] * torch.as_tensor(area)).sum(-1).numpy(), 1.0, rtol=1e-12)
    # the gradient w.r.t. albedo no longer vanishes above the last simulated node
    alpha = torch.tensor([0.99995], dtype=torch.float64, requires_grad=True)
    lut.reflectance(alpha, torch.tensor([0.5], dtype=torch.float64)).sum().backward()
    assert float(alpha.grad) > 0
    small = write("small.npz", 1.0 - np.geomspace(0.99, 1e-2, 5))  # ends at 0.99: held as before
    assert not small.albedo_extended and float(small.albedo[-1]) == 0.99
    assert not LookupTables.load(tmp_path / "paper.npz", extend_albedo=False).albedo_extended
