"""The LUT above its last albedo node: an analytic extension of R and P to albedo 1 (no rebuild needed).

Why: the table stops at albedo 0.9999 (``training.sim.lut.ALBEDO_MAX``) and ``LookupTables`` holds the
edge value beyond it with zero gradient, so a fit whose loss still falls at the edge stops there
("pinned"; the gate counted 6.6 % of its fitted albedos beyond the edge).  Rebuilding with a higher
``--albedo-max`` also needs a longer walk cap; instead the rows above the edge follow from the
asymptotics of a semi-infinite medium near albedo 1 (s = sqrt(1 - albedo)):

* R(albedo, g) = R_1 - c1(g) s - c2(g) s^2.  R_1 = 1 - the boundary's specular reflection of the
  cosine-weighted incident light (everything that enters comes back when nothing is absorbed); the
  leading sqrt law is that of transport theory (van de Hulst 1980, the plane albedo of a conservative
  half-space: 1 - R ~ sqrt(1 - albedo)); c1, c2 are solved from the table's own R at its last node and at
  the node nearest 4 x (1 - albedo_last).  Checked against adding-doubling (``tests/test_lut_extend.py``).
* P(r | albedo, g) = P(r | albedo_N, g) D(r; albedo, g) / D(r; albedo_N, g), renormalised to sum P area =
  1: the tabulated (transport-exact) profile at the last node carried to a higher albedo by the ratio of
  classical diffusion-dipole profiles (``training.sim.dipole``; Farrell et al. 1992), which is 1 in the
  near field and lengthens the exponential tail exp(-sigma_tr r) (sigma_tr = sqrt(3 mu_a sigma_t')).
  Checked against direct walks at albedo 1 - 1e-5 (``tests/test_lut_extend.py``).

``extend_albedo`` appends rows at 1 - (1 - albedo_N) 2^-k/2 (k = 1 .. EXTRA_ROWS - 1) and at 1 exactly;
``LookupTables.load`` applies it by default to tables ending at albedo >= EXTEND_FROM
(``extend_albedo=False`` loads the table as built).  Between the rows the lookups interpolate bilinearly
as everywhere else, so gradients w.r.t. albedo flow up to 1 and no fit sits on a flat edge.
"""

from __future__ import annotations

import math

import numpy as np

from exporters.constants import N_TISSUE
from training.sim.dipole import dipole_profile_shape
from training.sim.lut_interp import bin_centres
from training.sim.physics import diffuse_specular

#: Rows appended above the last node: 1 - albedo halves every second row, from 0.71 x (1 - albedo_N) down to
#: 2^-6.5 x (1 - albedo_N) (1.1e-6 for the paper-scale table: still distinct from 1 in float32), then 1.
#: Linear interpolation of the sqrt law over the last interval errs by <= 6e-4 in R.
EXTRA_ROWS: int = 14
#: Tables are extended on load only when their last albedo is at least this (the asymptotic laws hold
#: there; tiny test tables ending lower keep holding their edge value).
EXTEND_FROM: float = 0.999
#: Recorded with fits made through an extended table (fits made before held the edge instead).
ALBEDO_EXTENSION: str = "sqrt-law R, dipole-ratio P, to albedo 1 (v1)"


def extension_record(path) -> str:
    """What ``LookupTables.load(path)`` does above the table's last albedo, for the records of fits made
    through it: ALBEDO_EXTENSION, or "none (edge held)" for tables ending below EXTEND_FROM."""
    with np.load(path) as data:
        last = float(data["albedo"][-1])
    return ALBEDO_EXTENSION if EXTEND_FROM <= last < 1.0 else "none (edge held)"


def extension_albedos(albedo_last: float, rows: int = EXTRA_ROWS) -> np.ndarray:
    """(rows,) albedos above ``albedo_last``: 1 - (1 - albedo_last) 2^(-k/2), k = 1 .. rows - 1, then 1."""
    k = np.arange(1, rows)
    return np.concatenate([1.0 - (1.0 - albedo_last) * 2.0 ** (-k / 2.0), [1.0]])


def extend_albedo(albedo: np.ndarray, g: np.ndarray, r_edges_mfp: np.ndarray, R: np.ndarray, P: np.ndarray,
                  n_medium: float = N_TISSUE, rows: int = EXTRA_ROWS) -> dict[str, np.ndarray]:
    """The table (docs/contracts.md §2 arrays: albedo (NA,), g (NG,), r_edges_mfp (NR + 1,), R (NA, NG), P (NA, NG, NR))
    with ``rows`` albedo rows appended up to albedo 1 (module docstring).  Returns the same keys."""
    albedo, g = np.asarray(albedo, np.float64), np.asarray(g, np.float64)
    R, P = np.asarray(R, np.float64), np.asarray(P, np.float64)
    a_n = float(albedo[-1])
    if not 0.99 <= a_n < 1.0:
        raise ValueError(f"the albedo extension needs a table ending in [0.99, 1), this one ends at {a_n}")
    j = int(np.argmin(np.abs((1.0 - albedo) - 4.0 * (1.0 - a_n))))  # node at ~4x the edge's 1 - albedo
    if j == albedo.size - 1:
        raise ValueError("the albedo extension needs a node below the last one, near 4 x its 1 - albedo")
    new = extension_albedos(a_n, rows)
    r1 = 1.0 - diffuse_specular(n_medium)
    s_n, s_j, s = math.sqrt(1.0 - a_n), math.sqrt(1.0 - albedo[j]), np.sqrt(1.0 - new)
    # 1 - R deficit d = R_1 - R = c1 s + c2 s^2 through the two nodes (per g)
    det = s_n * s_j**2 - s_j * s_n**2
    d_n, d_j = r1 - R[-1], r1 - R[j]
    c1 = (d_n * s_j**2 - d_j * s_n**2) / det
    c2 = (s_n * d_j - s_j * d_n) / det
    r_new = np.clip(r1 - c1[None] * s[:, None] - c2[None] * s[:, None] ** 2, R[-1][None], r1)
    c = bin_centres(np.asarray(r_edges_mfp, np.float64))
    d_last = dipole_profile_shape(c[None, :], a_n, g[:, None], n_medium)  # (NG, NR)
    area = math.pi * np.diff(np.asarray(r_edges_mfp, np.float64) ** 2)
    p_new = np.empty((new.size, g.size, c.size))
    for i, a in enumerate(new):
        ratio = dipole_profile_shape(c[None, :], a, g[:, None], n_medium) / np.maximum(d_last, 1e-300)
        p = P[-1] * ratio
        p_new[i] = p / np.maximum((p * area).sum(-1, keepdims=True), 1e-300)
    return {"albedo": np.concatenate([albedo, new]), "g": g, "r_edges_mfp": np.asarray(r_edges_mfp, np.float64),
            "R": np.concatenate([R, r_new]), "P": np.concatenate([P, p_new])}
