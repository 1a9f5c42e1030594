"""Fit every tone x wavelength of a dataset split (``python -m training fit --dataset DIR``).

Input: the split files of ``python -m training dataset`` (``DIR/train.h5``, ``DIR/validation.h5``;
training/data/store.py), which must be complete.  Output, per split, ``OUT/<split>_fits.h5`` (or
``<split>_fits.shard{i}of{n}.h5`` with ``--shard i/n``), one row per tone of the shard:

    index (N,) position in the split; tone (N, 5); wavelength_nm, wavelength_index (Wf,): the fitted
    wavelengths (every ``wavelength_stride``-th of the 376);
    k{K}_alpha, k{K}_g, k{K}_sigma_t [cm^-1], k{K}_weight: (N, K, Wf) float32;
    k{K}_shape_rmse, k{K}_refl_rel_err, k{K}_joint: (N, Wf) float32;
    done (N,) bool; attributes: ks, method, refl_loss, wavelength_stride, anchor_every, max_tones,
    lut (path), lut_sha256, dataset attributes.

Speed (what makes a laptop run possible; measured in docs/research/fitting.md):

* ``anchor_every`` = a > 0: per tone, every a-th fitted wavelength (an *anchor*) gets the full schedule
  (coarse search, K = 1 -> 2 -> 3 with all the starts of ``fit_schedule``); every other wavelength is
  one short warm LM run per K (``fit_schedule(warm=...)``).  ``continuity`` "sweep" (default): warm
  from the previous wavelength's kept solution, in wavelength order, the anchors checking that it is as
  good as an independent fit, components matched along wavelength (``training.fit.sweep``);
  "anchors": warm from the nearest anchor (components in the fitter's order; neighbouring wavelengths can sit
  in different basins of the degenerate fit).  ``anchor_every`` = 0 makes every wavelength an anchor.
* ``wavelength_stride`` = s: fit every s-th wavelength only (the trainer's L_param then uses those).
* ``max_tones`` = m: fit m tones of the split only, chosen by ``select``: ``"first"``, the first m (a
  Halton prefix of the training split is stratified in the biophysical parameters; the validation tones
  are uniform random in any order), or ``"lightness"``, an equal share of each 5-unit band of the
  albedo's CIE L* (``select_tones``).  Uniform melanin makes half of the tones near-black (L* < 10) and
  1.6 % lighter than L* 50 in the laptop set, where most artists' textures lie; ``"lightness"`` gives
  those tones their share of the decoder's training.

Resumable: tones are fitted a chunk at a time and marked done; rerunning the same command skips them,
and a file made with other settings is never overwritten (ValueError).  Shards take every n-th tone.

``reuse`` = a folder of earlier fits of the same split (any ``max_tones``, ``select`` or shards): the
tones it holds done, fitted with the same settings, LUT and dataset (``FIT_KEYS``), are copied instead
of fitted again, e.g. to extend a 1,000-tone selection to the whole split.  A tone's fit does not
depend on the other tones of its chunk except through rounding: refitted in another chunk, K = 1 and 2
agree to float32 precision and K = 3 to within its degenerate directions (shape RMSE within 1e-3).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import torch
from tqdm import tqdm

from exporters.constants import anisotropy
from exporters.maps import sha256_file
from training.data import store
from training.fit.optimize import WARM_LM_ITERS, fit_schedule
from training.fit.sweep import fit_tones_sweep
from training.sim.lut_extend import extension_record
from training.sim.lut_interp import LookupTables

SPLITS = ("train", "validation")

#: Attributes that fix a tone's fits (besides the ``dataset_*`` ones): files agreeing on them are
#: interchangeable row by row (``reuse``).
FIT_KEYS = ("ks", "method", "refl_loss", "wavelength_stride", "anchor_every", "continuity", "lut_sha256",
            "lut_albedo_extension")
#: How a tone's wavelengths are chained (``continuity``): "sweep", in wavelength order from the previous
#: solution, components matched (training/fit/sweep.py); "anchors", each from its nearest
#: anchor, components in the fitter's order.
CONTINUITY = ("sweep", "anchors")


#: Width of the CIE L* bands of ``select_tones(how="lightness")``.
LIGHTNESS_BAND: float = 5.0
SELECTIONS = ("first", "lightness")


def select_tones(albedo_rgb: np.ndarray, m: int | None, how: str = "first") -> np.ndarray:
    """Positions (sorted, int64) of the ``m`` tones to fit among the split's tones (``albedo_rgb`` (N, 3),
    linear sRGB under D65); all of them when ``m`` is None or >= N.

    ``"lightness"``: the tones are grouped in bands of ``LIGHTNESS_BAND`` units of L*; each band gets an
    equal share of ``m`` (a band with fewer tones gives all it has and its remainder goes to the others),
    taken in split order (the Halton prefix within the band)."""
    if how not in SELECTIONS:
        raise ValueError(f"select must be one of {SELECTIONS}, got {how!r}")
    n = len(albedo_rgb)
    if m is None or m >= n:
        return np.arange(n)
    if how == "first":
        return np.arange(m)
    from exporters.colorimetry import linear_srgb_to_lab

    band = np.floor(linear_srgb_to_lab(np.clip(albedo_rgb, 0.0, 1.0))[:, 0] / LIGHTNESS_BAND).astype(int)
    members = [np.flatnonzero(band == b) for b in np.unique(band)]
    quota = np.zeros(len(members), dtype=int)
    left = m
    while left > 0:  # water-filling: equal shares, capped by what each band holds
        open_ = [j for j in range(len(members)) if quota[j] < len(members[j])]
        share = max(left // len(open_), 1)
        for j in open_:
            take = min(share, len(members[j]) - quota[j], left)
            quota[j] += take
            left -= take
            if left == 0:
                break
    return np.sort(np.concatenate([mem[:q] for mem, q in zip(members, quota, strict=True)]))


def out_path(out: Path, split: str, shard: tuple[int, int]) -> Path:
    i, n = shard
    return out / (f"{split}_fits.h5" if n == 1 else f"{split}_fits.shard{i}of{n}.h5")


def _create(path: Path, tones: np.ndarray, index: np.ndarray, ks: tuple[int, ...], wl: np.ndarray,
            widx: np.ndarray, attrs: dict) -> None:
    tmp = path.with_suffix(".tmp")
    n, w = len(index), len(widx)
    with h5py.File(tmp, "w") as f:
        f.create_dataset("index", data=index)
        f.create_dataset("tone", data=tones)
        f.create_dataset("wavelength_nm", data=wl[widx])
        f.create_dataset("wavelength_index", data=widx)
        f.create_dataset("done", data=np.zeros(n, bool))
        for k in ks:
            for name in ("alpha", "g", "sigma_t", "weight"):
                f.create_dataset(f"k{k}_{name}", shape=(n, k, w), dtype="f4")
            for name in ("shape_rmse", "refl_rel_err", "joint"):
                f.create_dataset(f"k{k}_{name}", shape=(n, w), dtype="f4")
        f.attrs.update(attrs)
    tmp.rename(path)


def _check(path: Path, index: np.ndarray, attrs: dict) -> None:
    with h5py.File(path, "r") as f:
        for key, val in attrs.items():
            if str(f.attrs.get(key)) != str(val):
                raise ValueError(f"{path} was made with {key}={f.attrs.get(key)!r}, not {val!r}: use another --out")
        if not np.array_equal(f["index"][:], index):
            raise ValueError(f"{path} holds other tones than this run: use another --out")


def _reuse(path: Path, folder: Path, split: str) -> int:
    """Copy into ``path`` the rows not yet done there that a fits file of ``folder`` holds done with the
    same ``FIT_KEYS`` and dataset; returns how many were copied."""
    copied = 0
    with h5py.File(path, "r+") as dst:
        want = {k: str(v) for k, v in dst.attrs.items() if k in FIT_KEYS or k.startswith("dataset_")}
        names = [n for n in dst if n.startswith("k")]
        for src_path in sorted(folder.glob(f"{split}_fits*.h5")):
            if src_path.resolve() == path.resolve():
                continue
            with h5py.File(src_path, "r", locking=False) as src:
                if {k: str(src.attrs.get(k)) for k in want} != want:
                    continue
                if not np.array_equal(src["wavelength_index"][:], dst["wavelength_index"][:]):
                    continue
                done, src_done = dst["done"][:], src["done"][:]
                pos = {int(t): j for j, t in enumerate(dst["index"][:])}
                pairs = [(pos[int(t)], j) for j, t in enumerate(src["index"][:])
                         if src_done[j] and int(t) in pos and not done[pos[int(t)]]]
                if not pairs:
                    continue
                to, fr = (np.array(x) for x in zip(*pairs, strict=True))
                for name in names:
                    vals = src[name][:][fr]
                    for r, v in zip(to, vals, strict=True):
                        dst[name][r] = v
                done[to] = True
                dst["done"][:] = done
                dst.flush()
                copied += len(to)
    return copied


def _nearest_anchor(n: int, every: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(anchor positions, other positions, the anchor rank nearest to each other position) in range(n)."""
    anchors = np.arange(0, n, every) if every > 0 else np.arange(n)
    rest = np.setdiff1d(np.arange(n), anchors)
    near = np.abs(rest[:, None] - anchors[None, :]).argmin(1) if len(rest) else np.zeros(0, np.int64)
    return anchors, rest, near


def fit_tones(
    lut: LookupTables,
    profile: torch.Tensor,
    R: torch.Tensor,
    stderr: torch.Tensor,
    r_edges_cm: torch.Tensor,
    photons: float,
    g_init: torch.Tensor,
    ks: tuple[int, ...],
    *,
    method: str = "lm",
    anchor_every: int = 0,
    relative_refl: bool = True,
    steps: dict[str, int] | None = None,
    weighting: str = "rendered",
    isotropic: bool = False,
) -> dict[int, dict[str, torch.Tensor]]:
    """Fit T tones at W wavelengths: ``profile``/``stderr`` (T, W, M), ``R`` (T, W), ``g_init`` (W,).

    Anchors and warm starts as in the module docstring; ``weighting``, ``isotropic`` as in
    ``optimize.fit_schedule``.  Returns {K: {alpha, g, sigma_t, weight:
    (T, K, W); shape_rmse, refl_rel_err, joint: (T, W)}}.
    """
    T, W, M = profile.shape
    anchors, rest, near = _nearest_anchor(W, anchor_every if method == "lm" else 0)
    kw = {"ks": tuple(range(1, max(ks) + 1)), "method": method, "relative_refl": relative_refl, "weighting": weighting,
          "isotropic": isotropic}

    def run(cols: np.ndarray, **extra):
        return fit_schedule(lut, profile[:, cols].reshape(-1, M), R[:, cols].reshape(-1), r_edges_cm, photons,
                            stderr=stderr[:, cols].reshape(-1, M), g_init=g_init[cols].repeat(T), **kw, **extra)

    parts = [(anchors, run(anchors, steps=steps))]
    if len(rest):
        src = torch.as_tensor((np.arange(T)[:, None] * len(anchors) + near[None, :]).reshape(-1))
        warm = {k: parts[0][1][k].theta[src] for k in kw["ks"]}
        parts.append((rest, run(rest, warm=warm, steps=WARM_LM_ITERS)))
    out: dict[int, dict[str, torch.Tensor]] = {}
    for k in ks:
        res = {}
        for name in ("alpha", "g", "sigma_t", "w", "shape_rmse", "refl_rel_err", "joint"):
            full = None
            for cols, fits in parts:
                f = fits[k]
                val = getattr(f.mixture, name) if name in ("alpha", "g", "sigma_t", "w") else getattr(f, name)
                val = val.reshape(T, len(cols), *val.shape[1:])
                if full is None:
                    full = torch.empty((T, W, *val.shape[2:]), dtype=val.dtype, device=val.device)
                full[:, torch.as_tensor(cols)] = val
            res["weight" if name == "w" else name] = full.transpose(1, 2) if full.dim() == 3 else full
        out[k] = res
    return out


def fit_split(
    dataset: Path,
    split: str,
    lut: LookupTables,
    lut_path: Path,
    ks: tuple[int, ...],
    out: Path,
    *,
    method: str = "lm",
    shard: tuple[int, int] = (0, 1),
    chunk_tones: int = 16,
    steps: dict[str, int] | None = None,
    wavelength_stride: int = 1,
    anchor_every: int = 0,
    max_tones: int | None = None,
    select: str = "first",
    relative_refl: bool = True,
    reuse: Path | None = None,
    progress: bool = True,
    continuity: str = "sweep",
    job=None,
    device: str = "cpu",
) -> Path:
    """Fit one split of ``dataset`` into ``out`` (see the module docstring); returns the output path.

    ``job`` (``training.cluster.engine.Job``): the chunks are submitted as its tasks (each worker loads
    the LUT at ``lut_path`` once onto ``device``, in float64 as the command does; ``lut`` may be None) and
    written here as they finish; call ``job.wait()`` after.
    """
    if wavelength_stride < 1 or anchor_every < 0 or (max_tones is not None and max_tones < 1):
        raise ValueError("wavelength_stride must be >= 1, anchor_every >= 0 and max_tones >= 1")
    if continuity not in CONTINUITY or (continuity == "sweep" and method != "lm"):
        raise ValueError(f"continuity must be one of {CONTINUITY}, and 'sweep' needs method 'lm' (got {continuity!r}, "
                         f"{method!r}): use --continuity anchors with --method paper")
    src = dataset / f"{split}.h5"
    if not src.is_file():
        raise ValueError(f"{src} not found (run `python -m training dataset` and merge its shards first)")
    with h5py.File(src, "r") as f:
        if not f["done"][:].all():
            raise ValueError(f"{src} is incomplete: finish the dataset first")
        if "profile_stderr" not in f:
            raise ValueError(f"{src} has no profile_stderr (made by an older version): rebuild the dataset")
        tones_all = f["tone"][:]
        albedo_all = f["albedo_rgb"][:]
        wl = f["wavelength_nm"][:]
        src_attrs = {f"dataset_{k}": str(v) for k, v in f.attrs.items()}
        widx = np.arange(0, len(wl), wavelength_stride)
        store.check_profile_wavelengths(f, widx, "fit it (--wavelength-stride)")
    i, n = shard
    index = select_tones(albedo_all, max_tones, select)[i::n]
    attrs = {
        "ks": ",".join(map(str, ks)),
        "method": method,
        "refl_loss": "relative" if relative_refl else "paper",
        "wavelength_stride": wavelength_stride,
        "anchor_every": anchor_every,
        "continuity": continuity,
        "max_tones": "all" if max_tones is None else max_tones,
        "select": select,
        "lut_sha256": sha256_file(lut_path),
        "lut_albedo_extension": extension_record(lut_path),  # the LUT's rows above its last albedo
        "shard": f"{i}/{n}",
        **src_attrs,
    }
    path = out_path(out, split, shard)
    out.mkdir(parents=True, exist_ok=True)
    if path.exists():
        _check(path, index, attrs)
    else:
        _create(path, tones_all[index], index, ks, wl, widx, {**attrs, "lut": str(lut_path)})
    if reuse is not None:
        if not reuse.is_dir():
            raise ValueError(f"--reuse {reuse} is not a folder of `fit --dataset` outputs")
        copied = _reuse(path, reuse, split)
        if progress:
            print(f"{split}: {copied} tones copied from {reuse}")
    with h5py.File(path, "r") as f:
        todo = np.flatnonzero(~f["done"][:])
    chunks = [todo[start : start + chunk_tones] for start in range(0, len(todo), chunk_tones)]
    opts = {"ks": ks, "method": method, "anchor_every": anchor_every, "relative_refl": relative_refl, "steps": steps,
            "continuity": continuity}
    if job is not None:
        for rows in chunks:
            job.submit(f"fit {split} tones {index[rows[0]]}-{index[rows[-1]]}", fit_rows_with, Path(lut_path).resolve(),
                       attrs["lut_sha256"], src.resolve(), index[rows], widx, opts, device,
                       on_done=lambda fits, rows=rows: _write_rows(path, rows, fits))
        return path
    bar = tqdm(total=len(index), initial=len(index) - len(todo), desc=f"fit {split} {i}/{n}", disable=not progress)
    for rows in chunks:
        _write_rows(path, rows, fit_rows(lut, src, index[rows], widx, **opts))
        bar.update(len(rows))
    bar.close()
    return path


def fit_rows(lut: LookupTables, src: Path, rows: np.ndarray, widx: np.ndarray, *, ks: tuple[int, ...],
             continuity: str = "sweep", method: str = "lm", **options) -> dict[str, np.ndarray]:
    """Fit the tones at positions ``rows`` of the split file ``src`` at wavelength indices ``widx``
    (``fit_tones_sweep`` with ``continuity`` "sweep", ``fit_tones`` with "anchors"; ``options`` theirs);
    the rows of the fits file: {"k{K}_{name}": (len(rows), ...) float32}."""
    dt, dev = lut.P.dtype, lut.P.device
    with h5py.File(src, "r") as f:
        wl, edges, photons = f["wavelength_nm"][:], f["r_edges_cm"][:], float(f.attrs["photons"])
        arrs = [np.stack([f[name][r][widx] for r in rows]).astype(np.float64)
                for name in ("profile", "R_d", "profile_stderr")]
    prof, R, se = (torch.tensor(a, dtype=dt, device=dev) for a in arrs)
    g0 = torch.tensor(anisotropy(wl[widx]), dtype=dt, device=dev)
    e = torch.tensor(edges, dtype=dt, device=dev)
    if continuity == "sweep":
        fits = fit_tones_sweep(lut, prof, R, se, e, photons, g0, ks, wavelength_nm=wl[widx], **options)
    else:
        fits = fit_tones(lut, prof, R, se, e, photons, g0, ks, method=method, **options)
    return {f"k{k}_{name}": val.cpu().numpy().astype(np.float32) for k in ks for name, val in fits[k].items()}


def fit_rows_with(lut_path: Path, lut_sha256: str, src: Path, rows: np.ndarray, widx: np.ndarray, options: dict,
                  device: str = "cpu") -> dict[str, np.ndarray]:
    """``fit_rows`` on a cluster worker: the LUT is loaded once per worker (float64, as the command loads it)."""
    from training.cluster.engine import memo

    lut = memo("lut", (str(lut_path), lut_sha256, device),
               lambda: LookupTables.load(lut_path, dtype=torch.float64, device=device))
    return fit_rows(lut, src, rows, widx, **options)


def _write_rows(path: Path, rows: np.ndarray, fits: dict[str, np.ndarray]) -> None:
    """Store fitted rows (``fit_rows``) at local ``rows`` of the fits file and mark them done."""
    with h5py.File(path, "r+") as f:
        for name, arr in fits.items():
            for j, r in enumerate(rows):
                f[name][r] = arr[j]
        done = f["done"][:]
        done[rows] = True
        f["done"][:] = done
        f.flush()


def fitted_counts(fits: list[Path]) -> dict:
    """How far one split's fits files (shards allowed) are: ``fitted`` tones done, ``selected`` tones the files
    hold (``max_tones`` / ``select``), ``of`` tones in the dataset's split (None if unrecorded), ``ks``,
    ``wavelengths`` fitted per tone, ``files``.  Reads the ``done`` masks and attributes only."""
    fitted = selected = 0
    for path in fits:
        with h5py.File(path, "r", locking=False) as f:
            fitted += int(f["done"][:].sum())
            selected += int(f["done"].shape[0])
            ks = [int(k) for k in str(f.attrs["ks"]).split(",")]
            of = int(f.attrs["dataset_n_total"]) if "dataset_n_total" in f.attrs else None
            wavelengths = int(f[f"k{ks[0]}_shape_rmse"].shape[1])
    return {"fitted": fitted, "selected": selected, "of": of, "ks": ks, "wavelengths": wavelengths,
            "files": len(fits)}


#: Bands of the paper's Table 2 (nm, lower bound inclusive).
BANDS: dict[str, tuple[float, float]] = {"UV": (250.0, 400.0), "Vis": (400.0, 700.0), "NIR": (700.0, 1000.1)}


def summarise(dataset: Path, fits: list[Path], chunk_tones: int = 64) -> dict:
    """Mean errors of the done rows of one split's fits files (shards allowed), per K and band.

    Per K: ``shape_rmse``, ``refl_rel_err`` (means over tones x fitted wavelengths), and the MC noise
    floor of L_shape (``loss.Target.noise``, recomputed from the dataset's standard errors) with
    ``shape_excess`` = sqrt(L_shape^2 - noise^2), the model error proper; the same per band.
    """
    from training.fit import loss as fit_loss

    rows, per_k = [], {}
    for path in fits:
        with h5py.File(path, "r", locking=False) as f:
            done = f["done"][:]
            rows.append(f["index"][:][done])
            widx = f["wavelength_index"][:] if "wavelength_index" in f else np.arange(f["k1_shape_rmse"].shape[1])
            ks = [int(k) for k in str(f.attrs["ks"]).split(",")]
            for k in ks:
                for name in ("shape_rmse", "refl_rel_err"):
                    per_k.setdefault(k, {}).setdefault(name, []).append(f[f"k{k}_{name}"][:][done])
    index = np.concatenate(rows)
    if len(index) == 0:
        raise ValueError("no fitted rows yet")
    src = dataset / f"{fits[0].name.split('_fits')[0]}.h5"
    noise = []
    with h5py.File(src, "r") as f:
        edges = torch.tensor(f["r_edges_cm"][:])
        wl = f["wavelength_nm"][:][widx]
        photons = float(f.attrs["photons"])
        for start in range(0, len(index), chunk_tones):
            idx = np.sort(index[start : start + chunk_tones])
            order = np.argsort(np.argsort(index[start : start + chunk_tones]))
            prof = torch.tensor(f["profile"][idx][:, widx], dtype=torch.float64)
            se = torch.tensor(f["profile_stderr"][idx][:, widx], dtype=torch.float64)
            R = torch.tensor(f["R_d"][idx][:, widx], dtype=torch.float64)
            t = fit_loss.make_target(prof, R, edges, photons, stderr=se)
            noise.append(t.noise.numpy()[order])
    noise = np.concatenate(noise)
    out = {"tones": int(len(index)), "wavelengths": int(len(widx)), "noise": float(noise.mean()), "K": {}}
    for k, d in per_k.items():
        shape, refl = np.concatenate(d["shape_rmse"]), np.concatenate(d["refl_rel_err"])
        excess = fit_loss.shape_excess(torch.tensor(shape, dtype=torch.float64), torch.tensor(noise)).numpy()
        res = {"shape_rmse": float(shape.mean()), "refl_rel_err": float(refl.mean()),
               "shape_excess": float(excess.mean()), "bands": {}}
        for band, (lo, hi) in BANDS.items():
            sel = (wl >= lo) & (wl < hi)
            res["bands"][band] = {name: float(arr[:, sel].mean()) for name, arr in (
                ("shape_rmse", shape), ("shape_excess", excess), ("refl_rel_err", refl), ("noise", noise))}
        out["K"][k] = res
    return out
