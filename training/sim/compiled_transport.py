"""Reflectance and transmittance of a layered medium by the compiled walk alone: numpy and numba, no torch.

``training.sim.transport.simulate`` with the numba engine gives the same numbers (same walk tables, same
packets, same tallies added in the same order) but loads torch, which costs a fresh process seconds of
start-up; the command line (``python -m training simulate-layers``) calls this module instead whenever the
walk runs on the CPU.
"""

from __future__ import annotations

import time

import numpy as np

from training.sim.walk_constants import (
    KIND_REFLECTED,
    KIND_TRANSMITTED,
    POOL_PACKETS_CPU,
    ROULETTE_BOOST,
    ROULETTE_THRESHOLD,
)


def mean_stderr(s1, s2, n: int):
    """Mean and standard error of the mean of n per-photon values from their sum and sum of squares.

    Works on numpy arrays and torch tensors alike (same type out as in).
    """
    mean = s1 / n
    var = (s2 / n - mean * mean).clip(0.0, None) * (n / max(n - 1, 1))
    return mean, (var / n) ** 0.5


def progress_bar(total: int, enabled: bool):
    """A tqdm bar over ``total`` packets on stderr, or None when not ``enabled``."""
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="packet", unit_scale=True, smoothing=0.1)


def walk_tables(mua: np.ndarray, mus: np.ndarray, g: np.ndarray, thickness: np.ndarray,
                table_dtype=np.float32) -> tuple[np.ndarray, ...]:
    """The walk's property tables, float64 values stored at ``table_dtype`` precision (the walker's dtype).

    mua, mus, g (L, W); thickness (L,) cm.  Returns t_mut, t_alb, t_g (L * W,) indexed by layer * W + channel
    (interaction coefficient cm^-1, single-scattering albedo, HG g) and the layer tops / bottoms t_ztop,
    t_zbot (L,) cm, as ``training.sim.packet_loop.walk_batch`` takes them.
    """
    mut = mua + mus
    alb = np.where(mut > 0, mus / np.maximum(mut, 1e-300), 1.0)
    zb = np.concatenate([np.zeros(1), np.cumsum(thickness)])
    at = lambda a: np.ascontiguousarray(a, dtype=np.float64).reshape(-1).astype(table_dtype).astype(np.float64)  # noqa: E731
    return at(mut), at(alb), at(g), at(zb[:-1]), at(zb[1:])


def simulate_compiled(mua: np.ndarray, mus: np.ndarray, g: np.ndarray, thickness: np.ndarray, photons: int, *,
                      n_medium: float = 1.4, n_below: float = 1.0, illumination: str = "diffuse", seed: int = 0,
                      max_steps: int = 100_000, threads: int | None = None, progress: bool = False) -> dict:
    """Monte Carlo R_d and T_d of a layered medium at all its channels, walked by the numba engine.

    mua, mus, g (L, W) float64 (cm^-1, cm^-1, HG g), thickness (L,) cm (the last may be inf), already checked
    (``training.sim.medium_check.check_layer_values``); photons per channel; illumination "diffuse" or
    "normal"; seed, max_steps and threads as ``training.sim.transport.simulate``.
    Returns numpy float64 (W,) arrays R_d, R_d_stderr, T_d, T_d_stderr (per-photon std / sqrt(N)), photons
    and seconds (the walk's wall time).
    """
    from training.sim.packet_loop import walk_compiled

    if illumination not in ("diffuse", "normal"):
        raise ValueError(f"illumination must be 'diffuse' or 'normal', got {illumination!r}")
    n_layers, n_ch = mua.shape
    r1, r2, t1, t2 = (np.zeros(n_ch) for _ in range(4))
    bar = progress_bar(photons * n_ch, progress)

    def tally(ch: np.ndarray, pid: np.ndarray, out: dict[str, np.ndarray]) -> None:
        for kind, s1, s2 in ((KIND_REFLECTED, r1, r2), (KIND_TRANSMITTED, t1, t2)):
            m = out["kind"] == kind
            w = out["w"][m]
            np.add.at(s1, ch[m], w)
            np.add.at(s2, ch[m], w * w)
        if bar:
            bar.update(ch.shape[0])

    t0 = time.perf_counter()
    walk_compiled(walk_tables(mua, mus, g, thickness), float(n_medium), float(n_below), n_layers, n_ch,
                  photons=int(photons), order="interleaved", seed=int(seed), diffuse=illumination == "diffuse",
                  pool_packets=max(POOL_PACKETS_CPU, n_ch), max_steps=int(max_steps),
                  roulette_threshold=ROULETTE_THRESHOLD, roulette_boost=ROULETTE_BOOST,
                  path_n0=np.full(n_ch, np.inf), path_keep=1.0, record_paths=False, threads=threads, sink=tally)
    if bar:
        bar.close()
    seconds = time.perf_counter() - t0
    r_d, r_se = mean_stderr(r1, r2, int(photons))
    t_d, t_se = mean_stderr(t1, t2, int(photons))
    return {"R_d": r_d, "R_d_stderr": r_se, "T_d": t_d, "T_d_stderr": t_se, "photons": int(photons),
            "seconds": seconds}
