"""Reading the dataset splits and the mixture fits into tensors for training.

Dataset (``training.data.store``): ``DIR/{split}.h5`` with ``tone`` (N, 5), ``R_d`` (N, 376),
``albedo_rgb`` (N, 3) linear sRGB (D65), ``done`` (N,).  Only rows marked done are used.

Fits: ``DIR/{split}_fits.h5`` of ``python -m training fit --dataset`` (``training.fit.dataset``): flat
datasets ``k{K}_alpha``, ``k{K}_g``, ``k{K}_sigma_t``, ``k{K}_weight`` (Nf, K, Wf), ``index`` (Nf,)
(row in the dataset split), ``tone``, ``done``, and ``wavelength_index`` (Wf,) when only every n-th
wavelength was fitted (absent: all 376); or its shards ``{split}_fits.shard{i}of{n}.h5`` (``fit
--shard``).  The tones are checked against the dataset's.  The fits may
cover a subset of the tones (``fit --max-tones``, or an unfinished run): every simulated tone still
serves stages 1 and 2, and stage 3 draws its batches from the fitted ones (``SplitData.fitted``).

Component order: the fitter's component order is arbitrary (it depends on which start won).  With
``targets="dense"`` (the default) the components are matched along wavelength on loading
(``training.fit.matching``: sorted by sigma_t at 600 nm, then each wavelength permuted to the nearest
of its neighbour), so the network's component k is one medium followed across the spectrum; fits of
any version are read this way (``fit --continuity sweep`` stores them matched already, and matching is
idempotent).  ``targets="fitted"``: sorted by increasing sigma_t per
(tone, wavelength), "the k-th slowest-decaying medium" at each wavelength on its own, whose identities
swap wherever two sigma_t cross.

Profiles (``profiles=True``): the Monte Carlo profile targets of the fitted rows, at every wavelength
(``"dense"``) or at the fitted ones (``"fitted"``), read a chunk of tones at a time (``SHAPE_CHUNK``)
and kept on every ``bin_stride``-th of the radial bins that some (tone, wavelength) uses.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import torch

from exporters.constants import WAVELENGTHS_NM
from training.data import store
from training.fit.loss import Target, make_target
from training.fit.matching import matched

FIT_FIELDS: tuple[str, ...] = ("alpha", "g", "sigma_t", "weight")
#: How stage 3 uses the fits (``TrainConfig.targets``): "dense", matched and at every wavelength;
#: "fitted", sorted by sigma_t and at the fitted wavelengths only.
TARGET_MODES: tuple[str, ...] = ("dense", "fitted")
#: Least model floor of L_shape in float32 training (cm^-2; ``loss.FLOOR_REL``): 1e-3 x the smallest used MC
#: value can be subnormal in float32 (near-black tones at few photons use bins down to 1e-37), and 1 / floor
#: then overflows in the gradient (NaN on the ``ci`` preset); the floor only acts where the model underflows.
FLOAT32_FLOOR: float = 1e-30
#: Tones per read when loading the profile targets (bounds the float64 working set: 128 x 376 x 512).
SHAPE_CHUNK: int = 128


@dataclass
class SplitData:
    """One split in memory (float32 tensors): tone (N, 5), R_d (N, W), albedo_rgb (N, 3) of every simulated
    tone; with fits, ``fitted`` (Nf,) the rows that have fit targets, ``targets`` {name: (Nf, K, Wf)} per
    name in ``FIT_FIELDS`` (sorted by sigma_t, row j belongs to tone ``fitted[j]``) and ``target_index``
    (Wf,) the wavelengths (indices into the 376) they were fitted at; with ``profiles``, ``shape_target`` the
    Monte Carlo profiles of the fitted rows at the wavelengths ``shape_index`` (Ws,) as the fitter's loss
    targets (leading dims (Nf, Ws), on the radial bins some problem uses; ``training.fit.loss.make_target``)."""

    tone: torch.Tensor
    R_d: torch.Tensor
    albedo_rgb: torch.Tensor
    targets: dict[str, torch.Tensor] | None = None
    photons: int = 0
    fitted: torch.Tensor | None = None
    target_index: torch.Tensor | None = None
    shape_target: Target | None = None
    shape_index: torch.Tensor | None = None

    def __len__(self) -> int:
        return int(self.tone.shape[0])

    def to(self, device: str | torch.device) -> SplitData:
        t = None if self.targets is None else {k: v.to(device) for k, v in self.targets.items()}
        opt = [None if x is None else x.to(device) for x in (self.fitted, self.target_index)]
        st = None if self.shape_target is None else self.shape_target.to(device)
        si = None if self.shape_index is None else self.shape_index.to(device)
        return SplitData(self.tone.to(device), self.R_d.to(device), self.albedo_rgb.to(device), t, self.photons,
                         *opt, st, si)

    def every(self, n: int) -> SplitData:
        """Every ``n``-th tone of the split (0, n, 2n, ...) with the fits of those that have them: the
        "20x less data" ablation (``training.ablations``).  ValueError if no fitted tone is left."""
        if n <= 1:
            return self
        keep = torch.arange(0, len(self), n, device=self.tone.device)
        out = SplitData(self.tone[keep], self.R_d[keep], self.albedo_rgb[keep], None, self.photons)
        if self.fitted is None:
            return out
        j = torch.nonzero(self.fitted % n == 0).squeeze(1)
        if j.numel() == 0:
            raise ValueError(f"no fitted tone is left in every {n}th tone of the split: fit more tones")
        out.targets = {k: v[j] for k, v in self.targets.items()}
        out.fitted, out.target_index = self.fitted[j] // n, self.target_index
        if self.shape_target is not None:
            out.shape_target, out.shape_index = self.shape_target.rows(j), self.shape_index
        return out


def dataset_file(dataset_dir: Path, split: str) -> Path:
    return Path(dataset_dir) / f"{split}.h5"


def fits_file(fits_dir: Path, split: str) -> Path:
    """The fits file of ``split`` in ``fits_dir`` (``python -m training fit --dataset --out fits_dir``)."""
    return Path(fits_dir) / f"{split}_fits.h5"


def fits_files(fits_dir: Path, split: str) -> list[Path]:
    """``fits_file`` if it exists, else the shard files ``{split}_fits.shard{i}of{n}.h5`` (``fit --shard``)."""
    one = fits_file(fits_dir, split)
    return [one] if one.is_file() else sorted(Path(fits_dir).glob(f"{split}_fits.shard*of*.h5"))


def _f32(a: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(np.ascontiguousarray(a, dtype=np.float32))


def sort_by_sigma_t(targets: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Reorder the K components of every (tone, wavelength) by increasing sigma_t; arrays (N, K, W)."""
    order = np.argsort(targets["sigma_t"], axis=1, kind="stable")
    return {k: np.take_along_axis(v, order, axis=1) for k, v in targets.items()}


def load_fits(paths: list[Path], k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, dict]:
    """(index (Nf,), tone (Nf, 5), done (Nf,), wavelength_index (Wf,) or None for all, {alpha, g, sigma_t,
    weight: (Nf, K, Wf)}) of the K-component fits in one fits file or its shards (module docstring)."""
    parts, widx = [], None
    for path in paths:
        with h5py.File(path, "r") as f:
            keys = {n: f"k{k}_{n}" for n in FIT_FIELDS}
            missing = [key for key in keys.values() if key not in f]
            if missing:
                raise ValueError(f"{path}: no K={k} fits ({missing} missing): fit with --k including {k}")
            w = np.asarray(f["wavelength_index"][:], np.int64) if "wavelength_index" in f else None
            if parts and not np.array_equal(-1 if w is None else w, -1 if widx is None else widx):
                raise ValueError(f"{path} was fitted at other wavelengths than {paths[0]}")
            widx = w
            parts.append((np.asarray(f["index"][:], np.int64), np.asarray(f["tone"][:], np.float64),
                          np.asarray(f["done"][:], bool),
                          {n: np.asarray(f[key][:], dtype=np.float64) for n, key in keys.items()}))
    arrays = {n: np.concatenate([p[3][n] for p in parts]) for n in FIT_FIELDS}
    return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
            np.concatenate([p[2] for p in parts]), widx, arrays)


def load_shape_target(path: Path, rows: np.ndarray, wavelength_index: np.ndarray, R_mc: np.ndarray,
                      photons: int, bin_stride: int = 1) -> Target:
    """The fitter's profile targets (``make_target``, with the stored standard errors) of dataset rows
    ``rows`` (Nf,) at ``wavelength_index`` (Wf,), whose R_d there is ``R_mc`` (Nf, Wf), float32, restricted
    to every ``bin_stride``-th of the radial bins that some (tone, wavelength) uses: leading dims (Nf, Wf).
    Read ``SHAPE_CHUNK`` tones at a time, twice (the bins used, then the targets)."""
    R = torch.as_tensor(np.asarray(R_mc, np.float64))
    with h5py.File(path, "r") as f:
        store.check_profile_wavelengths(f, wavelength_index, "train on fits made")
        edges = torch.as_tensor(np.asarray(f["r_edges_cm"][:], np.float64))

        def chunks():
            for s in range(0, len(rows), SHAPE_CHUNK):
                part = rows[s : s + SHAPE_CHUNK]
                prof = torch.empty(len(part), len(wavelength_index), edges.numel() - 1, dtype=torch.float64)
                se = torch.empty_like(prof)
                for j, row in enumerate(part):  # one stored chunk per tone
                    prof[j] = torch.as_tensor(f["profile"][row][wavelength_index].astype(np.float64))
                    se[j] = torch.as_tensor(f["profile_stderr"][row][wavelength_index].astype(np.float64))
                yield make_target(prof, R[s : s + SHAPE_CHUNK], edges, photons, stderr=se)

        used = torch.zeros(edges.numel() - 1, dtype=torch.bool)
        for t in chunks():
            used |= t.mask.flatten(0, -2).any(0) > 0
        used = torch.nonzero(used).squeeze(1)[::bin_stride]
        parts = [t.subset(used).to(dtype=torch.float32) for t in chunks()]
    t = Target(parts[0].r_cm, *(torch.cat([getattr(p, name) for p in parts]) for name in
                                ("log_p", "mask", "n_used", "floor", "R", "r_scale", "noise")))
    t.floor = t.floor.clamp_min(FLOAT32_FLOOR)
    return t


def load_split(dataset_dir: Path, split: str, fits_dir: Path | None = None, k: int = 3,
               profiles: bool = False, targets: str = "dense", bin_stride: int = 1, shape_every: int = 1) -> SplitData:
    """Load the done rows of ``split`` and, with ``fits_dir``, the fit targets of those that have them
    (and, with ``profiles``, their Monte Carlo profile targets: ``SplitData.shape_target``, on every
    ``bin_stride``-th used radial bin, at every ``shape_every``-th wavelength with ``targets="dense"``);
    ``targets`` one of ``TARGET_MODES`` (module docstring)."""
    if targets not in TARGET_MODES:
        raise ValueError(f"targets must be one of {TARGET_MODES}, got {targets!r}")
    path = dataset_file(dataset_dir, split)
    if not path.is_file():
        raise ValueError(f"no dataset split {path}: run `python -m training dataset` first")
    with h5py.File(path, "r") as f:
        done = np.asarray(f["done"][:], bool)
        tone = np.asarray(f["tone"][:], np.float64)
        R_d = np.asarray(f["R_d"][:], np.float64)
        rgb = np.asarray(f["albedo_rgb"][:], np.float64)
        photons = int(f.attrs.get("photons", 0))
    if not done.any():
        raise ValueError(f"{path}: no simulated rows")
    for name, arr in (("R_d", R_d[done]), ("albedo_rgb", rgb[done])):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{path}: non-finite {name}")
    data = SplitData(_f32(tone[done]), _f32(R_d[done]), _f32(rgb[done]), None, photons)
    if fits_dir is None:
        return data
    paths = fits_files(fits_dir, split)
    if not paths:
        raise ValueError(f"no fits {fits_file(fits_dir, split)}: run `python -m training fit --dataset ... --out "
                         f"{fits_dir}`")
    fpath = paths[0]
    index, ftone, fdone, widx, arrays = load_fits(paths, k)
    if index.min(initial=0) < 0 or index.max(initial=-1) >= len(tone):
        raise ValueError(f"{fpath}: row index outside {path}")
    if not np.allclose(ftone, tone[index], rtol=0, atol=1e-12):
        raise ValueError(f"{fpath} was fitted on other tones than {path}")
    use = fdone & done[index]
    if not use.any():
        raise ValueError(f"{fpath}: no fitted rows yet (finish `python -m training fit --dataset`)")
    order = np.argsort(index[use], kind="stable")  # dataset order
    rows_in_data = np.cumsum(done) - 1  # position of each dataset row among the done rows
    kept = {n: v[use][order] for n, v in arrays.items()}
    for n, v in kept.items():
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{fpath}: non-finite k{k}_{n}")
    w = R_d.shape[1]
    widx = np.arange(w) if widx is None else widx
    if widx.min(initial=0) < 0 or widx.max(initial=-1) >= w or kept["alpha"].shape[-1] != len(widx):
        raise ValueError(f"{fpath}: its wavelength_index does not match {w} wavelengths")
    kept = matched(kept, WAVELENGTHS_NM[widx]) if targets == "dense" else sort_by_sigma_t(kept)
    data.targets = {n: _f32(v) for n, v in kept.items()}
    data.fitted = torch.as_tensor(rows_in_data[index[use][order]], dtype=torch.int64)
    data.target_index = torch.as_tensor(widx, dtype=torch.int64)
    if profiles:
        rows = index[use][order]
        sidx = np.arange(0, w, shape_every) if targets == "dense" else widx
        data.shape_target = load_shape_target(path, rows, sidx, R_d[rows][:, sidx], photons, bin_stride)
        data.shape_index = torch.as_tensor(sidx, dtype=torch.int64)
    return data
