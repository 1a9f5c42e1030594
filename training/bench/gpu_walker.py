"""The GPU check of the per-packet kernel (``python -m training bench --only training.bench.gpu_walker``): run it
where a CUDA GPU is at hand; without one it writes a row saying so.

The semi-infinite medium of ``training.bench.walker`` (albedo 0.99, g 0.9, n 1.4, normal incidence) at 10^6
photons: engine "numba-cuda" (the CPU kernel's source, one GPU thread per packet) against the vectorised torch
step on the same GPU and, when the package ``pmcx`` (MCX, the field's standard GPU Monte Carlo) is installed,
against MCX on a 1 mm voxel half-space of the same optics in the same run.  Each engine is run once to compile
and once timed.
"""

from __future__ import annotations

import math
import time

import numpy as np
import torch

from training.bench.walker import N_SEMI, SEMI
from training.sim.medium import LayeredMedium
from training.sim.transport import simulate


def _ours(engine: str, photons: int) -> tuple[float, float]:
    mua, mus, g = SEMI
    m = LayeredMedium([[mua]], [[mus]], [[g]], [math.inf], n_medium=N_SEMI)
    simulate(m, 10_000, illumination="normal", device="cuda", engine=engine, r_edges_cm=None, seed=0)
    t0 = time.perf_counter()
    r = simulate(m, photons, illumination="normal", device="cuda", engine=engine, r_edges_cm=None, seed=1)
    torch.cuda.synchronize()
    return photons / (time.perf_counter() - t0), float(r.R_d[0])


def _mcx(photons: int) -> tuple[float, float] | None:
    try:
        import pmcx
    except ImportError:
        return None
    mua, mus, g = SEMI
    cfg = {"nphoton": photons, "vol": np.ones((60, 60, 60), dtype=np.uint8), "tstart": 0, "tend": 5e-9,
           "tstep": 5e-9, "srcpos": [30, 30, 0], "srcdir": [0, 0, 1], "unitinmm": 1.0,
           "prop": [[0, 0, 1, 1], [mua / 10, mus / 10, g, N_SEMI]], "issrcfrom0": 1, "isreflect": 1,
           "issaveref": 1, "isspecular": 0, "autopilot": 1, "gpuid": 1}
    pmcx.run({**cfg, "nphoton": 10_000})
    t0 = time.perf_counter()
    res = pmcx.run(cfg)
    rate = photons / (time.perf_counter() - t0)
    rd = float(np.sum(res["dref"][:, :, 0, 0])) if "dref" in res else float("nan")
    return rate, rd


def benchmarks(quick: bool) -> list[dict]:
    """One row per engine, or one row saying that no GPU is at hand."""
    if not torch.cuda.is_available():
        return [{"workload": "GPU walk, semi-infinite albedo 0.99, g 0.9, n 1.4", "ours": "not run",
                 "notes": "no CUDA GPU on this machine"}]
    photons = 1_000_000
    rows = []
    mcx = _mcx(photons)
    anchor = f"MCX (pmcx) {mcx[0]:,.0f} photons/s (R_d {mcx[1]:.4f})" if mcx else "pmcx not installed"
    for engine in ("numba-cuda", "torch"):
        rate, rd = _ours(engine, photons)
        rows.append({"workload": f"GPU walk, semi-infinite albedo 0.99, g 0.9, n 1.4, {photons:,} photons, {engine}",
                     "ours": f"{rate:,.0f} photons/s (R_d {rd:.4f})", "anchor": anchor,
                     "ratio": f"{rate / mcx[0]:.3f}x MCX" if mcx else "",
                     "notes": torch.cuda.get_device_name(0)})
    return rows
