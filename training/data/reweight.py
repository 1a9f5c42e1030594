"""The dataset's fast estimator: absorption reweighting of shared scattering trajectories.

In the skin model (``training.skin.model``) scattering and anisotropy depend on the wavelength only and
both layers have the same refractive index; a tone changes the absorption of each layer and the depth
of the epidermis/dermis boundary.  So, per wavelength, one walk through a medium cut into slabs at the
quantised epidermis thicknesses ``T_EPI_LEVELS_CM`` (every slab with the same scattering and the same
*baseline* absorption mu_a0, no larger than any tone's in either layer) serves every tone: a photon that
left the top after a path L_epi above the tone's epidermis depth and L_derm below it carries, for
that tone, the weight

    w_tone = w_baseline * exp(-(mu_a,epi - mu_a0) L_epi - (mu_a,derm - mu_a0) L_derm),

which is exact (same estimand as a direct walk of the tone; weight roulette decisions taken on the
baseline weight stay unbiased because the extra factor multiplies every later weight).  With
mu_a0 <= mu_a the factor is <= 1, so no weight grows and the variance stays bounded.

Cost: one walk per split for all of its tones (the walk is chunked by photons and saved, so it resumes),
then per tone a few multiply-adds and one exp per reflected photon and wavelength.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from exporters.constants import N_TISSUE, N_WAVELENGTHS, PARAM_NAMES, PARAM_RANGES, R_EDGES_CM
from training.cluster.engine import forget, memo
from training.data.binned_sums import cumulative_paths, reweighted_bin_sums
from training.data.sampling import T_EPI_LEVELS_CM
from training.sim.kernel import KIND_REFLECTED, KIND_TRUNCATED
from training.sim.medium import LayeredMedium
from training.sim.transport import POOL_PACKETS, mean_stderr, simulate_records
from training.sim.walker import WalkConfig
from training.skin.constants import SKIN_MODEL, SkinModelSpec
from training.skin.model import absorption, scattering

#: Photons per wavelength walked (and saved) at once on a CPU: ~1.9e6 packets, a few hundred MB of records.
WALK_CHUNK_PHOTONS = 5_000
#: The same on a GPU: as many as its walker keeps in flight at once (``transport.POOL_PACKETS``; 165,000 at
#: 376 wavelengths, a whole `laptop` split), since there the walk's tail, not its packets, sets the time:
#: CPU-sized chunks would pay a tail of ~50 s each (33 per `laptop` split).
WALK_CHUNK_PHOTONS_CUDA = POOL_PACKETS["cuda"] // N_WAVELENGTHS


def walk_chunk_photons(device: str | torch.device) -> int:
    """Default photons per walk chunk on ``device`` (``WALK_CHUNK_PHOTONS`` or ``WALK_CHUNK_PHOTONS_CUDA``)."""
    return WALK_CHUNK_PHOTONS_CUDA if torch.device(device).type == "cuda" else WALK_CHUNK_PHOTONS


#: The walk cap per photon (steps) of the dataset's walks: the walker's default.
WALK_MAX_STEPS = WalkConfig.max_steps
#: Records are stored in bins of ``R_EDGES_CM`` (512 bins, index 512 = beyond 5 cm).
N_BINS = R_EDGES_CM.size - 1


def baseline_absorption(extra_tones: np.ndarray | None = None, spec: SkinModelSpec = SKIN_MODEL) -> np.ndarray:
    """mu_a0 (W,), cm^-1: the smallest absorption of either layer over the parameter box of docs/contracts.md §1.

    mu_a of each layer is multilinear in (f_mel, f_blood, so2, b_mel) (``training.skin.model``), so its
    minimum over the box is at one of the 2^5 corners; ``extra_tones`` (B, 5) outside the box lower it
    further so that they can be reweighted too.
    """
    corners = np.array(list(itertools.product(*[PARAM_RANGES[n] for n in PARAM_NAMES])), dtype=np.float64)
    tones = corners if extra_tones is None else np.concatenate([corners, np.atleast_2d(extra_tones)])
    mua_epi, mua_derm = absorption(tones, spec=spec)
    return torch.minimum(mua_epi.min(0).values, mua_derm.min(0).values).numpy()


def slab_medium(mua0: np.ndarray, levels_cm: np.ndarray, channels: np.ndarray | None = None,
                spec: SkinModelSpec = SKIN_MODEL) -> LayeredMedium:
    """The baseline medium: slabs with boundaries at ``levels_cm`` over a semi-infinite rest, (W,) channels.

    ``mua0``: (W,) cm^-1 in every slab, or (S, W) per slab (S = len(levels_cm) + 1); W = the channels given.
    """
    mus, g = scattering(spec=spec)
    mua0_t = torch.as_tensor(mua0, dtype=torch.float64)
    if channels is not None:
        mus, g = mus[channels], g[channels]
    levels = np.asarray(levels_cm, dtype=np.float64)
    if levels.ndim != 1 or levels.size < 1 or np.any(np.diff(levels) <= 0) or levels[0] <= 0:
        raise ValueError(f"levels_cm must be positive and strictly increasing, got {levels.tolist()}")
    n_slabs = levels.size + 1
    thickness = torch.tensor([*np.diff(np.r_[0.0, levels]).tolist(), math.inf], dtype=torch.float64)
    full = lambda v: v.reshape(1, -1).expand(n_slabs, -1).clone()  # noqa: E731
    mua = mua0_t.clone() if mua0_t.ndim == 2 else full(mua0_t)
    return LayeredMedium(mua=mua, mus=full(mus), g=full(g), thickness=thickness, n_medium=N_TISSUE)


@dataclass
class Trajectories:
    """Reflected photons of one baseline walk, grouped by channel (numpy).

    Channel c's photons are rows offsets[c]:offsets[c + 1] of: w (n,) float32 exit weight at the
    baseline absorption, bin (n,) int16 radial bin of the exit point (``N_BINS`` = beyond 5 cm),
    path_cm (n, S) float32 path length in each of the S = len(levels_cm) + 1 slabs.
    photons: photons launched per channel; truncated (W,): weight still alive at the walk cap (per photon).
    """

    mua0: np.ndarray
    levels_cm: np.ndarray
    channels: np.ndarray
    photons: int
    offsets: np.ndarray
    w: np.ndarray
    bin: np.ndarray
    path_cm: np.ndarray
    truncated: np.ndarray
    seconds: float
    _by_bin: dict = field(default_factory=dict, repr=False, compare=False)  # channel -> bin_order(c), not saved

    def save(self, path: Path) -> None:
        tmp = path.with_name(path.name + ".tmp.npz")
        np.savez(tmp, **{k: np.asarray(v) for k, v in self.__dict__.items() if not k.startswith("_")})
        tmp.rename(path)  # a killed job leaves no half-written chunk under the real name

    def bin_order(self, c: int) -> tuple[np.ndarray, np.ndarray]:
        """Channel ``c``'s photons in bin order: (order (n,) int64 into rows offsets[c]:offsets[c + 1], stable;
        starts (N_BINS + 2,) int64, bin b holds ordered photons starts[b]:starts[b + 1]).  Cached."""
        if c not in self._by_bin:
            b = self.bin[int(self.offsets[c]) : int(self.offsets[c + 1])]
            order = np.argsort(b, kind="stable")
            starts = np.searchsorted(b[order], np.arange(N_BINS + 2), side="left").astype(np.int64)
            self._by_bin[c] = (order, starts)
        return self._by_bin[c]

    @classmethod
    def load(cls, path: Path) -> Trajectories:
        with np.load(path) as f:
            d = {k: f[k] for k in f.files}
        return cls(**{**d, "photons": int(d["photons"]), "seconds": float(d["seconds"])})

    @classmethod
    def concat(cls, parts: list[Trajectories]) -> Trajectories:
        """Join walks of the same medium (independent photons) into one; one part is returned as it is."""
        if len(parts) == 1:
            return parts[0]
        first = parts[0]
        for p in parts[1:]:
            if not (np.array_equal(p.mua0, first.mua0) and np.array_equal(p.levels_cm, first.levels_cm)
                    and np.array_equal(p.channels, first.channels)):
                raise ValueError("trajectory chunks of different media cannot be joined")
        n_ch = first.channels.size
        pieces = [(p, int(p.offsets[c]), int(p.offsets[c + 1])) for c in range(n_ch) for p in parts]
        cat = lambda k: np.concatenate([getattr(p, k)[lo:hi] for p, lo, hi in pieces])  # noqa: E731
        sizes = np.array([hi - lo for _, lo, hi in pieces]).reshape(n_ch, len(parts)).sum(1)
        photons = sum(p.photons for p in parts)
        return cls(
            mua0=first.mua0, levels_cm=first.levels_cm, channels=first.channels, photons=photons,
            offsets=np.r_[0, np.cumsum(sizes)], w=cat("w"), bin=cat("bin"), path_cm=cat("path_cm"),
            truncated=sum(p.truncated * p.photons for p in parts) / photons,
            seconds=sum(p.seconds for p in parts),
        )


def walk(
    photons: int, *, seed: int, mua0: np.ndarray, levels_cm: np.ndarray = T_EPI_LEVELS_CM,
    channels: np.ndarray | None = None, device: str = "cpu", compile: bool | str = "auto",
    illumination: str = "diffuse", spec: SkinModelSpec = SKIN_MODEL, max_steps: int = WALK_MAX_STEPS,
    walk_mua: np.ndarray | None = None,
) -> Trajectories:
    """One baseline walk: ``photons`` per channel.

    ``illumination``: "diffuse" (the dataset's cosine-weighted lobe) or "normal" (a collimated beam, the
    geometry of reflectance spectrophotometers; ``training.realskin``).  ``max_steps``: the walk cap per
    photon (the weight still alive there is ``truncated``).  ``walk_mua``: (S, W) cm^-1, the absorption of each
    of the S = len(levels_cm) + 1 slabs that the walk runs with, >= ``mua0`` (default ``mua0`` in every slab);
    the recorded weights are those of the baseline ``mua0``, w exp(sum_k (walk_mua_k - mua0) L_k) (exact: a
    walk's trajectories do not depend on absorption), so a walk at one tone's own absorption is as short as a
    direct walk of it and reweights to that tone with factors of 1.
    """
    mua0 = np.asarray(mua0, dtype=np.float64)
    ch_idx = np.arange(mua0.size) if channels is None else np.asarray(channels, dtype=np.int64)
    extra = None
    if walk_mua is not None:
        extra = np.asarray(walk_mua, dtype=np.float64)[:, ch_idx] - mua0[ch_idx]  # (S, C)
        if extra.shape[0] != np.size(levels_cm) + 1 or extra.min() < 0:
            raise ValueError(f"walk_mua must be (len(levels_cm) + 1, W) = ({np.size(levels_cm) + 1}, W) and >= mua0")
    medium = slab_medium(mua0[ch_idx] if extra is None else extra + mua0[ch_idx], levels_cm, ch_idx, spec)
    t0 = time.perf_counter()
    rec = simulate_records(medium, photons, illumination=illumination, seed=seed, device=device, compile=compile,
                           max_steps=max_steps)
    if extra is not None:
        rec.w = rec.w * np.exp(np.einsum("ns,sn->n", rec.path_cm, extra[:, rec.ch]))
    refl = rec.kind == KIND_REFLECTED
    order = np.argsort(rec.ch[refl], kind="stable")
    ch = rec.ch[refl][order]
    r_bin = np.clip(np.searchsorted(R_EDGES_CM, rec.r_cm[refl][order], side="right") - 1, 0, N_BINS)
    trunc = np.bincount(rec.ch[rec.kind == KIND_TRUNCATED], weights=rec.w[rec.kind == KIND_TRUNCATED],
                        minlength=ch_idx.size) / photons
    return Trajectories(
        mua0=np.asarray(mua0, dtype=np.float64)[ch_idx], levels_cm=np.asarray(levels_cm, dtype=np.float64),
        channels=ch_idx, photons=int(photons),
        offsets=np.r_[0, np.cumsum(np.bincount(ch, minlength=ch_idx.size))].astype(np.int64),
        w=rec.w[refl][order].astype(np.float32), bin=r_bin.astype(np.int16),
        path_cm=rec.path_cm[refl][order].astype(np.float32), truncated=trunc,
        seconds=time.perf_counter() - t0,
    )


def level_index(tones: np.ndarray, levels_cm: np.ndarray) -> np.ndarray:
    """Index into ``levels_cm`` of each tone's t_epi (B,); ValueError if one is not a level."""
    t_epi = np.atleast_2d(tones)[:, PARAM_NAMES.index("t_epi")]
    idx = np.abs(t_epi[:, None] - levels_cm[None]).argmin(1)
    bad = ~np.isclose(t_epi, levels_cm[idx], rtol=0, atol=1e-9)
    if bad.any():
        raise ValueError(
            f"t_epi {t_epi[bad].tolist()} is not one of the walked levels {levels_cm.tolist()} cm: "
            "quantise the tones (training.data.sampling.quantise_thickness) or walk their levels."
        )
    return idx


def reweight(traj: Trajectories, tones: np.ndarray, device: str = "cpu") -> dict[str, np.ndarray]:
    """R_d, R_d_stderr (B, C), profile, profile_stderr (B, C, 512) cm^-2 of tones (B, 5) from ``traj``.

    C is the walked channels (all 376 wavelengths for the dataset).  Standard errors are per-photon
    standard deviations / sqrt(photons), as for the direct estimator.
    """
    tones = np.atleast_2d(np.asarray(tones, dtype=np.float64))
    lev = level_index(tones, traj.levels_cm)
    mua_epi, mua_derm = (m.numpy()[:, traj.channels] for m in absorption(tones))
    d_epi, d_derm = mua_epi - traj.mua0, mua_derm - traj.mua0
    if min(d_epi.min(), d_derm.min()) < -1e-9 * max(1.0, float(traj.mua0.max())):
        raise ValueError("a tone absorbs less than the walk's baseline: walk with baseline_absorption(tones).")
    n_t, n_ch = len(tones), traj.channels.size
    p1 = np.zeros((n_t, n_ch, N_BINS + 1), dtype=np.float64)
    p2 = np.zeros_like(p1)
    flush = torch.set_flush_denormal(True)  # tiny weights: float32 denormals are ~10x slower on x86 CPUs
    try:
        if torch.device(device).type == "cpu":
            _reweight_by_bin(traj, lev, d_epi, d_derm, p1, p2)
        else:
            _reweight_channels(traj, _exponent_rows(lev, d_epi, d_derm, traj.levels_cm.size, device), p1, p2)
    finally:
        if flush:
            torch.set_flush_denormal(False)
    mean, se = mean_stderr(p1.sum(-1), p2.sum(-1), traj.photons)
    pm, pse = mean_stderr(p1[..., :N_BINS], p2[..., :N_BINS], traj.photons)  # float64: no flush-to-zero question
    area = math.pi * np.diff(R_EDGES_CM**2)
    return {"R_d": mean, "R_d_stderr": se, "profile": _float32_normal(pm / area),
            "profile_stderr": _float32_normal(pse / area)}


def _float32_normal(x: np.ndarray) -> np.ndarray:
    """``x`` in float32 with the values below float32's smallest normal number (1.2e-38) set to 0: whether float32
    arithmetic keeps such values as denormals depends on the flush-to-zero mode of the thread that runs it (torch
    sets it, its worker threads need not), which must not change the numbers written."""
    return np.where(np.abs(x) < np.finfo(np.float32).tiny, 0.0, x).astype(np.float32)


def one_tone(tone: np.ndarray, photons: int, *, seed: int, device: str = "cpu",
             compile: bool | str = "auto") -> dict[str, np.ndarray]:
    """The reweighted estimator for one tone (5,) at all 376 wavelengths (``simulate --method reweighted``).

    A walk cut at the tone's t_epi, reweighted as the dataset's (``reweight``; keys and shapes as there, B = 1).
    The baseline is the tone's own smaller absorption of its two layers at each wavelength (the dataset takes the
    smallest over the whole parameter box, since its walk serves every tone), and the walk runs at the tone's
    own absorption of each layer, its weights recorded at the baseline (``walk``'s ``walk_mua``): the same
    estimand, the cost of a direct walk of the tone, and for the same seed the direct walk's photons.
    """
    tone = np.asarray(tone, dtype=np.float64)
    mua_epi, mua_derm = (m.numpy()[0] for m in absorption(tone[None]))
    traj = walk(photons, seed=seed, mua0=np.minimum(mua_epi, mua_derm), levels_cm=tone[2:3], device=device,
                compile=compile, walk_mua=np.stack([mua_epi, mua_derm]))
    return reweight(traj, tone[None], device)


def _reweight_by_bin(traj: Trajectories, lev: np.ndarray, d_epi: np.ndarray, d_derm: np.ndarray,
                     p1: np.ndarray, p2: np.ndarray) -> None:
    """Fill p1, p2 (B, C, 513) float64 on the CPU: per tone, channel and radial bin, sums of photon weights and of
    their squares.

    A tone at level l weighs a photon exp(-(d_epi - d_derm) L_l - d_derm L + log w), with L_l its path above
    level l and L its whole path; per channel the photons are taken in bin order (``Trajectories.bin_order``) and
    summed by ``binned_sums.reweighted_bin_sums`` (one compiled pass per tone, float64 sums).
    """
    a, b = -(d_epi - d_derm), -d_derm
    for c in range(traj.channels.size):
        lo, hi = int(traj.offsets[c]), int(traj.offsets[c + 1])
        if hi == lo:
            continue
        order, starts = traj.bin_order(c)
        cum = cumulative_paths(traj.path_cm[lo:hi], order)  # (n_lev + 1, n): path above each level, in bin order
        log_w = np.log(traj.w[lo:hi][order])
        s1, s2 = np.zeros((lev.size, N_BINS + 1)), np.zeros((lev.size, N_BINS + 1))
        reweighted_bin_sums(cum, log_w, lev.astype(np.int64), np.ascontiguousarray(a[:, c]),
                            np.ascontiguousarray(b[:, c]), starts, s1, s2)
        p1[:, c], p2[:, c] = s1, s2


def _exponent_rows(lev: np.ndarray, d_epi: np.ndarray, d_derm: np.ndarray, n_lev: int, device: str) -> torch.Tensor:
    """X (B, C, n_lev + 2) float32 of ``_reweight_channels``: -(d_epi - d_derm) in the tone's level column, -d_derm
    and 1."""
    n_t, n_ch = d_epi.shape
    x = np.zeros((n_t, n_ch, n_lev + 2), dtype=np.float32)
    x[np.arange(n_t), :, lev] = -(d_epi - d_derm)
    x[:, :, n_lev] = -d_derm
    x[:, :, n_lev + 1] = 1.0
    return torch.as_tensor(x, device=torch.device(device))


def _reweight_channels(traj: Trajectories, x: torch.Tensor, p1: np.ndarray, p2: np.ndarray) -> None:
    """Fill p1, p2 (B, C, 513) on any torch device: per tone, channel and radial bin, sums of photon weights and
    of their squares (one (B, n_lev + 2) @ (n_lev + 2, n) product and scattered adds per channel).

    The exponent is X @ Y, one row of X per tone (``_exponent_rows``), Y = [path above each level (n_lev rows);
    total path; log w] (n_lev + 2, n).
    """
    dev = x.device
    for c in range(traj.channels.size):
        lo, hi = int(traj.offsets[c]), int(traj.offsets[c + 1])
        if hi == lo:
            continue
        b = torch.as_tensor(traj.bin[lo:hi].astype(np.int64), device=dev)
        cum = torch.as_tensor(traj.path_cm[lo:hi], device=dev).cumsum(1)  # (n, n_lev + 1): path above levels
        log_w = torch.as_tensor(traj.w[lo:hi], device=dev).log()[:, None]
        y = torch.cat([cum, log_w], dim=1).T  # (n_lev + 2, n)
        # (B, n): each photon's weight for each tone.  Exponents below -87 are raised to -87 (weights
        # < 1.7e-38, a bias below 1e-32 for 1e6 photons): expf's underflow path is ~30x slower.
        wt = (x[:, c] @ y).clamp_min_(-87.0).exp_()
        zeros = torch.zeros(x.shape[0], N_BINS + 1, dtype=torch.float32, device=dev)
        p1[:, c] = zeros.index_add(1, b, wt).cpu().numpy()
        p2[:, c] = zeros.index_add(1, b, wt.mul_(wt)).cpu().numpy()


#: What ``TrajectoryStore.discard`` leaves of a deleted walk: its seconds and photons (JSON).
WALKED_FILE = "walked.json"


def walk_seconds(folder: Path) -> float:
    """Seconds spent walking the trajectories under ``folder``: its chunk files and its deleted walks."""
    folder = Path(folder)
    kept = sum(float(np.load(p)["seconds"]) for p in sorted(folder.rglob("chunk*.npz")))
    return kept + sum(json.loads(p.read_text())["seconds"] for p in folder.rglob(WALKED_FILE))


class TrajectoryStore:
    """The baseline walk of one dataset split on disk, in photon chunks (resumable), and its reweighting.

    ``folder`` holds chunk{j}.npz for j = 0 .. ceil(photons / chunk) - 1, each walked with seed
    ``seed * 1_000_003 + j``; a killed walk loses at most the chunk in flight.  Shards of a split
    share the folder: shard I/N walks chunks j = I (mod N) first, then whatever is still missing (a
    chunk may then be walked twice, never corrupted: chunks are deterministic and renamed into place).
    On a Dask cluster (``submit_walk``) each missing chunk is a task that writes its file the same way.
    ``channels``: the wavelength indices walked (default all 376): a walk of a block of wavelengths, for builds
    that take the wavelengths a block at a time (``training.data.blocks``).
    """

    def __init__(self, folder: Path, photons: int, seed: int, *, device: str = "cpu",
                 shard: tuple[int, int] = (0, 1), chunk_photons: int | None = None,
                 max_steps: int = WALK_MAX_STEPS, progress: bool = False, channels: np.ndarray | None = None) -> None:
        self.folder, self.photons, self.seed, self.device = Path(folder), int(photons), int(seed), device
        self.mua0 = baseline_absorption()
        self.channels = np.arange(self.mua0.size) if channels is None else np.asarray(channels, dtype=np.int64)
        # a block of fewer wavelengths walks more photons per chunk: the same packets per chunk
        chunk = (walk_chunk_photons(device) * self.mua0.size // self.channels.size if chunk_photons is None
                 else chunk_photons)
        self.shard, self.chunk, self.max_steps, self.progress = shard, int(chunk), int(max_steps), progress
        self._traj: Trajectories | None = None

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_traj": None}  # what a cluster task receives: the settings, not the walk

    def _chunks(self) -> list[tuple[int, int]]:
        n = math.ceil(self.photons / self.chunk)
        return [(j, min(self.chunk, self.photons - j * self.chunk)) for j in range(n)]

    def chunk_path(self, j: int) -> Path:
        return self.folder / f"chunk{j:04d}.npz"

    def walk_chunk(self, j: int, count: int, verbose: bool = False) -> str:
        """Walk chunk ``j`` (``count`` photons, seed ``seed * 1_000_003 + j``) into its file unless it is there."""
        path = self.chunk_path(j)
        if not path.exists():
            if verbose:
                print(f"walking trajectory chunk {j + 1}/{len(self._chunks())} ({count} photons x {self.channels.size} "
                      f"wavelengths) into {self.folder}", flush=True)
            walk(count, seed=self.seed * 1_000_003 + j, mua0=self.mua0, channels=self.channels, device=self.device,
                 compile=self.photons * self.channels.size > (1 << 23), max_steps=self.max_steps).save(path)
        return str(path)

    def submit_walk(self, job) -> list:
        """The missing chunks as tasks of ``job`` (``training.cluster.engine.Job``); their futures."""
        self.folder.mkdir(parents=True, exist_ok=True)
        self._check_manifest()
        return [job.submit(f"walk {self.folder.name} chunk {j}", self.walk_chunk, j, count)
                for j, count in self._chunks() if not self.chunk_path(j).exists()]

    def trajectories(self) -> Trajectories:
        """Walk the missing chunks (resumably) and return the whole walk (cached in memory)."""
        if self._traj is not None:
            return self._traj
        self.folder.mkdir(parents=True, exist_ok=True)
        self._check_manifest()
        chunks = self._chunks()
        i, n = self.shard
        todo = [c for c in chunks if c[0] % n == i] + [c for c in chunks if c[0] % n != i]
        for j, count in todo:
            self.walk_chunk(j, count, verbose=self.progress)
        paths = [self.chunk_path(j) for j, _ in chunks]
        # one loaded walk per process, shared by the store objects that a cluster worker's tasks unpickle
        key = (str(self.folder.resolve()), self.photons, self.seed, self.chunk,
               tuple(p.stat().st_mtime_ns for p in paths))
        self._traj = memo("trajectories", key, lambda: Trajectories.concat([Trajectories.load(p) for p in paths]))
        return self._traj

    def _check_manifest(self) -> None:
        """Write the walk's settings; refuse a folder walked with other settings.

        The photon count may change when every stored chunk is full: chunk j does not depend on the
        total (its seed is ``seed * 1_000_003 + j``), so a walk grows by walking more chunks and shrinks to
        a prefix of them.  The manifest keeps the largest count walked so far.
        """
        manifest = {"photons": self.photons, "seed": self.seed, "chunk_photons": self.chunk,
                    "levels_cm": T_EPI_LEVELS_CM.tolist(), "mua0_sum": float(np.sum(self.mua0[self.channels])),
                    "max_steps": self.max_steps}
        if self.channels.size != self.mua0.size:  # a block of wavelengths (whole walks keep their old manifest)
            manifest["channels"] = self.channels.tolist()
        path = self.folder / "manifest.json"
        if path.exists():
            old = {"max_steps": WALK_MAX_STEPS, **json.loads(path.read_text())}  # walks from before the cap was kept
            diff = [k for k in manifest if np.shape(old.get(k)) != np.shape(manifest[k])
                    or not np.allclose(old.get(k, np.nan), manifest[k], rtol=1e-12, atol=0)]
            if diff == ["photons"] and old["photons"] % self.chunk == 0 and self.photons % self.chunk == 0:
                manifest["photons"] = max(int(old["photons"]), self.photons)
            elif diff:
                raise ValueError(f"{self.folder} holds a walk with other {', '.join(diff)}: "
                                 "use another --out folder or delete it to walk again (a walk of whole "
                                 "chunks can grow or shrink by whole chunks).")
        tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")  # processes of one split may write it at once
        tmp.write_text(json.dumps(manifest, indent=1))
        tmp.rename(path)

    def prepare(self) -> None:
        """Walk (or load) the trajectories now, so that chunk timings measure the reweighting alone."""
        self.trajectories()

    def discard(self) -> None:
        """Delete the walk's chunk files and forget the loaded walk: for a block of wavelengths whose tones are all
        reweighted (its records are 74 bytes per reflected photon).  The manifest stays, and ``walked.json``
        keeps the walk's CPU seconds (``walk_seconds``) for the dataset's summary."""
        paths = [self.chunk_path(j) for j, _ in self._chunks() if self.chunk_path(j).exists()]
        if paths:  # the seconds of these chunks and of any walk discarded here before
            seconds = walk_seconds(self.folder)
            (self.folder / WALKED_FILE).write_text(json.dumps({"seconds": seconds, "photons": self.photons}))
        for p in paths:
            p.unlink()
        self._traj = None
        forget("trajectories")

    def __call__(self, tones: np.ndarray, photons: int, seed: int, device: str) -> dict[str, np.ndarray]:
        """The dataset's SimulateFn: reweight ``tones`` (per-chunk seed unused: the walk is shared)."""
        if photons != self.photons:
            raise ValueError(f"the trajectories hold {self.photons} photons, not {photons}")
        return reweight(self.trajectories(), tones, device)
