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

Skin colours inside the table have G = 1 within the fit and the table's own error (0.1-1 %); the live group
(blender_addon.live) computes exactly this with nodes, and a bake through the table applies it to every texel
(exporters.texel_table.TexelTable.records), so both agree on every colour.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from . import collapse, cycles, painted, reflectance_tables

#: Smallest Subsurface Color the body fit covers (the shipped table's components with any weight hold 0.49-0.78:
#: the painted colour's albedo floor, exporters.collapse step 4); smaller colours are read as this one.
FIT_COLOUR_MIN: float = 0.3
#: Degrees of the body fit's two polynomials (forward in sqrt(top - A), inverse in rho): max relative error
#: 0.1 % forward, 5e-4 in A inverse over [FIT_COLOUR_MIN, top] (tests/test_painted_gain.py).
FIT_DEGREES: tuple[int, int] = (4, 6)
#: Smallest predicted body reflectance the gain divides by (keeps G finite for black).
GAIN_FLOOR: float = 1e-6


@dataclass(frozen=True)
class BodyFit:
    """rho(A), the reflectance Cycles' random walk renders for an isotropic closure of Subsurface Color A
    (averaged over view directions: exporters.reflectance_tables "cycles" of exporters.cycles.rw_albedo_forward),
    as two polynomials the nodes evaluate: rho ~ sum_i forward[i] s^i with s = sqrt(top - A) (rho behaves like
    1 - c sqrt(1 - alpha) near alpha = 1), A ~ sum_i inverse[i] rho^i.  ``top``: the colour of the largest albedo
    the collapse gives (exporters.collapse.ALPHA_HARD_MAX), ``reach`` = rho(top), ``low`` = FIT_COLOUR_MIN."""

    top: float
    low: float
    reach: float
    forward: tuple[float, ...]
    inverse: tuple[float, ...]


def body_fit(ior: float) -> BodyFit:
    """The :class:`BodyFit` for closures of IOR ``ior`` (the table's, CollapseOptions.ior)."""
    return _body_fit(round(float(ior), 6))


@cache
def _body_fit(ior: float) -> BodyFit:
    top = float(cycles.rw_albedo_inverse(collapse.ALPHA_HARD_MAX, 0.0).color)
    colour = np.linspace(FIT_COLOUR_MIN, top, 2001)
    rho = reflectance_tables.reflectance("cycles", cycles.rw_albedo_forward(colour, 0.0), 0.0, ior)
    poly = np.polynomial.polynomial
    forward = poly.polyfit(np.sqrt(top - colour), rho, FIT_DEGREES[0], w=1.0 / rho)
    inverse = poly.polyfit(rho, colour, FIT_DEGREES[1])
    return BodyFit(top=top, low=FIT_COLOUR_MIN, reach=float(rho[-1]), forward=tuple(map(float, forward)),
                   inverse=tuple(map(float, inverse)))


def _horner(coeffs: tuple[float, ...], x: np.ndarray) -> np.ndarray:
    """sum_i coeffs[i] x^i by Horner's rule, as the nodes compute it (one multiply-add per degree)."""
    out = np.full_like(x, coeffs[-1])
    for c in reversed(coeffs[:-1]):
        out = out * x + c
    return out


def body_reflectance(colour: np.ndarray, fit: BodyFit) -> np.ndarray:
    """rho of Subsurface Colors (any shape), the colour clamped to [fit.low, fit.top]."""
    s = np.sqrt(fit.top - np.clip(colour, fit.low, fit.top))
    return _horner(fit.forward, s)


def body_colour(rho: np.ndarray, fit: BodyFit) -> np.ndarray:
    """The Subsurface Color of reflectance ``rho`` (any shape; the inverse fit)."""
    return _horner(fit.inverse, rho)


def painted_media(colour: np.ndarray, weight: np.ndarray, rgb: np.ndarray, fit: BodyFit
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Colours and weights (N, K, 3) of looked-up media ``colour``, ``weight`` (N, K, 3) brought to the painted
    linear colours ``rgb`` (N, 3) (module docstring; NaN is 0, +Inf 1, as in the nodes).  Returns
    new arrays (float64)."""
    colour, weight = np.asarray(colour, np.float64), np.asarray(weight, np.float64)
    target = painted.target_colour(np.nan_to_num(np.asarray(rgb, np.float64), nan=0.0, posinf=1.0, neginf=0.0))
    rho = body_reflectance(colour, fit)
    gain = target / np.maximum(np.sum(weight * rho, axis=1), GAIN_FLOOR)  # (N, 3)
    scaled = weight * gain[:, None, :]
    rho_new = np.maximum(rho, np.minimum(scaled * rho, fit.reach))
    return colour + (body_colour(rho_new, fit) - body_colour(rho, fit)), np.minimum(scaled, 1.0)
