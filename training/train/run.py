"""Orchestration of the staged training in a run folder, resumable at every level.

RUNDIR holds:
  run.json       the model and training configuration, the inputs (paths, LUT SHA-256, dataset sizes
                 and photons), every command that trained into it, the last losses of each stage and
                 the validation metrics;
  stage{1,2,3}.pt  each stage's checkpoint (whole model + optimizer + history); a finished stage is
                 marked done and is never trained again;
  model.pt       the final model (config + state dict), written when stage 3 finishes.

Running the same command again continues where it stopped.  Asking for a later stage loads the
earlier stages' finished checkpoints (they must exist).  A different model, LUT, or option of a stage
that RUNDIR already holds a checkpoint of is refused (use another folder); a stage not yet started
may take other options of its own (``STAGE_OPTIONS``): a copy of ``stage1.pt``, ``stage2.pt`` and
``run.json`` in a new folder trains stage 3 another way on the same stages 1-2.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import torch

from exporters.maps import sha256_file
from training.model.chain import SkinChain
from training.model.config import ModelConfig, g_range_for_lut
from training.sim.lut_interp import LookupTables
from training.train import stages
from training.train.data import TARGET_MODES, SplitData, fits_files, load_split
from training.train.evaluate import evaluate_split
from training.train.loop import checkpoint_path, load_checkpoint, run_stage, save_atomic
from training.train.losses import LAMBDA_SMOOTH, REFL_LOSSES, SHAPE_BIN_STRIDE, VALIDATION_SHAPE_EVERY


@dataclass
class TrainConfig:
    """Hyper-parameters per stage (index 0, 1, 2 = stage 1, 2, 3) and of stage 2's synthetic albedos."""

    seed: int = 0
    epochs: list[int] = field(default_factory=lambda: [300, 100, 300])
    batch: list[int] = field(default_factory=lambda: [256, 256, 64])
    lr: list[float] = field(default_factory=lambda: [1e-3, 1e-3, 3e-4])
    synthetic: int = 20_000
    exposure_jitter: float = 0.25
    exposure_prior: float = 0.0
    shape_weight: float = 1.0
    #: stage 3: "dense" = targets matched along wavelength and compared at all 376 (interpolated),
    #: L_shape at all 376; "fitted" = sorted by sigma_t, at the fitted wavelengths only
    targets: str = "dense"
    #: stage 3: L_param's alpha, g, sigma_t terms weighted by the target weights (losses.param_loss)
    weighted_param: bool = True
    #: Ablations of the paper's §5 (``python -m training ablations``); the defaults are the paper's method.
    #: stage 3: weight of L_refl (paper 15; 0 = "parameter regression alone")
    lambda_r: float = 15.0
    #: stage 3: the slab-depth factor (1 - exp(-C sigma_t c(lambda))) in L_refl (paper eq. slab_factor)
    slab_factor: bool = True
    #: the earlier stages' Dec_R trains along in stages 2 and 3 (the paper: frozen)
    unfreeze: bool = False
    #: stages 2-3 learn from every n-th training tone only (1 = all; 20 = the paper's "20x less data")
    data_every: int = 1
    #: stage 3 (ours): share of each batch whose Dec_T input is the frozen encoder's answer to the
    #: tone's RGB albedo, p = Enc(A_RGB), instead of the true p (0 = the paper; ``stages.encoder_input``)
    encoder_share: float = 0.0
    #: stage 3: L_refl as the paper's mean |R_hat - R_MC| ("absolute") or ours, mean |ln R_hat - ln R_MC|
    #: ("log", ``losses.REFL_LOSSES``), which weighs a dark tone's colour as the eye (L*) does
    refl_loss: str = "absolute"
    #: stage 3: weight of L_smooth, mean |u(l + 1) - u(l)| (the paper's lambda_smooth = 0.5; ``losses.LAMBDA_SMOOTH``)
    smooth_weight: float = LAMBDA_SMOOTH
    #: stage 3 (ours): share of the tone draws by inverse local density in the parameter box, so that
    #: sparse corners are learnt more often (``training.train.balance``; 0 = every fitted tone once per epoch)
    balance: float = 0.0


#: What a run record made before an option existed trained with (its behaviour then).
LEGACY_TRAIN: dict = {"exposure_prior": 0.0, "shape_weight": 0.0, "targets": "fitted", "weighted_param": False,
                     "lambda_r": 15.0, "slab_factor": True, "unfreeze": False, "data_every": 1,
                     "encoder_share": 0.0, "refl_loss": "absolute", "smooth_weight": LAMBDA_SMOOTH, "balance": 0.0}


#: The training options each stage adds to those of the stages before it (a stage depends on all of them);
#: ``epochs``, ``batch``, ``lr`` have one entry per stage.  Every ``TrainConfig`` field is listed here once.
STAGE_OPTIONS: dict[int, tuple[str, ...]] = {
    1: ("seed",),
    2: ("synthetic", "exposure_jitter", "exposure_prior", "unfreeze", "data_every"),
    3: ("shape_weight", "targets", "weighted_param", "lambda_r", "slab_factor", "encoder_share", "refl_loss",
        "smooth_weight", "balance"),
}
PER_STAGE_OPTIONS = ("epochs", "batch", "lr")


def stage_options(train: dict, stage: int) -> dict:
    """The options (``asdict(TrainConfig)`` values) that stages 1..``stage`` were trained with."""
    out = {}
    for s in range(1, stage + 1):
        out.update({name: train[name] for name in STAGE_OPTIONS[s]})
        out.update({f"{name}[stage {s}]": train[name][s - 1] for name in PER_STAGE_OPTIONS})
    return out


def _write_json(path: Path, obj: dict) -> None:
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(obj, indent=2))
    os.replace(tmp, path)


def _started_stage(rundir: Path) -> int:
    """The last stage with a checkpoint in ``rundir`` (0: none)."""
    return max((s for s in (1, 2, 3) if checkpoint_path(rundir, s).exists()), default=0)


def _check_record(rundir: Path, record: dict) -> dict | None:
    """The run record already in ``rundir`` (None if none), after checking that ``record`` may train there:
    same model and LUT, same options for every stage that has a checkpoint (ValueError naming the difference)."""
    path = rundir / "run.json"
    if not path.exists():
        return None
    old = json.loads(path.read_text())
    old["train"] = {**LEGACY_TRAIN, **old.get("train", {})}  # runs made before an option existed
    if "model" in old:  # runs made before a model option existed: its default for them
        old["model"] = ModelConfig.from_dict(old["model"]).to_dict()
    for key in ("model", "lut_sha256"):
        if old.get(key) != record.get(key):
            raise ValueError(f"{rundir} was trained with another {key} ({old.get(key)} != {record.get(key)}): "
                             "use another --out folder")
    started = _started_stage(rundir)
    before, now = stage_options(old["train"], started), stage_options(record["train"], started)
    changed = {name: (before[name], now[name]) for name in before if before[name] != now[name]}
    if changed:
        what = ", ".join(f"{name} {a!r} -> {b!r}" for name, (a, b) in changed.items())
        raise ValueError(f"{rundir} holds stages 1-{started} trained with other options ({what}): use another "
                         "--out folder (a copy of the finished stages' checkpoints and run.json trains the next "
                         "stage another way)")
    return old


def _merge_record(rundir: Path, old: dict | None, record: dict) -> dict:
    """The run record to write: ``record`` in a new folder, else the folder's ``old`` one (``_check_record``'s
    answer) continued with ``record``'s options, command and fits."""
    if old is None:
        _write_json(rundir / "run.json", record)
        return record
    old["train"] = record["train"]  # equal for the stages started; the stages to come train with these
    old["commands"] = old.get("commands", []) + record["commands"]
    if record.get("fits") is not None:  # stage 3 loads the fits that stages 1-2 did not: count what it learns from
        old["fits"], old["dataset_info"] = record["fits"], record["dataset_info"]
    # written before training: a run killed in a stage it started here must resume with these options
    _write_json(rundir / "run.json", old)
    return old


def load_model(path: Path, device: str | torch.device = "cpu") -> SkinChain:
    """The final model of a run (``RUNDIR/model.pt``) in eval mode with frozen parameters."""
    state = torch.load(path, map_location="cpu", weights_only=False)
    model = SkinChain(ModelConfig.from_dict(state["config"]))
    model.load_state_dict(state["state_dict"])
    for p in model.parameters():
        p.requires_grad_(False)
    return model.to(device).eval()


def train(rundir: Path, dataset: Path, fits: Path | None, lut_path: Path, *, want: tuple[int, ...] = (1, 2, 3),
          mcfg: ModelConfig | None = None, tcfg: TrainConfig | None = None, device: str = "cpu",
          progress: bool = True, checkpoint_interval_s: float = 0.0, command: str = "",
          stop_after_epochs: int | None = None, eval_every: int = 1) -> dict:
    """Train the requested stages into ``rundir``; returns the run record (also written to run.json).
    ``eval_every``: validation metrics after every n-th epoch and the last (``loop.run_stage``)."""
    tcfg = tcfg or TrainConfig()
    dev = torch.device(device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError("--device cuda: no CUDA device available")
    lut = LookupTables.load(lut_path, dtype=torch.float32, device=dev)
    mcfg = mcfg or ModelConfig()
    mcfg.g_range = g_range_for_lut(*lut.g_range)
    mcfg = ModelConfig.from_dict(mcfg.to_dict())  # re-validate
    rundir = Path(rundir)
    rundir.mkdir(parents=True, exist_ok=True)
    need_fits = 3 in want
    profiles = need_fits and tcfg.shape_weight > 0
    if tcfg.targets not in TARGET_MODES:
        raise ValueError(f"targets must be one of {TARGET_MODES}, got {tcfg.targets!r}")
    if tcfg.data_every < 1 or tcfg.lambda_r < 0:
        raise ValueError(f"data_every must be >= 1 and lambda_r >= 0, got {tcfg.data_every}, {tcfg.lambda_r}")
    if tcfg.refl_loss not in REFL_LOSSES:
        raise ValueError(f"refl_loss must be one of {REFL_LOSSES}, got {tcfg.refl_loss!r}")
    if not 0.0 <= tcfg.encoder_share <= 1.0:
        raise ValueError(f"encoder_share must lie in [0, 1], got {tcfg.encoder_share}")
    if not (tcfg.smooth_weight >= 0 and math.isfinite(tcfg.smooth_weight)):
        raise ValueError(f"smooth_weight must be a finite number >= 0, got {tcfg.smooth_weight}")
    if not 0.0 <= tcfg.balance <= 1.0:
        raise ValueError(f"balance must lie in [0, 1], got {tcfg.balance}")
    lut_sha = sha256_file(lut_path)
    old_record = _check_record(rundir, {"model": mcfg.to_dict(), "train": asdict(tcfg), "lut_sha256": lut_sha})
    train_data = load_split(dataset, "train", fits if need_fits else None, mcfg.k, profiles, tcfg.targets,
                            SHAPE_BIN_STRIDE).to(dev)  # (checked first: loading takes minutes)
    val_fits = fits if (need_fits and fits is not None and fits_files(fits, "validation")) else None
    val_data = load_split(dataset, "validation", val_fits, mcfg.k, profiles and val_fits is not None,
                          tcfg.targets, shape_every=VALIDATION_SHAPE_EVERY).to(dev)
    # absolute as typed, links kept: data/ may link outside the checkout, and the card records data/laptop
    record = {
        "model": mcfg.to_dict(), "train": asdict(tcfg), "lut": os.path.abspath(lut_path),
        "lut_sha256": lut_sha,
        "dataset": os.path.abspath(dataset),
        "fits": None if fits is None or not need_fits else os.path.abspath(fits),
        "dataset_info": {"n_train": len(train_data), "n_validation": len(val_data), "photons": train_data.photons,
                         "n_train_fitted": 0 if train_data.fitted is None else len(train_data.fitted),
                         "n_validation_fitted": 0 if val_data.fitted is None else len(val_data.fitted),
                         "fitted_wavelengths": 0 if train_data.target_index is None else len(train_data.target_index)},
        "commands": [command] if command else [],
    }
    record = _merge_record(rundir, old_record, record)
    torch.manual_seed(tcfg.seed)
    model = SkinChain(mcfg).to(dev)
    common = {"seed": tcfg.seed, "device": dev, "progress": progress, "checkpoint_interval_s": checkpoint_interval_s,
              "stop_after_epochs": stop_after_epochs, "eval_every": eval_every}
    finished = True
    for s in (1, 2, 3):
        ck = checkpoint_path(rundir, s)
        if s not in want:
            if s < max(want):
                if not ck.exists() or not load_checkpoint(ck)["done"]:
                    raise ValueError(f"stage {s} is not finished in {rundir}: train it first (--stage {s})")
                model.load_state_dict(load_checkpoint(ck)["model"])
            continue
        spec = _spec(s, model, lut, train_data, val_data, tcfg)
        history = run_stage(spec, model, rundir, **common)
        done = bool(load_checkpoint(ck)["done"])
        record.setdefault("losses", {})[f"stage{s}"] = {**history[-1], "epochs_done": len(history), "done": done}
        if not done:
            finished = False
            break
    if finished and 3 in want:
        model.eval()
        save_atomic({"config": mcfg.to_dict(), "state_dict": model.state_dict()}, rundir / "model.pt")
        record["slab_depth_cm"] = {"min": float(model.slab.depth().min()), "max": float(model.slab.depth().max())}
        record["metrics"] = {"validation": evaluate_split(model, val_data, lut),
                             "train": evaluate_split(model, train_data, lut)}
    _write_json(rundir / "run.json", record)
    return record


def _spec(stage: int, model: SkinChain, lut: LookupTables, train_data: SplitData, val_data: SplitData,
          t: TrainConfig):
    i = stage - 1
    if stage == 1:
        return stages.stage1(model, train_data, val_data, t.epochs[i], t.batch[i], t.lr[i])
    train_data = train_data.every(t.data_every)  # stages 2-3 (the "less data" ablation); Dec_R saw all
    if stage == 2:
        return stages.stage2(model, train_data, val_data, t.epochs[i], t.batch[i], t.lr[i], t.synthetic,
                             t.exposure_jitter, t.seed, t.exposure_prior, t.unfreeze)
    return stages.stage3(model, lut, train_data, val_data, t.epochs[i], t.batch[i], t.lr[i], t.shape_weight,
                         t.targets == "dense", t.weighted_param, t.lambda_r, t.slab_factor, t.unfreeze,
                         t.encoder_share, t.refl_loss, t.smooth_weight, t.balance)
