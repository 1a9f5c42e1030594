"""``python -m training simulate``: the two-layer skin model of one tone at all 376 wavelengths (SPEC §2).

Epidermis of thickness t_epi over a semi-infinite dermis, n = 1.4, air above, diffuse illumination.
``--method direct`` walks the absorbing medium; ``--method reweighted`` walks it without absorption
once and weights each reflected photon by exp(-mua_epi L_epi - mua_derm L_derm) (same estimand).

Example::

    python -m training simulate --tone 0.1 0.02 0.01 0.75 0.9 --photons 20000 --out runs/tone.npz
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM
from training.sim.transport import simulate, simulate_records
from training.skin.tissue import skin_medium

#: Collision-count roulette of the absorption-free walks (see WalkConfig), in collisions / (1 - g).
REWEIGHT_PATH_C = 32.0


def reweighted(tone: np.ndarray, photons: int, seed: int, device: str, compile_) -> dict[str, np.ndarray]:
    """R_d, its standard error and the profile by absorption reweighting of one absorption-free run."""
    free = skin_medium(tone, absorbing=False)
    absorbing = skin_medium(tone, absorbing=True)
    g_mean = float(free.g.mean())
    rec = simulate_records(free, photons, seed=seed, device=device, path_roulette_n0=REWEIGHT_PATH_C / (1 - g_mean),
                           compile=compile_)
    refl = rec.kind == 1
    mua = absorbing.mua.numpy()  # (2, W)
    ch = rec.ch[refl]
    w = rec.w[refl] * np.exp(-mua[0, ch] * rec.path_cm[refl, 0] - mua[1, ch] * rec.path_cm[refl, 1])
    n_ch = free.n_channels
    nb = R_EDGES_CM.size  # 512 bins + overflow
    b = np.clip(np.searchsorted(R_EDGES_CM, rec.r_cm[refl], side="right") - 1, 0, nb - 1)
    s1 = np.bincount(ch, weights=w, minlength=n_ch)
    s2 = np.bincount(ch, weights=w * w, minlength=n_ch)
    p1 = np.bincount(ch * nb + b, weights=w, minlength=n_ch * nb).reshape(n_ch, nb)
    mean = s1 / photons
    se = np.sqrt(np.clip(s2 / photons - mean**2, 0, None) / max(photons - 1, 1))
    area = math.pi * np.diff(R_EDGES_CM**2)
    return {"R_d": mean, "R_d_stderr": se, "profile": p1[:, :-1] / photons / area}


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m training simulate",
                                description="Monte Carlo of one skin tone at all 376 wavelengths -> .npz.")
    p.add_argument("--tone", nargs=5, type=float, required=True,
                   metavar=("F_MEL", "F_BLOOD", "T_EPI", "SO2", "B_MEL"), help="biophysical vector (t_epi in cm)")
    p.add_argument("--photons", type=int, required=True, help="photons per wavelength")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--method", choices=("direct", "reweighted"), default="direct")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    p.add_argument("--compile", choices=("auto", "on", "off"), default="auto")
    p.add_argument("--no-progress", action="store_true")
    return p


def main(argv: list[str]) -> int:
    """Run the command; returns the exit status (2 for bad input)."""
    args = _parser().parse_args(argv)
    compile_ = {"auto": "auto", "on": True, "off": False}[args.compile]
    try:
        tone = np.asarray(args.tone, dtype=np.float64)
        if args.photons < 2:
            raise ValueError("--photons must be >= 2")
        if args.method == "direct":
            r = simulate(skin_medium(tone), args.photons, seed=args.seed, device=args.device,
                         progress=not args.no_progress, compile=compile_)
            res = {"R_d": r.R_d, "R_d_stderr": r.R_d_stderr, "profile": r.profile}
        else:
            res = reweighted(tone, args.photons, args.seed, args.device, compile_)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    np.savez(args.out, wavelength_nm=np.array(WAVELENGTHS_NM), r_edges_cm=np.array(R_EDGES_CM), tone=tone,
             photons=np.int64(args.photons), method=args.method, **res)
    return 0
