"""Every colour renders as painted: the media of a skin colour brought to any painted colour, per channel.

The fast-path table (exporters.texel_table) holds media for skin colours; a colour outside its box is answered
by the skin colour it projects onto (exporters.live_table, steps 1-4), and a colour in a cell reaching outside
the RGB cube by media extended from skin neighbours.  Those media render that other colour.  Here each channel
is brought to the painted colour P (linear, clamped to [0, 1]) in the reflectance domain, keeping the media's
radii and anisotropy (their translucency):

* the closure of component k in channel c adds w_kc rho(A_kc) to the channel (blender_addon.nodes: the mixture is
  a sum of closures), rho(A) the reflectance Cycles' walk renders for Subsurface Color A (averaged over view
  directions: exporters.reflectance_tables "cycles" at the closures' IOR, isotropic as the tables' components);
* Q = sum_k w_k rho(A_k) is what the media render, G = P / Q the gain; every component's light becomes
  G w_k rho(A_k), as the collapse shares a colour among components (exporters.collapse, step 4): the weight
  takes the gain while it stays at most 1 (exact: the light is linear in the weight, the walk unchanged), the
  albedo the rest (weight 1, rho' = G w rho, at most rho of the collapse's largest albedo).

The live group's images hold rho of each node's colour (exporters.live_table), so the nodes interpolate rho and
only the way back to a Subsurface Color is a fit (:class:`BodyFit`, within 5e-4).  Skin colours inside the table
have G = 1 within the table's own error (0.1-1 %); a bake through the table applies the same step to every texel
(exporters.texel_table.TexelTable.records: rho of its interpolated colour), so both agree on every colour (within
the difference between interpolating A and rho: 1e-4).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from . import collapse, cycles, painted, reflectance_tables

#: Smallest Subsurface Color the inverse fit covers (the shipped table's components with any weight hold 0.49-0.78:
#: the painted colour's albedo floor, exporters.collapse step 4); smaller reflectances are read as its.
FIT_COLOUR_MIN: float = 0.3
#: Degree of the inverse fit A(rho): within 5e-4 of A over [FIT_COLOUR_MIN, top] (tests/test_painted_gain.py).
INVERSE_DEGREE: int = 6


@dataclass(frozen=True)
class BodyFit:
    """The Subsurface Color A of a body reflectance rho (:func:`body_reflectance`) as a polynomial the nodes
    evaluate, A ~ sum_i inverse[i] rho^i for rho in [low, reach]: ``top`` the colour of the collapse's largest
    albedo (exporters.collapse.ALPHA_HARD_MAX), ``reach`` = rho(top), ``low`` = rho(FIT_COLOUR_MIN)."""

    top: float
    low: float
    reach: float
    inverse: tuple[float, ...]


def body_fit(ior: float) -> BodyFit:
    """The :class:`BodyFit` for closures of IOR ``ior`` (the table's, CollapseOptions.ior)."""
    return _body_fit(round(float(ior), 6))


@cache
def _body_fit(ior: float) -> BodyFit:
    top = float(cycles.rw_albedo_inverse(collapse.ALPHA_HARD_MAX, 0.0).color)
    colour = np.linspace(FIT_COLOUR_MIN, top, 2001)
    rho = body_reflectance(colour, ior)
    inverse = np.polynomial.polynomial.polyfit(rho, colour, INVERSE_DEGREE)
    return BodyFit(top=top, low=float(rho[0]), reach=float(rho[-1]), inverse=tuple(map(float, inverse)))


def _horner(coeffs: tuple[float, ...], x: np.ndarray) -> np.ndarray:
    """sum_i coeffs[i] x^i by Horner's rule, as the nodes compute it (one multiply-add per degree)."""
    out = np.full_like(x, coeffs[-1])
    for c in reversed(coeffs[:-1]):
        out = out * x + c
    return out


def body_reflectance(colour, ior: float) -> np.ndarray:
    """rho(A): the reflectance Cycles' random walk renders for an isotropic closure of Subsurface Color A (any
    shape, clipped to [0, 1]) and IOR ``ior``, averaged over view directions (exporters.reflectance_tables "cycles"
    of exporters.cycles.rw_albedo_forward); float64."""
    alpha = cycles.rw_albedo_forward(np.clip(np.asarray(colour, np.float64), 0.0, 1.0), 0.0)
    return reflectance_tables.reflectance("cycles", alpha, 0.0, ior)


def body_colour(rho: np.ndarray, fit: BodyFit) -> np.ndarray:
    """The Subsurface Color of reflectance ``rho`` (any shape, read as at least ``fit.low``; the inverse fit)."""
    return _horner(fit.inverse, np.maximum(rho, fit.low))


def painted_target(rgb) -> np.ndarray:
    """The painted linear colours ``rgb`` (N, 3) as the live group reads them: NaN is 0, +Inf 1, then clamped to
    [0, 1] (float64)."""
    return painted.target_colour(np.nan_to_num(np.asarray(rgb, np.float64), nan=0.0, posinf=1.0, neginf=0.0))


def painted_media(rho: np.ndarray, weight: np.ndarray, rgb: np.ndarray, fit: BodyFit
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Subsurface Colors and weights (N, K, 3) of media of body reflectance ``rho`` (:func:`body_reflectance` of
    their colours) and weights ``weight`` (N, K, 3), brought to the painted linear colours ``rgb`` (N, 3) (module
    docstring; NaN is 0, +Inf 1, as in the nodes).  Returns new arrays (float64)."""
    rho, weight = np.asarray(rho, np.float64), np.asarray(weight, np.float64)
    target = painted_target(rgb)
    total = np.sum(weight * rho, axis=1)  # (N, 3)
    gain = np.divide(target, total, out=np.zeros_like(target), where=total > 0.0)  # 0 where 0: Cycles' divide
    scaled = weight * gain[:, None, :]
    rho_new = np.maximum(rho, np.minimum(scaled * rho, fit.reach))
    return body_colour(rho_new, fit), np.minimum(scaled, 1.0)
