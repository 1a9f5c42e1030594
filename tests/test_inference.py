"""exporters.inference with the real shipped ONNX model and real onnxruntime."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from exporters import inference
from tests.onnx_fakes import missing_outputs_model, wrong_input_model

MODELS = Path(__file__).resolve().parents[1] / "blender_addon" / "models"
MODEL = MODELS / "skin_inversion.onnx"
CARD = json.loads((MODELS / "skin_inversion.json").read_text())


@pytest.fixture(scope="module")
def model():
    return inference.load_model(MODEL, threads=1)


def test_load_reads_k_and_hash_from_the_model(model):
    assert model.k == CARD["K"] == CARD["files"]["skin_inversion.onnx"]["outputs"]["alpha"][1]
    assert model.sha256 == CARD["files"]["skin_inversion.onnx"]["sha256"]
    assert model.threads == 1


def test_run_shapes_and_chunks_agree(model):
    rgb = np.random.default_rng(1).uniform(0.02, 0.9, (11, 3))
    whole = model.run(rgb)
    assert whole["alpha"].shape == (11, model.k, 376) and whole["reflectance"].shape == (11, 376)
    assert whole["biophysical"].shape == (11, 5) and whole["exposure"].shape == (11, 1)
    np.testing.assert_allclose(whole["weight"].sum(axis=1), 1.0, atol=1e-5)
    pieces = list(model.run_chunks(rgb, 4))
    assert [sl.stop - sl.start for sl, _ in pieces] == [4, 4, 3]
    for name in ("reflectance", "alpha", "sigma_t"):
        joined = np.concatenate([out[name] for _, out in pieces])
        np.testing.assert_allclose(joined, whole[name], rtol=2e-5, atol=1e-7)


def test_chunk_rows_follow_the_memory_budget(model):
    per = model.bytes_per_texel()
    assert per > 4 * 376 * (1 + 4 * model.k)  # at least the float32 outputs
    for mb in (1, 64, 512):
        rows = inference.chunk_rows(model, mb)
        assert rows * per <= mb * 2**20 < (rows + 1) * per
    assert inference.chunk_rows(model, 1e-6) == 1
    with pytest.raises(ValueError, match="> 0"):
        inference.chunk_rows(model, 0)


def test_nan_input_is_refused(model):
    with pytest.raises(ValueError, match=r"1 albedo texel\(s\) are NaN/Inf \(first row 1\)"):
        model.run(np.array([[0.3, 0.2, 0.1], [np.nan, 0.2, 0.1]]))
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        model.run(np.zeros((2, 4)))


def test_unique_rows_is_exact():
    next_up = np.nextafter(np.float32(0.3), np.float32(1.0))  # one ulp away: a different colour
    rgb = np.array([[0.1, 0.2, 0.3], [0.0, 0.5, 0.5], [0.1, 0.2, 0.3], [-0.0, 0.5, 0.5], [0.1, 0.2, next_up]],
                   dtype=np.float32)
    uniq, inverse = inference.unique_rows(rgb)
    assert len(uniq) == 3
    np.testing.assert_array_equal(uniq[inverse], rgb + np.float32(0.0))
    assert inverse[0] == inverse[2] and inverse[1] == inverse[3]


def test_model_errors_name_the_problem(tmp_path):
    with pytest.raises(inference.ModelError, match="model not found at .*nothing.onnx"):
        inference.load_model(tmp_path / "nothing.onnx")
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"\x00not an onnx graph")
    with pytest.raises(inference.ModelError, match="not a valid ONNX file"):
        inference.load_model(junk)
    with pytest.raises(inference.ModelError, match=r"expected one input 'albedo_rgb' of shape \(N, 3\)"):
        inference.load_model(wrong_input_model(tmp_path / "w.onnx"))
    with pytest.raises(inference.ModelError, match=r"lacks output\(s\) \['biophysical', 'exposure', 'alpha'"):
        inference.load_model(missing_outputs_model(tmp_path / "m.onnx"))
    with pytest.raises(ValueError, match="threads"):
        inference.load_model(MODEL, threads=-1)


def test_onnx_session_reads_a_path_or_bytes_alike():
    """``onnx_session`` from the file and from its bytes: the same graph, the same answers; threads < 0 refused."""
    rgb = np.array([[0.4, 0.3, 0.25], [0.1, 0.08, 0.06]], dtype=np.float32)
    by_path = inference.onnx_session(MODEL, threads=1).run(["reflectance"], {"albedo_rgb": rgb})[0]
    by_bytes = inference.onnx_session(MODEL.read_bytes(), threads=2).run(["reflectance"], {"albedo_rgb": rgb})[0]
    assert by_path.shape == (2, 376) and np.all(np.isfinite(by_path))
    np.testing.assert_allclose(by_bytes, by_path, rtol=1e-6, atol=1e-7)
    with pytest.raises(ValueError, match="threads must be >= 0"):
        inference.onnx_session(MODEL, threads=-1)


def test_every_onnx_session_of_the_code_is_made_in_one_place():
    """exporters, training and the add-on open onnxruntime sessions through ``inference.onnx_session`` only."""
    root = Path(__file__).resolve().parents[1]
    makers = [f"{p.relative_to(root)}:{i}" for top in ("exporters", "training", "blender_addon")
              for p in sorted((root / top).rglob("*.py"))
              for i, line in enumerate(p.read_text().splitlines(), 1) if "InferenceSession(" in line]
    assert len(makers) == 1 and makers[0].startswith("exporters/inference.py:"), makers
