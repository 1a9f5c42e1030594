"""Forward models of measured skin reflectance, tone -> R_measured at chosen channels (training.realskin).

* :class:`MonteCarloForward`: the project's own Monte Carlo, in the measurement's geometry (collimated
  normal beam, plus the rough surface's specular, ``geometry``).  One absorption-reduced walk per
  channel (``training.data.reweight``) serves every tone: a tone's reflectance is a reweighting of the
  walk's exiting photons.  The epidermis thickness is continuous: the walk is cut into thin slabs and the
  path a photon spent above depth t is interpolated linearly between slab boundaries (exact where the
  photon's path density is uniform within the 10 um slab).  Differentiable in the tone (torch).
* :class:`DecoderForward`: the shipped ``skin_decoder.onnx`` (the dataset's geometry: diffuse
  illumination, specular-free R_d) plus the same specular term, for comparison.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import torch

from exporters.constants import PARAM_NAMES, R_EDGES_CM
from exporters.inference import run_decoder
from training.data.reweight import Trajectories, baseline_absorption, walk
from training.realskin.geometry import port_collection, rough_specular
from training.sim.lut_interp import bin_centres
from training.skin.constants import SKIN_MODEL, SkinModelSpec
from training.skin.model import absorption, scattering

#: Epidermis thickness levels of the walk, cm: every 10 um over the range of docs/contracts.md §1 (0.005-0.035 cm).
T_EPI_FINE_LEVELS_CM = np.round(np.arange(0.005, 0.035 + 1e-9, 0.001), 6)
_T = PARAM_NAMES.index("t_epi")


def model_fingerprint(channels: np.ndarray, spec: SkinModelSpec = SKIN_MODEL, illumination: str = "normal") -> str:
    """SHA-256 (16 hex) of the skin model's scattering and box-minimum absorption at ``channels``.

    A cached walk is reused only if the fingerprint matches: a changed skin model walks again.
    """
    mus, g = scattering(spec=spec)
    mua0 = baseline_absorption(spec=spec)
    blob = np.concatenate([mus.numpy()[channels], g.numpy()[channels], mua0[channels]]).astype(np.float64)
    key = blob.tobytes() + np.asarray(channels, np.int64).tobytes() + illumination.encode()
    return hashlib.sha256(key).hexdigest()[:16]


def cached_walk(channels: np.ndarray, photons: int, seed: int, cache: Path | None, device: str = "cpu",
                progress: bool = False, spec: SkinModelSpec = SKIN_MODEL, illumination: str = "normal") -> Trajectories:
    """The walk of ``spec`` at ``channels`` (photons per channel; collimated normal beam unless
    ``illumination`` is "diffuse"), from ``cache`` when it holds it."""
    key = f"walk_{illumination}_{model_fingerprint(channels, spec, illumination)}_{photons}_{seed}.npz"
    path = None if cache is None else Path(cache) / key
    if path is not None and path.exists():
        return Trajectories.load(path)
    if progress:
        print(f"walking {photons} photons x {len(channels)} wavelengths ({illumination} illumination, "
              f"skin model {spec.name}) ...", flush=True)
    traj = walk(photons, seed=seed, mua0=baseline_absorption(spec=spec), levels_cm=T_EPI_FINE_LEVELS_CM,
                channels=np.asarray(channels), device=device, illumination=illumination, spec=spec)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        traj.save(path)
    return traj


class MonteCarloForward:
    """R_measured (B, C) of tones (B, 5) at the walk's channels: specular + reweighted R_d (normal beam).

    ``port_cm`` = (beam radius, port radius): count only light leaving through a sample port of that radius
    around a uniformly lit beam disc (``geometry.port_collection``); None: all of R_d (a port much wider
    than the light's lateral spread).
    """

    def __init__(self, traj: Trajectories, specular: float | None = None, spec: SkinModelSpec = SKIN_MODEL,
                 port_cm: tuple[float, float] | None = None) -> None:
        if traj.levels_cm.size < 2:
            raise ValueError("the walk needs at least two epidermis levels")
        if np.any(baseline_absorption(spec=spec)[traj.channels] < traj.mua0 - 1e-9):
            raise ValueError(f"the walk's baseline absorbs more than skin model {spec.name!r} can: walk with its "
                             "baseline_absorption(spec=...)")
        self.spec = spec
        self.channels = np.asarray(traj.channels)
        self.levels = torch.as_tensor(traj.levels_cm, dtype=torch.float64)
        self.photons = traj.photons
        self.specular = rough_specular() if specular is None else float(specular)
        self.mua0 = torch.as_tensor(traj.mua0, dtype=torch.float64)
        counts = np.diff(traj.offsets)
        n_max, n_ch, n_lev = int(counts.max()), self.channels.size, traj.levels_cm.size
        # Padded per-channel photon arrays: cum (n_lev + 1, C, n) path above each level and in total,
        # log_w (C, n) baseline exit weight (-inf for padding).
        cum = np.zeros((n_lev + 1, n_ch, n_max), dtype=np.float32)
        log_w = np.full((n_ch, n_max), -np.inf, dtype=np.float32)
        w = traj.w.astype(np.float64)
        if port_cm is not None:
            w = w * port_collection(_bin_centres_cm()[traj.bin.astype(np.int64)], *port_cm)
        for c in range(n_ch):
            lo, hi = int(traj.offsets[c]), int(traj.offsets[c + 1])
            cum[:, c, : hi - lo] = np.cumsum(traj.path_cm[lo:hi], axis=1).T
            with np.errstate(divide="ignore"):
                log_w[c, : hi - lo] = np.log(w[lo:hi])
        self.cum, self.log_w = torch.from_numpy(cum), torch.from_numpy(log_w)

    def _path_above(self, t_epi: torch.Tensor) -> torch.Tensor:
        """Path above depth t_epi (B,) per photon: (B, C, n), linear between slab boundaries."""
        lev = self.levels
        t = t_epi.clamp(float(lev[0]), float(lev[-1]))
        j = torch.searchsorted(lev, t.detach(), right=True).clamp(1, lev.numel() - 1)  # lev[j-1] <= t < lev[j]
        frac = ((t - lev[j - 1]) / (lev[j] - lev[j - 1])).to(torch.float32)[:, None, None]
        return self.cum[j - 1] * (1 - frac) + self.cum[j] * frac

    def __call__(self, tones: torch.Tensor) -> torch.Tensor:
        """R_measured (B, C), float64; ``tones`` (B, 5) float64 (differentiable).

        A sixth column k scales both layers' scattering coefficient (μs, hence μs′; g unchanged).  By
        similarity the total reflectance of a layered medium under one boundary depends on μa / μs and on the
        thicknesses in units of 1/μs only, so scattering k μs with absorption μa and epidermis t reflects like
        μs with μa / k and t k: the same walk, reweighted.  k > 1 can take μa / k below the walk's baseline;
        the reweighting then raises weights (unbiased, noisier), and t k is clamped to the walk's epidermis levels
        (50–350 µm).
        """
        scale = tones[:, 5:6] if tones.shape[1] == 6 else None
        mua_epi, mua_derm = absorption(tones[:, :5], spec=self.spec)
        ch = torch.as_tensor(self.channels)
        mua_epi, mua_derm = mua_epi[:, ch], mua_derm[:, ch]
        t_epi = tones[:, _T]
        if scale is not None:
            mua_epi, mua_derm, t_epi = mua_epi / scale, mua_derm / scale, t_epi * scale[:, 0]
        d_epi = (mua_epi - self.mua0).to(torch.float32)[:, :, None]
        d_derm = (mua_derm - self.mua0).to(torch.float32)[:, :, None]
        above = self._path_above(t_epi)
        total = self.cum[-1][None]
        expo = self.log_w[None] - (d_epi - d_derm) * above - d_derm * total
        r_d = torch.exp(expo.clamp(-87.0, 87.0)).sum(-1, dtype=torch.float64) / self.photons
        return r_d + self.specular


class DecoderForward:
    """R_measured (B, C) of tones from ``skin_decoder.onnx``: its R_d (dataset geometry) + the specular."""

    def __init__(self, decoder_path: Path, channels: np.ndarray, specular: float | None = None) -> None:
        self.decoder_path = Path(decoder_path)
        self.channels = np.asarray(channels)
        self.specular = rough_specular() if specular is None else float(specular)

    def __call__(self, tones: torch.Tensor) -> torch.Tensor:
        refl = run_decoder(tones.detach().cpu().numpy(), self.decoder_path, outputs=("reflectance",))["reflectance"]
        return torch.from_numpy(refl[:, self.channels]) + self.specular


def _bin_centres_cm() -> np.ndarray:
    """Exit radius of each stored radial bin (513,), cm: the LUT's bin centres, and the overflow bin (beyond
    5 cm) far outside any port."""
    return np.r_[bin_centres(R_EDGES_CM), 1e3]
