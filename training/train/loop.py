"""One training stage: mini-batch Adam over epochs, checkpoints, exact resume, progress bar.

Reproducibility: the batch order of epoch e is a permutation drawn from a generator seeded with
(seed, stage, e), and the learning rate of epoch e is a function of e (cosine from ``lr`` to
``LR_FLOOR * lr``).  A checkpoint holds the whole model, the optimizer state, the last finished
epoch and the loss history, written atomically (temporary file + rename).  Resuming therefore
replays exactly the remaining epochs of an uninterrupted run (bitwise on the same machine and thread
count).  Parameters outside the stage are frozen (requires_grad False) and never change.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn
from tqdm import tqdm

#: Final learning rate of the cosine schedule, as a fraction of the initial one.
LR_FLOOR: float = 0.05


@dataclass
class StageSpec:
    """What one stage trains and how.

    ``step(idx)``: losses (dict with "loss" to minimise plus parts to report) of the items ``idx``
    (a LongTensor of indices into the stage's training items).  ``evaluate()``: validation metrics
    (floats) at the end of an epoch.
    """

    stage: int
    name: str
    trainable: list[nn.Module]
    n_items: int
    batch_size: int
    epochs: int
    lr: float
    step: Callable[[torch.Tensor], dict[str, torch.Tensor]]
    evaluate: Callable[[], dict[str, float]]
    #: (n_items,) probabilities of drawing each item (``training.train.balance``); None: a permutation per epoch
    item_probabilities: torch.Tensor | None = None


def checkpoint_path(rundir: Path, stage: int) -> Path:
    return Path(rundir) / f"stage{stage}.pt"


def save_atomic(obj: dict, path: Path) -> None:
    """torch.save to ``path`` via a temporary file and a rename (a kill never leaves half a file)."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def load_checkpoint(path: Path) -> dict:
    return torch.load(path, map_location="cpu", weights_only=False)


def cosine_lr(lr: float, epoch: int, epochs: int) -> float:
    """Learning rate of ``epoch`` (0-based): cosine from lr to LR_FLOOR * lr over ``epochs``."""
    t = epoch / max(epochs - 1, 1)
    return lr * (LR_FLOOR + (1 - LR_FLOOR) * 0.5 * (1 + math.cos(math.pi * t)))


def epoch_order(n: int, seed: int, stage: int, epoch: int, device: torch.device,
                probabilities: torch.Tensor | None = None) -> torch.Tensor:
    """The items (n,) of one epoch, drawn from a generator seeded by (seed, stage, epoch): a permutation, or with
    ``probabilities`` (n,) n draws with replacement (``training.train.balance``)."""
    gen = torch.Generator().manual_seed(int(seed) * 1_000_003 + stage * 10_007 + epoch)
    if probabilities is None:
        return torch.randperm(n, generator=gen).to(device)
    return torch.multinomial(probabilities.cpu().double(), n, replacement=True, generator=gen).to(device)


def freeze_all_but(model: nn.Module, trainable: list[nn.Module]) -> list[nn.Parameter]:
    for p in model.parameters():
        p.requires_grad_(False)
    params: list[nn.Parameter] = []
    for m in trainable:
        for p in m.parameters():
            p.requires_grad_(True)
            params.append(p)
    return params


def run_stage(spec: StageSpec, model: nn.Module, rundir: Path, *, seed: int, device: torch.device,
              progress: bool = True, checkpoint_interval_s: float = 0.0,
              stop_after_epochs: int | None = None, eval_every: int = 1) -> list[dict]:
    """Train one stage (resuming from its checkpoint if present); returns the per-epoch history.

    ``checkpoint_interval_s``: write a checkpoint after an epoch only if this many seconds passed
    since the last one (0: every epoch); the last epoch is always written.  ``stop_after_epochs``:
    return after that many epochs of this call (used by the resume test to simulate a kill).
    ``eval_every``: run ``spec.evaluate`` (monitoring only: the model of the last epoch is the stage's result)
    after every n-th epoch and the last one; the other epochs' rows hold the training terms only.
    """
    if eval_every < 1:
        raise ValueError(f"eval_every must be >= 1, got {eval_every}")
    ckpt = checkpoint_path(rundir, spec.stage)
    params = freeze_all_but(model, spec.trainable)
    opt = torch.optim.Adam(params, lr=spec.lr)
    start, history = 0, []
    if ckpt.exists():
        state = load_checkpoint(ckpt)
        model.load_state_dict(state["model"])
        history = state["history"]
        if state["done"]:
            freeze_all_but(model, [])
            return history
        opt.load_state_dict(state["optim"])
        start = state["epoch"] + 1
    n_batches = math.ceil(spec.n_items / spec.batch_size)
    bar = tqdm(total=(spec.epochs - start) * n_batches, desc=f"stage {spec.stage} {spec.name}", disable=not progress)
    last_save, ran = time.monotonic(), 0
    for epoch in range(start, spec.epochs):
        for group in opt.param_groups:
            group["lr"] = cosine_lr(spec.lr, epoch, spec.epochs)
        for m in spec.trainable:
            m.train()
        order = epoch_order(spec.n_items, seed, spec.stage, epoch, device, spec.item_probabilities)
        sums: dict[str, float] = {}
        for b in range(n_batches):
            idx = order[b * spec.batch_size : (b + 1) * spec.batch_size]
            opt.zero_grad(set_to_none=True)
            losses = spec.step(idx)
            if not torch.isfinite(losses["loss"]):
                raise FloatingPointError(f"stage {spec.stage}: non-finite loss at epoch {epoch}, batch {b}")
            losses["loss"].backward()
            opt.step()
            for k, v in losses.items():
                sums[k] = sums.get(k, 0.0) + float(v.detach()) * len(idx)
            bar.update(1)
        row = {"epoch": epoch, "lr": opt.param_groups[0]["lr"]}
        row.update({f"train_{k}": v / spec.n_items for k, v in sums.items()})
        if (epoch + 1) % eval_every == 0 or epoch == spec.epochs - 1:
            with torch.no_grad():
                row.update({f"val_{k}": float(v) for k, v in spec.evaluate().items()})
        history.append(row)
        bar.set_postfix({k: f"{v:.4g}" for k, v in row.items() if k not in ("epoch", "lr")})
        last = epoch == spec.epochs - 1
        ran += 1
        stopping = stop_after_epochs is not None and ran >= stop_after_epochs
        if last or stopping or time.monotonic() - last_save >= checkpoint_interval_s:
            save_atomic({"model": model.state_dict(), "optim": opt.state_dict(), "epoch": epoch,
                         "history": history, "done": last, "stage": spec.stage}, ckpt)
            last_save = time.monotonic()
        if stopping and not last:
            break
    bar.close()
    freeze_all_but(model, [])
    return history
