"""exporters.image_input: one verdict for an albedo however it arrives (file read densely, file read as a
palette, a Blender pixel buffer), the colour-space names of the installed Blender and OpenImageIO, and the
one-place helpers of the bake (folder checks, error lines).  Real files, real bpy, real OpenImageIO."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import bpy
import numpy as np
import OpenImageIO as oiio
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from blender_addon import baker, preferences  # noqa: E402
from exporters import bake, image_input, inference, maps  # noqa: E402
from exporters.image_input import ImageError  # noqa: E402
from tests.addon_scene import write_image  # noqa: E402

L, S = "linear", "srgb"
#: Every colour space of Blender 5.0's OCIO config (ColorManagedInputColorspaceSettings.name), classified by
#: hand from its description: the transfer curve, not the primaries.  "log" must be refused.
BLENDER_5_0 = {
    "ACES 1.3 sRGB": S, "ACES 2.0 sRGB": S, "ACES2065-1": L, "ACEScc": "log", "ACEScct": "log", "ACEScg": L,
    "AgX Base sRGB": S, "AgX Log": "log", "Display P3": S, "Filmic Log": "log", "Filmic sRGB": S,
    "Khronos PBR Neutral sRGB": S, "Linear CIE-XYZ D65": L, "Linear CIE-XYZ E": L, "Linear DCI-P3 D65": L,
    "Linear FilmLight E-Gamut": L, "Linear Rec.2020": L, "Linear Rec.709": L, "Non-Color": L, "Rec.1886": None,
    "Rec.2020": None, "Rec.2100-HLG": None, "Rec.2100-PQ": None, "sRGB": S, "scene_linear": L,
}
#: Blender <= 3.6 and OpenImageIO's older names.
OLDER = {"Linear": L, "Linear ACES": L, "Linear ACEScg": L, "Raw": L, "XYZ": L, "linear": L, "lin_srgb": L,
         "data": L, "srgb-linear": L, "srgb_linear": L, "linear_srgb": L, "rec709_linear": L, "GammaCorrected2.2": None,
         "Rec709": None, "": None}
_G = ("Gamma 1.8 Encoded Rec.709", "g18_encoded_rec709", "Utility - Gamma 1.8 - Rec.709 - Texture", "g18_rec709",
      "Gamma 1.8 Rec.709 - Texture", "g18_rec709_tx", "g18_rec709_scene", "Gamma 2.2 Encoded Rec.709",
      "g22_encoded_rec709", "Utility - Gamma 2.2 - Rec.709 - Texture", "g22_rec709", "Gamma 2.2 Rec.709 - Texture",
      "g22_rec709_tx", "g22_rec709_scene", "Gamma 2.4 Encoded Rec.709", "g24_encoded_rec709", "g24_rec709",
      "rec709_display", "Utility - Rec.709 - Display", "Gamma 2.4 Rec.709 - Texture", "g24_rec709_tx",
      "Gamma 2.2 Encoded AdobeRGB", "g22_encoded_adobergb", "adobergb", "g22_adobergb_scene", "Gamma 2.2 Encoded AP1",
      "g22_encoded_ap1", "g22_ap1", "Gamma 2.2 AP1 - Texture", "g22_ap1_tx", "g22_ap1_scene",
      "Rec.1886 Rec.709 - Display", "rec1886_rec709_display", "Rec.2100-PQ - Display", "rec2100_pq_display",
      "ST2084-P3-D65 - Display", "st2084_p3d65_display", "P3-D65 - Display", "p3d65_display")
_S = ("sRGB - Display", "srgb_display", "Display P3 - Display", "displayp3_display", "sRGB Encoded Rec.709 (sRGB)",
      "srgb_encoded_rec709_srgb", "Utility - sRGB - Texture", "srgb_texture", "srgb_rec709_scene",
      "Input - Generic - sRGB - Texture", "sRGB - Texture", "srgb_tx", "sRGB Encoded P3-D65", "srgb_encoded_p3d65",
      "srgb_p3d65", "srgb_displayp3", "srgb_p3d65_scene", "sRGB Encoded P3-D65 - Texture", "srgb_encoded_p3d65_tx",
      "sRGB Encoded AP1", "srgb_encoded_ap1", "srgb_ap1", "srgb_ap1_scene", "sRGB Encoded AP1 - Texture",
      "srgb_encoded_ap1_tx")
_L = ("ACES2065-1", "aces2065_1", "aces", "ACES - ACES2065-1", "lin_ap0", "lin_ap0_scene", "ACEScg", "ACES - ACEScg",
      "lin_ap1", "lin_ap1_scene", "Linear Rec.709 (sRGB)", "lin_rec709_srgb", "Utility - Linear - Rec.709",
      "lin_rec709", "lin_rec709_scene", "lin_srgb", "Utility - Linear - sRGB", "Linear P3-D65", "lin_p3d65",
      "Utility - Linear - P3-D65", "lin_displayp3", "lin_p3d65_scene", "Linear Display P3", "Linear AdobeRGB",
      "lin_adobergb", "Utility - Linear - Adobe RGB", "lin_adobergb_scene", "Linear Rec.2020", "lin_rec2020",
      "Utility - Linear - Rec.2020", "lin_rec2020_scene", "Raw", "Utility - Raw", "none")
_LOG = ("ACEScc", "ACES - ACEScc", "acescc_ap1", "ACEScct", "ACES - ACEScct", "acescct_ap1")
#: OpenImageIO 3.0's built-in OCIO config (the CG config): every name and alias.
OIIO_3_0 = {**dict.fromkeys(_G), **dict.fromkeys(_S, S), **dict.fromkeys(_L, L), **dict.fromkeys(_LOG, "log")}
TABLE = {**OLDER, **OIIO_3_0, **BLENDER_5_0}


def _classify(name: str) -> str | None:
    try:
        return image_input.colorspace_of_name(name)
    except ImageError as exc:
        assert "log encoding" in str(exc) and name in str(exc)
        return "log"


def test_every_blender_and_oiio_colour_space_is_classified():
    blender = {it.identifier for it in bpy.types.ColorManagedInputColorspaceSettings.bl_rna.properties["name"]
               .enum_items}
    config = oiio.ColorConfig()
    oiio_names = set(config.getColorSpaceNames())
    oiio_names |= {a for n in config.getColorSpaceNames() for a in config.getAliases(n)}
    assert blender <= set(TABLE), f"classify the new Blender colour spaces {sorted(blender - set(TABLE))}"
    assert oiio_names <= set(TABLE), f"classify the new OpenImageIO colour spaces {sorted(oiio_names - set(TABLE))}"
    wrong = {name: (_classify(name), want) for name, want in TABLE.items() if _classify(name) != want}
    assert not wrong, wrong


def _spec_named(name: str, fmt: str = "uint8") -> oiio.ImageSpec:
    spec = oiio.ImageSpec(1, 1, 3, fmt)
    spec.attribute("oiio:ColorSpace", name)
    return spec


@pytest.mark.parametrize("name", sorted(BLENDER_5_0))
def test_file_and_addon_read_a_colour_space_alike(name):
    """The add-on's From Image and a file's own tag give the same encoding (before: two lists that disagreed,
    e.g. the add-on read Filmic Log / AgX Log as linear; now every path refuses log encodings)."""
    want = BLENDER_5_0[name]
    image = bpy.data.images.new(f"cs {name}", 1, 1)
    image.colorspace_settings.name = name
    try:
        if want == "log":
            with pytest.raises(ImageError, match="log encoding"):
                baker._image_colorspace(image, "FROM_IMAGE")
            with pytest.raises(ImageError, match="log encoding"):
                image_input._detect_colorspace(_spec_named(name), "x.png")
            return
        assert baker._image_colorspace(image, "FROM_IMAGE") == (want or "auto")
        # no name match: 8-bit files are sRGB, float files linear (docs/contracts.md §1)
        assert image_input._detect_colorspace(_spec_named(name), "x.png") == (want or "srgb")
        assert image_input._detect_colorspace(_spec_named(name, "float"), "x.exr") == (want or "linear")
    finally:
        bpy.data.images.remove(image)


def test_srgb_linear_is_linear():
    """Where the two lists disagreed: the add-on's prefix rule read "srgb_linear" as sRGB."""
    assert image_input.colorspace_of_name("sRGB_linear") == "linear"
    assert image_input.colorspace_of_name("sRGB-linear") == "linear"


def _rgba(bad_alpha: float = 1.0, neg: float = 0.4) -> np.ndarray:
    px = np.full((2, 3, 4), 0.4, np.float32)
    px[..., 3] = 1.0
    px[0, 1, 3] = bad_alpha
    px[1, 2, 0] = neg
    return px


def _pixels_image(name: str, px: np.ndarray) -> bpy.types.Image:
    h, w, _ = px.shape
    image = bpy.data.images.new(name, w, h, alpha=True, float_buffer=True)
    image.pixels.foreach_set(np.ascontiguousarray(px[::-1]).ravel())  # Blender rows are bottom-up
    return image


def test_nan_alpha_is_refused_by_every_reader(tmp_path):
    """Where the readers disagreed: the palette reader (the bake's) ignored a NaN alpha, the dense reader and the
    add-on's pixel path refused it.  A non-finite value anywhere means a broken file: all refuse it now."""
    path = write_image(tmp_path / "a.exr", _rgba(bad_alpha=np.nan), "float")
    msg = r"1 texel\(s\) with NaN/Inf, first at \(x=1, y=0\)"
    with pytest.raises(ImageError, match=msg):
        image_input.read_albedo(path)
    with pytest.raises(ImageError, match=msg):
        image_input.read_albedo_indexed(path)
    image = _pixels_image("nan alpha", _rgba(bad_alpha=np.nan))
    try:
        with pytest.raises(ImageError, match="image 'nan alpha': " + msg):
            baker._albedo_from_pixels(image, "linear")
    finally:
        bpy.data.images.remove(image)


def test_negative_texels_same_message_from_pixels_and_files(tmp_path):
    """The add-on's pixel path now counts the texels and names the first, as the file readers do."""
    msg = r"1 texel\(s\) with negative values, first at \(x=2, y=1\)"
    path = write_image(tmp_path / "n.exr", _rgba(neg=-0.1), "float")
    for read in (image_input.read_albedo, image_input.read_albedo_indexed):
        with pytest.raises(ImageError, match=msg):
            read(path)
    image = _pixels_image("negative", _rgba(neg=-0.1))
    try:
        with pytest.raises(ImageError, match=msg):
            baker._albedo_from_pixels(image, "linear")
        ok = baker._albedo_from_pixels(_pixels_image("fine", _rgba()), "linear")
        assert ok.alpha is None and ok.rgb.shape == (2, 3, 3)  # opaque buffer: no alpha
        np.testing.assert_allclose(ok.rgb, np.float32(0.4))
    finally:
        bpy.data.images.remove(image)
        bpy.data.images.remove(bpy.data.images["fine"])


def test_bake_of_a_checked_image_refuses_what_reading_refuses():
    """A hand-made AlbedoImage goes through the same check as a file (exporters.bake.masking)."""
    rgb = np.full((2, 2, 3), 0.3)
    rgb[1, 0, 2] = np.inf
    albedo = image_input.AlbedoImage(rgb=rgb, alpha=None, colorspace="linear", source_format="float", n_clamped=0)
    with pytest.raises(ImageError, match=r"albedo: 1 texel\(s\) with NaN/Inf, first at \(x=0, y=1\)"):
        bake.BakeJob.index(albedo)


def test_output_folder_checks_raise_one_kind(tmp_path):
    """One folder check for every writer (standard OSError types), the bake's included (it raised BakeError)."""
    with pytest.raises(FileNotFoundError, match="output folder does not exist"):
        maps.check_output_folder(tmp_path / "missing")
    (tmp_path / "file").write_text("x")
    with pytest.raises(NotADirectoryError, match="not a folder"):
        maps.check_output_folder(tmp_path / "file")
    with pytest.raises(NotADirectoryError, match="not a folder"):
        maps.make_output_folder(tmp_path / "file")
    with pytest.raises(FileNotFoundError, match="parent of the output folder b does not exist"):
        maps.make_output_folder(tmp_path / "a" / "b")
    assert maps.make_output_folder(tmp_path / "new") and (tmp_path / "new").is_dir()
    assert not maps.make_output_folder(tmp_path / "new")
    albedo = image_input.AlbedoImage(rgb=np.full((1, 1, 3), 0.3), alpha=None, colorspace="linear",
                                     source_format="float", n_clamped=0)
    opts = bake.BakeOptions(exact=True, cache_tables=False)
    model = inference.ModelFile(preferences.DEFAULT_MODEL)
    with pytest.raises(FileNotFoundError, match="output folder does not exist"):
        bake.BakeJob(albedo, tmp_path / "missing", "s", model, opts)


def test_one_line():
    """The error line of bake.py and of the add-on's operator (one function; each had its own copy)."""
    said = FileNotFoundError(2, "No such file or directory", "/tmp/gone.png")
    assert bake.one_line(said) == "[Errno 2] No such file or directory: '/tmp/gone.png'"  # the name once
    assert bake.one_line(ValueError("two\n  lines")) == "two lines"
    assert bake.one_line(RuntimeError()) == "RuntimeError"


def test_write_exr_is_the_bake_writer(tmp_path):
    """write_exr goes through MapStream: half maps, the units header, no temporaries, overflow named."""
    data = np.linspace(-1, 1, 12).reshape(2, 2, 3)
    path = maps.write_exr(tmp_path / "c.exr", data, maps.RGB_CHANNELS, "1", pixel_type="half")
    back, _, attrs = maps.read_exr(path)
    np.testing.assert_allclose(back, data, atol=2.5e-4)
    assert attrs["spectral_skin_sss:units"] == "1" and sorted(os.listdir(tmp_path)) == ["c.exr"]
    with pytest.raises(ValueError, match="overflow float32"):
        maps.write_exr(tmp_path / "big.exr", np.full((1, 1), 1e39), maps.SINGLE_CHANNEL, "1")
    assert sorted(os.listdir(tmp_path)) == ["c.exr"]
