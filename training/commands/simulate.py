"""``python -m training simulate``: the two-layer skin model of one tone at all 376 wavelengths (docs/contracts.md §2).

Epidermis of thickness t_epi over a semi-infinite dermis, n = 1.4, air above, diffuse illumination.
``--method direct`` walks the absorbing medium; ``--method reweighted`` is the dataset's estimator
(``training.data.reweight``): a walk at a baseline absorption mua0 (here the smaller of the tone's two layers'
absorptions at each wavelength; the walk itself runs at the tone's absorption), each reflected photon weighted by
exp(-(mua_epi - mua0) L_epi - (mua_derm - mua0) L_derm) (same estimand).  Both write docs/contracts.md §2 keys plus
``profile_stderr``.  ``--profile cdf`` resamples the profile through its CDF (``training.sim.resample``;
``profile_stderr`` stays the histogram's).

Example::

    python -m training simulate --tone 0.1 0.02 0.01 0.75 0.9 --photons 20000 --out runs/tone.npz
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from exporters.cli_io import OneLineParser
from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM
from training.commands.options import (
    atomic_file,
    check_biophysical,
    check_output_file,
    command,
    count,
    error_status,
    finite_float,
    require,
)
from training.data.reweight import one_tone
from training.sim.resample import cdf_resample_profile
from training.sim.tissue import skin_medium
from training.sim.transport import PROFILE_ESTIMATORS, simulate


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="python -m training simulate",
                      description="Monte Carlo of one skin tone at all 376 wavelengths -> .npz.")
    p.add_argument("--tone", nargs=5, type=finite_float, required=True,
                   metavar=("F_MEL", "F_BLOOD", "T_EPI", "SO2", "B_MEL"), help="biophysical vector (t_epi in cm)")
    p.add_argument("--photons", type=count, required=True, help="photons per wavelength (>= 2)")
    p.add_argument("--out", type=Path, required=True, help="output file (.npz; replaced if it exists)")
    p.add_argument("--method", choices=("direct", "reweighted"), default="direct")
    p.add_argument("--profile", choices=PROFILE_ESTIMATORS, default=PROFILE_ESTIMATORS[0],
                   help="radial profile estimator: the plain histogram or CDF-based conservative resampling of "
                   "the same tallies (paper §3; `python -m training resampling` compares them)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    p.add_argument("--compile", choices=("auto", "on", "off"), default="auto")
    p.add_argument("--no-progress", action="store_true")
    return p


@command("simulate")
def main(argv: list[str]) -> int:
    """Run the command; returns the exit status (2 for bad input)."""
    args = build_parser().parse_args(argv)
    check_biophysical(args.tone, "--tone")
    require(args.photons >= 2, "--photons must be >= 2 (the standard errors need two photons)")
    check_output_file(args.out, "--out", suffixes=(".npz",))
    compile_ = {"auto": "auto", "on": True, "off": False}[args.compile]
    try:
        tone = np.asarray(args.tone, dtype=np.float64)
        if args.method == "direct":
            r = simulate(skin_medium(tone), args.photons, seed=args.seed, device=args.device,
                         progress=not args.no_progress, compile=compile_)
            res = {"R_d": r.R_d, "R_d_stderr": r.R_d_stderr, "profile": r.profile,
                   "profile_stderr": r.profile_stderr}
        else:
            res = {k: v[0] for k, v in one_tone(tone, args.photons, seed=args.seed, device=args.device,
                                                compile=compile_).items()}
        if args.profile == "cdf":
            res["profile"] = cdf_resample_profile(res["profile"], res["profile_stderr"], np.array(R_EDGES_CM),
                                                  args.photons)
    except ValueError as exc:
        return error_status(exc)
    with atomic_file(args.out) as f:
        np.savez(f, wavelength_nm=np.array(WAVELENGTHS_NM), r_edges_cm=np.array(R_EDGES_CM), tone=tone,
                 photons=np.int64(args.photons), method=args.method, profile_estimator=args.profile, **res)
    return 0
