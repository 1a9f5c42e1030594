"""`python -m training fit` (training/commands/fit.py): JSON contract, errors, parameter output.

The tone file is a closed-form two-component dipole mixture at a few wavelengths, the LUT the
dipole test table (training/sim/dipole.py: test/reference tables only) on a wide radial grid.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM
from training.commands.fit import main
from training.sim.dipole import dipole_lut, dipole_mixture_profile

WIDE_EDGES_MFP = np.concatenate([[0.0], np.geomspace(1e-3, 1e4, 512)])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("fitcli")
    albedo = np.concatenate([[0.0], 1.0 - np.geomspace(0.95, 1e-5, 60), [1.0]])
    np.savez(d / "lut.npz", **dipole_lut(albedo=albedo, r_edges_mfp=WIDE_EDGES_MFP))
    n = 5
    alpha = np.stack([np.linspace(0.9, 0.97, n), np.linspace(0.995, 0.9995, n)], 1)
    g = np.full((n, 2), 0.8)
    sigma_t = np.stack([np.linspace(400, 200, n), np.linspace(50, 25, n)], 1)
    w = np.full((n, 2), 0.5)
    profile, R = dipole_mixture_profile(R_EDGES_CM, WIDE_EDGES_MFP, alpha, g, sigma_t, w)
    np.savez(
        d / "tone.npz",
        wavelength_nm=WAVELENGTHS_NM[::80][:n],
        R_d=R,
        R_d_stderr=1e-4 * R,
        r_edges_cm=R_EDGES_CM,
        profile=profile,
        tone=np.array([0.05, 0.02, 0.01, 0.75, 0.8]),
        photons=10**9,
    )
    return d


def test_tone_file_json(files, capsys):
    rc = main(["--tone-file", str(files / "tone.npz"), "--lut", str(files / "lut.npz"), "--k", "1,2,3", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    fits = out["fits"]
    assert [f["K"] for f in fits] == [1, 2, 3]
    for f in fits:
        assert np.isfinite(f["shape_rmse"]) and np.isfinite(f["refl_rel_err"])
    assert fits[0]["shape_rmse"] > 0.2  # one medium cannot fit a two-scale profile
    assert fits[1]["shape_rmse"] < 0.02 and fits[1]["refl_rel_err"] < 0.03  # R weighs little in the loss
    assert fits[2]["joint_loss"] <= fits[1]["joint_loss"] * (1 + 1e-9)


def test_params_out_and_no_overwrite(files, capsys):
    out = files / "params.npz"
    args = ["--tone-file", str(files / "tone.npz"), "--lut", str(files / "lut.npz"), "--k", "2", "--out", str(out)]
    assert main(args) == 0
    with np.load(out) as p:
        assert p["k2_sigma_t"].shape == (2, 5) and p["k2_w"].shape == (2, 5)
        np.testing.assert_allclose(p["k2_w"].sum(0), 1.0, rtol=1e-12)
        assert (p["k2_sigma_t"] > 0).all()
    assert main(args) == 2
    assert "not overwriting" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--tone-file", "TONE", "--lut", "LUT", "--k", "4"], "among 1, 2, 3"),
        (["--tone-file", "TONE", "--lut", "missing.npz"], "no such file"),
    ],
)
def test_errors_exit_2(files, capsys, argv, message):
    argv = [a.replace("TONE", str(files / "tone.npz")).replace("LUT", str(files / "lut.npz")) for a in argv]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_not_a_tone_file(files, capsys):
    assert main(["--tone-file", str(files / "lut.npz"), "--lut", str(files / "lut.npz")]) == 2
    assert "not a tone file" in capsys.readouterr().err
