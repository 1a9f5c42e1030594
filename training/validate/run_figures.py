"""The figures of a validation run (``training.validate.figures`` draws them) from its ground truth, renders,
fits and Table 1: what goes into each, for the representative tones.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM
from training.validate import figures
from training.validate import gate as G
from training.validate import metrics as M
from training.validate.assemble import mc_target
from training.validate.record import GateRecord

if TYPE_CHECKING:
    from training.validate.run import RunContext

#: Wavelengths of the cross-section figure (nm; the nearest validation wavelength is shown).
CROSS_SECTION_NM = (250, 350, 450, 550, 650, 750, 850, 1000)
#: Tones of the profile heat maps (those present are used).
HEAT_TONES = ("R01", "R05", "R09", "R10")


def write_figures(ctx: RunContext, renders: list[dict], fits: dict, dec_full: dict[str, np.ndarray],
                  gate: GateRecord) -> None:
    """The four figures of the run (``run.OUTPUTS``) into ``ctx.opts.out``: the K progression of the edge images,
    the decoder's spectral parameters (``dec_full``: (T, K, 376) arrays), the ground truth's cross-sections and
    its reflectance with the fits' profiles."""
    opts, lut, tones, gt = ctx.opts, ctx.lut, ctx.tones, ctx.gt
    wl_val, wl_r, col_r = ctx.wl_val, ctx.wl_r, ctx.col_r
    wl = WAVELENGTHS_NM[wl_r]
    rep = [i for i, k in enumerate(tones.kinds) if k == "representative"] or list(range(len(tones.names)))
    x = M.edge_positions_cm()
    edge = []
    for i in rep:
        g_r = gt["R_d"][i][col_r]
        cells = [M.linear_srgb(M.edge_exitance(gt["profile"][i][col_r].astype(np.float64), g_r, x), wl)]
        for r in G.ROWS:
            rend = renders[i][r]
            cells.append(M.linear_srgb(M.edge_exitance(rend["profile"].astype(np.float64), rend["R_d"], x), wl))
        edge.append(np.stack(cells))  # (rows, P, 3)
    edge_rgb = np.stack(edge, axis=1)  # (rows, tones, P, 3)
    de, de_edge = np.zeros(edge_rgb.shape[:2]), np.zeros(edge_rgb.shape[:2])
    per_tone = gate.per_tone
    for j, i in enumerate(rep):
        for r_i, r in enumerate(G.ROWS):
            de[r_i + 1, j] = per_tone[r][tones.names[i]].delta_e
            de_edge[r_i + 1, j] = per_tone[r][tones.names[i]].delta_e_edge
    names = [tones.names[i] for i in rep]
    figures.k_progression(opts.out / "fig_k_progression.png", names, ["MC ground truth"] +
                          [G.ROW_LABELS[r].replace(" (", "\n(") for r in G.ROWS], edge_rgb, de, de_edge)
    figures.spectral_parameters(opts.out / "fig_spectral_parameters.png", WAVELENGTHS_NM, dec_full["alpha"],
                                dec_full["sigma_t"], dec_full["weight"],
                                f"skin_decoder.onnx on the true p of the {len(tones.names)} gate tones: median and IQR")
    cols = [int(np.argmin(np.abs(WAVELENGTHS_NM[wl_val] - w))) for w in CROSS_SECTION_NM]
    cols = list(dict.fromkeys(cols))
    figures.cross_sections(opts.out / "fig_cross_sections.png", names, WAVELENGTHS_NM[wl_val][cols],
                           gt["profile"][rep][:, cols].astype(np.float64))
    heat = [i for i in rep if tones.names[i] in HEAT_TONES] or rep[:1]
    fit_prof = {}
    for k in (1, 3):
        arr = np.zeros((len(tones.names), wl_val.size, R_EDGES_CM.size - 1))
        for i in heat:
            arr[i] = lut_profile(lut, G.fit_params(fits[tones.names[i]], k, wl_val))
        fit_prof[f"K={k}"] = arr
    srgb = np.array([gate.ground_truth[n].srgb for n in names])
    used = np.zeros((len(rep), wl_val.size, R_EDGES_CM.size - 1), bool)  # the bins the fitter's loss uses
    for j, i in enumerate(rep):
        if i in heat:
            used[j] = mc_target(lut, gt, i, np.arange(wl_val.size), opts.config.gt_photons).mask.numpy() > 0
    from exporters.colorimetry import srgb_encode

    figures.reflectance_and_profiles(opts.out / "fig_reflectance_profiles.png", WAVELENGTHS_NM[wl_val], names,
                                     gt["R_d"][rep], srgb_encode(srgb), [rep.index(i) for i in heat],
                                     gt["profile"][rep].astype(np.float64), used,
                                     {k: v[rep] for k, v in fit_prof.items()})


def lut_profile(lut, params: G.Params) -> np.ndarray:
    """Absolute profile sum_k w_k R_k P_k (W, 512) cm^-2 of a mixture through the LUT (paper eq. mixture)."""
    from training.sim.lut_interp import bin_centres

    dt = lut.P.dtype
    r = torch.as_tensor(bin_centres(R_EDGES_CM), dtype=dt)
    a, s, g, w = (torch.as_tensor(v.T, dtype=dt) for v in (params.alpha, params.sigma_t, params.g, params.weight))
    p = lut.profile(r, a, g, s)  # (W, K, M)
    return ((w * lut.reflectance(a, g))[..., None] * p).sum(1).numpy()
