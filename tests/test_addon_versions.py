"""Every supported Blender: the extension zip (blender_addon/package.py) installs through Blender's own extension
system, enables, bakes, renders and exits cleanly in the oldest (bpy 4.2 LTS, Python 3.11), the project's own
(bpy 5.0.1) and the newest (bpy 5.3, Python 3.13) Blender.

The other Blenders live in their own virtual environments, which ``make test`` creates (``make blender-envs``:
.venv-blender42, .venv-blender53, with tests/blender_env.py giving them Blender's bundled site-packages); each runs
tests/installed_addon_check.py in a fresh process with a sandboxed user folder.  A missing environment skips its
case and says how to make it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.blender_versions import BLENDERS, IDS, run_check

ROOT = Path(__file__).resolve().parents[1]
CHECK = ROOT / "tests" / "installed_addon_check.py"


@pytest.fixture(scope="module")
def blender_50(tmp_path_factory) -> dict:
    """The version check's thin back-lit disk (per backend) and its read-back of the live group's media, rendered here
    in the project's own Blender 5.0.1 with the project's add-on: the translucency the media were made for (Cycles'
    Random Walk dividing the radius by 4 pi, the convention of exporters.cycles and of the tests against
    adding-doubling) and the media tests/test_live_group.py compares with exporters.live_table.group_media within
    2e-4."""
    import bpy

    from blender_addon import nodes
    from tests import installed_addon_check as check

    def wire(material, backend: str):
        group = nodes.build_osl_group(1) if backend == "OSL" else nodes.build_svm_group(1)
        return nodes.wire_into_material(material, group)

    folder = str(tmp_path_factory.mktemp("blender_50"))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    try:
        thin = {backend: np.array(check.thin_disk_centre(backend, wire, folder)) for backend in ("SVM", "OSL")}
        media = {name: np.array(value) for name, value in check.live_media("blender_addon", folder).items()}
    finally:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    return {"thin": thin, "live_media": media}


@pytest.mark.parametrize("case,python,version,py_version", BLENDERS, ids=IDS)
def test_installs_bakes_renders_and_exits_cleanly(case, python, version, py_version, ext_zip, tmp_path,
                                                  blender_50):
    # The script is left to exit by itself with the add-on still enabled: a hang is a timeout, a crash a signal.
    out = run_check(python, CHECK, ext_zip, tmp_path, timeout=240)
    assert out["blender"].startswith(version) and out["python"] == py_version, out
    assert out["enabled"]
    # Self-contained: the core is the extension's own subpackage; nothing top-level, nothing on sys.path.
    assert out["core"] == "bl_ext.user_default.spectral_skin_sss.exporters"
    assert out["top_level_modules"] == [] and not out["extension_on_sys_path"]
    assert not out["openimageio_imported_by_enabling"]  # Blender 4.2 has no OpenImageIO module of its own
    # The network runs with the onnxruntime wheel the zip carries for this Python.
    assert out["inference_finite"]
    site = f"{tmp_path / 'user'}/extensions/.local/lib/python{py_version}/site-packages/onnxruntime/"
    if case != "5.0-project":  # the project env has its own onnxruntime, found first
        assert out["onnxruntime"].startswith(site), out["onnxruntime"]
    # The baked path, every colour through the network (on 4.2, with no OpenImageIO module, the maps are written
    # uncompressed by exporters.exr).
    assert out["invert"] == ["FINISHED"] and out["group_backend"] == "SVM", out
    assert out["openimageio"] is None if case == "4.2" else out["openimageio"]
    # bake.py of the installed extension, run inside Blender: the extension's exporters, no top-level one.  It reads
    # the albedo file with OpenImageIO, which 4.2 lacks: a one-line error there.
    assert out["bake_script_exit"] == (2 if case == "4.2" else 0) and out["top_level_modules_after_script"] == []
    assert out["bake_script_files"] == (0 if case == "4.2" else 13)  # K = 3: 12 maps and the record
    # SVM by default, OSL only on request, and the scene's shading system untouched by either operator.
    assert not out["shading_system_after_invert"] and not out["shading_system_after_add_osl"]
    assert out["add_osl"] == ["FINISHED"] and out["osl_compiled"]
    # The live group (the operator's default) installs and renders skin on every version.
    assert out["live_invert"] == ["FINISHED"] and any("Live" in name for name in out["live_group"]), \
        out.get("live_invert_error", out)
    for key in ("svm_centre", "osl_centre", "live_centre"):  # skin-coloured: red > green > blue > 0, nothing black
        r, g, b = out[key]
        assert r > g > b > 0.05, (key, out[key])
    # A preset's edit renders from its cache as from the table, whose texels are drawn per sample: the two renders
    # differ by their noise (under 1 % at 256 samples; the flush changes the colour by 7-20 %).
    assert out["edit_preset"] == ["FINISHED"] and out["edit_cache"] == "Rendered from edit cache 1", out
    np.testing.assert_allclose(out["edit_centre_cached"], out["edit_centre_table"], rtol=2e-2)
    assert not np.allclose(out["edit_centre_cached"], out["live_centre"], rtol=1e-2)  # the edit shows
    # Painted by a mask through Edit Mask: from the mask cache, as from the table, and weaker than the full edit.
    assert out["edit_mask_cache"] == "Rendered from the mask cache", out
    np.testing.assert_allclose(out["edit_mask_centre_cached"], out["edit_mask_centre_table"], rtol=2e-2)
    assert not np.allclose(out["edit_mask_centre_cached"], out["edit_centre_cached"], rtol=1e-2)
    # A blush keyframed on Blood holds its line in the mask cache (the keys read through this version's action API).
    assert out["keyed_line"] == [1.0, 2.5, 0.0] and out["keyed_status"] == "Animation render: from the mask cache", out
    assert out["edit_twelfth_cache"] == "Rendered from edit cache 16", out  # a twelfth constant edit: the last cache
    np.testing.assert_allclose(out["edit_twelfth_centre_cached"], out["edit_twelfth_centre_table"], rtol=2e-2)
    assert out["edit_spare_cache"] == "Rendered from edit cache 7", out  # a fifteenth constant edit: the last spare
    np.testing.assert_allclose(out["edit_spare_centre_cached"], out["edit_spare_centre_table"], rtol=2e-2)
    assert not np.allclose(out["edit_spare_centre_cached"], out["edit_centre_cached"], rtol=1e-2)
    assert out["use_edit_mask"] == ["FINISHED"] and out["use_edit_mask_cache"] == "Rendered from the mask cache", out
    # A skin material appended from another file renders through this file's groups; the copies it brought are unused.
    assert out["appended_group"] == "Spectral Skin SSS Live" and out["appended_copies_used"] == [], out
    # Melanin fed by a Value node renders from a cache; a bake takes the live group's edit, Blood painted by a mask.
    assert out["value_fed_cache"].startswith("Rendered from edit cache"), out
    assert out["live_edit_bake"] == ["FINISHED"], out
    np.testing.assert_allclose(out["live_edit_bake_centre"], out["values_bake_centre"], rtol=1e-5)
    assert not np.allclose(out["live_edit_bake_centre"], out["live_centre"], rtol=1e-2)  # the edit shows
    # The same translucency as in Blender 5.0: a thin back-lit disk lets through what it lets through there, within
    # 5 % (two renders' noise: about 3 % at 3 sigma).  Blender 5.3's plain "Random Walk" takes radii 4 pi times longer.
    for backend, reference in blender_50["thin"].items():
        np.testing.assert_allclose(out[f"thin_{backend.lower()}"], reference, rtol=0.05, err_msg=backend)
    # The Principled BSDF inside a node group: the live group goes in there and renders what it renders flat.
    assert out["grouped_invert"] == ["FINISHED"] and out["grouped_restored"], out
    assert out["grouped_outputs"] == ["BSDF", "Cycles (Spectral Skin SSS)", "EEVEE (Spectral Skin SSS)"]
    np.testing.assert_allclose(out["grouped_centre"], out["live_centre"], rtol=1e-6)
    assert out["grouped_exposed"][0] == 1.5 and out["grouped_exposed"][1].startswith("Rendered from edit cache"), out
    assert out["grouped_bake"] == ["FINISHED"] and out["grouped_bake_restored"], out
    assert out["grouped_bake_inside"] == 12  # K = 3: the twelve maps, in the node group
    np.testing.assert_allclose(out["grouped_bake_centre"], out["flat_bake_centre"], rtol=1e-6)
    # The live group's nodes compute the same media in every version (its curves, Map Ranges, clamps and mixes).
    for name, reference in blender_50["live_media"].items():
        np.testing.assert_allclose(out["live_media"][name], reference, rtol=2e-4, atol=1e-6, err_msg=name)


@pytest.mark.parametrize("case,python,version,py_version", BLENDERS, ids=IDS)
def test_a_script_that_registers_and_never_unregisters_exits_cleanly(case, python, version, py_version, ext_zip,
                                                                       tmp_path):
    # Blender 4.2's bpy module crashes and 4.5's hangs at exit when classes are left registered.
    out = run_check(python, CHECK, ext_zip, tmp_path, 120, "register-only")
    assert out["blender"].startswith(version) and out["registered"] and not out["enabled"]
