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
                      max_steps: int = 100_000, threads: int | None = None, progress: bool = False,
                      r_edges_cm: np.ndarray | None = None, x_edges_cm: np.ndarray | None = None) -> dict:
    """Monte Carlo R_d and T_d of a layered medium at all its channels, walked by the numba engine.

    mua, mus, g (L, W) float64 (cm^-1, cm^-1, HG g), thickness (L,) cm (the last may be inf), already checked
    (``training.sim.medium_check.check_layer_values``); photons per channel; illumination "diffuse", "normal"
    or "collimated:THETA" (degrees; the beam travels towards +x, so x-z is the plane of incidence:
    ``training.sim.illumination``); seed, max_steps and threads as ``training.sim.transport.simulate``.
    Returns numpy float64 (W,) arrays R_d, R_d_stderr, T_d, T_d_stderr (per-photon std / sqrt(N)), photons
    and seconds (the walk's wall time).  With ``r_edges_cm`` (NB + 1,) also ``profile`` (W, NB) cm^-2, the
    azimuthally averaged reflected exitance per unit incident power in each annulus (``SimResult.profile``);
    with ``x_edges_cm`` (NX + 1,), increasing, signed, also ``profile_plane`` (W, NX) cm^-1, the reflected
    exitance integrated across the plane of incidence (over y) per unit length along it (x).  With either,
    ``shift_cm`` (W,): the reflected light's mean exit x (its centroid along the plane of incidence, cm), and
    the per-channel ``specular`` (W,) (the beam's Fresnel part).
    """
    from training.sim.illumination import parse_illumination
    from training.sim.packet_loop import walk_compiled

    light = parse_illumination(illumination)
    n_layers, n_ch = mua.shape
    r1, r2, t1, t2, xw = (np.zeros(n_ch) for _ in range(5))
    hists = {name: (np.asarray(e, dtype=np.float64), np.zeros((n_ch, len(e) - 1)))
             for name, e in (("r", r_edges_cm), ("x", x_edges_cm)) if e is not None}
    bar = progress_bar(photons * n_ch, progress)

    def tally(ch: np.ndarray, pid: np.ndarray, out: dict[str, np.ndarray]) -> None:
        for kind, s1, s2 in ((KIND_REFLECTED, r1, r2), (KIND_TRANSMITTED, t1, t2)):
            m = out["kind"] == kind
            w = out["w"][m]
            np.add.at(s1, ch[m], w)
            np.add.at(s2, ch[m], w * w)
        if hists:
            m = out["kind"] == KIND_REFLECTED
            c, w, x = ch[m], out["w"][m], out["x"][m]
            np.add.at(xw, c, w * x)
            for name, (edges, h) in hists.items():
                v = np.hypot(x, out["y"][m]) if name == "r" else x
                b = np.searchsorted(edges, v, side="right") - 1
                ok = (b >= 0) & (b < h.shape[1])
                np.add.at(h, (c[ok], b[ok]), w[ok])
        if bar:
            bar.update(ch.shape[0])

    t0 = time.perf_counter()
    spec, _, _, _ = walk_compiled(
        walk_tables(mua, mus, g, thickness), float(n_medium), float(n_below), n_layers, n_ch,
        photons=int(photons), order="interleaved", seed=int(seed), diffuse=light.diffuse,
        pool_packets=max(POOL_PACKETS_CPU, n_ch), max_steps=int(max_steps),
        roulette_threshold=ROULETTE_THRESHOLD, roulette_boost=ROULETTE_BOOST,
        path_n0=np.full(n_ch, np.inf), path_keep=1.0, record_paths=False, threads=threads, sink=tally,
        cos_in=light.cos_in)
    if bar:
        bar.close()
    seconds = time.perf_counter() - t0
    n = int(photons)
    r_d, r_se = mean_stderr(r1, r2, n)
    t_d, t_se = mean_stderr(t1, t2, n)
    res = {"R_d": r_d, "R_d_stderr": r_se, "T_d": t_d, "T_d_stderr": t_se, "photons": n, "seconds": seconds}
    if hists:
        res["specular"] = spec / n
        res["shift_cm"] = np.where(r1 > 0, xw / np.where(r1 > 0, r1, 1.0), 0.0)
    if "r" in hists:
        edges, h = hists["r"]
        res["profile"] = h / n / (np.pi * np.diff(edges**2))
    if "x" in hists:
        edges, h = hists["x"]
        res["profile_plane"] = h / n / np.diff(edges)
    return res
