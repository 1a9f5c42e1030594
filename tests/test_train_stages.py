"""Staged training on a tiny synthetic dataset in the real file formats: it learns, stages stay frozen,
a killed run resumes to the uninterrupted result, and the CLI refuses inconsistent runs."""

import json
from dataclasses import asdict

import h5py
import numpy as np
import pytest
import torch

from exporters.constants import PARAM_NAMES, PARAM_RANGES
from training.commands.train import main as train_main
from training.model import ModelConfig
from training.model.chain import SkinChain
from training.model.config import SIZES
from training.sim.lut_interp import LookupTables
from training.train import losses as train_losses
from training.train.balance import CAP, sampling_probabilities
from training.train.data import load_split
from training.train.loop import checkpoint_path, epoch_order, load_checkpoint
from training.train.run import TrainConfig, train
from training.train.toy import write_toy

TCFG = dict(epochs=[3, 3, 3], batch=[8, 64, 8], lr=[3e-3, 3e-3, 1e-3], synthetic=256, shape_weight=1.0)


@pytest.fixture(scope="module")
def toy(tmp_path_factory):
    return write_toy(tmp_path_factory.mktemp("toy"), n_train=24, n_validation=6)


def _train(rundir, toy, want=(1, 2, 3), stop=None, tcfg=None, eval_every=1):
    data, fits, lut = toy
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # the same reduction order in both runs
    try:
        return train(rundir, data, fits, lut, want=want, mcfg=ModelConfig(**SIZES["tiny"]),
                     tcfg=TrainConfig(**(tcfg or TCFG)), progress=False, stop_after_epochs=stop,
                     eval_every=eval_every)
    finally:
        torch.set_num_threads(threads)


def _stage3_from(base, rundir, toy, tcfg):
    """Stage 3 trained in ``rundir`` on copies of the finished stages 1-2 of ``base``
    (the A/B recipe of docs/research/rebuilding.md)."""
    rundir.mkdir()
    for s in (1, 2):
        (rundir / checkpoint_path(base, s).name).write_bytes(checkpoint_path(base, s).read_bytes())
    return _train(rundir, toy, want=(3,), tcfg=tcfg)


def _states(rundir):
    return {s: load_checkpoint(checkpoint_path(rundir, s))["model"] for s in (1, 2, 3)}


def test_fits_are_read_matched_along_wavelength(toy, tmp_path):
    """dense (default): the components are matched along wavelength; the toy's media never cross in sigma_t,
    so that is the sigma_t order.  A copy of the fits with the components shuffled per (tone, wavelength)
    reads back identical (matching undoes it); "fitted" sorts each wavelength on its own."""
    data, fits, _ = toy
    split = load_split(data, "train", fits, k=3)
    assert len(split) == 24 and split.targets["sigma_t"].shape == (18, 3, 188)  # toy: 18 fitted, every 2nd λ
    assert (torch.diff(split.targets["sigma_t"], dim=1) >= 0).all()
    torch.testing.assert_close(split.targets["weight"].sum(1), torch.ones(18, 188), atol=1e-5, rtol=0)
    assert split.fitted.tolist() == list(range(18)) and split.target_index.tolist() == list(range(0, 376, 2))
    rng = np.random.default_rng(3)
    order = np.argsort(rng.random((18, 3, 188)), axis=1)
    with h5py.File(fits / "train_fits.h5", "r") as src, h5py.File(tmp_path / "train_fits.h5", "w") as dst:
        for name in ("index", "tone", "done", "wavelength_index"):
            dst[name] = src[name][:]
        for field in ("alpha", "g", "sigma_t", "weight"):
            dst[f"k3_{field}"] = np.take_along_axis(src[f"k3_{field}"][:], order, axis=1)
    shuffled = load_split(data, "train", tmp_path, k=3)
    for name, v in split.targets.items():
        torch.testing.assert_close(shuffled.targets[name], v, rtol=0, atol=0)
    old = load_split(data, "train", tmp_path, k=3, targets="fitted")
    torch.testing.assert_close(old.targets["sigma_t"], split.targets["sigma_t"], rtol=0, atol=0)


def test_fits_of_shards_are_aligned_by_index(toy, tmp_path):
    data, fits, _ = toy
    ref = load_split(data, "train", fits, k=2)
    # two shard files (`fit --shard i/2`) holding tones 5, 2 and 9, in another order; 9 not done yet
    shards = {"train_fits.shard0of2.h5": (np.array([5, 2]), [True, True]),
              "train_fits.shard1of2.h5": (np.array([9]), [False])}
    with h5py.File(fits / "train_fits.h5", "r") as src:
        for name, (index, done) in shards.items():
            with h5py.File(tmp_path / name, "w") as dst:
                dst["index"], dst["tone"], dst["done"] = index, src["tone"][:][index], np.array(done)
                dst["wavelength_index"] = src["wavelength_index"][:]
                for field in ("alpha", "g", "sigma_t", "weight"):
                    dst[f"k2_{field}"] = src[f"k2_{field}"][:][index]
    got = load_split(data, "train", tmp_path, k=2)
    assert len(got) == 24  # every simulated tone serves stages 1 and 2
    assert got.fitted.tolist() == [2, 5]  # rows 2 and 5 have targets (row 9 not done), in dataset order
    torch.testing.assert_close(got.tone[got.fitted], ref.tone[[2, 5]])
    for name in ("alpha", "sigma_t"):
        torch.testing.assert_close(got.targets[name], ref.targets[name][[2, 5]])


def test_staged_training_learns_freezes_and_resumes_exactly(toy, tmp_path):
    full = tmp_path / "full"
    rec = _train(full, toy)
    assert (full / "model.pt").is_file() and rec["metrics"]["validation"]["n_tones"] == 6
    states = _states(full)
    # each stage changes only its own networks (frozen predecessors and successors)
    for name, t in states[1].items():
        if name.startswith("dec_r."):
            torch.testing.assert_close(states[2][name], t, rtol=0, atol=0)
            torch.testing.assert_close(states[3][name], t, rtol=0, atol=0)
    for name, t in states[2].items():
        if name.startswith("enc."):
            torch.testing.assert_close(states[3][name], t, rtol=0, atol=0)
        if name.startswith("enc.net."):
            assert not torch.equal(states[1][name], t)  # stage 2 did train Enc
    # losses went down within each stage
    for s in (1, 2, 3):
        hist = load_checkpoint(checkpoint_path(full, s))["history"]
        assert hist[-1]["train_loss"] < hist[0]["train_loss"], (s, hist)
    assert hist[-1]["val_shape"] < hist[0]["val_shape"]  # stage 3 learns the profiles' shape

    # a run killed after 2 epochs of stage 1 and after 1 epoch of stage 3, then restarted, ends identical
    part = tmp_path / "part"
    _train(part, toy, stop=2)
    assert not load_checkpoint(checkpoint_path(part, 1))["done"]
    _train(part, toy, want=(1,), stop=None)
    _train(part, toy, want=(2,))
    _train(part, toy, want=(3,), stop=1)
    assert load_checkpoint(checkpoint_path(part, 3))["epoch"] == 0
    _train(part, toy, eval_every=3)  # validation is monitoring only: skipping it changes nothing trained
    resumed = _states(part)
    for s in (1, 2, 3):
        for name, t in states[s].items():
            torch.testing.assert_close(resumed[s][name], t, rtol=0, atol=0, msg=f"stage {s} {name}")
    h_full = load_checkpoint(checkpoint_path(full, 3))["history"]
    h_part = load_checkpoint(checkpoint_path(part, 3))["history"]
    assert [r["train_loss"] for r in h_full] == [r["train_loss"] for r in h_part]
    assert "val_loss" in h_part[0] and "val_loss" not in h_part[1] and h_part[2]["val_loss"] == h_full[2]["val_loss"]
    commands = json.loads((part / "run.json").read_text())
    assert commands["losses"]["stage3"]["done"]


def test_cli_refuses_inconsistent_runs(toy, tmp_path, capsys):
    data, fits, lut = toy
    base = ["--dataset", str(data), "--lut", str(lut), "--out", str(tmp_path / "r"), "--size", "tiny",
            "--batch", "8", "--synthetic", "16", "--no-progress", "--threads", "1", "--epochs"]
    assert train_main(base + ["1", "--stage", "3"]) == 2  # no --fits
    assert "needs --fits" in capsys.readouterr().err
    assert train_main(base + ["1", "--fits", str(fits), "--stage", "2"]) == 2  # stage 1 not trained
    assert "stage 1 is not finished" in capsys.readouterr().err
    assert train_main(base + ["1", "--stage", "1"]) == 0
    assert train_main(base + ["2", "--stage", "1"]) == 2  # another configuration in the same folder
    assert "epochs[stage 1] 1 -> 2" in capsys.readouterr().err
    rec = json.loads((tmp_path / "r" / "run.json").read_text())
    assert rec["commands"][0].startswith("python -m training train --dataset")
    assert rec["model"]["enc_hidden"] == SIZES["tiny"]["enc_hidden"]
    assert train_main(base + ["1", "--stage", "1", "--enc-hidden", "24"]) == 2  # another model in the folder
    assert "another model" in capsys.readouterr().err
    wide = [a if a != str(tmp_path / "r") else str(tmp_path / "w") for a in base]
    assert train_main(wide + ["1", "--stage", "1", "--enc-hidden", "24"]) == 0
    assert json.loads((tmp_path / "w" / "run.json").read_text())["model"]["enc_hidden"] == 24


def test_shape_loss_scores_the_rendered_mixture_against_the_profiles(toy):
    """The toy profiles are the K = 3 targets' rendered mixture: L_shape of the targets is ~0 at the
    fitted wavelengths, and a mixture with every sigma_t doubled (a profile twice as narrow) is far off."""
    from training.sim.lut_interp import LookupTables
    from training.train import losses as TL

    data, fits, lut_path = toy
    lut = LookupTables.load(lut_path, dtype=torch.float32)
    split = load_split(data, "train", fits, k=3, profiles=True, targets="fitted")
    assert split.shape_target.log_p.shape[:2] == (18, 188)
    t = split.targets
    assert float(TL.profile_shape_loss(lut, t, split.shape_target, None)) < 1e-3
    wider = {**t, "sigma_t": 2 * t["sigma_t"]}
    assert float(TL.profile_shape_loss(lut, wider, split.shape_target, None)) > 0.1
    # the decoder's (N, K, 376) outputs are read at the fitted wavelengths
    full = {k: torch.zeros(18, 3, 376).index_copy_(2, split.target_index, v) for k, v in t.items()}
    torch.testing.assert_close(TL.profile_shape_loss(lut, full, split.shape_target, split.target_index),
                               TL.profile_shape_loss(lut, t, split.shape_target, None))
    # dense: profiles at all 376 wavelengths; the targets interpolated there from every 2nd one render them
    # (the toy's alpha is linear in wavelength, its other parameters constant: interpolation is exact but
    # for the last wavelength, where the last fitted one is repeated)
    from training.train.spectral import interpolate, interpolation_matrix

    dense = load_split(data, "train", fits, k=3, profiles=True)
    assert dense.shape_target.log_p.shape[:2] == (18, 376) and dense.shape_index.tolist() == list(range(376))
    m = interpolation_matrix(dense.target_index.numpy(), 376)
    at_all = {k: interpolate(v, m) for k, v in dense.targets.items()}
    assert float(TL.profile_shape_loss(lut, at_all, dense.shape_target, dense.shape_index)) < 1e-3


def test_old_run_records_resume_with_the_behaviour_they_had(toy, tmp_path):
    """A run folder made before --exposure-prior existed trained stage 2 without it: resuming it with the
    old value works, asking for another value does not silently change it."""
    rec = _train(tmp_path / "r", toy, want=(1, 2), tcfg={**TCFG, "exposure_prior": 0.0})
    path = tmp_path / "r" / "run.json"
    old = json.loads(path.read_text())
    del old["train"]["exposure_prior"]
    path.write_text(json.dumps(old))
    _train(tmp_path / "r", toy, want=(1, 2), tcfg={**TCFG, "exposure_prior": 0.0})
    with pytest.raises(ValueError, match="exposure_prior 0.0 -> 0.01"):
        _train(tmp_path / "r", toy, want=(1, 2), tcfg={**TCFG, "exposure_prior": 0.01})
    assert rec["train"]["exposure_prior"] == 0.0


def test_a_stage_not_started_may_train_another_way(toy, tmp_path):
    """Stage 3's own options may differ from the record's while stage 3 has no checkpoint (a copy of stages
    1-2 trains it another way); once it has one, or for an option of a started stage, the folder refuses."""
    import shutil

    from training.train.run import PER_STAGE_OPTIONS, STAGE_OPTIONS

    names = [n for stage in STAGE_OPTIONS.values() for n in stage] + list(PER_STAGE_OPTIONS)
    assert sorted(names) == sorted(TrainConfig.__dataclass_fields__)  # every option belongs to one stage

    _train(tmp_path / "a", toy, want=(1, 2))
    (tmp_path / "b").mkdir()
    for name in ("stage1.pt", "stage2.pt", "run.json"):
        shutil.copy(tmp_path / "a" / name, tmp_path / "b" / name)
    other = {**TCFG, "encoder_share": 0.5, "epochs": [3, 3, 2]}
    with pytest.raises(ValueError, match=r"exposure_jitter 0.25 -> 1.0"):
        _train(tmp_path / "b", toy, want=(3,), tcfg={**other, "exposure_jitter": 1.0})
    rec = _train(tmp_path / "b", toy, want=(3,), tcfg=other)
    assert rec["train"]["encoder_share"] == 0.5 and rec["losses"]["stage3"]["epochs_done"] == 2
    for name, t in load_checkpoint(checkpoint_path(tmp_path / "a", 2))["model"].items():
        if name.startswith(("enc.", "dec_r.")):  # the copied stages are the ones stage 3 built on
            torch.testing.assert_close(load_checkpoint(checkpoint_path(tmp_path / "b", 3))["model"][name], t)
    with pytest.raises(ValueError, match=r"encoder_share 0.5 -> 0.0"):
        _train(tmp_path / "b", toy, want=(3,), tcfg={**other, "encoder_share": 0.0})


def test_exposure_prior_adds_the_mean_log_exposure():
    """colour_loss with a prior = the paper's colour L1 + prior * mean |ln gamma|, gamma = Y(A) / Y(A_hat)
    recomputed here from the luminance row of the sRGB matrix (Rec. 709: 0.2126, 0.7152, 0.0722)."""
    from training.train import losses as TL

    torch.manual_seed(0)
    model = SkinChain(ModelConfig(**SIZES["tiny"]))
    albedo = torch.tensor([[0.6, 0.4, 0.3], [0.05, 0.03, 0.02], [0.2, 0.2, 0.25]])
    with torch.no_grad():
        rgb = model.colour.rgb(model.dec_r(model.enc(albedo)))
        y = torch.tensor([0.2126, 0.7152, 0.0722])
        gamma = (albedo @ y) / (rgb @ y)
        plain = TL.colour_loss(model, albedo)
        torch.testing.assert_close(plain, (albedo - gamma[:, None] * rgb).abs().mean(), rtol=1e-4, atol=1e-7)
        with_prior = TL.colour_loss(model, albedo, exposure_prior=0.01)
        torch.testing.assert_close(with_prior - plain, 0.01 * gamma.log().abs().mean(), rtol=1e-3, atol=1e-7)


def test_weighted_param_loss_ignores_the_media_of_weightless_components():
    """L_param weighted by the target weights: equal weights give the plain loss; the alpha, g, sigma_t of a
    component whose target weight is 0 do not count, its weight does; a target of weight 1 counts K times."""
    from training.train.losses import param_loss

    torch.manual_seed(0)
    u, u_t = torch.rand(5, 4, 3, 7), torch.rand(5, 4, 3, 7)
    u_t[:, 3] = 1.0 / 3.0
    torch.testing.assert_close(param_loss(u, u_t, weighted=True), param_loss(u, u_t))
    u_t[:, 3] = torch.tensor([0.6, 0.4, 0.0])[None, :, None]
    moved = u.clone()
    moved[:, :3, 2] += 0.3  # the weightless component's media
    torch.testing.assert_close(param_loss(moved, u_t, weighted=True), param_loss(u, u_t, weighted=True))
    assert float(param_loss(moved, u_t)) > float(param_loss(u, u_t))
    moved_w = u.clone()
    moved_w[:, 3, 2] += 0.3  # its weight still counts
    assert float(param_loss(moved_w, u_t, weighted=True)) > float(param_loss(u, u_t, weighted=True))


def test_encoder_share_trains_dec_t_on_the_encoders_tones(toy, tmp_path):
    """--encoder-share: a share of each stage-3 batch is fed Enc(A_RGB) of the tone's albedo (no gradient to
    the frozen Enc) with the true tone's targets, and the validation reports the terms on that path too.
    Whether it helps is measured on real data in the gate (docs/research/training.md): on this toy Dec_T's
    output hardly depends on its input."""
    from training.train.stages import encoder_input, stage3

    data, fits, lut = toy
    split = load_split(data, "train", fits, k=3)
    torch.manual_seed(0)
    model = SkinChain(ModelConfig(**SIZES["tiny"]))
    a, p = split.albedo_rgb[:8], split.tone[:8]
    assert encoder_input(model, a, p, 0.0) is p
    mixed = encoder_input(model, a, p, 0.5)
    with torch.no_grad():
        torch.testing.assert_close(mixed[:4], model.enc(a[:4].clamp(0.0, 1.0)))
    torch.testing.assert_close(mixed[4:], p[4:], rtol=0, atol=0)
    assert mixed.grad_fn is None  # the frozen encoder gets no gradient

    tcfg = dict(TCFG, shape_weight=0.0)
    base = tmp_path / "base"
    _train(base, toy, want=(1, 2), tcfg=tcfg)
    runs = {}
    for share in (0.0, 1.0):
        runs[share] = _stage3_from(base, tmp_path / f"share{share}", toy, dict(tcfg, encoder_share=share))
    assert runs[1.0]["train"]["encoder_share"] == 1.0 and runs[0.0]["train"]["encoder_share"] == 0.0
    last = {s: r["losses"]["stage3"] for s, r in runs.items()}
    assert "val_refl_rgb" in last[1.0] and "val_refl_rgb" not in last[0.0]
    enc2 = {k: v for k, v in load_checkpoint(checkpoint_path(base, 2))["model"].items() if k.startswith("enc.")}
    enc3 = load_checkpoint(checkpoint_path(tmp_path / "share1.0", 3))["model"]
    for k, v in enc2.items():
        torch.testing.assert_close(enc3[k], v, rtol=0, atol=0)
    assert all(np.isfinite(r["metrics"]["train"]["inversion_mixture_vs_mc_delta_e76"]["mean"]) for r in runs.values())

    # a stage-3 step with share 1 scores Dec_T on Enc(A_RGB), with the true tone's targets (not on the true p)
    lut_t = LookupTables.load(lut, dtype=torch.float32)
    val = load_split(data, "validation", None, k=3)
    idx = torch.arange(4)
    rows = split.fitted[idx]
    targets = {k: v[idx] for k, v in split.targets.items()}
    losses = {}
    for name, q in (("rgb", model.enc(split.albedo_rgb[rows].clamp(0.0, 1.0))), ("true", split.tone[rows])):
        with torch.no_grad():
            losses[name] = float(train_losses.stage3_losses(model, lut_t, q, split.R_d[rows], targets,
                                                            split.target_index, weighted=True)["loss"])
    spec = stage3(model, lut_t, split, val, 1, 4, 1e-3, dense=False, encoder_share=1.0)
    with torch.no_grad():
        step = float(spec.step(idx)["loss"])
    assert step == pytest.approx(losses["rgb"], rel=1e-6) and abs(losses["rgb"] - losses["true"]) > 1e-4, losses


def test_log_reflectance_loss_weighs_dark_and_light_tones_alike():
    """--refl-loss log: mean |ln(R_hat + f) - ln(R + f)|.  Twice too bright costs ln 2 on a dark tone (R 0.01)
    as on a light one (0.5), up to the floor f; the paper's absolute form charges the light tone 50x more."""
    target = torch.tensor([[0.01, 0.01], [0.5, 0.5]])
    pred = 2 * target
    f = train_losses.LOG_REFL_FLOOR
    log = [float(train_losses.reflectance_loss(pred[i:i + 1], target[i:i + 1], "log")) for i in (0, 1)]
    assert log[0] == pytest.approx(np.log((0.02 + f) / (0.01 + f)), rel=1e-6)
    assert log[1] == pytest.approx(np.log((1.0 + f) / (0.5 + f)), rel=1e-6)
    assert abs(log[0] - log[1]) < 0.01 * np.log(2)
    absolute = [float(train_losses.reflectance_loss(pred[i:i + 1], target[i:i + 1])) for i in (0, 1)]
    assert absolute == pytest.approx([0.01, 0.5])
    zero = torch.zeros(1, 2)  # a black target and prediction: finite, zero
    assert float(train_losses.reflectance_loss(zero, zero, "log")) == 0.0
    with pytest.raises(ValueError, match="absolute"):
        train_losses.reflectance_loss(pred, target, "squared")


def test_stage3_trains_with_the_log_reflectance_loss(toy, tmp_path):
    """A run with refl_loss="log" records it, and its stage 3 lowers the log reflectance error."""
    rec = _train(tmp_path / "r", toy, tcfg={**TCFG, "refl_loss": "log", "epochs": [3, 3, 6]})
    assert rec["train"]["refl_loss"] == "log"
    h = load_checkpoint(checkpoint_path(tmp_path / "r", 3))["history"]
    assert h[-1]["train_refl"] < h[0]["train_refl"]
    with pytest.raises(ValueError, match="refl_loss"):
        _train(tmp_path / "bad", toy, tcfg={**TCFG, "refl_loss": "l2"})


def test_smooth_weight_sets_how_much_dec_t_may_change_per_wavelength_step(toy, tmp_path):
    """--smooth-weight S: stage 3 adds S x L_smooth, the mean |u(l + 1) - u(l)| of Dec_T's normalised outputs
    (checked against the differences taken here).  From the same stages 1-2, a stage 3 with S = 50 ends with
    smoother outputs than one with the paper's 0.5; the weight is recorded, a folder holding a stage 3 refuses
    another, and a negative one is refused."""
    data, fits, lut = toy
    tcfg = dict(TCFG, shape_weight=0.0, epochs=[3, 3, 8])
    base = tmp_path / "base"
    _train(base, toy, want=(1, 2), tcfg=tcfg)
    split = load_split(data, "train", fits, k=3)
    lut_t = LookupTables.load(lut, dtype=torch.float32)
    model = SkinChain(ModelConfig(**SIZES["tiny"]))
    model.load_state_dict(load_checkpoint(checkpoint_path(base, 2))["model"])
    idx = torch.arange(4)
    rows, targets = split.fitted[idx], {k: v[idx] for k, v in split.targets.items()}
    with torch.no_grad():
        u = model.dec_t(split.tone[rows], model.dec_r(split.tone[rows]))["u"]  # (N, 4, K, W)
        by = {s: train_losses.stage3_losses(model, lut_t, split.tone[rows], split.R_d[rows], targets,
                                            split.target_index, lambda_smooth=s) for s in (0.0, 3.0)}
    smooth = float(np.abs(np.diff(u.numpy(), axis=-1)).mean())
    assert float(by[3.0]["smooth"]) == pytest.approx(smooth, rel=1e-5)
    assert float(by[3.0]["loss"] - by[0.0]["loss"]) == pytest.approx(3.0 * smooth, rel=1e-4)

    runs = {}
    for weight in (0.5, 50.0):
        runs[weight] = _stage3_from(base, tmp_path / f"smooth{weight}", toy, dict(tcfg, smooth_weight=weight))
        assert runs[weight]["train"]["smooth_weight"] == weight
    assert runs[50.0]["losses"]["stage3"]["train_smooth"] < 0.5 * runs[0.5]["losses"]["stage3"]["train_smooth"]
    with pytest.raises(ValueError, match="smooth_weight 50.0 -> 5.0"):
        _train(tmp_path / "smooth50.0", toy, want=(3,), tcfg=dict(tcfg, smooth_weight=5.0))
    with pytest.raises(ValueError, match="smooth_weight must be"):
        _train(tmp_path / "negative", toy, tcfg=dict(tcfg, smooth_weight=-1.0))


def test_balance_draws_the_tones_of_sparse_corners_more_often():
    """The inverse-density weights: 400 tones crowded around medium skin and 4 alone in a corner of the box.
    With balance 1 each lone tone is drawn about CAP times as often as a crowded one (the 8th neighbour of a
    lone tone is far, its inverse-density weight hits the cap); with balance 0 every tone alike; the draws of
    one epoch follow the probabilities and are the same for the same seed."""
    rng = np.random.default_rng(3)
    lo = np.array([PARAM_RANGES[n][0] for n in PARAM_NAMES])
    hi = np.array([PARAM_RANGES[n][1] for n in PARAM_NAMES])
    crowd = np.array([0.03, 0.02, 0.01, 0.75, 0.75]) * (1 + 0.05 * rng.standard_normal((400, 5)))
    lone = np.stack([lo + 0.02 * (hi - lo) * rng.random(5) for _ in range(4)])  # near the lower corner
    tones = np.concatenate([crowd, lone])
    uniform = sampling_probabilities(tones, 0.0)
    assert np.allclose(uniform, 1 / len(tones))
    p = sampling_probabilities(tones, 1.0)
    assert p.sum() == pytest.approx(1.0)
    assert np.allclose(p[-4:], p.max())  # every lone tone at the cap
    assert p[-4:].mean() / np.median(p) == pytest.approx(CAP, rel=1e-6)
    probs = torch.as_tensor(p)
    a, b = (epoch_order(len(tones), 0, 3, 7, torch.device("cpu"), probs) for _ in range(2))
    assert torch.equal(a, b) and len(a) == len(tones)
    draws = torch.cat([epoch_order(len(tones), 0, 3, e, torch.device("cpu"), probs) for e in range(50)])
    lone_share = float((draws >= 400).double().mean())
    assert lone_share == pytest.approx(p[-4:].sum(), rel=0.2)
    with pytest.raises(ValueError, match="balance"):
        sampling_probabilities(tones, 1.5)


def test_stage3_trains_with_balanced_tone_draws(toy, tmp_path):
    """--balance B: stage 3 draws its tones by the balanced probabilities (recorded in the run), still learns,
    and a folder holding a stage 3 with another balance refuses it."""
    tcfg = dict(TCFG, shape_weight=0.0, epochs=[3, 3, 6], balance=1.0)
    rec = _train(tmp_path / "r", toy, tcfg=tcfg)
    assert rec["train"]["balance"] == 1.0
    h = load_checkpoint(checkpoint_path(tmp_path / "r", 3))["history"]
    assert h[-1]["train_loss"] < h[0]["train_loss"]
    with pytest.raises(ValueError, match="balance 1.0 -> 0.5"):
        _train(tmp_path / "r", toy, want=(3,), tcfg=dict(tcfg, balance=0.5))
    with pytest.raises(ValueError, match="balance must"):
        _train(tmp_path / "bad", toy, tcfg=dict(tcfg, balance=-0.1))


def test_a_run_killed_in_a_stage_with_new_options_resumes(toy, tmp_path):
    """The A/B recipe (a copy of stages 1-2 and run.json) trains stage 3 with options of its own; the process is
    killed (SIGKILL) after stage 3's first checkpoint.  Running the same command again resumes it, because the
    folder's record names the new options before the stage starts (were it written only at the end, the
    resume would be refused: "balance 0.0 -> 1.0")."""
    import shutil
    import signal
    import subprocess
    import sys
    import time

    data, fits, lut = toy
    _train(tmp_path / "a", toy, want=(1, 2))
    b = tmp_path / "b"
    b.mkdir()
    for name in ("stage1.pt", "stage2.pt", "run.json"):
        shutil.copy(tmp_path / "a" / name, b / name)
    args = ["--dataset", str(data), "--fits", str(fits), "--lut", str(lut), "--out", str(b), "--stage", "3",
            "--size", "tiny", "--epochs", "3,3,100000", "--batch", "8,64,8", "--lr", "3e-3,3e-3,1e-3",
            "--synthetic", "256", "--balance", "1", "--threads", "1", "--no-progress"]
    proc = subprocess.Popen([sys.executable, "-m", "training", "train", *args])
    try:
        deadline = time.monotonic() + 300
        while not checkpoint_path(b, 3).exists():
            assert proc.poll() is None and time.monotonic() < deadline, "stage 3 never wrote a checkpoint"
            time.sleep(0.2)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert json.loads((b / "run.json").read_text())["train"]["balance"] == 1.0
    same = TrainConfig(epochs=[3, 3, 100000], batch=[8, 64, 8], lr=[3e-3, 3e-3, 1e-3], synthetic=256, balance=1.0)
    rec = train(b, data, fits, lut, want=(3,), mcfg=ModelConfig(**SIZES["tiny"]), tcfg=same, progress=False,
                stop_after_epochs=1)
    assert rec["losses"]["stage3"]["epochs_done"] >= 2  # the killed run's epochs, then one more: resumed
    with pytest.raises(ValueError, match=r"balance 1.0 -> 0.5"):
        train(b, data, fits, lut, want=(3,), mcfg=ModelConfig(**SIZES["tiny"]),
              tcfg=TrainConfig(**{**asdict(same), "balance": 0.5}), progress=False, stop_after_epochs=1)
