"""Fitting mixtures of K homogeneous media to Monte Carlo profiles through the lookup tables (paper §4)."""
