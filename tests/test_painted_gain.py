"""exporters.painted_gain: every colour's media render the painted colour, by the reflectance tables.

The fit is checked against what it approximates (Cycles' walk reflectance from the adding-doubling tables of
exporters.reflectance_tables and Cycles' albedo map exporters.cycles.rw_albedo_forward); the media the live group
and a table bake give a colour (exporters.live_table.group_media, exporters.bake.evaluate) are checked to render,
by those tables and not by the fit, the painted colour for non-skin colours, negative and above 1, with skin
colours' media unchanged within 1 % and radii those of the skin colour the colour was projected onto.  Renders in
real Cycles: tests/test_live_colours.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from exporters import cycles, live_table, painted_gain, reflectance_tables, texel_table
from exporters.bake.evaluate import Evaluator
from exporters.bake.table_cache import default_table_path
from exporters.colorimetry import srgb_decode
from exporters.inference import ModelFile
from exporters.texel_records import CollapseOptions
from training.paths import SHIPPED_MODEL

#: Non-skin colours (8-bit sRGB): lipstick reds, coral, tattoo inks (blue-black, green), blue / teal / purple
#: eyeshadow, bruises (purple, yellow-green), yellow and orange paint, greys, near-white, near-black.
NON_SKIN = np.array([(190, 30, 45), (150, 20, 35), (230, 110, 120), (30, 40, 60), (20, 90, 60), (60, 110, 190),
                     (40, 140, 130), (120, 60, 150), (90, 60, 100), (170, 160, 80), (240, 200, 30), (240, 120, 20),
                     (128, 128, 128), (50, 50, 50), (245, 245, 245), (10, 10, 10)], np.uint8)


@pytest.fixture(scope="module")
def table() -> texel_table.TexelTable:
    return texel_table.load(default_table_path(SHIPPED_MODEL))


def _rendered(media: dict[str, np.ndarray], k: int, ior: float) -> np.ndarray:
    """(N, 3) body reflectance sum_k w_k H(alpha(A_k)) of media, by the reflectance tables (no fit)."""
    total = 0.0
    for i in range(1, k + 1):
        alpha = cycles.rw_albedo_forward(np.clip(media[f"k{i} Color"], 0.0, 1.0), 0.0)
        total = total + media[f"k{i} Weight"] * reflectance_tables.reflectance("cycles", alpha, 0.0, ior)
    return total


def test_fit_inverts_the_walk_reflectance():
    fit = painted_gain.body_fit(1.4)
    colour = np.linspace(painted_gain.FIT_COLOUR_MIN, fit.top, 777)
    rho = reflectance_tables.reflectance("cycles", cycles.rw_albedo_forward(colour, 0.0), 0.0, 1.4)
    np.testing.assert_allclose(painted_gain.body_reflectance(colour, 1.4), rho, rtol=1e-12)
    np.testing.assert_allclose(painted_gain.body_colour(rho, fit), colour, atol=6e-4)
    assert fit.reach == pytest.approx(rho[-1]) and 0.99 < fit.reach < 1.0


def test_non_skin_colours_get_media_of_the_painted_colour(table):
    painted = srgb_decode(NON_SKIN / 255.0)
    extra = np.array([[-0.3, 0.25, 0.1], [1.6, 0.7, 0.2], [0.02, 0.04, 0.7], [0.0, 1.0, 0.0], [3.0, 3.0, 3.0],
                      [np.nan, 0.2, 0.1]])
    rgb = np.concatenate([painted, extra])
    target = np.clip(np.nan_to_num(rgb, nan=0.0), 0.0, 1.0)
    media = live_table.group_media(table, rgb)
    body = _rendered(media, table.k, table.options.ior)
    assert np.all(np.isfinite(body))
    reachable = target.max(axis=1) < 0.99  # white takes every component's largest albedo: 0.997 of it
    np.testing.assert_allclose(body[reachable], target[reachable], rtol=4e-3, atol=2e-4)
    np.testing.assert_allclose(body[~reachable], target[~reachable], rtol=1.5e-2, atol=2e-4)
    for k in range(1, table.k + 1):
        assert np.all(media[f"k{k} Weight"] <= 1.0) and np.all(media[f"k{k} Weight"] >= 0.0)
        assert np.all(media[f"k{k} Color"] <= painted_gain.body_fit(1.4).top + 1e-3)
        assert np.all(media[f"k{k} Color"] >= painted_gain.FIT_COLOUR_MIN - 1e-3)
    # the translucency is the projected skin colour's: radii as the table's lookup at that colour
    grids, layout = live_table.grid_values(table), live_table.layout_of(table)
    for k in range(1, table.k + 1):
        radius = np.exp(live_table.lookup(grids[f"k{k} Log Radius"], layout, rgb)[:, :3])
        np.testing.assert_array_equal(media[f"k{k} Radius"], radius)


def test_skin_colours_keep_their_media(table):
    rng = np.random.default_rng(3)
    rgb = rng.uniform(0.0, 1.0, (3000, 3)) ** 2 * np.array([1.0, 0.7, 0.55])
    inside, base, frac = table.locate(rgb)
    rgb = rgb[inside & (rgb.min(axis=1) > 0.01)]
    assert len(rgb) > 300
    media = live_table.group_media(table, rgb)
    values = table.interpolate(*table.locate(rgb)[1:])  # the table's own colours and weights there
    names = texel_table.channel_names(table.k)
    for k in range(1, table.k + 1):
        for kind, prefix in (("Color", "color"), ("Weight", "weight")):
            before = values[:, [names.index(f"{prefix}_k{k}_{c}") for c in "rgb"]]
            np.testing.assert_allclose(media[f"k{k} {kind}"], before, rtol=1e-2, atol=1e-4)


def test_a_path_out_of_the_box_changes_media_continuously(table):
    t = np.linspace(0.0, 1.0, 801)[:, None]
    rgb = (1.0 - t) * np.array([0.40, 0.20, 0.12]) + t * np.array([0.02, 0.15, 0.6])  # skin to eyeshadow blue
    outside = ~table.locate(rgb)[0]
    assert outside[-1] and not outside[0]
    media = live_table.group_media(table, rgb)
    for name, value in media.items():
        steps = np.abs(np.diff(value, axis=0)).reshape(len(t) - 1, -1).max(axis=1)
        neighbours = np.maximum(steps[:-2], steps[2:])
        assert np.all(steps[1:-1] <= 2.0 * neighbours + 1e-5), name  # no step stands out: no jump at the edge


def test_a_table_bake_gives_the_live_groups_media(table):
    rgb = np.concatenate([srgb_decode(NON_SKIN / 255.0), [[0.4, 0.2, 0.12], [0.05, 0.02, 0.01], [1.4, -0.1, 0.3]]])
    timings = {"table": 0.0, "evaluate": 0.0, "inference": 0.0, "load_model": 0.0}
    evaluator = Evaluator(rgb, ("cycles",), ModelFile(SHIPPED_MODEL), table, CollapseOptions(), 1, timings)
    rec, _ = evaluator.records(rgb.astype(np.float32))
    media = live_table.group_media(table, rgb.astype(np.float32))
    for k in range(1, table.k + 1):
        # the bake takes rho of the interpolated colour, the group interpolates rho: within 1e-3
        np.testing.assert_allclose(rec["color"][:, k - 1], media[f"k{k} Color"], rtol=1e-3, atol=1e-5)
        np.testing.assert_allclose(rec["weight"][:, k - 1], media[f"k{k} Weight"], rtol=1e-3, atol=1e-5)
        np.testing.assert_allclose(rec["radius_m"][:, k - 1], media[f"k{k} Radius"], rtol=2e-5)
