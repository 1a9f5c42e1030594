"""Spectral Skin SSS exporters: the shipped runtime (model inference, colour, maps, Cycles mapping, the bake).

Runtime dependencies are numpy, onnxruntime, OpenImageIO and colour-science only: this package never imports
torch, bpy or training (the Blender add-on and the training code both import it), and holds no benchmark, no
validation renderer and no command (``training.bench``, ``training.validate.mitsuba_scene``,
``python -m training texel-table`` ...); model paths are parameters (the add-on's ``blender_addon/models``
names its files).
"""

from .constants import N_WAVELENGTHS, WAVELENGTHS_NM

__all__ = ["N_WAVELENGTHS", "WAVELENGTHS_NM"]
