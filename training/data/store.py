"""Chunked on-disk storage of one dataset split (HDF5 via h5py).

One file per split (or per shard of a split) holds fixed-size datasets, written a chunk of tones at a
time, plus a ``done`` mask: a killed job restarts where it stopped and loses at most the chunk in flight.
A training loop reads tone slices without loading the file (profiles are chunked one tone per chunk).

Datasets (N tones, W = 376 wavelengths, B = 512 radial bins):
  tone (N, 5), R_d (N, W), R_d_stderr (N, W), profile (N, W, B) and profile_stderr (N, W, B) cm^-2 float32
  (LZF-compressed: far bins of absorbing wavelengths are empty),
  albedo_rgb (N, 3) linear sRGB under D65, done (N,) bool, index (N,) position in the full split.
File attributes: preset, split, photons, seed, shard ("I/N"), method, n_total, created_by, seconds
(simulation time so far; the reweighted walk's time is in each trajectory chunk); a split built a block of
wavelengths at a time (``training.data.blocks``) adds wavelength_block and profile_stride (profiles kept at every
n-th wavelength; NaN elsewhere, ``check_profile_wavelengths``).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from exporters.constants import N_RADIAL_BINS, N_WAVELENGTHS, R_EDGES_CM, WAVELENGTHS_NM

FIELDS = {
    "tone": ((5,), "f8"),
    "R_d": ((N_WAVELENGTHS,), "f4"),
    "R_d_stderr": ((N_WAVELENGTHS,), "f4"),
    "profile": ((N_WAVELENGTHS, N_RADIAL_BINS), "f4"),
    "profile_stderr": ((N_WAVELENGTHS, N_RADIAL_BINS), "f4"),
    "albedo_rgb": ((3,), "f8"),
}
#: The fields a simulation writes (everything but the tones, which ``create`` writes).
SIMULATED = tuple(name for name in FIELDS if name != "tone")


def create(path: Path, tones: np.ndarray, index: np.ndarray, attrs: dict) -> None:
    """Create an empty split file for ``tones`` (N, 5) whose positions in the full split are ``index``."""
    tmp = path.with_suffix(".tmp")
    with h5py.File(tmp, "w") as f:
        n = len(tones)
        for name, (shape, dtype) in FIELDS.items():
            big = len(shape) > 1
            f.create_dataset(name, shape=(n, *shape), dtype=dtype, chunks=(1, *shape) if big else None,
                             compression="lzf" if big else None, shuffle=big)
        f["tone"][:] = tones
        f.create_dataset("done", data=np.zeros(n, bool))
        f.create_dataset("index", data=index)
        f.create_dataset("wavelength_nm", data=np.asarray(WAVELENGTHS_NM))
        f.create_dataset("r_edges_cm", data=np.asarray(R_EDGES_CM))
        f.attrs.update(attrs)
    tmp.rename(path)  # a crash during creation leaves no half-made file under the real name


def check_matches(path: Path, tones: np.ndarray, attrs: dict) -> None:
    """Raise ValueError if an existing file was made for other tones or settings (never overwrite it)."""
    with h5py.File(path, "r") as f:
        for key in ("preset", "split", "photons", "seed", "shard", "method"):
            if str(f.attrs.get(key)) != str(attrs[key]):
                raise ValueError(
                    f"{path} was made with {key}={f.attrs.get(key)!r}, not {attrs[key]!r}: "
                    "use another --out folder or delete the file to start over."
                )
        if not np.array_equal(f["tone"][:], tones):
            raise ValueError(f"{path} holds other tones than this run would make: use another --out folder.")


def pending(path: Path) -> np.ndarray:
    """Local row numbers not yet simulated."""
    with h5py.File(path, "r") as f:
        return np.flatnonzero(~f["done"][:])


def write_rows(path: Path, rows: np.ndarray, values: dict[str, np.ndarray], seconds: float = 0.0,
               fields: tuple[str, ...] = SIMULATED) -> None:
    """Write simulated ``values`` (each (len(rows), ...)) at local ``rows`` and mark them done.

    ``seconds`` (the time it took to simulate them) adds to the file attribute ``seconds``; ``fields``: the
    values written (a block file of ``training.data.blocks`` holds fewer).
    """
    rows = np.asarray(rows)
    run = len(rows) > 0 and np.array_equal(rows, np.arange(rows[0], rows[0] + len(rows)))
    with h5py.File(path, "r+") as f:
        for name in fields:
            data = np.asarray(values[name])
            if not np.all(np.isfinite(data)):
                raise ValueError(f"refusing to store non-finite {name} for rows {rows.tolist()}")
            if run:  # consecutive rows: one write
                f[name][rows[0] : rows[0] + len(rows)] = data
                continue
            for i, row in enumerate(rows):
                f[name][row] = data[i]
        done = f["done"][:]
        done[rows] = True
        f["done"][:] = done
        f.attrs["seconds"] = float(f.attrs.get("seconds", 0.0)) + float(seconds)
        f.flush()


def profile_stride(f: h5py.File) -> int:
    """The split keeps radial profiles at every n-th wavelength (attribute ``profile_stride``; 1: all of them)."""
    return int(f.attrs.get("profile_stride", 1))


def check_profile_wavelengths(f: h5py.File, wavelength_index: np.ndarray, what: str) -> None:
    """ValueError unless the open split ``f`` keeps profiles at every wavelength index asked for."""
    stride = profile_stride(f)
    if np.any(np.asarray(wavelength_index) % stride):
        raise ValueError(f"{f.filename} keeps radial profiles at every {stride}th wavelength only: {what} at a "
                         f"wavelength stride that is a multiple of {stride}.")


def read_split(path: Path, fields: tuple[str, ...] = ("tone", "R_d", "albedo_rgb")) -> dict[str, np.ndarray]:
    """Load the given (small) fields of a complete split into memory."""
    with h5py.File(path, "r") as f:
        if not f["done"][:].all():
            raise ValueError(f"{path} is incomplete: run the dataset command again to resume it.")
        return {name: f[name][:] for name in fields}
