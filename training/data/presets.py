"""Dataset presets: sizes and photon counts (the paper's scale is for GPUs)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Preset:
    """How many tones, how many photons per wavelength, and how many tones per stored chunk.

    chunk_tones is for the direct estimator (minutes per tone); the reweighted estimator writes
    ``reweighted_chunk_tones`` at a time (a chunk of it takes about a minute on one CPU core).
    """

    name: str
    n_train: int
    n_validation: int
    photons: int
    chunk_tones: int
    reweighted_chunk_tones: int = 128
    train_seed: int = 1
    validation_seed: int = 2


PRESETS: dict[str, Preset] = {
    # CI: under 2 minutes on 2 CPU cores; enough to exercise every later stage end to end.
    "ci": Preset("ci", n_train=24, n_validation=8, photons=500, chunk_tones=8),
    # Laptop: >= 5,000 + 1,000 tones at noise equal to >= 1e5 direct photons per wavelength (a few hours,
    # resumable): the reweighted variance is 1.61x the direct one (mean over tones and wavelengths,
    # training/data/bench.py), so 1.65e5 photons are walked.
    "laptop": Preset("laptop", n_train=5_000, n_validation=1_000, photons=165_000, chunk_tones=16),
    # Paper: 25,000 + 5,000 tones at noise equal to 1e6 direct photons per wavelength (GPUs; see laptop).
    "paper": Preset("paper", n_train=25_000, n_validation=5_000, photons=1_650_000, chunk_tones=64),
}
