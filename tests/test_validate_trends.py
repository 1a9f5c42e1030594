"""training/validate/trends.py: the K = 1 medium equivalent to a profile (R, median radius) through the
LUT, checked on closed-form dipole media binned in centimetres (training/sim/dipole.py, test tables)."""

import numpy as np
import pytest
import torch

from exporters.constants import R_EDGES_CM
from training.sim.dipole import dipole_lut, dipole_mixture_profile
from training.sim.lut_interp import LookupTables
from training.validate.trends import albedo_for_reflectance, equivalent_medium, median_radius

WIDE_EDGES_MFP = np.concatenate([[0.0], np.geomspace(1e-3, 1e4, 512)])


def test_median_radius_of_a_uniform_disc_and_a_ring():
    edges = np.linspace(0.0, 2.0, 41)
    centres = 0.5 * (edges[1:] + edges[:-1])
    disc = (centres < 1.0).astype(float)
    assert median_radius(disc, edges) == pytest.approx(np.sqrt(0.5), rel=1e-12)
    ring = ((centres > 1.0) & (centres < 1.5)).astype(float)  # half the power inside r^2 = (1 + 2.25) / 2
    np.testing.assert_allclose(median_radius(np.stack([disc, ring]), edges), [np.sqrt(0.5), np.sqrt(1.625)])
    with pytest.raises(ValueError, match="no reflected power"):
        median_radius(np.zeros(40), edges)


def test_equivalent_medium_recovers_a_homogeneous_medium():
    albedo = np.concatenate([[0.0], 1.0 - np.geomspace(0.95, 1e-5, 60), [1.0]])
    lut = LookupTables.from_arrays(**dipole_lut(albedo=albedo, g=np.linspace(0.0, 0.95, 20),
                                                r_edges_mfp=WIDE_EDGES_MFP), dtype=torch.float64)
    a = np.array([[0.99], [0.95], [0.8]])
    g = np.full_like(a, 0.8)
    s = np.array([[150.0], [300.0], [60.0]])
    profile, R = dipole_mixture_profile(R_EDGES_CM, WIDE_EDGES_MFP, a, g, s, np.ones_like(a))
    alpha_eq, sigma_eq = equivalent_medium(lut, R, median_radius(profile, R_EDGES_CM), g[:, 0])
    np.testing.assert_allclose(alpha_eq, a[:, 0], atol=2e-3)
    np.testing.assert_allclose(sigma_eq, s[:, 0], rtol=0.03)
    # beyond the LUT's albedo range the answer is its edge, never NaN
    assert albedo_for_reflectance(lut, np.array([2.0]), np.array([0.8]))[0] == pytest.approx(1.0)
