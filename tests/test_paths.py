"""Shipped files record paths without the build machine's absolute paths (training.paths)."""

import json
import re
from pathlib import Path

import pytest

from training.paths import REPO_ROOT, portable, portable_command, portable_strings


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


def test_a_linked_data_folder_is_recorded_as_the_repository_names_it(tmp_path, monkeypatch):
    """data/ as a link to a disk outside the checkout (docs/research/rebuilding.md) is recorded as data/...,
    not by its target;
    a link inside the checkout to another place inside it, and ".." in a path, still resolve into the checkout."""
    repo, disk = tmp_path / "repo", tmp_path / "disk" / "sss"
    (disk / "data" / "laptop").mkdir(parents=True)
    (repo / "docs").mkdir(parents=True)
    (repo / "data").symlink_to(disk / "data")
    (tmp_path / "docs_link").symlink_to(repo / "docs")
    monkeypatch.setattr("training.paths.REPO_ROOT", repo)
    assert portable(repo / "data" / "laptop") == "data/laptop"
    assert portable(tmp_path / "docs_link") == "docs"
    assert portable(repo / "data" / ".." / "docs") == "docs"


def test_relative_paths_are_taken_from_the_working_folder(monkeypatch):
    monkeypatch.chdir(REPO_ROOT)
    assert portable("data/fits_laptop") == "data/fits_laptop"


def test_command_lines_lose_absolute_paths_and_keep_the_rest(tmp_path):
    cmd = portable_command("python -m training train",
                           ["--dataset", str(REPO_ROOT / "data" / "laptop"), f"--lut={tmp_path / 'x' / 'l.npz'}",
                            "--note", "two words", "--epochs", "1,2,3"])
    assert cmd == "python -m training train --dataset data/laptop --lut=x/l.npz --note 'two words' --epochs 1,2,3"
    assert portable_strings({"a": [str(REPO_ROOT / "data")], "c": "python -m training validate --out /tmp/v",
                             "n": 3}) == {"a": ["data"], "c": "python -m training validate --out tmp/v", "n": 3}


SHIPPED = ["blender_addon/models/skin_inversion.json", "docs/validation/tables.json", "docs/validation/tables.md",
           "docs/figures/mitsuba_strips.json"]


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_files_record_no_absolute_paths(name):
    text = (REPO_ROOT / name).read_text()
    found = re.findall(r"""(?:^|[\s"'=(])(/(?:work|root|home|tmp|Users|scratch|mnt|data)/[^\s"']*)""", text)
    assert not found, f"{name} records machine paths: {found[:3]}"


def test_card_counts_the_fitted_tones_stage_3_learnt_from():
    card = json.loads((REPO_ROOT / SHIPPED[0]).read_text())
    d = card["dataset"]
    assert card["fits"]["path"] and d["n_train_fitted"] > 0 and d["fitted_wavelengths"] > 0
    assert d["n_train_fitted"] <= d["n_train"] and d["n_validation_fitted"] <= d["n_validation"]
