"""ONNX export: I/O exactly per docs/contracts.md §3, torch-vs-onnxruntime parity, the input domain in the graph,
the float16 path, the failure paths, and the card's SHA-256 (on a tiny model trained on toy data)."""

import hashlib
import json
import math

import numpy as np
import onnx
import pytest
import torch

from exporters.colorimetry import SRGB_LUMINANCE, spectrum_to_linear_srgb
from exporters.constants import N_WAVELENGTHS
from exporters.inference import onnx_session
from training.commands import export as export_cli
from training.export.graphs import export_graphs, parity, parity_failures
from training.model import ModelConfig
from training.model.config import FALLBACK_ALBEDO_RGB, SIZES
from training.train.run import TrainConfig, load_model, train
from training.train.toy import write_toy

SPEC_INVERSION = {"albedo_rgb": ["N", 3]}
SPEC_INV_OUT = {"biophysical": ["N", 5], "exposure": ["N", 1], "reflectance": ["N", N_WAVELENGTHS],
                "alpha": ["N", 3, N_WAVELENGTHS], "sigma_t": ["N", 3, N_WAVELENGTHS], "g": ["N", 3, N_WAVELENGTHS],
                "weight": ["N", 3, N_WAVELENGTHS]}
SPEC_DEC_OUT = {k: v for k, v in SPEC_INV_OUT.items() if k not in ("biophysical", "exposure")}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("exp")
    data, fits, lut = write_toy(root, n_train=16, n_validation=4)
    tcfg = TrainConfig(epochs=[2, 2, 2], batch=[8, 64, 8], synthetic=128)
    train(root / "run", data, fits, lut, mcfg=ModelConfig(**SIZES["tiny"]), tcfg=tcfg, progress=False,
          command="python -m training train (test)")
    return root / "run"


@pytest.fixture(scope="module")
def exported(run, tmp_path_factory):
    out = tmp_path_factory.mktemp("models")
    card = export_cli.export_run(run, out, parity_n=2000, command="test export")
    return out, card


def _io(path):
    m = onnx.load(path)

    def dims(v):
        return [d.dim_param or d.dim_value for d in v.type.tensor_type.shape.dim]

    elem = {v.name: v.type.tensor_type.elem_type for v in list(m.graph.input) + list(m.graph.output)}
    assert set(elem.values()) == {onnx.TensorProto.FLOAT}
    return {v.name: dims(v) for v in m.graph.input}, {v.name: dims(v) for v in m.graph.output}


def test_graph_io_is_exactly_spec(exported):
    out, card = exported
    ins, outs = _io(out / "skin_inversion.onnx")
    assert ins == SPEC_INVERSION and outs == SPEC_INV_OUT
    assert list(outs) == list(SPEC_INV_OUT)
    ins, outs = _io(out / "skin_decoder.onnx")
    assert ins == {"biophysical": ["N", 5]} and outs == SPEC_DEC_OUT
    sess = onnx_session(out / "skin_inversion.onnx", threads=1)
    for n in (1, 7):  # dynamic N
        res = sess.run(None, {"albedo_rgb": np.full((n, 3), 0.3, np.float32)})
        assert [r.shape[0] for r in res] == [n] * 7
    # the card's hashes are those of the files
    for name in ("skin_inversion.onnx", "skin_decoder.onnx"):
        assert card["files"][name]["sha256"] == hashlib.sha256((out / name).read_bytes()).hexdigest()
    on_disk = json.loads((out / "skin_inversion.json").read_text())
    assert on_disk["K"] == 3 and on_disk["training"]["commands"] == ["python -m training train (test)"]
    assert on_disk["export"]["parity_torch_vs_onnxruntime"]["skin_inversion.onnx"]["sigma_t"] <= 1e-4


def test_parity_on_10000_random_inputs(run):
    model = load_model(run / "model.pt")
    errors = parity(model, export_graphs(model, "float32"), "float32", n=10_000, seed=5)
    assert not parity_failures(errors), errors
    assert set(errors["skin_inversion.onnx"]) == set(SPEC_INV_OUT)


def test_graph_input_domain_and_exposure_identity(exported):
    out, _ = exported
    sess = onnx_session(out / "skin_inversion.onnx", threads=1)
    x = np.array([[0.5, 0.3, 0.2], [math.nan, 0.1, 0.1], [0.1, math.inf, 0.2], [-math.inf, 0.0, 0.0],
                  list(FALLBACK_ALBEDO_RGB), [1.5, -0.5, 0.4], [1.0, 0.0, 0.4], [0.0, 0.0, 0.0]], np.float32)
    res = dict(zip(["biophysical", "exposure", "reflectance", "alpha", "sigma_t", "g", "weight"],
                   sess.run(None, {"albedo_rgb": x}), strict=True))
    for name, r in res.items():
        assert np.isfinite(r).all(), name
        for i in (1, 2, 3):  # non-finite rows behave as the fallback colour
            np.testing.assert_allclose(r[i], r[4], rtol=1e-6, atol=1e-7, err_msg=name)
        np.testing.assert_allclose(r[5], r[6], rtol=1e-6, atol=1e-7, err_msg=name)  # clamped to [0, 1]
    assert res["exposure"][7, 0] == 0.0  # black: zero luminance
    rgb = spectrum_to_linear_srgb(res["reflectance"].astype(np.float64), "D65") * res["exposure"]
    x_dom = np.clip(np.where(np.isfinite(x).all(1, keepdims=True), x, FALLBACK_ALBEDO_RGB), 0, 1)
    np.testing.assert_allclose(rgb @ SRGB_LUMINANCE, x_dom @ SRGB_LUMINANCE, rtol=3e-5, atol=1e-7)
    dec = onnx_session(out / "skin_decoder.onnx", threads=1)
    r = dec.run(None, {"biophysical": np.array([[math.nan, 0.1, 0.01, 0.7, 0.5]], np.float32)})
    assert all(np.isfinite(a).all() for a in r)


def test_float16_storage_is_checked_against_the_rounded_model(run):
    model = load_model(run / "model.pt")
    g32, g16 = export_graphs(model, "float32"), export_graphs(model, "float16")
    assert len(g16["skin_decoder.onnx"]) < 0.7 * len(g32["skin_decoder.onnx"])
    assert not parity_failures(parity(model, g16, "float16", n=1000))
    # against the unrounded model the float16 graph differs measurably: the check is not vacuous
    errs = parity(model, g16, "float32", n=1000)
    assert max(errs["skin_decoder.onnx"].values()) > 1e-6


def test_export_fails_without_writing_when_checks_fail(run, tmp_path, monkeypatch):
    out = tmp_path / "m"
    assert export_cli.main(["--run", str(run), "--out", str(out), "--max-mb", "0.01", "--parity-n", "100"]) == 1
    assert not out.exists()
    monkeypatch.setattr(export_cli, "PARITY_TOL", 0.0)
    monkeypatch.setattr("training.export.graphs.PARITY_TOL", 0.0)
    assert export_cli.main(["--run", str(run), "--out", str(out), "--parity-n", "100"]) == 1
    assert not out.exists()
    monkeypatch.undo()
    assert export_cli.main(["--run", str(run), "--out", str(out), "--parity-n", "100"]) == 0
    assert export_cli.main(["--run", str(run), "--out", str(out), "--parity-n", "100"]) == 2  # no overwrite
    assert export_cli.main(["--run", str(tmp_path / "none"), "--out", str(out)]) == 2


def test_torch_and_graph_agree_on_named_tones(run, exported):
    model = load_model(run / "model.pt")
    out, _ = exported
    x = torch.tensor([[0.45, 0.30, 0.24], [0.08, 0.04, 0.03], [0.7, 0.55, 0.5]])
    ref = model.invert(x)
    got = onnx_session(out / "skin_inversion.onnx", threads=1).run(["biophysical", "weight"], {"albedo_rgb": x.numpy()})
    np.testing.assert_allclose(got[0], ref["biophysical"].numpy(), atol=1e-5)
    np.testing.assert_allclose(got[1], ref["weight"].numpy(), atol=1e-5)
