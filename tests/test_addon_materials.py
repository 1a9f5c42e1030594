"""A character whose skin spans several materials (head, body and limbs, each a material of its own beside the
clothes' and eyes'): Invert Skin Albedo and Remove Skin SSS take a material of the active object by name (the
``material`` option; the panel lists them with a button each), leave every other material as it was, and refuse a
name that is not in the object's slots in one line, changing nothing."""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import blender_addon  # noqa: E402
from blender_addon import panels, wiring  # noqa: E402
from tests.addon_scene import run_invert, skin_codes, skin_object, snapshot, write_image  # noqa: E402


@pytest.fixture
def character(tmp_path):
    """A sphere with two materials, each a texture into a Principled BSDF: 'Cloth' (slot 1, active) and 'Skin'
    (slot 2)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    blender_addon.register()
    albedo = write_image(tmp_path / "albedo.png", skin_codes(), "uint8")
    obj, cloth, _ = skin_object(albedo, name="Cloth")
    skin_object(albedo, name="Skin")  # a second sphere, for its material
    skin = bpy.data.materials["Skin"]
    obj.data.materials.append(skin)
    obj.active_material_index = 0
    yield obj, cloth, skin
    blender_addon.unregister()


def _remove(obj: bpy.types.Object, **kwargs) -> set[str]:
    with bpy.context.temp_override(object=obj, active_object=obj):
        return bpy.ops.spectral_skin.remove(**kwargs)


@pytest.mark.parametrize("mode", ["LIVE", "BAKE"])
def test_a_material_named_is_wired_and_the_active_one_left_alone(character, mode):
    obj, cloth, skin = character
    before = snapshot()
    assert run_invert(obj, mode=mode, material="Skin") == {"FINISHED"}
    assert wiring.wired_group_node(skin) is not None
    assert not any(wiring.is_added(n) for n in cloth.node_tree.nodes)
    assert obj.active_material == cloth
    assert panels.slot_materials(obj) == [(cloth, False), (skin, True)]
    assert _remove(obj, material="Skin") == {"FINISHED"}
    assert panels.slot_materials(obj) == [(cloth, False), (skin, False)]
    after = snapshot()
    for name in ("Cloth", "Skin"):
        assert after["materials"][name] == before["materials"][name]


def test_a_name_not_in_the_slots_is_refused_and_nothing_changes(character):
    obj, _, _ = character
    before = snapshot()
    with pytest.raises(RuntimeError, match="material 'Face' is not in the slots of 'Sphere' \\(its materials: "
                                           "'Cloth', 'Skin'\\)"):
        run_invert(obj, mode="LIVE", material="Face")
    with pytest.raises(RuntimeError, match="material 'Face' is not in the slots"):
        run_invert(obj, mode="BAKE", material="Face")
    with pytest.raises(RuntimeError, match="material 'Face' is not in the slots"):
        _remove(obj, material="Face")
    assert snapshot() == before
