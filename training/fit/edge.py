"""How many fits sit at the LUT's last albedo, and what they carry: the MC fixture problems fitted through a
table loaded as built (edge held) and extended to albedo 1 (``training.sim.lut_extend``).

    python -m training.fit.edge --lut data/lut_paper.npz [--out edge.json]

Problems: the fit benchmark's Monte Carlo fixtures (tones R02 and R08 at 16 wavelengths, 50,000 photons;
``training/fit/data``), fitted by the default schedule (LM, K = 1, 2, 3).  Per K: components at or beyond
the file's last albedo, the share of the mixture's light they carry (v_k = w_k R_k / sum_j w_j R_j), and the
mean joint loss, shape RMSE and |dR|/R.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from training.fit.optimize import fit_schedule
from training.fit.problems import bench_problems
from training.sim.lut_interp import LookupTables


def edge_stats(lut_path: Path, extend: bool) -> dict:
    """Fit the fixture problems through the table (extended or not); statistics per K (module docstring)."""
    with np.load(lut_path) as d:
        last = float(d["albedo"][-1])
    t0 = time.perf_counter()
    lut = LookupTables.load(lut_path, extend_albedo=extend)
    pr = bench_problems(quick=False)
    fits = fit_schedule(lut, pr["profile"], pr["R"], pr["edges"], pr["photons"], pr["g_init"], ks=(1, 2, 3))
    out: dict = {"extended": lut.albedo_extended, "file_last_albedo": last, "problems": int(pr["R"].numel()),
                 "seconds": time.perf_counter() - t0}
    for k, f in fits.items():
        a, w = f.mixture.alpha, f.mixture.w
        rk = lut.reflectance(a, f.mixture.g)
        v = w * rk / (w * rk).sum(-1, keepdim=True)
        edge = a >= last * (1 - 1e-12)
        out[f"K{k}"] = {
            "components": int(a.numel()), "at_or_beyond_edge": int(edge.sum()),
            "problems_with_edge": int(edge.any(-1).sum()),
            "light_share_at_edge_mean": float((v * edge).sum(-1).mean()),
            "light_share_at_edge_max": float((v * edge).sum(-1).max()),
            "one_minus_alpha_at_edge": sorted({float(f"{x:.2e}") for x in (1 - a[edge]).tolist()}),
            "joint_mean": float(f.joint.mean()), "shape_rmse_mean": float(f.shape_rmse.mean()),
            "refl_rel_err_mean": float(f.refl_rel_err.abs().mean()),
        }
    return out


def main(argv: list[str] | None = None) -> int:
    """Print (and with --out write) the statistics held vs extended as JSON."""
    p = argparse.ArgumentParser(prog="python -m training.fit.edge", description=__doc__.splitlines()[0])
    p.add_argument("--lut", type=Path, required=True)
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    res = {"held": edge_stats(args.lut, False), "extended": edge_stats(args.lut, True)}
    text = json.dumps(res, indent=1)
    print(text)
    if args.out:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
