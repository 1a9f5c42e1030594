"""Build one dataset split per shard, resumably, and merge shards (``python -m training dataset``)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
from tqdm import tqdm

from exporters.colorimetry import spectrum_to_linear_srgb
from training.data import store
from training.data.presets import Preset
from training.data.sampling import training_tones, validation_tones

#: simulate(tones (B, 5), photons, seed, device) -> {"R_d", "R_d_stderr": (B, W),
#:                                                    "profile", "profile_stderr": (B, W, 512)}
SimulateFn = Callable[[np.ndarray, int, int, str], dict[str, np.ndarray]]
SPLITS = ("train", "validation")


def split_tones(preset: Preset, split: str) -> tuple[np.ndarray, int]:
    """All tones of a split and the seed that drew them."""
    if split == "train":
        return training_tones(preset.n_train, preset.train_seed), preset.train_seed
    if split == "validation":
        return validation_tones(preset.n_validation, preset.validation_seed), preset.validation_seed
    raise ValueError(f"unknown split {split!r}; use one of {SPLITS}")


def shard_path(out: Path, split: str, shard: tuple[int, int]) -> Path:
    i, n = shard
    return out / (f"{split}.h5" if n == 1 else f"{split}.shard{i}of{n}.h5")


def open_split(preset: Preset, split: str, out: Path, method: str, shard: tuple[int, int]
               ) -> tuple[Path, np.ndarray, np.ndarray, int]:
    """Create (or check, to resume) this shard's file of ``split``; returns (path, tones of the split,
    positions of the shard's tones in it, the split's seed)."""
    tones, seed = split_tones(preset, split)
    i, n = shard
    index = np.arange(len(tones))[i::n]  # round-robin: every shard gets the same mix of tones
    attrs = {"preset": preset.name, "split": split, "photons": preset.photons, "seed": seed,
             "shard": f"{i}/{n}", "method": method, "n_total": len(tones), "created_by": "python -m training dataset"}
    path = shard_path(out, split, shard)
    out.mkdir(parents=True, exist_ok=True)
    if path.exists():
        store.check_matches(path, tones[index], attrs)
    else:
        store.create(path, tones[index], index, attrs)
    return path, tones, index, seed


def simulate_chunk(simulate: SimulateFn, tones: np.ndarray, photons: int, seed: int, device: str,
                   *after) -> tuple[dict[str, np.ndarray], float]:
    """One chunk of tones (B, 5): the stored fields (``store.SIMULATED``) and the seconds it took.

    The chunk's seed derives from its first tone's position in the split: results do not depend on
    sharding, resuming or where the chunk runs.  ``after``: what a cluster task waited for (the split's
    walk chunks), unused.
    """
    if hasattr(simulate, "prepare"):
        simulate.prepare()  # e.g. load the shared walk: not part of the chunk's time
    t0 = time.perf_counter()
    values = simulate(tones, photons, seed, device)
    values["albedo_rgb"] = spectrum_to_linear_srgb(values["R_d"], "D65")
    return values, time.perf_counter() - t0


def build_split(
    preset: Preset, split: str, out: Path, simulate: SimulateFn, *, method: str,
    shard: tuple[int, int] = (0, 1), device: str = "cpu", progress: bool = True, chunk_tones: int | None = None,
    job=None,
) -> Path:
    """Simulate this shard's tones of ``split`` into ``out``; resumes a partial file of the same run.

    ``job`` (``training.cluster.engine.Job``): the chunks (and the missing walk chunks of a reweighting
    ``simulate``) are submitted as its tasks, written here as they finish; call ``job.wait()`` after.
    """
    path, tones, index, seed = open_split(preset, split, out, method, shard)
    todo = store.pending(path)
    chunk = chunk_tones or preset.chunk_tones
    chunks = [todo[start : start + chunk] for start in range(0, len(todo), chunk)]
    if job is not None:
        after = simulate.submit_walk(job) if len(todo) and hasattr(simulate, "submit_walk") else []
        for rows in chunks:
            job.submit(f"{split} tones {index[rows[0]]}-{index[rows[-1]]}", simulate_chunk, simulate,
                       tones[index[rows]], preset.photons, seed * 1_000_003 + int(index[rows[0]]), device, *after,
                       on_done=lambda res, rows=rows: store.write_rows(path, rows, res[0], seconds=res[1]))
        return path
    if len(todo) and hasattr(simulate, "prepare"):
        simulate.prepare()  # the reweighted estimator's walk, before the bar starts
    i, n = shard
    bar = tqdm(total=len(index), initial=len(index) - len(todo), desc=f"{split} {i}/{n}", disable=not progress)
    for rows in chunks:
        values, seconds = simulate_chunk(simulate, tones[index[rows]], preset.photons,
                                         seed * 1_000_003 + int(index[rows[0]]), device)
        store.write_rows(path, rows, values, seconds=seconds)
        bar.set_postfix(s_per_tone=f"{seconds / len(rows):.2f}")
        bar.update(len(rows))
    bar.close()
    return path


def merge(out: Path, split: str) -> Path:
    """Check that the shards of ``split`` in ``out`` are complete and consistent, and join them."""
    shards = sorted(out.glob(f"{split}.shard*of*.h5"))
    if not shards:
        raise ValueError(f"no shards of {split!r} in {out}")
    counts = {int(p.name.split("of")[1].split(".")[0]) for p in shards}
    if len(counts) != 1 or len(shards) != counts.pop():
        raise ValueError(f"shards of {split!r} in {out} are missing or mixed: {[p.name for p in shards]}")
    with h5py.File(shards[0], "r") as f:
        attrs = dict(f.attrs)
    n_total = int(attrs["n_total"])
    parts, tone_parts, seconds = [], [], 0.0
    for p in shards:
        with h5py.File(p, "r") as f:
            if not f["done"][:].all():
                raise ValueError(f"{p} is incomplete: finish it (run its --shard again) before merging.")
            for key in ("preset", "photons", "seed", "method", "n_total"):
                if f.attrs[key] != attrs[key]:
                    raise ValueError(f"{p} differs from {shards[0]} in {key}")
            parts.append((p, f["index"][:]))
            seconds += float(f.attrs.get("seconds", 0.0))
            tone_parts.append(f["tone"][:])
    index = np.concatenate([ix for _, ix in parts])
    if sorted(index.tolist()) != list(range(n_total)):
        raise ValueError(f"the shards of {split!r} do not cover tones 0..{n_total - 1} exactly once")
    target = out / f"{split}.h5"
    if target.exists():
        raise ValueError(f"{target} exists already; move it away to merge again.")
    tones = np.empty((n_total, 5))
    tones[index] = np.concatenate(tone_parts)
    store.create(target, tones, np.arange(n_total), {**attrs, "shard": "0/1", "seconds": seconds})  # all shards' time
    with h5py.File(target, "r+") as dst:
        for p, ix in parts:
            with h5py.File(p, "r") as src:
                for name in store.SIMULATED:  # tones: written by create()
                    for local, global_row in enumerate(ix):
                        dst[name][global_row] = src[name][local]
        dst["done"][:] = True
    return target

