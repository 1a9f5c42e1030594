"""Measured skin reflectance spectra: reading the NIST file layout and matching it to the model grid.

The shipped file ``data/nist_skin_reflectance_odd_subjects.csv`` is the NIST Reference Data Set of Human
Skin Reflectance (Cooksey, Allen and Tsai 2017), odd-numbered subjects only (its header gives the source).
Layout: ``#`` comment lines, a header ``wavelength_nm,<subject>,...``, one row per wavelength (nm), values
are reflectance factors in [0, 1] (directional-hemispherical, specular included).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from exporters.constants import WAVELENGTHS_NM

#: The measured spectra shipped with the project (a copy of the team's file, header kept).
NIST_FILE = Path(__file__).with_name("data") / "nist_skin_reflectance_odd_subjects.csv"
#: Fewer grid wavelengths than this in common with the file: the file is interpolated onto the grid.
_MIN_COMMON = 20


@dataclass(frozen=True)
class Measurements:
    """S measured spectra on M wavelengths: ``wavelength_nm`` (M,), ``reflectance`` (S, M), ``names`` (S)."""

    wavelength_nm: np.ndarray
    reflectance: np.ndarray
    names: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.names)


def read_measurements(path: str | Path = NIST_FILE) -> Measurements:
    """Read a measured-reflectance CSV (NIST layout); ValueError naming the problem for a bad file."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file (pass --data with a CSV of measured spectra; "
                         f"the shipped one is {NIST_FILE.name}).")
    lines = [ln.strip() for ln in path.read_text().splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if len(lines) < 3:
        raise ValueError(f"{path}: expected a header line and at least two rows of numbers.")
    header = [h.strip() for h in lines[0].split(",")]
    if header[0] != "wavelength_nm" or len(header) < 2:
        raise ValueError(f"{path}: the first column must be 'wavelength_nm', followed by one column per "
                         f"subject; got header {header[:3]}...")
    try:
        values = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]], dtype=np.float64)
    except ValueError as exc:
        raise ValueError(f"{path}: a value is not a number ({exc}).") from None
    if values.ndim != 2 or values.shape[1] != len(header):
        raise ValueError(f"{path}: every row needs {len(header)} values, like the header.")
    wl, refl = values[:, 0], values[:, 1:].T
    if np.any(np.diff(wl) <= 0):
        raise ValueError(f"{path}: wavelengths must increase strictly.")
    if not np.all(np.isfinite(refl)) or refl.min() < 0 or refl.max() > 1.5:
        raise ValueError(f"{path}: reflectance must be finite factors in [0, 1.5] (not percent).")
    if wl.min() > 400 or wl.max() < 1000:
        raise ValueError(f"{path}: the spectra must cover 400-1000 nm (they span {wl.min():g}-{wl.max():g} nm).")
    return Measurements(wavelength_nm=wl, reflectance=refl, names=tuple(header[1:]))


def diffuse_on_grid(meas: Measurements, specular: float) -> np.ndarray:
    """The measured spectra on the full 2 nm grid (linear interpolation) without their specular part
    ``specular`` (training.realskin.geometry.rough_specular), clipped to [0, 1]: (S, 376), what skin looks
    like without its highlight (the colour an artist paints)."""
    grid = np.stack([np.interp(WAVELENGTHS_NM, meas.wavelength_nm, r) for r in meas.reflectance])
    return np.clip(grid - specular, 0.0, 1.0)


def grid_channels(meas: Measurements) -> tuple[np.ndarray, np.ndarray]:
    """Model channels to compare at and the measurements there: (indices into WAVELENGTHS_NM (C,), (S, C)).

    Where the file shares at least 20 wavelengths with the 2 nm grid (the NIST file, every 3 nm: 250, 256,
    ..., 1000 nm, 126 wavelengths) those are used as measured; otherwise the spectra are interpolated
    linearly onto every 6th grid wavelength inside the measured range.
    """
    common = np.isin(WAVELENGTHS_NM, meas.wavelength_nm)
    if common.sum() >= _MIN_COMMON:
        idx = np.flatnonzero(common)
        cols = np.searchsorted(meas.wavelength_nm, WAVELENGTHS_NM[idx])
        return idx, meas.reflectance[:, cols]
    inside = (WAVELENGTHS_NM >= meas.wavelength_nm[0]) & (WAVELENGTHS_NM <= meas.wavelength_nm[-1])
    idx = np.flatnonzero(inside)[::3]
    interp = np.stack([np.interp(WAVELENGTHS_NM[idx], meas.wavelength_nm, r) for r in meas.reflectance])
    return idx, interp
