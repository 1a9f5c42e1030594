"""Property-based stability tests (hypothesis) of texel inference and the fast path: the real ONNX model through
exporters.inference, the shipped table's lookup (skin coordinates, location, trilinear interpolation, records),
16-bit mantissa rounding, distinct-colour indexing and the UV raster, with extreme and degenerate inputs.

Documented behaviour: finite texels give finite values in the documented ranges (also far outside [0, 1]:
the model and the table clamp to [0, 1]); NaN/Inf texels raise ValueError; empty inputs give empty outputs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from matplotlib.path import Path as MplPath

from exporters import inference, maps, palette, texel_records, texel_table, uv_coverage
from exporters.constants import PARAM_NAMES, PARAM_RANGES

pytestmark = pytest.mark.stability
SETTINGS = settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
MODEL = Path(__file__).resolve().parents[1] / "blender_addon" / "models" / "skin_inversion.onnx"
TINY, HUGE = 5e-324, 1e300
TINY32 = float(np.finfo(np.float32).smallest_subnormal)  # 1.4e-45
EDGES = [0.0, TINY, 1e-308, 1e-7, 0.5, 1.0, 1.0 + 1e-12, 2.0, 1e6, HUGE, -TINY, -1.0, -HUGE]


def texel_values() -> st.SearchStrategy:
    return st.one_of(st.sampled_from(EDGES), st.floats(0.0, 1.0), st.floats(-1e308, 1e308))


def rows(min_rows: int = 0, max_rows: int = 12, values=None) -> st.SearchStrategy:
    return hnp.arrays(np.float64, st.tuples(st.integers(min_rows, max_rows), st.just(3)),
                      elements=values if values is not None else texel_values())


@pytest.fixture(scope="module")
def model():
    return inference.load_model(MODEL, threads=1)


@pytest.fixture(scope="module")
def table():
    return texel_table.load(MODEL.with_name("skin_inversion_table.npz"))


LO = np.array([PARAM_RANGES[p][0] for p in PARAM_NAMES])
HI = np.array([PARAM_RANGES[p][1] for p in PARAM_NAMES])


@SETTINGS
@given(rows())
def test_inference_finite_and_in_range(model, rgb):
    if np.any(np.abs(rgb) > np.finfo(np.float32).max):  # not representable as the model's float32 input
        with pytest.raises(ValueError, match="float32 range"):
            model.run(rgb)
        return
    out = model.run(rgb)
    n = len(rgb)
    assert out["alpha"].shape == (n, model.k, 376) and out["biophysical"].shape == (n, 5)
    for name, value in out.items():
        assert np.all(np.isfinite(value)), name
    assert np.all(out["biophysical"] >= LO - 1e-6) and np.all(out["biophysical"] <= HI + 1e-6)
    assert np.all((out["alpha"] >= 0) & (out["alpha"] <= 1)) and np.all(out["sigma_t"] > 0)
    np.testing.assert_allclose(out["weight"].sum(axis=1), 1.0, atol=1e-5)
    assert np.all(out["exposure"] >= 0)
    clamped = model.run(np.clip(rgb, 0.0, 1.0))  # documented: inputs are clamped to [0, 1]
    np.testing.assert_allclose(out["reflectance"], clamped["reflectance"], rtol=1e-6, atol=1e-7)


@SETTINGS
@given(rows(1), st.sampled_from([np.nan, np.inf, -np.inf]), st.integers(0, 100))
def test_inference_refuses_nan_and_inf(model, rgb, bad, i):
    rgb = rgb.copy()
    rgb.flat[i % rgb.size] = bad
    with pytest.raises(ValueError, match="NaN/Inf"):
        model.run(rgb)
    with pytest.raises(ValueError):
        texel_table.skin_coords(rgb)


@SETTINGS
@given(rows())
def test_table_lookup_finite_and_convex(table, rgb):
    inside, base, frac = table.locate(rgb)
    assert inside.shape == (len(rgb),) and base.shape == (inside.sum(),) and frac.shape == (inside.sum(), 3)
    assert np.all((frac >= 0) & (frac <= 1))
    values = table.interpolate(base, frac)
    assert values.shape == (inside.sum(), len(texel_table.channel_names(table.k))) and np.all(np.isfinite(values))
    lo, hi = np.nanmin(table.values, axis=(0, 1, 2)), np.nanmax(table.values, axis=(0, 1, 2))
    assert np.all(values >= lo - 1e-5 * (1 + np.abs(lo))) and np.all(values <= hi + 1e-5 * (1 + np.abs(hi)))
    rec = table.records(rgb[inside], values, ("cycles", "physical", "spectral"))
    for name, value in rec.items():
        assert np.all(np.isfinite(value)), name
    assert np.all(rec["biophysical"] >= LO) and np.all(rec["biophysical"] <= HI)
    assert np.all((rec["alpha"] >= 0) & (rec["alpha"] < 1)) and np.all(rec["sigma_t_cm"] > 0)
    assert np.all(rec["exposure"] >= 0)
    for kind in ("color", "radius", "weight", "anisotropy", "alpha", "sigma_t", "g", "biophysical"):
        v = texel_records.map_values(kind, 1, rec, 0.01)
        assert v.dtype == np.float32 and len(v) == inside.sum() and np.all(np.isfinite(v))


@SETTINGS
@given(st.integers(0, 10**6))
def test_table_reproduces_its_nodes(table, seed):
    rng = np.random.default_rng(seed)
    ok = np.argwhere(np.all(np.isfinite(table.values), axis=3))
    idx = ok[rng.integers(0, len(ok), 8)]
    rgb, in_cube = texel_table.rgb_of_coords(table.origin + table.step * idx)
    assert np.all(in_cube)
    np.testing.assert_allclose(texel_table.skin_coords(rgb), table.origin + table.step * idx, atol=1e-9)
    inside, base, frac = table.locate(rgb)
    values = table.interpolate(base, frac)
    expected = table.values[tuple(idx[inside].T)]
    np.testing.assert_allclose(values, expected, rtol=1e-5, atol=1e-5 * np.nanmax(np.abs(table.values)))


@SETTINGS
@given(hnp.arrays(np.float32, st.integers(0, 20), elements=st.one_of(
    st.sampled_from([0.0, -0.0, TINY32, -TINY32, float(np.float32(1e-38)), 1.0, -1.0, float(np.finfo(np.float32).max),
                     -float(np.finfo(np.float32).max)]),
    st.floats(width=32, allow_nan=False, allow_infinity=False))), st.integers(1, 23))
def test_mantissa_rounding(x, bits):
    r = maps.round_mantissa(x, bits)
    assert r.dtype == np.float32 and r.shape == x.shape and np.all(np.isfinite(r))
    assert np.all(np.signbit(r) == np.signbit(x)) | np.all(x == 0)
    normal = np.abs(x) >= np.finfo(np.float32).tiny
    rel = np.abs(r[normal].astype(np.float64) / x[normal] - 1.0)
    assert np.all(rel <= 2.0 ** -(bits + 1) * (1 + 1e-6) + 2.0 ** -23)
    np.testing.assert_array_equal(maps.round_mantissa(r, bits), r)  # idempotent


def test_mantissa_rounding_refuses_nan():
    with pytest.raises(ValueError, match="finite"):
        maps.round_mantissa(np.array([1.0, np.nan], np.float32), 16)
    with pytest.raises(ValueError, match="1..23"):
        maps.round_mantissa(np.ones(2, np.float32), 0)


@SETTINGS
@given(hnp.arrays(np.float32, st.tuples(st.integers(0, 200), st.just(3)), elements=st.one_of(
    st.sampled_from([0.0, -0.0, TINY32, 1.0, 0.25]), st.floats(width=32, allow_nan=False, allow_infinity=False))))
def test_distinct_rows_are_exact(x):
    found, inverse = palette.unique_float_rows(x)
    np.testing.assert_array_equal(found[inverse], x + np.float32(0))
    assert len(found) == len(np.unique(x + np.float32(0), axis=0))
    codes = (np.abs(x) % 256).astype(np.uint8)
    found, inverse = palette.unique_codes(codes)
    np.testing.assert_array_equal(found[inverse], codes)


@SETTINGS
@given(hnp.arrays(np.float64, st.tuples(st.integers(0, 12), st.just(3), st.just(2)),
                  elements=st.one_of(st.sampled_from([0.0, 1.0, 0.5, TINY]), st.floats(-0.2, 1.2))),
       st.integers(1, 40), st.integers(1, 40))
def test_uv_raster_matches_point_in_polygon(tris, width, height):
    mask = uv_coverage.uv_coverage(tris, width, height, margin=0)
    ys, xs = np.mgrid[0:height, 0:width]
    centres = np.stack([((xs + 0.5) / width).ravel(), (1 - (ys + 0.5) / height).ravel()], axis=1)
    ref = np.zeros(height * width, bool)
    for t in tris:
        area = (t[1, 0] - t[0, 0]) * (t[2, 1] - t[0, 1]) - (t[2, 0] - t[0, 0]) * (t[1, 1] - t[0, 1])
        if abs(area) * width * height > 1e-12:  # degenerate triangles cover nothing (documented)
            ref |= MplPath(t).contains_points(centres, radius=1e-9) | MplPath(t[::-1]).contains_points(centres,
                                                                                                       radius=1e-9)
    # centres within 1e-9 of an edge may go either way; everything else must agree
    diff = mask.ravel() != ref
    assert diff.sum() <= sum(_near_edge(centres[diff], t) for t in tris).sum() if diff.any() else True


def _near_edge(points: np.ndarray, tri: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    near = np.zeros(len(points), bool)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        ab = tri[b] - tri[a]
        t = np.clip(((points - tri[a]) @ ab) / max(ab @ ab, 1e-300), 0, 1)
        near |= np.linalg.norm(points - (tri[a] + t[:, None] * ab), axis=1) < eps
    return near
