"""``--target openpbr`` (docs/contracts.md §4): the OpenPBR maps, the MaterialX document and the USD layer, written by
blender_addon/bake.py in subprocesses from real images and the shipped model, read back with OpenImageIO, MaterialX
(its own validator, the standard data libraries) and usd-core (its validators; stage opened from a moved folder)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import MaterialX as mx
import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdShade, UsdValidation

from exporters import cycles, maps, reflectance_tables
from exporters.colorimetry import srgb_decode
from tests.addon_scene import write_image

ROOT = Path(__file__).resolve().parents[1]
BAKE = ROOT / "blender_addon" / "bake.py"
KINDS = ("base_color", "subsurface_color", "subsurface_radius", "subsurface_radius_scale", "subsurface_anisotropy",
         "subsurface_weight", "coat_color")
LIGHT, DARK = (224, 172, 150), (120, 80, 60)


def bake(*args: str, timeout: int = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(BAKE), *args, "--threads", "1"], capture_output=True, text=True,
                          timeout=timeout, cwd=str(ROOT))


def openpbr_files(stem: str, material: str | None = None) -> set[str]:
    names = {f"{stem}_openpbr_{kind}.exr" for kind in KINDS}
    if material is not None:
        names |= {f"{material}_openpbr.mtlx", f"{material}_openpbr.usda"}
    return names


@pytest.fixture(scope="module")
def face(tmp_path_factory) -> tuple[Path, np.ndarray]:
    codes = np.empty((3, 4, 3), np.uint8)
    codes[...] = LIGHT
    codes[:, 2:] = DARK
    return write_image(tmp_path_factory.mktemp("img") / "face.png", codes, "uint8"), codes


@pytest.fixture(scope="module")
def baked(face, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bake") / "maps"
    proc = bake("--albedo", str(face[0]), "--out", str(out), "--target", "openpbr", "--unit-scale", "0.01")
    assert proc.returncode == 0, proc.stderr
    return out


def test_files_and_record(baked):
    assert {p.name for p in baked.iterdir()} == openpbr_files("face", "face") | {"face_maps.json"}
    record = json.loads((baked / "face_maps.json").read_text())
    assert set(record["files"]) == openpbr_files("face", "face")
    assert all(entry["target"] == "openpbr" for entry in record["files"].values())
    assert "scene units" in record["files"]["face_openpbr_subsurface_radius.exr"]["units"]
    assert record["openpbr"]["material_files"] == ["face_openpbr.mtlx", "face_openpbr.usda"]
    assert record["bake"]["files"].keys() == record["files"].keys()  # the material files count for an up-to-date bake


def test_map_values(face, baked, tmp_path):
    codes = face[1]
    painted = srgb_decode(codes / 255.0)
    read = {kind: maps.read_exr(baked / f"face_openpbr_{kind}.exr")[0] for kind in KINDS}
    assert read["base_color"].shape == (3, 4, 3) and read["subsurface_radius"].shape == (3, 4, 1)
    np.testing.assert_allclose(read["base_color"], painted, atol=3e-3)  # the colour the mixture renders: painted
    assert np.all(read["subsurface_weight"] == 1.0) and np.all(read["subsurface_anisotropy"] == 0.0)
    np.testing.assert_allclose(read["subsurface_radius_scale"].max(axis=2), 1.0, rtol=1e-6)
    mfp_mm = read["subsurface_radius"] * read["subsurface_radius_scale"] * 10.0  # 1 unit = 1 cm
    assert np.all((mfp_mm > 0.001) & (mfp_mm < 5.0))  # skin: micrometres to millimetres
    assert np.all(mfp_mm[..., 0] > mfp_mm[..., 2])  # red travels further than blue
    # Cycles' own map from a subsurface colour to the walk's albedo (exporters.cycles, the kernel's fit), seen
    # face-on through the tinted clear coat (coat_color, 1 - F0, the walk's measured gain under it), gives the
    # painted colour; the walk keeps the mixture's high albedo and the coat absorbs the rest.
    from exporters import openpbr

    alpha = cycles.rw_albedo_forward(read["subsurface_color"].astype(np.float64), 0.0)
    assert np.all(alpha > 0.9) and np.all((read["coat_color"] > 0.0) & (read["coat_color"] <= 1.0))
    face_on = (read["coat_color"] * openpbr.COAT_ENTRY_GAIN * (1.0 - cycles.fresnel_dielectric(1.0, 1.4))
               * reflectance_tables.normal_reflectance(alpha, 0.0))
    np.testing.assert_allclose(face_on, painted, rtol=5e-3, atol=1e-3)
    metres = tmp_path / "metres"  # the radius is in scene units: 1 unit = 1 m gives values 100 times smaller
    assert bake("--albedo", str(face[0]), "--out", str(metres), "--target", "openpbr").returncode == 0
    np.testing.assert_allclose(maps.read_exr(metres / "face_openpbr_subsurface_radius.exr")[0] * 100.0,
                               read["subsurface_radius"], rtol=1e-5)


def test_materialx_document_is_valid_and_reads_the_maps(baked):
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(baked / "face_openpbr.mtlx"))
    library = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), library)
    doc.importLibrary(library)
    ok, message = doc.validate()
    assert ok, message
    shader = next(n for n in doc.getNodes() if n.getCategory() == "open_pbr_surface")
    assert shader.getNodeDef().getName() == "ND_open_pbr_surface_surfaceshader"
    assert shader.getInputValue("specular_ior") == pytest.approx(1.4)
    assert shader.getInputValue("coat_weight") == 1.0 and shader.getInputValue("coat_ior") == pytest.approx(1.4)
    material = doc.getMaterialNodes()[0]
    assert material.getInput("surfaceshader").getConnectedNode() == shader
    read = {}
    for name in ("base_color", "subsurface_color", "subsurface_radius", "subsurface_radius_scale",
                 "subsurface_scatter_anisotropy", "subsurface_weight", "coat_color"):
        image = shader.getInput(name).getConnectedOutput().getConnectedNode()
        assert image.getCategory() == "image"
        read[name] = image.getInput("file").getValueString()
        assert (baked / read[name]).is_file() and not Path(read[name]).is_absolute()
    assert read["subsurface_color"] == "face_openpbr_subsurface_color.exr"


def _assets(stage: Usd.Stage) -> dict[str, Sdf.AssetPath]:
    out = {}
    for prim in stage.Traverse():
        shader = UsdShade.Shader(prim)
        if shader and shader.GetInput("file"):
            out[str(prim.GetPath())] = shader.GetInput("file").Get()
    return out


def test_usd_layer_opens_validates_and_moves(baked, tmp_path):
    moved = tmp_path / "elsewhere" / "skin"
    shutil.copytree(baked, moved)  # the folder moves: every path in the layer is relative to it
    stage = Usd.Stage.Open(str(moved / "face_openpbr.usda"))
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01) and UsdGeom.GetStageUpAxis(stage) == "Z"
    material = UsdShade.Material(stage.GetDefaultPrim().GetChild("Skin"))
    mtlx = material.ComputeSurfaceSource("mtlx")[0]
    preview = material.ComputeSurfaceSource()[0]
    assert mtlx.GetIdAttr().Get() == "ND_open_pbr_surface_surfaceshader"
    assert preview.GetIdAttr().Get() == "UsdPreviewSurface"
    assets = _assets(stage)
    assert len(assets) == 8  # seven OpenPBR maps and the preview's colour
    for prim, asset in assets.items():
        assert asset.path.startswith("./"), (prim, asset.path)
        assert Path(asset.resolvedPath).parent == moved and Path(asset.resolvedPath).is_file(), (prim, asset)
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    # usd-core's wheel has no MaterialX plugin (usdMtlx), so its shader registry lacks the ND_* ids (MaterialX's own
    # validator checks those, above); UsdPreviewSurface, UsdUVTexture and the primvar reader are checked here.
    other = [e.GetMessage() for e in errors
             if not (e.GetName() == "MissingShaderIdInRegistry" and "'ND_" in e.GetMessage())]
    assert not other, other


def test_udim_set_gets_one_material_reading_every_tile(tmp_path):
    tiles = tmp_path / "tiles"
    tiles.mkdir()
    write_image(tiles / "skin.1001.png", np.full((2, 3, 3), LIGHT, np.uint8), "uint8")
    write_image(tiles / "skin.1002.png", np.full((2, 3, 3), DARK, np.uint8), "uint8")
    out = tmp_path / "maps"
    proc = bake("--albedo", str(tiles / "skin.<UDIM>.png"), "--out", str(out), "--target", "openpbr")
    assert proc.returncode == 0, proc.stderr
    assert {p.name for p in out.iterdir()} == (openpbr_files("skin.1001") | openpbr_files("skin.1002", "skin")
                                               | {"skin.1001_maps.json", "skin.1002_maps.json"})
    assert "skin_openpbr.mtlx" in json.loads((out / "skin.1002_maps.json").read_text())["files"]
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(out / "skin_openpbr.mtlx"))
    files = {n.getInput("file").getValueString() for n in doc.getNodeGraphs()[0].getNodes()}
    assert files == {f"skin.<UDIM>_openpbr_{kind}.exr" for kind in KINDS}
    for tile in (1001, 1002):
        assert all((out / f.replace("<UDIM>", str(tile))).is_file() for f in files)
    stage = Usd.Stage.Open(str(out / "skin_openpbr.usda"))
    assert {a.path for a in _assets(stage).values()} == {f"./{f}" for f in files}


def test_bad_input_one_line_and_nothing_written(face, baked, tmp_path):
    out = tmp_path / "taken"
    out.mkdir()
    (out / "face_openpbr.usda").write_text("someone's layer\n")
    proc = bake("--albedo", str(face[0]), "--out", str(out), "--target", "openpbr")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "--overwrite" in proc.stderr, proc.stderr
    assert {p.name for p in out.iterdir()} == {"face_openpbr.usda"}
    assert (out / "face_openpbr.usda").read_text() == "someone's layer\n"
    proc = bake("--albedo", str(face[0]), "--out", str(tmp_path / "x"), "--target", "openpbr,usd")
    assert proc.returncode == 2 and "openpbr" in proc.stderr and proc.stderr.count("\n") == 1


def _without_libraries(*args: str) -> subprocess.CompletedProcess:
    """bake.py in a Python where MaterialX and pxr cannot be imported (Blender's own Python may lack them)."""
    script = ("import sys, runpy\n"
              "for name in ('MaterialX', 'pxr'):\n"
              "    sys.modules[name] = None\n"
              f"sys.argv = ['bake.py', *{list(args)!r}]\n"
              f"runpy.run_path({str(BAKE)!r}, run_name='__main__')\n")
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)


def test_without_materialx_and_usd_the_target_says_so_and_others_bake(face, tmp_path):
    out = tmp_path / "none"
    proc = _without_libraries("--albedo", str(face[0]), "--out", str(out), "--target", "cycles,openpbr")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert "materialx" in proc.stderr and "usd-core" in proc.stderr and not out.exists()
    proc = _without_libraries("--albedo", str(face[0]), "--out", str(out))
    assert proc.returncode == 0, proc.stderr[-2000:]
    probe = subprocess.run([sys.executable, "-c", "import sys, exporters.bake, exporters.openpbr; "
                            "print('MaterialX' in sys.modules or 'pxr' in sys.modules)"],
                           capture_output=True, text=True, cwd=str(ROOT), timeout=60)
    assert probe.stdout.strip() == "False", probe.stderr  # only the writers import them, when asked


def test_single_medium_stays_finite_and_bounded():
    """Edge cases of exporters.openpbr.single_medium: a component without weight, albedos at 0 and near 1, a black
    channel, a white one: finite everywhere, the diffusion length within what the bleed model allows around the
    light-weighted mean (the transport ratio lies in [0, sqrt 3]: D_bleed within 1 + kappa sqrt 3 of the mean either
    way, then shortened by at most 15 %)."""
    from exporters import openpbr

    rng = np.random.default_rng(5)
    n, k = 200, 3
    weight = rng.uniform(0.0, 1.0, (n, k, 3))
    weight[:20, 0] = 0.0
    alpha = rng.uniform(0.0, 0.9999, (n, k, 3))
    alpha[20:30] = 0.0
    alpha[30:40] = 0.999999
    sigma_t = 10.0 ** rng.uniform(0.0, 4.0, (n, k, 3))
    medium = openpbr.single_medium(weight, alpha, sigma_t, np.zeros((n, k)))
    for name in ("base_color", "subsurface_color", "alpha", "mean_free_path_cm", "diffusion_length_cm"):
        assert np.all(np.isfinite(getattr(medium, name))), name
    assert np.all((medium.base_color >= 0) & (medium.base_color <= 1))
    ratio = medium.diffusion_length_cm / medium.mean_diffusion_length_cm
    spread = 1.0 + openpbr.BLEED_KAPPA * np.sqrt(3.0)
    assert np.all((ratio >= 0.85 / spread - 1e-9) & (ratio <= spread + 1e-9))
    assert np.all(medium.mean_free_path_cm >= 1e-3 * (1 - 1e-12))  # exporters.collapse.MIN_MFP_CM
    with pytest.raises(ValueError, match="NaN"):
        openpbr.single_medium(np.full((1, 1, 3), np.nan), alpha[:1, :1], sigma_t[:1, :1], np.zeros((1, 1)))
