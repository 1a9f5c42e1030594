"""The fitter's reference problems: Monte Carlo profiles of two skin tones and the LUT they are fitted through.

Problems: training/fit/data/mc_*.npz (the project's simulator, 16 wavelengths 250-1000 nm each, 50k photons;
how they were made is in training/fit/data/README.md).  LUT: the file named by $SKIN_SSS_LUT if set (the MC
tables of ``python -m training lut``), otherwise the diffusion-dipole table of ``training.sim.dipole`` on a
1e-3..1e4 mfp radial grid (a stand-in).  Used by the fitter's benchmark (``training.bench.fit``), the albedo
edge study (``training.fit.edge``), the coherence study (``training.validate.coherence``) and the tests.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from exporters.constants import anisotropy
from training.sim.dipole import dipole_lut
from training.sim.lut_interp import LookupTables

DATA = Path(__file__).parent / "data"
#: The stand-in table's axes: albedo denser near 1, wide radial range (mfp).
DIPOLE_ALBEDO = np.concatenate([[0.0], 1.0 - np.geomspace(0.95, 1e-5, 60), [1.0]])
DIPOLE_EDGES_MFP = np.concatenate([[0.0], np.geomspace(1e-3, 1e4, 512)])


def bench_lut() -> tuple[LookupTables, str]:
    """The LUT for the benchmark and a line saying which one it is."""
    path = os.environ.get("SKIN_SSS_LUT")
    if path and Path(path).is_file():
        return LookupTables.load(path), f"MC LUT {path}"
    lut = LookupTables.from_arrays(**dipole_lut(albedo=DIPOLE_ALBEDO, r_edges_mfp=DIPOLE_EDGES_MFP))
    return lut, "dipole stand-in LUT (no $SKIN_SSS_LUT)"


def bench_problems(quick: bool) -> dict[str, torch.Tensor]:
    """Stack the MC fixture problems: profile (B, 512), R (B,), edges (513,), photons, g_init (B,)."""
    files = sorted(DATA.glob("mc_*.npz"))
    if quick:
        files = files[-1:]
    prof, R, g0, wl = [], [], [], []
    for f in files:
        with np.load(f) as d:
            sel = slice(None, None, 3) if quick else slice(None)
            prof.append(d["profile"][sel])
            R.append(d["R_d"][sel])
            wl.append(d["wavelength_nm"][sel])
            edges, photons = d["r_edges_cm"], float(d["photons"])
    wl_all = np.concatenate(wl)
    g0 = anisotropy(wl_all)
    return {
        "profile": torch.tensor(np.concatenate(prof)),
        "R": torch.tensor(np.concatenate(R)),
        "edges": torch.tensor(edges),
        "photons": photons,
        "g_init": torch.tensor(g0),
        "names": [f.stem for f in files],
    }
