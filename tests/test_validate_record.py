"""The typed validation record (training.validate.record) writes the keys that tables.json has always had.

docs/validation/tables.json was written by a full validation run; its keys, in their order, are what
training.validate.tables, the model card's headline and the report read.  Each dataclass of the record must name
exactly those keys (a field that may be ``ABSENT`` may be missing from a run's file, nothing else).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from training.validate import record as R

TABLES_JSON = Path(__file__).resolve().parents[1] / "docs" / "validation" / "tables.json"


@pytest.fixture(scope="module")
def committed() -> dict:
    return json.loads(TABLES_JSON.read_text())


def _field_names(cls) -> list[str]:
    return [f.name for f in dataclasses.fields(cls)]


#: (dataclass, where its JSON object is in tables.json).
SECTIONS = [
    (R.ValidationRecord, ()),
    (R.GateRecord, ("gate",)),
    (R.RowSummary, ("gate", "rows", "nn")),
    (R.ToneMetrics, ("gate", "per_tone", "nn_painted", "R01")),
    (R.NetworkVsK3, ("gate", "nn_vs_k3")),
    (R.GroundTruthColour, ("gate", "ground_truth", "R01")),
    (R.TrainingNeighbours, ("gate", "training_neighbours")),
    (R.McCheck, ("gate", "mc_check", "nn")),
    (R.BandedRecord, ("banded",)),
    (R.ProfileFidelity, ("profile_fidelity",)),
    (R.Goals, ("goals",)),
    (R.Goal, ("goals", "nn_delta_e_at_most_paper")),
    (R.ReductionGoal, ("goals", "k2_profile_reduction_at_least_paper")),
    (R.BaselinesRecord, ("baselines",)),
    (R.Calibration, ("baselines", "calibration")),
    (R.HeldFits, ("fits_held_at_lut_albedo",)),
    (R.NetworkAnswers, ("network",)),
    (R.RunInfo, ("run",)),
    (R.WavelengthInfo, ("run", "wavelengths")),
    (R.LutInfo, ("run", "lut")),
    (R.ModelInfo, ("run", "model")),
    (R.GroundTruthInfo, ("run", "ground_truth")),
    (R.FitInfo, ("run", "fits")),
]


@pytest.mark.parametrize(("cls", "where"), SECTIONS, ids=[c.__name__ for c, _ in SECTIONS])
def test_each_dataclass_names_the_keys_of_tables_json(committed, cls, where):
    obj = committed
    for key in where:
        obj = obj[key]
    optional = {f.name for f in dataclasses.fields(cls) if f.default is R.ABSENT}
    fields = _field_names(cls)
    assert [k for k in fields if k in obj] == list(obj), "same order"
    assert set(obj) - set(fields) == set(), f"keys of tables.json that {cls.__name__} lacks"
    assert set(fields) - set(obj) <= optional, f"fields of {cls.__name__} that tables.json lacks"


def test_network_targets_have_the_keys_of_tables_json(committed):
    for target in committed["goals"]["network_targets"]:
        assert list(target) == _field_names(R.NetworkTarget)


def test_to_json_leaves_absent_fields_out_and_keeps_the_rest_in_order():
    given = R.Calibration(mode="given")
    assert R.to_json(given) == {"mode": "given"}
    calibrated = R.Calibration(mode="calibrated", tone="R05", scales_m=[0.01, 0.1], errors={"m": [1.0, 2.0]})
    assert list(R.to_json(calibrated)) == ["mode", "tone", "scales_m", "errors"]
    empty = R.BandedRecord(tones=[])
    assert R.to_json(empty) == {"tones": [], "shape": {}, "reduction": {}, "excess": {}, "excess_reduction": {}}
    metrics = R.ToneMetrics(1.0, 0.1, 2.0, 0.01, 0.2, 0.3, [0.1, 0.2, 0.3], 0.0, clamped=False)
    assert R.to_json({"nn_painted": {"R01": metrics}})["nn_painted"]["R01"]["clamped"] is False
    assert R.to_json(R.GateRecord([], [], {}, [], {}, {}, R.NetworkVsK3({}, {}, {}), {}))["mc_check"] is None


def test_headline_reads_the_committed_tables_json(committed):
    head = R.headline(committed)
    assert head["gate"]["nn_delta_e"] == committed["gate"]["rows"]["nn"]["delta_e"]
    assert head["goals"] == committed["goals"]
