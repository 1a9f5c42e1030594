"""Classical diffusion-dipole tables: an analytic, physically shaped stand-in for the MC lookup tables.

ONLY A TEST / REFERENCE TABLE.  The fits of the project use the Monte Carlo LUT of
``python -m training lut``.  This module exists so that the interpolation and fitting code can be
tested against a table whose every value is known in closed form and which has the right physical
shape (a peak of width ~1 mfp, an exponential tail whose length grows as albedo -> 1).

Formulas (sigma_t = 1, so mu_a = 1 - alpha, mu_s = alpha, lengths in mfp):

* reduced coefficients mu_s' = alpha (1 - g), sigma_t' = mu_a + mu_s', alpha' = mu_s' / sigma_t';
* sigma_tr = sqrt(3 mu_a sigma_t'), z_r = 1 / sigma_t', z_v = z_r (1 + 4 A / 3), with the internal
  reflection parameter A = (1 + F_dr) / (1 - F_dr) and Egan & Hilgeman's
  F_dr = -1.440 / n^2 + 0.710 / n + 0.668 + 0.0636 n (Jensen et al. 2001, SIGGRAPH, eq. 5-6);
* R_d(r) = alpha' / (4 pi) * sum_{j in {r, v}} z_j (sigma_tr d_j + 1) exp(-sigma_tr d_j) / d_j^3,
  d_j = sqrt(r^2 + z_j^2) (Farrell, Patterson & Wilson 1992; Jensen et al. 2001 eq. 4);
* total R = alpha' / 2 (1 + exp(-4/3 A sqrt(3 (1 - alpha')))) exp(-sqrt(3 (1 - alpha'))) (Jensen
  et al. 2001, eq. 8).

The table's P is R_d(r) at the bin centres (``bin_centres``), renormalised so that sum P * area = 1
over the tabulated radii, as docs/contracts.md §2 requires of the MC table.
"""

from __future__ import annotations

import numpy as np

from exporters.constants import N_TISSUE, radial_edges
from training.sim.lut_interp import bin_centres


def fresnel_a(n: float = N_TISSUE) -> float:
    """Internal reflection parameter A of the dipole boundary condition (Jensen et al. 2001)."""
    f_dr = -1.440 / n**2 + 0.710 / n + 0.668 + 0.0636 * n
    return (1.0 + f_dr) / (1.0 - f_dr)


def dipole_profile_shape(r_mfp: np.ndarray, alpha: np.ndarray, g: np.ndarray, n: float = N_TISSUE) -> np.ndarray:
    """Dipole R_d(r) / alpha' at sigma_t = 1 (mfp^-2); ``alpha``, ``g`` broadcast against ``r_mfp``."""
    mu_a = 1.0 - alpha
    sig_tp = mu_a + alpha * (1.0 - g)
    sig_tr = np.sqrt(3.0 * mu_a * sig_tp)
    z_r = 1.0 / sig_tp
    z_v = z_r * (1.0 + 4.0 * fresnel_a(n) / 3.0)
    out = np.zeros(np.broadcast(r_mfp, alpha, g).shape)
    for z in (z_r, z_v):
        d = np.sqrt(r_mfp**2 + z**2)
        out = out + z * (sig_tr * d + 1.0) * np.exp(-sig_tr * d) / d**3
    return out / (4.0 * np.pi)


def dipole_reflectance(alpha: np.ndarray, g: np.ndarray, n: float = N_TISSUE) -> np.ndarray:
    """Dipole total diffuse reflectance (dimensionless) of a semi-infinite medium."""
    alpha_p = alpha * (1.0 - g) / (1.0 - alpha * g)
    s = np.sqrt(3.0 * (1.0 - alpha_p))
    return 0.5 * alpha_p * (1.0 + np.exp(-4.0 / 3.0 * fresnel_a(n) * s)) * np.exp(-s)


def dipole_lut(
    albedo: np.ndarray | None = None, g: np.ndarray | None = None, r_edges_mfp: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """A LUT dict with the docs/contracts.md §2 keys, filled from the dipole (test/reference table only).

    Defaults: 41 albedos denser near 1 (0, then 1 - geomspace(1 - 0.05, 1e-4)... and 1), 12 g values in
    [-0.9, 0.95], the radial edges of docs/contracts.md §1 (513) read in mfp.
    """
    if albedo is None:
        albedo = np.concatenate([[0.0], 1.0 - np.geomspace(0.95, 1e-4, 39), [1.0]])
    if g is None:
        g = np.linspace(-0.9, 0.95, 12)
    if r_edges_mfp is None:
        r_edges_mfp = radial_edges()
    a, gg = np.meshgrid(albedo, g, indexing="ij")
    c = bin_centres(r_edges_mfp)
    shape = dipole_profile_shape(c[None, None, :], a[..., None], gg[..., None])
    area = np.pi * np.diff(r_edges_mfp**2)
    P = shape / (shape * area).sum(-1, keepdims=True)
    return {"albedo": albedo, "g": g, "r_edges_mfp": r_edges_mfp, "R": dipole_reflectance(a, gg), "P": P}


def dipole_mixture_profile(
    r_edges_cm: np.ndarray,
    r_edges_mfp: np.ndarray,
    alpha: np.ndarray,
    g: np.ndarray,
    sigma_t: np.ndarray,
    w: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """MC-like target of a dipole mixture in closed form (test/reference only).

    ``alpha``, ``g``, ``sigma_t`` (cm^-1), ``w``: shape (B, K).  Each component's normalised profile is
    sigma_t^2 shape(sigma_t r) / (the area integral of the shape over the table's radii ``r_edges_mfp``),
    i.e. the normalisation a LUT built by ``dipole_lut(r_edges_mfp=...)`` uses, evaluated at the bin
    centres of ``r_edges_cm`` and zero beyond the table's last radius.  Returns (profile (B, M) cm^-2
    = sum_k w_k R_k P_k, the exitance of a medium picked with probability w_k, and R (B,) = sum_k w_k R_k).
    """
    alpha, g, sigma_t, w = (np.asarray(x, dtype=np.float64) for x in (alpha, g, sigma_t, w))
    c_mfp = bin_centres(r_edges_mfp)
    a_mfp = np.pi * np.diff(r_edges_mfp**2)
    norm = (dipole_profile_shape(c_mfp, alpha[..., None], g[..., None]) * a_mfp).sum(-1)  # (B, K)
    x = sigma_t[..., None] * bin_centres(r_edges_cm)  # (B, K, M), mfp
    p_k = sigma_t[..., None] ** 2 * dipole_profile_shape(x, alpha[..., None], g[..., None]) / norm[..., None]
    p_k = np.where(x <= r_edges_mfp[-1], p_k, 0.0)
    r_k = dipole_reflectance(alpha, g)
    return ((w * r_k)[..., None] * p_k).sum(-2), (w * r_k).sum(-1)
