"""Benchmarks of the Monte Carlo engine (collected by ``python -m training bench``).

1. Photon histories per second on the 7-layer skin case at 600 nm (docs/research/monte_carlo.md §4; all layers
   at n = 1.4 because the simulator has one index), normal incidence, vs MCML 1.2.2 measured on this
   machine kind: 19,400 photons/s on one core, ~37,000 on both (anchors: docs/research/monte_carlo.md §4a; MCML
   itself is not run here; ``training.bench.walker`` runs it side by side when it is at hand).  Measured on
   one thread (= one core) of the numba engine, the CPU default.
2. LUT build: a measured batch of g nodes at two photon counts, projected to the paper-scale 800 x 800
   table with 1e6 photons per simulated g node (48 nodes, the other g columns interpolated; cost is
   linear in photons and in nodes; the albedo count only affects the final matrix product), and the
   g-interpolation error against adding-doubling.  Goal: < 1 h on 2 cores.
"""

from __future__ import annotations

import math
import time

import numpy as np
import torch

from training.sim.lut import COLUMN_BATCH, G_NODES, albedo_grid, g_grid, simulate_columns
from training.sim.medium import LayeredMedium
from training.sim.transport import simulate

#: 7-layer skin at 600 nm (Meglinsky & Matcher; GPU-MCML's benchmark): mua, mus (cm^-1), g, d (cm).
SEVEN_LAYER = [
    (0.2, 1000.0, 0.9, 0.002),
    (0.15, 400.0, 0.85, 0.008),
    (0.7, 300.0, 0.8, 0.01),
    (1.0, 350.0, 0.9, 0.008),
    (0.7, 200.0, 0.76, 0.162),
    (1.0, 350.0, 0.95, 0.02),
    (0.3, 150.0, 0.8, 0.59),
]
MCML_1CORE, MCML_2CORE = 19_400.0, 37_000.0


def seven_layer_medium() -> LayeredMedium:
    t = torch.tensor(SEVEN_LAYER, dtype=torch.float64)
    return LayeredMedium(t[:, 0:1], t[:, 1:2], t[:, 2:3], t[:, 3], n_medium=1.4, n_below=1.0)


def _throughput(photons: int, threads: int) -> tuple[float, float, float]:
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        m = seven_layer_medium()
        simulate(m, 2000, illumination="normal", seed=0, threads=1, r_edges_cm=None)  # compile + warm
        r = simulate(m, photons, illumination="normal", seed=1, threads=threads)
    finally:
        torch.set_num_threads(before)
    return photons / r.seconds, float(r.R_d[0]), float(r.R_d_stderr[0])


def _lut_build(photons: int) -> tuple[float, float, float]:
    """Cost of simulating g nodes: (fixed s per batch run, s per 1e6 photons per node, measured s).

    Four nodes of the default 48-node grid (g = 0, 0.32, 0.65, 0.95: the cost grows ~1/(1-g)) walked
    together as one batch, at ``photons`` and 4 x ``photons`` (1 thread, compiled); the difference gives
    the marginal cost per photon, the rest is the tail of the batch's longest walks.  Numba engine, 1 thread.
    """
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        gs = g_grid(G_NODES)[[0, 16, 32, 47]]
        albedo = albedo_grid(800)
        simulate_columns(gs, albedo, 500, threads=1)  # compile + warm
        times = []
        for p in (photons, 4 * photons):
            t0 = time.perf_counter()
            simulate_columns(gs, albedo, p, threads=1)
            times.append(time.perf_counter() - t0)
    finally:
        torch.set_num_threads(before)
    slope = max((times[1] - times[0]) / (3 * photons * gs.size), 0.0)
    fixed = max(times[0] - slope * photons * gs.size, 0.0)
    return fixed, slope * 1e6, sum(times)


def _g_interpolation_error(n_albedo: int) -> tuple[float, float]:
    """Max |R| error of PCHIP along g from the 48 default nodes, at the midpoints, vs adding-doubling.

    Adding-doubling (iadpython, an independent solver) gives R(albedo, g) of the LUT's medium (URU minus
    the boundary's specular part); the max is over ``n_albedo`` albedos in [0.3, 0.9999] and every midpoint.
    One quadrature (16 points) for every g and for the specular part: a change of quadrature along g
    would show up as a step, not as interpolation error.
    """
    import iadpython as iad
    from scipy.interpolate import PchipInterpolator

    def uru(a: float, g: float) -> float:
        return float(iad.Sample(a=a, b=math.inf, g=g, n=1.4, n_above=1.0, n_below=1.0, quad_pts=16).rt()[2])

    specular = uru(0.0, 0.0)
    r = lambda a, g: uru(a, g) - specular  # noqa: E731

    nodes = g_grid(G_NODES)
    mids = 0.5 * (nodes[1:] + nodes[:-1])
    worst, worst_rel = 0.0, 0.0
    for a in 1.0 - np.geomspace(0.7, 1e-4, n_albedo):
        at_nodes = np.array([r(a, g) for g in nodes])
        truth = np.array([r(a, g) for g in mids])
        err = np.abs(PchipInterpolator(nodes, at_nodes)(mids) - truth)
        worst, worst_rel = max(worst, err.max()), max(worst_rel, (err / truth).max())
    return worst, worst_rel


def benchmarks(quick: bool) -> list[dict]:
    """Rows for bench/results.md (see the module docstring)."""
    photons = 50_000 if quick else 200_000  # fewer leave the pool part-empty: overhead, not throughput
    rows = []
    rate1, rd, se = _throughput(photons, 1)
    rows.append({
        "workload": f"7-layer skin @600 nm (n = 1.4 throughout), normal incidence, {photons} photons, 1 core",
        "ours": f"{rate1:,.0f} photons/s (R_d = {rd:.4f} +- {se:.4f})",
        "anchor": f"MCML 1.2.2 (C, gcc -O3), 1 core: {MCML_1CORE:,.0f} photons/s (docs/research/monte_carlo.md §4a)",
        "ratio": f"{rate1 / MCML_1CORE:.2f}x",
        "error": "R_d differs from MCML's 0.5630 by design (one refractive index instead of 1.34-1.53)",
        "notes": "numba engine, 1 thread (compile time excluded), float64 walk and tallies; shared machine",
    })
    lut_photons = 25_000 if quick else 100_000  # the pool must fill (2^18 packets) for a clean slope
    fixed, per_1e6, dt = _lut_build(lut_photons)
    batches = math.ceil(G_NODES / COLUMN_BATCH)
    total_1core = per_1e6 * G_NODES + fixed * batches
    n_albedo = 3 if quick else 12
    err_abs, err_rel = _g_interpolation_error(n_albedo)
    rows.append({
        "workload": f"LUT 800 x 800, 1e6 photons per g ({G_NODES} simulated g nodes, the rest interpolated), "
        "projected",
        "ours": f"{total_1core / 3600:.2f} h on 1 core, ~{total_1core / 7200:.2f} h on 2 (--shard 0/2, 1/2)",
        "anchor": "goal < 1 h on 2 cores; all 800 g columns simulated: "
        f"{(per_1e6 * 800 + fixed * 100) / 7200:.1f} h on 2 cores",
        "ratio": f"{(total_1core / 2) / 3600:.2f}x the goal",
        "error": f"g interpolation (PCHIP, 48 nodes) vs adding-doubling at the 47 midpoints x {n_albedo} "
        f"albedos: max |dR| "
        f"{err_abs:.1e} ({100 * err_rel:.2f} % rel.); albedo reweighting exact, count binning <= 3e-5",
        "notes": f"{per_1e6:.0f} s per 1e6 photons per node (mean of g = 0, 0.32, 0.65, 0.95) + {fixed:.0f} s "
        f"tail per batch of {COLUMN_BATCH}; measured at {lut_photons} and {4 * lut_photons} photons x 4 nodes "
        f"({dt:.0f} s, 1 thread, numba engine, shared machine)",
    })
    return rows


if __name__ == "__main__":
    for row in benchmarks(quick=True):
        print(row)
