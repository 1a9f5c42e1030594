"""Unusual and bad input for Invert Skin Albedo (real bpy) and bake.py: valid special images give the right
maps; bad ones give a clear message and change nothing (images, node groups, materials, files)."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from blender_addon import bake as bake_cli  # noqa: E402
from blender_addon import preferences  # noqa: E402
from exporters import bake, colorimetry, maps  # noqa: E402
from tests.addon_scene import run_invert, skin_object, snapshot, write_image  # noqa: E402
from tests.onnx_fakes import missing_outputs_model, wrong_input_model  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CODES = np.array([[[224, 172, 150], [150, 100, 80]], [[90, 60, 45], [224, 172, 150]]], np.uint8)  # 2 x 2


def bake_files(path: Path, out: Path) -> Path:
    """Bake ``path`` with exporters.bake (every texel through the model) into ``out``."""
    out.mkdir()
    bake.bake(path, out, preferences.DEFAULT_MODEL, bake.BakeOptions(threads=1))
    return out


def color_map(folder: Path, stem: str, k: int = 1) -> np.ndarray:
    return maps.read_exr(folder / f"{stem}_k{k}_color.exr")[0]


# -- valid special images: right maps ------------------------------------------------------------------------


def test_png_16bit_exr_grayscale_alpha_give_the_maps_of_their_colours(tmp_path):
    ref = bake_files(write_image(tmp_path / "s8.png", CODES, "uint8"), tmp_path / "r8")
    # 16-bit PNG of the same codes (x 257 is exact): same linear values, same maps
    s16 = write_image(tmp_path / "s16.png", CODES.astype(np.uint16) * 257, "uint16")
    np.testing.assert_array_equal(color_map(bake_files(s16, tmp_path / "r16"), "s16"), color_map(ref, "s8"))
    # float EXR holding the decoded values: linear, the same maps up to float32 rounding of the input
    lin = colorimetry.srgb_decode(CODES / 255.0).astype(np.float32)
    exr = write_image(tmp_path / "sf.exr", lin, "float")
    np.testing.assert_allclose(color_map(bake_files(exr, tmp_path / "rf"), "sf"), color_map(ref, "s8"), rtol=1e-5,
                               atol=1e-6)
    # alpha is ignored (straight alpha, colour untouched)
    rgba = np.concatenate([CODES, np.array([[[255], [0]], [[128], [255]]], np.uint8)], axis=2)
    ra = bake_files(write_image(tmp_path / "sa.png", rgba, "uint8"), tmp_path / "ra")
    np.testing.assert_array_equal(color_map(ra, "sa"), color_map(ref, "s8"))
    assert any("alpha channel ignored" in n for n in _json(ra, "sa")["notes"])
    # grayscale: the gray value for R, G and B
    gray = write_image(tmp_path / "g.png", CODES[..., 1], "uint8")
    gray_rgb = write_image(tmp_path / "g3.png", np.repeat(CODES[..., 1:2], 3, axis=2), "uint8")
    rg = bake_files(gray, tmp_path / "rg")
    np.testing.assert_array_equal(color_map(rg, "g"), color_map(bake_files(gray_rgb, tmp_path / "rg3"), "g3"))
    assert any("grayscale" in n for n in _json(rg, "g")["notes"])


def _json(folder: Path, stem: str) -> dict:
    import json

    return json.loads((folder / f"{stem}_maps.json").read_text())


def test_one_by_one_and_non_square_in_blender(addon, tmp_path):
    one = write_image(tmp_path / "one.png", CODES[:1, :1], "uint8")
    wide = write_image(tmp_path / "wide.png", np.concatenate([CODES[0], CODES[1]])[None], "uint8")  # 4 x 1
    for path, size in ((one, (1, 1)), (wide, (4, 1))):
        obj, mat, _ = skin_object(path, name=path.stem)
        assert run_invert(obj, backend="SVM") == {"FINISHED"}
        image = bpy.data.images[f"{path.stem}_k1_color.exr"]
        assert tuple(image.size) == size
        ref = color_map(bake_files(path, tmp_path / f"ref_{path.stem}"), path.stem)
        px = np.empty(size[0] * size[1] * 4, np.float32)
        image.pixels.foreach_get(px)
        np.testing.assert_allclose(px.reshape(size[1], size[0], 4)[::-1, :, :3], ref, rtol=1e-6, atol=1e-7)


# -- bad input: clear message, nothing changed ----------------------------------------------------------------


def _fails(obj, match: str, folder: Path | None = None, **kwargs) -> None:
    before = snapshot(folder)
    with pytest.raises(RuntimeError, match=match):
        run_invert(obj, **kwargs)
    assert snapshot(folder) == before


def test_no_active_image(addon):
    obj, mat, _ = skin_object(None)
    _fails(obj, "no albedo image: no Image Texture with an image feeds the Principled BSDF's Base Color")
    _fails(obj, "no image named 'nope'", image_name="nope")


def test_missing_and_unreadable_files(addon, tmp_path):
    png = write_image(tmp_path / "gone.png", CODES, "uint8")
    obj, mat, _ = skin_object(png)
    png.unlink()
    _fails(obj, "the file of image 'gone.png' is missing")
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not a png at all")
    _fails(obj, "cannot read image .*junk.png", filepath=str(junk))
    _fails(obj, "albedo image not found", filepath=str(tmp_path / "never.png"))


def test_nan_and_negative_texels(addon, tmp_path):
    bad = np.full((2, 3, 3), 0.4, np.float32)
    bad[1, 2, 0] = np.nan
    neg = np.full((2, 3, 3), 0.4, np.float32)
    neg[0, 1, 2] = -0.2
    obj, mat, _ = skin_object(None)
    _fails(obj, r"1 texel\(s\) with NaN/Inf, first at \(x=2, y=1\)", filepath=str(write_image(tmp_path / "n.exr", bad,
                                                                                               "float")))
    _fails(obj, r"negative values, first at \(x=1, y=0\)", filepath=str(write_image(tmp_path / "m.exr", neg, "float")))
    # the same problems in an image that only lives in Blender
    img = bpy.data.images.new("painted_nan", 2, 1, float_buffer=True)
    img.pixels.foreach_set(np.array([0.4, np.nan, 0.4, 1, 0.4, 0.4, 0.4, 1], np.float32))
    _fails(obj, "painted_nan': 1 texel", image_name="painted_nan")


def read_only_folder(tmp_path: Path) -> Path:
    """A folder this process cannot write: a chmod-ed one, or for root (who ignores permissions) /proc/sys, which
    the kernel keeps read-only even for root."""
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(stat.S_IRUSR | stat.S_IXUSR)
    if not os.access(ro, os.W_OK):
        return ro
    if os.access("/proc/sys", os.W_OK):
        pytest.skip("no folder here that this user cannot write")
    return Path("/proc/sys")


def test_read_only_and_existing_output(addon, tmp_path):
    png = write_image(tmp_path / "alb.png", CODES, "uint8")
    obj, mat, _ = skin_object(png)
    ro = read_only_folder(tmp_path)
    _fails(obj, "output folder is not writable", folder=ro, storage="FILES", output_dir=str(ro))
    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "alb_k1_color.exr").write_bytes(b"the user's file")
    _fails(obj, r"1 file\(s\) exist in .*allow overwriting", folder=taken, storage="FILES", output_dir=str(taken))
    assert (taken / "alb_k1_color.exr").read_bytes() == b"the user's file"
    _fails(obj, "save the .blend first", storage="FILES")


def test_missing_or_wrong_model(addon, tmp_path):
    obj, mat, _ = skin_object(write_image(tmp_path / "alb.png", CODES, "uint8"))
    for model, match in ((tmp_path / "none.onnx", "model not found at"),
                         (wrong_input_model(tmp_path / "w.onnx"), r"expected one input 'albedo_rgb' of shape \(N, 3\)"),
                         (missing_outputs_model(tmp_path / "m.onnx"), r"lacks output\(s\)")):
        addon.model_path = str(model)
        _fails(obj, match)


# -- the same through bake.py -------------------------------------------------------------------------------


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "blender_addon" / "bake.py"), *args], capture_output=True,
                          text=True, timeout=120)


def test_bake_py_bad_input_exit_2_and_writes_nothing(tmp_path, capsys):
    png = write_image(tmp_path / "alb.png", CODES, "uint8")
    nan = np.full((2, 2, 3), 0.3, np.float32)
    nan[0, 0, 1] = np.inf
    cases = [
        (["--albedo", str(tmp_path / "none.png")], "albedo image not found"),
        (["--albedo", str(write_image(tmp_path / "nan.exr", nan, "float"))], "NaN/Inf"),
        (["--albedo", str(png), "--model", str(wrong_input_model(tmp_path / "w.onnx"))], "albedo_rgb"),
        (["--albedo", str(png), "--model", str(tmp_path / "none.onnx")], "model not found"),
    ]
    out = tmp_path / "out"
    for args, match in cases:
        proc = _cli(*args, "--out", str(out))
        assert proc.returncode == 2 and match in proc.stderr and proc.stderr.count("\n") == 1, proc.stderr
        assert not out.exists()  # the folder it created is removed again
    target = read_only_folder(tmp_path) / "maps"
    assert bake_cli.main(["--albedo", str(png), "--out", str(target), "--quiet"]) == 2
    assert "not writable" in capsys.readouterr().err and not target.exists()
