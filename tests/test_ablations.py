"""The ablations of the paper (``python -m training ablations``): the options each one needs do what they claim
(trainer: lambda_R, no slab factor, unfreezing, less data; fitter: isotropic fits, the paper's mixture profile),
and the --quick command runs end to end from the smoke dataset preset and resumes."""

from __future__ import annotations

import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from exporters.constants import R_EDGES_CM
from training.ablations.run import TRAINED
from training.commands import ablations as cli
from training.fit.mixture import mix
from training.fit.optimize import ISOTROPIC_G, fit_schedule
from training.model import ModelConfig
from training.model.config import SIZES, SLAB_DEPTH_INIT
from training.sim.dipole import dipole_lut
from training.sim.lut_interp import LookupTables, bin_centres
from training.train import losses as train_losses
from training.train.data import load_split
from training.train.loop import checkpoint_path, load_checkpoint
from training.train.run import TrainConfig, train
from training.train.toy import write_toy

TCFG = dict(epochs=[2, 2, 2], batch=[8, 64, 8], lr=[3e-3, 3e-3, 1e-3], synthetic=64, shape_weight=0.0)


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return write_toy(tmp_path_factory.mktemp("toy"), n_train=24, n_validation=6)


def _decr(state: dict) -> dict:
    return {k: v for k, v in state.items() if k.startswith("dec_r.")}


def test_trainer_ablation_options(toy, tmp_path):
    """unfreeze: Dec_R changes in stages 2-3 (frozen: it is stage 1's bit for bit); no slab factor: c(lambda)
    stays at its initial value; lambda_R weighs L_refl in the total."""
    data, fits, lut = toy
    mcfg = ModelConfig(**SIZES["tiny"])
    base, unfrozen, no_slab = tmp_path / "base", tmp_path / "unfreeze", tmp_path / "no_slab"
    train(base, data, fits, lut, mcfg=mcfg, tcfg=TrainConfig(**TCFG), progress=False)
    for rundir, first, opts in ((unfrozen, 2, {"unfreeze": True}), (no_slab, 3, {"slab_factor": False})):
        rundir.mkdir()
        for s in range(1, first):
            shutil.copy(checkpoint_path(base, s), checkpoint_path(rundir, s))
        train(rundir, data, fits, lut, want=tuple(range(first, 4)), mcfg=ModelConfig(**SIZES["tiny"]),
              tcfg=TrainConfig(**TCFG, **opts), progress=False)
    s1 = _decr(load_checkpoint(checkpoint_path(base, 1))["model"])
    final = {n: load_checkpoint(checkpoint_path(d, 3))["model"] for n, d in (("base", base), ("unfreeze", unfrozen),
                                                                              ("no_slab", no_slab))}
    for k, v in s1.items():
        assert torch.equal(_decr(final["base"])[k], v), k  # the paper: frozen
    assert any(not torch.equal(_decr(final["unfreeze"])[k], v) for k, v in s1.items())
    torch.testing.assert_close(final["no_slab"]["slab.log_c"],
                               torch.full_like(final["no_slab"]["slab.log_c"], math.log(SLAB_DEPTH_INIT)))
    assert not torch.allclose(final["base"]["slab.log_c"], final["no_slab"]["slab.log_c"])
    rec = json.loads((unfrozen / "run.json").read_text())
    assert rec["train"]["unfreeze"] is True and rec["train"]["lambda_r"] == 15.0


def test_reflectance_without_slab_factor_and_lambda_r(toy):
    data, fits, lut_path = toy
    from training.model.chain import SkinChain

    torch.manual_seed(0)
    model = SkinChain(ModelConfig(**SIZES["tiny"]))
    lut = LookupTables.load(lut_path, dtype=torch.float32)
    split = load_split(data, "train", fits, k=3)
    p = split.tone[split.fitted]
    with torch.no_grad():
        out = model.dec_t(p, model.dec_r(p))
        # sum_k w_k R(alpha_k, g_k), computed here from the LUT row by row
        want = torch.stack([sum(out["weight"][i, k] * lut.reflectance(out["alpha"][i, k], out["g"][i, k])
                                for k in range(3)) for i in range(len(p))])
        torch.testing.assert_close(train_losses.lut_reflectance(model, lut, out, slab=False), want)
        thin = dict(out, sigma_t=torch.full_like(out["sigma_t"], 0.5))  # 0.5 / cm: a thin slab at c = 0.3 cm
        torch.testing.assert_close(train_losses.lut_reflectance(model, lut, thin),
                                   want * (1 - math.exp(-3.0 * 0.5 * 0.3)))
        args = (model, lut, p, split.R_d[split.fitted], split.targets, split.target_index)
        a, b = train_losses.stage3_losses(*args, lambda_r=0.0), train_losses.stage3_losses(*args, lambda_r=40.0)
    torch.testing.assert_close(a["loss"], a["param"] + train_losses.LAMBDA_SMOOTH * a["smooth"])
    torch.testing.assert_close(b["loss"] - a["loss"], 40.0 * a["refl"])


def test_less_data_keeps_every_nth_tone_with_its_fits(toy):
    data, fits, _ = toy
    full = load_split(data, "train", fits, k=3)  # 24 tones, the first 18 fitted
    part = full.every(4)
    assert len(part) == 6 and torch.equal(part.tone, full.tone[::4])
    assert part.fitted.tolist() == [0, 1, 2, 3, 4]  # tones 0, 4, 8, 12, 16
    torch.testing.assert_close(part.targets["alpha"], full.targets["alpha"][[0, 4, 8, 12, 16]])
    one = full.every(19)  # tones 0 and 19: only 0 is fitted
    assert len(one) == 2 and one.fitted.tolist() == [0]


def test_isotropic_fit_recovers_the_similar_medium():
    """g held at 0: a single anisotropic dipole medium (alpha 0.99, g 0.8, sigma_t 200 / cm) is fitted by the
    isotropic medium of the same reduced albedo alpha (1 - g) / (1 - alpha g) and reduced extinction
    sigma_t (1 - alpha g), the similarity relation under which the dipole is exact."""
    from training.sim.dipole import dipole_mixture_profile

    edges = np.concatenate([[0.0], np.geomspace(1e-3, 1e4, 512)])
    albedo = np.concatenate([[0.0], 1.0 - np.geomspace(0.95, 1e-5, 60), [1.0]])
    lut = LookupTables.from_arrays(**dipole_lut(albedo=albedo, r_edges_mfp=edges))
    a, g, s = 0.99, 0.8, 200.0
    prof, R = dipole_mixture_profile(R_EDGES_CM, edges, [[a]], [[g]], [[s]], [[1.0]])
    fit = fit_schedule(lut, torch.tensor(prof), torch.tensor(R), torch.tensor(R_EDGES_CM), 1e9, torch.full((1,), 0.8),
                       ks=(1,), isotropic=True)[1]
    assert 0.0 <= float(fit.mixture.g) <= ISOTROPIC_G
    assert float(fit.mixture.alpha) == pytest.approx(a * (1 - g) / (1 - a * g), rel=5e-3)  # LUT interpolation
    assert float(fit.mixture.sigma_t) == pytest.approx(s * (1 - a * g), rel=2e-2)


def test_papers_mixture_profile_and_its_method():
    rng = np.random.default_rng(0)
    p_k, r_k = torch.tensor(rng.random((4, 3, 7))), torch.tensor(rng.random((4, 3)))
    w = torch.softmax(torch.tensor(rng.normal(size=(4, 3))), -1)
    p, r = mix(p_k, r_k, w, "paper")
    np.testing.assert_allclose(p.numpy(), np.einsum("bk,bkm->bm", w.numpy(), p_k.numpy()), rtol=1e-12)
    np.testing.assert_allclose(r.numpy(), (w * r_k).sum(-1).numpy(), rtol=1e-12)
    lut = LookupTables.from_arrays(**dipole_lut())
    prof = torch.ones((1, R_EDGES_CM.size - 1)) * torch.exp(-torch.tensor(bin_centres(R_EDGES_CM)) * 10)
    with pytest.raises(ValueError, match="method 'paper'"):
        fit_schedule(lut, prof, torch.tensor([0.3]), torch.tensor(R_EDGES_CM), 1e6, weighting="paper")


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("ablations") / "out"
    rc = cli.main(["--out", str(out), "--quick", "--no-progress"])
    return out, rc


def test_quick_ablations_end_to_end(quick):
    out, rc = quick
    assert rc == 0
    rec = json.loads((out / "ablations.json").read_text())
    assert set(rec["trained"]) == {c.name for c in TRAINED}
    for name, r in rec["trained"].items():
        for row in ("nn", "decoder"):
            assert math.isfinite(r["gate"][row]["delta_e"]) and math.isfinite(r["gate"][row]["delta_e_edge"]), name
    assert rec["trained"]["no_refl"]["train"]["lambda_r"] == 0.0
    assert rec["trained"]["no_slab"]["train"]["slab_factor"] is False
    assert rec["trained"]["less_data"]["train"]["data_every"] == 20
    # less data: as many stage-3 optimiser steps as base (20x the epochs on 1/20 of the tones)
    epochs = {n: rec["trained"][n]["train"]["epochs"] for n in ("base", "less_data")}
    assert epochs["less_data"] == [*epochs["base"][:2], 20 * epochs["base"][2]]
    assert len(rec["claims"]) == 7
    for c in rec["claims"]:
        assert c["verdict"].split(" (")[0] in ("agree", "partly", "disagree"), c
    # the trained claims are judged on the decoder from the true p (the shared encoder dominates RGB in)
    slab = next(c for c in rec["claims"] if c["claim"].startswith("no slab"))
    assert slab["ours"] == [rec["trained"][n]["gate"]["decoder"]["delta_e"] for n in ("no_slab", "base")]
    assert set(rec["trained"]["base"]["gate"]["nn"]["exposure"]) == set(rec["scale"]["tones"])
    for kind in ("isotropic", "anisotropic"):
        assert all(math.isfinite(rec["fits"][kind][k]["delta_e"]) for k in ("K1", "K2", "K3"))
    md = (out / "ablations.md").read_text()
    assert "Quick mode" in md and "0.5 → 0.019" in md and "7.6 → 3.19" in md and "11.0 → 0.062" in md
    assert "Why the decoder" in md
    # the stages the ablations share are the base run's (copied), so only what each changes differs
    s2 = {n: load_checkpoint(checkpoint_path(out / "runs" / n, 2))["model"] for n in ("base", "no_refl")}
    assert all(torch.equal(v, s2["no_refl"][k]) for k, v in s2["base"].items())


def _finished_pieces(out: Path) -> dict[str, int]:
    """The runs' stage checkpoints and the gate's cached pieces (ground truth, fits) with their modification times
    (each run's model.pt is written again from its last stage at every call)."""
    return {str(p.relative_to(out)): p.stat().st_mtime_ns for p in sorted(out.rglob("*"))
            if p.is_file() and (re.fullmatch(r"stage\d\.pt", p.name) or p.suffix == ".npz")}


def test_quick_ablations_resume(quick):
    out, _ = quick
    before = json.loads((out / "ablations.json").read_text())
    kept = _finished_pieces(out)
    assert any(name.endswith(".pt") for name in kept) and any(name.startswith("cache") for name in kept), kept
    assert cli.main(["--out", str(out), "--quick", "--no-progress"]) == 0
    assert _finished_pieces(out) == kept  # every checkpoint, ground truth and fit read again, none redone
    after = json.loads((out / "ablations.json").read_text())
    assert [c["ours"] for c in after["claims"]] == [c["ours"] for c in before["claims"]]
    # another scale in the same folder is refused, not mixed
    assert cli.main(["--out", str(out), "--quick", "--no-progress", "--epochs", "4"]) == 2
