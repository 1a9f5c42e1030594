"""Biophysical two-layer skin model: 5 parameters -> per-layer mu_a, mu_s, g at 376 wavelengths."""
