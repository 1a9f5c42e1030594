"""A dataset split built a block of wavelengths at a time (presets with ``wavelength_block``, `paper`).

The reweighted estimator's walk of a split keeps 74 bytes per reflected photon: 4 GB at the `laptop` preset,
~32 GB per split at the `paper` preset, more than this project's machines hold in memory or on disk beside the
dataset.  So such a split is built per block of ``Preset.wavelength_block`` wavelengths:

1. walk the block (``TrajectoryStore`` in ``DIR/trajectories_<split>/block<b>/``, photon chunks, resumable);
2. reweight every tone of the split at those wavelengths, a chunk of tones at a time, into
   ``DIR/<split>.blocks/block<b>.h5`` (R_d, R_d_stderr (N, C), profile, profile_stderr (N, C, 512) and a
   ``done`` mask: a killed build resumes at the chunk in flight);
3. delete the block's walk.

The training split keeps its radial profiles at every ``Preset.train_profile_stride``-th wavelength only (the
fitted ones); the block files store nothing of the others, and the joined file reads NaN there.

Blocks are independent: ``--shard I/N`` builds blocks I, I + N, ... (processes or machines sharing the folder).
When every block is done, ``DIR/<split>.h5`` is written with the small fields (tone, albedo_rgb, done, index,
wavelength_nm, r_edges_cm) as data and R_d, R_d_stderr, profile and profile_stderr as HDF5 virtual datasets
over the block files: readers see the usual (N, 376) and (N, 376, 512) arrays (``training.data.store``), as long
as the ``.blocks`` folder stays beside the file.

Block b walks with the seed ``block_seed(split seed, b)``, so every wavelength's Monte Carlo noise is
independent of the others', as in one walk of all wavelengths.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
from tqdm import tqdm

from exporters.colorimetry import spectrum_to_linear_srgb
from exporters.constants import N_RADIAL_BINS, N_WAVELENGTHS, R_EDGES_CM, WAVELENGTHS_NM
from training.data import store
from training.data.build import split_tones
from training.data.presets import Preset

#: The fields a block file holds per tone: (C,) or (C, 512) each, C the block's wavelengths.
BLOCK_FIELDS = ("R_d", "R_d_stderr", "profile", "profile_stderr")
#: Blocks per split are numbered below this, which keeps the blocks' seeds apart from the next split's.
MAX_BLOCKS = 1_000

#: walk_store(block, channels, seed) -> the block's TrajectoryStore (``training.data.reweight``).
WalkStoreFn = Callable[[int, np.ndarray, int], object]


def wavelength_blocks(block: int) -> list[np.ndarray]:
    """Index arrays into the 376 wavelengths, ``block`` consecutive ones each (the last may be shorter)."""
    if not 1 <= block <= N_WAVELENGTHS:
        raise ValueError(f"wavelength_block must be 1..{N_WAVELENGTHS}, not {block}.")
    return [np.arange(c, min(c + block, N_WAVELENGTHS)) for c in range(0, N_WAVELENGTHS, block)]


def block_seed(seed: int, b: int) -> int:
    """The walk seed of block ``b`` of a split drawn with ``seed``."""
    if not 0 <= b < MAX_BLOCKS:
        raise ValueError(f"block {b} is outside 0..{MAX_BLOCKS - 1}.")
    return int(seed) * MAX_BLOCKS + int(b)


def block_folder(out: Path, split: str) -> Path:
    """Where the block files of ``split`` live: ``DIR/<split>.blocks``."""
    return Path(out) / f"{split}.blocks"


def profile_slice(channels: np.ndarray, stride: int) -> slice:
    """The block's wavelengths that keep profiles (those at multiples of ``stride``), as a slice of the 376."""
    lo, hi = int(channels[0]), int(channels[-1]) + 1
    return slice(-(-lo // stride) * stride, hi, stride)


def kept_columns(channels: np.ndarray, stride: int) -> np.ndarray:
    """Positions within the block (C,) of the wavelengths that keep profiles (``profile_slice``)."""
    return np.arange(N_WAVELENGTHS)[profile_slice(channels, stride)] - int(channels[0])


def _create_block(path: Path, tones: np.ndarray, channels: np.ndarray, stride: int, attrs: dict) -> None:
    """An empty block file for ``tones`` (N, 5) at wavelength indices ``channels`` (C,), profiles at every
    ``stride``-th wavelength."""
    tmp = path.with_suffix(".tmp")
    n, c = len(tones), channels.size
    cp = kept_columns(channels, stride).size
    with h5py.File(tmp, "w") as f:
        for name in BLOCK_FIELDS:
            big = name.startswith("profile")
            shape = (n, cp, N_RADIAL_BINS) if big else (n, c)
            f.create_dataset(name, shape=shape, dtype="f4", chunks=(1, cp, N_RADIAL_BINS) if big else None,
                             compression="lzf" if big else None, shuffle=big)
        f.create_dataset("tone", data=tones)
        f.create_dataset("channels", data=channels)
        f.create_dataset("done", data=np.zeros(n, bool))
        f.attrs.update(attrs)
    tmp.rename(path)


def build_split_blocked(preset: Preset, split: str, out: Path, walk_store: WalkStoreFn, *, device: str = "cpu",
                        progress: bool = True, chunk_tones: int | None = None,
                        shard: tuple[int, int] = (0, 1)) -> Path | None:
    """Build ``split`` of ``preset`` in ``out`` a block of wavelengths at a time (module docstring); resumes.

    ``walk_store(b, channels, seed)``: the reweighting estimator of block ``b``; ``chunk_tones``: tones reweighted
    and written at once (default ``preset.reweighted_chunk_tones``); ``shard`` (I, N): build blocks I, I + N, ...
    only (processes or machines sharing ``out``).  Returns the joined ``DIR/<split>.h5``, written by whichever
    shard finds every block complete; None while other shards' blocks are not.
    """
    tones, seed = split_tones(preset, split)
    stride = preset.train_profile_stride if split == "train" else 1
    if preset.wavelength_block % stride:
        raise ValueError(f"wavelength_block ({preset.wavelength_block}) must be a multiple of train_profile_stride "
                         f"({stride}).")
    attrs = {"preset": preset.name, "split": split, "photons": preset.photons, "seed": seed, "shard": "0/1",
             "method": "reweighted", "n_total": len(tones), "created_by": "python -m training dataset",
             "wavelength_block": preset.wavelength_block, "profile_stride": stride}
    target = Path(out) / f"{split}.h5"
    if target.exists():
        store.check_matches(target, tones, attrs)
        return target
    folder = block_folder(out, split)
    folder.mkdir(parents=True, exist_ok=True)
    chunk = chunk_tones or preset.reweighted_chunk_tones
    blocks = wavelength_blocks(preset.wavelength_block)
    paths = [folder / f"block{b:03d}.h5" for b in range(len(blocks))]
    i, n = shard
    for b, channels in enumerate(blocks):
        path = paths[b]
        if b % n != i:
            continue
        if path.exists():
            store.check_matches(path, tones, attrs)
        else:
            _create_block(path, tones, channels, stride, attrs)
        todo = store.pending(path)
        kept = kept_columns(channels, stride)
        walk = walk_store(b, channels, block_seed(seed, b))
        if len(todo):
            walk.prepare()
        bar = tqdm(total=len(tones), initial=len(tones) - len(todo), desc=f"{split} block {b + 1}/{len(blocks)}",
                   disable=not progress or not len(todo))
        for start in range(0, len(todo), chunk):
            rows = todo[start : start + chunk]
            t0 = time.perf_counter()
            values = walk(tones[rows], preset.photons, seed, device)
            values = {**values, **{k: values[k][:, kept] for k in ("profile", "profile_stderr")}}
            store.write_rows(path, rows, values, seconds=time.perf_counter() - t0, fields=BLOCK_FIELDS)
            bar.update(len(rows))
        bar.close()
        walk.discard()
    if not all(p.exists() and not len(store.pending(p)) for p in paths):
        return None
    join_blocks(target, tones, attrs, paths)
    return target


def join_blocks(target: Path, tones: np.ndarray, attrs: dict, paths: list[Path]) -> None:
    """Write ``target``: the split's small fields as data, its spectra and profiles as virtual datasets over the
    complete block files ``paths`` (which together cover the 376 wavelengths once, in order)."""
    n = len(tones)
    r_d = np.empty((n, N_WAVELENGTHS), np.float32)
    layouts = {name: h5py.VirtualLayout(shape=(n, N_WAVELENGTHS, N_RADIAL_BINS) if name.startswith("profile")
                                        else (n, N_WAVELENGTHS), dtype="f4") for name in BLOCK_FIELDS}
    covered, seconds = [], 0.0
    for path in paths:
        with h5py.File(path, "r") as f:
            if not f["done"][:].all():
                raise ValueError(f"{path} is incomplete: run the dataset command again to resume it.")
            channels = f["channels"][:]
            lo, hi = int(channels[0]), int(channels[-1]) + 1
            r_d[:, lo:hi] = f["R_d"][:]
            seconds += float(f.attrs.get("seconds", 0.0))
            for name in BLOCK_FIELDS:
                cols = profile_slice(channels, int(attrs["profile_stride"])) if name.startswith("profile") \
                    else slice(lo, hi)
                # the source named relative to the joined file, so the dataset folder can move as a whole
                source = h5py.VirtualSource(f"{path.parent.name}/{path.name}", name, shape=f[name].shape)
                layouts[name][:, cols] = source
        covered.extend(range(lo, hi))
    if covered != list(range(N_WAVELENGTHS)):
        raise ValueError(f"the blocks of {target.name} do not cover the {N_WAVELENGTHS} wavelengths once, in order.")
    tmp = target.with_suffix(f".{os.getpid()}.tmp")  # two shards may join at once: the same file either way
    with h5py.File(tmp, "w") as f:
        for name, layout in layouts.items():
            f.create_virtual_dataset(name, layout, fillvalue=np.nan)
        f.create_dataset("tone", data=tones)
        f.create_dataset("albedo_rgb", data=spectrum_to_linear_srgb(r_d.astype(np.float64), "D65"))
        f.create_dataset("done", data=np.ones(n, bool))
        f.create_dataset("index", data=np.arange(n))
        f.create_dataset("wavelength_nm", data=np.asarray(WAVELENGTHS_NM))
        f.create_dataset("r_edges_cm", data=np.asarray(R_EDGES_CM))
        f.attrs.update({**attrs, "seconds": seconds})
    tmp.rename(target)
