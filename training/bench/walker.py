"""Benchmarks of the CPU walker (collected by ``python -m training bench``): cores used, MCML side by side.

1. ``simulate-layers`` end to end (a fresh process: start-up without torch, the compiled kernel loaded from
   numba's cache, the walk, JSON out) on MCML's semi-infinite test medium (mua 1, mus 99 cm^-1: albedo 0.99, g 0.9,
   n 1.4, normal incidence) on 1 thread and on every CPU the process is given; the scaling ratio is
   rate(all) / rate(1), whose goal is >= 0.8 x the CPU count.  Wall-clock rates and CPU-time rates (photons
   per CPU-second of the process: what a core delivers when it is not shared) are both given, with the
   load average, since the machine is shared.
   MCML 1.2.2 (Wang, Jacques & Zheng; C) on the same medium (10^8 cm thick) in the same run when the
   environment variable SKIN_SSS_MCML names its executable (build it yourself, e.g. gcc -O3
   -march=native; the project ships no MCML), else the anchor measured on a quiet machine of this kind
   (docs/research/monte_carlo.md §4a: 26,800 photons/s on one core).
2. The dataset's baseline walk (``training.data.reweight.walk``, 376 wavelengths) on 1 thread and on all,
   against the vectorised torch step on one thread (the walker ordinary runs used before the compiled
   engine: eager below 2^23 packets).
3. ``simulate`` of one tone, ``--method reweighted`` against ``--method direct`` at the same photons.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: MCML 1.2.2 on the semi-infinite medium, one core, quiet machine (docs/research/monte_carlo.md §4a).
MCML_SEMI_1CORE = 26_800.0
#: The medium: mua, mus (cm^-1), g; n = 1.4; semi-infinite.
SEMI = (1.0, 99.0, 0.9)
N_SEMI = 1.4
#: A tone of the calibrated skin model (f_mel, f_blood, t_epi cm, so2, b_mel) for the reweighted / direct row.
TONE = np.array([0.1, 0.02, 0.01, 0.75, 0.9])


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _timed_process(cmd: list[str], **kw) -> tuple[float, float, subprocess.CompletedProcess]:
    """(wall s, CPU s, result) of one child process."""
    c0, t0 = _children_cpu(), time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, check=True, **kw)
    return time.perf_counter() - t0, _children_cpu() - c0, out


def _ours(photons: int, threads: int) -> tuple[float, float, float]:
    """simulate-layers end to end on ``threads`` threads: (wall s, CPU s, R_d)."""
    mua, mus, g = SEMI
    cmd = [sys.executable, "-m", "training", "simulate-layers", "--layer", str(mua), str(mus), str(g), "inf",
           "--n-medium", str(N_SEMI), "--illumination", "normal", "--photons", str(photons), "--seed", "1",
           "--threads", str(threads), "--json"]
    wall, cpu, out = _timed_process(cmd, env=os.environ.copy())
    return wall, cpu, float(json.loads(out.stdout.strip().splitlines()[-1])["R_d"])


def _mcml(exe: str, photons: int) -> tuple[float, float, float]:
    """MCML on the same medium (10^8 cm thick): (wall s, CPU s, R_d)."""
    mua, mus, g = SEMI
    with tempfile.TemporaryDirectory() as tmp:
        mci = Path(tmp) / "semi.mci"
        mci.write_text(f"1.0\n1\nsemi.mco A\n{photons}\n0.01 0.01\n10 10 1\n1\n1.0\n"
                       f"{N_SEMI} {mua} {mus} {g} 1.0E+8\n1.0\n")
        wall, cpu, _ = _timed_process([exe, mci.name], cwd=tmp)
        lines = (Path(tmp) / "semi.mco").read_text().splitlines()
    rd = next(float(s.split()[0]) for s in lines if "Diffuse reflectance" in s)
    return wall, cpu, rd


def _semi_rows(photons: int) -> list[dict]:
    all_threads = len(os.sched_getaffinity(0))
    _ours(1000, 1)  # numba's cache written (a first run compiles the kernel, ~10-20 s)
    startup_cpu = min(_ours(1000, 1)[1] for _ in range(2))  # python, torch, numba and the cached kernel loaded
    exe = os.environ.get("SKIN_SSS_MCML")
    load0 = os.getloadavg()[0]
    runs = {1: [], all_threads: [], "mcml": []}
    for _ in range(2):  # interleaved, best of two: the machine is shared
        runs[1].append(_ours(photons, 1))
        runs[all_threads].append(_ours(photons, all_threads))
        if exe:
            runs["mcml"].append(_mcml(exe, photons))
    load1 = os.getloadavg()[0]
    best = {k: min(v) for k, v in runs.items() if v}
    r1, rn = photons / best[1][0], photons / best[all_threads][0]
    cpu1 = photons / best[1][1]
    load = f"load average {load0:.1f} -> {load1:.1f} on {os.cpu_count()} CPUs"
    if exe:
        m_wall, m_cpu, m_rd = best["mcml"]
        m_rate, m_cpu_rate = photons / m_wall, photons / m_cpu
        anchor = f"MCML 1.2.2, same run, 1 core: {m_rate:,.0f} photons/s wall, {m_cpu_rate:,.0f} per CPU-s " \
                 f"(R_d {m_rd:.4f})"
    else:
        m_rate = m_cpu_rate = MCML_SEMI_1CORE
        anchor = f"MCML 1.2.2, 1 core, quiet machine: {MCML_SEMI_1CORE:,.0f} photons/s (note §4a; SKIN_SSS_MCML " \
                 "unset)"
    util = best[all_threads][1] / best[all_threads][0]
    cpun = photons / best[all_threads][1]
    # an idle machine: the start-up on one CPU, the walk's CPU time spread over every thread
    idle_wall = startup_cpu + (best[all_threads][1] - startup_cpu) / all_threads
    idle_rate = photons / idle_wall
    return [
        {"workload": f"simulate-layers end to end, semi-infinite albedo 0.99, g 0.9, n 1.4, normal, {photons:,} "
         "photons, 1 thread",
         "ours": f"{r1:,.0f} photons/s wall, {cpu1:,.0f} per CPU-s (R_d {best[1][2]:.4f})", "anchor": anchor,
         "ratio": f"{r1 / m_rate:.2f}x wall, {cpu1 / m_cpu_rate:.2f}x per CPU-s",
         "error": "R_d: MCML 0.25065 +- 0.00016 (10^6 photons, note §4a)",
         "notes": f"numba engine, float64, compile excluded (cache); start-up (python, numba, the cached kernel; "
         f"no torch) {startup_cpu:.1f} CPU-s of a 1,000-photon run; best of 2 interleaved; {load}"},
        {"workload": f"the same, {all_threads} threads (every CPU given)",
         "ours": f"{rn:,.0f} photons/s wall ({util:.2f} CPUs busy on average), {cpun:,.0f} per CPU-s; idle machine "
         f"(projected from the CPU time): {idle_rate:,.0f} photons/s",
         "anchor": f"{all_threads} x the 1-thread rate: {all_threads * r1:,.0f}; MCML 1 core {m_rate:,.0f} wall, "
         f"{m_cpu_rate:,.0f} per CPU-s",
         "ratio": f"wall: scaling {rn / r1:.2f} of {all_threads} ({rn / r1 / all_threads:.2f} per CPU, goal 0.8), "
         f"{rn / m_rate:.2f}x MCML's 1-core rate (goal 2x); CPU-s per photon {cpu1 / cpun:.2f}x the 1-thread run's; "
         f"idle projection {idle_rate / m_cpu_rate:.2f}x MCML's 1-core rate",
         "error": "records identical to the 1-thread run (tests/test_sim_packet_loop.py)",
         "notes": f"{load}; on a shared machine the second core is only partly ours (CPUs busy above)"},
    ]


def _walk_rows(photons: int) -> list[dict]:
    import numba
    import torch

    from training.data.reweight import baseline_absorption, walk
    from training.sim import walker as walker_mod

    mua0 = baseline_absorption()
    all_threads = numba.config.NUMBA_NUM_THREADS
    times = {}
    walk(20, seed=1, mua0=mua0)  # loaded from cache
    for threads in (1, all_threads):
        numba.set_num_threads(threads)
        try:
            t0 = time.perf_counter()
            walk(photons, seed=2, mua0=mua0)
            times[threads] = time.perf_counter() - t0
        finally:
            numba.set_num_threads(all_threads)
    before, resolve = torch.get_num_threads(), walker_mod.resolve_engine
    torch.set_num_threads(1)
    walker_mod.resolve_engine = lambda engine, device: "torch"  # the vectorised step, as ordinary runs had it
    try:
        t0 = time.perf_counter()
        walk(photons, seed=2, mua0=mua0, compile=False)
        t_torch = time.perf_counter() - t0
    finally:
        walker_mod.resolve_engine = resolve
        torch.set_num_threads(before)
    rate = lambda t: photons * mua0.size / t  # noqa: E731
    return [{
        "workload": f"dataset baseline walk, {photons} photons x {mua0.size} wavelengths, paths recorded",
        "ours": f"1 thread {rate(times[1]):,.0f} packets/s; {all_threads} threads {rate(times[all_threads]):,.0f}",
        "anchor": f"vectorised torch step, 1 thread (eager, as the dataset walked before): {rate(t_torch):,.0f}",
        "ratio": f"{t_torch / times[1]:.1f}x per thread; scaling {times[1] / times[all_threads]:.2f} of "
        f"{all_threads}",
        "notes": f"load average {os.getloadavg()[0]:.1f}",
    }]


def _reweighted_row(photons: int) -> dict:
    from training.data.reweight import one_tone
    from training.sim.tissue import skin_medium
    from training.sim.transport import simulate

    t0 = time.perf_counter()
    direct = simulate(skin_medium(TONE), photons, seed=3)
    t1 = time.perf_counter()
    rew = one_tone(TONE, photons, seed=4)
    t2 = time.perf_counter()
    z = (rew["R_d"][0] - direct.R_d) / np.hypot(rew["R_d_stderr"][0], direct.R_d_stderr)
    return {
        "workload": f"simulate one tone {TONE.tolist()}, 376 wavelengths, {photons} photons",
        "ours": f"--method reweighted {t2 - t1:.1f} s", "anchor": f"--method direct {t1 - t0:.1f} s",
        "ratio": f"{(t2 - t1) / (t1 - t0):.2f}x the direct time (goal <= 1)",
        "error": f"R_d reweighted - direct: max |z| {np.abs(z).max():.1f} over 376 wavelengths",
        "notes": f"numba engine, all threads; load average {os.getloadavg()[0]:.1f}",
    }


def benchmarks(quick: bool) -> list[dict]:
    """Rows for bench/results.md (see the module docstring)."""
    rows = _semi_rows(100_000 if quick else 400_000)
    rows += _walk_rows(100 if quick else 400)
    rows.append(_reweighted_row(500 if quick else 2000))
    return rows


if __name__ == "__main__":
    for row in benchmarks(quick=True):
        print(row)
