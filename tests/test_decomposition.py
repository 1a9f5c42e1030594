"""The K = 3 decomposition statistics (training.validate.decomposition) on mixtures whose answers are known by
construction, and the command on the shipped model (real onnxruntime, --quick)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from exporters.constants import WAVELENGTHS_NM
from training.validate import decomposition as D

# The 2 nm grid 250..1000 nm holds 75 UV wavelengths (250..398), 50 blue (400..498) and 151 NIR (700..1000).
N_UV, N_BLUE, N_NIR, N_ALL = 75, 50, 151, 376


def _constructed(rng: np.random.Generator, bimodal: bool = True) -> dict[str, np.ndarray]:
    """Four tones, K = 3.  Output 0 is the low-albedo medium (alpha 0.3, weight 0.35), outputs 1 and 2 the
    high ones (alpha 0.97 and 0.95, weights 0.4 and 0.25).  The low one's sigma_t is 5 cm^-1 (else 50):
    tone 0 everywhere, tone 1 in the UV, tone 2 in the UV and blue, tone 3 nowhere.  Its g is 0 (tones 0, 1)
    and 0.87 (tones 2, 3) with a 0.01 spread, or 0.6 +- 0.05 for all (``bimodal=False``)."""
    n, w = 4, N_ALL
    wl = WAVELENGTHS_NM
    uv, blue = wl < 400, (wl >= 400) & (wl < 500)
    alpha = np.empty((n, 3, w))
    alpha[:, 0], alpha[:, 1], alpha[:, 2] = 0.3, 0.97, 0.95
    weight = np.empty_like(alpha)
    weight[:, 0], weight[:, 1], weight[:, 2] = 0.35, 0.4, 0.25
    sigma_t = np.full_like(alpha, 50.0)
    for tone, where in enumerate((np.ones(w, bool), uv, uv | blue, np.zeros(w, bool))):
        sigma_t[tone, 0, where] = 5.0
    g = np.full_like(alpha, 0.8)
    if bimodal:
        g[:, 0] = np.array([0.0, 0.0, 0.87, 0.87])[:, None] + 0.01 * rng.standard_normal((n, w))
    else:
        g[:, 0] = 0.6 + 0.05 * rng.standard_normal((n, w))
    return {"alpha": alpha, "sigma_t": sigma_t, "g": g, "weight": weight}


def test_statistics_of_a_constructed_mixture():
    stats = D.decomposition_stats(_constructed(np.random.default_rng(0)))
    assert [c["output"] for c in stats["components"]] == [1, 2, 0]
    assert stats["high_median_alpha"] == pytest.approx(0.96)  # median of equal numbers of 0.97 and 0.95
    assert stats["low_median_alpha"] == pytest.approx(0.3)
    assert stats["low_median_weight"] == pytest.approx(0.35)
    assert stats["lowest_per_sample"]["median_alpha"] == pytest.approx(0.3)
    b = stats["boundary_mass"]
    assert b["all"] == pytest.approx((N_ALL + N_UV + N_UV + N_BLUE) / (4 * N_ALL))
    assert b["bands"] == pytest.approx({"UV": 3 / 4, "blue": 2 / 4, "NIR": 1 / 4})
    assert b["concentration"] == pytest.approx((3 / 4 + 2 / 4) / 2 / (1 / 4))
    assert b["concentration_pooled"] == pytest.approx((3 * N_UV + 2 * N_BLUE) / (4 * (N_UV + N_BLUE)) / (1 / 4))
    g = stats["g_low"]
    assert g["bimodal"] and len(g["modes"]) == 2
    assert g["modes"] == pytest.approx([0.0, 0.87], abs=0.02)
    verdicts = {row["claim"]: row["verdict"] for row in D.comparison(stats)}
    assert verdicts["high-alpha components (C1, C2): median alpha"] == "agree"
    assert verdicts["C3: g bimodal, modes"] == "agree"
    assert verdicts["low-alpha component (C3): median alpha"] == "agree"  # absorbs 0.70 vs the paper's 0.66
    assert verdicts["C3: share of mass at sigma_t < 10 cm^-1, UV"] == "partly"  # 0.75 vs 0.307: 2.4x
    assert verdicts["C3: concentration mean(UV, blue) / NIR"] == "agree"  # 2.5 vs 2.7


def test_a_unimodal_g_has_one_mode():
    stats = D.decomposition_stats(_constructed(np.random.default_rng(1), bimodal=False))
    assert stats["g_low"]["modes"] == pytest.approx([0.6], abs=0.02)
    assert not stats["g_low"]["bimodal"]
    assert {r["claim"]: r["verdict"] for r in D.comparison(stats)}["C3: g bimodal, modes"] == "disagree"


def test_boundary_shares_weigh_by_mass():
    wl = np.array([300.0, 450.0, 800.0])  # one UV, one blue, one NIR wavelength
    sigma_t = np.array([[5.0, 50.0, 5.0], [5.0, 5.0, 50.0]])
    mass = np.array([[3.0, 1.0, 1.0], [1.0, 1.0, 3.0]])
    s = D.boundary_shares(sigma_t, mass, wl)
    assert s["bands"] == pytest.approx({"UV": 1.0, "blue": 0.5, "NIR": 0.25})
    assert s["all"] == pytest.approx((3 + 1 + 1 + 1) / 10)
    assert s["concentration"] == pytest.approx(0.75 / 0.25)
    none_nir = D.boundary_shares(np.array([[5.0, 5.0, 50.0]]), np.ones((1, 3)), wl)
    assert none_nir["concentration"] is None  # 1.0 / 0: undefined, not inf


def test_bimodality_coefficient_of_known_distributions():
    rng = np.random.default_rng(2)
    assert D.bimodality_coefficient(rng.uniform(size=200_000)) == pytest.approx(1 / 1.8, abs=0.01)  # 5/9
    assert D.bimodality_coefficient(rng.standard_normal(200_000)) == pytest.approx(1 / 3, abs=0.01)


def test_bad_mixtures_are_refused():
    mix = _constructed(np.random.default_rng(3))
    mix["g"][0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="'g' contains NaN"):
        D.decomposition_stats(mix)
    one = {f: v[:, :1] for f, v in _constructed(np.random.default_rng(3)).items()}
    with pytest.raises(ValueError, match="K >= 2"):
        D.decomposition_stats(one)


def _finite(x) -> bool:
    if isinstance(x, dict):
        return all(_finite(v) for v in x.values())
    if isinstance(x, list):
        return all(_finite(v) for v in x)
    return not isinstance(x, float) or math.isfinite(x)


def test_quick_command_on_the_shipped_model(tmp_path, capsys):
    assert D.main(["--out", str(tmp_path), "--quick"]) == 0
    for name in D.FILES.values():
        assert (tmp_path / name).stat().st_size > 0, name
    result = json.loads((tmp_path / D.FILES["json"]).read_text())
    assert _finite(result)
    assert set(result["sets"]) == {"validation", "representative", "measured", "subjects"}
    for s in result["sets"].values():
        st = s["stats"]
        assert st["k"] == 3 and 0 < st["low_median_alpha"] <= st["high_median_alpha"] <= 1
        assert 0 <= st["boundary_mass"]["all"] <= 1
    assert str(tmp_path) not in (tmp_path / D.FILES["md"]).read_text()  # no absolute path recorded
    before = (tmp_path / D.FILES["json"]).read_bytes()
    assert D.main(["--out", str(tmp_path), "--quick"]) == 2  # nothing overwritten without --overwrite
    assert "--overwrite" in capsys.readouterr().err
    assert (tmp_path / D.FILES["json"]).read_bytes() == before
