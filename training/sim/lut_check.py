"""The LUT's profile between its simulated g nodes: P(r | albedo, g) at g midpoints against direct walks.

The builder (``training.sim.lut``) simulates G_NODES g values and interpolates the other g columns
(PCHIP along g).  R between nodes is checked against adding-doubling (``training.bench.sim``); P has no
independent solver, so it is checked here against a direct walk of the homogeneous medium at the
midpoint g itself (sigma_t = 1 cm^-1, so cm = mfp; same boundary and illumination as the LUT).

What is compared: the fraction of the profile's energy (inside the table's last edge) in a few radial
bands (``BANDS_MFP``); band fractions average hundreds of bins, so their noise is small and an
interpolation error (a shift of the profile's length scale) shows as a systematic difference.

How the noise is stated: the direct walk's band fraction has standard error se_dir from its per-photon
sums (bins summed in quadrature: each photon lands in one bin, so this slightly overestimates).  The
LUT column comes from the same estimator (implicit capture, weight albedo^n, exact reweighting), so its
per-photon variance is taken equal: se_lut = se_dir sqrt(N_dir / N_lut) (the LUT's collision-count
roulette adds variance only in the long-path tail).  z = (f_lut - f_dir) / hypot(se_lut, se_dir);
|z| < 4 is "within the Monte Carlo noise".
"""

from __future__ import annotations

import math

import numpy as np

from exporters.constants import R_EDGES_MFP
from training.sim.medium import LayeredMedium
from training.sim.transport import simulate

#: Radial bands (mean free paths) of the comparison: each spans about half a decade of the profile.
BANDS_MFP: tuple[float, ...] = (0.0, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, math.inf)


def band_fractions(profile: np.ndarray, r_edges: np.ndarray, bands: tuple[float, ...] = BANDS_MFP) -> np.ndarray:
    """Fraction of sum(profile * area) in each band: ``profile`` (..., NB) per unit area, ``r_edges`` (NB + 1,).

    A bin belongs to the band holding its inner edge.  Returns (..., len(bands) - 1), summing to 1.
    """
    energy = profile * (math.pi * np.diff(r_edges**2))
    which = np.searchsorted(np.asarray(bands), r_edges[:-1], side="right") - 1
    out = np.stack([energy[..., which == b].sum(-1) for b in range(len(bands) - 1)], axis=-1)
    return out / out.sum(-1, keepdims=True)


def band_stderr(profile: np.ndarray, stderr: np.ndarray, r_edges: np.ndarray,
                bands: tuple[float, ...] = BANDS_MFP) -> np.ndarray:
    """Standard error of ``band_fractions`` from per-bin standard errors (bins in quadrature, total held)."""
    energy = profile * (math.pi * np.diff(r_edges**2))
    se = stderr * (math.pi * np.diff(r_edges**2))
    which = np.searchsorted(np.asarray(bands), r_edges[:-1], side="right") - 1
    out = np.stack([np.sqrt((se[..., which == b] ** 2).sum(-1)) for b in range(len(bands) - 1)], axis=-1)
    return out / energy.sum(-1, keepdims=True)


def direct_profiles(albedo: np.ndarray, g: np.ndarray, photons: int, seed: int = 0, max_steps: int = 100_000,
                    compile: bool | str = "auto"):
    """Direct walks of the LUT's medium (sigma_t = 1, n = 1.4, diffuse light) at every (albedo, g) pair.

    ``albedo`` and ``g``: (C,) each, one channel per pair; returns ``training.sim.transport.SimResult``
    with profiles on R_EDGES_MFP (cm = mfp at sigma_t = 1).
    """
    a = np.asarray(albedo, dtype=np.float64)
    medium = LayeredMedium.homogeneous(1.0 - a, a, np.asarray(g, dtype=np.float64), n_medium=1.4)
    return simulate(medium, photons, illumination="diffuse", seed=seed, r_edges_cm=R_EDGES_MFP,
                    max_steps=max_steps, compile=compile)


def compare(p_lut: np.ndarray, lut_photons: int, direct, r_edges: np.ndarray = R_EDGES_MFP) -> dict[str, np.ndarray]:
    """Band fractions of LUT profiles ``p_lut`` (C, NB) against ``direct`` (SimResult, C channels).

    Returns f_lut, f_dir, se (combined standard error, module docstring) and z, each (C, n_bands).
    """
    f_lut = band_fractions(p_lut, r_edges)
    f_dir = band_fractions(direct.profile, r_edges)
    se_dir = band_stderr(direct.profile, direct.profile_stderr, r_edges)
    se = se_dir * math.sqrt(1.0 + direct.photons / lut_photons)
    z = np.where(se > 0, (f_lut - f_dir) / np.where(se > 0, se, 1.0), 0.0)
    return {"f_lut": f_lut, "f_dir": f_dir, "se": se, "z": z}


def check_parts(parts, node_index: tuple[int, ...] = (5, 20, 36),
                albedo_targets: tuple[float, ...] = (0.9, 0.99, 0.999), photons: int = 100_000,
                seed: int = 11) -> dict:
    """The check on a built table's simulated node columns (``<lut>.npz.parts``, any subset of nodes done).

    Midpoints between nodes j and j + 1 for j in ``node_index`` (PCHIP over the nodes present, as the
    builder does; nodes j - 1 .. j + 2 must be present), at the table's albedo nodes nearest to
    ``albedo_targets`` (so only g is interpolated).  Returns a JSON-able summary with per-pair z.
    """
    import json
    from pathlib import Path

    from training.sim.lut import _columns_at

    parts = Path(parts)
    man = json.loads((parts / "manifest.json").read_text())
    nodes_all, albedo = np.array(man["g"]), np.array(man["albedo"])
    have = [j for j in range(nodes_all.size) if (parts / f"g_{j:04d}.npz").exists()]
    for j in node_index:
        if not all(k in have for k in range(j - 1, j + 3)):
            raise ValueError(f"{parts}: node {j} needs nodes {j - 1}..{j + 2} built")
    cols = [dict(np.load(parts / f"g_{j:04d}.npz")) for j in have]
    nodes = nodes_all[have]
    mids = np.array([0.5 * (nodes_all[j] + nodes_all[j + 1]) for j in node_index])
    table = _columns_at(cols, nodes, mids, R_EDGES_MFP)
    ia = [int(np.argmin(np.abs(albedo - a))) for a in albedo_targets]
    pairs = [(i, m) for i in ia for m in range(mids.size)]
    direct = direct_profiles(albedo[[i for i, _ in pairs]], mids[[m for _, m in pairs]], photons, seed=seed)
    res = compare(np.stack([table["P"][i, m] for i, m in pairs]), int(man["photons"]), direct)
    rel = np.abs(res["f_lut"] - res["f_dir"]) / np.maximum(res["f_dir"], 1e-300)
    main_band = res["f_dir"] > 0.02  # bands holding >= 2 % of the energy
    return {
        "lut_photons": int(man["photons"]), "direct_photons": int(photons), "seconds": direct.seconds,
        "pairs": [{"albedo": float(albedo[i]), "g": float(mids[m]), "z": np.round(res["z"][k], 2).tolist(),
                   "f_lut": np.round(res["f_lut"][k], 5).tolist(), "f_dir": np.round(res["f_dir"][k], 5).tolist()}
                  for k, (i, m) in enumerate(pairs)],
        "max_abs_z": float(np.abs(res["z"]).max()),
        "max_abs_diff": float(np.abs(res["f_lut"] - res["f_dir"]).max()),
        "max_rel_diff_main_bands": float(rel[main_band].max()),
        "bands_mfp": [str(b) for b in BANDS_MFP],
    }


if __name__ == "__main__":
    import argparse
    import json

    import torch

    ap = argparse.ArgumentParser(description="P(r | albedo, g) at g midpoints of a built LUT vs direct walks.")
    ap.add_argument("--parts", required=True, help="the LUT's <out>.parts folder")
    ap.add_argument("--photons", type=int, default=100_000)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--nodes", default="5,20,36",
                    help="comma-separated node indices j: the midpoint between simulated g nodes j and j + 1 is "
                         "checked (nodes j - 1 .. j + 2 must be built; default 5,20,36, the midpoints 0.111, "
                         "0.414, 0.738 of the paper-scale table; 40,43,45 gives its high g 0.819, 0.879, 0.920)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    nodes = tuple(int(j) for j in args.nodes.split(","))
    print(json.dumps(check_parts(args.parts, node_index=nodes, photons=args.photons, seed=args.seed), indent=1))
