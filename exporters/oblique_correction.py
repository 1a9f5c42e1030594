"""Grazing-light correction of the K-media mixture: per-channel factors on the weights and the radii that grow
with the angle of the light, fitted to the Monte Carlo.

The mixtures are fitted under the cosine-weighted lobe (light mostly between 30 and 60 degrees).  Under a grazing
beam the two-layer skin of dark tones reflects less than its mixture and its light spreads less far
(docs/validation/oblique.md: the epidermis' melanin is crossed along a slanted path).  The correction is

    w_kc' = w_kc f_c,   r_kc' = r_kc s_c,   f_c = 1 + a_c(Y) h_w(mu),   s_c = 1 + b_c(Y) h_r(mu),
    h(mu) = smoothstep(e0, e1, 1 - mu)   (0 up to 1 - mu = e0, 1 from 1 - mu = e1, t^2 (3 - 2 t) between),

the same factor for every component k of channel c (the light of a channel is linear in its weights, so f_c
scales the channel's reflectance and leaves its profile's shape alone; s_c scales the profile's width and leaves
the reflectance of a semi-infinite medium alone).  ``mu`` is the cosine of the angle of the light at the surface
and Y the relative luminance of the painted colour (linear sRGB, Rec. 709 weights: the renderer knows the colour,
not the tone); a_c and b_c are piecewise linear in Y between the representative tones' luminances (constant
beyond them).  At normal incidence, and wherever 1 - mu <= e0, h = 0, so f = s = 1 exactly: there the mixture
renders as without the correction.

In Cycles' shader nodes the light's angle is not known per light; the live group uses the view's facing ratio
mu = |N . I|.  Under uniform light (a white world, an overcast sky) that is exact by reciprocity: the radiance
seen at view angle theta equals the reflectance of a beam arriving at theta.  Under one light from another
direction it is an approximation (the rim seen at grazing view is corrected whatever the light's angle).

The coefficients live in ``data/oblique_correction.json``, written by ``python -m training.validate.oblique_fit``
from the Monte Carlo of ``training.validate.oblique`` (its provenance is in the file).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np

from .colorimetry import SRGB_LUMINANCE

#: The fitted coefficients shipped with the add-on.
DATA_PATH = Path(__file__).resolve().parent / "data" / "oblique_correction.json"


@dataclass(frozen=True)
class ObliqueCorrection:
    """Coefficients of the correction (module docstring).

    ``luminance`` (N,) increasing knots of Y; ``weight_slope`` a_c and ``radius_slope`` b_c (N, 3) at the knots
    (R, G, B); ``weight_ramp`` and ``radius_ramp`` the edges (e0, e1) of their h, 0 <= e0 < e1 <= 1;
    ``source``: how they were fitted."""

    luminance: np.ndarray
    weight_slope: np.ndarray
    radius_slope: np.ndarray
    weight_ramp: tuple[float, float]
    radius_ramp: tuple[float, float]
    source: str = ""

    def to_json(self) -> str:
        return json.dumps({"luminance": self.luminance.tolist(), "weight_slope": self.weight_slope.tolist(),
                           "radius_slope": self.radius_slope.tolist(), "weight_ramp": list(self.weight_ramp),
                           "radius_ramp": list(self.radius_ramp), "source": self.source}, indent=1)


def from_json(text: str) -> ObliqueCorrection:
    """The correction held in ``text`` (a JSON object as :meth:`ObliqueCorrection.to_json` writes); ValueError
    when its knots are not increasing or its arrays do not match them."""
    d = json.loads(text)
    y = np.asarray(d["luminance"], dtype=np.float64)
    a = np.asarray(d["weight_slope"], dtype=np.float64)
    b = np.asarray(d["radius_slope"], dtype=np.float64)
    if y.ndim != 1 or y.size < 2 or np.any(np.diff(y) <= 0) or a.shape != (y.size, 3) or b.shape != (y.size, 3):
        raise ValueError("oblique correction: luminance knots must increase and the slopes be (knots, 3)")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(np.isfinite(y))):
        raise ValueError("oblique correction: non-finite coefficients")
    ramps = tuple((float(d[k][0]), float(d[k][1])) for k in ("weight_ramp", "radius_ramp"))
    if any(not 0.0 <= e0 < e1 <= 1.0 for e0, e1 in ramps):
        raise ValueError("oblique correction: each ramp needs 0 <= e0 < e1 <= 1")
    return ObliqueCorrection(y, a, b, ramps[0], ramps[1], str(d.get("source", "")))


@cache
def shipped() -> ObliqueCorrection:
    """The shipped correction (``DATA_PATH``)."""
    return from_json(DATA_PATH.read_text())


def angle_shape(mu: np.ndarray, ramp: tuple[float, float]) -> np.ndarray:
    """h(mu) = smoothstep(e0, e1, 1 - mu) for ``ramp`` (e0, e1): 0 at normal incidence, 1 at grazing; ``mu``
    clipped to [0, 1]."""
    x = 1.0 - np.clip(np.asarray(mu, dtype=np.float64), 0.0, 1.0)
    t = np.clip((x - ramp[0]) / (ramp[1] - ramp[0]), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def slopes(corr: ObliqueCorrection, colour: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """a_c and b_c (..., 3) at the luminance of ``colour`` (..., 3) (linear, clamped to [0, 1] as painted)."""
    y = np.clip(np.asarray(colour, dtype=np.float64), 0.0, 1.0) @ SRGB_LUMINANCE
    a = np.stack([np.interp(y, corr.luminance, corr.weight_slope[:, c]) for c in range(3)], axis=-1)
    b = np.stack([np.interp(y, corr.luminance, corr.radius_slope[:, c]) for c in range(3)], axis=-1)
    return a, b


def factors(corr: ObliqueCorrection, colour: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weight factors f_c and radius factors s_c (..., 3) for painted ``colour`` (..., 3) lit at cosine ``mu``
    (broadcast against colour[..., 0]).  Both are 1 exactly at mu = 1."""
    a, b = slopes(corr, colour)
    mu = np.asarray(mu, dtype=np.float64)[..., None]
    return 1.0 + a * angle_shape(mu, corr.weight_ramp), 1.0 + b * angle_shape(mu, corr.radius_ramp)


#: Texels (luminances, facings) of the tables the live group reads the correction from (:func:`tables`): the
#: slopes' corners over a luminance step (the larger part) and the smooth step's curvature over a facing step keep
#: the shipped correction's bilinear interpolation within 9e-4 of :func:`factors` (tests/test_oblique_correction.py);
#: 0.5 MB a table.
TABLE_SIZE: tuple[int, int] = (1024, 32)


def table_axes(corr: ObliqueCorrection, size: tuple[int, int] = TABLE_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """Luminances (``size[0]``, the tables' columns) and facings 1 - mu (``size[1]``, their rows) at the texel
    centres of :func:`tables`: from the first knot to the last, and from the earlier ramp's start to the later
    one's end (beyond them the factors are constant)."""
    facing = (min(corr.weight_ramp[0], corr.radius_ramp[0]), max(corr.weight_ramp[1], corr.radius_ramp[1]))
    return (np.linspace(corr.luminance[0], corr.luminance[-1], size[0]), np.linspace(*facing, size[1]))


def tables(corr: ObliqueCorrection, size: tuple[int, int] = TABLE_SIZE) -> dict[str, np.ndarray]:
    """The correction as two small images, ``"Weight"`` and ``"Radius"``: (rows, columns, 4) float32, RGB the factors
    f_c = 1 + a_c(Y) h_w and s_c = 1 + b_c(Y) h_r at the texel centres of :func:`table_axes` (luminance along the
    width, facing along the height, row 0 at the bottom), alpha 1.  Where h = 0 (face-on views) they hold 1
    exactly, so bilinear filtering gives 1 exactly there too (the shader reads the factors with no node after the
    lookup)."""
    lum, facing = table_axes(corr, size)
    colour = np.repeat(lum[:, None], 3, axis=1) / np.sum(SRGB_LUMINANCE)  # grey of luminance Y
    a, b = slopes(corr, colour)  # (columns, 3)
    out = {}
    for name, slope, ramp in (("Weight", a, corr.weight_ramp), ("Radius", b, corr.radius_ramp)):
        h = angle_shape(1.0 - facing, ramp)  # (rows,)
        image = np.ones((size[1], size[0], 4), np.float32)
        image[..., :3] = 1.0 + h[:, None, None] * slope[None, :, :]
        out[name] = image
    return out
