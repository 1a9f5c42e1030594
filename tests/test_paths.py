"""Shipped files record paths without the build machine's absolute paths (training.paths)."""

from pathlib import Path

from training.paths import REPO_ROOT, portable


def test_paths_inside_the_repository_are_relative_to_its_root():
    assert portable(REPO_ROOT / "data" / "laptop") == "data/laptop"
    assert portable(REPO_ROOT / "blender_addon" / "models" / "skin_inversion.json") == \
        "blender_addon/models/skin_inversion.json"
    assert portable(REPO_ROOT) == "."


def test_paths_outside_keep_only_their_last_two_parts(tmp_path):
    p = tmp_path / "runs" / "lut_paper.npz"
    assert portable(p) == "runs/lut_paper.npz"
    assert not Path(portable(p)).is_absolute()
    assert portable(None) is None


def test_relative_paths_are_taken_from_the_working_folder(monkeypatch):
    monkeypatch.chdir(REPO_ROOT)
    assert portable("data/fits_laptop") == "data/fits_laptop"
