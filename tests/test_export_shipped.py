"""The shipped model in blender_addon/models/: docs/contracts.md §3 I/O, card hashes, size budget, and its outputs on
every colour of a 33 x 33 x 33 grid of the RGB cube (black, white, non-skin colours) with onnxruntime."""

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest

from exporters.colorimetry import SRGB_LUMINANCE, spectrum_to_linear_srgb
from exporters.constants import N_WAVELENGTHS, PARAM_RANGES

MODELS = Path(__file__).resolve().parents[1] / "blender_addon" / "models"
INV_OUT = ("biophysical", "exposure", "reflectance", "alpha", "sigma_t", "g", "weight")
DEC_OUT = ("reflectance", "alpha", "sigma_t", "g", "weight")
FALLBACK = [0.45, 0.30, 0.24]  # documented in the card's input_domain


@pytest.fixture(scope="module")
def card():
    return json.loads((MODELS / "skin_inversion.json").read_text())


def _session(name):
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 2
    return ort.InferenceSession(str(MODELS / name), sess_options=opts, providers=["CPUExecutionProvider"])


def _dims(v):
    return [d.dim_param or d.dim_value for d in v.type.tensor_type.shape.dim]


def test_files_card_and_io(card):
    k = card["K"]
    total = 0
    for name in ("skin_inversion.onnx", "skin_decoder.onnx"):
        data = (MODELS / name).read_bytes()
        total += len(data)
        assert hashlib.sha256(data).hexdigest() == card["files"][name]["sha256"], name
    assert total < 25e6
    w = N_WAVELENGTHS
    spec = {"biophysical": ["N", 5], "exposure": ["N", 1], "reflectance": ["N", w], "alpha": ["N", k, w],
            "sigma_t": ["N", k, w], "g": ["N", k, w], "weight": ["N", k, w]}
    inv, dec = onnx.load(MODELS / "skin_inversion.onnx"), onnx.load(MODELS / "skin_decoder.onnx")
    assert [(v.name, _dims(v)) for v in inv.graph.input] == [("albedo_rgb", ["N", 3])]
    assert [(v.name, _dims(v)) for v in inv.graph.output] == [(n, spec[n]) for n in INV_OUT]
    assert [(v.name, _dims(v)) for v in dec.graph.input] == [("biophysical", ["N", 5])]
    assert [(v.name, _dims(v)) for v in dec.graph.output] == [(n, spec[n]) for n in DEC_OUT]
    for m in (inv, dec):
        for v in list(m.graph.input) + list(m.graph.output):
            assert v.type.tensor_type.elem_type == onnx.TensorProto.FLOAT
    assert card["training"]["commands"] and card["dataset"]["n_train"] > 0
    assert card["input_domain"].count(str(FALLBACK)) == 1


def test_rgb_cube_outputs_are_physical_and_decoder_agrees(card):
    inv, dec = _session("skin_inversion.onnx"), _session("skin_decoder.onnx")
    v = np.linspace(0.0, 1.0, 33, dtype=np.float32)
    cube = np.stack(np.meshgrid(v, v, v, indexing="ij"), -1).reshape(-1, 3)
    g_lo, g_hi = card["architecture"]["g_range"]
    lo = np.array([r[0] for r in PARAM_RANGES.values()])
    hi = np.array([r[1] for r in PARAM_RANGES.values()])
    for chunk in np.array_split(cube, 9):
        out = dict(zip(INV_OUT, inv.run(None, {"albedo_rgb": chunk}), strict=True))
        for name, a in out.items():
            assert np.isfinite(a).all(), name
        assert ((out["alpha"] >= 0) & (out["alpha"] <= 1)).all()
        assert (out["sigma_t"] > 0).all()
        assert ((out["g"] > -1) & (out["g"] < 1)).all()
        assert ((out["g"] >= g_lo - 1e-6) & (out["g"] <= g_hi + 1e-6)).all()
        assert (out["weight"] >= 0).all()
        np.testing.assert_allclose(out["weight"].sum(1), 1.0, atol=1e-5)
        assert ((out["biophysical"] >= lo - 1e-6) & (out["biophysical"] <= hi + 1e-6)).all()
        # exposure identity, with the project's float64 colour pipeline
        rgb = spectrum_to_linear_srgb(out["reflectance"].astype(np.float64), "D65") * out["exposure"]
        np.testing.assert_allclose(rgb @ SRGB_LUMINANCE, chunk.astype(np.float64) @ SRGB_LUMINANCE,
                                   rtol=5e-5, atol=1e-7)
        # the spectral outputs depend on the texel only through biophysical (docs/contracts.md §3)
        sub = slice(0, None, 37)
        d = dict(zip(DEC_OUT, dec.run(None, {"biophysical": out["biophysical"][sub]}), strict=True))
        for name in DEC_OUT:
            tol = {"rtol": 1e-5} if name == "sigma_t" else {"atol": 1e-5}
            np.testing.assert_allclose(d[name], out[name][sub], **tol, err_msg=name)


def test_non_finite_inputs_behave_as_documented():
    inv = _session("skin_inversion.onnx")
    x = np.array([FALLBACK, [math.nan, 0.2, 0.1], [0.3, math.inf, 0.1], [-math.inf, math.nan, 0.0]], np.float32)
    res = inv.run(None, {"albedo_rgb": x})
    for name, a in zip(INV_OUT, res, strict=True):
        assert np.isfinite(a).all(), name
        for i in (1, 2, 3):
            np.testing.assert_allclose(a[i], a[0], rtol=1e-6, atol=1e-7, err_msg=name)


def _visible_means(out):
    """Component-weighted visible (450-650 nm) albedo, sigma_t [cm^-1], sigma_a [cm^-1], and the
    translucency length [cm]: the effective attenuation length of
    diffusion theory, 1 / sigma_eff with sigma_eff = sigma_t sqrt(3 (1 - alpha)(1 - alpha g)) (Jensen et al.
    2001), averaged over the components by the light each reflects, E_k = w_k R(alpha_k, g_k) (the exporter's
    reflectance table, checked against adding-doubling); (N,) each."""
    from exporters import reflectance_tables as rt
    from exporters.constants import WAVELENGTHS_NM

    vis = (WAVELENGTHS_NM >= 450) & (WAVELENGTHS_NM <= 650)
    w, a, st, g = (out[k][..., vis].astype(np.float64) for k in ("weight", "alpha", "sigma_t", "g"))
    a_c = np.minimum(a, rt.ALPHA_TABLE_MAX)
    light = w * rt.reflectance("model", a_c, np.clip(g, 0.0, rt.G_TABLE_MAX))
    length = 1.0 / (st * np.sqrt(3.0 * (1.0 - a_c) * (1.0 - a_c * g)))
    return {"alpha": (w * a).sum(1).mean(-1), "sigma_t": (w * st).sum(1).mean(-1),
            "sigma_a": (w * (1.0 - a) * st).sum(1).mean(-1),
            "translucency": ((light * length).sum(1) / light.sum(1)).mean(-1)}


def _ranks(x):
    return np.argsort(np.argsort(x)).astype(float)


def test_physical_trends_over_skin_tones_darker_means_lower_albedo_higher_sigma_t():
    """The paper's trend (§6, its parameters pooled over subjects): darker skin -> lower visible albedo
    and higher sigma_t, i.e. light that travels less far.  Tones drawn as the validation split draws them
    (uniform in the biophysical box), ordered by the luminance Y of their decoded reflectance under D65.
    Per luminance decile, from light to dark, the medians of the albedo fall, of sigma_a rise and of the
    translucency length (``_visible_means``: what sets the width of the reflected profile, and what the
    Cycles collapse turns into the radius) fall at every step; sigma_t rises at every step darker than
    the lightest two deciles (Y < ~0.05), where it levels off (the lightest steps stay within 5 %): there
    the two-layer Monte Carlo itself asks for no rise (``python -m training.validate.trends``;
    docs/research/training.md, "Physical trends").  Over all tones the rank correlation with luminance is
    strong (|rho| > 0.85 for
    alpha, sigma_a and sigma_t: measured 0.88-0.99; > 0.8 for the translucency length, measured 0.84 on
    the shipped decoder: at equal luminance it also varies with the blood and the epidermis).

    Not tested: the weight-averaged mean free path sum_k w_k / sigma_t_k.  The rebuilt decoder gives dark
    tones a low-albedo component of long free path that is picked often and reflects little (its mean
    free path rises from 0.08 to 0.25 mm over the first eight deciles); the light-weighted translucency
    length falls from 0.32 to 0.05 mm over all ten."""
    rng = np.random.default_rng(7)
    lo, hi = (np.array([r[i] for r in PARAM_RANGES.values()]) for i in (0, 1))
    p = (lo + (hi - lo) * rng.random((3000, 5))).astype(np.float32)
    out = dict(zip(DEC_OUT, _session("skin_decoder.onnx").run(list(DEC_OUT), {"biophysical": p}), strict=True))
    lum = spectrum_to_linear_srgb(out["reflectance"].astype(np.float64), "D65") @ SRGB_LUMINANCE
    m = _visible_means(out)
    deciles = np.array_split(np.argsort(lum)[::-1], 10)  # light to dark
    assert np.median(lum[deciles[2]]) < 0.06
    for name, darker_is_higher, strict_from, rho_min in (("alpha", False, 0, 0.85), ("sigma_a", True, 0, 0.85),
                                                          ("sigma_t", True, 2, 0.85), ("translucency", False, 0, 0.8)):
        medians = np.array([np.median(m[name][d]) for d in deciles])
        step = np.diff(medians) * (1 if darker_is_higher else -1)  # > 0: the trend holds at that step
        assert np.all(step[strict_from:] > 0), (name, medians)
        assert np.all(step[:strict_from] > -0.05 * medians[1:strict_from + 1]), (name, medians)
        rho = np.corrcoef(_ranks(lum), _ranks(m[name]))[0, 1]
        assert (rho < -rho_min) if darker_is_higher else (rho > rho_min), (name, rho)


def test_physical_trends_along_melanin_and_skin_colours():
    """Along a melanin sweep through the decoder (other parameters fixed) and along light-to-dark skin
    colours through the inversion: lower visible albedo and higher sigma_a = (1 - alpha) sigma_t at every
    step; sigma_t rises at every step from f_mel 0.05 on.

    Below f_mel ~0.05 sigma_t of the decoder (and of the fits it learns from) falls as melanin rises, and
    so does that of the homogeneous medium equivalent to the Monte Carlo itself (the K = 1 medium with the
    same R and median reflected radius: 195 -> 161 cm^-1 from f_mel 0.002 to 0.08, then up to 253 at
    0.3; ``python -m training.validate.trends``, docs/validation/trends.json): melanin in a thin
    epidermis lowers R more than it narrows the profile, and a homogeneous medium whose albedo drops
    that far narrows more, in mean free paths, so its mean free path must grow to keep the width."""
    f_mel = np.array([0.002, 0.01, 0.03, 0.05, 0.08, 0.15, 0.3, 0.45], np.float32)
    p = np.stack([f_mel] + [np.full_like(f_mel, v) for v in (0.03, 0.012, 0.75, 0.7)], 1)
    m = _visible_means(dict(zip(DEC_OUT, _session("skin_decoder.onnx").run(list(DEC_OUT), {"biophysical": p}),
                                strict=True)))
    assert np.all(np.diff(m["alpha"]) < 0) and np.all(np.diff(m["sigma_a"]) > 0), m
    assert np.all(np.diff(m["sigma_t"][f_mel >= 0.05]) > 0), m["sigma_t"]
    rgb = np.array([[0.6, 0.42, 0.33], [0.45, 0.3, 0.22], [0.3, 0.18, 0.12], [0.15, 0.08, 0.05],
                    [0.06, 0.03, 0.02]], np.float32)
    out = dict(zip(INV_OUT, _session("skin_inversion.onnx").run(list(INV_OUT), {"albedo_rgb": rgb}), strict=True))
    m = _visible_means(out)
    assert np.all(np.diff(m["alpha"]) < 0) and np.all(np.diff(m["sigma_a"]) > 0), m
    assert np.all(np.diff(out["biophysical"][:, 0]) > 0)  # and more melanin
