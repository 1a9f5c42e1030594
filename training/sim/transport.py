"""``simulate``: Monte Carlo reflectance, transmittance and radial profile of a layered medium.

All channels (wavelengths) are walked in one run by ``training.sim.walker.Walker``; this module turns
the walker's finished-packet records into per-channel tallies (float64) with per-photon standard
errors.  ``simulate_records`` returns the records themselves (exit radius, path length per layer,
collision count) for absorption reweighting.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import torch

from exporters.constants import N_WAVELENGTHS, R_EDGES_CM
from training.sim.compiled_transport import mean_stderr, progress_bar  # noqa: F401 - mean_stderr: public here too
from training.sim.kernel import KIND_REFLECTED, KIND_TRANSMITTED, KIND_TRUNCATED, KIND_UNSCATTERED
from training.sim.medium import LayeredMedium
from training.sim.walk_constants import POOL_PACKETS_CPU
from training.sim.walker import AUTO_COMPILE_PACKETS, Source, WalkConfig, Walker

#: Radial profile estimators of ``simulate`` (``training.sim.resample``); the first is the default.
PROFILE_ESTIMATORS: tuple[str, ...] = ("histogram", "cdf")
#: Packets walked at once by default: ``POOL_PACKETS_CPU`` on a CPU.  On a GPU the
#: walk's time is set by its number of steps, which the longest walks fix, not by the packets per step: on
#: an H200 the dataset's baseline medium at 376 wavelengths took 48-61 s for 2,000 photons,
#: 49 s for 20,000 and 98 s for 165,000 (62e6 packets, ~6 GB with path records), so a GPU keeps that many
#: in flight and pays the tail once.
POOL_PACKETS = {"cpu": POOL_PACKETS_CPU, "cuda": 165_000 * N_WAVELENGTHS}


@dataclass
class SimResult:
    """Per-channel results (numpy float64); W channels, NB radial bins.

    R_d (W,): diffuse reflectance (specular excluded), with R_d_stderr (W,) = per-photon std / sqrt(N).
    T_d (W,): diffuse transmittance, scattered light only (0 for a semi-infinite medium), T_d_stderr.
    T_unscattered (W,): ballistic transmittance of a finite stack.
    absorbed (W,), specular (W,) (Fresnel reflection of the incident light), truncated (W,) (weight of
    packets still alive at the walk cap: an upper bound on the light they could still bring out),
    roulette_balance (W,): net weight created by roulette, so that
        R_d + T_d + T_unscattered + absorbed + specular + truncated - roulette_balance = 1.
    profile (W, NB) cm^-2: reflected exitance per unit area per unit incident power, averaged over
    each radial bin of ``r_edges_cm`` (NB + 1,); sum profile * pi (r1^2 - r0^2) = R_d - R_beyond,
    with R_beyond (W,) the reflectance beyond the last edge.  profile_stderr likewise.
    photons: photons per channel; seconds: wall time; packet_steps: total packet steps walked.
    """

    R_d: np.ndarray
    R_d_stderr: np.ndarray
    T_d: np.ndarray
    T_d_stderr: np.ndarray
    T_unscattered: np.ndarray
    absorbed: np.ndarray
    specular: np.ndarray
    truncated: np.ndarray
    roulette_balance: np.ndarray
    profile: np.ndarray
    profile_stderr: np.ndarray
    R_beyond: np.ndarray
    r_edges_cm: np.ndarray
    photons: int
    seconds: float
    packet_steps: int

    def energy_residual(self) -> np.ndarray:
        """R_d + T_d + T_unscattered + absorbed + specular + truncated - roulette_balance - 1, (W,)."""
        return (
            self.R_d + self.T_d + self.T_unscattered + self.absorbed + self.specular + self.truncated
            - self.roulette_balance - 1.0
        )


class _Tallies:
    """Sink reducing finished packets to per-channel float64 sums (and sums of squares)."""

    def __init__(self, n_ch: int, r_edges: torch.Tensor | None, device: torch.device) -> None:
        z = lambda: torch.zeros(n_ch, dtype=torch.float64, device=device)  # noqa: E731
        self.n_ch = n_ch
        self.r1, self.r2, self.t1, self.t2, self.tu, self.ab, self.tr = (z() for _ in range(7))
        self.edges = r_edges
        nb = 0 if r_edges is None else r_edges.shape[0]  # bins + 1 overflow bin
        self.p1 = torch.zeros(n_ch * nb, dtype=torch.float64, device=device)
        self.p2 = torch.zeros_like(self.p1)
        self.nb = nb

    def __call__(self, rec: dict[str, torch.Tensor]) -> None:
        ch, kind = rec["ch"], rec["kind"]
        w = rec["w"].double()
        self.ab.index_add_(0, ch, rec["absorbed"].double())
        for k, s1, s2 in ((KIND_REFLECTED, self.r1, self.r2), (KIND_TRANSMITTED, self.t1, self.t2)):
            m = kind == k
            s1.index_add_(0, ch[m], w[m])
            s2.index_add_(0, ch[m], w[m] * w[m])
        m = kind == KIND_UNSCATTERED
        self.tu.index_add_(0, ch[m], w[m])
        m = kind == KIND_TRUNCATED
        self.tr.index_add_(0, ch[m], w[m])
        if self.nb:
            m = kind == KIND_REFLECTED
            wr = w[m]
            r = torch.hypot(rec["x"][m].double(), rec["y"][m].double())
            b = (torch.searchsorted(self.edges, r, right=True) - 1).clamp_(0, self.nb - 1)
            flat = ch[m] * self.nb + b
            self.p1.index_add_(0, flat, wr)
            self.p2.index_add_(0, flat, wr * wr)


def _check_common(photons: int, device: str | torch.device) -> torch.device:
    if int(photons) < 1:
        raise ValueError(f"photons must be >= 1, got {photons}")
    dev = torch.device(device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError("device 'cuda' requested but CUDA is not available")
    return dev


def simulate(
    medium: LayeredMedium,
    photons: int,
    *,
    illumination: str = "diffuse",
    seed: int = 0,
    device: str | torch.device = "cpu",
    r_edges_cm: np.ndarray | None = R_EDGES_CM,
    dtype: torch.dtype = torch.float32,
    chunk_photons: int | None = None,
    max_steps: int = 100_000,
    progress: bool = False,
    compile: bool | str = "auto",
    profile_estimator: str = "histogram",
    engine: str = "auto",
    threads: int | None = None,
) -> SimResult:
    """Monte Carlo of ``medium`` at all its channels (wavelengths) at once.

    Args:
        medium: the layered medium (W channels).
        photons: photons per channel (each photon is one packet per channel).
        illumination: "diffuse" (cosine-weighted from air, the dataset's), "normal" (collimated) or
            "collimated:THETA" (collimated at THETA degrees, towards +x; ``training.sim.illumination``).
        seed: seed of the torch.Generator; results are deterministic for fixed arguments.
        device: "cpu" or "cuda" (same code).
        r_edges_cm: radial bin edges (NB + 1,), cm, increasing from 0; None skips the profile.
        dtype: precision of the torch engine's walk (float32 default; the numba engine walks in float64;
            tallies are always float64).
        chunk_photons: photons per channel walked at once (pool = chunk_photons * W packets); default
            ``POOL_PACKETS`` packets (2^18 on CPU, 62e6 on CUDA).
        max_steps: walk cap per packet (see SimResult.truncated).
        progress: show a tqdm progress bar.
        compile: torch.compile the torch engine's step (True / False / "auto": only for runs of more than
            AUTO_COMPILE_PACKETS packets, where the one-off compile time, ~10-30 s, pays off).
        engine: "auto" (numba on a CPU, torch on CUDA), "numba" (the compiled per-packet loop,
            ``training.sim.packet_loop``) or "torch" (the vectorised step); ``training.sim.walker.ENGINES``.
        threads: threads of the numba engine (None: every CPU the process may run on).
        profile_estimator: "histogram" (the plain tally per bin, default) or "cdf" (CDF-based conservative
            resampling of the same tallies, ``training.sim.resample``: same shape, same energy inside the
            last edge, less noise where bins are sparse; ``profile_stderr`` stays the histogram's).
    Returns: SimResult (numpy float64 arrays).
    """
    if profile_estimator not in PROFILE_ESTIMATORS:
        raise ValueError(f"profile_estimator must be one of {PROFILE_ESTIMATORS}, got {profile_estimator!r}")
    dev = _check_common(photons, device)
    n_ch = medium.n_channels
    if chunk_photons is None:
        pool = max(POOL_PACKETS.get(dev.type, 1 << 18), n_ch)
    else:
        if int(chunk_photons) < 1:
            raise ValueError("chunk_photons must be >= 1")
        pool = int(chunk_photons) * n_ch
    edges_t = None
    if r_edges_cm is not None:
        edges = np.asarray(r_edges_cm, dtype=np.float64)
        if edges.ndim != 1 or edges.size < 2 or edges[0] != 0.0 or np.any(np.diff(edges) <= 0):
            raise ValueError("r_edges_cm must be 1-D, start at 0 and increase strictly")
        edges_t = torch.tensor(edges, device=dev)
    cfg = WalkConfig(illumination=illumination, pool_packets=pool, max_steps=int(max_steps))
    walker = Walker(medium, cfg, seed=seed, device=dev, dtype=dtype,
                    compile=_want_compile(compile, photons * n_ch), engine=engine, threads=threads)
    tallies = _Tallies(n_ch, edges_t, dev)
    t0 = time.perf_counter()
    bar = progress_bar(photons * n_ch, progress)
    totals = walker.run(Source(int(photons), n_ch), tallies, progress=bar.update if bar else None)
    if bar:
        bar.close()
    seconds = time.perf_counter() - t0
    res = _result(tallies, totals, int(photons), edges_t, seconds)
    if profile_estimator == "cdf" and edges_t is not None:
        from training.sim.resample import cdf_resample

        n = int(photons)
        sums = [t.detach().cpu().numpy().reshape(n_ch, -1)[:, :-1] / n for t in (tallies.p1, tallies.p2)]
        res.profile = cdf_resample(*sums, res.r_edges_cm, n)
    return res


def _want_compile(compile: bool | str, packets: int) -> bool:
    if compile == "auto":
        return packets > AUTO_COMPILE_PACKETS
    if not isinstance(compile, bool):
        raise ValueError(f"compile must be True, False or 'auto', got {compile!r}")
    return compile


def _result(tal: _Tallies, totals, n: int, edges_t: torch.Tensor | None, seconds: float) -> SimResult:
    np64 = lambda t: t.detach().cpu().numpy().astype(np.float64)  # noqa: E731
    r_d, r_se = mean_stderr(np64(tal.r1), np64(tal.r2), n)
    t_d, t_se = mean_stderr(np64(tal.t1), np64(tal.t2), n)
    if edges_t is not None:
        edges = np64(edges_t)
        area = math.pi * np.diff(edges**2)
        p1 = np64(tal.p1).reshape(tal.n_ch, -1)
        p2 = np64(tal.p2).reshape(tal.n_ch, -1)
        pm, pse = mean_stderr(p1, p2, n)
        profile, profile_se, beyond = pm[:, :-1] / area, pse[:, :-1] / area, pm[:, -1]
    else:
        edges = np.zeros(0)
        profile = profile_se = np.zeros((tal.n_ch, 0))
        beyond = np.zeros(tal.n_ch)
    return SimResult(
        R_d=r_d, R_d_stderr=r_se, T_d=t_d, T_d_stderr=t_se,
        T_unscattered=np64(tal.tu) / n, absorbed=np64(tal.ab) / n,
        specular=np64(totals.specular) / n, truncated=np64(tal.tr) / n,
        roulette_balance=np64(totals.roulette_balance) / n,
        profile=profile, profile_stderr=profile_se, R_beyond=beyond, r_edges_cm=edges,
        photons=n, seconds=seconds, packet_steps=int(totals.packet_steps),
    )


@dataclass
class ExitRecords:
    """Per-packet records of a run (numpy), one row per photon and channel that left the medium.

    ch (int64), pid (int64), kind (int8, walker KIND_*), w (exit weight), r_cm (exit radius), ncoll
    (collisions), path_cm (n, L) path length in each layer, for the reflected / transmitted /
    truncated packets; plus the run's specular (W,) and roulette_balance (W,) per photon.
    """

    ch: np.ndarray
    pid: np.ndarray
    kind: np.ndarray
    w: np.ndarray
    r_cm: np.ndarray
    ncoll: np.ndarray
    path_cm: np.ndarray
    specular: np.ndarray
    roulette_balance: np.ndarray
    photons: int
    seconds: float


def simulate_records(
    medium: LayeredMedium,
    photons: int,
    *,
    illumination: str = "diffuse",
    seed: int = 0,
    device: str | torch.device = "cpu",
    dtype: torch.dtype = torch.float32,
    chunk_photons: int | None = None,
    max_steps: int = 100_000,
    path_roulette_n0: int | None = None,
    compile: bool | str = "auto",
    engine: str = "auto",
    threads: int | None = None,
) -> ExitRecords:
    """Like ``simulate`` but returns every exiting packet's record (for absorption reweighting).

    Packets killed by roulette or absorbed carry no light and are dropped; with mua = 0 nothing is
    absorbed and only the walk cap (kind KIND_TRUNCATED) and the optional path roulette lose packets.
    ``engine``, ``threads``: as for ``simulate``.
    """
    dev = _check_common(photons, device)
    n_ch = medium.n_channels
    pool = max(POOL_PACKETS.get(dev.type, 1 << 18), n_ch) if chunk_photons is None else int(chunk_photons) * n_ch
    cfg = WalkConfig(
        illumination=illumination, pool_packets=pool, max_steps=int(max_steps), record_paths=True,
        path_roulette_n0=path_roulette_n0,
    )
    walker = Walker(medium, cfg, seed=seed, device=dev, dtype=dtype,
                    compile=_want_compile(compile, photons * n_ch), engine=engine, threads=threads)
    keep: list[dict[str, np.ndarray]] = []

    def sink(rec: dict[str, torch.Tensor]) -> None:
        m = rec["kind"] != 0
        keep.append({
            "ch": rec["ch"][m].cpu().numpy(), "pid": rec["pid"][m].cpu().numpy(),
            "kind": rec["kind"][m].cpu().numpy(), "w": rec["w"][m].double().cpu().numpy(),
            "r_cm": torch.hypot(rec["x"][m].double(), rec["y"][m].double()).cpu().numpy(),
            "ncoll": rec["ncoll"][m].cpu().numpy(), "path_cm": rec["path"][m].double().cpu().numpy(),
        })

    t0 = time.perf_counter()
    totals = walker.run(Source(int(photons), n_ch), sink)
    cat = {k: np.concatenate([d[k] for d in keep]) if keep else None for k in
           ("ch", "pid", "kind", "w", "r_cm", "ncoll", "path_cm")}
    if not keep:
        cat = {"ch": np.zeros(0, np.int64), "pid": np.zeros(0, np.int64), "kind": np.zeros(0, np.int8),
               "w": np.zeros(0), "r_cm": np.zeros(0), "ncoll": np.zeros(0, np.int32),
               "path_cm": np.zeros((0, medium.n_layers))}
    return ExitRecords(
        **cat, specular=totals.specular.cpu().numpy() / photons,
        roulette_balance=totals.roulette_balance.cpu().numpy() / photons,
        photons=int(photons), seconds=time.perf_counter() - t0,
    )
