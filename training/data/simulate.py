"""Per-tone simulation for the dataset: the direct estimator (one full Monte Carlo run per tone)."""

from __future__ import annotations

import numpy as np

from training.sim.tissue import skin_medium
from training.sim.transport import simulate
from training.sim.walker import WalkConfig


def simulate_direct(tones: np.ndarray, photons: int, seed: int, device: str,
                    max_steps: int = WalkConfig.max_steps) -> dict[str, np.ndarray]:
    """Simulate each tone (B, 5) at all wavelengths, each packet walked at most ``max_steps`` steps.

    Returns R_d, R_d_stderr (B, 376), profile, profile_stderr (B, 376, 512).
    """
    results = [
        simulate(skin_medium(tone), photons, illumination="diffuse", seed=seed + i, device=device,
                 max_steps=max_steps)
        for i, tone in enumerate(tones)
    ]
    return {
        "R_d": np.stack([r.R_d for r in results]),
        "R_d_stderr": np.stack([r.R_d_stderr for r in results]),
        "profile": np.stack([r.profile for r in results]),
        "profile_stderr": np.stack([r.profile_stderr for r in results]),
    }
