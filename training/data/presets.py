"""Dataset presets: sizes and photon counts (the paper's scale is for GPUs)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Preset:
    """How many tones, how many photons per wavelength, and how many tones per stored chunk.

    chunk_tones is for the direct estimator (minutes per tone); the reweighted estimator writes
    ``reweighted_chunk_tones`` at a time (a chunk of it takes about a minute on one CPU core).  Its walk
    is saved in chunks of ``walk_chunk_photons`` photons (None: ``reweight.walk_chunk_photons(device)``) with a walk
    cap of ``walk_max_steps`` steps per photon (None: ``reweight.WALK_MAX_STEPS``, the walker's default).
    ``wavelength_block``: walk and reweight that many wavelengths at a time, deleting each block's walk once its
    tones are done (``training.data.blocks``), for splits whose whole walk does not fit in memory or on disk;
    None: one walk of all 376 wavelengths per split, kept (it can grow by more photon chunks).
    ``train_profile_stride``: with ``wavelength_block``, the training split keeps its radial profiles at every n-th
    wavelength only (R_d at all): the fits and the training read them at the fitted wavelengths alone.
    """

    name: str
    n_train: int
    n_validation: int
    photons: int
    chunk_tones: int
    reweighted_chunk_tones: int = 128
    train_seed: int = 1
    validation_seed: int = 2
    walk_chunk_photons: int | None = None
    walk_max_steps: int | None = None
    wavelength_block: int | None = None
    train_profile_stride: int = 1


PRESETS: dict[str, Preset] = {
    # Smoke: the smallest build with every kind of piece (3 walk chunks per split, several reweighting
    # chunks) for tests of the plumbing (resume, shards, Dask): 1-3 s per walk chunk.  Its walk cap
    # of 500 steps leaves ~12 % of the weight alive (recorded as `truncated`): not for science.
    "smoke": Preset("smoke", n_train=6, n_validation=4, photons=60, chunk_tones=2, reweighted_chunk_tones=2,
                    walk_chunk_photons=20, walk_max_steps=500),
    # CI: under 2 minutes on 2 CPU cores; enough to exercise every later stage end to end.
    "ci": Preset("ci", n_train=24, n_validation=8, photons=500, chunk_tones=8),
    # Laptop: >= 5,000 + 1,000 tones at noise equal to >= 1e5 direct photons per wavelength (a few hours,
    # resumable): the reweighted variance was 1.61x the direct one for the skin model before its real-skin
    # calibration (mean over tones and wavelengths, training/bench/data.py), so 1.65e5 photons are walked.
    "laptop": Preset("laptop", n_train=5_000, n_validation=1_000, photons=165_000, chunk_tones=16),
    # Paper: 25,000 + 5,000 tones at noise equal to >= 1e6 direct photons per wavelength: the variance ratio of
    # the present skin model is 1.17 on the preset's first 12 training tones (`python -m training.bench.data
    # --variance-ratio paper 12 2000`) and 1.29 on six tones of the built laptop dataset (darkest to lightest,
    # docs/research/dataset.md), so 1.3e6 photons are walked.  A split's whole walk would hold ~32 GB of records
    # (74 bytes x 0.87 reflected photons per packet x 1.3e6 x 376), so it is
    # built 8 wavelengths at a time (~0.7 GB of walk in memory; on disk at most one block's walk per split), its
    # tones reweighted 1,024 at a time (~20 s per chunk of a block on one core).  Its training profiles are kept at
    # the fitted wavelengths (every 4th, `fit --wavelength-stride 4`): all 376 would take ~30 GB of disk (LZF).
    "paper": Preset("paper", n_train=25_000, n_validation=5_000, photons=1_300_000, chunk_tones=64,
                    reweighted_chunk_tones=1_024, wavelength_block=8, train_profile_stride=4),
}
