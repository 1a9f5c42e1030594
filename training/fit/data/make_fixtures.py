"""Generate one Monte Carlo fixture of the fit benchmark (see README.md in this folder).

usage: python training/fit/data/make_fixtures.py NAME F_MEL F_BLOOD T_EPI SO2 B_MEL PHOTONS
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import torch

from exporters.constants import WAVELENGTHS_NM
from training.sim.tissue import skin_medium
from training.sim.transport import simulate

#: Every 25th wavelength of the 376-sample grid: 250, 300, ..., 1000 nm (16 wavelengths).
WAVELENGTH_INDEX = np.arange(0, 376, 25)


def main(argv: list[str]) -> int:
    name, tone, photons = argv[0], [float(x) for x in argv[1:6]], int(argv[6])
    torch.set_num_threads(1)
    idx = WAVELENGTH_INDEX
    sub = skin_medium(tone).select_channels(idx)
    t0 = time.time()
    res = simulate(sub, photons, seed=7)
    print(name, f"{time.time() - t0:.0f} s", res.R_d.round(4))
    np.savez_compressed(
        Path(__file__).parent / f"mc_{name}.npz",
        wavelength_nm=WAVELENGTHS_NM[idx],
        R_d=res.R_d,
        R_d_stderr=res.R_d_stderr,
        r_edges_cm=res.r_edges_cm,
        profile=res.profile,
        tone=np.array(tone),
        photons=res.photons,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
