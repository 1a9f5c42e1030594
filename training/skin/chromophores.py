"""Tabulated chromophore spectra shipped with the package (copies of the team's data files).

``chromophores_250_1000_2nm.csv`` is the convenience table on the project grid derived from the four
source files beside it (their headers give sources, units and terms).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from exporters.constants import WAVELENGTHS_NM

DATA_DIR = Path(__file__).with_name("data")
GRID_TABLE = DATA_DIR / "chromophores_250_1000_2nm.csv"


def read_table(path: Path) -> tuple[list[str], np.ndarray]:
    """Read one of the shipped CSV files: ``#`` comment lines, one header line, numeric rows.

    Returns (column names, array (rows, columns)).
    """
    lines = [line for line in path.read_text().splitlines() if line and not line.startswith("#")]
    names = lines[0].split(",")
    values = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    return names, values


@lru_cache(maxsize=1)
def grid_spectra() -> dict[str, np.ndarray]:
    """Chromophore spectra on ``WAVELENGTHS_NM`` (each (376,), float64).

    Keys: ``eps_hbo2``, ``eps_hb``, ``eps_bilirubin``, ``eps_beta_carotene`` (decadic molar extinction,
    cm^-1 M^-1) and ``mua_water`` (cm^-1).
    """
    names, values = read_table(GRID_TABLE)
    if not np.array_equal(values[:, 0], WAVELENGTHS_NM):
        raise RuntimeError(f"{GRID_TABLE} is not on the project grid 250:1000:2 nm.")
    keys = ["eps_hbo2", "eps_hb", "eps_bilirubin", "eps_beta_carotene", "mua_water"]
    if len(names) != len(keys) + 1:
        raise RuntimeError(f"{GRID_TABLE}: expected columns wavelength + {keys}, got {names}.")
    return {key: values[:, i + 1].copy() for i, key in enumerate(keys)}
