"""The measurement's geometry: what a spectrophotometer with an integrating sphere reads from skin.

NIST measured directional-hemispherical reflectance factors: a collimated beam at 8 degrees from the
normal, every reflected direction collected, the specular part included (Cooksey et al. 2017).  We model
it as

    R_measured(lambda) = S + R_d,normal(lambda)

* ``R_d,normal``: the Monte Carlo's diffuse reflectance for a collimated normal beam through the smooth
  n = 1.4 boundary (what enters is 1 - F(0); 8 degrees changes Fresnel by < 2e-5 and the depth of entry by
  cos 5.7 deg = 0.995, both far below the data's noise);
* ``S``: the hemispherical specular reflectance of a rough n = 1.4 surface at 8 degrees, the Fresnel
  reflectance averaged over the microfacets the beam sees (Beckmann slopes, rms m = ``SKIN_ROUGHNESS``).
  It is wavelength-independent (one n).  Single bounce: light the facets send back into the surface is a
  second-order term (< 1e-3 for m <= 0.4).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from exporters.constants import N_TISSUE
from training.sim.physics import fresnel_unpolarised

#: Incidence angle of the NIST measurements (8 degrees, specular included; Cooksey et al. 2017).
INCIDENCE_DEG = 8.0
#: rms facet slope of skin's surface, Beckmann m: Weyrich et al. 2006 (ACM TOG 25:1013) fit Torrance-Sparrow
#: roughness 0.3-0.45 over faces; forearm skin is smoother than the face's pores, 0.35 is used.
SKIN_ROUGHNESS = 0.35


def rough_specular(n: float = N_TISSUE, roughness: float = SKIN_ROUGHNESS, incidence_deg: float = INCIDENCE_DEG,
                   nodes: int = 400) -> float:
    """Hemispherical specular reflectance of a rough dielectric (Beckmann facets, single bounce), in [0, 1].

    Integrates F(i . h) over facet normals h weighted by the projected area each presents to the beam:
    S = integral D(h) max(i . h, 0) F(i . h) dh / (i . z), where integral D(h) (h . z) dh = 1;
    quadrature on a polar grid of h.
    Hand-written: no package here integrates a rough dielectric's specular albedo.
    """
    th = (np.arange(nodes) + 0.5) * (0.5 * math.pi / nodes)  # facet polar angle, midpoint rule
    ph = (np.arange(2 * nodes) + 0.5) * (math.pi / nodes)
    t, p = np.meshgrid(th, ph, indexing="ij")
    tan2 = np.tan(t) ** 2
    d = np.exp(-tan2 / roughness**2) / (math.pi * roughness**2 * np.cos(t) ** 4)  # Beckmann D(h)
    h = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    inc = math.radians(incidence_deg)
    i = np.array([math.sin(inc), 0.0, math.cos(inc)])
    cos_ih = np.clip(np.tensordot(i, h, axes=1), 0.0, 1.0)
    f = fresnel_unpolarised(torch.from_numpy(cos_ih), 1.0, n).numpy()
    dw = np.sin(t) * (0.5 * math.pi / nodes) * (math.pi / nodes)
    return float(np.sum(d * cos_ih * f * dw) / i[2])


def smooth_specular(n: float = N_TISSUE, incidence_deg: float = INCIDENCE_DEG) -> float:
    """Fresnel reflectance of the smooth boundary at the measurement's incidence (for comparison)."""
    cos_i = torch.tensor([math.cos(math.radians(incidence_deg))], dtype=torch.float64)
    return float(fresnel_unpolarised(cos_i, 1.0, n)[0])


def port_collection(r_cm: np.ndarray, beam_radius_cm: float, port_radius_cm: float) -> np.ndarray:
    """Share of light that exits at distance ``r_cm`` from where it entered and still leaves through the port.

    The beam lights a uniform disc of radius ``beam_radius_cm`` centred in a sample port of radius
    ``port_radius_cm``; light leaving the skin outside the port is not collected by the sphere (the lateral
    loss of small ports: Takiwaki et al. 2002, Skin Res Technol 8:94, measured up to ~10 % more reflectance
    at 700 nm through an 11 mm than a 5 mm aperture).  For an entry point uniform in the beam and an exit
    direction uniform in angle, the share is the area of the lens where the beam disc and the port disc
    shifted by r overlap, over the beam's area (closed form; ``r_cm`` any shape, result in [0, 1]).
    """
    a, b = float(beam_radius_cm), float(port_radius_cm)
    if a <= 0 or b <= 0:
        raise ValueError("beam and port radii must be positive (cm)")
    d = np.asarray(r_cm, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        ca = np.clip((d**2 + a**2 - b**2) / (2 * d * a), -1.0, 1.0)
        cb = np.clip((d**2 + b**2 - a**2) / (2 * d * b), -1.0, 1.0)
        k = np.clip((-d + a + b) * (d + a - b) * (d - a + b) * (d + a + b), 0.0, None)
        lens = a**2 * np.arccos(ca) + b**2 * np.arccos(cb) - 0.5 * np.sqrt(k)
    lens = np.where(d <= abs(b - a), math.pi * min(a, b) ** 2, np.where(d >= a + b, 0.0, lens))
    return np.clip(lens / (math.pi * a**2), 0.0, 1.0)
