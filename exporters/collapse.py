"""Collapse the spectral K-media mixture (376 wavelengths) to the three channels Cycles renders.

Input, per texel: the model's reflectance R(lambda) and its K components (alpha_k, sigma_t,k, g_k, w_k)
(lambda) (docs/contracts.md §3).  Output, per texel, component k and linear-sRGB channel c: a medium
(alpha_kc, sigma_t,kc, g_k) and a weight w_kc such that Cycles' RANDOM_WALK mixture (each path picks
component k, then walks in its medium; blender_addon/nodes.py) shows what the spectral model shows.

What "shows" means, and the method
----------------------------------
1. **Target colour.**  By default (``painted``) T_c = A_c, the painted linear-sRGB albedo of the texel
   (clamped to [0, 1]): what the artist painted is what renders.  With the model's colour (``painted=None``,
   the bake's ``--model-colour``) T_c = sum_lambda M_c(lambda) R(lambda), the linear-sRGB colour of the
   model's reflectance under D65 (``exporters.colorimetry.spectrum_to_linear_srgb``; M_c has negative lobes,
   T is what a viewer sees).
2. **Channel sensitivity.**  omega_c(lambda) = max(M_c(lambda), 0), normalised to sum 1: where channel
   c looks.  Used for every per-channel average below.
3. **Light carried by each component.**  E_k(lambda) = w_k R_model(alpha_k, g_k), with R_model the
   semi-infinite diffuse reflectance at the model's own boundary (n = 1.4 below air, specular excluded:
   ``exporters.reflectance_tables``).  Component k's share of channel c is
   s_kc = <omega_c, E_k> / sum_j <omega_c, E_j>  (sums to 1 over k).  With the painted colour, E_k is
   that of the painted spectral media (exporters.painted: E_k times a smooth, bounded correction c(lambda)
   whose mixture has the colour A at the model's boundary), so the Cycles channels split the light as the
   painted spectral mixture does.
4. **Reflectance.**  Cycles' walk has no Fresnel boundary, so the same alpha would render brighter than
   the model's medium.  Each component gets the Cycles albedo whose Cycles reflectance carries its share:
   w_kc R_cycles(alpha_kc, g_k) = s_kc T_c, with w_kc = <omega_c, w_k> (the channel's mean weight) and
   R_cycles the diffuse reflectance Cycles renders for the closure IOR ``ior`` (Snell refraction of the
   view ray, no Fresnel weight, Lambertian exit: ``reflectance_tables``, "cycles").  Summed over k this
   is exactly T_c.  Cycles' walk is exact only for alpha >= 0.2 and loses energy near alpha -> 1 (it
   kills walks after 256 bounces; from bounce 10 on it walks the similar isotropic medium of albedo
   alpha* = alpha (1 - g) / (1 - alpha g)), so alpha_kc is kept in [0.2, alpha_soft(g)], alpha_soft the
   albedo with alpha* = 0.99 (measured loss 0.1 %; at alpha* = 0.997 it is 1.4 %, at 0.9999 7 %): a
   darker share keeps alpha = 0.2 and lowers w_kc, a brighter one keeps alpha_soft and raises w_kc (up to
   1, Cycles' Mix Shader limit; beyond that alpha may rise to 1 - 1e-6 and texels that still miss T are
   counted in ``unreachable``).  The profile width does not depend on this split (step 6).  Weights then sum to
   at most 1 per channel (the rest is absorbed), or above 1 when a bright share needs it.
   With the painted colour the lower bound is alpha*(g) (:func:`face_on_albedo`) instead of 0.2: under the
   node group's coat, a walk of lower albedo renders face-on (a camera straight above, the artist's check
   against a Diffuse BSDF) up to 15 % darker than its reflectance averaged over view directions, a higher one
   up to 5 % brighter; at alpha* both agree, so the painted colour holds face-on and on average.  The share
   goes into the weight (the profile width is kept, step 6: at a fixed diffusion length the median exit
   radius changes by at most ~25 % between alpha 0.4 and 0.98), and walks get longer (~1 / (1 - alpha*)).
5. **Anisotropy.**  One g per component (Cycles takes one per closure; docs/contracts.md §4 stores one channel):
   the light-weighted mean of g_k over the visible channels, capped at :data:`G_MAX` = 0: every component
   renders as its similar isotropic medium, with the reflectance of step 4 solved at g = 0 and the
   diffusion length of step 6 kept (mu_a and the reduced scattering mu_s (1 - g) are what set both).  Why 0
   and not the largest g Cycles walks accurately (0.7, exporters.cycles.RECOMMENDED_G_MAX): render cost.  At
   g = 0.7 the painted colour needs alpha >= 0.987 (step 4's face-on floor; alpha* 0.958), at g = 0 only
   alpha >= 0.91, and Cycles' walk takes sigma_t = 1 / (d (1 - g)), 3.3x denser steps for its first 10
   events: on the demo head the live group's CPU time per sample went from 3.3x to 1.3x Principled Random
   Walk (Skin)'s with the same coat (training.bench.render_cost, before and after this choice).  What is
   given up is the anisotropy of the first scattering events (Cycles itself walks the similar isotropic
   medium from its 10th event on): the colour is still solved for (step 4, diffuse light and the face-on
   view) and the diffusion length kept (step 6), but the reflectance's angular shape and the profile's
   first tens of micrometres are those of an isotropic medium.
6. **Profile width.**  The spatial spread of component k's light is set by its diffusion length
   D = 1 / sigma_tr, sigma_tr = sigma_t sqrt(3 (1 - alpha)(1 - alpha g)) (the decay rate of the
   diffusion profile, in cm).  Its light-weighted channel mean D_kc = <omega_c, E_k D_k> / <omega_c, E_k>
   is kept: sigma_t,kc = 1 / (D_kc sqrt(3 (1 - alpha_kc)(1 - alpha_kc g_k))).  So changing alpha to
   match the boundary does not change how far light bleeds.
7. **Resolvable mean free path.**  Cycles walks in float32 from an entry point whose position error
   grows with the camera distance (~1e-7 of it): with a mean free path of 1 um (sigma_t = 1e4 cm^-1,
   the model's densest components) a probe 10 units away rendered +84 % too bright, at 1000 units +400 %.
   sigma_t is therefore capped at 1 / ``min_mfp_cm`` (default 10 um): the reflectance (alpha) is
   unchanged, the profile of such a component widens to ~10-30 um, far below any pixel.

All arrays are float64; every output is finite for finite input (non-finite input raises ValueError).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path

import numpy as np

from . import cycles, painted, reflectance_tables
from .colorimetry import xyz_to_linear_srgb_matrix, xyz_weights
from .constants import N_WAVELENGTHS

#: Cycles' walk substitutes alpha < 0.2 (integrator/subsurface_random_walk.h), so we never ask for less.
ALPHA_MIN: float = cycles.ALPHA_EXACT_MIN
#: Highest isotropic-equivalent albedo alpha* = alpha (1 - g) / (1 - alpha g) used while the weight can still
#: grow.  Measured (Cycles 5.0.1, IOR 1.4, diffuse average, 512 spp) against the adding-doubling table:
#: g = 0: alpha 0.99 -0.1 %, 0.997 -1.4 %, 0.999 -3.5 %, 0.9999 -6.8 %; g = 0.7: alpha 0.997 (alpha* 0.990)
#: +0.9 %, 0.9995 (alpha* 0.998) -1.7 %: the loss follows alpha*, i.e. the walk after the similarity switch.
ALPHA_STAR_SOFT_MAX: float = 0.99
#: Absolute ceiling (a component that is brighter than this even at weight 1 is unreachable).
ALPHA_HARD_MAX: float = reflectance_tables.ALPHA_TABLE_MAX
#: Anisotropy of the rendered components: the similar isotropic medium (step 5 of the module docstring).
G_MAX: float = 0.0
#: Smallest mean free path given to Cycles (cm): 10 um (step 7 of the module docstring).
MIN_MFP_CM: float = 1e-3
#: Largest weight a Cycles Mix Shader passes (its Fac is clamped to [0, 1]).
WEIGHT_MAX: float = 1.0
_TINY = 1e-30


#: M of :func:`channel_matrix`, stored so that the add-on needs no colour-science inside Blender (whose
#: Python lacks it and scipy); tests/test_collapse.py checks it against exporters.colorimetry.
CHANNEL_MATRIX_PATH = Path(__file__).resolve().parent / "data" / "linear_srgb_d65_weights.npy"


def compute_channel_matrix() -> np.ndarray:
    """M (3, 376) from exporters.colorimetry (colour-science): XYZ-to-linear-sRGB matrix times the D65 CMF
    weights.  ``python -m training channel-matrix`` writes it to CHANNEL_MATRIX_PATH."""
    return xyz_to_linear_srgb_matrix("D65") @ xyz_weights("D65")


@cache
def channel_matrix() -> np.ndarray:
    """M (3, 376): linear sRGB (D65) = M @ R for a reflectance spectrum R on the project grid."""
    m = np.load(CHANNEL_MATRIX_PATH) if CHANNEL_MATRIX_PATH.is_file() else compute_channel_matrix()
    if m.shape != (3, N_WAVELENGTHS):
        raise RuntimeError(f"{CHANNEL_MATRIX_PATH} holds shape {m.shape}, expected (3, {N_WAVELENGTHS})")
    m.setflags(write=False)
    return m


@cache
def channel_weights() -> np.ndarray:
    """omega (3, 376): max(M_c, 0) normalised to sum 1 per channel (where each channel looks)."""
    w = np.maximum(channel_matrix(), 0.0)
    w = w / w.sum(axis=1, keepdims=True)
    w.setflags(write=False)
    return w


@cache
def _support() -> np.ndarray:
    """Wavelength indices where any channel weight is non-zero (the rest never matters)."""
    return np.flatnonzero(channel_weights().sum(axis=0) > 0.0)


@dataclass(frozen=True)
class ChannelMedia:
    """Per texel (N), component (K) and channel (3): the media Cycles walks and their weights.

    ``alpha`` (N, K, 3) single-scattering albedo; ``sigma_t_cm`` (N, K, 3) extinction in cm^-1; ``g``
    (N, K) anisotropy; ``weight`` (N, K, 3); ``target`` (N, 3) the linear-sRGB channel reflectance the
    mixture reproduces (sum_k weight R_cycles(alpha, g) = target where reachable); ``low``/``high`` (N, K, 3)
    shares clamped at alpha = 0.2 / raised weight; ``unreachable`` (N, 3) channels brighter than Cycles
    can show with weights <= 1; ``mfp_capped`` (N, K, 3) extinction capped at 1 / min_mfp_cm;
    ``spectral_clamped`` (N,) with the painted colour: texels whose painted spectral media miss the painted
    colour (exporters.painted; None for the model's colour).
    """

    alpha: np.ndarray
    sigma_t_cm: np.ndarray
    g: np.ndarray
    weight: np.ndarray
    target: np.ndarray
    low: np.ndarray
    high: np.ndarray
    unreachable: np.ndarray
    mfp_capped: np.ndarray | None = None
    ior: float = reflectance_tables.CYCLES_IOR
    spectral_clamped: np.ndarray | None = None

    def cycles_reflectance(self) -> np.ndarray:
        """(N, 3): sum_k weight R_cycles(alpha, g), the diffuse reflectance these media render in Cycles."""
        r = reflectance_tables.reflectance("cycles", self.alpha, self.g[..., None], self.ior)
        return np.sum(self.weight * r, axis=1)


def _finite(name: str, x, dtype=np.float64) -> np.ndarray:
    arr = np.asarray(x, dtype=dtype)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: NaN or infinite value(s); the model output must be finite")
    return arr


def _check_shapes(reflectance, alpha, sigma_t, g, weight) -> None:
    n, k, nl = alpha.shape
    if nl != N_WAVELENGTHS or reflectance.shape != (n, nl):
        raise ValueError(f"expected reflectance (N, {N_WAVELENGTHS}) and components (N, K, {N_WAVELENGTHS}), got "
                         f"{reflectance.shape} and {alpha.shape}")
    for name, arr in (("sigma_t", sigma_t), ("g", g), ("weight", weight)):
        if arr.shape != alpha.shape:
            raise ValueError(f"{name} has shape {arr.shape}, alpha {alpha.shape}")
    if np.any((alpha < 0) | (alpha > 1)) or np.any(sigma_t <= 0) or np.any(np.abs(g) >= 1) or np.any(weight < 0):
        raise ValueError("need alpha in [0, 1], sigma_t > 0, |g| < 1 and weight >= 0")


def collapse(reflectance, alpha, sigma_t_cm, g, weight, painted_rgb=None, g_max: float = G_MAX,
             ior: float = reflectance_tables.CYCLES_IOR, min_mfp_cm: float = MIN_MFP_CM) -> ChannelMedia:
    """Collapse spectral mixtures to per-channel Cycles media (method: module docstring).

    ``reflectance`` (N, 376); ``alpha``, ``sigma_t_cm`` (cm^-1), ``g``, ``weight`` (N, K, 376) as the model
    outputs them; ``painted_rgb`` (N, 3): the painted linear-sRGB albedo the channels reproduce (None: the
    colour of the model's reflectance); ``ior``: the IOR of the Cycles closures (the node group's IOR
    input), which sets how the view ray enters the medium; ``min_mfp_cm``: the smallest mean free path
    handed to Cycles (step 7; 0 disables the cap).
    """
    refl = _finite("reflectance", reflectance)
    # The per-wavelength work runs in float32 (the model's own precision; sums of 236 terms keep ~1e-6).
    al, st, gg, w = (_finite(n, x, np.float32) for n, x in (("alpha", alpha), ("sigma_t", sigma_t_cm), ("g", g),
                                                              ("weight", weight)))
    if al.ndim != 3:
        raise ValueError(f"alpha must have shape (N, K, {N_WAVELENGTHS}), got {al.shape}")
    _check_shapes(refl, al, st, gg, w)
    if painted_rgb is None:
        target = np.maximum(refl @ channel_matrix().T, 0.0)  # (N, 3)
    else:
        target = painted.target_colour(painted_rgb)
        if target.shape != (len(refl), 3):
            raise ValueError(f"painted_rgb must have shape ({len(refl)}, 3), got {target.shape}")
    sup = _support()
    omega = channel_weights()[:, sup].astype(np.float32).T  # (L', 3)
    al, st, gg, w = al[..., sup], st[..., sup], gg[..., sup], w[..., sup]
    al_c, g_c, light = _light(al, gg, w)
    spectral_clamped = None
    if painted_rgb is not None:  # the painted spectral media's light (exporters.painted)
        light, spectral_clamped = _painted_light(light, w, g_c, target)
    diff_len = 1.0 / (st * np.sqrt(3.0 * (1.0 - al_c) * (1.0 - al_c * gg)))  # D_k in cm, (N, K, L')
    # One matrix product for all six channel averages: E, w, E D, w D, E g, w g against omega.
    sums = (np.stack([light, w, light * diff_len, w * diff_len, light * gg, w * gg]) @ omega).astype(np.float64)
    share_raw, w_mean, light_d, w_d, light_g, w_g = sums  # each (N, K, 3)
    # Channels where a component carries no light (E = 0): fall back to weight-weighted means.
    dark = share_raw <= _TINY
    d_mean = np.where(dark, w_d / np.maximum(w_mean, _TINY), light_d / np.maximum(share_raw, _TINY))
    fallback = np.repeat(diff_len.mean(axis=2, dtype=np.float64)[..., None], 3, axis=2)  # weight 0 everywhere
    d_mean = np.where(np.isfinite(d_mean) & (d_mean > 0), d_mean, fallback)
    total = share_raw.sum(axis=1, keepdims=True)
    share = np.where(total > _TINY, share_raw / np.maximum(total, _TINY), w_mean)
    light_all = share_raw.sum(axis=2)  # (N, K)
    g_light = light_g.sum(axis=2) / np.maximum(light_all, _TINY)
    g_weight = w_g.sum(axis=2) / np.maximum(w_mean.sum(axis=2), _TINY)
    g_eff = np.clip(np.where(light_all > _TINY, g_light, g_weight), cycles.G_MIN, g_max)
    if min_mfp_cm < 0:
        raise ValueError("min_mfp_cm must be >= 0")
    media = _solve_channels(share * target[:, None, :], w_mean, g_eff, d_mean, target, ior, min_mfp_cm,
                            face_on=painted_rgb is not None)
    return replace(media, spectral_clamped=spectral_clamped)


def _light(al: np.ndarray, gg: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(alpha, g clipped to the tables, E_k = w_k R_model(alpha_k, g_k)) of float32 components (N, K, L')."""
    al_c = np.minimum(al, np.float32(reflectance_tables.ALPHA_TABLE_MAX))
    g_c = np.clip(gg, np.float32(0), np.float32(reflectance_tables.G_TABLE_MAX))
    return al_c, g_c, w * reflectance_tables.reflectance("model", al_c, g_c)


def _painted_light(light: np.ndarray, w: np.ndarray, g_c: np.ndarray, target: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The light E'_k (N, K, L') of the painted spectral media on the support (exporters.painted) and which
    texels (N,) miss the painted colour."""
    sup = _support()
    cap = w * painted.brightest(g_c).astype(np.float32)
    corr = painted.solve(light, cap, channel_matrix()[:, sup], target, columns=sup)
    return np.minimum(corr.factor(sup).astype(np.float32)[:, None, :] * light, cap), corr.clamped


def painted_clamped(alpha, g, weight, painted_rgb) -> np.ndarray:
    """(N,) bool: texels whose painted colour (N, 3) the painted spectral media of the components (N, K, 376)
    cannot take (exporters.painted; what ``collapse(..., painted_rgb)`` reports as ``spectral_clamped``)."""
    sup = _support()
    al, gg, w = (_finite(n, x, np.float32)[..., sup] for n, x in (("alpha", alpha), ("g", g), ("weight", weight)))
    _, g_c, light = _light(al, gg, w)
    return _painted_light(light, w, g_c, painted.target_colour(painted_rgb))[1]


@cache
def _face_on_nodes(ior: float) -> np.ndarray:
    """alpha* (N_G,) at the reflectance tables' g nodes for closure IOR ``ior`` (:func:`face_on_albedo`)."""
    u = reflectance_tables.u_grid()
    alpha = 1.0 - u**2  # decreasing along the grid
    coat = float(cycles.coat_body_scale(1.0, ior)) if ior > 1.0 else 1.0
    out = np.full(reflectance_tables.N_G, ALPHA_MIN)
    for i, g in enumerate(reflectance_tables.g_grid()):
        mean = reflectance_tables.reflectance("cycles", alpha, g, ior)
        face_on = coat * reflectance_tables.normal_reflectance(alpha, g)
        ratio = np.divide(face_on, mean, out=np.ones_like(mean), where=mean > 0.0) - 1.0
        below = np.flatnonzero(ratio < 0.0)  # face-on darker than the mean: these albedos are too low
        if below.size == 0 or below[0] == 0:
            continue  # no crossing (face-on never or always as bright): no floor
        j = below[0]  # ratio[j - 1] >= 0 > ratio[j]: interpolate in u
        f = ratio[j - 1] / (ratio[j - 1] - ratio[j])
        out[i] = max(ALPHA_MIN, 1.0 - (u[j - 1] + f * (u[j] - u[j - 1])) ** 2)
    out.setflags(write=False)
    return out


def face_on_albedo(g, ior: float = reflectance_tables.CYCLES_IOR) -> np.ndarray:
    """alpha*(g): the albedo at which Cycles' walk under the node group's coat renders face-on what it renders
    on average over view directions, (1 - F(1)) / (1 - F_dr) R1(alpha, g; mu = 1) = H(alpha, g; ior).

    Below it a medium looks darker from straight above than its (cosine-weighted) reflectance, by up to ~15 %
    at alpha 0.6 (the view ray enters along the normal and is absorbed deeper); above it a little brighter
    (up to the coat's face-on 1 - F(1) over 1 - F_dr, 5 % at IOR 1.4).  0.91 at g = 0, 0.976 at g = 0.5,
    0.987 at g = 0.7 (IOR 1.4); ALPHA_MIN where no albedo balances (IOR near 1: no coat)."""
    gg = np.clip(np.asarray(g, np.float64), 0.0, (reflectance_tables.N_G - 1) * reflectance_tables.G_STEP)
    return np.interp(gg, reflectance_tables.g_grid(), _face_on_nodes(round(float(ior), 6)))


def alpha_soft_max(g) -> np.ndarray:
    """The albedo whose similar isotropic medium has albedo ALPHA_STAR_SOFT_MAX, for anisotropy g."""
    gg = np.asarray(g, dtype=np.float64)
    return ALPHA_STAR_SOFT_MAX / (1.0 - gg + ALPHA_STAR_SOFT_MAX * gg)


def _solve_channels(contribution, w_mean, g_eff, d_mean, target, ior: float, min_mfp_cm: float,
                    face_on: bool = False) -> ChannelMedia:
    """Per (N, K, 3): alpha and weight with w R_cycles(alpha, g) = contribution; sigma_t from D.  ``face_on``:
    albedos at least face_on_albedo(g) (step 4)."""
    g3 = np.broadcast_to(g_eff[..., None], contribution.shape)
    a_soft = alpha_soft_max(g3)
    a_lo = np.minimum(face_on_albedo(g3, ior), a_soft) if face_on else ALPHA_MIN
    r_lo = reflectance_tables.reflectance("cycles", a_lo, g3, ior)
    r_soft = reflectance_tables.reflectance("cycles", a_soft, g3, ior)
    r_hard = reflectance_tables.reflectance("cycles", ALPHA_HARD_MAX, g3, ior)
    used = w_mean > 1e-12
    rho = np.where(used, contribution / np.maximum(w_mean, 1e-12), 0.0)
    rho_c = np.clip(rho, r_lo, r_soft)
    weight = np.where(used | (contribution > 0), contribution / rho_c, 0.0)
    over = weight > WEIGHT_MAX
    rho_over = np.clip(contribution, r_lo, r_hard)  # weight 1: reflectance must carry all of it
    rho_c = np.where(over, rho_over, rho_c)
    weight = np.where(over, np.minimum(contribution / rho_c, WEIGHT_MAX), weight)
    alpha = reflectance_tables.albedo_for_reflectance("cycles", rho_c, g3, ior)
    alpha = np.clip(alpha, ALPHA_MIN, ALPHA_HARD_MAX)
    sigma_t = 1.0 / (d_mean * np.sqrt(3.0 * (1.0 - alpha) * (1.0 - alpha * g3)))
    capped = sigma_t * min_mfp_cm > 1.0
    sigma_t = np.where(capped, 1.0 / max(min_mfp_cm, 1e-300), sigma_t)
    low = used & (rho < r_lo)
    high = weight > w_mean * (1.0 + 1e-9)
    reached = np.sum(weight * reflectance_tables.reflectance("cycles", alpha, g3, ior), axis=1)
    unreachable = reached < target * (1.0 - 1e-3)
    out = ChannelMedia(alpha=alpha, sigma_t_cm=sigma_t, g=np.array(g_eff), weight=weight, target=target, low=low,
                       high=high, unreachable=unreachable, mfp_capped=capped, ior=float(ior))
    for name in ("alpha", "sigma_t_cm", "g", "weight"):
        if not np.all(np.isfinite(getattr(out, name))):
            raise RuntimeError(f"collapse produced non-finite {name}")  # guarded above; never expected
    return out


@dataclass(frozen=True)
class CyclesMaps:
    """Node inputs per texel and component (``--target cycles``): color, radius (Blender units), weight
    (N, K, 3) and anisotropy (N, K)."""

    color: np.ndarray
    radius: np.ndarray
    weight: np.ndarray
    anisotropy: np.ndarray


def to_cycles(media: ChannelMedia, unit_scale_m: float = 1.0) -> CyclesMaps:
    """RANDOM_WALK inputs (Scale = 1) for ``media``: Color = f^-1(alpha; g), radius = 4 pi / (sigma_t (1 - g))
    in Blender units of ``unit_scale_m`` metres (exporters.cycles.medium_to_cycles)."""
    g3 = np.broadcast_to(media.g[..., None], media.alpha.shape)
    cin = cycles.medium_to_cycles(media.alpha, media.sigma_t_cm, g3, unit_scale_m=unit_scale_m, g_max=cycles.G_MAX)
    return CyclesMaps(color=cin.color, radius=cin.radius, weight=media.weight, anisotropy=np.array(media.g))
