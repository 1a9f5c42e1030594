"""The inversion on measured skin colours (``training.realskin.inversion``): the exposure the shipped
``skin_inversion.onnx`` answers the NIST subjects' colours with, checked against Y(input) / Y(its own
reflectance) recomputed here, and the acceptance (every subject within 0.9-1.1), which a
model trained on the uncalibrated skin model fails."""

from __future__ import annotations

import numpy as np
import pytest

from exporters.colorimetry import spectrum_to_linear_srgb
from exporters.inference import load_model
from training.paths import SHIPPED_MODEL
from training.realskin.geometry import rough_specular
from training.realskin.inversion import EXPOSURE_BAND, inversion_exposure, main, measured_albedo_rgb
from training.realskin.measurements import read_measurements

#: Rec. 709 / sRGB luminance weights of linear sRGB (IEC 61966-2-1), independent of exporters.colorimetry.
Y_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


@pytest.fixture(scope="module")
def record():
    return inversion_exposure(SHIPPED_MODEL)


def test_exposure_is_the_luminance_ratio_of_input_and_tone(record):
    meas = read_measurements()
    rgb = measured_albedo_rgb(meas, rough_specular())
    assert rgb.shape == (50, 3) and np.all((rgb > 0) & (rgb < 1))
    out = load_model(SHIPPED_MODEL, threads=1).run(rgb)
    y_tone = spectrum_to_linear_srgb(out["reflectance"].astype(np.float64), "D65") @ Y_WEIGHTS
    expected = (rgb @ Y_WEIGHTS) / y_tone
    got = np.array([s["exposure"] for s in record["subjects"]])
    np.testing.assert_allclose(got, expected, rtol=2e-3)
    s = record["summary"]
    assert s["n"] == 50 and s["min"] == pytest.approx(got.min(), abs=1e-4)
    assert s["inside_band"] == int(((got >= EXPOSURE_BAND[0]) & (got <= EXPOSURE_BAND[1])).sum())
    assert [r["name"] for r in record["subjects"]] == list(meas.names)


def test_command_prints_the_range(capsys):
    assert main([]) == 0
    assert "measured skin colours" in capsys.readouterr().out
    assert main(["--model-dir", "no/such/folder"]) == 2


def test_measured_skin_is_answered_at_its_own_brightness(record):
    """Every measured colour answered with exposure 0.9-1.1 (a model trained on the uncalibrated skin model
    answers 1.27-1.89)."""
    assert record["summary"]["inside_band"] == record["summary"]["n"], record["summary"]
