"""Benchmarks of the mixture fitter: our Levenberg-Marquardt vs the paper's Adam schedule, same problems.

Problems: Monte Carlo profiles of two skin tones (training/fit/data/mc_*.npz: the project's simulator,
16 wavelengths 250-1000 nm each, 50k photons; how they were made is in training/fit/data/README.md).
LUT: the file named by $SKIN_SSS_LUT if set (the MC tables of ``python -m training lut``), otherwise the
diffusion-dipole table of training/sim/dipole.py on a 1e-3..1e4 mfp radial grid (both from
``training.fit.problems``) (a stand-in: the
comparison of optimisers is on identical problems either way, but the absolute losses depend on it).

With $SKIN_SSS_DATASET (a dataset folder) a further row times a chunk of its validation tones fitted as
``fit --dataset`` does (anchors + warm starts) against the full schedule at every wavelength.

Quick mode: the dark tone only, every third of its wavelengths, K = 1 and 2 (the paper's K = 3 stage
alone is 10,000 Adam steps).  Both methods run the same schedule from the same start, batched over
all problems in one call, on one CPU thread.  Reported per (tone, wavelength): wall time up to and
including each K, and the mean joint loss reached; "reached" counts the problems where LM's joint
loss is within 1 % (or 1e-3) of the paper schedule's.  The paper's schedule: Adam lr 1e-2 with cosine
decay, K=1 1,000 + 1,000 steps (shape only, then joint; the paper does not give these), K=2 3,000
steps, K=3 10,000 steps.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import torch

from exporters.constants import anisotropy
from training.fit.optimize import fit_schedule
from training.fit.problems import bench_lut, bench_problems
from training.sim.lut_interp import LookupTables


def _run(lut, pr, method, ks):
    t0 = time.perf_counter()
    fits = fit_schedule(lut, pr["profile"], pr["R"], pr["edges"], pr["photons"], pr["g_init"], ks=ks, method=method)
    return fits, time.perf_counter() - t0


def dataset_chunk_row(lut: LookupTables, lut_note: str, quick: bool) -> dict | None:
    """Fitting a dataset chunk as ``fit --dataset`` does: anchors every 12th fitted wavelength + warm starts
    vs the full schedule at every wavelength, same problems.  Needs $SKIN_SSS_DATASET (a dataset folder
    with validation.h5); None without it."""
    from training.fit.dataset import fit_tones

    path = os.environ.get("SKIN_SSS_DATASET")
    if not path or not (Path(path) / "validation.h5").is_file():
        return None
    import h5py

    T, stride = (4, 8) if quick else (8, 4)
    with h5py.File(Path(path) / "validation.h5", "r") as f:
        widx = np.arange(0, f["R_d"].shape[1], stride)
        prof, R, se = (torch.tensor(f[name][:T][:, widx], dtype=torch.float64)
                       for name in ("profile", "R_d", "profile_stderr"))
        edges, photons, wl = torch.tensor(f["r_edges_cm"][:]), float(f.attrs["photons"]), f["wavelength_nm"][:][widx]
    g0 = torch.tensor(anisotropy(wl))
    res = {}
    for every in (12, 0):
        t0 = time.perf_counter()
        fits = fit_tones(lut, prof, R, se, edges, photons, g0, (1, 2, 3), anchor_every=every)
        res[every] = (time.perf_counter() - t0, fits)
    n = T * len(widx)
    (t_w, w), (t_f, full) = res[12], res[0]
    return {
        "workload": f"fit a dataset chunk, K=1,2,3, per (tone, wavelength): {T} validation tones x {len(widx)} "
                    "wavelengths, 1 thread",
        "ours": f"{1e3 * t_w / n:.0f} ms (anchors every 12th wavelength, warm starts between)",
        "anchor": f"{1e3 * t_f / n:.0f} ms (full schedule at every wavelength)",
        "ratio": f"{t_f / t_w:.1f}x",
        "error": "mean shape RMSE K=1/2/3 " + "/".join(f"{float(w[k]['shape_rmse'].mean()):.4f}" for k in (1, 2, 3))
                 + " vs " + "/".join(f"{float(full[k]['shape_rmse'].mean()):.4f}" for k in (1, 2, 3)),
        "notes": f"{path}; {lut_note}",
    }


def benchmarks(quick: bool) -> list[dict]:
    """Rows for bench/results.md (see module docstring)."""
    n_threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        lut, lut_note = bench_lut()
        pr = bench_problems(quick)
        B = pr["profile"].shape[0]
        ks = (1, 2) if quick else (1, 2, 3)  # quick: skip the 10,000-step K = 3 Adam stage
        ours, t_ours = _run(lut, pr, "lm", ks)
        paper, t_paper = _run(lut, pr, "paper", ks)
        chunk = dataset_chunk_row(lut, lut_note, quick)
    finally:
        torch.set_num_threads(n_threads)
    rows = []
    for k in ks:
        o, a = ours[k], paper[k]
        reached = (o.joint <= a.joint * 1.01 + 1e-3).sum().item()
        ms_o, ms_a = 1e3 * o.seconds / B, 1e3 * a.seconds / B
        rows.append(
            {
                "workload": f"fit K={k} ({4 * k - 1} params) per (tone, wavelength), stages up to K={k}, 1 thread",
                "ours": f"{ms_o:.0f} ms, joint loss {o.joint.mean():.4f} (LM, {o.work:.0f} evals)",
                "anchor": f"{ms_a:.0f} ms, joint loss {a.joint.mean():.4f} (paper Adam, {a.work:.0f} evals)",
                "ratio": f"{ms_a / ms_o:.1f}x faster ({a.work / o.work:.1f}x fewer evals)",
                "error": (
                    f"LM reaches the paper's loss on {reached}/{B}; shape RMSE {o.shape_rmse.mean():.3f} vs "
                    f"{a.shape_rmse.mean():.3f}, |dR|/R {o.refl_rel_err.mean():.3f} vs {a.refl_rel_err.mean():.3f}"
                ),
                "notes": f"{B} MC problems ({', '.join(pr['names'])}); {lut_note}; batched in one call",
            }
        )
    rows.append(
        {
            "workload": f"fit K={','.join(map(str, ks))} schedule, all {B} problems (total wall time)",
            "ours": f"{t_ours:.1f} s",
            "anchor": f"{t_paper:.1f} s",
            "ratio": f"{t_paper / t_ours:.1f}x",
            "error": "",
            "notes": "includes the shared K=1 initial search",
        }
    )
    if chunk is not None:
        rows.append(chunk)
    return rows


if __name__ == "__main__":
    import sys

    for row in benchmarks(quick="--quick" in sys.argv):
        print(row)
