"""The rendering gate of paper §6: ground truth, joint-optimised fits, network and baselines, rendered.

For each gate tone (``training/skin/tones.csv``: 10 representative + 10 outliers):

1. **Ground truth**: the two-layer biophysical model by Monte Carlo at the validation wavelengths — the
   dataset's estimator (``training.data.reweight``: one baseline walk cut at every gate tone's t_epi,
   reweighted per tone; tested equal to the direct walk within its standard errors), R_d and the radial
   profile.  Walked in chunks saved under ``cache/gt_walk/`` (a kill loses one chunk).
2. **Joint-optimised fits** K = 1, 2, 3 of that ground truth through the LUT
   (``training.fit.optimize.fit_schedule``, the fitter of the dataset fits): at every validation
   wavelength for the representative tones (Table 2 needs UV and NIR), in the colour range for outliers.
3. **Network**: ``skin_inversion.onnx`` on the ground truth's linear-sRGB albedo (what a user's texel
   gives, the paper's "K = 3 NN"); the same media with the painted colour (``exporters.painted``: the bake's
   default, the albedo being the ground truth's colour), whose slab colour is the albedo by construction and
   whose edge ΔE shows the translucency the network keeps; and ``skin_decoder.onnx`` on the tone's true
   biophysical vector (the translucency decoder alone).
4. **Baselines**: Chiang 2016 and Wrenninge 2017 albedo inversion (``training.validate.baselines``).
5. **Render** every configuration at the validation wavelengths inside 360-830 nm, with radial profiles.
   ``renderer="lut"`` (default): through the paper-scale lookup tables (``lut_render``): the slab's R_d and
   profile are sum_k w_k R(alpha_k, g_k) and sum_k w_k R_k P(r | alpha_k, g_k, sigma_t,k) (exact by
   linearity), and R, P are the tabulated Monte Carlo of exactly this slab (10^6 photons per simulated g
   node, within 4.3e-4 of adding-doubling in R): noise-free at the gate's scale, so the noise floor is the
   ground truth's alone.  Every configuration is also rendered by our Monte Carlo mixture renderer
   (``training.validate.mixture``; each component walked with ``photons``, combined with w_k(lambda)), one
   batched walk per tone cached in ``cache/render_<tone>.npz`` with the parameters it rendered (a changed model
   re-renders its rows): the independent check of the tables' renders (``mc_check``), and the renderer
   itself with ``renderer="mc"``.  ``photons=0`` skips it.

Everything is deterministic for a fixed configuration and seed.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from exporters.constants import R_EDGES_CM, WAVELENGTHS_NM, anisotropy
from training.skin.tones import ToneSet, load_tones
from training.validate import baselines as bl
from training.validate.metrics import COLOUR_RANGE_NM, linear_srgb
from training.validate.mixture import check_mixture, combine, render_media

#: Rows of the gate: joint-optimised fits, the paper's fits as written (``PAPER_FIT``), the network (RGB input;
#: decoder on the true p), baselines.
FIT_ROWS: tuple[str, ...] = ("k1", "k2", "k3")
PAPER_ROWS: tuple[str, ...] = ("paper_k1_shape", "paper_k1", "paper_k2", "paper_k3")
NN_ROWS: tuple[str, ...] = ("nn", "nn_painted", "nn_decoder")
ROWS: tuple[str, ...] = FIT_ROWS + PAPER_ROWS + NN_ROWS + bl.METHODS
#: The paper's fitting method as its §4 writes it: Adam (lr 1e-2, cosine; 1,000 / 1,000 / 3,000 / 10,000 steps),
#: the absolute reflectance term 5 (R_hat - R)^2, the mixture profile sum_k w_k P_k, from the shape-only K = 1
#: start; at every render wavelength, no anchors.  Its shape-only K = 1 start is a row of its own.
PAPER_FIT: dict = {"method": "paper", "relative_refl": False, "weighting": "paper", "anchor_every": 0}
ROW_LABELS: dict[str, str] = {
    "k1": "K = 1 (joint-opt)", "k2": "K = 2 (joint-opt)", "k3": "K = 3 (joint-opt)",
    "paper_k1_shape": "K = 1 paper as written, shape-only start",
    "paper_k1": "K = 1 paper as written (Adam, abs. L_R, Σ w_k P_k)",
    "paper_k2": "K = 2 paper as written", "paper_k3": "K = 3 paper as written",
    "nn": "K = 3 NN (skin_inversion.onnx, RGB in)",
    "nn_painted": "K = 3 NN, painted colour (RGB in; the bake's default)",
    "nn_decoder": "K = 3 NN decoder (true p in)",
    **bl.LABELS,
}
#: Renderers of the gate's slabs (module docstring step 5).
RENDERERS: tuple[str, ...] = ("lut", "mc")
#: Photons per ground-truth walk chunk (saved between chunks).
GT_CHUNK_PHOTONS = 5_000
#: Walker packets above which torch.compile pays for itself (~10 s once per process; measured 3-5x faster).
COMPILE_PACKETS = 1 << 21


@dataclass(frozen=True)
class GateConfig:
    """Everything that determines the gate's numbers.

    ``wavelength_step``: grid samples between validation wavelengths (2 = every 4 nm);
    ``gt_photons``: ground-truth photons per wavelength (the paper's 500,000); ``renderer``: "lut" (the
    tables, noise-free) or "mc" (our Monte Carlo renderer), module docstring step 5; ``photons``: Monte Carlo
    render photons per component and
    wavelength; ``fit_steps``: per-stage iteration overrides of the fitter (None = its defaults);
    ``baseline_scale_m``: the baselines' Subsurface Scale (None = calibrated on ``calibration_tone``);
    ``anchor_every``: the fitter's anchor spacing (``training.fit.dataset``; 0 = full schedule everywhere);
    ``max_steps``: the renders' walk cap per photon (the simulator's default 100,000; lower only for
    smoke tests: the weight still alive at the cap is recorded as ``truncated``).
    """

    tones: tuple[str, ...]
    wavelength_step: int = 2
    gt_photons: int = 500_000
    photons: int = 2_000
    renderer: str = "lut"
    fit_method: str = "lm"
    fit_steps: tuple[tuple[str, int], ...] | None = None
    anchor_every: int = 4
    max_steps: int = 100_000
    seed: int = 0
    baseline_scale_m: float | None = None
    calibration_tone: str = "R05"
    calibration_scales_m: tuple[float, ...] = tuple(bl.CALIBRATION_SCALES_M.tolist())

    def __post_init__(self) -> None:
        if not self.tones:
            raise ValueError("the gate needs at least one tone.")
        if self.wavelength_step < 1:
            raise ValueError("wavelength_step must be >= 1 grid sample.")
        if self.gt_photons < 10 or not (self.photons == 0 or self.photons >= 10):
            raise ValueError("photon counts must be >= 10 (render photons: 0 skips the Monte Carlo renders).")
        if self.renderer not in RENDERERS:
            raise ValueError(f"renderer must be one of {RENDERERS}.")
        if self.renderer == "mc" and self.photons == 0:
            raise ValueError("renderer 'mc' needs render photons > 0.")
        if self.anchor_every < 0:
            raise ValueError("anchor_every must be >= 0.")
        if self.fit_method not in ("lm", "paper"):
            raise ValueError("fit_method must be 'lm' or 'paper'.")
        if self.baseline_scale_m is not None and not self.baseline_scale_m > 0:
            raise ValueError("the baseline scale must be > 0 m.")

    def steps(self) -> dict[str, int] | None:
        return None if self.fit_steps is None else dict(self.fit_steps)


def validation_indices(step: int) -> np.ndarray:
    """Indices into WAVELENGTHS_NM of the validation wavelengths (every ``step``-th grid sample)."""
    return np.arange(0, WAVELENGTHS_NM.size, int(step))


def render_indices(step: int) -> np.ndarray:
    """The validation wavelengths inside the colour range (360-830 nm): those the gate renders."""
    idx = validation_indices(step)
    wl = WAVELENGTHS_NM[idx]
    return idx[(wl >= COLOUR_RANGE_NM[0]) & (wl <= COLOUR_RANGE_NM[1])]


def gate_tones(names: tuple[str, ...]) -> ToneSet:
    """The named tones of tones.csv, in the given order (ValueError naming unknown ones)."""
    table = load_tones()
    bad = [n for n in names if n not in table.names]
    if bad:
        raise ValueError(f"unknown tone(s) {bad}; tones.csv has {list(table.names)}.")
    pick = [table.names.index(n) for n in names]
    return ToneSet(tuple(table.names[i] for i in pick), tuple(table.kinds[i] for i in pick),
                   table.values[pick], tuple(table.descriptions[i] for i in pick))


# ------------------------------------------------------------------------------------------ cache
class Cache:
    """The run's cache folder: a manifest of the configuration, then one file per finished piece."""

    def __init__(self, folder: Path, manifest: dict) -> None:
        self.folder = Path(folder)
        self.manifest = manifest

    def open(self, reset: bool = False) -> None:
        """Create the folder; refuse one made with another configuration unless ``reset`` (then empty it)."""
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / "manifest.json"
        if path.exists():
            old = json.loads(path.read_text())
            if old != self.manifest:
                diff = sorted(k for k in set(old) | set(self.manifest) if old.get(k) != self.manifest.get(k))
                if not reset:
                    raise ValueError(f"{self.folder} holds a validation run with other settings ({', '.join(diff)}): "
                                     "use another --out, or --overwrite to start it again.")
                for p in sorted(self.folder.rglob("*"), reverse=True):
                    p.unlink() if p.is_file() else p.rmdir()
                self.folder.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.manifest, indent=1, sort_keys=True))

    def path(self, name: str) -> Path:
        return self.folder / name

    @staticmethod
    def save(path: Path, **arrays) -> None:
        tmp = path.with_name(path.name + ".tmp.npz")
        np.savez(tmp, **arrays)
        tmp.rename(path)  # a killed run leaves no half-written file under the real name

    @staticmethod
    def load(path: Path) -> dict[str, np.ndarray] | None:
        if not path.exists():
            return None
        with np.load(path, allow_pickle=False) as f:
            return {k: f[k] for k in f.files}


# ------------------------------------------------------------------------------------------ ground truth
def walk_gt_chunk(path: Path, j: int, count: int, seed: int, mua0: np.ndarray, levels: np.ndarray,
                  wl_idx: np.ndarray, compile_: bool) -> str:
    """Walk ground-truth chunk ``j`` (``count`` photons, seed ``seed * 1_000_003 + j``) into ``path``."""
    from training.data.reweight import walk

    walk(count, seed=seed * 1_000_003 + j, mua0=mua0, levels_cm=levels, channels=wl_idx, compile=compile_).save(path)
    return str(path)


def ground_truth(tones: np.ndarray, wl_idx: np.ndarray, photons: int, seed: int, cache: Cache,
                 progress: Callable[[str], None] | None = None, job=None) -> dict[str, np.ndarray]:
    """R_d, R_d_stderr (T, W), profile, profile_stderr (T, W, 512) cm^-2 of the tones at grid indices
    ``wl_idx`` by the dataset's reweighted estimator (module docstring); cached.  ``job``
    (``training.cluster.engine.Job``): the missing walk chunks are its tasks (same files), the
    reweighting stays here."""
    from training.data.reweight import Trajectories, baseline_absorption, reweight

    done = Cache.load(cache.path("gt.npz"))
    if done is not None:
        return done
    tones = np.atleast_2d(np.asarray(tones, dtype=np.float64))
    levels = np.unique(tones[:, 2])
    mua0 = baseline_absorption(tones)
    folder = cache.path("gt_walk")
    folder.mkdir(exist_ok=True)
    n_chunks = math.ceil(photons / GT_CHUNK_PHOTONS)
    chunks = [(j, min(GT_CHUNK_PHOTONS, photons - j * GT_CHUNK_PHOTONS)) for j in range(n_chunks)]
    compile_ = photons * wl_idx.size > COMPILE_PACKETS
    t0 = time.perf_counter()
    for j, count in chunks:
        path = folder / f"chunk{j:04d}.npz"
        if path.exists():
            continue
        if job is not None:
            job.submit(f"ground truth chunk {j}", walk_gt_chunk, path, j, count, seed, mua0, levels, wl_idx, compile_)
            continue
        if progress:
            progress(f"ground truth: walking chunk {j + 1}/{n_chunks} ({count} photons x {wl_idx.size} wavelengths)")
        walk_gt_chunk(path, j, count, seed, mua0, levels, wl_idx, compile_)
    if job is not None:
        job.wait()
    traj = Trajectories.concat([Trajectories.load(folder / f"chunk{j:04d}.npz") for j, _ in chunks])
    res = reweight(traj, tones)
    out = {"R_d": res["R_d"], "R_d_stderr": res["R_d_stderr"], "profile": res["profile"].astype(np.float32),
           "profile_stderr": res["profile_stderr"].astype(np.float32), "wl_idx": wl_idx, "tones": tones,
           "photons": np.int64(photons), "walk_seconds": np.float64(traj.seconds),
           "seconds": np.float64(time.perf_counter() - t0)}
    Cache.save(cache.path("gt.npz"), **out)
    return out


# ------------------------------------------------------------------------------------------ fits
def fit_tone(lut, profile: np.ndarray, R_d: np.ndarray, stderr: np.ndarray, wl_idx: np.ndarray, photons: int,
             method: str, steps: dict[str, int] | None, anchor_every: int, ks: tuple[int, ...] = (1, 2, 3),
             **options) -> dict[str, np.ndarray]:
    """Joint-optimised K = 1, 2, 3 mixtures of one tone's MC profiles (W, 512) with standard errors and
    R_d (W,) at grid indices ``wl_idx``, by the dataset fitter (``training.fit.dataset.fit_tones``: the
    full schedule at every ``anchor_every``-th wavelength, warm-started LM between; 0 = full everywhere;
    ``options``: its relative_refl, weighting, isotropic).
    Returns k{K}_alpha, k{K}_g, k{K}_sigma_t, k{K}_weight (K, W), k{K}_shape_rmse, k{K}_refl_rel_err
    (W,), plus ``wl_idx`` and ``seconds``."""
    from training.fit.dataset import fit_tones

    dt, dev = lut.P.dtype, lut.P.device
    as_t = lambda x: torch.as_tensor(np.array(x, dtype=np.float64)[None], dtype=dt, device=dev)  # noqa: E731
    t0 = time.perf_counter()
    fits = fit_tones(lut, as_t(profile), as_t(R_d), as_t(stderr), torch.tensor(R_EDGES_CM, dtype=dt, device=dev),
                     float(photons), torch.as_tensor(anisotropy(WAVELENGTHS_NM[wl_idx]), dtype=dt, device=dev),
                     ks, method=method, anchor_every=anchor_every, steps=steps, **options)
    out: dict[str, np.ndarray] = {"wl_idx": wl_idx, "seconds": np.float64(time.perf_counter() - t0)}
    for k, f in fits.items():
        for name in ("alpha", "g", "sigma_t", "weight", "shape_rmse", "refl_rel_err"):
            out[f"k{k}_{name}"] = f[name][0].detach().cpu().numpy().astype(np.float64)
    return out


def fit_tone_into(path: Path, lut_path: Path, lut_sha256: str, fit: Callable, *args) -> dict[str, np.ndarray]:
    """``fit(lut, *args)`` (``fit_tone`` or ``fit_tone_paper``) on a cluster worker, saved to the cache file
    ``path``; the LUT is loaded once per worker, as ``training.validate.run`` loads it."""
    from training.cluster.engine import memo
    from training.sim.lut_interp import LookupTables

    lut = memo("lut", (str(lut_path), lut_sha256, "cpu"), lambda: LookupTables.load(lut_path))
    out = fit(lut, *args)
    Cache.save(path, **out)
    return out


def fit_tone_paper(lut, profile: np.ndarray, R_d: np.ndarray, stderr: np.ndarray, wl_idx: np.ndarray, photons: int,
                   steps: dict[str, int] | None) -> dict[str, np.ndarray]:
    """The paper's fits as written (``PAPER_FIT``) of one tone, in ``fit_tone``'s form, plus its shape-only
    K = 1 start as k1s_* (the same Adam schedule stopped after the shape-only stage)."""
    fit = fit_tone(lut, profile, R_d, stderr, wl_idx, photons, steps=steps, **PAPER_FIT)
    start = fit_tone(lut, profile, R_d, stderr, wl_idx, photons, steps={**(steps or {}), "k1_joint": 0}, ks=(1,),
                     **PAPER_FIT)
    fit |= {k.replace("k1_", "k1s_"): v for k, v in start.items() if k.startswith("k1_")}
    fit["seconds"] = fit["seconds"] + start["seconds"]
    return fit


# ------------------------------------------------------------------------------------------ configurations
@dataclass
class Params:
    """A K-media mixture per wavelength: (K, W) arrays, weights summing to 1 over K."""

    alpha: np.ndarray
    sigma_t: np.ndarray
    g: np.ndarray
    weight: np.ndarray
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.alpha, self.sigma_t, self.g, self.weight = check_mixture(self.alpha, self.sigma_t, self.g, self.weight)
        self.weight = self.weight / self.weight.sum(axis=0)  # float32 network outputs: exact renormalisation

    @property
    def k(self) -> int:
        return int(self.alpha.shape[0])

    def stacked(self) -> np.ndarray:
        """(4, K, W) for caching and comparison."""
        return np.stack([self.alpha, self.sigma_t, self.g, self.weight])

    def cols(self, cols: np.ndarray) -> Params:
        """The mixture at wavelength columns ``cols`` (same ``extra``)."""
        return Params(self.alpha[:, cols], self.sigma_t[:, cols], self.g[:, cols], self.weight[:, cols], self.extra)


def fit_params(fit: dict[str, np.ndarray], k: int | str, wl_idx: np.ndarray) -> Params:
    """The K-component fit at grid indices ``wl_idx`` (a subset of the fit's wavelengths); ``k`` "1s": the
    shape-only K = 1 start of ``fit_tone_paper``."""
    cols = np.searchsorted(fit["wl_idx"], wl_idx)
    if np.any(cols >= fit["wl_idx"].size) or not np.array_equal(fit["wl_idx"][cols], wl_idx):
        raise ValueError("the fits do not cover the render wavelengths.")
    return Params(*(fit[f"k{k}_{n}"][:, cols] for n in ("alpha", "sigma_t", "g", "weight")))


def baseline_params(method: str, albedo_rgb: np.ndarray, scale_m: float, wl_idx: np.ndarray) -> Params:
    """One baseline's medium as a K = 1 mixture at grid indices ``wl_idx``."""
    m = bl.baseline_medium(method, np.clip(albedo_rgb, 0.0, 1.0), scale_m, WAVELENGTHS_NM[wl_idx])
    return Params(m.alpha[None], m.sigma_t[None], m.g[None], np.ones((1, m.alpha.size)))


def hold_lut_albedo(params: Params, lut) -> tuple[Params, int]:
    """A fit's mixture with alpha held within the LUT's albedo range, and how many values moved.

    The LUT holds its edge value beyond its range (``training.sim.lut_interp``), so a fitted alpha of
    1 - 1e-6 *means* the LUT's last albedo: the fitter cannot tell them apart, while a walk at 1 - 1e-6 is
    ~100x longer and reflects more.  (The paper-scale table is loaded extended up to albedo 1,
    ``training.sim.lut_extend``: then nothing moves.)"""
    lo, hi = float(params_lut_range(lut)[0]), float(params_lut_range(lut)[1])
    a = np.clip(params.alpha, lo, hi)
    return Params(a, params.sigma_t, params.g, params.weight), int(np.count_nonzero(a != params.alpha))


def params_lut_range(lut) -> tuple[float, float]:
    """The LUT's albedo range (first, last node)."""
    return float(lut.albedo[0]), float(lut.albedo[-1])


def albedo_rgb_of(R_d: np.ndarray, wl_idx: np.ndarray) -> np.ndarray:
    """Linear-sRGB (D65) albedo (T, 3) of ground-truth spectra (T, W) at grid indices ``wl_idx``."""
    return linear_srgb(R_d, WAVELENGTHS_NM[wl_idx])


# ------------------------------------------------------------------------------------------ rendering
def render_rows(rows: dict[str, Params], photons: int, seed: int, max_steps: int = 100_000
                ) -> dict[str, dict[str, np.ndarray]]:
    """Render every configuration of one tone in one batched walk; per row R_d, R_d_stderr (W,),
    profile, profile_stderr (W, 512) cm^-2 (float32), ``truncated`` (W,) (sum_k w_k x the weight alive
    at the walk cap) and ``seconds`` (of the whole walk)."""
    names = list(rows)
    alpha = np.concatenate([rows[n].alpha.ravel() for n in names])
    sigma = np.concatenate([rows[n].sigma_t.ravel() for n in names])
    g = np.concatenate([rows[n].g.ravel() for n in names])
    compile_ = alpha.size * photons > COMPILE_PACKETS
    res = render_media(alpha, sigma, g, photons=photons, seed=seed, r_edges_cm=R_EDGES_CM, compile=compile_,
                       max_steps=max_steps)
    out, start = {}, 0
    for n in names:
        p = rows[n]
        k, w = p.alpha.shape
        sl = slice(start, start + k * w)
        start += k * w
        r, r_se = combine(p.weight, res.R_d[sl].reshape(k, w), res.R_d_stderr[sl].reshape(k, w))
        nb = res.profile.shape[-1]
        prof, prof_se = combine(p.weight, res.profile[sl].reshape(k, w, nb), res.profile_stderr[sl].reshape(k, w, nb))
        out[n] = {"R_d": r, "R_d_stderr": r_se, "profile": prof.astype(np.float32),
                  "profile_stderr": prof_se.astype(np.float32), "seconds": np.float64(res.seconds),
                  "truncated": np.sum(p.weight * res.truncated[sl].reshape(k, w), axis=0)}
    return out


RENDER_KEYS = ("R_d", "R_d_stderr", "profile", "profile_stderr", "seconds", "truncated")


def lut_render(lut, params: Params) -> dict[str, np.ndarray]:
    """A mixture's slab through the lookup tables, in ``render_rows``' form: R_d (W,) = sum_k w_k R_k and
    profile (W, 512) cm^-2 = sum_k w_k R_k P_k at the bin centres of ``R_EDGES_CM``; standard errors and
    ``truncated`` 0 (module docstring step 5).  Albedos beyond the tables' range take their edge value."""
    from training.fit.mixture import Mixture, radial_profile
    from training.sim.lut_interp import bin_centres

    t0 = time.perf_counter()
    dt = lut.P.dtype
    a, s, g, w = (torch.as_tensor(np.asarray(v, np.float64).T, dtype=dt)
                  for v in (params.alpha, params.sigma_t, params.g, params.weight))  # (W, K)
    r_d = (w * lut.reflectance(a, g)).sum(1).double().numpy()
    prof = radial_profile(lut, Mixture(a, g, s, w), torch.as_tensor(bin_centres(R_EDGES_CM), dtype=dt))  # (W, 512)
    prof = prof.numpy().astype(np.float32)
    zeros = np.zeros_like(r_d)
    return {"R_d": r_d, "R_d_stderr": zeros, "profile": prof, "profile_stderr": np.zeros_like(prof),
            "seconds": np.float64(time.perf_counter() - t0), "truncated": zeros}


def render_tone(cache: Cache, name: str, rows: dict[str, Params], photons: int, seed: int,
                max_steps: int = 100_000) -> dict[str, dict]:
    """``render_rows`` for one tone, cached in ``render_<name>.npz`` together with the parameters rendered.
    Rows whose parameters changed since (a new model, new fits) are rendered again, in one walk; the
    others are kept (so after a model change their Monte Carlo noise is that of the first run)."""
    path = cache.path(f"render_{name}.npz")
    old = Cache.load(path) or {}

    def same(n: str) -> bool:
        return (f"{n}_params" in old and f"{n}_truncated" in old and old[f"{n}_params"].shape == rows[n].stacked().shape
                and np.allclose(old[f"{n}_params"], rows[n].stacked(), rtol=1e-6, atol=0))

    out = {n: {key: old[f"{n}_{key}"] for key in RENDER_KEYS} for n in rows if same(n)}
    todo = {n: p for n, p in rows.items() if n not in out}
    if todo:
        out |= render_rows(todo, photons, seed, max_steps)
        flat = {f"{n}_{key}": v for n, rec in out.items() for key, v in rec.items()}
        flat |= {f"{n}_params": rows[n].stacked() for n in rows}
        Cache.save(path, **flat)
    return {n: out[n] for n in rows}


def params_digest(rows: dict[str, Params]) -> str:
    """SHA-256 of the rendered parameters (for the record)."""
    h = hashlib.sha256()
    for n in sorted(rows):
        h.update(n.encode())
        h.update(np.ascontiguousarray(rows[n].stacked()).tobytes())
    return h.hexdigest()


def mc_target(lut, profile, R_d, stderr, photons: float):
    """The fitter's targets (``training.fit.loss.make_target``, bins chosen by standard error) of MC
    profiles (W, 512), R_d (W,) and the profiles' standard errors, in the LUT's dtype."""
    from training.fit import loss as fit_loss

    dt = lut.P.dtype
    as_t = lambda x: torch.as_tensor(np.array(x, dtype=np.float64), dtype=dt)  # noqa: E731
    return fit_loss.make_target(as_t(profile), as_t(R_d), torch.tensor(R_EDGES_CM, dtype=dt), float(photons),
                                stderr=as_t(stderr))


def lut_mixture_shape_error(lut, params: Params, target, rows: np.ndarray, weighting: str = "rendered") -> np.ndarray:
    """L_shape per wavelength of ``rows`` (training.fit.loss) of a mixture's profile through the LUT against
    MC targets; (len(rows),).

    ``weighting="rendered"``: sum_k w_k R_k P_k / sum_k w_k R_k, what a renderer that picks medium k with
    probability w_k produces; the fitter's loss (training.fit.mixture.mix); ``"fit"``: sum_k w_k P_k, as the paper's
    §4 text writes its loss."""
    from training.fit import loss as fit_loss
    from training.fit.mixture import mix

    if weighting not in ("rendered", "fit"):
        raise ValueError("weighting must be 'rendered' or 'fit'.")
    dt = lut.P.dtype
    t = target.rows(torch.as_tensor(rows))
    a, s, g, w = (torch.as_tensor(x[:, rows].T, dtype=dt) for x in (params.alpha, params.sigma_t, params.g,
                                                                   params.weight))  # (B, K)
    p_k = lut.profile(t.r_cm, a, g, s)  # (B, K, M)
    p_hat = mix(p_k, lut.reflectance(a, g), w, "rendered" if weighting == "rendered" else "paper")[0]
    return fit_loss.shape_loss(p_hat, t).detach().cpu().numpy()


def config_record(config: GateConfig) -> dict:
    """The configuration as plain JSON."""
    return json.loads(json.dumps(asdict(config)))
