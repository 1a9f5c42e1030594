"""The fused, branch-free step of the packet walker, and its counter-based random numbers.

``step_packets`` is a pure function of tensors (no Python branching on data, no in-place writes), so
the same code runs eagerly on CPU / CUDA or compiled by ``torch.compile`` into one loop.

Random numbers: every step needs 4 uniforms per packet.  Drawing them from a torch.Generator costs
more than the rest of a compiled step, so they come from a counter-based hash instead (hand-written:
torch has no vectorised counter-based generator usable inside compiled code): u = F(key ^ salt_j),
with F the MurmurHash3 32-bit finaliser (Appleby), ``key`` a per-packet 32-bit value (a bijective hash
of the packet's launch serial number and the seed, drawn from the run's torch.Generator seed) and
``salt_j`` = F(4 * step + j + seed).  F is a bijection, so packets launched in one run get distinct
keys and distinct numbers at each step.  Results are deterministic for a given seed and pool size.
"""

from __future__ import annotations

import torch

from training.sim.physics import fresnel_unpolarised, hg_cos, rotate
from training.sim.walk_constants import (  # noqa: F401 - the fates, re-exported for the engines' users
    KIND_ABSORBED,
    KIND_REFLECTED,
    KIND_TRANSMITTED,
    KIND_TRUNCATED,
    KIND_UNSCATTERED,
    MAX_HOP_CM,
)

_M1 = 0x85EBCA6B - (1 << 32)  # MurmurHash3 fmix32 constants as signed int32
_M2 = 0xC2B2AE35 - (1 << 32)


def fmix32(h: torch.Tensor) -> torch.Tensor:
    """MurmurHash3 32-bit finaliser on an int32 tensor (wrapping arithmetic; logical shifts)."""
    h = h ^ ((h >> 16) & 0xFFFF)
    h = h * _M1
    h = h ^ ((h >> 13) & 0x7FFFF)
    h = h * _M2
    return h ^ ((h >> 16) & 0xFFFF)


def fmix32_int(v: int) -> int:
    """The same finaliser on a Python int; returns a signed 32-bit value."""
    h = v & 0xFFFFFFFF
    h ^= h >> 16
    h = (h * 0x85EBCA6B) & 0xFFFFFFFF
    h ^= h >> 13
    h = (h * 0xC2B2AE35) & 0xFFFFFFFF
    h ^= h >> 16
    return h - (1 << 32) if h >= 1 << 31 else h


def uniform(key: torch.Tensor, salt: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """Uniform numbers in (0, 1) (24 bits, never 0 or 1) from int32 keys and an int32 salt."""
    h = fmix32(key ^ salt)
    return ((h >> 8) & 0xFFFFFF).to(dtype) * (2.0**-24) + 2.0**-25


def step_packets(
    x, y, z, ux, uy, uz, w, s, absorbed, layer, ch, key, ncoll, alive, kind, path, salt,
    t_mut, t_alb, t_g, t_ztop, t_zbot, n: float, n_below: float, n_layers: int, n_ch: int,
):
    """One hop of every packet: to its next interaction, or to the next boundary if that is nearer.

    Inputs (1-D, one entry per packet; float tensors in the walk dtype): position x, y, z (cm),
    direction ux, uy, uz, weight w, remaining optical depth s, absorbed weight so far, layer and ch
    (int64), key (int32), ncoll (int32), alive (bool), kind (int8), path (P, L) or None; salt (4,)
    int32; property tables t_mut, t_alb, t_g (L * C,) and layer tops / bottoms t_ztop, t_zbot (L,).

    At a boundary: internal ones are crossed (index-matched); at the top surface (to air) and at the
    bottom of a finite stack (to n_below) the packet is reflected with the Fresnel probability or
    escapes (alive -> False, kind set).  At an interaction: w *= albedo (the rest is absorbed), HG
    scattering.  Returns the updated (x, y, z, ux, uy, uz, w, s, absorbed, layer, ncoll, alive, kind,
    path).  Dead packets do not move and tally nothing.
    """
    dt = x.dtype
    k = layer * n_ch + ch
    mut, alb, g = t_mut[k], t_alb[k], t_g[k]
    zwall = torch.where(uz > 0, t_zbot[layer], t_ztop[layer])
    db = (zwall - z) / uz  # distance to the boundary ahead (inf or nan when uz == 0)
    di = s / mut  # distance to the interaction (inf in a transparent layer)
    hit = (db < di) & alive
    d = torch.where(hit, db, di)
    d = torch.where(alive, d, torch.zeros_like(d)).clamp(0.0, MAX_HOP_CM)
    x = x + d * ux
    y = y + d * uy
    z = torch.where(hit, zwall, z + d * uz)
    if path is not None:
        lay_ids = torch.arange(n_layers, device=layer.device)
        path = path + d.unsqueeze(1) * (layer.unsqueeze(1) == lay_ids).to(dt)
    u0, u1, u2, u3 = uniform(key.unsqueeze(0), salt.unsqueeze(1), dt).unbind(0)
    # --- boundary events
    up = uz < 0
    top = hit & up & (layer == 0)
    bot = hit & ~up & (layer == n_layers - 1)
    surf = top | bot
    n_out = torch.where(top, torch.ones_like(uz), torch.full_like(uz, n_below))
    refl = surf & (u3 < fresnel_unpolarised(uz, n, n_out))
    esc = surf & ~refl
    cross = hit & ~surf
    layer = layer + torch.where(cross, torch.where(up, -1, 1), 0)
    kind = torch.where(
        esc,
        torch.where(top, KIND_REFLECTED, torch.where(ncoll == 0, KIND_UNSCATTERED, KIND_TRANSMITTED)),
        kind.to(torch.int64),
    ).to(torch.int8)
    # --- interactions: absorb by weight, then scatter
    inter = alive & ~hit
    s = torch.where(hit, (s - db * mut).clamp_min(0.0), -torch.log(u0))
    dw = torch.where(inter, w * (1.0 - alb), torch.zeros_like(w))
    w = w - dw
    absorbed = absorbed + dw
    nx, ny, nz = rotate(ux, uy, uz, hg_cos(g, u1), u2)
    ux = torch.where(inter, nx, ux)
    uy = torch.where(inter, ny, uy)
    uz = torch.where(inter, nz, torch.where(refl, -uz, uz))
    ncoll = ncoll + inter.to(torch.int32)
    alive = alive & ~esc
    return x, y, z, ux, uy, uz, w, s, absorbed, layer, ncoll, alive, kind, path


#: Names of ``step_packets``' outputs, in order (the walker's state keys).
STEP_OUT = ("x", "y", "z", "ux", "uy", "uz", "w", "s", "absorbed", "layer", "ncoll", "alive", "kind", "path")
