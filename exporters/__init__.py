"""Spectral Skin SSS exporters: model inference, colour, maps and renderer scenes.

Runtime dependencies are numpy, onnxruntime, OpenImageIO and colour-science only:
this package never imports torch or bpy (the Blender add-on and the training code both import it).
"""

from exporters.constants import N_WAVELENGTHS, WAVELENGTHS_NM

__all__ = ["N_WAVELENGTHS", "WAVELENGTHS_NM"]
