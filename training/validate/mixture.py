"""Our renderer of a K-media mixture: Monte Carlo total diffuse reflectance on a semi-infinite slab.

This is the renderer of the paper's rendering gate (§6, "each photon randomly selects a medium from the
K-media mixture"): each component k is a homogeneous semi-infinite medium (mu_a = (1 - alpha) sigma_t,
mu_s = alpha sigma_t, Henyey-Greenstein g) under the dataset's boundary (n = 1.4, smooth unpolarised
Fresnel, air above) and the dataset's illumination (``"diffuse"``: a cosine-weighted lobe entering at the
origin; ``"normal"`` selectable).  R_d never includes the specular reflection (docs/contracts.md §1).

**How the mixture is combined.**  A photon that picks medium k with probability w_k(lambda) has expected
reflectance ``sum_k w_k R_k``, so we walk every component with the same photons in one batched run of
``training.sim.transport.simulate`` (K x W channels) and combine the per-component tallies with w_k:
exact by linearity, and with lower variance than a per-photon choice (each component gets all the
photons; stderr = sqrt(sum_k w_k^2 se_k^2), the components being independent walks).  Where one precision is
wanted at least cost, :func:`photons_for_precision` gives each component its own photons (Neyman's allocation:
by its weight and its spread), and the walk runs once per distinct count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from exporters.colorimetry import Illuminant, spectrum_to_lab, spectrum_to_srgb
from exporters.constants import N_TISSUE, WAVELENGTHS_NM
from training.sim.medium import LayeredMedium
from training.sim.transport import SimResult, simulate

#: Tolerance on sum_k w_k = 1 (the decoder's softmax in float16/32).
WEIGHT_SUM_TOL = 1e-3


@dataclass(frozen=True)
class MixtureResult:
    """R_d (W,) of the mixture with its standard error, per-component R_k and R_k_stderr (K, W),
    photons per component and wavelength, and the wall time (s).  With radial tallies (``r_edges_cm``
    given) also ``profile`` and ``profile_stderr`` (W, NB) in cm^-2 (docs/contracts.md §1 definition), else None."""

    R_d: np.ndarray
    R_d_stderr: np.ndarray
    R_k: np.ndarray
    R_k_stderr: np.ndarray
    photons: int | np.ndarray
    seconds: float
    profile: np.ndarray | None = None
    profile_stderr: np.ndarray | None = None

    @property
    def per_photon_sd(self) -> np.ndarray:
        """(K, W): the standard deviation of one photon's estimate of R_k (stderr x sqrt(photons))."""
        return self.R_k_stderr * np.sqrt(self.photons)


def _as_kw(name: str, x, shape: tuple[int, ...] | None = None) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2:
        raise ValueError(f"{name} must have shape (K, W), got {a.shape}.")
    if shape is not None and a.shape != shape:
        raise ValueError(f"{name} must have the shape of alpha {shape}, got {a.shape}.")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or Inf.")
    return a


def check_mixture(alpha, sigma_t, g, weight) -> tuple[np.ndarray, ...]:
    """The four (K, W) arrays as float64 after checking ranges; ValueError naming what is wrong."""
    a = _as_kw("alpha", alpha)
    s, gg, w = (_as_kw(n, v, a.shape) for n, v in (("sigma_t", sigma_t), ("g", g), ("weight", weight)))
    if a.min() < 0 or a.max() > 1:
        raise ValueError("alpha must lie in [0, 1].")
    if s.min() <= 0:
        raise ValueError("sigma_t must be > 0 (cm^-1).")
    if np.abs(gg).max() > 0.99:
        raise ValueError("g must lie in [-0.99, 0.99] (the simulator's range).")
    if w.min() < 0 or np.abs(w.sum(axis=0) - 1).max() > WEIGHT_SUM_TOL:
        raise ValueError("weights must be >= 0 and sum to 1 over the K components at every wavelength.")
    return a, s, gg, w


def render_media(alpha, sigma_t, g, *, photons: int, seed: int = 0, illumination: str = "diffuse",
                 r_edges_cm: np.ndarray | None = None, device: str = "cpu", compile: bool | str = "auto",
                 progress: bool = False, max_steps: int = 100_000) -> SimResult:
    """One batched walk of C independent homogeneous semi-infinite media (the components of any number of
    mixtures): ``alpha``, ``sigma_t`` (cm^-1), ``g`` of shape (C,).  Returns the simulator's SimResult
    (R_d, R_d_stderr (C,), profile (C, NB) when ``r_edges_cm`` is given; ``truncated`` (C,): the weight
    still alive at the walk cap ``max_steps``, an upper bound on the light the cap lost)."""
    a, s, gg = (np.asarray(x, dtype=np.float64).ravel() for x in (alpha, sigma_t, g))
    check_mixture(a[None], s[None], gg[None], np.ones((1, a.size)))
    medium = LayeredMedium.homogeneous((1 - a) * s, a * s, gg, n_medium=N_TISSUE)
    return simulate(medium, int(photons), illumination=illumination, seed=seed, device=device,
                    r_edges_cm=r_edges_cm, progress=progress, compile=compile, max_steps=max_steps)


def combine(weight: np.ndarray, values: np.ndarray, stderr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mixture of independent component estimates: (sum_k w_k v_k, sqrt(sum_k w_k^2 se_k^2)).

    ``weight`` (K, W); ``values``, ``stderr`` (K, W) or (K, W, NB) (radial profiles)."""
    w = weight if values.ndim == weight.ndim else weight[..., None]
    return np.sum(w * values, axis=0), np.sqrt(np.sum((w * stderr) ** 2, axis=0))


def mixture_reflectance(alpha, sigma_t, g, weight, *, photons: int | np.ndarray, seed: int = 0,
                        illumination: str = "diffuse", device: str = "cpu", progress: bool = False,
                        r_edges_cm: np.ndarray | None = None, compile: bool | str = "auto") -> MixtureResult:
    """Total diffuse reflectance of the mixture at each of its W wavelengths.

    Args:
        alpha, sigma_t (cm^-1), g, weight: (K, W) arrays (or (W,) for K = 1); weights sum to 1 over K.
        photons: photons per component and wavelength: one number (one batched walk of all K x W media) or a
            (K, W) array (:func:`photons_for_precision`; one walk per distinct count, none for a count of 0,
            whose component must have zero weight).
        illumination: "diffuse" (the dataset's) or "normal".
        r_edges_cm: radial bin edges (NB + 1,) to tally the mixture's profile too (None: R_d only).
    Returns: MixtureResult; R_d = sum_k w_k R_k (exact by linearity, see the module docstring).
    """
    a, s, gg, w = check_mixture(alpha, sigma_t, g, weight)
    k, n_w = a.shape
    counts = np.broadcast_to(np.asarray(photons, dtype=np.int64), (k, n_w))
    if np.any((counts <= 0) & (w > 0)):
        raise ValueError("photons must be > 0 for every component of non-zero weight.")
    nb = 0 if r_edges_cm is None else np.asarray(r_edges_cm).size - 1
    r_k, se_k = np.zeros((k, n_w)), np.zeros((k, n_w))
    p_k, pse_k = np.zeros((k, n_w, nb)), np.zeros((k, n_w, nb))
    seconds = 0.0
    for i, n in enumerate(int(n) for n in np.unique(counts) if n > 0):
        sel = counts == n
        res = render_media(a[sel], s[sel], gg[sel], photons=n, seed=seed + 104729 * i, illumination=illumination,
                           r_edges_cm=r_edges_cm, device=device, compile=compile, progress=progress)
        r_k[sel], se_k[sel], seconds = res.R_d, res.R_d_stderr, seconds + res.seconds
        if nb:
            p_k[sel], pse_k[sel] = res.profile, res.profile_stderr
    r_d, r_se = combine(w, r_k, se_k)
    prof = prof_se = None
    if nb:
        prof, prof_se = combine(w, p_k, pse_k)
    return MixtureResult(R_d=r_d, R_d_stderr=r_se, R_k=r_k, R_k_stderr=se_k,
                         photons=int(photons) if np.ndim(photons) == 0 else counts.copy(), seconds=seconds,
                         profile=prof, profile_stderr=prof_se)


def neyman_allocation(weight: np.ndarray, per_sample_sd: np.ndarray, target_stderr: np.ndarray, *,
                      multiple: int = 1, floor: int = 1) -> np.ndarray:
    """Samples per component and wavelength (K, W) that give a mixture's estimate sum_k w_k R_k the standard
    error ``target_stderr`` (W,) at each wavelength for the fewest samples in all: Neyman's allocation of a
    stratified estimate, n_k = w_k s_k (sum_j w_j s_j) / target^2, with ``per_sample_sd`` s (K, W) (a pilot
    run's spread of one sample, e.g. :attr:`MixtureResult.per_photon_sd`).  Rounded up to a multiple of
    ``multiple``, at least ``floor`` for every component of non-zero weight (a pilot's spread is itself
    noisy), 0 for those of zero weight."""
    w, s = np.asarray(weight, np.float64), np.asarray(per_sample_sd, np.float64)
    target = np.asarray(target_stderr, np.float64)
    if w.ndim != 2 or w.shape != s.shape or target.shape != w.shape[1:] or not np.all(target > 0):
        raise ValueError(f"need weight and per_sample_sd of one shape (K, W) and a positive target (W,), got "
                         f"{w.shape}, {s.shape}, {target.shape}.")
    ws = w * np.nan_to_num(s, nan=0.0, posinf=0.0)
    n = np.nan_to_num(ws * ws.sum(axis=0) / target**2, nan=0.0, posinf=0.0)
    n = np.ceil(np.maximum(n, floor) / multiple) * multiple
    return np.where(w > 0, n, 0).astype(np.int64)


def precision_target(r_d: np.ndarray, rel_stderr: float) -> np.ndarray:
    """The standard error (W,) that is ``rel_stderr`` x |R_d| at each wavelength, for :func:`neyman_allocation`;
    inf where R_d is 0 (nothing to resolve: the allocation's floor)."""
    target = rel_stderr * np.abs(np.asarray(r_d, np.float64))
    return np.where(target > 0, target, np.inf)


def photons_for_precision(alpha, sigma_t, g, weight, rel_stderr: float, *, pilot_photons: int = 20_000,
                          seed: int = 0, illumination: str = "diffuse") -> np.ndarray:
    """Photons per component and wavelength (K, W) for :func:`mixture_reflectance` to reach a standard error of
    about ``rel_stderr`` x R_d at every wavelength: a pilot walk of ``pilot_photons`` per component measures each
    component's spread, then :func:`neyman_allocation` (floor: pilot_photons / 4).  Give the real walk another
    ``seed`` than the pilot's, so that it does not reuse the pilot's photons."""
    pilot = mixture_reflectance(alpha, sigma_t, g, weight, photons=pilot_photons, seed=seed,
                                illumination=illumination)
    return neyman_allocation(np.atleast_2d(np.asarray(weight, np.float64)), pilot.per_photon_sd,
                             precision_target(pilot.R_d, rel_stderr), floor=max(pilot_photons // 4, 1))


def _full_grid(reflectance) -> np.ndarray:
    r = np.asarray(reflectance, dtype=np.float64)
    if r.shape[-1] != WAVELENGTHS_NM.size:
        raise ValueError(f"colour needs the full {WAVELENGTHS_NM.size}-sample spectrum, got {r.shape}.")
    return r


def reflectance_srgb(reflectance, illuminant: Illuminant = "D65") -> np.ndarray:
    """sRGB-encoded colour (..., 3) of R_d spectra (..., 376) seen under ``illuminant`` (default D65)."""
    return spectrum_to_srgb(_full_grid(reflectance), illuminant)


def reflectance_lab(reflectance, illuminant: Illuminant = "D65") -> np.ndarray:
    """CIE Lab (..., 3) of R_d spectra (..., 376) under ``illuminant``, for the gate's Delta E76."""
    return spectrum_to_lab(_full_grid(reflectance), illuminant)


def torch_threads(n: int) -> None:
    """Set torch's intra-op threads (the walker is fastest on one thread on a busy 2-core machine)."""
    if n < 1:
        raise ValueError("threads must be >= 1")
    torch.set_num_threads(int(n))
