"""One homogeneous medium per texel for OpenPBR Surface (``--target openpbr``): the K-media mixture collapsed once more.

OpenPBR Surface 1.1 (and Blender's Principled BSDF, Arnold's standard_surface, RenderMan's PxrSurface) holds ONE
subsurface medium per point: a colour (the multiple-scattering albedo the surface shows), a mean free path per
channel, one anisotropy and a weight.  The bake's records (exporters.texel_records) hold, per channel c, the K media
Cycles walks (alpha_kc, sigma_t,kc, g_k) and their weights w_kc (exporters.collapse).  This module turns them into
the one medium that reproduces the mixture best, per texel and channel:

1. **Colour, exactly.**  The mixture renders T_c = sum_k w_kc R_cycles(alpha_kc, g_k) (the painted colour, or the
   model's with ``--model-colour``; exporters.collapse step 4).  ``base_color`` is T_c.  ``subsurface_color`` is the
   colour whose random walk, under OpenPBR's dielectric specular layer, renders T_c seen straight above under a
   uniform white world (the artist's check): the walk's albedo alpha_c solves
   (1 - F0(ior)) R1(alpha_c, g; mu = 1) = T_c, R1 the directional reflectance of Cycles' walk along the normal
   (exporters.reflectance_tables.normal_reflectance) and 1 - F0 the light the specular layer lets through face-on;
   then ``subsurface_color`` = f^-1(alpha_c; g), the inverse of the albedo mapping Cycles (Chiang et al. 2016,
   the fit OpenPBR renderers share) applies to a subsurface colour (exporters.cycles.rw_albedo_inverse).
2. **Anisotropy.**  The light-weighted mean of g_k over components and channels (0 for the bake's media:
   exporters.collapse step 5), clipped to [0, 0.7] (the largest g Cycles walks accurately).
3. **Translucency, as close as one medium can.**  A component's light spreads over its diffusion length
   D_kc = 1 / sigma_tr,kc, sigma_tr = sigma_t sqrt(3 (1 - alpha)(1 - alpha g)).  The single medium keeps the
   light-weighted mean D_c = sum_k s_kc D_kc (s_kc = w_kc R_cycles(alpha_kc, g_k) / T_c, the component's share of
   the channel's light): in the diffusion regime the mean distance at which light leaves the skin is D, so the
   mixture's and the single medium's mean exit distances agree per channel.  Its extinction follows from its own
   albedo: sigma_t,c = 1 / (D_c sqrt(3 (1 - alpha_c)(1 - alpha_c g))), and ``mean_free_path`` = 1 / sigma_t,c
   (OpenPBR's subsurface_radius x subsurface_radius_scale, in scene units after ``unit_scale_m``), at least
   exporters.collapse.MIN_MFP_CM.  What one medium cannot keep: the mixture's profile is a sum of K exponentials
   (a sharp core and a long tail); one exponential with the same mean is too wide near the point of entry and too
   short in the tail, so thin back-lit parts (ears, nostrils) transmit less (docs/user/other_renderers.md has the
   numbers for the representative tones: :func:`fidelity`).
4. **Weight.**  ``subsurface_weight`` 1 everywhere: skin is all subsurface (the mixture's weights below 1 are the
   absorbed share, already in the colour).

Renderers differ in what a "radius" is: OpenPBR's is the extinction mean free path 1 / sigma_t; Cycles' Principled
BSDF walks sigma_t = 4 pi / (Radius x Scale x (1 - g)) (exporters.cycles.RADIUS_TO_D), so OpenPBR's radius renders
in Cycles with Subsurface Scale = :data:`CYCLES_RADIUS_SCALE` (4 pi).  All arrays float64; finite in, finite out.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from . import collapse, cycles, reflectance_tables

#: Index of refraction of the specular layer (OpenPBR specular_ior) and of the walk's entry: the tissue's.
SPECULAR_IOR: float = reflectance_tables.CYCLES_IOR
#: Subsurface Scale that makes Cycles' Principled BSDF walk OpenPBR's mean free path: Cycles divides Radius x Scale
#: by 4 pi (closure/bssrdf.h bssrdf_setup_radius, exporters.cycles.RADIUS_TO_D) before taking sigma_t = 1 / d.
CYCLES_RADIUS_SCALE: float = 4.0 * np.pi
#: The albedo grid on which R1(alpha; mu = 1) is inverted (dense near 1, where skin's albedos lie).
_N_ALBEDO = 4097


@dataclass(frozen=True)
class SingleMedium:
    """One medium per texel (N) and channel (3).

    ``base_color`` (N, 3) the colour the mixture renders (linear sRGB); ``subsurface_color`` (N, 3) OpenPBR's
    subsurface_color (step 1 of the module docstring); ``alpha`` (N, 3) the walk's single-scattering albedo;
    ``mean_free_path_cm`` (N, 3) 1 / sigma_t in cm; ``anisotropy`` (N,); ``weight`` (N,) subsurface_weight;
    ``diffusion_length_cm`` (N, 3) D_c kept from the mixture.
    """

    base_color: np.ndarray
    subsurface_color: np.ndarray
    alpha: np.ndarray
    mean_free_path_cm: np.ndarray
    anisotropy: np.ndarray
    weight: np.ndarray
    diffusion_length_cm: np.ndarray

    def mean_free_path(self, unit_scale_m: float) -> np.ndarray:
        """(N, 3) mean free path in scene units of ``unit_scale_m`` metres."""
        return self.mean_free_path_cm / (cycles.CM_PER_M * float(unit_scale_m))


def diffusion_length_cm(alpha, sigma_t_cm, g) -> np.ndarray:
    """D = 1 / (sigma_t sqrt(3 (1 - alpha)(1 - alpha g))) in cm (broadcast shapes); alpha is held below 1 - 1e-12."""
    al = np.minimum(np.asarray(alpha, np.float64), 1.0 - 1e-12)
    return 1.0 / (np.asarray(sigma_t_cm, np.float64) * np.sqrt(3.0 * (1.0 - al) * (1.0 - al * np.asarray(g))))


@cache
def _normal_curve(g: float) -> tuple[np.ndarray, np.ndarray]:
    """(R1(alpha; mu = 1) increasing, alpha) on a grid dense near alpha = 1, for anisotropy ``g``."""
    alpha = 1.0 - np.linspace(1.0, reflectance_tables.U_MIN, _N_ALBEDO) ** 2  # uniform in sqrt(1 - alpha)
    r1 = reflectance_tables.normal_reflectance(alpha, np.full_like(alpha, g))
    return np.maximum.accumulate(r1), alpha


def face_on_albedo_for(colour: np.ndarray, g: float, ior: float = SPECULAR_IOR) -> np.ndarray:
    """alpha (shape of ``colour``) whose walk renders ``colour`` straight above under the specular layer:
    (1 - F0(ior)) R1(alpha, g; mu = 1) = colour (clipped to what the walk can show)."""
    r1, alpha = _normal_curve(round(float(g), 6))
    through = 1.0 - float(cycles.fresnel_dielectric(1.0, ior))
    return np.interp(np.asarray(colour, np.float64) / through, r1, alpha)


def single_medium(weight, alpha, sigma_t_cm, anisotropy, ior: float = SPECULAR_IOR) -> SingleMedium:
    """The single medium (module docstring) of the bake's per-channel media: ``weight``, ``alpha``, ``sigma_t_cm``
    (N, K, 3) and ``anisotropy`` (N, K), as exporters.texel_records holds them."""
    w, al, st = (np.asarray(x, np.float64) for x in (weight, alpha, sigma_t_cm))
    g = np.asarray(anisotropy, np.float64)
    for name, x in (("weight", w), ("alpha", al), ("sigma_t_cm", st), ("anisotropy", g)):
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{name}: NaN or infinite value(s)")
    if w.ndim != 3 or w.shape[2] != 3 or al.shape != w.shape or st.shape != w.shape or g.shape != w.shape[:2]:
        raise ValueError(f"need (N, K, 3) media and (N, K) anisotropy, got {w.shape}, {al.shape}, {st.shape}, "
                         f"{g.shape}")
    light = w * reflectance_tables.reflectance("cycles", al, g[..., None], ior)  # (N, K, 3)
    target = light.sum(axis=1)
    total = np.where(target > 0.0, target, 1.0)[:, None, :]
    share = np.where(target[:, None, :] > 0.0, light / total, w / np.maximum(w.sum(axis=1, keepdims=True), 1e-30))
    g_single = np.clip(np.einsum("nkc,nk->n", share, g) / 3.0, cycles.G_MIN, cycles.RECOMMENDED_G_MAX)
    d_mix = np.sum(share * diffusion_length_cm(al, st, g[..., None]), axis=1)  # (N, 3)
    base = np.clip(target, 0.0, 1.0)
    alpha_s = np.empty_like(base)
    for gv in np.unique(g_single):
        rows = g_single == gv
        alpha_s[rows] = face_on_albedo_for(base[rows], float(gv), ior)
    alpha_s = np.clip(alpha_s, 0.0, reflectance_tables.ALPHA_TABLE_MAX)
    colour = cycles.rw_albedo_inverse(alpha_s, g_single[:, None]).color
    sigma_t = 1.0 / (d_mix * np.sqrt(3.0 * (1.0 - alpha_s) * (1.0 - alpha_s * g_single[:, None])))
    mfp = np.maximum(1.0 / sigma_t, collapse.MIN_MFP_CM)
    out = SingleMedium(base_color=base, subsurface_color=np.clip(colour, 0.0, 1.0), alpha=alpha_s,
                       mean_free_path_cm=mfp, anisotropy=g_single, weight=np.ones(len(base)),
                       diffusion_length_cm=d_mix)
    for name in ("base_color", "subsurface_color", "alpha", "mean_free_path_cm", "anisotropy"):
        if not np.all(np.isfinite(getattr(out, name))):
            raise RuntimeError(f"single medium: non-finite {name}")  # guarded above; never expected
    return out


@dataclass(frozen=True)
class Fidelity:
    """How far the single medium is from the mixture, per texel (N) and channel (3), in the diffusion model where a
    medium of diffusion length D sends the fraction exp(-r / D) of its light beyond the distance r from where it
    entered (the exponential tail of the diffusion profile; the mean exit distance is D):

    ``d_mix_mm`` (N, 3) D_c of the single medium (the mixture's light-weighted mean); ``d_max_mm`` (N, 3) the
    longest-reaching component's D that carries at least 1 % of the channel's light; ``half_light`` (N, 3) the
    single medium's half-light radius over the mixture's (1: same); ``tail`` (N, 3) the light beyond 1 mm,
    single over mixture (how a thin back-lit part transmits: below 1 transmits less)."""

    d_mix_mm: np.ndarray
    d_max_mm: np.ndarray
    half_light: np.ndarray
    tail: np.ndarray


def fidelity(weight, alpha, sigma_t_cm, anisotropy, ior: float = SPECULAR_IOR, tail_mm: float = 1.0) -> Fidelity:
    """:class:`Fidelity` of the single medium of these media (arguments as :func:`single_medium`)."""
    w, al, st = (np.asarray(x, np.float64) for x in (weight, alpha, sigma_t_cm))
    g = np.asarray(anisotropy, np.float64)
    light = w * reflectance_tables.reflectance("cycles", al, g[..., None], ior)
    share = light / np.maximum(light.sum(axis=1, keepdims=True), 1e-30)
    d_k = diffusion_length_cm(al, st, g[..., None]) * 10.0  # mm
    d_mix = np.sum(share * d_k, axis=1)
    d_max = np.max(np.where(share >= 0.01, d_k, 0.0), axis=1)

    def beyond(r: np.ndarray) -> np.ndarray:  # mixture's light beyond r (N, 3)
        return np.sum(share * np.exp(-r[:, None, :] / d_k), axis=1)

    lo, hi = np.zeros_like(d_mix), np.maximum(d_k.max(axis=1), d_mix) * 10.0
    for _ in range(80):  # bisection: beyond(r) = 0.5 (decreasing in r)
        mid = 0.5 * (lo + hi)
        big = beyond(mid) > 0.5
        lo, hi = np.where(big, mid, lo), np.where(big, hi, mid)
    r50_mix = 0.5 * (lo + hi)
    r = np.full_like(d_mix, tail_mm)
    tail = np.exp(-r / d_mix) / np.maximum(beyond(r), 1e-300)
    return Fidelity(d_mix_mm=d_mix, d_max_mm=d_max, half_light=d_mix * np.log(2.0) / r50_mix, tail=tail)
