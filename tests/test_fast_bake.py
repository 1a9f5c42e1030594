"""The fast bake path (exporters.texel_table) with the real shipped model and table: the table belongs to the
model, real bakes through the table match real exact bakes (appearance ΔE76, biophysical maps), a table of
another model is refused, tables are built and cached for other options, negligible components are dropped,
only the targets asked for are computed, and only the texels the UVs cover are evaluated."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import onnx
import pytest

from exporters import bake, cycles, inference, maps, reflectance_tables, texel_records, texel_table
from exporters.colorimetry import delta_e76, linear_srgb_to_lab, srgb_decode
from exporters.constants import PARAM_NAMES, PARAM_RANGES
from tests.addon_scene import write_image
from training.bench.runtime import skin_texture
from training.paths import SHIPPED_TABLE

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "blender_addon" / "models"
MODEL = MODELS / "skin_inversion.onnx"
CARD = json.loads((MODELS / "skin_inversion.json").read_text())


@pytest.fixture(scope="module")
def skin_png(tmp_path_factory) -> Path:
    """48 x 48 8-bit skin texture (light to dark, noise: ~1,500 distinct colours)."""
    return write_image(tmp_path_factory.mktemp("skin") / "skin.png", skin_texture(48, seed=3), "uint8")


def bake_png(png: Path, out: Path, **options) -> bake.BakeResult:
    out.mkdir(exist_ok=True)
    return bake.bake(png, out, MODEL, bake.BakeOptions(threads=1, **options))


def appearance(folder: Path, stem: str, k: int) -> np.ndarray:
    """CIE Lab of the colour the Cycles maps render: sum_k w_k R_cycles(f(color_k, g_k), g_k) per texel, with
    Cycles' own colour -> albedo map (exporters.cycles) and its reflectance table (IOR 1.4)."""
    total = 0.0
    for i in range(1, k + 1):
        color = maps.read_exr(folder / f"{stem}_k{i}_color.exr")[0].astype(np.float64)
        weight = maps.read_exr(folder / f"{stem}_k{i}_weight.exr")[0].astype(np.float64)
        g = maps.read_exr(folder / f"{stem}_k{i}_anisotropy.exr")[0].astype(np.float64)
        alpha = cycles.rw_albedo_forward(np.clip(color, 0, 1), g)
        total = total + weight * reflectance_tables.reflectance("cycles", alpha, g, reflectance_tables.CYCLES_IOR)
    return linear_srgb_to_lab(total)


def test_shipped_table_was_made_from_the_shipped_model():
    table = texel_table.load(SHIPPED_TABLE)
    assert SHIPPED_TABLE == bake.default_table_path(MODEL) == MODELS / "skin_inversion_table.npz"
    assert table.model_sha256 == maps.sha256_file(MODEL) == CARD["files"]["skin_inversion.onnx"]["sha256"], \
        "rebuild the table: python -m training texel-table --overwrite"
    assert table.k == CARD["K"] and table.options == texel_table.CollapseOptions()
    # the command that built it (the shipped table predates the builder's move from `python -m exporters.texel_table`
    # to `python -m training texel-table`; tables built since record the latter, see the round-trip test)
    assert table.meta["command"].startswith(("python -m training texel-table --model ",
                                             "python -m exporters.texel_table --model "))
    assert sum(p.stat().st_size for p in MODELS.iterdir()) < 25e6  # the add-on's model folder stays small
    proc = subprocess.run([sys.executable, "-m", "training", "texel-table", "--check"], capture_output=True, text=True,
                          cwd=ROOT, timeout=60)
    assert proc.returncode == 0 and "matches" in proc.stdout


def test_table_bake_matches_exact_bake(skin_png, tmp_path):
    fast = bake_png(skin_png, tmp_path / "fast", targets=("cycles", "spectral"))
    exact = bake_png(skin_png, tmp_path / "exact", targets=("cycles", "spectral"), exact=True)
    assert fast.stats["texels_from_table"] == 48 * 48 and exact.stats["texels_evaluated_exactly"] == 48 * 48
    de = delta_e76(appearance(tmp_path / "fast", "skin", fast.k), appearance(tmp_path / "exact", "skin", exact.k))
    assert de.mean() <= 0.1 and de.max() <= 0.5, (de.mean(), de.max())
    # The biophysical map and the exposure, interpolated in the table, against the network evaluated exactly:
    # on average within 0.5 % of each parameter's range and 0.5 % in exposure, and at every texel well inside
    # what the encoder itself can tell (its mean error on its validation tones, the card's p_abs_err and
    # exposure_error).  The shipped model (f_blood on a log scale, a wider encoder) reaches here
    # max 4.5 % of the range in f_blood (0.011 against its own 0.041), 3.4 % in b_mel (0.034 against 0.30),
    # 3.2 % in exposure (against 0.014 mean); means 0.007-0.18 % and 0.20 %.  The appearance above is what
    # the table is built for.
    span = np.array([PARAM_RANGES[p][1] - PARAM_RANGES[p][0] for p in PARAM_NAMES])
    own = CARD["metrics"]["validation"]
    bf = maps.read_exr(tmp_path / "fast" / "skin_biophysical.exr", channels=maps.BIOPHYSICAL_CHANNELS)[0]
    be = maps.read_exr(tmp_path / "exact" / "skin_biophysical.exr", channels=maps.BIOPHYSICAL_CHANNELS)[0]
    diff = np.abs(bf[..., :5] - be[..., :5]).reshape(-1, 5)
    assert np.all(diff.mean(0) / span <= 0.005), diff.mean(0) / span
    assert np.all(diff.max(0) <= 0.5 * np.array([own["p_abs_err"][p] for p in PARAM_NAMES])), diff.max(0)
    rel = np.abs(bf[..., 5] / be[..., 5] - 1)
    assert rel.mean() <= 0.005 and rel.max() <= 3 * own["exposure_error"]["mean"], (rel.mean(), rel.max())
    record = json.loads((tmp_path / "fast" / "skin_maps.json").read_text())
    assert record["evaluation"]["mode"] == "table"
    assert record["evaluation"]["table"]["sha256"] == maps.sha256_file(SHIPPED_TABLE)
    assert json.loads((tmp_path / "exact" / "skin_maps.json").read_text())["evaluation"]["mode"] == "exact"


def test_colours_outside_the_table_keep_the_nearest_skin_colours_translucency_and_render_as_painted(tmp_path):
    """Blue, green and red texels (not skin) bake to the radii and anisotropy of their projection onto the table's
    box in skin space, as the live group looks them up: those of a bake of the projected colours themselves, which
    lie inside the table (nudged 1e-6 of a step into the box, which moves no map value measurably); their colour
    and weight maps render the painted colour (exporters.painted_gain), by the reflectance tables."""
    codes = np.array([[[224, 172, 150], [30, 60, 220]], [[0, 255, 0], [250, 20, 20]]], np.uint8)
    png = write_image(tmp_path / "odd.png", codes, "uint8")
    fast = bake_png(png, tmp_path / "fast")
    assert fast.stats["texels_outside_table"] == 3 and fast.stats["texels_from_table"] == 1
    assert fast.stats["texels_evaluated_exactly"] == 0
    table = texel_table.load(SHIPPED_TABLE)
    painted = srgb_decode(codes.reshape(-1, 3) / 255.0)
    coords = texel_table.skin_coords(painted)
    top = table.origin + table.step * (np.array(table.shape) - 1)
    projected, in_cube = texel_table.rgb_of_coords(np.clip(coords, table.origin + 1e-6 * table.step,
                                                           top - 1e-6 * table.step))
    assert in_cube.all() and table.locate(projected.astype(np.float32))[0].all()
    exr = write_image(tmp_path / "projected.exr", projected.reshape(2, 2, 3).astype(np.float32), "float")
    bake_png(exr, tmp_path / "projected")
    for kind in ("k1_radius", "k2_radius", "k3_radius", "k1_anisotropy"):
        a = maps.read_exr(tmp_path / "fast" / f"odd_{kind}.exr")[0]
        b = maps.read_exr(tmp_path / "projected" / f"projected_{kind}.exr")[0]
        np.testing.assert_allclose(a, b, rtol=1e-3, atol=1e-6, err_msg=kind)
    body = 0.0
    for k in range(1, table.k + 1):
        colour = maps.read_exr(tmp_path / "fast" / f"odd_k{k}_color.exr")[0].reshape(-1, 3).astype(np.float64)
        weight = maps.read_exr(tmp_path / "fast" / f"odd_k{k}_weight.exr")[0].reshape(-1, 3).astype(np.float64)
        alpha = cycles.rw_albedo_forward(np.clip(colour, 0.0, 1.0), 0.0)
        body = body + weight * reflectance_tables.reflectance("cycles", alpha, 0.0, table.options.ior)
    np.testing.assert_allclose(body, painted, rtol=5e-3, atol=5e-4)  # half-float maps: ~5e-4


def _pixel_type(path: Path) -> str:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    try:
        return str(inp.spec().format)
    finally:
        inp.close()


def test_fast_bake_stores_bounded_maps_as_half_and_float_maps_keeps_float32(skin_png, tmp_path):
    """Colour, weight and anisotropy maps (bounded to [-1, 1]) are half floats on the fast path, and so is the
    radius when every radius lies in half's normal range (relative rounding <= 4.9e-4; here at unit scale 1, but
    not in kilometre units, where skin's radii would be subnormal halves); --float-maps and exact bakes write
    float32 throughout."""
    fast = bake_png(skin_png, tmp_path / "fast")
    types = {f.name.split("_", 2)[-1]: _pixel_type(f) for f in fast.files if f.suffix == ".exr"}
    assert types == {"color.exr": "half", "weight.exr": "half", "anisotropy.exr": "half", "radius.exr": "half"}
    km = bake_png(skin_png, tmp_path / "km", unit_scale_m=1000.0)
    assert {f.name.split("_", 2)[-1]: _pixel_type(f) for f in km.files if f.suffix == ".exr"}["radius.exr"] == "float"
    radius = maps.read_exr(tmp_path / "fast" / "skin_k1_radius.exr")[0]
    np.testing.assert_allclose(maps.read_exr(tmp_path / "km" / "skin_k1_radius.exr")[0] * 1000.0, radius, rtol=5e-4)
    record = json.loads((tmp_path / "fast" / "skin_maps.json").read_text())
    assert record["evaluation"]["half_kinds"] == ["anisotropy", "color", "radius", "weight"]
    full = bake_png(skin_png, tmp_path / "full", half_maps=False)
    assert {_pixel_type(f) for f in full.files if f.suffix == ".exr"} == {"float"}
    exact = bake_png(skin_png, tmp_path / "exact", exact=True)
    assert {_pixel_type(f) for f in exact.files if f.suffix == ".exr"} == {"float"}
    for name in ("skin_k1_color.exr", "skin_k2_weight.exr"):
        a, b = maps.read_exr(tmp_path / "fast" / name)[0], maps.read_exr(tmp_path / "full" / name)[0]
        assert 0 < np.abs(a - b).max() <= 2.5e-4  # half's rounding error below 1: at most 2^-12 = 2.4e-4
    a, b = (maps.read_exr(tmp_path / d / "skin_k2_radius.exr")[0] for d in ("fast", "full"))
    assert 0 < np.abs(a / b - 1).max() <= 4.9e-4  # normal halves: relative rounding at most 2^-11
    stream = maps.MapStream(tmp_path / "h.exr", 2, 1, ("Y",), "1", pixel_type="half")
    with pytest.raises(ValueError, match="half-float range"):
        stream.write_rows(np.array([[1.0, 7e4]]))
    stream.discard()


def test_table_of_another_model_is_refused_with_a_warning(skin_png, tmp_path):
    other = onnx.load(str(MODEL))
    other.doc_string = "the same network saved again: another file, another SHA-256"
    copy = tmp_path / "copy.onnx"
    onnx.save(other, str(copy))
    out = tmp_path / "maps"
    proc = subprocess.run([sys.executable, str(ROOT / "blender_addon" / "bake.py"), "--albedo", str(skin_png), "--out",
                           str(out), "--model", str(copy), "--table", str(SHIPPED_TABLE), "--threads", "1"],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert "warning: fast-path table" in proc.stderr and "refused" in proc.stderr
    assert "python -m training texel-table" in proc.stderr  # says how to rebuild
    record = json.loads((out / "skin_maps.json").read_text())
    assert record["evaluation"]["mode"] == "exact" and record["stats"]["texels_evaluated_exactly"] == 48 * 48


def test_table_file_round_trip_and_bad_files(tmp_path):
    model = inference.load_model(MODEL, threads=1)
    table = texel_table.build(model, step=0.1)
    path = texel_table.save(table, tmp_path / "t.npz")
    with pytest.raises(FileExistsError):
        texel_table.save(table, path)
    back = texel_table.load(path)
    assert back.model_sha256 == model.sha256 and back.shape == table.shape and back.sha256 == maps.sha256_file(path)
    assert back.meta["command"] == "python -m training texel-table --model blender_addon/models/skin_inversion.onnx " \
                                   "--step 0.1"  # how to rebuild it
    span = np.asarray(back.meta["quantisation"]["hi"]) - np.asarray(back.meta["quantisation"]["lo"])
    ok = np.isfinite(table.values)
    assert np.array_equal(ok, np.isfinite(back.values))
    assert np.all(np.abs(back.values - table.values)[ok] <= (np.broadcast_to(span, table.values.shape)[ok] / 65534
                                                               + 1e-6))
    # nodes hold the exact evaluation of their colour (up to 16-bit storage)
    n = np.array(back.shape)
    i = np.argwhere(np.all(ok, axis=3))[len(np.argwhere(np.all(ok, axis=3))) // 2]
    rgb, inside = texel_table.rgb_of_coords((back.origin + back.step * i)[None])
    assert inside[0] and np.all(i < n)
    exact = texel_records.exact_records(model, rgb.astype(np.float32), ("cycles", "spectral"), back.options)
    node = back.values[tuple(i)]
    k1 = back.channel("color_k1_r")
    assert node[k1] == pytest.approx(exact["color"][0, 0, 0], abs=span[k1] / 65534 + 1e-6)
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a table")
    with pytest.raises(texel_table.TableError, match="not a texel table"):
        texel_table.load(junk)
    with pytest.raises(texel_table.TableError, match="no fast-path table"):
        texel_table.load(tmp_path / "missing.npz")


def test_other_options_build_and_cache_a_table(skin_png, tmp_path, monkeypatch):
    monkeypatch.setenv("SPECTRAL_SKIN_SSS_CACHE", str(tmp_path / "cache"))
    opts = {"model_colour": True, "cache_min_colours": 100, "cache_step": 0.1}
    first = bake_png(skin_png, tmp_path / "a", **opts)
    assert any("built a fast-path table" in n for n in first.notes)
    cached = list((tmp_path / "cache").glob("table_*.npz"))
    assert len(cached) == 1 and texel_table.load(cached[0]).options.colour == "model"
    before = inference.inference_counts()
    second = bake_png(skin_png, tmp_path / "b", **opts)  # another folder: a new bake, served by the cached table
    assert not any("built" in n for n in second.notes)
    inferred = inference.inference_counts()["texels"] - before["texels"]  # distinct colours (+ 1: the load probe)
    assert inferred <= second.stats["texels_evaluated_exactly"] + 1 < second.stats["distinct_texels"] / 10
    record = json.loads((tmp_path / "b" / "skin_maps.json").read_text())
    assert record["evaluation"]["table"]["path"] == str(cached[0])
    few = bake_png(skin_png, tmp_path / "c", model_colour=True, ior=1.3, cache_step=0.1)  # 1,500 colours: no build
    assert any("no fast-path table" in n for n in few.notes) and few.stats["texels_evaluated_exactly"] == 48 * 48


def test_negligible_components_are_dropped(tmp_path):
    png = write_image(tmp_path / "u.png", np.full((2, 3, 3), (224, 172, 150), np.uint8), "uint8")
    full = bake_png(png, tmp_path / "full")
    shares = json.loads((tmp_path / "full" / "u_maps.json").read_text())["components"]["max_share"]
    assert full.k == CARD["K"] and min(shares) < 0.5  # no component of the shipped model is negligible
    threshold = float(np.sort(shares)[0] + 1e-3)  # just above the smallest component's share
    pruned = bake_png(png, tmp_path / "pruned", prune_share=threshold)
    drop = int(np.argmin(shares)) + 1
    assert pruned.k == CARD["K"] - 1 and pruned.components == [k for k in range(1, CARD["K"] + 1) if k != drop]
    names = {p.name for p in (tmp_path / "pruned").iterdir()}
    assert f"u_k{CARD['K']}_color.exr" not in names and "u_k1_color.exr" in names
    record = json.loads((tmp_path / "pruned" / "u_maps.json").read_text())
    assert record["K"] == CARD["K"] - 1 and record["components"]["dropped"] == [drop]
    for new, old in enumerate(pruned.components, start=1):  # renumbered maps hold the kept components' values
        a = maps.read_exr(tmp_path / "pruned" / f"u_k{new}_color.exr")[0]
        np.testing.assert_array_equal(a, maps.read_exr(tmp_path / "full" / f"u_k{old}_color.exr")[0])


def test_only_the_targets_asked_for(skin_png, tmp_path):
    spectral = bake_png(skin_png, tmp_path / "s", targets=("spectral",), exact=True)
    assert {p.name for p in (tmp_path / "s").iterdir()} == {"skin_biophysical.exr", "skin_maps.json"}
    assert "alpha_raised_to_floor" not in spectral.stats  # the collapse never ran
    cyc = bake_png(skin_png, tmp_path / "c", targets=("cycles",), exact=True)
    assert "alpha_raised_to_floor" in cyc.stats and not any("alpha" in p.name for p in (tmp_path / "c").iterdir())


def test_uv_mask_evaluates_only_covered_texels(tmp_path):
    codes = np.full((4, 6, 3), (224, 172, 150), np.uint8)
    codes[:, 3:] = (30, 60, 220)  # the right half (not skin: would need exact evaluation) is not covered
    codes[0, 0] = (150, 100, 80)
    png = write_image(tmp_path / "half.png", codes, "uint8")
    mask = np.zeros((4, 6), bool)
    mask[:, :3] = True
    result = bake_png(png, tmp_path / "m", texel_mask=mask)
    assert result.stats["texels_not_covered_by_uvs"] == 12 and result.stats["distinct_texels"] == 2
    assert result.stats["texels_outside_table"] == 0  # the blue half was never evaluated
    color = maps.read_exr(tmp_path / "m" / "half_k1_color.exr")[0]
    np.testing.assert_array_equal(color[:, 3:], np.broadcast_to(color[1, 1], (4, 3, 3)))  # most common covered
    with pytest.raises(bake.BakeError, match="shape"):
        bake_png(png, tmp_path / "bad", texel_mask=np.ones((3, 3), bool))
    with pytest.raises(bake.BakeError, match="cover no texel"):
        bake_png(png, tmp_path / "none", texel_mask=np.zeros((4, 6), bool))
