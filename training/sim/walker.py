"""The photon-packet walker (MCML-style hop / drop / spin): the vectorised torch step (CPU or CUDA) and, by
default on a CPU, the compiled per-packet loop (``training.sim.packet_loop``, numba, every CPU core; the
same loop on CUDA is ``training.sim.packet_loop_cuda``), behind one interface (``Walker``, sources, sinks).

Hand-written: no maintained library offers a batched, differentiable-free, multi-wavelength layered
Monte Carlo in torch.  The physics follows MCML (Wang, Jacques & Zheng 1995, Comput. Methods Programs
Biomed. 47:131): packets of weight w take exponential optical-depth steps, are cut at layer boundaries
(the remaining optical depth carries over: "partial steps"), lose w (1 - albedo) at each interaction
(implicit capture), scatter with Henyey-Greenstein, meet a smooth unpolarised Fresnel boundary at the
top (and at the bottom of a finite stack), where they are reflected or escape all-or-none, and are
Russian-rouletted when w < ``roulette_threshold`` (survive 1/m with weight x m).

Layout of the torch engine: one packet = one photon at one channel (a wavelength, or a g column of the
LUT); all packets of all channels live in flat tensors of a fixed-size pool.  Every ``check_every`` steps finished
packets are handed to a *sink* as per-packet records and the pool is compacted and refilled from the
source, so the pool stays full until the source runs dry (no per-chunk tail).  The sink decides what
to keep: ``transport`` reduces records to tallies, the LUT builder to (radius, collision count)
histograms, a record sink keeps them all (exit radius, path length per layer, collisions) for
absorption reweighting.  The numba engines walk batches of ``pool_packets`` packets each to its end and hand
the batch's records to the same sinks.

Energy bookkeeping per channel, exact up to floating-point rounding:
    specular + sum over finished packets (exit weight + absorbed) = launched + roulette_balance,
where ``roulette_balance`` is the net weight created by every roulette (weight and path roulette).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from training.sim.illumination import parse_illumination
from training.sim.kernel import (
    KIND_ABSORBED,
    KIND_TRUNCATED,
    STEP_OUT,
    fmix32,
    fmix32_int,
    step_packets,
)
from training.sim.medium import LayeredMedium
from training.sim.physics import fresnel_unpolarised, refract_cos
from training.sim.walk_constants import ENGINES, ROULETTE_BOOST, ROULETTE_THRESHOLD

__all__ = ["KIND_ABSORBED", "KIND_TRUNCATED", "Source", "WalkConfig", "WalkTotals", "Walker"]

#: Above this many packets per run, ``compile="auto"`` compiles the step (compile time ~10-30 s).
AUTO_COMPILE_PACKETS = 1 << 23


@dataclass
class WalkConfig:
    """Walker settings.

    illumination: "diffuse" (cosine-weighted lobe from air, refracted at the origin; the Fresnel part
        of each photon is tallied as specular), "normal" (collimated normal beam, specular
        ((n - 1) / (n + 1))^2) or "collimated:THETA" (a collimated beam at polar angle THETA degrees in air,
        travelling towards +x, refracted at the origin; specular its Fresnel reflectance;
        ``training.sim.illumination``).
    pool_packets: packets walked at once (memory ~ 100 bytes each).
    max_steps: walk cap per packet (steps = interactions + boundary events); packets still alive are
        finished as KIND_TRUNCATED with their weight reported.
    roulette_threshold, roulette_boost: weight roulette (MCML: 1e-4 and 10).
    path_roulette_n0, path_roulette_keep: optional collision-count roulette for non-absorbing runs:
        a packet whose collision count passes n0 * 2^k (k = 0, 1, ...) survives with probability
        ``keep`` and weight / keep (n0: one value, or one per channel).  Unbiased (the decision
        uses only the past); it bounds the cost of the heavy-tailed walks of albedo-1 runs at the
        price of more variance in the long-path tail.
    record_paths: track the path length in each layer (for absorption reweighting).
    check_every: steps between flush / roulette / compaction passes.
    """

    illumination: str = "diffuse"
    pool_packets: int = 1 << 18
    max_steps: int = 100_000
    roulette_threshold: float = ROULETTE_THRESHOLD
    roulette_boost: float = ROULETTE_BOOST
    path_roulette_n0: float | list[float] | None = None
    path_roulette_keep: float = 0.5**0.5
    record_paths: bool = False
    check_every: int = 8

    def __post_init__(self) -> None:
        parse_illumination(self.illumination)
        if self.pool_packets < 1 or self.max_steps < 1 or self.check_every < 1:
            raise ValueError("pool_packets, max_steps and check_every must be >= 1")
        if not (0.0 < self.roulette_threshold < 1.0 and self.roulette_boost > 1.0):
            raise ValueError("need 0 < roulette_threshold < 1 and roulette_boost > 1")
        if not (0.0 < self.path_roulette_keep <= 1.0):
            raise ValueError("path_roulette_keep must be in (0, 1]")


@dataclass
class Source:
    """Which packets to launch: ``photons`` per channel, over ``n_channels`` channels.

    order "interleaved": packet q is photon q // C of channel q % C (all channels progress together);
    "channel_major": packet q is photon q % N of channel q // N (channels finish one after another,
    which lets the LUT builder write each column as soon as it is complete).
    """

    photons: int
    n_channels: int
    order: str = "interleaved"

    @property
    def total(self) -> int:
        return self.photons * self.n_channels

    def packets(self, q0: int, count: int, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
        q = torch.arange(q0, q0 + count, device=device, dtype=torch.int64)
        if self.order == "interleaved":
            return q % self.n_channels, q // self.n_channels
        return q // self.photons, q % self.photons


@dataclass
class WalkTotals:
    """Per-channel totals kept by the walker itself (float64, (C,)): launch weight and roulette."""

    specular: torch.Tensor
    roulette_balance: torch.Tensor
    steps: int = 0
    packet_steps: int = 0
    extra: dict = field(default_factory=dict)


#: A sink receives the finished packets of one flush: dict of 1-D tensors (same length):
#: ch, pid (int64), kind (int8), w (exit weight; 0 for absorbed), x, y (exit position, cm),
#: ncoll (int32), absorbed (weight absorbed along the walk), and path (n, L) if record_paths.
Sink = Callable[[dict[str, torch.Tensor]], None]

class Walker:
    """Walk every packet of ``source`` through ``medium`` and hand finished packets to ``sink``."""

    def __init__(
        self,
        medium: LayeredMedium,
        cfg: WalkConfig,
        *,
        seed: int = 0,
        device: str | torch.device = "cpu",
        dtype: torch.dtype = torch.float32,
        compile: bool = False,
        engine: str = "auto",
        threads: int | None = None,
    ) -> None:
        if dtype not in (torch.float32, torch.float64):
            raise ValueError("dtype must be torch.float32 or torch.float64")
        self.medium, self.cfg, self.dtype = medium, cfg, dtype
        self.cos_in = parse_illumination(cfg.illumination).cos_in
        self.device = torch.device(device)
        self.engine = resolve_engine(engine, self.device)
        self.threads = threads
        self.seed = int(seed)
        self.gen = torch.Generator(device=self.device)
        self.gen.manual_seed(int(seed))
        # 32-bit salts of the counter-based per-step random numbers, drawn from the seeded generator
        # (on the generator's own device: a CUDA generator cannot fill a CPU tensor)
        salts = torch.randint(0, 1 << 31, (2,), generator=self.gen, device=self.device)
        self.seed_mix, self.key_mix = (int(v) for v in salts)
        self._step_fn = _compiled_step() if compile else step_packets
        dev, dt = self.device, dtype
        mut = medium.mua + medium.mus
        alb = torch.where(mut > 0, medium.mus / mut.clamp_min(1e-300), torch.ones_like(mut))
        self.n_layers, self.n_ch = medium.n_layers, medium.n_channels
        # Flat (L * C) property tables, indexed by layer * C + channel.
        self.t_mut = mut.reshape(-1).to(dev, dt)
        self.t_alb = alb.reshape(-1).to(dev, dt)
        self.t_g = medium.g.reshape(-1).to(dev, dt)
        zb = medium.boundaries()
        self.t_ztop = zb[:-1].to(dev, dt)
        self.t_zbot = zb[1:].to(dev, dt)
        self.n = float(medium.n_medium)
        self.n_below = float(medium.n_below)
        self.totals = WalkTotals(
            specular=torch.zeros(self.n_ch, dtype=torch.float64, device=dev),
            roulette_balance=torch.zeros(self.n_ch, dtype=torch.float64, device=dev),
        )
        self.it = 0
        self.launched = 0
        self.st: dict[str, torch.Tensor] = {}

    # ----------------------------------------------------------------------------------------------
    def _rand(self, *shape: int) -> torch.Tensor:
        return torch.rand(*shape, generator=self.gen, device=self.device, dtype=self.dtype)

    def _keys(self, m: int) -> torch.Tensor:
        """Distinct int32 keys for the next ``m`` launched packets (bijective hash of a serial)."""
        serial = torch.arange(self.launched, self.launched + m, device=self.device, dtype=torch.int64)
        self.launched += m
        serial = ((serial & 0xFFFFFFFF) ^ (self.key_mix & 0xFFFFFFFF))
        serial = torch.where(serial >= 1 << 31, serial - (1 << 32), serial).to(torch.int32)
        return fmix32(serial)

    def _launch(self, ch: torch.Tensor, pid: torch.Tensor) -> dict[str, torch.Tensor]:
        """New packets at the origin, refracted into the medium; tallies their specular part."""
        m, dev, dt = ch.shape[0], self.device, self.dtype
        if self.cfg.illumination == "diffuse":
            u = self._rand(3, m)
            ci = torch.sqrt(1.0 - u[0])  # cosine-weighted: pdf 2 mu on (0, 1]
            r_sp = fresnel_unpolarised(ci, 1.0, self.n)
            ct = refract_cos(ci, 1.0, self.n)
            st = torch.sqrt((1.0 - ct * ct).clamp_min(0.0))
            phi = (2.0 * math.pi) * u[1]
            ux, uy, uz = st * torch.cos(phi), st * torch.sin(phi), ct
            s0 = -torch.log1p(-u[2])
        elif self.cos_in < 1.0:  # collimated at a polar angle, refracted in the x-z plane towards +x
            ci = torch.full((m,), self.cos_in, device=dev, dtype=dt)
            r_sp = fresnel_unpolarised(ci, 1.0, self.n)
            uz = refract_cos(ci, 1.0, self.n)
            ux, uy = torch.sqrt((1.0 - uz * uz).clamp_min(0.0)), torch.zeros(m, device=dev, dtype=dt)
            s0 = -torch.log1p(-self._rand(m))
        else:
            r0 = ((self.n - 1.0) / (self.n + 1.0)) ** 2
            r_sp = torch.full((m,), r0, device=dev, dtype=dt)
            ux, uy = torch.zeros(m, device=dev, dtype=dt), torch.zeros(m, device=dev, dtype=dt)
            uz = torch.ones(m, device=dev, dtype=dt)
            s0 = -torch.log1p(-self._rand(m))
        self.totals.specular.index_add_(0, ch, r_sp.to(torch.float64))
        zeros = torch.zeros(m, device=dev, dtype=dt)
        layer = torch.zeros(m, device=dev, dtype=torch.int64)
        return {
            "x": zeros, "y": zeros.clone(), "z": zeros.clone(), "ux": ux, "uy": uy, "uz": uz,
            "w": 1.0 - r_sp, "s": s0, "absorbed": zeros.clone(),
            "layer": layer, "ch": ch, "pid": pid, "key": self._keys(m),
            "ncoll": torch.zeros(m, device=dev, dtype=torch.int32),
            "birth": torch.full((m,), self.it, device=dev, dtype=torch.int64),
            "stage": torch.zeros(m, device=dev, dtype=torch.int32),
            "kind": torch.zeros(m, device=dev, dtype=torch.int8),
            "alive": torch.ones(m, device=dev, dtype=torch.bool),
            **({"path": torch.zeros(m, self.n_layers, device=dev, dtype=dt)} if self.cfg.record_paths else {}),
        }

    # ----------------------------------------------------------------------------------------------
    def _step(self) -> None:
        """One hop for every packet (the fused, branch-free ``step_packets``)."""
        st = self.st
        salt = torch.tensor([fmix32_int(self.it * 4 + j + self.seed_mix) for j in range(4)],
                            dtype=torch.int32).to(self.device)
        path = st.get("path")
        out = self._step_fn(
            st["x"], st["y"], st["z"], st["ux"], st["uy"], st["uz"], st["w"], st["s"], st["absorbed"],
            st["layer"], st["ch"], st["key"], st["ncoll"], st["alive"], st["kind"], path, salt,
            self.t_mut, self.t_alb, self.t_g, self.t_ztop, self.t_zbot, self.n, self.n_below,
            self.n_layers, self.n_ch,
        )
        for k, v in zip(STEP_OUT, out, strict=True):
            if v is not None:
                st[k] = v

    # ----------------------------------------------------------------------------------------------
    def _roulettes(self) -> None:
        """Weight roulette, path (collision-count) roulette and the walk cap, on alive packets."""
        st, cfg = self.st, self.cfg
        alive = st["alive"]
        low = alive & (st["w"] < cfg.roulette_threshold)
        idx = low.nonzero().squeeze(1)
        if idx.numel():
            self._roulette(idx, 1.0 / cfg.roulette_boost)
        if cfg.path_roulette_n0 is not None and cfg.path_roulette_keep < 1.0:
            n0 = torch.as_tensor(cfg.path_roulette_n0, dtype=torch.float64, device=self.device)
            n0 = n0[st["ch"]] if n0.ndim else n0
            thresh = n0 * torch.pow(2.0, st["stage"].to(torch.float64))
            idx = (st["alive"] & (st["ncoll"] >= thresh)).nonzero().squeeze(1)
            if idx.numel():
                st["stage"][idx] += 1
                self._roulette(idx, cfg.path_roulette_keep)
        capped = (st["alive"] & (self.it - st["birth"] >= cfg.max_steps)).nonzero().squeeze(1)
        if capped.numel():
            st["kind"][capped] = KIND_TRUNCATED
            st["alive"][capped] = False

    def _roulette(self, idx: torch.Tensor, keep: float) -> None:
        st = self.st
        w = st["w"][idx]
        survive = (self._rand(idx.shape[0]) < keep) & (w > 0)
        w_new = torch.where(survive, w / keep, torch.zeros_like(w))
        self.totals.roulette_balance.index_add_(0, st["ch"][idx], (w_new.double() - w.double()))
        st["w"][idx] = w_new
        st["alive"][idx] = survive  # a killed packet keeps kind KIND_ABSORBED (0)

    def _flush(self, sink: Sink, refill: int, source: Source, q: int) -> int:
        """Hand finished packets to the sink, compact the pool and launch ``refill`` new packets."""
        st = self.st
        dead = (~st["alive"]).nonzero().squeeze(1) if st else None
        if dead is not None and dead.numel():
            alive = st["alive"]
            rec = {k: st[k][dead] for k in ("ch", "pid", "kind", "w", "x", "y", "ncoll", "absorbed")}
            rec["w"] = torch.where(rec["kind"] == KIND_ABSORBED, torch.zeros_like(rec["w"]), rec["w"])
            if self.cfg.record_paths:
                rec["path"] = st["path"][dead]
            sink(rec)
            keep = alive.nonzero().squeeze(1)
            self.st = {k: v[keep] for k, v in st.items()}
        if refill > 0:
            ch, pid = source.packets(q, refill, self.device)
            new = self._launch(ch, pid)
            self.st = {k: torch.cat([self.st[k], new[k]]) for k in new} if self.st else new
            q += refill
        # keep directions unit length in float32 (rotation rounding drifts by ~1e-7 per step)
        st = self.st
        if st and self.dtype == torch.float32:
            norm = torch.rsqrt(st["ux"] ** 2 + st["uy"] ** 2 + st["uz"] ** 2)
            for k in ("ux", "uy", "uz"):
                st[k] = st[k] * norm
        return q

    def run(self, source: Source, sink: Sink, progress: Callable[[int], None] | None = None) -> WalkTotals:
        """Walk all packets of ``source``; returns the walker's per-channel totals."""
        if source.n_channels != self.n_ch:
            raise ValueError(f"source has {source.n_channels} channels, medium {self.n_ch}")
        if self.engine in ("numba", "numba-cuda"):
            return self._run_compiled(source, sink, progress)
        pool, q, total = self.cfg.pool_packets, 0, source.total
        done_before = 0
        q = self._flush(sink, min(pool, total), source, 0) if total else 0
        while self.st and self.st["alive"].shape[0] > 0:
            for _ in range(self.cfg.check_every):
                self._step()
                self.it += 1
            self.totals.steps += self.cfg.check_every
            self.totals.packet_steps += self.cfg.check_every * self.st["alive"].shape[0]
            self._roulettes()
            n_pool = self.st["alive"].shape[0]
            n_alive = int(self.st["alive"].sum())
            room = pool - n_alive
            refill = min(room, total - q) if (room >= pool // 4 or n_alive == 0) else 0
            if refill > 0 or n_alive < 0.75 * n_pool:
                q = self._flush(sink, refill, source, q)
            if progress is not None:
                done = q - int(self.st["alive"].shape[0]) if self.st else q
                progress(max(done - done_before, 0))
                done_before = max(done, done_before)
        return self.totals

    def _run_compiled(self, source: Source, sink: Sink, progress: Callable[[int], None] | None) -> WalkTotals:
        """The numba engines: batches of ``pool_packets`` packets, each walked to its end by ``walk_batch`` (CPU
        threads) or ``walk_batch_cuda`` (one GPU thread per packet)."""
        from training.sim.packet_loop import walk_batch, walk_compiled

        if self.engine == "numba-cuda":
            from training.sim.packet_loop_cuda import walk_batch_cuda as walk_batch

        cfg, n_ch = self.cfg, self.n_ch
        f64 = lambda t: t.detach().cpu().to(torch.float64).numpy()  # noqa: E731
        tables = (f64(self.t_mut), f64(self.t_alb), f64(self.t_g), f64(self.t_ztop), f64(self.t_zbot))
        n0 = np.full(n_ch, np.inf) if cfg.path_roulette_n0 is None or cfg.path_roulette_keep >= 1.0 else \
            np.broadcast_to(np.asarray(cfg.path_roulette_n0, dtype=np.float64), (n_ch,)).copy()

        def batch_sink(ch: np.ndarray, pid: np.ndarray, out: dict[str, np.ndarray]) -> None:
            rec = {"ch": torch.from_numpy(ch), "pid": torch.from_numpy(pid),
                   **{k: torch.from_numpy(out[k]) for k in ("kind", "w", "x", "y", "ncoll", "absorbed")}}
            if cfg.record_paths:
                rec["path"] = torch.from_numpy(out["path"])
            sink({k: v.to(self.device) for k, v in rec.items()})
            if progress is not None:
                progress(ch.shape[0])

        spec, roul, packet_steps, longest = walk_compiled(
            tables, self.n, self.n_below, self.n_layers, n_ch, photons=source.photons, order=source.order,
            seed=self.seed, diffuse=cfg.illumination == "diffuse", pool_packets=cfg.pool_packets,
            max_steps=cfg.max_steps, roulette_threshold=cfg.roulette_threshold, roulette_boost=cfg.roulette_boost,
            path_n0=n0, path_keep=cfg.path_roulette_keep, record_paths=cfg.record_paths, threads=self.threads,
            sink=batch_sink, walk=walk_batch, cos_in=self.cos_in)
        self.totals.packet_steps += packet_steps
        self.totals.steps = max(self.totals.steps, longest)
        self.totals.specular += torch.from_numpy(spec).to(self.device)
        self.totals.roulette_balance += torch.from_numpy(roul).to(self.device)
        return self.totals


def resolve_engine(engine: str, device: torch.device) -> str:
    """The engine that runs on ``device``: "auto" is "numba" on a CPU and "torch" elsewhere."""
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
    if engine == "auto":
        return "numba" if device.type == "cpu" else "torch"
    if engine == "numba" and device.type != "cpu":
        raise ValueError(f"the numba engine walks on the CPU only, not on {device}: use engine 'torch' or 'numba-cuda'")
    if engine == "numba-cuda":
        from numba import cuda

        if not cuda.is_available():
            raise ValueError("engine 'numba-cuda' needs a CUDA GPU visible to numba (or its simulator: "
                             "NUMBA_ENABLE_CUDASIM=1 NUMBA_DISABLE_JIT=1)")
    return engine


def default_threads() -> int:
    """Threads of the numba engine when none are asked for (``training.sim.packet_loop.default_threads``)."""
    from training.sim.packet_loop import default_threads as numba_threads

    return numba_threads()


_COMPILED = None


def _compiled_step():
    """``step_packets`` compiled once per process (dynamic shapes: the pool size varies)."""
    global _COMPILED
    if _COMPILED is None:
        _COMPILED = torch.compile(step_packets, dynamic=True)
    return _COMPILED
