"""An up-to-date bake (same image content, model, options) is reused, not recomputed: real bakes with the real
model, and onnxruntime session runs counted by exporters.inference (the counter every InversionSession.run
increments), in-process, through bake.py and through the Blender operator."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import blender_addon  # noqa: E402,F401
from exporters import bake, inference  # noqa: E402
from tests.addon_scene import run_invert, skin_codes, skin_object, write_image  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "blender_addon" / "models" / "skin_inversion.onnx"


@pytest.fixture()
def png(tmp_path) -> Path:
    codes = np.random.default_rng(5).integers(60, 230, (5, 7, 3)).astype(np.uint8)  # 35 distinct colours
    return write_image(tmp_path / "face.png", codes, "uint8")


def state(folder: Path) -> dict:
    return {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in folder.iterdir()}


def test_rerun_does_no_inference(png, tmp_path):
    out = tmp_path / "maps"
    out.mkdir()
    opts = bake.BakeOptions(threads=1, exact=True, targets=("cycles", "spectral"))
    before = inference.inference_counts()
    first = bake.bake(png, out, MODEL, opts)
    after_first = inference.inference_counts()
    assert not first.reused and after_first["texels"] - before["texels"] >= 35  # the 35 colours (+ load probe)
    files = state(out)
    again = bake.bake(png, out, MODEL, opts)
    assert inference.inference_counts() == after_first  # no session run, not even a model load
    assert again.reused and any("up to date" in n for n in again.notes)
    assert state(out) == files  # nothing rewritten
    assert sorted(again.files) == sorted(first.files) and again.k == first.k


def test_what_makes_a_bake_out_of_date(png, tmp_path):
    out = tmp_path / "maps"
    out.mkdir()
    opts = bake.BakeOptions(threads=1)
    bake.bake(png, out, MODEL, opts)
    files = state(out)
    for changed in (bake.BakeOptions(threads=1, unit_scale_m=0.01), bake.BakeOptions(threads=1, exact=True),
                    bake.BakeOptions(threads=1, targets=("spectral",))):  # other options: not this bake
        with pytest.raises(bake.BakeError, match="exist"):
            bake.bake(png, out, MODEL, changed)
    assert state(out) == files
    assert bake.bake(png, out, MODEL, bake.BakeOptions(threads=1, force=True, overwrite=True)).reused is False
    # a map edited since: the folder is no longer an up-to-date bake of this image
    color = out / "face_k1_color.exr"
    os.utime(color, ns=(color.stat().st_atime_ns, color.stat().st_mtime_ns + 10**9))
    with pytest.raises(bake.BakeError, match="exist"):
        bake.bake(png, out, MODEL, opts)
    # other image content under the same name
    write_image(png, skin_codes(5, 7), "uint8")
    with pytest.raises(bake.BakeError, match="exist"):
        bake.bake(png, out, MODEL, opts)


def test_bake_py_reports_an_up_to_date_folder(png, tmp_path):
    out = tmp_path / "cli"
    args = [sys.executable, str(ROOT / "blender_addon" / "bake.py"), "--albedo", str(png), "--out", str(out),
            "--threads", "1"]
    assert subprocess.run(args, capture_output=True, text=True, timeout=120).returncode == 0
    files = state(out)
    proc = subprocess.run(args, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "up to date" in proc.stdout and "kept" in proc.stdout
    assert state(out) == files
    record = json.loads((out / "face_maps.json").read_text())
    assert len(record["bake"]["key"]) == 64 and set(record["bake"]["files"]) == set(record["files"])


def test_invert_twice_reuses_the_packed_maps(addon, png):
    obj, mat, tex = skin_object(png)
    assert run_invert(obj, backend="SVM", exact=True) == {"FINISHED"}
    images = sorted(bpy.data.images.keys())
    node_names = sorted(n.name for n in mat.node_tree.nodes)
    counts = inference.inference_counts()
    assert run_invert(obj, backend="SVM", exact=True) == {"FINISHED"}
    assert inference.inference_counts() == counts  # nothing evaluated
    assert sorted(bpy.data.images.keys()) == images  # no second set of images
    assert sorted(n.name for n in mat.node_tree.nodes) == node_names  # already wired: nothing added
    obj2, mat2, tex2 = skin_object(png, name="Other")  # another material with the same albedo image
    duplicate, tex2.image = tex2.image, tex.image
    bpy.data.images.remove(duplicate)
    assert run_invert(obj2, backend="SVM", exact=True) == {"FINISHED"}
    assert inference.inference_counts() == counts and sorted(bpy.data.images.keys()) == images
    assert any(n.bl_idname == "ShaderNodeGroup" for n in mat2.node_tree.nodes)  # wired to the same packed maps
