"""The Notes section of tables.md from its template (training/validate/templates/notes.md).

The committed docs/validation/tables.json and tables.md were written together by a validation run, so
rebuilding the Markdown from the JSON must give the committed file byte for byte: the notes' prose now lives in
the template, and this shows it still says exactly what the run wrote.
"""

from __future__ import annotations

import copy
import json
import re
import tomllib
from fnmatch import fnmatch
from pathlib import Path

import pytest

from training.validate import tables

ROOT = Path(__file__).resolve().parents[1]
TABLES_JSON = ROOT / "docs" / "validation" / "tables.json"
TABLES_MD = ROOT / "docs" / "validation" / "tables.md"


@pytest.fixture(scope="module")
def record() -> dict:
    return json.loads(TABLES_JSON.read_text())


def test_committed_tables_md_is_rebuilt_byte_for_byte_from_tables_json(record):
    committed = TABLES_MD.read_text()
    stamp = re.search(r"— (\d{4}-\d\d-\d\d \d\d:\d\d UTC)\.", committed).group(1)
    rebuilt = copy.deepcopy(record)
    rebuilt["notes"] = tables.notes(rebuilt)
    assert rebuilt["notes"] == record["notes"]
    assert tables.markdown(rebuilt, stamp=stamp) == committed


def test_the_other_branches_fill_every_placeholder(record):
    """Quick mode, no card, no Table 3 data, a given baseline scale, an explicit fitter schedule, clamped
    painted colours: every note is one line with no placeholder left."""
    rec = copy.deepcopy(record)
    rec["run"]["quick"] = True
    rec["run"]["config"]["renderer"] = "mc"
    rec["run"]["model"]["card"] = {"path": "models/skin_inversion.json", "missing": True}
    rec["profile_fidelity"] = {"fits": None, "network": None, "fits_missing": "no --fits given"}
    rec["baselines"]["calibration"] = {"mode": "given"}
    rec["run"]["fits"]["steps"] = [["k1_shape", 3]]
    first = rec["gate"]["tones"][0]
    rec["gate"]["per_tone"]["nn_painted"][first]["clamped"] = True
    out = tables.notes(rec)
    assert out[0].startswith("QUICK MODE") and "rendered by our Monte Carlo mixture renderer" in out[1]
    assert "(no model card found)" in " ".join(out) and "given (--baseline-scale)" in " ".join(out)
    assert "iterations [['k1_shape', 3]]" in " ".join(out)
    assert f"had to be clamped: {first}." in " ".join(out)
    assert all("$" not in n and "\n" not in n for n in out)


def test_the_template_ships_with_the_package():
    globs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["training"]
    assert any(fnmatch("validate/" + tables.NOTES_TEMPLATE, g) for g in globs), globs
    assert {"quick", "photons", "compute"} <= set(tables.note_templates())
