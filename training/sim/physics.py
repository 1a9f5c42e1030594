"""Elementary photon-transport physics on tensors: Fresnel, Henyey-Greenstein, direction rotation.

Hand-written (no well-kept torch library samples these); every function is elementwise, branch-free
(``torch.where``), and finite for every valid input, so it can run on any device and dtype.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import torch

from exporters.constants import N_TISSUE
from training.sim.walk_constants import G_ISOTROPIC_EPS


def fresnel_unpolarised(cos_i: torch.Tensor, n1: float | torch.Tensor, n2: float | torch.Tensor) -> torch.Tensor:
    """Unpolarised Fresnel reflectance of a smooth boundary (light going from index n1 to n2).

    Args:
        cos_i: cosine of the angle of incidence, in [0, 1] (any shape).
        n1, n2: refractive indices (scalars or broadcastable tensors).
    Returns: reflectance in [0, 1], the shape of ``cos_i``; 1 beyond the critical angle.
    """
    ci = cos_i.abs().clamp(0.0, 1.0)
    ratio = n1 / n2
    sin_t2 = ratio * ratio * (1.0 - ci * ci)
    tir = sin_t2 >= 1.0
    ct = torch.sqrt((1.0 - sin_t2).clamp_min(0.0))
    # r_s = (n1 ci - n2 ct) / (n1 ci + n2 ct), r_p = (n1 ct - n2 ci) / (n1 ct + n2 ci), written with
    # the ratio so that n1 = n2 gives exactly 0.
    a_s, b_s = ratio * ci - ct, ratio * ci + ct
    a_p, b_p = ratio * ct - ci, ratio * ct + ci
    rs = a_s / b_s.clamp_min(1e-30)
    rp = a_p / b_p.clamp_min(1e-30)
    r = 0.5 * (rs * rs + rp * rp)
    r = torch.where(torch.as_tensor(ratio == 1.0, device=r.device), torch.zeros_like(r), r)  # exact 0
    return torch.where(tir, torch.ones_like(r), r.clamp(0.0, 1.0))


@cache
def diffuse_specular(n: float = N_TISSUE, nodes: int = 256) -> float:
    """Specular reflectance of a smooth boundary (air -> n) for cosine-weighted incidence:
    2 * int_0^1 F(mu) mu dmu, unpolarised Fresnel F (:func:`fresnel_unpolarised`); 0.0768115 for n = 1.4.

    Gauss-Legendre quadrature in float64 (the integrand is smooth; 256 nodes reach double precision).  Used by
    the LUT's albedo extension (``training.sim.lut_extend``) and the Mitsuba slab renders
    (``training.validate.mitsuba_scene``), which remove the boundary's specular part with it.
    """
    x, w = np.polynomial.legendre.leggauss(nodes)
    mu = torch.from_numpy(0.5 * (x + 1.0))
    f = fresnel_unpolarised(mu, 1.0, float(n)).numpy()
    return float(np.sum(w * f * mu.numpy()))  # 2 * 0.5 w: nodes mapped from [-1, 1] onto [0, 1]


def refract_cos(cos_i: torch.Tensor, n1: float, n2: float) -> torch.Tensor:
    """Cosine of the refracted angle for light from n1 to n2 (assumes no total internal reflection)."""
    ratio = n1 / n2
    return torch.sqrt((1.0 - ratio * ratio * (1.0 - cos_i * cos_i)).clamp_min(0.0))


def hg_cos(g: torch.Tensor, xi: torch.Tensor) -> torch.Tensor:
    """Sample the cosine of the Henyey-Greenstein scattering angle by inversion.

    cos = (1 + g^2 - ((1 - g^2) / (1 - g + 2 g xi))^2) / (2 g); isotropic 2 xi - 1 for |g| < 1e-6.
    Stable for |g| <= 0.99 in float32 (the denominator stays >= 1 - |g| > 0).
    Args: g, xi (uniform in [0, 1)) of the same shape.  Returns cos in [-1, 1].
    """
    small = g.abs() < G_ISOTROPIC_EPS
    gs = torch.where(small, torch.ones_like(g), g)
    t = (1.0 - gs * gs) / (1.0 - gs + 2.0 * gs * xi)
    c = (1.0 + gs * gs - t * t) / (2.0 * gs)
    c = torch.where(small, 2.0 * xi - 1.0, c)
    return c.clamp(-1.0, 1.0)


def rotate(
    ux: torch.Tensor, uy: torch.Tensor, uz: torch.Tensor, cos_t: torch.Tensor, phi_xi: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """New unit direction at polar cosine ``cos_t`` from (ux, uy, uz), azimuth 2 pi ``phi_xi``.

    Uses the branch-free orthonormal frame of Duff et al. (2017, "Building an orthonormal basis,
    revisited", JCGT 6(1)), stable for every direction including uz = +-1.
    """
    sign = torch.where(uz >= 0, torch.ones_like(uz), -torch.ones_like(uz))
    a = -1.0 / (sign + uz)
    b = ux * uy * a
    # t1 = (1 + sign ux^2 a, sign b, -sign ux); t2 = (b, sign + uy^2 a, -uy)
    sin_t = torch.sqrt((1.0 - cos_t * cos_t).clamp_min(0.0))
    phi = (2.0 * math.pi) * phi_xi
    c1 = sin_t * torch.cos(phi)
    c2 = sin_t * torch.sin(phi)
    nx = c1 * (1.0 + sign * ux * ux * a) + c2 * b + cos_t * ux
    ny = c1 * (sign * b) + c2 * (sign + uy * uy * a) + cos_t * uy
    nz = -(c1 * sign * ux) - c2 * uy + cos_t * uz
    return nx, ny, nz
