"""The models shipped with the add-on, by path: the one place that names this folder and its files.

``exporters`` takes every model path as a parameter and knows no folder of the add-on.  This module imports
nothing but pathlib and never bpy: code outside Blender loads it by its file (``training.paths`` does), since
importing it as ``blender_addon.models`` would first run the add-on's ``__init__``, which imports bpy.
"""

from pathlib import Path

#: This folder (in the repository and in the installed extension alike).
MODEL_DIR = Path(__file__).resolve().parent
#: The inversion graph (docs/contracts.md §3): linear-sRGB albedo (N, 3) -> biophysical, exposure, reflectance
#: and the K media.
INVERSION_MODEL = MODEL_DIR / "skin_inversion.onnx"
#: The decoder graph: biophysical rows (N, 5) -> reflectance and the K mixture components (docs/contracts.md §3).
DECODER_MODEL = MODEL_DIR / "skin_decoder.onnx"
#: The fast-path texel table built from INVERSION_MODEL (``python -m training texel-table``), beside it.
TEXEL_TABLE = MODEL_DIR / "skin_inversion_table.npz"
#: The skin-edit table built from INVERSION_MODEL, DECODER_MODEL and TEXEL_TABLE (``python -m training edit-table``).
EDIT_TABLE = MODEL_DIR / "skin_inversion_edits.npz"
#: The model card (architecture, training data, validation numbers) of INVERSION_MODEL.
MODEL_CARD = MODEL_DIR / "skin_inversion.json"
