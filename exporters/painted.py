"""The painted colour: a smooth, bounded correction of the model's spectrum that renders the albedo as painted.

The network answers an albedo texel with a biophysical skin and its K-media mixture; the mixture's own colour
is that skin's colour, which differs from the painted one (in brightness by the model's exposure, and in hue
where no skin of the model has that colour).  An artist expects the painted colour, so by default a bake
keeps what the network knows and albedo inversion cannot (the spectral shape, radii, weights, anisotropy)
and takes the colour from the texture.  This module does it for the spectral media; exporters.collapse uses
it for the Cycles channels.

Method, per texel
-----------------
Light carried by component k at wavelength lambda: E_k = w_k R(alpha_k, g_k), R the reflectance of the
model's boundary (n = 1.4, diffuse light, specular excluded: ``exporters.reflectance_tables``, "model"), so the
mixture's spectrum is sum_k E_k and its colour M @ sum_k E_k (M: linear sRGB under D65, exporters.collapse).

1. **Correction** c(lambda) = exp(sum_j a_j B_j(lambda)), j = blue, green, red: three smooth bumps
   (:func:`basis`) that split the visible into a partition of unity (logistic transitions at 490 and 580 nm)
   under a window that falls to 0 outside 395-710 nm (logistic edges), so c = 1 in the UV and the NIR: the
   biophysical spectral shape is kept where colour does not look, and a uniform a scales the visible.
2. **Corrected light** E'_k = min(c E_k, w_k R(ALPHA_MAX, g_k)): no component is asked to reflect more than
   a medium of albedo ALPHA_MAX can.
3. **Solve** M @ sum_k E'_k = A (the painted linear-sRGB albedo, clamped to [0, 1] as the model clamps it)
   for a by damped Newton (3 x 3 per texel, the basis is nearly channel-aligned so the Jacobian is well
   conditioned), with |a_j| <= ln(C_MAX) (the bound: c stays within [1/C_MAX, C_MAX]).  A texel whose
   colour is still off by more than TOLERANCE is **clamped**: its painted colour lies outside what a bounded
   correction of its skin can produce (e.g. saturated non-skin colours, or brighter than the medium allows);
   it gets the nearest colour the bound allows, and is counted.
4. **Media** (:func:`paint_mixture`): alpha'_k(lambda) = R^-1(E'_k / w_k, g_k) through the same table, and
   sigma_t'_k such that the diffusion length 1 / (sigma_t sqrt(3 (1 - alpha)(1 - alpha g))) is unchanged
   (as exporters.collapse step 6 keeps it): the painted medium bleeds light as far as the network's.
   g_k and w_k are unchanged.

The painted media depend on the network's mixture and the painted albedo only, so a consumer of the spectral
target (``S_biophysical.exr`` through ``skin_decoder.onnx``) reproduces them from the albedo texture itself:
``paint_mixture(decoder outputs, albedo texel)``.  Hand-written: no colour library corrects a spectrum
under a colour constraint with a smooth multiplicative basis.  Arrays are float64 unless said otherwise;
non-finite input raises ValueError.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from . import reflectance_tables
from .constants import N_WAVELENGTHS, WAVELENGTHS_NM

#: The correction stays within [1 / C_MAX, C_MAX] at every wavelength.  The shipped model's skins are 1.2-2x
#: darker than the painted skin colours they answer (its exposure), so 4 leaves room for hue and keeps the
#: spectrum a skin's: saturated non-skin colours are clamped instead of bent into any shape.
C_MAX: float = 4.0
#: Brightest medium a corrected component may become (the paper-scale LUT's last albedo: Monte Carlo walks and
#: Mitsuba stay finite; a medium closer to 1 would reflect at most 1 % more).
ALPHA_MAX: float = 0.9999
#: A channel is reached when |colour - A| <= TOLERANCE x max(A, 0.01) (0.1 %: ~0.05 ΔE76 on skin).
TOLERANCE: float = 1e-3
#: Newton iterations (measured: skin colours converge in 3-5; more only help colours that end clamped).
ITERATIONS: int = 12
#: Logistic edges of the window (nm) and their widths (nm): c = 1 below ~370 and above ~760 nm.
WINDOW_NM: tuple[float, float] = (395.0, 710.0)
WINDOW_WIDTH_NM: tuple[float, float] = (8.0, 10.0)
#: Logistic transitions blue|green and green|red (nm), and their width (nm).
SPLIT_NM: tuple[float, float] = (490.0, 580.0)
SPLIT_WIDTH_NM: float = 12.0
#: Basis values below this are 0, so the media are untouched where colour cannot see them.
BASIS_FLOOR: float = 1e-6


def _logistic(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * x))


@cache
def basis() -> np.ndarray:
    """B (3, 376): the blue, green and red bumps of the correction (module docstring, step 1)."""
    wl = WAVELENGTHS_NM.astype(np.float64)
    window = _logistic((wl - WINDOW_NM[0]) / WINDOW_WIDTH_NM[0]) * _logistic((WINDOW_NM[1] - wl) / WINDOW_WIDTH_NM[1])
    blue = _logistic((SPLIT_NM[0] - wl) / SPLIT_WIDTH_NM)
    red = _logistic((wl - SPLIT_NM[1]) / SPLIT_WIDTH_NM)
    b = window * np.stack([blue, 1.0 - blue - red, red])
    b[b < BASIS_FLOOR] = 0.0  # c is exactly 1 far from the visible (below 286 and above 848 nm)
    b.setflags(write=False)
    return b


def _finite(name: str, x) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: NaN or infinite value(s); the model output and the albedo must be finite")
    return arr


def target_colour(albedo_rgb) -> np.ndarray:
    """The colour a painted texel asks for: linear sRGB (N, 3) clamped to [0, 1] (as the model clamps it)."""
    return np.clip(_finite("albedo_rgb", albedo_rgb), 0.0, 1.0)


def brightest(g) -> np.ndarray:
    """R(ALPHA_MAX, g) at the model's boundary: the most a corrected component may reflect."""
    return reflectance_tables.reflectance("model", ALPHA_MAX, g)


@dataclass(frozen=True)
class Correction:
    """Solved correction of N texels: ``a`` (N, 3) coefficients of :func:`basis`, ``colour`` (N, 3) the
    corrected mixture's linear sRGB, ``clamped`` (N,) bool (painted colour not reached within TOLERANCE)."""

    a: np.ndarray
    colour: np.ndarray
    clamped: np.ndarray

    def factor(self, columns: slice | np.ndarray = slice(None)) -> np.ndarray:
        """c (N, L) at the grid wavelengths ``columns`` (default all 376)."""
        return np.exp(self.a @ basis()[:, columns])


def solve(light, cap, matrix, target, columns: slice | np.ndarray = slice(None)) -> Correction:
    """Coefficients a with M @ sum_k min(c E_k, cap_k) = target (module docstring, steps 2-3).

    ``light`` E_k and ``cap`` (N, K, L) at the grid wavelengths ``columns`` (L of them; float32 or float64);
    ``matrix`` M (3, L) at the same wavelengths; ``target`` (N, 3) linear sRGB (already clamped to [0, 1]).
    Wavelengths outside ``columns`` must not matter to the colour (M = 0 there).
    """
    e = np.asarray(light)
    cap = np.asarray(cap, dtype=e.dtype)
    m = np.asarray(matrix, np.float64)
    b = basis()[:, columns]
    t = np.asarray(target, np.float64)
    n = len(e)
    bound = np.log(C_MAX)
    m_b = (m[:, None, :] * b[None, :, :]).astype(e.dtype)  # (3, 3, L): M_c B_j per wavelength
    colour = e.sum(axis=1).astype(np.float64) @ m.T
    # start: each channel's ratio on its own bump (the basis is nearly channel-aligned)
    a = np.log(np.clip(np.maximum(t, 1e-6) / np.maximum(colour, 1e-6), 1.0 / C_MAX, C_MAX))
    best_a, best_err = a.copy(), np.full(n, np.inf)
    eye = np.eye(3)
    for _ in range(ITERATIONS):
        c = np.exp(a @ b).astype(e.dtype)  # (N, L)
        scaled = c[:, None, :] * e
        free = scaled < cap
        mix = np.where(free, scaled, cap).sum(axis=1)  # (N, L)
        colour = mix.astype(np.float64) @ m.T
        err = _relative_error(colour, t)
        better = err < best_err
        best_a[better], best_err[better] = a[better], err[better]
        dmix = np.where(free, scaled, 0).sum(axis=1)  # d mix / d ln c
        jac = np.einsum("nl,cjl->ncj", dmix, m_b, dtype=np.float64)  # (N, 3, 3)
        ridge = 1e-9 * np.maximum(np.abs(jac).max(axis=(1, 2)), 1e-30)[:, None, None]
        step = np.linalg.solve(jac + ridge * eye, (t - colour)[..., None])[..., 0]
        step = np.where(np.isfinite(step), step, 0.0)
        step *= np.minimum(1.0, 1.0 / np.maximum(np.abs(step).max(axis=1, keepdims=True), 1e-300))  # |step| <= 1
        a = np.clip(a + step, -bound, bound)
        if best_err.max(initial=0.0) <= 0.1 * TOLERANCE:
            break
    c = np.exp(best_a @ b).astype(e.dtype)
    colour = np.minimum(c[:, None, :] * e, cap).sum(axis=1).astype(np.float64) @ m.T
    clamped = _relative_error(colour, t) > TOLERANCE
    return Correction(a=best_a, colour=colour, clamped=clamped)


def _relative_error(colour: np.ndarray, target: np.ndarray) -> np.ndarray:
    """max over channels of |colour - target| / max(target, 0.01), (N,)."""
    return np.max(np.abs(colour - target) / np.maximum(target, 0.01), axis=1)


@dataclass(frozen=True)
class PaintedMixture:
    """The painted media of N texels on the 376-sample grid: ``alpha``, ``sigma_t`` (cm^-1) (N, K, 376);
    ``factor`` c (N, 376); ``colour`` (N, 3) their mixture's linear sRGB at the model's boundary (the painted
    albedo unless ``clamped`` (N,))."""

    alpha: np.ndarray
    sigma_t: np.ndarray
    factor: np.ndarray
    colour: np.ndarray
    clamped: np.ndarray


def paint_mixture(alpha, sigma_t, g, weight, albedo_rgb) -> PaintedMixture:
    """The network's mixture (``alpha``, ``sigma_t`` cm^-1, ``g``, ``weight``: (N, K, 376), docs/contracts.md §3) with
    painted colour of ``albedo_rgb`` (N, 3) linear sRGB (module docstring, steps 1-4).  g and weight stay."""
    from .collapse import channel_matrix  # collapse imports this module

    al, st, gg, w = (_finite(n, x) for n, x in (("alpha", alpha), ("sigma_t", sigma_t), ("g", g), ("weight", weight)))
    if al.ndim != 3 or al.shape[2] != N_WAVELENGTHS or any(x.shape != al.shape for x in (st, gg, w)):
        raise ValueError(f"alpha, sigma_t, g, weight must share a shape (N, K, {N_WAVELENGTHS}), got "
                         f"{[x.shape for x in (al, st, gg, w)]}")
    target = target_colour(albedo_rgb).reshape(-1, 3)
    if len(target) != len(al):
        raise ValueError(f"{len(target)} albedo rows for {len(al)} mixtures")
    g_c = np.clip(gg, 0.0, reflectance_tables.G_TABLE_MAX)
    a_c = np.minimum(al, ALPHA_MAX)
    r = reflectance_tables.reflectance("model", a_c, g_c)
    r_max = brightest(g_c)
    corr = solve(w * r, w * r_max, channel_matrix(), target)
    c = corr.factor()
    changed = np.broadcast_to(c[:, None, :] != 1.0, al.shape)
    r_new = np.minimum(c[:, None, :] * r, r_max)[changed]
    alpha_new = al.copy()
    alpha_new[changed] = np.clip(reflectance_tables.albedo_for_reflectance("model", r_new, g_c[changed]), 0.0,
                                 ALPHA_MAX)
    keep = np.ones_like(al)  # sigma_t' / sigma_t that keeps the diffusion length (alpha' <= ALPHA_MAX < 1)
    old, new, gk = a_c[changed], alpha_new[changed], gg[changed]
    keep[changed] = np.sqrt((1.0 - old) * (1.0 - old * gk) / ((1.0 - new) * (1.0 - new * gk)))
    return PaintedMixture(alpha=alpha_new, sigma_t=st * keep, factor=c, colour=corr.colour, clamped=corr.clamped)
