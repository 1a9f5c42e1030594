"""`fit --dataset` (training/fit/dataset.py): output layout, resume, shards, refusal to mix runs.

The split file is written with the dataset's own store (training/data/store.py); its profiles are
closed-form dipole media (test tables only, training/sim/dipole.py), and the fits are cut short
(a few iterations): these tests check the plumbing, test_fit_mixture.py the fitting.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from exporters.constants import N_WAVELENGTHS, R_EDGES_CM
from training.commands.fit import main
from training.data import store
from training.fit import optimize
from training.fit.dataset import fit_split, out_path
from training.sim.dipole import dipole_lut, dipole_mixture_profile
from training.sim.lut_interp import LookupTables

WIDE_EDGES_MFP = np.concatenate([[0.0], np.geomspace(1e-3, 1e4, 512)])
STEPS = {"k1_shape": 2, "k1_joint": 2, "k2": 2}


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("fitds")
    lut_path = d / "lut.npz"
    albedo = np.concatenate([[0.0], 1.0 - np.geomspace(0.95, 1e-5, 30), [1.0]])
    np.savez(lut_path, **dipole_lut(albedo=albedo, g=np.linspace(0.0, 0.95, 5), r_edges_mfp=WIDE_EDGES_MFP))
    ds = d / "dataset"
    ds.mkdir()
    n = 3
    tones = np.array([[0.01, 0.02, 0.01, 0.75, 0.8], [0.1, 0.03, 0.012, 0.8, 0.9], [0.3, 0.05, 0.02, 0.6, 0.5]])
    attrs = {
        "preset": "test",
        "split": "train",
        "photons": 10**9,
        "seed": 1,
        "shard": "0/1",
        "method": "direct",
        "n_total": n,
        "created_by": "test",
    }
    store.create(ds / "train.h5", tones, np.arange(n), attrs)
    W = N_WAVELENGTHS
    rng = np.random.default_rng(0)
    alpha = rng.uniform(0.9, 0.999, (n * W, 1))
    profile, R = dipole_mixture_profile(
        R_EDGES_CM,
        WIDE_EDGES_MFP,
        alpha,
        np.full((n * W, 1), 0.8),
        rng.uniform(50, 500, (n * W, 1)),
        np.ones((n * W, 1)),
    )
    store.write_rows(
        ds / "train.h5",
        np.arange(n),
        {
            "R_d": R.reshape(n, W),
            "R_d_stderr": 1e-4 * R.reshape(n, W),
            "profile": profile.reshape(n, W, -1),
            "profile_stderr": 1e-3 * profile.reshape(n, W, -1),
            "albedo_rgb": np.full((n, 3), 0.5),
        },
    )
    return d, ds, lut_path


def test_fit_split_layout_and_resume(setup, monkeypatch):
    d, ds, lut_path = setup
    # plumbing test: one K = 2 start instead of the multi-start (1,128 problems here)
    monkeypatch.setattr(optimize, "K2_SPLITS", optimize.K2_SPLITS[:1])
    lut = LookupTables.load(lut_path)
    out = d / "fits"
    path = fit_split(ds, "train", lut, lut_path, (1, 2), out, chunk_tones=3, steps=STEPS, progress=False)
    assert path == out_path(out, "train", (0, 1))
    with h5py.File(path, "r") as f:
        assert f["done"][:].all()
        assert f["k2_alpha"].shape == (3, 2, N_WAVELENGTHS)
        assert f["k1_sigma_t"].shape == (3, 1, N_WAVELENGTHS)
        np.testing.assert_allclose(f["k2_weight"][:].sum(1), 1.0, rtol=1e-5)
        for key in ("k1_shape_rmse", "k2_refl_rel_err", "k2_sigma_t", "k2_g"):
            assert np.isfinite(f[key][:]).all()
        first = f["k2_sigma_t"][:]
        f.attrs["ks"]  # noqa: B018 - present
    mtime = path.stat().st_mtime_ns
    # rerun: nothing left to do, the file is unchanged
    fit_split(ds, "train", lut, lut_path, (1, 2), out, chunk_tones=3, steps=STEPS, progress=False)
    assert path.stat().st_mtime_ns == mtime
    with h5py.File(path, "r") as f:
        np.testing.assert_array_equal(f["k2_sigma_t"][:], first)
    # other settings into the same folder are refused
    with pytest.raises(ValueError, match="was made with"):
        fit_split(ds, "train", lut, lut_path, (1,), out, steps=STEPS, progress=False)


def test_wavelength_stride_anchors_and_tone_limit(setup, monkeypatch):
    d, ds, lut_path = setup
    monkeypatch.setattr(optimize, "K2_SPLITS", optimize.K2_SPLITS[:1])
    lut = LookupTables.load(lut_path)
    path = fit_split(ds, "train", lut, lut_path, (1, 2), d / "fits_stride", steps=STEPS, wavelength_stride=8,
                     anchor_every=3, max_tones=2, progress=False)
    with h5py.File(path, "r") as f:
        assert f["index"][:].tolist() == [0, 1] and f["done"][:].all()
        assert f["wavelength_index"][:].tolist() == list(range(0, N_WAVELENGTHS, 8))
        np.testing.assert_array_equal(f["wavelength_nm"][:], 250.0 + 2.0 * f["wavelength_index"][:])
        assert f["k2_alpha"].shape == (2, 2, 47) and np.isfinite(f["k2_joint"][:]).all()
        assert f.attrs["anchor_every"] == 3 and f.attrs["refl_loss"] == "relative"
    # the summary: means over the fitted rows, per K and band, with the noise floor (1e-3 relative stderr)
    assert main(["--dataset", str(ds), "--out", str(d / "fits_stride"), "--split", "train", "--summary"]) == 0
    summary = json.loads((d / "fits_stride" / "summary.json").read_text())["train"]
    assert summary["tones"] == 2 and summary["wavelengths"] == 47
    assert summary["noise"] == pytest.approx(1e-3, rel=1e-3)
    for k in ("1", "2"):
        assert set(summary["K"][k]["bands"]) == {"UV", "Vis", "NIR"}
        assert 0 <= summary["K"][k]["shape_excess"] <= summary["K"][k]["shape_rmse"]
    with pytest.raises(ValueError, match="wavelength_stride"):
        fit_split(ds, "train", lut, lut_path, (1,), d / "x", wavelength_stride=0, progress=False)


def test_shards_cover_the_split(setup):
    d, ds, lut_path = setup
    lut = LookupTables.load(lut_path)
    out = d / "fits_sharded"
    idx = []
    for i in range(2):
        p = fit_split(ds, "train", lut, lut_path, (1,), out, shard=(i, 2), steps=STEPS, progress=False)
        with h5py.File(p, "r") as f:
            assert f["done"][:].all()
            idx.extend(f["index"][:].tolist())
    assert sorted(idx) == [0, 1, 2]


def test_cli_dataset_errors(setup, capsys):
    d, ds, lut_path = setup
    assert main(["--dataset", str(d / "nowhere"), "--lut", str(lut_path), "--out", str(d / "o")]) == 2
    assert "not found" in capsys.readouterr().err
    assert main(["--dataset", str(ds), "--lut", str(lut_path)]) == 2
    assert "--out" in capsys.readouterr().err
    code = main(["--dataset", str(ds), "--lut", str(lut_path), "--out", str(d / "o"), "--shard", "2/2"])
    err = capsys.readouterr().err
    assert code == 2 and "--shard" in err and err.count("\n") == 1  # argparse: one line, exit status 2


def test_lightness_selection_gives_each_lstar_band_its_share():
    """--select lightness: bands of 5 L* units get equal shares (a band short of tones gives all it has, the
    rest goes to the others); within a band, split order; 'first' is the prefix."""
    from exporters.colorimetry import linear_srgb_to_lab
    from training.fit.dataset import select_tones

    rng = np.random.default_rng(0)
    # 900 dark tones (L* ~ 10-25), 40 mid (L* ~ 40-45), 4 light (L* ~ 70-75): like uniform melanin
    grey = np.concatenate([rng.uniform(0.012, 0.045, 900), rng.uniform(0.12, 0.14, 40), rng.uniform(0.41, 0.48, 4)])
    albedo = np.repeat(grey[:, None], 3, axis=1) * np.array([1.1, 0.95, 0.9])
    band = np.floor(linear_srgb_to_lab(albedo)[:, 0] / 5).astype(int)
    np.testing.assert_array_equal(select_tones(albedo, 100, "first"), np.arange(100))
    np.testing.assert_array_equal(select_tones(albedo, None, "lightness"), np.arange(len(grey)))
    pick = select_tones(albedo, 100, "lightness")
    assert len(pick) == len(np.unique(pick)) == 100 and np.all(np.diff(pick) > 0)
    counts = {b: int(np.sum(band[pick] == b)) for b in np.unique(band)}
    assert set(range(940, 944)) <= set(pick.tolist())  # every light tone is taken
    full = [c for b, c in counts.items() if c < np.sum(band == b)]
    assert max(full) - min(full) <= 1  # the bands that could give more get equal shares
    for b in np.unique(band):  # split order within a band
        members = np.flatnonzero(band == b)
        np.testing.assert_array_equal(pick[band[pick] == b], members[: counts[b]])
    with pytest.raises(ValueError, match="select"):
        select_tones(albedo, 10, "darkest")


def test_reuse_copies_matching_fits_and_fits_the_rest(setup, monkeypatch, capsys):
    d, ds, lut_path = setup
    monkeypatch.setattr(optimize, "K2_SPLITS", optimize.K2_SPLITS[:1])
    lut = LookupTables.load(lut_path)
    kw = {"steps": STEPS, "wavelength_stride": 16, "progress": False}
    part = fit_split(ds, "train", lut, lut_path, (1, 2), d / "reuse_part", max_tones=2, **kw)
    other = fit_split(ds, "train", lut, lut_path, (1,), d / "reuse_other", max_tones=1, **kw)  # other ks
    with h5py.File(part, "r+") as f:  # mark the copies: a refit would not give these values
        f["k2_sigma_t"][0] = 123.0
        f["k1_alpha"][1] = 0.5
    whole = fit_split(ds, "train", lut, lut_path, (1, 2), d / "reuse_whole", reuse=d / "reuse_part",
                      **{**kw, "progress": True})
    assert "2 tones copied" in capsys.readouterr().out
    with h5py.File(whole, "r") as f, h5py.File(part, "r") as p:
        assert f["index"][:].tolist() == [0, 1, 2] and f["done"][:].all()
        for name in ("k1_alpha", "k2_sigma_t", "k2_weight", "k2_shape_rmse"):
            np.testing.assert_array_equal(f[name][:2], p[name][:])
        assert np.isfinite(f["k2_sigma_t"][2]).all() and f["k2_sigma_t"][2].min() > 0  # fitted here
    # a folder fitted with other settings is not a source
    fresh = fit_split(ds, "train", lut, lut_path, (1, 2), d / "reuse_none", max_tones=1,
                      reuse=other.parent, **{**kw, "progress": True})
    assert "0 tones copied" in capsys.readouterr().out
    with h5py.File(fresh, "r") as f:
        assert f["done"][:].all()
    with pytest.raises(ValueError, match="--reuse"):
        fit_split(ds, "train", lut, lut_path, (1,), d / "reuse_bad", reuse=d / "missing", **kw)
