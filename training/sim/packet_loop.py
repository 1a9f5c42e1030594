"""The compiled per-packet walk (numba): each packet walked to its end in a scalar loop, packets in parallel.

The same physics as the vectorised step (``training.sim.kernel.step_packets``; MCML hop / drop / spin, see
``training.sim.walker``), written as one loop per packet in float64, compiled by numba and run over the
packets of a batch with ``prange`` on every thread numba is given.  A scalar loop does only the work of its
own packet (no masked lanes, no pool compaction, no per-step tensor traffic), which is what makes it
several times faster per core than the vectorised step on a CPU.

Random numbers: packet ``q`` of a run (its serial number in the run's ``Source``) owns the SplitMix64
stream (Steele, Lea & Flood 2014, the seeder of java.util.SplittableRandom) started at
mix(run key ^ mix(q)), with mix the SplitMix64 finaliser: a packet's walk depends on the seed and on q
only, so a run's records are the same bit for bit whatever the thread count, the batch size or the
order in which threads pick packets up.  Uniforms have 53 bits and lie in (0, 1); the azimuth's point of
the unit disc takes the two 32-bit halves of one output; free path lengths (standard exponentials) come from
the ziggurat of numpy's ``Generator.standard_exponential`` (Marsaglia & Tsang's tables for 53-bit integers),
which needs a logarithm in ~1 % of the draws only.

Differences from the vectorised step, none of which changes the estimand: the walk is float64 (the step's
dtype does not apply), roulettes are decided right after each interaction (the step checks every
``check_every`` steps), the walk cap ends a packet after exactly ``max_steps`` steps, and a step draws
only the uniforms it uses.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from contextlib import contextmanager

import numba
import numpy as np

from training.sim.walk_constants import (
    G_ISOTROPIC_EPS,
    KIND_ABSORBED,
    KIND_REFLECTED,
    KIND_TRANSMITTED,
    KIND_TRUNCATED,
    KIND_UNSCATTERED,
    MAX_HOP_CM,
)

#: Packets per block of the parallel loop: blocks are handed to threads dynamically (walk lengths vary
#: by orders of magnitude), and a block is long enough that scheduling costs nothing.
BLOCK_PACKETS = 64

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S11, _S27, _S30, _S31 = np.uint64(11), np.uint64(27), np.uint64(30), np.uint64(31)
_S32, _LOW32 = np.uint64(32), np.uint64(0xFFFFFFFF)
_TWO_M53 = 2.0**-53
_TWO_M31 = 2.0**-31
_TWO_PI = 2.0 * math.pi
_INF = math.inf


def _exponential_ziggurat(layers: int = 256, r: float = 7.69711747013104972, v: float = 3.949659822581572e-3,
                          bits: int = 53) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tables (k, w, f) of the exponential ziggurat (Marsaglia & Tsang 2000, J. Stat. Softw. 5(8), ``zigset``),
    for ``bits``-bit integers as numpy's ``random_standard_exponential`` draws them: ``layers`` strips of area
    ``v`` each, the base strip ending at ``r``.  k: acceptance bounds (uint64), w: integer-to-x scales, f: exp(-x)
    at the strips' edges."""
    m = 2.0**bits
    k, w, f = np.zeros(layers, np.uint64), np.zeros(layers), np.zeros(layers)
    de = te = r
    q = v / math.exp(-de)
    k[0], w[0], w[-1], f[0], f[-1] = np.uint64(de / q * m), q / m, de / m, 1.0, math.exp(-de)
    for i in range(layers - 2, 0, -1):
        de = -math.log(v / de + math.exp(-de))
        k[i + 1] = np.uint64(de / te * m)
        te = de
        f[i], w[i] = math.exp(-de), de / m
    return k, w, f


_ZIG_K, _ZIG_W, _ZIG_F = _exponential_ziggurat()
_ZIG_R = 7.69711747013104972
_S3, _S8, _LOW8 = np.uint64(3), np.uint64(8), np.uint64(0xFF)


def mix64_py(v: int) -> int:
    """The SplitMix64 finaliser on a Python int (for run keys); returns an unsigned 64-bit value."""
    m = (1 << 64) - 1
    z = v & m
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & m
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & m
    return z ^ (z >> 31)


def run_key(seed: int) -> int:
    """The 64-bit key of a run from its seed (any Python int)."""
    return mix64_py(mix64_py(int(seed)) ^ 0x5DEECE66D)


@numba.njit(cache=True, inline="always")
def _mix64(z):
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


@numba.njit(cache=True, inline="always")
def _uniform(state):
    """Advance a SplitMix64 state; returns (new state, uniform in (0, 1))."""
    state = state + _GOLDEN
    z = _mix64(state)
    return state, (float(np.int64(z >> _S11)) + 0.5) * _TWO_M53  # < 2^53: a signed conversion is exact


@numba.njit(cache=True)
def _exponential_slow(state, idx, x):
    """The ziggurat's rare cases (~1.1 % of draws): the tail beyond r, the wedge test, or a fresh draw."""
    while True:
        if idx == 0:  # the tail: r + a standard exponential
            state, u = _uniform(state)
            return state, _ZIG_R - math.log(u)
        state, u = _uniform(state)
        if (_ZIG_F[idx - 1] - _ZIG_F[idx]) * u + _ZIG_F[idx] < math.exp(-x):
            return state, x
        state, idx, x, accept = _ziggurat_draw(state)
        if accept:
            return state, x


@numba.njit(cache=True, inline="always")
def _ziggurat_draw(state):
    """One ziggurat step from a fresh SplitMix64 output: (new state, strip index, x, whether x lies inside the
    strip's rectangle and is accepted at once)."""
    state = state + _GOLDEN
    ri = _mix64(state) >> _S3
    idx = int(ri & _LOW8)
    ri = ri >> _S8
    return state, idx, float(np.int64(ri)) * _ZIG_W[idx], ri < _ZIG_K[idx]


@numba.njit(cache=True, inline="always")
def _exponential(state):
    """Advance a SplitMix64 state; returns (new state, a standard exponential variate) by the ziggurat (the
    algorithm of numpy's ``Generator.standard_exponential``: 53 bits of one output for x, 8 for the strip),
    without a logarithm in ~98.9 % of the draws."""
    state, idx, x, accept = _ziggurat_draw(state)
    if accept:
        return state, x
    return _exponential_slow(state, idx, x)


@numba.njit(cache=True)
def exponential_samples(seed: int, count: int) -> np.ndarray:
    """``count`` draws of the walk's exponential sampler from the stream of packet 0 of run ``seed`` (checks)."""
    state = _mix64(np.uint64(seed) ^ _mix64(np.uint64(0)))
    out = np.empty(count)
    for i in range(count):
        state, out[i] = _exponential(state)
    return out


@numba.njit(cache=True, inline="always")
def _uniform_pair(state):
    """Advance a SplitMix64 state; returns (new state, a, b): two uniforms in (-1, 1) from the two 32-bit
    halves of one output (for the azimuth, where 32 bits are ample)."""
    state = state + _GOLDEN
    z = _mix64(state)
    a = (float(np.int64(z >> _S32)) + 0.5) * _TWO_M31 - 1.0
    b = (float(np.int64(z & _LOW32)) + 0.5) * _TWO_M31 - 1.0
    return state, a, b


@numba.njit(cache=True, inline="always")
def _fresnel(cos_i, n1, n2):
    """Unpolarised Fresnel reflectance (scalar ``physics.fresnel_unpolarised``)."""
    if n1 == n2:
        return 0.0
    ci = min(abs(cos_i), 1.0)
    ratio = n1 / n2
    sin_t2 = ratio * ratio * (1.0 - ci * ci)
    if sin_t2 >= 1.0:
        return 1.0
    ct = math.sqrt(1.0 - sin_t2)
    rs = (ratio * ci - ct) / max(ratio * ci + ct, 1e-30)
    rp = (ratio * ct - ci) / max(ratio * ct + ci, 1e-30)
    return min(max(0.5 * (rs * rs + rp * rp), 0.0), 1.0)


@numba.njit(cache=True, inline="always")
def _hg_cos(g, xi):
    """Henyey-Greenstein cosine by inversion (scalar ``physics.hg_cos``)."""
    if abs(g) < G_ISOTROPIC_EPS:
        c = 2.0 * xi - 1.0
    else:
        t = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi)
        c = (1.0 + g * g - t * t) / (2.0 * g)
    return min(max(c, -1.0), 1.0)


@numba.njit(cache=True, inline="always")
def _rotate(ux, uy, uz, cos_t, cos_phi, sin_phi):
    """New direction at polar cosine cos_t and azimuth phi (scalar ``physics.rotate``, Duff et al. frame)."""
    sign = 1.0 if uz >= 0.0 else -1.0
    a = -1.0 / (sign + uz)
    b = ux * uy * a
    sin_t = math.sqrt(max(1.0 - cos_t * cos_t, 0.0))
    c1 = sin_t * cos_phi
    c2 = sin_t * sin_phi
    nx = c1 * (1.0 + sign * ux * ux * a) + c2 * b + cos_t * ux
    ny = c1 * (sign * b) + c2 * (sign + uy * uy * a) + cos_t * uy
    nz = -(c1 * sign * ux) - c2 * uy + cos_t * uz
    return nx, ny, nz


@numba.njit(cache=True)
def _walk_one(i, ch, serial, key, t_mut, t_alb, t_g, t_ztop, t_zbot, n, n_below, n_layers, n_ch,
              diffuse, cos_in, max_steps, roulette_threshold, roulette_keep, path_n0, path_keep, record_paths,
              out_kind, out_w, out_x, out_y, out_ncoll, out_absorbed, out_path, out_specular,
              out_roulette, out_steps):
    """Walk packet ``i`` of the batch to its end and write its record into the out_* arrays."""
    c = ch[i]
    state = _mix64(key ^ _mix64(np.uint64(serial[i])))
    # --- launch at the origin, refracted into the medium
    if diffuse:
        state, u = _uniform(state)
        ci = math.sqrt(1.0 - u)  # cosine-weighted incidence
        r_sp = _fresnel(ci, 1.0, n)
        ratio = 1.0 / n
        ct = math.sqrt(max(1.0 - ratio * ratio * (1.0 - ci * ci), 0.0))
        st = math.sqrt(max(1.0 - ct * ct, 0.0))
        state, u = _uniform(state)
        phi = _TWO_PI * u
        ux, uy, uz = st * math.cos(phi), st * math.sin(phi), ct
    elif cos_in < 1.0:  # collimated at a polar angle: refracted in the x-z plane, towards +x
        r_sp = _fresnel(cos_in, 1.0, n)
        ratio = 1.0 / n
        ct = math.sqrt(max(1.0 - ratio * ratio * (1.0 - cos_in * cos_in), 0.0))
        ux, uy, uz = math.sqrt(max(1.0 - ct * ct, 0.0)), 0.0, ct
    else:
        r_sp = ((n - 1.0) / (n + 1.0)) ** 2
        ux, uy, uz = 0.0, 0.0, 1.0
    state, s = _exponential(state)
    x, y, z = 0.0, 0.0, 0.0
    w = 1.0 - r_sp
    absorbed = 0.0
    roulette = 0.0
    layer = 0
    ncoll = 0
    kind = KIND_TRUNCATED
    next_path_roulette = path_n0[c]  # n0 * 2^stage
    steps = 0
    path_here = 0.0
    if record_paths:
        for k in range(n_layers):
            out_path[i, k] = 0.0
    while True:
        k = layer * n_ch + c
        mut = t_mut[k]
        if uz > 0.0:
            zwall = t_zbot[layer]
            db = (zwall - z) / uz
        elif uz < 0.0:
            zwall = t_ztop[layer]
            db = (zwall - z) / uz
        else:
            zwall = z
            db = _INF
        di = s / mut if mut > 0.0 else _INF
        hit = db < di
        d = min(max(db if hit else di, 0.0), MAX_HOP_CM)
        x += d * ux
        y += d * uy
        path_here += d  # path in the current layer, stored when the packet leaves it
        steps += 1
        if hit:
            z = zwall
            s = max(s - db * mut, 0.0)
            if uz < 0.0 and layer == 0:  # top surface, to air
                state, u = _uniform(state)
                if u < _fresnel(uz, n, 1.0):
                    uz = -uz
                else:
                    kind = KIND_REFLECTED
                    break
            elif uz > 0.0 and layer == n_layers - 1:  # bottom of a finite stack
                state, u = _uniform(state)
                if u < _fresnel(uz, n, n_below):
                    uz = -uz
                else:
                    kind = KIND_UNSCATTERED if ncoll == 0 else KIND_TRANSMITTED
                    break
            else:
                if record_paths:
                    out_path[i, layer] += path_here
                path_here = 0.0
                layer += -1 if uz < 0.0 else 1
        else:
            z += d * uz
            state, s = _exponential(state)
            dw = w * (1.0 - t_alb[k])
            w -= dw
            absorbed += dw
            state, u1 = _uniform(state)
            while True:  # azimuth: a uniform point of the unit disc gives (cos 2 phi, sin 2 phi) (von Neumann)
                state, a, b = _uniform_pair(state)
                r2 = a * a + b * b
                if r2 <= 1.0:
                    break
            inv_r2 = 1.0 / r2
            ux, uy, uz = _rotate(ux, uy, uz, _hg_cos(t_g[k], u1), (a * a - b * b) * inv_r2, 2.0 * a * b * inv_r2)
            ncoll += 1
            if w < roulette_threshold:  # weight roulette: survive with weight w / keep
                state, u = _uniform(state)
                w_new = w / roulette_keep if (u < roulette_keep and w > 0.0) else 0.0
                roulette += w_new - w
                w = w_new
                if w == 0.0:
                    kind = KIND_ABSORBED
                    break
            if ncoll >= next_path_roulette:  # path (collision-count) roulette
                next_path_roulette *= 2.0
                state, u = _uniform(state)
                w_new = w / path_keep if u < path_keep else 0.0
                roulette += w_new - w
                w = w_new
                if w == 0.0:
                    kind = KIND_ABSORBED
                    break
        if steps >= max_steps:
            kind = KIND_TRUNCATED
            break
    if record_paths:
        out_path[i, layer] += path_here
    out_kind[i] = kind
    out_w[i] = 0.0 if kind == KIND_ABSORBED else w
    out_x[i] = x
    out_y[i] = y
    out_ncoll[i] = ncoll
    out_absorbed[i] = absorbed
    out_specular[i] = r_sp
    out_roulette[i] = roulette
    out_steps[i] = steps


@numba.njit(cache=True, parallel=True)
def walk_batch(ch, serial, key, t_mut, t_alb, t_g, t_ztop, t_zbot, n, n_below, n_layers, n_ch,
               diffuse, cos_in, max_steps, roulette_threshold, roulette_keep, path_n0, path_keep, record_paths,
               out_kind, out_w, out_x, out_y, out_ncoll, out_absorbed, out_path, out_specular,
               out_roulette, out_steps):
    """Walk every packet of a batch (parallel over blocks of ``BLOCK_PACKETS`` packets).

    Inputs: ch (m,) int64 channel, serial (m,) int64 packet serial in the run, key uint64 run key;
    property tables t_mut, t_alb, t_g (L * C,) float64 indexed by layer * C + channel, layer tops /
    bottoms t_ztop, t_zbot (L,) cm; n, n_below indices; diffuse (bool) illumination, else a collimated beam
    whose polar cosine in air is cos_in (1.0: normal incidence; below 1 the beam travels towards +x, so the
    x-z plane is the plane of incidence); max_steps walk cap;
    weight roulette below roulette_threshold with survival roulette_keep; path roulette at
    path_n0[channel] * 2^k collisions (inf: none) with survival path_keep; record_paths (bool).
    Outputs (written, length m): kind int8, w (exit weight, 0 when absorbed), x, y (exit point, cm),
    ncoll int32, absorbed weight, path (m, L) cm per layer (when record_paths), specular, roulette
    (net weight created by roulette), steps int64.
    """
    m = ch.shape[0]
    n_blocks = (m + BLOCK_PACKETS - 1) // BLOCK_PACKETS
    for b in numba.prange(n_blocks):
        for i in range(b * BLOCK_PACKETS, min(m, (b + 1) * BLOCK_PACKETS)):
            _walk_one(i, ch, serial, key, t_mut, t_alb, t_g, t_ztop, t_zbot, n, n_below, n_layers, n_ch,
                      diffuse, cos_in, max_steps, roulette_threshold, roulette_keep, path_n0, path_keep, record_paths,
                      out_kind, out_w, out_x, out_y, out_ncoll, out_absorbed, out_path, out_specular,
                      out_roulette, out_steps)


def default_threads() -> int:
    """Threads of the numba engine when none are asked for: numba's current setting, which is every CPU this
    process may run on (its affinity mask, e.g. ``taskset``) unless NUMBA_NUM_THREADS or
    ``numba.set_num_threads`` lowered it."""
    return int(numba.get_num_threads())


@contextmanager
def compiled_threads(threads: int | None):
    """Run numba parallel loops on ``threads`` threads (None: ``default_threads()``) inside the block, handing
    blocks of packets to threads one at a time (walk lengths vary by orders of magnitude)."""
    want = default_threads() if threads is None else int(threads)
    if not 1 <= want <= numba.config.NUMBA_NUM_THREADS:
        raise ValueError(f"threads must be in 1..{numba.config.NUMBA_NUM_THREADS} (the CPUs this process may use, "
                         f"or NUMBA_NUM_THREADS), got {want}")
    before = numba.get_num_threads()
    numba.set_num_threads(want)
    try:
        with numba.parallel_chunksize(1):
            yield
    finally:
        numba.set_num_threads(before)


def source_packets(q0: int, count: int, photons: int, n_channels: int, order: str) -> tuple[np.ndarray, np.ndarray]:
    """Channel and photon index (int64, (count,)) of packets q0 .. q0 + count - 1 of a run of ``photons`` per
    channel; ``order`` as ``training.sim.walker.Source``: "interleaved" or "channel_major"."""
    q = np.arange(q0, q0 + count, dtype=np.int64)
    if order == "interleaved":
        return q % n_channels, q // n_channels
    return q // photons, q % photons


#: Receives one walked batch: channel (m,), photon index (m,) and the outputs of ``walk_batch`` by name.
BatchSink = Callable[[np.ndarray, np.ndarray, dict[str, np.ndarray]], None]


def walk_compiled(tables: tuple[np.ndarray, ...], n: float, n_below: float, n_layers: int, n_ch: int, *,
                  photons: int, order: str, seed: int, diffuse: bool, pool_packets: int, max_steps: int,
                  roulette_threshold: float, roulette_boost: float, path_n0: np.ndarray, path_keep: float,
                  record_paths: bool, threads: int | None, sink: BatchSink,
                  walk: Callable = walk_batch, cos_in: float = 1.0) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Walk every packet of a run in batches of ``pool_packets`` (each batch to its end), handing each batch to
    ``sink``.

    tables: (t_mut, t_alb, t_g, t_ztop, t_zbot) float64 as ``walk_batch`` takes them; path_n0 (n_ch,) path
    roulette thresholds (inf: none); walk: ``walk_batch`` or ``packet_loop_cuda.walk_batch_cuda``; cos_in: the
    polar cosine in air of a collimated beam (``diffuse`` False; 1.0: normal incidence).
    Returns the per-channel specular and roulette balance sums (n_ch,) float64 (added packet by packet, so they
    do not depend on the batch size), the total packet steps and the longest walk in steps.
    """
    key = np.uint64(run_key(seed))
    spec, roul = np.zeros(n_ch), np.zeros(n_ch)
    packet_steps = longest = 0
    total = photons * n_ch
    with compiled_threads(threads):
        for q0 in range(0, total, pool_packets):
            m = min(pool_packets, total - q0)
            ch, pid = source_packets(q0, m, photons, n_ch, order)
            out = {"kind": np.empty(m, np.int8), "w": np.empty(m), "x": np.empty(m), "y": np.empty(m),
                   "ncoll": np.empty(m, np.int32), "absorbed": np.empty(m),
                   "path": np.empty((m, n_layers) if record_paths else (1, n_layers)),
                   "specular": np.empty(m), "roulette": np.empty(m), "steps": np.empty(m, np.int64)}
            walk(ch, np.arange(q0, q0 + m, dtype=np.int64), key, *tables, n, n_below, n_layers, n_ch, diffuse,
                 float(cos_in), max_steps, roulette_threshold, 1.0 / roulette_boost, path_n0, path_keep, record_paths,
                 out["kind"], out["w"], out["x"], out["y"], out["ncoll"], out["absorbed"], out["path"],
                 out["specular"], out["roulette"], out["steps"])
            np.add.at(spec, ch, out["specular"])
            np.add.at(roul, ch, out["roulette"])
            packet_steps += int(out["steps"].sum())
            longest = max(longest, int(out["steps"].max()))
            sink(ch, pid, out)
    return spec, roul, packet_steps, longest
