"""Homogeneous semi-infinite lookup tables R(albedo, g) and P(r | albedo, g) (paper §4.2), by reweighting.

Medium: semi-infinite, sigma_t = 1 (so radii are in mean free paths), n = 1.4 below air, diffuse
(cosine-weighted) illumination through the Fresnel boundary, specular reflection excluded.

Absorption reweighting (exact): at fixed sigma_t, a packet that left the medium after n collisions in
a NON-absorbing run carries weight albedo^n in the run at that albedo (implicit capture multiplies by
the albedo at each collision; trajectories do not depend on it).  So one albedo-1 run per g serves
every albedo: each exiting packet is histogrammed by (radial bin, collision count n) and every albedo
follows from a matrix product with albedo^n.

Collision-count bins: exact for n < N_EXACT; above, geometric bins of relative width DELTA_N.  Each
bin keeps sum w and sum w n per radial bin, and albedo^n is expanded to first order about the bin's
mean count nbar (a^n ~ a^nbar (1 + (n - nbar) ln a)); the remainder is below
(n delta ln a)^2 / 2 * a^n <= 0.54 DELTA_N^2 / 2 ~ 3e-5 relative for DELTA_N = 1 %.

Cost control (both unbiased): the walk cap (max_steps; packets alive at the cap are reported as a
bias bound, sum w a^n_cap / N, stored as ``R_trunc_bound``) and a collision-count roulette (a packet
passing n0 * 2^k collisions survives with probability 1/sqrt(2), weight x sqrt(2); n0 = PATH_C / (1 - g)
so that it starts in the diffusive regime): it bounds the heavy-tailed cost of albedo-1 walks while
the variance grows only logarithmically with the largest albedo.

Grids (the table stores both): albedo with 1 - albedo log-spaced from 1 - albedo_min to
1 - albedo_max (dense near 1, where profiles change fastest); g linear.  Radial edges: R_EDGES_MFP
(exporters.constants: 1e-3 to 1e4 mean free paths); the light beyond the last edge is in R but not in P
(``frac_inside`` = the fraction of R inside).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from exporters.cli_io import InputError, atomic_file, check_input
from exporters.constants import N_TISSUE, R_EDGES_MFP
from training.sim.kernel import KIND_REFLECTED, KIND_TRUNCATED, fmix32_int
from training.sim.medium import LayeredMedium
from training.sim.walker import Source, WalkConfig, Walker

N_EXACT = 256  #: collision counts below this are histogrammed exactly
DELTA_N = 0.01  #: relative width of the collision-count bins above N_EXACT
PATH_C = 32.0  #: collision-count roulette starts at PATH_C / (1 - g) collisions
ALBEDO_MIN, ALBEDO_MAX = 0.01, 0.9999  #: default albedo range
G_MIN, G_MAX = 0.0, 0.95  #: default anisotropy range
MAX_STEPS = 100_000  #: default walk cap (0.9999^1e5 = 4.5e-5)


def albedo_grid(n: int, a_min: float = ALBEDO_MIN, a_max: float = ALBEDO_MAX) -> np.ndarray:
    """(n,) increasing albedos with 1 - albedo log-spaced from 1 - a_min to 1 - a_max."""
    if n < 2 or not (0.0 < a_min < a_max < 1.0):
        raise ValueError(f"need n >= 2 and 0 < albedo_min < albedo_max < 1, got {n}, {a_min}, {a_max}")
    return 1.0 - np.geomspace(1.0 - a_min, 1.0 - a_max, n)


def g_grid(n: int, g_min: float = G_MIN, g_max: float = G_MAX) -> np.ndarray:
    """(n,) linearly spaced anisotropies in [g_min, g_max] within [-0.99, 0.99]."""
    if n < 2 or not (-0.99 <= g_min < g_max <= 0.99):
        raise ValueError(f"need n >= 2 and -0.99 <= g_min < g_max <= 0.99, got {n}, {g_min}, {g_max}")
    return np.linspace(g_min, g_max, n)


@dataclass
class CountBins:
    """Collision-count binning: exact below N_EXACT, geometric (ratio 1 + DELTA_N) above, up to n_max."""

    n_max: int

    @property
    def n_bins(self) -> int:
        return N_EXACT + int(math.ceil(math.log(max(self.n_max, N_EXACT) / N_EXACT) / math.log1p(DELTA_N))) + 1

    def index(self, n: torch.Tensor) -> torch.Tensor:
        nf = n.to(torch.float64).clamp_min(1.0)
        log_bin = N_EXACT + torch.floor(torch.log(nf / N_EXACT) / math.log1p(DELTA_N)).to(torch.int64)
        return torch.where(n < N_EXACT, n.to(torch.int64), log_bin).clamp_(0, self.n_bins - 1)

    def centres(self) -> np.ndarray:
        """Fallback representative counts (used only for empty bins)."""
        k = np.arange(self.n_bins - N_EXACT)
        return np.concatenate([np.arange(N_EXACT, dtype=float), N_EXACT * (1 + DELTA_N) ** (k + 0.5)])


class _Histograms:
    """Sink: per channel, sums of w and w n over (radial bin incl. overflow, count bin); sum w^2 per count bin."""

    def __init__(self, n_ch: int, edges: torch.Tensor, bins: CountBins, device: torch.device) -> None:
        self.edges, self.bins, self.nr, self.nb = edges, bins, edges.shape[0], bins.n_bins
        self.hw = torch.zeros(n_ch * self.nr * self.nb, dtype=torch.float64, device=device)
        self.hwn = torch.zeros_like(self.hw)
        self.hw2 = torch.zeros(n_ch * self.nb, dtype=torch.float64, device=device)
        self.trunc: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def __call__(self, rec: dict[str, torch.Tensor]) -> None:
        m = rec["kind"] == KIND_REFLECTED
        ch, w, n = rec["ch"][m], rec["w"][m].double(), rec["ncoll"][m]
        r = torch.hypot(rec["x"][m].double(), rec["y"][m].double())
        rb = (torch.searchsorted(self.edges, r, right=True) - 1).clamp_(0, self.nr - 1)
        nb = self.bins.index(n)
        flat = (ch * self.nr + rb) * self.nb + nb
        self.hw.index_add_(0, flat, w)
        self.hwn.index_add_(0, flat, w * n.double())
        self.hw2.index_add_(0, ch * self.nb + nb, w * w)
        t = rec["kind"] == KIND_TRUNCATED
        if bool(t.any()):
            self.trunc.append((rec["ch"][t].cpu().numpy(), rec["w"][t].double().cpu().numpy(),
                               rec["ncoll"][t].cpu().numpy()))

    def channel(self, c: int) -> dict[str, np.ndarray]:
        sl = slice(c * self.nr * self.nb, (c + 1) * self.nr * self.nb)
        tw = [(w[ch == c], n[ch == c]) for ch, w, n in self.trunc]
        return {
            "hw": self.hw[sl].reshape(self.nr, self.nb).cpu().numpy(),
            "hwn": self.hwn[sl].reshape(self.nr, self.nb).cpu().numpy(),
            "hw2": self.hw2[c * self.nb:(c + 1) * self.nb].cpu().numpy(),
            "trunc_w": np.concatenate([t[0] for t in tw]) if tw else np.zeros(0),
            "trunc_n": np.concatenate([t[1] for t in tw]).astype(np.float64) if tw else np.zeros(0),
        }


def _matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a @ b (float64) by torch, on the torch threads the command set (``--threads``, 1 by default): numpy's
    BLAS picks its own thread count, and OpenBLAS's sums differ in the last bit between 1 and 2 threads,
    so one process and a cluster's single-threaded workers would not write the same table bit for bit."""
    return (torch.from_numpy(np.ascontiguousarray(a, dtype=np.float64))
            @ torch.from_numpy(np.ascontiguousarray(b, dtype=np.float64))).numpy()


def reweight(hist: dict[str, np.ndarray], albedo: np.ndarray, photons: int, r_edges: np.ndarray,
             bins: CountBins) -> dict[str, np.ndarray]:
    """Tables of one g column from its histograms.

    Returns R (NA,), R_stderr (NA,), P (NA, NB) (per unit area, sum P area = 1 inside the last edge),
    frac_inside (NA,) and R_trunc_bound (NA,) (upper bound of the reflectance the capped walks could
    still have added).
    """
    hw, hwn, hw2 = hist["hw"], hist["hwn"], hist["hw2"]
    tot_w = hw.sum(0)
    nbar = np.where(tot_w > 0, hwn.sum(0) / np.where(tot_w > 0, tot_w, 1.0), bins.centres())
    nbar[:N_EXACT] = np.arange(N_EXACT)
    log_a = np.log(albedo)
    e = np.exp(np.outer(nbar, log_a))  # (NB, NA): albedo^nbar
    dev = hwn - hw * nbar[None, :]  # first-order term: sum w (n - nbar)
    praw = (_matmul(hw, e) + _matmul(dev, e) * log_a[None, :]) / photons  # (NR + 1, NA), overflow bin last
    # the first-order term can dip below 0 in far bins holding a handful of photons; the exact sum is >= 0
    praw = np.clip(praw, 0.0, None)
    r_tot = praw.sum(0)
    ev2 = _matmul(hw2[None], np.exp(np.outer(nbar, 2.0 * log_a)))[0] / photons
    r_se = np.sqrt(np.clip(ev2 - r_tot**2, 0.0, None) / max(photons - 1, 1))
    inside = praw[:-1].sum(0)
    area = math.pi * np.diff(r_edges**2)
    safe = np.where(inside > 0, inside, 1.0)
    p = np.where(inside[:, None] > 0, praw[:-1].T / safe[:, None] / area[None, :], 0.0)
    trunc = (hist["trunc_w"][:, None] * np.exp(np.outer(hist["trunc_n"], log_a))).sum(0) / photons
    return {"R": r_tot, "R_stderr": r_se, "P": p, "frac_inside": inside / np.where(r_tot > 0, r_tot, 1.0),
            "R_trunc_bound": trunc}


def simulate_columns(
    g_values: np.ndarray,
    albedo: np.ndarray,
    photons: int,
    *,
    seed: int = 0,
    device: str | torch.device = "cpu",
    dtype: torch.dtype = torch.float32,
    max_steps: int = MAX_STEPS,
    path_c: float | None = PATH_C,
    n_medium: float = N_TISSUE,
    r_edges_mfp: np.ndarray = R_EDGES_MFP,
    compile: bool = False,
    pool_packets: int | None = None,
    progress=None,
    engine: str = "auto",
    threads: int | None = None,
) -> list[dict[str, np.ndarray]]:
    """One non-absorbing run over the g columns ``g_values`` (as channels); tables for each column.

    ``engine``, ``threads``: the walker's (``training.sim.transport.simulate``)."""
    dev = torch.device(device)
    g_values = np.asarray(g_values, dtype=np.float64)
    ng = g_values.size
    medium = LayeredMedium(
        torch.zeros(1, ng), torch.ones(1, ng), torch.tensor(g_values)[None], torch.tensor([math.inf]),
        n_medium=n_medium,
    )
    n0 = None if path_c is None else [path_c / (1.0 - g) for g in g_values]
    pool = pool_packets or (1 << 18 if dev.type == "cpu" else 1 << 22)
    cfg = WalkConfig(illumination="diffuse", pool_packets=pool, max_steps=max_steps, path_roulette_n0=n0)
    walker = Walker(medium, cfg, seed=seed, device=dev, dtype=dtype, compile=compile, engine=engine,
                    threads=threads)
    bins = CountBins(max_steps + 1)
    edges = np.asarray(r_edges_mfp, dtype=np.float64)
    hist = _Histograms(ng, torch.tensor(edges, device=dev), bins, dev)
    walker.run(Source(int(photons), ng), hist, progress=progress)
    return [reweight(hist.channel(c), albedo, photons, edges, bins) for c in range(ng)]


def column_seed(seed: int, j: int) -> int:
    """Seed of g column j: independent of how columns are batched."""
    return fmix32_int(seed * 1_000_003 + j) & 0x7FFFFFFF


#: Default number of simulated g nodes; more requested columns are interpolated between them.
G_NODES = 48
#: g columns walked together in one run (they share the walk's tail of long-lived packets).
COLUMN_BATCH = 8


def build_lut(
    out: str | Path,
    albedo_n: int,
    g_n: int,
    photons: int,
    *,
    seed: int = 0,
    device: str = "cpu",
    albedo_range: tuple[float, float] = (ALBEDO_MIN, ALBEDO_MAX),
    g_range: tuple[float, float] = (G_MIN, G_MAX),
    g_nodes: int | None = None,
    max_steps: int = MAX_STEPS,
    compile: bool = False,
    shard: tuple[int, int] = (0, 1),
    progress: bool = False,
    log=print,
    job=None,
) -> Path | None:
    """Build the LUT file ``out`` (.npz, docs/contracts.md §2 keys plus R_stderr, R_trunc_bound, frac_inside, photons,
    g_nodes).

    ``g_nodes`` (default min(g_n, G_NODES)) g values spanning ``g_range`` are simulated with ``photons``
    each; the g_n table columns are interpolated between them along g (monotone cubic, PCHIP: no
    overshoot, so P stays >= 0; P is renormalised).  Columns at a node are the node's simulation.  The
    interpolated columns carry at most the nodes' noise; ``training.bench.sim`` measures the
    interpolation error against direct columns.

    Resumable: g nodes are walked COLUMN_BATCH at a time and each is written to
    ``<out>.parts/g_XXXX.npz``; a rerun with the same arguments skips finished batches (a kill loses at
    most the batch in progress).  ``shard`` (I, N): this process walks batches b = I (mod N); the table
    is written by whichever process finds every batch done (returns None otherwise).  ``job``
    (``training.cluster.engine.Job``): the unfinished batches are walked as its tasks instead, each writing
    its nodes' files as this process would (same seeds, same files, same table).
    """
    out = Path(out)
    if photons < 2:
        raise ValueError("photons must be >= 2")
    albedo = albedo_grid(albedo_n, *albedo_range)
    gs = g_grid(g_n, *g_range)
    n_nodes = min(g_n, G_NODES) if g_nodes is None else int(g_nodes)
    if not 2 <= n_nodes <= g_n:
        raise ValueError(f"g_nodes must be in [2, g_n = {g_n}], got {n_nodes}")
    nodes = g_grid(n_nodes, *g_range)
    parts = out.with_name(out.name + ".parts")
    parts.mkdir(parents=True, exist_ok=True)
    manifest = {"albedo": albedo.tolist(), "g": nodes.tolist(), "photons": int(photons), "seed": int(seed),
                "max_steps": int(max_steps), "r_edges_mfp": R_EDGES_MFP.tolist(), "n": N_TISSUE,
                "path_c": PATH_C, "delta_n": DELTA_N, "n_exact": N_EXACT, "column_batch": COLUMN_BATCH}
    mpath = parts / "manifest.json"
    if mpath.exists() and json.loads(mpath.read_text()) != manifest:
        raise ValueError(f"{parts} holds columns of a different LUT build; remove it or change --out")
    _check_parts(parts)
    mpath.write_text(json.dumps(manifest))
    t0 = time.perf_counter()
    if job is None:
        _walk_nodes(parts, nodes, albedo, photons, seed, device, max_steps, compile, shard, progress)
    else:
        for batch in _pending_batches(parts, nodes.size, shard):
            job.submit(f"lut g nodes {batch[0]}-{batch[-1]}", walk_batch, parts, nodes, batch, albedo, photons, seed,
                       device, max_steps, compile)
        job.wait()
    missing = [j for j in range(n_nodes) if not (parts / f"g_{j:04d}.npz").exists()]
    if missing:
        log(f"shard {shard[0]}/{shard[1]} done; {len(missing)} g nodes left to other shards: run any shard "
            "again when they have finished to write the table")
        return None
    node_cols = [dict(np.load(parts / f"g_{j:04d}.npz")) for j in range(n_nodes)]
    table = _columns_at(node_cols, nodes, gs, R_EDGES_MFP)
    with atomic_file(out) as f:
        np.savez(f, albedo=albedo, g=gs, r_edges_mfp=np.array(R_EDGES_MFP), **table,
                 photons=np.int64(photons), n_medium=np.float64(N_TISSUE), g_nodes=nodes)
    log(f"LUT {albedo_n}x{g_n} ({n_nodes} simulated g nodes), {photons} photons per node -> {out} "
        f"({time.perf_counter() - t0:.1f} s)")
    return out


def _check_parts(parts: Path) -> None:
    """ValueError naming the first node file in ``parts`` that is not a whole .npz (a copy cut short, a full
    disk), so that a resume does not stop halfway with a zip error."""
    for path in sorted(parts.glob("g_*.npz")):
        try:
            check_input(path, "LUT part file", "npz")
        except InputError as exc:
            raise ValueError(f"{exc}; delete it and run the same command again to recompute it") from None


def _batches(n_nodes: int, shard: tuple[int, int]) -> list[list[int]]:
    """This shard's batches of g-node indices (COLUMN_BATCH at a time; batch b goes to shard b mod N)."""
    batches = [list(range(b, min(b + COLUMN_BATCH, n_nodes))) for b in range(0, n_nodes, COLUMN_BATCH)]
    return [b for i, b in enumerate(batches) if i % shard[1] == shard[0]]


def _pending_batches(parts: Path, n_nodes: int, shard: tuple[int, int]) -> list[list[int]]:
    """This shard's batches with a node file still missing."""
    return [b for b in _batches(n_nodes, shard) if not all((parts / f"g_{j:04d}.npz").exists() for j in b)]


def walk_batch(parts: Path, nodes: np.ndarray, batch: list[int], albedo: np.ndarray, photons: int, seed: int,
               device: str, max_steps: int, compile: bool, progress=None) -> list[str]:
    """Walk the g nodes ``batch`` in one run (seed ``column_seed(seed, batch[0])``) and write each node's
    tables to parts/g_XXXX.npz (renamed into place: a kill leaves no half file); returns the files."""
    cols = simulate_columns(nodes[batch], albedo, photons, seed=column_seed(seed, batch[0]), device=device,
                            max_steps=max_steps, compile=compile, progress=progress)
    for j, col in zip(batch, cols, strict=True):
        with atomic_file(parts / f"g_{j:04d}.npz") as f:
            np.savez(f, **col)
    return [str(parts / f"g_{j:04d}.npz") for j in batch]


def _walk_nodes(parts: Path, nodes: np.ndarray, albedo: np.ndarray, photons: int, seed: int, device: str,
                max_steps: int, compile: bool, shard: tuple[int, int], progress: bool) -> None:
    """Walk this shard's unfinished batches of g nodes; each node's table goes to parts/g_XXXX.npz."""
    mine = _batches(nodes.size, shard)
    todo = _pending_batches(parts, nodes.size, shard)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=sum(len(b) for b in mine) * photons, unit="photon", unit_scale=True, smoothing=0.05)
        bar.update(sum(len(b) for b in mine if b not in todo) * photons)
    for batch in todo:
        walk_batch(parts, nodes, batch, albedo, photons, seed, device, max_steps, compile,
                   progress=bar.update if bar else None)
    if bar:
        bar.close()


def _columns_at(node_cols: list[dict], nodes: np.ndarray, gs: np.ndarray, r_edges: np.ndarray) -> dict:
    """Tables at the g values ``gs`` from the simulated node columns: (NA, NG, ...) arrays.

    Monotone cubic (PCHIP) interpolation along g of R, P, frac_inside; linear for the error bounds
    (R_stderr, R_trunc_bound).  P is clipped at 0 and renormalised to sum P area = 1.
    """
    from scipy.interpolate import PchipInterpolator

    stack = lambda k: np.stack([c[k] for c in node_cols], axis=1)  # noqa: E731  (NA, n_nodes, ...)
    if nodes.size == gs.size and np.allclose(nodes, gs, rtol=0, atol=1e-12):
        return {k: stack(k) for k in ("R", "P", "R_stderr", "R_trunc_bound", "frac_inside")}
    def pchip(k: str) -> np.ndarray:
        with np.errstate(divide="ignore", over="ignore"):  # flat (zero-slope) stretches: handled by PCHIP
            return PchipInterpolator(nodes, stack(k), axis=1)(gs)

    lin = lambda k: np.stack([np.interp(gs, nodes, row) for row in stack(k)])  # noqa: E731
    p = np.clip(pchip("P"), 0.0, None)
    norm = (p * (math.pi * np.diff(r_edges**2))).sum(-1, keepdims=True)
    p = np.where(norm > 0, p / np.where(norm > 0, norm, 1.0), 0.0)
    table = {"R": np.clip(pchip("R"), 0.0, 1.0), "P": p, "R_stderr": lin("R_stderr"),
             "R_trunc_bound": lin("R_trunc_bound"), "frac_inside": np.clip(pchip("frac_inside"), 0.0, 1.0)}
    for j, g in enumerate(gs):  # columns at a node: the node's own tables, bit for bit
        hit = np.flatnonzero(np.isclose(nodes, g, rtol=0, atol=1e-12))
        if hit.size:
            for k in table:
                table[k][:, j] = node_cols[hit[0]][k]
    return table
