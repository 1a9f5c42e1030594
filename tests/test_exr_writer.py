"""exporters.exr, the uncompressed EXR writer used where OpenImageIO's module is missing (Blender 4.2): its files
read back exactly with OpenImageIO, the independent reader."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from exporters import maps
from exporters.exr import ExrScanlineWriter


def read(path) -> tuple[np.ndarray, tuple[str, ...], str, str]:
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    data = inp.read_image(0, 0, 0, spec.nchannels, "float")
    inp.close()
    units = spec.getattribute("spectral_skin_sss:units")
    return data, tuple(spec.channelnames), spec.getattribute("compression"), units


@pytest.mark.parametrize("pixel_type", ["float", "half"])
def test_rows_written_in_bands_read_back_exactly(tmp_path, pixel_type):
    rng = np.random.default_rng(7)
    data = (rng.random((5, 7, 3)) * 40.0 - 20.0).astype(np.float32)
    path = tmp_path / "m.exr"
    out = ExrScanlineWriter(path, 7, 5, ("R", "G", "B"), pixel_type, {"spectral_skin_sss:units": "cm^-1"})
    assert out.write_scanlines(0, 2, 0, data[:2]) and out.write_scanlines(2, 5, 0, data[2:])
    out.close()
    back, channels, compression, units = read(path)
    expected = data.astype(np.float16).astype(np.float32) if pixel_type == "half" else data
    assert channels == ("R", "G", "B") and compression == "none" and units == "cm^-1"
    np.testing.assert_array_equal(back, expected)


def test_channels_in_any_order_and_one_channel(tmp_path):
    data = np.arange(3 * 4 * 6, dtype=np.float32).reshape(3, 4, 6) / 7.0
    out = ExrScanlineWriter(tmp_path / "b.exr", 4, 3, maps.BIOPHYSICAL_CHANNELS)  # stored sorted by name
    assert out.write_scanlines(0, 3, 0, data)
    out.close()
    back, channels, _ = maps.read_exr(tmp_path / "b.exr", channels=maps.BIOPHYSICAL_CHANNELS)
    assert channels == maps.BIOPHYSICAL_CHANNELS
    np.testing.assert_array_equal(back, data)
    one = np.linspace(0.0, 0.9, 6, dtype=np.float32).reshape(2, 3)
    out = ExrScanlineWriter(tmp_path / "y.exr", 3, 2, ("Y",))
    assert out.write_scanlines(0, 2, 0, one)
    out.close()
    np.testing.assert_array_equal(read(tmp_path / "y.exr")[0][..., 0], one)


def test_rows_of_the_wrong_shape_are_refused(tmp_path):
    out = ExrScanlineWriter(tmp_path / "w.exr", 4, 2, ("R", "G", "B"))
    assert not out.write_scanlines(0, 1, 0, np.zeros((1, 3, 3), np.float32))
    assert "rows of shape (1, 3, 3)" in out.geterror()
    out.close()
    with pytest.raises(ValueError, match="pixel type"):
        ExrScanlineWriter(tmp_path / "x.exr", 1, 1, ("R",), "double")
