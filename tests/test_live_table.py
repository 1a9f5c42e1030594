"""exporters.live_table: the slice atlases hold the table's nodes where the layout says, the filled grid keeps every
valid node and extends it with bounded values, the reference lookup is the fast bake's interpolation inside the
table's domain, and the images fit the per-scene budget."""

from __future__ import annotations

import numpy as np
import pytest

from exporters import live_table, texel_table
from exporters.bake.table_cache import default_table_path
from training.paths import SHIPPED_MODEL


@pytest.fixture(scope="module")
def table() -> texel_table.TexelTable:
    return texel_table.load(default_table_path(SHIPPED_MODEL))


def test_atlas_pixels_hold_the_grid_nodes_with_repeated_borders(table):
    layout, atlases = live_table.atlases(table)
    grids = live_table.grid_values(table)
    tile_w, tile_h = layout.tile
    n0, n1, n2 = layout.shape
    rng = np.random.default_rng(1)
    for name in ("k1 Color", "k3 Log Radius", "k2 Weight"):
        atlas, grid = atlases[name], grids[name]
        assert atlas.shape == (layout.size[1], layout.size[0], 4) and atlas.dtype == np.float32
        for s, i1, i2 in zip(rng.integers(0, n0, 50), rng.integers(0, n1, 50), rng.integers(0, n2, 50), strict=True):
            col, row = s % layout.columns, s // layout.columns
            np.testing.assert_allclose(atlas[row * tile_h + 1 + i2, col * tile_w + 1 + i1], grid[s, i1, i2], rtol=1e-6)
        s = n0 - 1  # the border repeats the tile's edge
        col, row = s % layout.columns, s // layout.columns
        np.testing.assert_allclose(atlas[row * tile_h, col * tile_w + 1:col * tile_w + 1 + n1],
                                   grid[s, :, 0].astype(np.float32))


def test_fill_keeps_valid_nodes_and_bounds_the_rest(table):
    used = [texel_table.channel_names(table.k).index(n) for n in ("color_k1_r", "log_radius_m_k2_g", "weight_k3_b")]
    raw = table.values[..., used]
    filled = live_table.fill_outside_cube(raw)
    valid = np.all(np.isfinite(raw), axis=3)
    assert 0 < valid.sum() < valid.size and np.all(np.isfinite(filled))
    np.testing.assert_array_equal(filled[valid], raw[valid])
    lo, hi = np.nanmin(raw, axis=(0, 1, 2)), np.nanmax(raw, axis=(0, 1, 2))
    assert np.all(filled >= lo) and np.all(filled <= hi)  # means of neighbours never leave the valid range


def test_reference_lookup_is_the_fast_bake_inside_the_domain(table):
    rng = np.random.default_rng(0)
    rgb = rng.uniform(0.0, 1.0, (4000, 3)) ** 2 * np.array([1.0, 0.7, 0.55])
    inside, base, frac = table.locate(rgb)
    assert inside.sum() > 300
    values = table.interpolate(base, frac)
    names = texel_table.channel_names(table.k)
    grids, layout = live_table.grid_values(table), live_table.layout_of(table)
    for image, prefix in (("k2 Log Radius", "log_radius_m_k2"), ("k1 Weight", "weight_k1")):
        ref = live_table.lookup(grids[image], layout, rgb[inside])[:, :3]
        cols = [names.index(f"{prefix}_{c}") for c in "rgb"]
        np.testing.assert_allclose(ref, values[:, cols], atol=2e-5)


def test_outside_fraction_and_budget(table):
    skin, blue = np.array([[0.4, 0.2, 0.12]]), np.array([[0.05, 0.1, 0.9]])
    assert live_table.outside_fraction(table, np.concatenate([skin, skin, skin, blue])) == pytest.approx(0.25)
    assert live_table.outside_fraction(table, np.array([[np.nan, 0.2, 0.1]] + [[0.4, 0.2, 0.12]])) == 0.5
    assert live_table.outside_fraction(table, np.zeros((0, 3))) == 0.0
    layout = live_table.layout_of(table)
    assert live_table.atlas_bytes(layout, 3 * table.k) <= 16 * 2 ** 20


def test_atlas_ranges_are_those_of_the_filled_grids(table):
    """The ranges the live group's curves and constants use, found from the table's valid nodes, hold every value
    of the filled grids the atlases are made of."""
    ranges = live_table.atlas_ranges(table)
    grids = live_table.grid_values(table)
    log_r = np.stack([grids[f"k{k} Log Radius"][..., :3] for k in range(1, table.k + 1)])
    assert ranges.log_radius == pytest.approx((log_r.min(), log_r.max()), abs=1e-12)
    rho = np.stack([grids[f"k{k} Color"][..., :3] for k in range(1, table.k + 1)])
    assert ranges.rho_max == pytest.approx(rho.max(), abs=1e-12)
