"""Fits made consistent along wavelength: a warm-started sweep in wavelength order.

The mixture fits are degenerate: quite different (alpha, g, sigma_t, w) render the same profile, and
which of these basins a fit lands in depends on its start.  Fitted independently, or warm-started from
the nearest anchor (``fit --continuity anchors``), neighbouring wavelengths
can sit in different basins, and a decoder supervised by them learns the jumps.

``fit_tones_sweep`` fits every tone's wavelengths in order, each from the previous wavelength's solution:

1. *Anchors* (every ``anchor_every``-th fitted wavelength, the first one included) get the full schedule
   of ``optimize.fit_schedule`` (coarse search, all starts), batched: the independent fits.
2. *Sweep*: from the first anchor, wavelength i is one warm LM run per K from the solution kept at i - 1
   (``fit_schedule(warm=...)``), so it stays in that basin.  At an anchor the continuation is kept
   where its joint loss is within the tolerance of the independent fit (``CONTINUITY_RTOL`` relative,
   ``CONTINUITY_ATOL`` absolute: "an equally good solution exists in the same basin"), or lower;
   otherwise the anchor's fit replaces it and the sweep goes on from there.
3. *Repair*: where the continuation was rejected at an anchor, the segment before it may have drifted
   into a worse basin.  It is swept again backwards from the anchor's fit, and for each such (tone, K)
   the one switch point between the forward and the backward solutions with the lowest summed loss over
   the segment is kept (the forward sweep everywhere if that is best).
4. The components are matched along wavelength (``training.fit.matching``), since the K - 1 fallback of
   a warm run and a replaced anchor bring their own order.

Cost: the anchors' full schedules as before, plus one warm run per other wavelength (as the nearest-anchor
warm starts cost), plus one per anchor and the repairs; each warm run now starts one fitted wavelength
away instead of up to half an anchor spacing.  The sweep is sequential in wavelength, batched over the
tones of a chunk: a larger ``--chunk-tones`` amortises the per-call overhead (measured in docs/research/fitting.md).
"""

from __future__ import annotations

import time

import numpy as np
import torch

from training.fit.matching import matched
from training.fit.mixture import g_bounds, unpack
from training.fit.optimize import WARM_LM_ITERS, FitResult, fit_schedule
from training.sim.lut_interp import LookupTables

#: "Equally good" at an anchor: the continuation's joint loss at most this much above the independent
#: fit's, relative (our choice: well inside the spread of the K = 3 fits' shape excess over tones; the
#: sweep: docs/research/fitting.md).
CONTINUITY_RTOL: float = 0.01
#: ... or this much absolute (tones whose loss is near 0).
CONTINUITY_ATOL: float = 1e-3
METRICS: tuple[str, ...] = ("shape_rmse", "refl_rel_err", "joint")


class _Store:
    """The kept solution per K at every (tone, wavelength): theta (T, W, 4K - 1) and the metrics (T, W)."""

    def __init__(self, kall: tuple[int, ...], T: int, W: int, like: torch.Tensor):
        self.theta = {k: torch.zeros(T, W, 4 * k - 1, dtype=like.dtype, device=like.device) for k in kall}
        self.metric = {k: {m: torch.zeros(T, W, dtype=like.dtype, device=like.device) for m in METRICS}
                       for k in kall}

    def put(self, k: int, tt: torch.Tensor, cc: torch.Tensor, res: FitResult, rows: torch.Tensor | None = None):
        """Store the rows ``rows`` (all if None) of ``res`` at (tt, cc)."""
        pick = (lambda x: x) if rows is None else (lambda x: x[rows])
        self.theta[k][tt, cc] = pick(res.theta)
        for m in METRICS:
            self.metric[k][m][tt, cc] = pick(getattr(res, m))


def fit_tones_sweep(
    lut: LookupTables,
    profile: torch.Tensor,
    R: torch.Tensor,
    stderr: torch.Tensor,
    r_edges_cm: torch.Tensor,
    photons: float,
    g_init: torch.Tensor,
    ks: tuple[int, ...],
    *,
    anchor_every: int = 12,
    relative_refl: bool = True,
    steps: dict[str, int] | None = None,
    wavelength_nm: np.ndarray | None = None,
    stats: dict | None = None,
) -> dict[int, dict[str, torch.Tensor]]:
    """Fit T tones at W wavelengths in wavelength order (module docstring): ``profile``/``stderr``
    (T, W, M), ``R`` (T, W), ``g_init`` (W,); ``anchor_every`` 0 makes every wavelength an anchor;
    ``wavelength_nm`` (W,) for the matching's reference wavelength.  Returns the layout of
    ``training.fit.dataset.fit_tones``: {K: {alpha, g, sigma_t, weight: (T, K, W); shape_rmse,
    refl_rel_err, joint: (T, W)}}, components matched along wavelength.  ``stats``, if given, is
    incremented with counts: anchors_checked, anchors_kept (per K summed), repaired (tone x K segments), and
    the CPU seconds of each step (cpu_anchors, cpu_sweep, cpu_repair)."""
    T, W, _ = profile.shape
    dev = profile.device
    kall = tuple(range(1, max(ks) + 1))
    anchors = np.arange(0, W, anchor_every) if anchor_every > 0 else np.arange(W)
    store = _Store(kall, T, W, R)

    def solve(tt: torch.Tensor, cc: torch.Tensor, warm: dict | None = None, n: dict | None = None):
        return fit_schedule(lut, profile[tt, cc], R[tt, cc], r_edges_cm, photons, stderr=stderr[tt, cc],
                            g_init=g_init[cc], ks=kall, method="lm", relative_refl=relative_refl, warm=warm, steps=n)

    warm_steps = {k: min(v, (steps or {}).get(k, v)) for k, v in WARM_LM_ITERS.items()}  # steps cut them short
    tones = torch.arange(T, device=dev)
    clock = time.process_time()

    def lap(name: str) -> None:
        nonlocal clock
        if stats is not None:
            stats[name] = stats.get(name, 0.0) + time.process_time() - clock
        clock = time.process_time()

    # 1. anchors: the full schedule, batched over tones x anchors
    ta = tones.repeat_interleave(len(anchors))
    ca = torch.as_tensor(anchors, device=dev).repeat(T)
    indep = solve(ta, ca, n=steps)
    anchor_fit = {k: {"theta": indep[k].theta.reshape(T, len(anchors), -1),
                      **{m: getattr(indep[k], m).reshape(T, len(anchors)) for m in METRICS}} for k in kall}
    for k in kall:
        store.put(k, ta, ca, indep[k])
    lap("cpu_anchors")
    # 2. the forward sweep
    rank = {int(a): j for j, a in enumerate(anchors)}
    lost = {k: torch.zeros(T, len(anchors), dtype=torch.bool, device=dev) for k in kall}
    for i in range(1, W):
        col = torch.full((T,), i, device=dev)
        cont = solve(tones, col, warm={k: store.theta[k][:, i - 1] for k in kall}, n=warm_steps)
        for k in kall:
            if i not in rank:
                store.put(k, tones, col, cont[k])
                continue
            j = rank[i]
            ref = anchor_fit[k]["joint"][:, j]
            keep = cont[k].joint <= ref + torch.clamp(CONTINUITY_RTOL * ref, min=CONTINUITY_ATOL)
            lost[k][:, j] = ~keep
            store.put(k, tones[keep], col[keep], cont[k], keep)
            if stats is not None:
                stats["anchors_checked"] = stats.get("anchors_checked", 0) + T
                stats["anchors_kept"] = stats.get("anchors_kept", 0) + int(keep.sum())
    lap("cpu_sweep")
    # 3. repair the segments ending at a rejected anchor
    _repair(solve, store, anchors, lost, kall, warm_steps, stats)
    lap("cpu_repair")
    # 4. physical parameters, matched along wavelength
    lo, hi = g_bounds(lut)
    out: dict[int, dict[str, torch.Tensor]] = {}
    for k in ks:
        m = unpack(store.theta[k], k, lo, hi)  # fields (T, W, K)
        arrays = {"alpha": m.alpha, "g": m.g, "sigma_t": m.sigma_t, "weight": m.w}
        arrays = matched({n: v.transpose(1, 2).cpu().numpy() for n, v in arrays.items()}, wavelength_nm)
        res = {n: torch.as_tensor(v, device=dev) for n, v in arrays.items()}
        out[k] = {**res, **store.metric[k]}
    return out


def _repair(solve, store: _Store, anchors: np.ndarray, lost: dict[int, torch.Tensor], kall: tuple[int, ...],
            warm_steps: dict[str, int], stats: dict | None) -> None:
    """Step 3 of the module docstring, batched over the (tone, segment) pairs with any K rejected."""
    any_lost = torch.stack([lost[k] for k in kall]).any(0)  # (T, n_anchors)
    t_idx, j_idx = torch.nonzero(any_lost[:, 1:], as_tuple=True)  # anchor j + 1 closes segment j
    if t_idx.numel() == 0:
        return
    start = torch.as_tensor(anchors, device=t_idx.device)[j_idx]  # segment (start, end): interior positions
    end = torch.as_tensor(anchors, device=t_idx.device)[j_idx + 1]
    length = int((end - start - 1).max())
    if length <= 0:
        return
    P = len(t_idx)
    back = {k: {"theta": torch.zeros(P, length, 4 * k - 1, dtype=store.theta[k].dtype, device=t_idx.device),
                **{m: torch.full((P, length), float("inf"), dtype=store.theta[k].dtype, device=t_idx.device)
                   for m in METRICS}} for k in kall}
    warm = {k: store.theta[k][t_idx, end] for k in kall}
    for d in range(1, length + 1):  # position end - d; offset end - d - start - 1 inside the segment
        act = torch.nonzero(end - d > start).squeeze(1)
        if act.numel() == 0:
            break
        col = end[act] - d
        res = solve(t_idx[act], col, warm={k: warm[k][act] for k in kall}, n=warm_steps)
        off = col - start[act] - 1
        for k in kall:
            back[k]["theta"][act, off] = res[k].theta
            warm[k][act] = res[k].theta
            for m in METRICS:
                back[k][m][act, off] = getattr(res[k], m)
    pos = torch.arange(length, device=t_idx.device)
    inside = pos[None, :] < (end - start - 1)[:, None]  # (P, length)
    cols = (start[:, None] + 1 + pos[None, :]).clamp(max=store.theta[kall[0]].shape[1] - 1)
    for k in kall:
        rows = lost[k][t_idx, j_idx + 1]
        if not rows.any():
            continue
        fwd = torch.where(inside, store.metric[k]["joint"][t_idx[:, None], cols], torch.zeros(()))
        bwd = torch.where(inside, back[k]["joint"], torch.zeros(()))
        # cost of switching at s (0..length): forward before s, backward from s on
        zero = torch.zeros(P, 1, dtype=fwd.dtype, device=fwd.device)
        cost = torch.cat([zero, fwd.cumsum(1)], 1) + (bwd.sum(1, keepdim=True) - torch.cat([zero, bwd.cumsum(1)], 1))
        s = cost.argmin(1)
        use_back = inside & (pos[None, :] >= s[:, None]) & rows[:, None]
        p_i, o_i = torch.nonzero(use_back, as_tuple=True)
        tt, cc = t_idx[p_i], cols[p_i, o_i]
        store.theta[k][tt, cc] = back[k]["theta"][p_i, o_i]
        for m in METRICS:
            store.metric[k][m][tt, cc] = back[k][m][p_i, o_i]
        if stats is not None:
            stats["repaired"] = stats.get("repaired", 0) + int((use_back.any(1) & rows).sum())
