"""blender_addon/bake.py (docs/contracts.md §4) in subprocesses: plain python, and the Blender-style ``-- args`` form
with bpy imported; real images, the real shipped model, real EXR files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from exporters import cycles, maps
from tests.addon_scene import write_image

ROOT = Path(__file__).resolve().parents[1]
BAKE = ROOT / "blender_addon" / "bake.py"
CARD = json.loads((ROOT / "blender_addon" / "models" / "skin_inversion.json").read_text())
K = CARD["K"]


def bake(*args: str, timeout: int = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(BAKE), *args], capture_output=True, text=True, timeout=timeout,
                          cwd=str(ROOT))


@pytest.fixture(scope="module")
def skin_png(tmp_path_factory) -> Path:
    codes = np.empty((3, 5, 3), np.uint8)  # non-square; two colours, the second one repeated
    codes[...] = (224, 172, 150)
    codes[1, 1:4] = (150, 100, 80)
    return write_image(tmp_path_factory.mktemp("img") / "face.png", codes, "uint8")


def files_for(stem: str, targets: tuple[str, ...]) -> set[str]:
    names = {f"{stem}_maps.json"}
    kinds = {"cycles": ("color", "radius", "weight", "anisotropy"), "physical": ("alpha", "sigma_t", "g", "weight")}
    for t in targets:
        if t == "spectral":
            names.add(f"{stem}_biophysical.exr")
        else:
            names |= {f"{stem}_k{k}_{kind}.exr" for k in range(1, K + 1) for kind in kinds[t]}
    return names


def test_cycles_target_maps_and_record(skin_png, tmp_path):
    out = tmp_path / "maps"
    proc = bake("--albedo", str(skin_png), "--out", str(out), "--unit-scale", "0.1", "--threads", "1")
    assert proc.returncode == 0, proc.stderr
    assert {p.name for p in out.iterdir()} == files_for("face", ("cycles",))  # no temporaries left
    record = json.loads((out / "face_maps.json").read_text())
    assert record["K"] == K and record["input"]["colorspace"] == "srgb"
    assert record["model_sha256"] == {"skin_inversion.onnx": CARD["files"]["skin_inversion.onnx"]["sha256"]}
    assert record["unit_scale_m_per_blender_unit"] == 0.1
    assert set(record["files"]) == files_for("face", ("cycles",)) - {"face_maps.json"}
    assert record["stats"]["texels"] == 15 and record["stats"]["distinct_texels"] == 2
    assert "inference" in record["timings_s"]
    assert record["evaluation"]["mode"] == "table" and record["stats"]["texels_from_table"] == 15
    color, names, attrs = maps.read_exr(out / "face_k1_color.exr")
    assert color.shape == (3, 5, 3) and names == ("R", "G", "B")
    assert attrs["spectral_skin_sss:colorspace"] == "Non-Color"
    aniso = maps.read_exr(out / "face_k1_anisotropy.exr")[0]
    assert aniso.shape == (3, 5, 1) and np.all((aniso >= 0) & (aniso <= cycles.RECOMMENDED_G_MAX + 1e-6))
    total_w = sum(maps.read_exr(out / f"face_k{k}_weight.exr")[0] for k in range(1, K + 1))
    assert np.all(total_w > 0) and np.all(total_w <= K)
    for k in range(1, K + 1):
        c = maps.read_exr(out / f"face_k{k}_color.exr")[0]
        r = maps.read_exr(out / f"face_k{k}_radius.exr")[0]
        assert np.all((c >= 0) & (c <= 1)) and np.all(r > cycles.MIN_RADIUS)
        np.testing.assert_array_equal(c[1, 1], c[1, 3])  # same colour in, same maps out
        np.testing.assert_array_equal(c[0, 0], c[2, 4])
        w = maps.read_exr(out / f"face_k{k}_weight.exr")[0]  # the painted colour lives in the weights
        assert not np.array_equal(w[0, 0], w[1, 1])


@pytest.mark.parametrize("path, rtol, half_atol", [("table", 6e-4, 2.5e-4), ("exact", 1e-5, 1e-7)])
def test_all_targets_are_consistent(skin_png, tmp_path, path, rtol, half_atol):
    # fast-path maps keep 16 mantissa bits (relative 7.6e-6 each); its colour, weight and anisotropy maps are half
    # floats (rounding <= 2^-12 below 1), and so is its radius here (relative rounding <= 2^-11)
    out = tmp_path / "all"
    proc = bake("--albedo", str(skin_png), "--out", str(out), "--target", "cycles,physical,spectral",
                "--unit-scale", "0.01", *(["--exact"] if path == "exact" else []))
    assert proc.returncode == 0, proc.stderr
    assert {p.name for p in out.iterdir()} == files_for("face", ("cycles", "physical", "spectral"))
    bio, names, attrs = maps.read_exr(out / "face_biophysical.exr", channels=maps.BIOPHYSICAL_CHANNELS)
    assert names == maps.BIOPHYSICAL_CHANNELS and bio.shape == (3, 5, 6)
    assert "t_epi cm" in attrs["spectral_skin_sss:units"]
    lo, hi = zip(*CARD["architecture"]["param_ranges"].values(), strict=True)
    assert np.all(bio[..., :5] >= np.array(lo) - 1e-6) and np.all(bio[..., :5] <= np.array(hi) + 1e-6)
    for k in range(1, K + 1):
        alpha = maps.read_exr(out / f"face_k{k}_alpha.exr")[0].astype(np.float64)
        sigma_t = maps.read_exr(out / f"face_k{k}_sigma_t.exr")[0].astype(np.float64)
        g = maps.read_exr(out / f"face_k{k}_g.exr")[0].astype(np.float64)
        color = maps.read_exr(out / f"face_k{k}_color.exr")[0].astype(np.float64)
        radius = maps.read_exr(out / f"face_k{k}_radius.exr")[0].astype(np.float64)
        aniso = maps.read_exr(out / f"face_k{k}_anisotropy.exr")[0].astype(np.float64)
        np.testing.assert_allclose(g, np.repeat(aniso, 3, axis=2), atol=half_atol)
        # Cycles' own forward maps (exporters.cycles, kernel formulas) turn the node inputs back into the medium
        np.testing.assert_allclose(cycles.rw_albedo_forward(color, g), alpha, atol=2e-5 + 4 * half_atol)
        np.testing.assert_allclose(4 * np.pi / (sigma_t * 100 * 0.01 * (1 - g)), radius, rtol=rtol)
        assert np.all((alpha >= 0.2 - 1e-6) & (alpha < 1))


def test_no_overwrite_then_overwrite(skin_png, tmp_path):
    out = tmp_path / "again"
    assert bake("--albedo", str(skin_png), "--out", str(out)).returncode == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    proc = bake("--albedo", str(skin_png), "--out", str(out), "--unit-scale", "2")
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "exist" in proc.stderr and "--overwrite" in proc.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    proc = bake("--albedo", str(skin_png), "--out", str(out), "--unit-scale", "2", "--overwrite", "--quiet")
    assert proc.returncode == 0 and proc.stdout == ""
    assert {p.name for p in out.iterdir()} == set(before)
    r1 = maps.read_exr(out / "face_k1_radius.exr")[0]
    assert json.loads((out / "face_maps.json").read_text())["unit_scale_m_per_blender_unit"] == 2.0
    assert r1.tobytes() != before["face_k1_radius.exr"]


def test_blender_style_arguments_with_bpy_loaded(skin_png, tmp_path):
    out = tmp_path / "bl"
    script = ("import sys, runpy, bpy\n"
              f"sys.argv = ['blender', '-b', '--python', {str(BAKE)!r}, '--', '--albedo', {str(skin_png)!r}, "
              f"'--out', {str(out)!r}, '--target', 'spectral']\n"
              f"runpy.run_path({str(BAKE)!r}, run_name='__main__')\n")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert {p.name for p in out.iterdir()} == {"face_biophysical.exr", "face_maps.json"}


def test_usage_errors_exit_2(skin_png, tmp_path):
    proc = bake("--albedo", str(skin_png), "--out", str(tmp_path / "x"), "--target", "mitsuba")
    assert proc.returncode == 2 and "unknown target" in proc.stderr and proc.stderr.count("\n") == 1
    assert not (tmp_path / "x").exists()  # the folder it would have created is gone again
    proc = bake("--out", str(tmp_path))
    assert proc.returncode == 2 and "--albedo" in proc.stderr
    proc = bake("--albedo", str(skin_png), "--out", str(tmp_path / "y"), "--unit-scale", "-1")
    assert proc.returncode == 2 and "unit scale" in proc.stderr


def test_painted_colour_by_default_model_colour_on_request(skin_png, tmp_path):
    painted = tmp_path / "painted"
    assert bake("--albedo", str(skin_png), "--out", str(painted), "--threads", "1").returncode == 0
    record = json.loads((painted / "face_maps.json").read_text())
    assert record["colour"]["mode"] == "painted" and record["collapse"]["colour"] == "painted"
    own = tmp_path / "own"
    proc = bake("--albedo", str(skin_png), "--out", str(own), "--model-colour", "--threads", "1")
    assert proc.returncode == 0, proc.stderr
    assert json.loads((own / "face_maps.json").read_text())["colour"]["mode"] == "model"
    # the model's own colour is darker than the painted one (the shipped model's skins are ~1.5x too dark)
    w_p, w_o = (sum(maps.read_exr(d / f"face_k{k}_weight.exr")[0].astype(np.float64) for k in range(1, K + 1))
                for d in (painted, own))
    assert not np.allclose(w_p, w_o)
    # the flag it replaces says where the brightness went, and changes nothing
    proc = bake("--albedo", str(skin_png), "--out", str(tmp_path / "gone"), "--match-exposure")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert "painted albedo by default" in proc.stderr and "--model-colour" in proc.stderr
    assert not (tmp_path / "gone").exists()


def test_colours_no_medium_can_take_are_clamped_counted_and_reported(tmp_path):
    codes = np.empty((2, 4, 3), np.uint8)
    codes[...] = (224, 172, 150)
    codes[0, :3] = (0, 255, 0)  # saturated green: no skin's spectrum bends that far
    png = write_image(tmp_path / "green.png", codes, "uint8")
    out = tmp_path / "maps"
    # through the table a non-skin colour gets the painted colour on the nearest skin colour's media, said in a note
    proc = bake("--albedo", str(png), "--out", str(tmp_path / "table"), "--threads", "1")
    assert proc.returncode == 0, proc.stderr
    assert "bake.py: note: 3 of 8 texel(s) lie outside the fast-path table's skin colours" in proc.stdout
    # the network itself (--exact) is asked for the painted green: clamped, counted, reported
    proc = bake("--albedo", str(png), "--out", str(out), "--target", "cycles,spectral", "--threads", "1", "--exact")
    assert proc.returncode == 0, proc.stderr
    record = json.loads((out / "green_maps.json").read_text())
    assert record["stats"]["texels_colour_clamped_spectral"] == 3
    assert record["stats"]["texels_colour_unreachable_in_cycles"] == 0  # per channel, Cycles shows it
    warning = [n for n in record["notes"] if "painted colour" in n]
    assert len(warning) == 1 and warning[0].startswith("warning: 3 of 8 texel(s)")
    assert "bake.py: warning: 3 of 8 texel(s)" in proc.stderr


def test_runs_without_colour_science_or_scipy(skin_png, tmp_path):
    # Blender's Python has numpy and OpenImageIO but neither colour-science nor scipy: the bake must not need
    # them (sRGB decoding and the channel weights are stored / written out in exporters).
    out = tmp_path / "plain"
    script = ("import sys, runpy\n"
              "for name in ('colour', 'scipy'):\n"
              "    sys.modules[name] = None  # any import of them now fails\n"
              f"sys.argv = ['bake.py', '--albedo', {str(skin_png)!r}, '--out', {str(out)!r}]\n"
              f"runpy.run_path({str(BAKE)!r}, run_name='__main__')\n")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (out / "face_maps.json").is_file()


def test_udim_albedo_bakes_every_tile_to_maps_named_per_tile(tmp_path):
    # Two tiles of different colours, and a file that only looks like a tile (1000 is outside the UDIM range).
    tiles = tmp_path / "tiles"
    tiles.mkdir()
    light, dark = np.full((2, 3, 3), (224, 172, 150), np.uint8), np.full((2, 3, 3), (120, 80, 60), np.uint8)
    write_image(tiles / "skin.1001.png", light, "uint8")
    write_image(tiles / "skin.1002.png", dark, "uint8")
    write_image(tiles / "skin.1000.png", dark, "uint8")
    out = tmp_path / "maps"
    proc = bake("--albedo", str(tiles / "skin.<UDIM>.png"), "--out", str(out), "--threads", "1")
    assert proc.returncode == 0, proc.stderr
    assert {p.name for p in out.iterdir()} == files_for("skin.1001", ("cycles",)) | files_for("skin.1002",
                                                                                                 ("cycles",))
    assert "tile skin.1001.png" in proc.stdout and "tile skin.1002.png" in proc.stdout
    record = json.loads((out / "skin.1002_maps.json").read_text())
    assert record["input"]["image"].endswith("skin.1002.png")
    first = maps.read_exr(out / "skin.1001_k1_weight.exr")[0]
    second = maps.read_exr(out / "skin.1002_k1_weight.exr")[0]
    assert first.shape == second.shape == (2, 3, 3) and not np.allclose(first, second)
    alone = tmp_path / "alone"  # a tile baked on its own gives the same maps
    assert bake("--albedo", str(tiles / "skin.1002.png"), "--out", str(alone), "--prune-share", "0").returncode == 0
    np.testing.assert_array_equal(maps.read_exr(alone / "skin.1002_k1_weight.exr")[0], second)


def test_udim_albedo_errors_leave_the_folder_as_it_was(tmp_path):
    out = tmp_path / "maps"
    proc = bake("--albedo", str(tmp_path / "skin.<UDIM>.png"), "--out", str(out))
    assert proc.returncode == 2 and not out.exists()
    assert proc.stderr.strip().splitlines() == [
        f"bake.py: error: no UDIM tile of {tmp_path / 'skin.<UDIM>.png'} found (files named skin.1001.png, "
        "skin.1002.png ...)"]
    write_image(tmp_path / "skin.1001.png", np.full((2, 2, 3), (224, 172, 150), np.uint8), "uint8")
    (tmp_path / "skin.1002.png").write_bytes(b"not a png")  # the second tile fails after the first was baked
    proc = bake("--albedo", str(tmp_path / "skin.<UDIM>.png"), "--out", str(out))
    assert proc.returncode == 2 and "skin.1002.png" in proc.stderr and not out.exists()
    proc = bake("--albedo", str(tmp_path / "skin.<UDIM>.png"), "--out", str(out), "--prune-share", "0.01")
    assert proc.returncode == 2 and "leave it out for UDIM albedos" in proc.stderr and not out.exists()
