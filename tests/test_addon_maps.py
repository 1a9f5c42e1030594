"""exporters.maps and exporters.image_input with real files written by OpenImageIO in temporary folders."""

from __future__ import annotations

import json
import os
import stat

import numpy as np
import OpenImageIO as oiio
import pytest

from exporters import image_input, maps


def write_image(path, pixels: np.ndarray, fmt: str, **attrs) -> str:
    pixels = pixels if pixels.ndim == 3 else pixels[..., None]
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, fmt)
    if c == 4:
        spec.alpha_channel = 3
        spec.attribute("oiio:UnassociatedAlpha", 1)  # the buffer is straight (not premultiplied) colour
    for key, value in attrs.items():
        spec.attribute(key.replace("__", ":"), value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), oiio.geterror()
    assert out.write_image(pixels)
    out.close()
    return str(path)


def srgb_to_linear(v):
    """IEC 61966-2-1 decoding, written out here as the independent reference."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def test_8bit_png_is_srgb_decoded(tmp_path):
    codes = np.array([[[0, 10, 128], [200, 255, 64]]], dtype=np.uint8)  # 1 x 2, non-square
    img = image_input.read_albedo(write_image(tmp_path / "a.png", codes, "uint8"))
    assert img.colorspace == "srgb" and img.source_format == "uint8" and img.alpha is None
    assert img.rgb.shape == (1, 2, 3) and img.rgb.dtype == np.float64
    np.testing.assert_allclose(img.rgb, srgb_to_linear(codes / 255.0), rtol=1e-12, atol=1e-15)


def test_16bit_png_with_alpha_unassociated(tmp_path):
    rgba = np.zeros((3, 5, 4), dtype=np.uint16)
    rgba[..., :3] = 40000
    rgba[..., 3] = 32768  # half transparent: colour must NOT be premultiplied
    rgba[0, 0, 3] = 0
    img = image_input.read_albedo(write_image(tmp_path / "a16.png", rgba, "uint16"))
    assert img.source_format == "uint16" and img.rgb.shape == (3, 5, 3)
    np.testing.assert_allclose(img.rgb, srgb_to_linear(40000 / 65535), rtol=1e-4)
    np.testing.assert_allclose(img.alpha[1:], 32768 / 65535, rtol=1e-4)
    assert img.alpha[0, 0] == 0.0


def test_float_exr_is_linear_and_override(tmp_path):
    vals = np.array([[[0.2, 0.5, 0.9]]], dtype=np.float32)  # 1x1
    path = write_image(tmp_path / "a.exr", vals, "float")
    img = image_input.read_albedo(path)
    assert img.colorspace == "linear" and img.rgb.shape == (1, 1, 3)
    np.testing.assert_allclose(img.rgb[0, 0], vals[0, 0], rtol=0)
    forced = image_input.read_albedo(path, colorspace="srgb")
    np.testing.assert_allclose(forced.rgb[0, 0], srgb_to_linear(vals[0, 0]), rtol=1e-6)


def test_png_tagged_linear_is_not_decoded(tmp_path):
    codes = np.full((2, 2, 3), 128, dtype=np.uint8)
    img = image_input.read_albedo(write_image(tmp_path / "lin.png", codes, "uint8", oiio__ColorSpace="linear"))
    assert img.colorspace == "linear"
    np.testing.assert_allclose(img.rgb, 128 / 255, rtol=1e-12)


def test_grayscale_and_gray_alpha(tmp_path):
    gray = np.array([[0, 255], [128, 64]], dtype=np.uint8)
    img = image_input.read_albedo(write_image(tmp_path / "g.png", gray, "uint8"))
    assert img.rgb.shape == (2, 2, 3)
    np.testing.assert_allclose(img.rgb[..., 0], img.rgb[..., 2])
    np.testing.assert_allclose(img.rgb[..., 1], srgb_to_linear(gray / 255.0))
    ga = np.stack([gray, np.full_like(gray, 255)], axis=-1)
    spec_path = tmp_path / "ga.png"
    h, w, c = ga.shape
    spec = oiio.ImageSpec(w, h, c, "uint8")
    spec.channelnames = ("Y", "A")
    spec.alpha_channel = 1
    out = oiio.ImageOutput.create(str(spec_path))
    assert out.open(str(spec_path), spec)
    out.write_image(ga)
    out.close()
    img2 = image_input.read_albedo(spec_path)
    np.testing.assert_allclose(img2.rgb, img.rgb)
    np.testing.assert_allclose(img2.alpha, 1.0)


def test_nan_and_negative_texels(tmp_path):
    bad = np.full((4, 3, 3), 0.5, dtype=np.float32)
    bad[2, 1, 0] = np.nan
    with pytest.raises(image_input.ImageError, match=r"1 texel\(s\) with NaN/Inf, first at \(x=1, y=2\)"):
        image_input.read_albedo(write_image(tmp_path / "nan.exr", bad, "float"))
    neg = np.full((4, 3, 3), 0.5, dtype=np.float32)
    neg[0, 2, 1] = -0.01
    path = write_image(tmp_path / "neg.exr", neg, "float")
    with pytest.raises(image_input.ImageError, match=r"negative values, first at \(x=2, y=0\)"):
        image_input.read_albedo(path)
    img = image_input.read_albedo(path, clamp_negative=True)
    assert img.n_clamped == 1 and img.rgb.min() == 0.0


def test_missing_unreadable_and_bad_arguments(tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        image_input.read_albedo(tmp_path / "nope.png")
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"this is not a png")
    with pytest.raises(image_input.ImageError, match="cannot read"):
        image_input.read_albedo(junk)
    with pytest.raises(ValueError, match="colorspace"):
        image_input.read_albedo(junk, colorspace="rec2020")


def test_exr_round_trip_channels_units_no_overwrite(tmp_path):
    data = np.random.default_rng(0).uniform(0, 5, size=(3, 7, 3))
    path = maps.write_exr(tmp_path / "S_k1_radius.exr", data, maps.RGB_CHANNELS, units="Blender units")
    back, names, attrs = maps.read_exr(path)
    assert names == ("R", "G", "B")
    np.testing.assert_allclose(back, data.astype(np.float32))
    assert attrs["spectral_skin_sss:units"] == "Blender units"
    assert attrs["spectral_skin_sss:colorspace"] == "Non-Color"
    with pytest.raises(FileExistsError, match="overwrite"):
        maps.write_exr(path, data * 2, maps.RGB_CHANNELS, units="Blender units")
    np.testing.assert_allclose(maps.read_exr(path)[0], data.astype(np.float32))  # untouched
    maps.write_exr(path, data * 2, maps.RGB_CHANNELS, units="Blender units", overwrite=True)
    np.testing.assert_allclose(maps.read_exr(path)[0], (data * 2).astype(np.float32))
    bio_vals = np.arange(6.0).reshape(1, 1, 6)
    bio = maps.write_exr(tmp_path / "S_biophysical.exr", bio_vals, maps.BIOPHYSICAL_CHANNELS, "mixed")
    raw, raw_names, _ = maps.read_exr(bio)  # EXR sorts channel names
    assert sorted(raw_names) == sorted(maps.BIOPHYSICAL_CHANNELS)
    assert raw[0, 0, raw_names.index("so2")] == 3.0
    ordered, names, _ = maps.read_exr(bio, channels=maps.BIOPHYSICAL_CHANNELS)
    assert names == maps.BIOPHYSICAL_CHANNELS and ordered[0, 0].tolist() == bio_vals[0, 0].tolist()
    with pytest.raises(KeyError, match="melanin"):
        maps.read_exr(bio, channels=("melanin",))
    one = maps.write_exr(tmp_path / "S_k1_anisotropy.exr", np.full((2, 2), 0.7), maps.SINGLE_CHANNEL, "1")
    assert maps.read_exr(one)[0].shape == (2, 2, 1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["S_biophysical.exr", "S_k1_anisotropy.exr",
                                                          "S_k1_radius.exr"]  # no temporaries left


def test_exr_rejects_bad_data(tmp_path):
    with pytest.raises(ValueError, match="NaN/Inf"):
        maps.write_exr(tmp_path / "x.exr", np.array([[np.nan]]), maps.SINGLE_CHANNEL, "1")
    with pytest.raises(ValueError, match="channel names"):
        maps.write_exr(tmp_path / "x.exr", np.zeros((2, 2, 3)), maps.SINGLE_CHANNEL, "1")
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores folder permissions")
def test_read_only_output_folder_nonroot(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        with pytest.raises(PermissionError, match="not writable"):
            maps.write_exr(ro / "a.exr", np.zeros((1, 1)), maps.SINGLE_CHANNEL, "1")
    finally:
        ro.chmod(stat.S_IRWXU)


def test_read_only_output_folder(tmp_path, monkeypatch):
    # Also runs as root (which bypasses permission bits): os.access is what the writer consults.
    ro = tmp_path / "ro"
    ro.mkdir()
    real_access = os.access
    monkeypatch.setattr(maps.os, "access", lambda p, mode: False if str(p) == str(ro) else real_access(p, mode))
    with pytest.raises(PermissionError, match="not writable"):
        maps.write_exr(ro / "a.exr", np.zeros((1, 1)), maps.SINGLE_CHANNEL, "1")
    with pytest.raises(PermissionError, match="not writable"):
        maps.write_maps_json(ro / "S_maps.json", {}, 1, {}, "a.png", "srgb", {})
    with pytest.raises(FileNotFoundError, match="does not exist"):
        maps.write_exr(tmp_path / "missing" / "a.exr", np.zeros((1, 1)), maps.SINGLE_CHANNEL, "1")


def test_maps_json(tmp_path):
    maps.write_exr(tmp_path / "S_k1_color.exr", np.zeros((1, 1, 3)), maps.RGB_CHANNELS, "1")
    model = tmp_path / "m.onnx"
    model.write_bytes(b"abc")
    sha = maps.sha256_file(model)
    assert sha == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"  # FIPS 180-2 "abc"
    files = {"S_k1_color.exr": {"units": "1", "channels": ["R", "G", "B"]}}
    path = maps.write_maps_json(tmp_path / "S_maps.json", files, 1, {"skin_inversion.onnx": sha}, "S.png", "srgb",
                                {"inference": 1.5}, unit_scale_m=1.0)
    rec = json.loads(path.read_text())
    assert rec["K"] == 1 and rec["files"] == files and rec["input"]["colorspace"] == "srgb"
    assert rec["model_sha256"]["skin_inversion.onnx"] == sha and rec["timings_s"]["inference"] == 1.5
    with pytest.raises(FileExistsError):
        maps.write_maps_json(path, files, 1, {}, "S.png", "srgb", {})
    with pytest.raises(FileNotFoundError, match="not in"):
        maps.write_maps_json(tmp_path / "T_maps.json", {"T_k1_color.exr": {}}, 1, {}, "T.png", "srgb", {})
