"""exporters.uv_coverage against an independent point-in-polygon test (matplotlib.path), and the add-on's use
of a mesh's UVs: only covered texels are evaluated."""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
import numpy as np
import pytest
from matplotlib.path import Path as MplPath

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from blender_addon import baker, preferences  # noqa: E402
from exporters import uv_coverage  # noqa: E402
from tests.addon_scene import write_image  # noqa: E402


def reference(tris: np.ndarray, width: int, height: int) -> np.ndarray:
    ys, xs = np.mgrid[0:height, 0:width]
    centres = np.stack([((xs + 0.5) / width).ravel(), (1.0 - (ys + 0.5) / height).ravel()], axis=1)
    mask = np.zeros(height * width, bool)
    for t in tris:  # both orientations: matplotlib's radius sign includes the boundary for one of them
        mask |= MplPath(t).contains_points(centres, radius=1e-9) | MplPath(t[::-1]).contains_points(centres,
                                                                                                   radius=1e-9)
    return mask.reshape(height, width)


@pytest.mark.parametrize("width, height", [(97, 64), (13, 200), (1, 1), (5, 1)])
def test_matches_point_in_polygon(width, height):
    rng = np.random.default_rng(width)
    tris = rng.random((80, 3, 2)) * 0.3 + rng.random((80, 1, 2)) * 0.7
    fixed = np.array([[[0.05, 0.1], [0.9, 0.2], [0.4, 0.95]], [[0, 0], [1, 0], [1, 1]],
                      [[0.1, 0.5], [0.6, 0.5], [0.3, 0.9]], [[0.1, 0.5], [0.6, 0.5], [0.3, 0.1]],
                      [[0.2, 0.2], [0.4, 0.4], [0.6, 0.6]]])  # flat top, flat bottom, degenerate
    tris = np.concatenate([tris, fixed])
    np.testing.assert_array_equal(uv_coverage.uv_coverage(tris, width, height, margin=0),
                                  reference(tris, width, height))


def test_margin_dilates_by_whole_texels():
    tri = np.array([[[0.505, 0.505], [0.53, 0.505], [0.505, 0.53]]])  # only the centre (0.5156, 0.5156) of 32
    core = uv_coverage.uv_coverage(tri, 32, 32, margin=0)
    assert core.sum() == 1
    grown = uv_coverage.uv_coverage(tri, 32, 32, margin=2)
    (y,), (x,) = np.nonzero(core)
    assert grown.sum() == 25 and grown[y - 2:y + 3, x - 2:x + 3].all()


def test_bad_input():
    with pytest.raises(ValueError, match="shape"):
        uv_coverage.uv_coverage(np.zeros((3, 2)), 4, 4)
    with pytest.raises(ValueError, match="NaN"):
        uv_coverage.uv_coverage(np.full((1, 3, 2), np.nan), 4, 4)
    with pytest.raises(ValueError, match="size"):
        uv_coverage.uv_coverage(np.zeros((1, 3, 2)), 0, 4)
    assert not uv_coverage.uv_coverage(np.zeros((0, 3, 2)), 4, 3).any()


def test_addon_bakes_only_what_the_mesh_covers(tmp_path):
    import addon_utils

    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert addon_utils.enable("blender_addon", default_set=True, handle_error=None) is not None
    try:
        codes = np.full((8, 8, 3), (224, 172, 150), np.uint8)
        codes[:, 5:] = (30, 60, 220)  # outside the plane's UVs: never evaluated
        png = write_image(tmp_path / "half.png", codes, "uint8")
        bpy.ops.mesh.primitive_plane_add(size=1.0, calc_uvs=True)
        obj = bpy.context.active_object
        uv = obj.data.uv_layers.active.data
        for loop in uv:  # squeeze the UVs into the left half
            loop.uv = (loop.uv[0] * 0.5, loop.uv[1])
        mat = bpy.data.materials.new("Half")
        obj.data.materials.append(mat)
        tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
        tex.image = bpy.data.images.load(str(png))
        mat.node_tree.nodes.active = tex
        settings = baker.BakeSettings(model_path=preferences.DEFAULT_MODEL, threads=1, backend="SVM")
        with bpy.context.temp_override(object=obj, active_object=obj):
            run = baker.AddonBake(bpy.context, settings)
        run.run()
        run.apply(bpy.context)
        stats = run.result.stats
        assert stats["texels_not_covered_by_uvs"] == 8 * 2  # columns 6, 7 (column 5 is in the 2-texel margin)
        assert stats["texels_outside_table"] == 8  # the blue margin column: outside the skin table
    finally:
        addon_utils.disable("blender_addon", default_set=True)
