"""exporters.palette (distinct colours of an image) and image_input.read_albedo_indexed against numpy's own np.unique
and the dense reader, on real image files of every supported kind."""

from __future__ import annotations

import numpy as np
import pytest

from exporters import image_input, palette
from tests.addon_scene import write_image


def check_exact(rows: np.ndarray, found: np.ndarray, inverse: np.ndarray) -> None:
    assert inverse.shape == (len(rows),) and inverse.dtype == np.int32
    np.testing.assert_array_equal(found[inverse], rows)  # bit for bit
    assert len(found) == len(np.unique(rows, axis=0))  # as many as numpy finds


@pytest.mark.parametrize("dtype, channels", [(np.uint8, 3), (np.uint8, 1), (np.uint8, 4), (np.uint16, 3),
                                             (np.uint16, 1)])
def test_unique_codes(dtype, channels):
    rng = np.random.default_rng(0)
    top = np.iinfo(dtype).max
    rows = rng.integers(0, 6, (5000, channels)).astype(dtype) * (top // 5)  # many repeats, extremes 0 and max
    found, inverse = palette.unique_codes(rows)
    check_exact(rows, found, inverse)
    assert found.dtype == dtype
    empty, inv = palette.unique_codes(np.zeros((0, channels), dtype))
    assert empty.shape == (0, channels) and inv.shape == (0,)
    with pytest.raises(ValueError, match="uint8 or uint16"):
        palette.unique_codes(rows.astype(np.int32))


def test_unique_float_rows_exact():
    rng = np.random.default_rng(1)
    base = rng.random((300, 3), dtype=np.float32)
    rows = base[rng.integers(0, 300, 4000)]
    rows[::7] = np.nextafter(rows[::7], np.float32(2))  # neighbours one ulp apart stay distinct
    rows[5] = [0.0, 0.0, 0.0]
    rows[6] = [-0.0, 0.0, 0.0]  # -0.0 and +0.0 are one colour
    found, inverse = palette.unique_float_rows(rows)
    check_exact(rows + np.float32(0), found, inverse)
    many = rng.random((50_000, 3), dtype=np.float32)  # mostly distinct: the argsort branch
    check_exact(many, *palette.unique_float_rows(many))
    check_exact(many, *palette._exact_float_unique(many))  # the collision fallback gives the same grouping
    found, inverse = palette.unique_float_rows(np.zeros((0, 3), np.float32))
    assert found.shape == (0, 3) and inverse.shape == (0,)


CODES = np.array([[[224, 172, 150], [150, 100, 80], [224, 172, 150]],
                  [[90, 60, 45], [224, 172, 150], [0, 0, 0]]], np.uint8)


@pytest.mark.parametrize("kind", ["png8", "png16", "exr", "gray", "rgba", "gray_alpha"])
def test_indexed_reader_matches_the_dense_reader(tmp_path, kind):
    if kind == "png8":
        path = write_image(tmp_path / "a.png", CODES, "uint8")
    elif kind == "png16":
        path = write_image(tmp_path / "a.png", CODES.astype(np.uint16) * 257 + 3, "uint16")
    elif kind == "exr":
        path = write_image(tmp_path / "a.exr", (CODES / 255.0).astype(np.float32) ** 2.2, "float")
    elif kind == "gray":
        path = write_image(tmp_path / "a.png", CODES[..., 1], "uint8")
    elif kind == "rgba":
        path = write_image(tmp_path / "a.png", np.concatenate([CODES, CODES[..., :1]], axis=2), "uint8")
    else:
        path = write_image(tmp_path / "a.png", np.stack([CODES[..., 0], CODES[..., 2]], axis=2), "uint8")
    dense = image_input.read_albedo(path)
    indexed = image_input.read_albedo_indexed(path)
    np.testing.assert_array_equal(indexed.rgb, dense.rgb)
    assert indexed.colorspace == dense.colorspace and indexed.source_format == dense.source_format
    assert indexed.has_alpha == (dense.alpha is not None) and indexed.n_channels == dense.n_channels
    assert indexed.counts.sum() == CODES.shape[0] * CODES.shape[1]


def test_indexed_reader_rejects_what_the_dense_one_rejects(tmp_path):
    bad = np.full((2, 3, 3), 0.4, np.float32)
    bad[1, 2, 0] = np.nan
    with pytest.raises(image_input.ImageError, match=r"NaN/Inf, first at \(x=2, y=1\)"):
        image_input.read_albedo_indexed(write_image(tmp_path / "n.exr", bad, "float"))
    neg = np.full((2, 3, 3), 0.4, np.float32)
    neg[0, 1, 2] = -0.1
    path = write_image(tmp_path / "neg.exr", neg, "float")
    with pytest.raises(image_input.ImageError, match=r"negative values, first at \(x=1, y=0\)"):
        image_input.read_albedo_indexed(path)
    clamped = image_input.read_albedo_indexed(path, clamp_negative=True)
    assert clamped.n_clamped == 1 and clamped.palette.min() == 0.0
    with pytest.raises(FileNotFoundError):
        image_input.read_albedo_indexed(tmp_path / "none.png")
