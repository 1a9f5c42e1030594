"""Spectral Skin SSS research code: skin model, Monte Carlo, dataset, fitting, training, validation.

May import ``exporters``; never imported by ``exporters`` or the Blender add-on.
"""
