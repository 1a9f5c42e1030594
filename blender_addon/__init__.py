"""Spectral Skin SSS: Blender add-on (bpy layer over the numpy core in ``exporters``)."""
