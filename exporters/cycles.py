"""Cycles random-walk subsurface scattering: physical medium <-> node inputs (numpy only).

Cycles (Blender 5.0.1, ``RANDOM_WALK`` method of the Subsurface Scattering node and of OSL
``bssrdf("random_walk", ...)``) does not take a medium directly.  Per RGB channel it takes a
*Subsurface Color* ``A`` (the closure albedo) and a *radius* ``r`` (Blender units), plus one
anisotropy ``g`` per closure, and turns them into a homogeneous medium inside the mesh
(kernel sources shipped in the bpy wheel, ``cycles/source/kernel/``):

* ``closure/bssrdf.h`` ``bssrdf_setup``: ``g`` clamped to [0, 0.9]; channels with ``r < 1e-8`` are
  dropped to a Lambertian diffuse closure; ``bssrdf_setup_radius``: ``d = r / (4 pi)`` for RANDOM_WALK.
* ``integrator/subsurface_random_walk.h`` ``subsurface_random_walk_remap``:
  ``sigma_t = 1 / (max(d, 1e-16) (1 - g))`` and the single-scattering albedo
  ``alpha = f(A, g)``, an empirical fit (Chiang et al. 2016, anisotropic extension by Wrenninge et al.)
  clamped to [0, 0.999999]; ``subsurface_random_walk_coefficients``: ``alpha < 0.2`` is replaced by
  0.2 with the throughput scaled by ``alpha / 0.2`` (an approximation, not the same medium).
* The walk uses Henyey-Greenstein(g) for the first 10 scattering events and the similarity-transformed
  isotropic medium afterwards; it stops after 256 events (energy loss when alpha -> 1).

This module writes the forward map ``f`` (re-typed from the kernel: no library exposes it) and its
inverse, and the radius <-> extinction map including unit conversion.  All functions take arrays of any
(broadcastable) shape, compute in float64 and raise ``ValueError`` on NaN/Inf input.

Units: sigma_t in cm^-1 (docs/contracts.md §1); radii in Blender units; ``unit_scale_m`` is metres per Blender unit
(``scene.unit_settings.scale_length``; 1.0 by default).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# --- Constants of the Cycles 5.0.1 kernel (file in cycles/source/kernel/) --------------------------------
#: ``bssrdf_setup`` clamps the anisotropy of every BSSRDF closure to this range (closure/bssrdf.h).
G_MIN: float = 0.0
G_MAX: float = 0.9
#: ``subsurface_random_walk_remap`` clamps the single-scattering albedo to at most this value.
ALPHA_MAX: float = 0.999999
#: Below this single-scattering albedo the walk substitutes 0.2 and rescales throughput (approximate).
ALPHA_EXACT_MIN: float = 0.2
#: ``BSSRDF_MAX_BOUNCES`` (kernel/types.h): walks longer than this are killed.
MAX_BOUNCES: int = 256
#: ``BSSRDF_MIN_RADIUS`` (kernel/types.h): smaller radii turn the channel into a diffuse BSDF.
MIN_RADIUS: float = 1e-8
#: ``bssrdf_setup_radius``: RANDOM_WALK diffusion length d = r * 0.25 / pi.
RADIUS_TO_D: float = 0.25 / np.pi
#: ``SUBSURFACE_RANDOM_WALK_SIMILARITY_LEVEL``: events 0..9 use HG(g), later ones the similar g=0 medium.
SIMILARITY_LEVEL: int = 9
#: Largest g at which Cycles 5.0.1's anisotropic walk reproduces the medium to ~1% (measured here against
#: iadpython adding-doubling, normal incidence, semi-infinite, 1024 spp; see tests/test_cycles_render.py).
#: Above it the walk is biased high: +3.4% (g=0.8) and +18% (g=0.9) at alpha=0.99.  The similarity
#: transform down to 0.7 costs at most ~1.3% (alpha=0.99, g=0.9; ~0% for diffuse illumination), so
#: :func:`medium_to_cycles` moves larger g down to this value by default.
RECOMMENDED_G_MAX: float = 0.7
#: cm per metre, for sigma_t [cm^-1] -> [m^-1].
CM_PER_M: float = 100.0

# Polynomial coefficients of subsurface_random_walk_remap, lowest order first (g^0 .. g^7).
_POLY_A = (1.8260523782, -1.28451056436, -1.79904629312, 9.19393289202, -22.8215585862, 32.0234874259,
           -23.6264803333, 7.21067002658)
_EXP_B = (0.0, 31.1491581433, -201.847017512, 841.576016723, -2018.09288505, 2731.71560286, -1935.41424244,
          559.009054474)
_POLY_C = (1.09686102424, -0.394704063468, 1.05258115941, -8.83963712726, 28.8643230661, -46.8802913581,
           38.5402837518, -12.7181042538)
_POLY_D = (0.496310210422, 0.360146581622, -2.15139309747, 17.8896899217, -55.2984010333, 82.065982243,
           -58.5106008578, 15.8478295021)
_EXP_E = (0.0, 76.7316253952, -594.356773233, 2448.8834203, -5576.68528998, 7116.60171912, -4763.54467887,
          1303.5318055)
_POLY_F = (2.40602999408, -2.51814844609, 9.18494908356, -79.2191708682, 259.082868209, -403.613804597,
           302.85712436, -87.4370473567)


def _finite(name: str, x) -> np.ndarray:
    """``x`` as a float64 array; ValueError naming ``name`` if any element is NaN or infinite."""
    arr = np.asarray(x, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
        raise ValueError(f"{name}: {bad} NaN or infinite value(s); all inputs must be finite")
    return arr


def _poly(coeffs: tuple[float, ...], g: np.ndarray) -> np.ndarray:
    return np.polynomial.polynomial.polyval(g, coeffs)


def _fit_coefficients(g: np.ndarray) -> tuple[np.ndarray, ...]:
    """The six g-dependent coefficients A..F of ``subsurface_random_walk_remap`` (float64)."""
    return (
        _poly(_POLY_A, g),
        4.98511194385 + 0.127355959438 * np.exp(_poly(_EXP_B, g)),
        _poly(_POLY_C, g),
        _poly(_POLY_D, g),
        4.23190299701 + 0.00310603949088 * np.exp(_poly(_EXP_E, g)),
        _poly(_POLY_F, g),
    )


def _check_g(g: np.ndarray) -> None:
    if np.any((g < G_MIN) | (g > G_MAX)):
        raise ValueError(
            f"anisotropy g must lie in [{G_MIN}, {G_MAX}] (Cycles clamps it there); "
            "use similar_medium() to move other g into that range"
        )


def _f_unclamped(color: np.ndarray, coeffs: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Unclamped fit f(A) and df/dA for A >= 0 (derivative is +inf at A = 0)."""
    pa, pb, pc, pd, pe, pf = coeffs
    with np.errstate(divide="ignore", invalid="ignore"):
        blend = color**0.25
        dblend = 0.25 * color ** (-0.75)
        at_b = np.arctan(pb * color)
        at_e = np.arctan(pe * color)
        t1 = pa * at_b**pc
        t2 = pd * at_e**pf
        dt1 = pa * pc * at_b ** (pc - 1.0) * pb / (1.0 + (pb * color) ** 2)
        dt2 = pd * pf * at_e ** (pf - 1.0) * pe / (1.0 + (pe * color) ** 2)
        value = (1.0 - blend) * t1 + blend * t2
        deriv = dblend * (t2 - t1) + (1.0 - blend) * dt1 + blend * dt2
    return value, deriv


def rw_albedo_forward(color, g) -> np.ndarray:
    """Cycles' map Subsurface Color A -> single-scattering albedo alpha (RANDOM_WALK), float64.

    ``color``: closure albedo A per channel, in [0, 1]; ``g``: anisotropy in [0, 0.9], broadcastable.
    Returns alpha = clamp(f(A, g), 0, 0.999999) exactly as ``subsurface_random_walk_remap`` (evaluated in
    float64; the kernel uses float32, which differs by ~1e-7).  The kernel's later substitution of
    alpha < 0.2 (approximate walk) is *not* applied here: this is the medium Cycles aims at.
    """
    a = _finite("color", color)
    gg = _finite("g", g)
    if np.any((a < 0.0) | (a > 1.0)):
        raise ValueError("color (Subsurface Color) must lie in [0, 1]")
    _check_g(gg)
    value, _ = _f_unclamped(a, _fit_coefficients(gg))
    return np.clip(value, 0.0, ALPHA_MAX)


def _solve(target: np.ndarray, coeffs: tuple[np.ndarray, ...], lo: np.ndarray, hi: np.ndarray,
           max_iter: int = 200) -> np.ndarray:
    """Safeguarded Newton for f(A) = target on [lo, hi] where f(lo) <= target <= f(hi), f increasing.

    Newton steps that leave the current bracket are replaced by bisection, so every element converges.
    An element stops when its residual is within 4 eps (f is an albedo in [0, 1]), its step is within
    16 ulp, or its bracket is within 16 ulp; only unfinished elements are iterated (1-D index compaction).
    All inputs are 1-D arrays of one length.
    """
    x = 0.5 * (lo + hi)
    lo, hi = lo.copy(), hi.copy()
    active = np.arange(target.size)
    co = coeffs
    for _ in range(max_iter):
        xa, la, ha, ta = x[active], lo[active], hi[active], target[active]
        val, der = _f_unclamped(xa, co)
        resid = val - ta
        below = resid < 0.0
        la = np.where(below, xa, la)
        ha = np.where(below, ha, xa)
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = xa - resid / der
        ok = np.isfinite(newton) & (newton >= la) & (newton <= ha)
        xn = np.where(ok, newton, 0.5 * (la + ha))
        tol = 16.0 * np.spacing(np.maximum(np.abs(xa), 1e-300))
        small = np.abs(resid) <= 4.0 * np.finfo(np.float64).eps
        x[active], lo[active], hi[active] = np.where(small, xa, xn), la, ha
        keep = ~(small | (np.abs(xn - xa) <= tol) | (ha - la <= tol))
        active = active[keep]
        co = tuple(c[keep] for c in co)
        if active.size == 0:
            break
    return x


def _per_unique_g(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique anisotropies and the inverse index (most maps use a handful of g values)."""
    uniq, inverse = np.unique(g.ravel(), return_inverse=True)
    return uniq, inverse


def _saturation_unique(g_unique: np.ndarray) -> np.ndarray:
    coeffs = _fit_coefficients(g_unique)
    n = g_unique.size
    return _solve(np.full(n, ALPHA_MAX), coeffs, np.zeros(n), np.ones(n))


def saturation_color(g) -> np.ndarray:
    """Smallest Subsurface Color at which Cycles' alpha saturates at 0.999999, for anisotropy g.

    About 0.918 (g=0), 0.857 (g=0.5), 0.702 (g=0.9).  Colours above it all give the same medium.
    """
    gg = _finite("g", g)
    _check_g(gg)
    uniq, inverse = _per_unique_g(gg)
    return _saturation_unique(uniq)[inverse].reshape(gg.shape)


@dataclass(frozen=True)
class AlbedoInversion:
    """Result of :func:`rw_albedo_inverse`; all arrays have the broadcast shape of (alpha, g).

    ``color``: the Subsurface Color in [0, saturation_color(g)].
    ``saturated``: alpha was above 0.999999 (Cycles' cap); colour set to the saturation colour.
    ``approximate``: alpha < 0.2: the colour is the exact preimage, but Cycles' walk then replaces alpha
    by 0.2 and rescales the throughput, which is not the same medium (close for a dark medium).
    """

    color: np.ndarray
    saturated: np.ndarray
    approximate: np.ndarray


def rw_albedo_inverse(alpha, g) -> AlbedoInversion:
    """Subsurface Color A such that Cycles' RANDOM_WALK walk uses single-scattering albedo ``alpha``.

    ``alpha`` in [0, 1] and ``g`` in [0, 0.9] (broadcastable).  f is strictly increasing on
    [0, saturation_color(g)] (checked on a dense grid in the tests), so the preimage is unique; it is found
    by safeguarded Newton in float64 to a few ulp.  Representable range: [0, 0.999999]; above it the colour
    is clamped to the saturation colour with ``saturated`` set (never NaN).  Values in [0, 0.2) are inverted
    exactly but flagged ``approximate`` (see :class:`AlbedoInversion`).
    """
    al = _finite("alpha", alpha)
    gg = _finite("g", g)
    if np.any((al < 0.0) | (al > 1.0)):
        raise ValueError("alpha (single-scattering albedo) must lie in [0, 1]")
    _check_g(gg)
    al, gg = np.broadcast_arrays(al, gg)
    saturated = al > ALPHA_MAX
    target = np.minimum(al, ALPHA_MAX).ravel()
    uniq, inverse = _per_unique_g(gg)
    hi = _saturation_unique(uniq)[inverse]
    coeffs = tuple(c[inverse] for c in _fit_coefficients(uniq))
    color = _solve(target, coeffs, np.zeros(target.size), hi.copy())
    color = np.where(saturated.ravel(), hi, np.where(target == 0.0, 0.0, color)).reshape(al.shape)
    return AlbedoInversion(color=color, saturated=saturated, approximate=al < ALPHA_EXACT_MIN)


# --- Extinction <-> radius ---------------------------------------------------------------------------------


def _check_scale(unit_scale_m) -> np.ndarray:
    s = _finite("unit_scale_m", unit_scale_m)
    if np.any(s <= 0.0):
        raise ValueError("unit_scale_m (metres per Blender unit) must be > 0")
    return s


def sigma_t_to_blender(sigma_t_cm, unit_scale_m=1.0) -> np.ndarray:
    """Extinction in cm^-1 -> per Blender unit (1 BU = unit_scale_m metres)."""
    return _finite("sigma_t_cm", sigma_t_cm) * CM_PER_M * _check_scale(unit_scale_m)


def rw_radius_from_sigma_t(sigma_t_cm, g, unit_scale_m=1.0) -> np.ndarray:
    """RANDOM_WALK radius (Blender units, with Scale = 1) giving extinction ``sigma_t_cm`` at anisotropy g.

    Inverts d = r/(4 pi) and sigma_t = 1/(d (1-g)):  r = 4 pi / (sigma_t[BU^-1] (1 - g)).  ``sigma_t_cm`` > 0
    in cm^-1; ``g`` in [0, 0.9].  Radii below Cycles' 1e-8 minimum (which would turn the channel into a
    diffuse BSDF) raise ValueError: use a larger unit scale or a smaller extinction.
    """
    if np.any(_finite("sigma_t_cm", sigma_t_cm) <= 0.0):
        raise ValueError("sigma_t must be > 0")
    with np.errstate(over="ignore", under="ignore", divide="ignore"):
        st = sigma_t_to_blender(sigma_t_cm, unit_scale_m)
        gg = _finite("g", g)
        _check_g(gg)
        r = 4.0 * np.pi / (st * (1.0 - gg))
    if not np.all(np.isfinite(r)):
        raise ValueError("radius overflow: sigma_t too small for float64")
    if np.any(r < MIN_RADIUS):
        raise ValueError(f"radius below Cycles' minimum {MIN_RADIUS} BU: the channel would become diffuse")
    return r


def rw_sigma_t_from_radius(radius_bu, g, unit_scale_m=1.0) -> np.ndarray:
    """Cycles' forward map: extinction (cm^-1) of the walk for RANDOM_WALK radius (BU, Scale=1) and g."""
    r = _finite("radius_bu", radius_bu)
    gg = _finite("g", g)
    _check_g(gg)
    if np.any(r < MIN_RADIUS):
        raise ValueError(f"radius must be >= Cycles' minimum {MIN_RADIUS} BU")
    d = np.maximum(r * RADIUS_TO_D, 1e-16)
    return 1.0 / (d * (1.0 - gg)) / (CM_PER_M * _check_scale(unit_scale_m))


# --- Anisotropy outside Cycles' range ----------------------------------------------------------------------


@dataclass(frozen=True)
class SimilarMedium:
    """A medium moved to another anisotropy by the similarity relation (see :func:`similar_medium`)."""

    alpha: np.ndarray
    sigma_t_cm: np.ndarray
    g: np.ndarray
    changed: np.ndarray


def similar_medium(alpha, sigma_t_cm, g, g_new=None, g_max: float = G_MAX) -> SimilarMedium:
    """Similarity transform (alpha, sigma_t, g) -> (alpha', sigma_t', g') keeping mu_a and mu_s (1 - g).

    Cycles clamps g to [0, 0.9]; skin reaches g > 0.9 above ~965 nm (g(lambda), docs/contracts.md §1).  Instead of
    Cycles clamp g silently (which changes the reduced scattering coefficient, hence the diffuse
    reflectance), g outside [0, g_max] is moved to the nearest bound (or to ``g_new`` when given, e.g. one
    common g for all channels of a closure) with the absorption mu_a = (1-alpha) sigma_t and the reduced
    scattering mu_s (1-g) unchanged.  This is exact in the diffusion limit and is the same relation Cycles
    itself applies after the 10th scattering event.  ``changed`` flags the elements whose g was moved.
    """
    al = _finite("alpha", alpha)
    st = _finite("sigma_t_cm", sigma_t_cm)
    gg = _finite("g", g)
    if np.any((al < 0.0) | (al > 1.0)) or np.any(st <= 0.0) or np.any(np.abs(gg) >= 1.0):
        raise ValueError("need alpha in [0, 1], sigma_t > 0 and |g| < 1")
    if not G_MIN <= g_max <= G_MAX:
        raise ValueError(f"g_max must lie in [{G_MIN}, {G_MAX}]")
    target = np.clip(gg, G_MIN, g_max) if g_new is None else _finite("g_new", g_new) + 0.0 * gg
    if np.any(np.abs(target) >= 1.0):
        raise ValueError("g_new must satisfy |g_new| < 1")
    with np.errstate(over="ignore", under="ignore", divide="ignore", invalid="ignore"):
        mu_a = (1.0 - al) * st
        mu_s_reduced = al * st * (1.0 - gg)
        mu_s_new = mu_s_reduced / (1.0 - target)
        st_new = mu_a + mu_s_new
        al_new = mu_s_new / st_new
    al, st, gg, target, al_new, st_new = np.broadcast_arrays(al, st, gg, target, al_new, st_new)
    changed = target != gg
    if not (np.all(np.isfinite(al_new[changed])) and np.all(np.isfinite(st_new[changed]))
            and np.all(st_new[changed] > 0)):
        raise ValueError("similar_medium: sigma_t too small or too large for float64 (the moved medium under- or "
                         "overflows)")
    return SimilarMedium(alpha=np.where(changed, al_new, al), sigma_t_cm=np.where(changed, st_new, st),
                         g=target.copy(), changed=changed)


@dataclass(frozen=True)
class CyclesInputs:
    """Node inputs for one RANDOM_WALK closure (Scale = 1); arrays share one broadcast shape.

    ``color`` Subsurface Color, ``radius`` in Blender units, ``g`` anisotropy in [0, 0.9];
    flags as in :class:`AlbedoInversion` plus ``g_moved`` (similarity transform applied).
    """

    color: np.ndarray
    radius: np.ndarray
    g: np.ndarray
    saturated: np.ndarray
    approximate: np.ndarray
    g_moved: np.ndarray


def medium_to_cycles(alpha, sigma_t_cm, g, unit_scale_m=1.0, g_common=None,
                     g_max: float = RECOMMENDED_G_MAX) -> CyclesInputs:
    """Physical medium (alpha, sigma_t [cm^-1], g) -> RANDOM_WALK node inputs, float64.

    g outside [0, g_max] (or every g, if ``g_common`` is given) is first moved by :func:`similar_medium`
    (``g_max`` defaults to :data:`RECOMMENDED_G_MAX`, where Cycles' walk is accurate; pass 0.9 for
    Cycles' own limit);
    then Color = f^-1(alpha; g) and radius = 4 pi / (sigma_t (1 - g)) in Blender units.
    """
    sim = similar_medium(alpha, sigma_t_cm, g, g_common, g_max)
    inv = rw_albedo_inverse(sim.alpha, sim.g)
    radius = rw_radius_from_sigma_t(sim.sigma_t_cm, sim.g, unit_scale_m)
    color, radius, gg = np.broadcast_arrays(inv.color, radius, sim.g)
    return CyclesInputs(color=color, radius=radius, g=gg, saturated=inv.saturated,
                        approximate=inv.approximate, g_moved=sim.changed)


# --- Specular coat over the subsurface mixture (blender_addon/nodes.py) -----------------------------------

#: Hemispherical Fresnel reflectance of a smooth dielectric (air -> n) for cosine-weighted light,
#: F_dr(n) = 2 int_0^1 F(mu; n) mu dmu, as a polynomial in x = (n - 1)/(n + 1) with no constant term (x^1..x^5).
#: Least-squares fit to Gauss-Legendre quadrature (training.sim.physics.diffuse_specular) on n in [1, 3.8], held
#: exact at n = 1.4 (0.0768115): |error| <= 1.1e-3 over [1, 3.8], <= 7e-5 for n in [1.25, 1.7].  A polynomial
#: because the node group evaluates it with Math nodes (the closed form cancels catastrophically in float32
#: near n = 1).
DIFFUSE_FRESNEL_POLY: tuple[float, ...] = (0.5747379285, -1.418261621, 5.688563564, -8.559370577, 5.338668414)


def fresnel_dielectric(cos_i, n) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a smooth dielectric (air -> n), Cycles' ``fresnel_dielectric_cos``
    (kernel/closure/bsdf_util.h, the Fresnel node): ``cos_i`` the cosine to the normal, 1 for total internal
    reflection (n < 1 only)."""
    c = np.abs(_finite("cos_i", cos_i))
    eta = _finite("n", n)
    g2 = eta * eta - 1.0 + c * c
    with np.errstate(invalid="ignore", divide="ignore"):
        g = np.sqrt(np.maximum(g2, 0.0))
        a = (g - c) / (g + c)
        b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        f = 0.5 * a * a * (1.0 + b * b)
    return np.where(g2 > 0.0, f, 1.0)


def diffuse_fresnel(n) -> np.ndarray:
    """F_dr(n) of :data:`DIFFUSE_FRESNEL_POLY`; ``n`` below 1 counts as 1 (no coat, F_dr = 0)."""
    eta = np.maximum(_finite("n", n), 1.0)
    x = (eta - 1.0) / (eta + 1.0)
    return x * np.polynomial.polynomial.polyval(x, DIFFUSE_FRESNEL_POLY)


def coat_body_scale(cos_i, n) -> np.ndarray:
    """Weight of the subsurface mixture under the specular coat seen at ``cos_i``: (1 - F(cos_i)) / (1 - F_dr(n)).

    The baked maps already carry the skin's *body* reflectance behind its Fresnel boundary (the model's
    reflectance excludes the specular part, exporters.collapse step 1), so the coat only redistributes it over
    viewing angles: the cosine-weighted mean of this factor is 1 (up to the F_dr fit), and F + (1 - F) x body
    / (1 - F_dr) <= 1 wherever the body reflectance is physical (at most 1 - F_dr)."""
    eta = np.maximum(_finite("n", n), 1.0)
    return (1.0 - fresnel_dielectric(cos_i, eta)) / (1.0 - diffuse_fresnel(eta))
