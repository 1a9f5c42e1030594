"""A skin object that is not at its real size in the scene's units is named (blender_addon.real_size): a character
modelled in centimetres in a scene left in metres is 180 m tall to the renderer, and its physical skin renders nearly
opaque; Invert Skin Albedo's report says so, with what to set, and a model at its real size gets no such line."""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import blender_addon  # noqa: E402
from blender_addon import real_size  # noqa: E402
from tests.addon_scene import run_invert, skin_codes, skin_object, write_image  # noqa: E402


def _box(sides: tuple[float, float, float]) -> bpy.types.Object:
    """A box of ``sides`` (Blender units) at the origin of an empty scene."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    obj = bpy.context.active_object
    obj.scale = sides
    bpy.context.view_layer.update()
    return obj


@pytest.mark.parametrize(("sides", "unit_scale_m", "expected"), [
    ((0.5, 0.3, 1.8), 1.0, None),  # a character in metres
    ((50.0, 30.0, 180.0), 0.01, None),  # the same in centimetres, Unit Scale 0.01
    ((0.2, 0.15, 0.25), 1.0, None),  # a head
    ((0.02, 0.015, 0.01), 1.0, None),  # a fingertip
    ((50.0, 30.0, 180.0), 1.0, "'Cube' is 180 m across at Unit Scale 1 m per Blender unit"),  # centimetres, in m
    ((0.2, 0.15, 0.25), 0.01, "'Cube' is 2.5 mm across at Unit Scale 0.01 m per Blender unit"),  # a head, in cm
])
def test_the_warning_says_how_large_the_object_is(sides, unit_scale_m, expected):
    warning = real_size.warning(_box(sides), unit_scale_m)
    if expected is None:
        assert warning is None
    else:
        assert warning.startswith(expected) and "Unit Scale to its real size" in warning
        assert ("nearly opaque" if real_size.extent_m(bpy.context.active_object, unit_scale_m) > 1 else "wax") \
            in warning


def test_a_parents_scale_counts():
    """The size is the world's: a model of real size under an empty scaled 100x (an import in centimetres) is
    named."""
    obj = _box((0.5, 0.3, 1.8))
    parent = bpy.data.objects.new("Import", None)
    bpy.context.scene.collection.objects.link(parent)
    parent.scale = (100.0, 100.0, 100.0)
    obj.parent = parent
    bpy.context.view_layer.update()
    assert real_size.warning(obj, 1.0).startswith("'Cube' is 180 m across")
    assert real_size.warning(obj, 0.01) is None


def test_invert_skin_albedo_reports_a_model_not_at_its_real_size(tmp_path, capfd):
    """The operator wires the skin either way (a creature may be meant to be large) and its report carries the
    warning as a warning; at Unit Scale 0.01 the same sphere (2 cm) gets none."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    blender_addon.register()
    try:
        albedo = write_image(tmp_path / "albedo.png", skin_codes(), "uint8")
        obj, _, _ = skin_object(albedo)
        obj.scale = (100.0, 100.0, 100.0)  # a sphere of radius 100 m
        bpy.context.view_layer.update()
        capfd.readouterr()
        assert run_invert(obj, mode="LIVE") == {"FINISHED"}
        out = capfd.readouterr().out
        assert "Warning: live group wired into" in out and "'Sphere' is 200 m across" in out
        bpy.context.scene.unit_settings.scale_length = 0.0001  # 2 cm
        assert run_invert(obj, mode="LIVE") == {"FINISHED"}
        out = capfd.readouterr().out
        assert "up to date" in out and "across" not in out
    finally:
        blender_addon.unregister()
