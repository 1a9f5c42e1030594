"""`python -m training report` (training/commands/report.py): the counts it names, read independently from the
files; a changed graph flagged; a missing folder refused.

The tiny dataset is test_fit_dataset.py's (the dataset's own store, closed-form dipole profiles); its fits are
real ``fit_split`` runs cut short (2 of 3 tones, 8 wavelengths, K = 1)."""

from __future__ import annotations

import json
import shutil

import h5py
import pytest

from tests.test_fit_dataset import STEPS, setup  # noqa: F401  (setup: the module's fixture)
from training.commands.report import main
from training.fit.dataset import fit_split
from training.paths import REPO_ROOT, SHIPPED_CARD, SHIPPED_MODEL_DIR
from training.sim.lut_interp import LookupTables


def report(capsys, *argv: str) -> dict:
    assert main([*argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def fits(setup):  # noqa: F811
    d, ds, lut_path = setup
    out = d / "fits_report"
    fit_split(ds, "train", LookupTables.load(lut_path), lut_path, (1,), out, steps=STEPS, wavelength_stride=47,
              max_tones=2, progress=False)
    return out


def test_report_names_the_counts_of_the_dataset_fits_and_card(setup, fits, capsys):  # noqa: F811
    d, ds, _ = setup
    with h5py.File(ds / "train.h5", "r") as f:
        tones_done, tones_total = int(f["done"][:].sum()), int(f.attrs["n_total"])
    with h5py.File(fits / "train_fits.h5", "r") as f:
        fitted, selected, wavelengths = int(f["done"][:].sum()), len(f["index"]), f["k1_alpha"].shape[2]
    card = json.loads(SHIPPED_CARD.read_text())

    rec = report(capsys, "--dataset", str(ds), "--fits", str(fits))
    assert rec["dataset"]["splits"]["train"]["tones"] == tones_done == 3
    assert rec["dataset"]["splits"]["train"]["of"] == tones_total
    got = rec["fits"]["splits"]["train"]
    assert (got["fitted"], got["selected"], got["of"], got["ks"], got["wavelengths"]) == (
        fitted, selected, tones_total, [1], wavelengths)
    assert (fitted, selected, wavelengths) == (2, 2, 8)
    assert got["errors"]["tones"] == 2 and set(got["errors"]["K"]) == {"1"}
    assert rec["model"]["K"] == card["K"] and rec["model"]["created"] == card["created"]
    assert rec["model"]["dataset"]["n_train"] == card["dataset"]["n_train"]
    assert all(c["ok"] for c in rec["model"]["files"].values()) and set(rec["model"]["files"]) == set(card["files"])
    notes = " ".join(rec["notes"])
    assert "no validation.h5" in notes and "no validation_fits" in notes and "validation: not given" in notes

    assert main(["--dataset", str(ds), "--fits", str(fits)]) == 0
    md = capsys.readouterr().out
    assert f"| train | {tones_done} | {tones_total} |" in md
    assert f"| train | {fitted} | {selected} | {tones_total} | 1 | {wavelengths} | 1 |" in md
    assert f"K = {card['K']}" in md and f"{card['dataset']['n_train']:,} training" in md
    assert str(d) not in md and str(REPO_ROOT) not in md  # no absolute machine paths


def test_report_reads_the_validation_headline(capsys):
    tables = json.loads((REPO_ROOT / "docs" / "validation" / "tables.json").read_text())
    rec = report(capsys, "--validation", str(REPO_ROOT / "docs" / "validation"))
    assert rec["validation"]["path"] == "docs/validation"
    assert rec["validation"]["gate"]["nn_delta_e"] == tables["gate"]["rows"]["nn"]["delta_e"]
    assert rec["validation"]["goals"] == tables["goals"]


def test_report_lists_the_network_targets_of_the_card(capsys):
    """The shipped card's validation entry carries the network's targets; the Markdown report lists
    each with ours, the target and met / not met as the card says."""
    from training.commands.report import main

    card = json.loads((SHIPPED_MODEL_DIR / "skin_inversion.json").read_text())
    targets = card["validation"]["goals"]["network_targets"]
    assert main([]) == 0
    lines = [x for x in capsys.readouterr().out.splitlines() if x.startswith("- target: ")]
    assert len(lines) == len(targets) > 0
    for line, t in zip(lines, targets, strict=True):
        assert t["what"] in line and line.endswith("not met" if not t["met"] else ", met")


def test_changed_graph_is_flagged(tmp_path, capsys):
    model = tmp_path / "model"
    shutil.copytree(SHIPPED_MODEL_DIR, model, ignore=shutil.ignore_patterns("*.py", "*.npz", "__pycache__"))
    card = json.loads((model / "skin_inversion.json").read_text())
    data = bytearray((model / "skin_decoder.onnx").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (model / "skin_decoder.onnx").write_bytes(bytes(data))

    rec = report(capsys, "--model-dir", str(model))
    files = rec["model"]["files"]
    assert files["skin_inversion.onnx"]["ok"] and not files["skin_decoder.onnx"]["ok"]
    assert files["skin_decoder.onnx"]["expected"] == card["files"]["skin_decoder.onnx"]["sha256"]
    assert any("skin_decoder.onnx SHA-256 does not match" in n for n in rec["notes"])
    assert main(["--model-dir", str(model)]) == 0
    assert "**NO: file is" in capsys.readouterr().out


def test_missing_folder_and_existing_out_are_refused(tmp_path, capsys):
    assert main(["--fits", str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--fits" in err and "no such folder" in err
    out = tmp_path / "report.md"
    out.write_text("mine")
    assert main(["--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err and out.read_text() == "mine"
    assert main(["--out", str(out), "--overwrite"]) == 0
    assert out.read_text().startswith("# Report")
