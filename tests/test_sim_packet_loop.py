"""The compiled per-packet walk (numba engines): reproducible whatever the threads, the same physics as the
vectorised torch step, the same records from its GPU path (in numba's CUDA simulator), and the engine / thread
choices refused clearly when wrong.

The physics against independent solvers (adding-doubling, van de Hulst, H-function tables) is tested in
tests/test_sim_transport.py and tests/test_sim_lut.py, which run on the numba engine (the CPU default).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
import torch
from numba import cuda

from training.commands.simulate_layers import main as cli_main
from training.sim.compiled_transport import simulate_compiled
from training.sim.medium import LayeredMedium
from training.sim.transport import simulate, simulate_records
from training.sim.walker import default_threads, resolve_engine

ROOT = Path(__file__).resolve().parents[1]
#: A finite two-layer stack with absorption, a semi-infinite case would hide the bottom boundary.
STACK = LayeredMedium(
    mua=torch.tensor([[3.0, 0.2], [0.5, 0.05]]), mus=torch.tensor([[150.0, 40.0], [90.0, 60.0]]),
    g=torch.tensor([[0.85, 0.0], [0.7, -0.3]]), thickness=torch.tensor([0.01, 0.05]), n_medium=1.4,
)


#: The most threads numba may use here (2 on the project's machines).
MAX_THREADS = numba.config.NUMBA_NUM_THREADS


def test_records_do_not_depend_on_threads_or_batch_size() -> None:
    one = simulate_records(STACK, 3000, seed=8, threads=1)
    two = simulate_records(STACK, 3000, seed=8, threads=MAX_THREADS)
    small_batches = simulate_records(STACK, 3000, seed=8, threads=MAX_THREADS, chunk_photons=256)
    for other in (two, small_batches):
        for key in ("ch", "pid", "kind", "w", "r_cm", "ncoll", "path_cm", "specular", "roulette_balance"):
            np.testing.assert_array_equal(getattr(one, key), getattr(other, key), err_msg=key)
    again = simulate(STACK, 3000, seed=8, threads=1)
    np.testing.assert_array_equal(again.R_d, simulate(STACK, 3000, seed=8, threads=MAX_THREADS).R_d)
    assert not np.array_equal(again.R_d, simulate(STACK, 3000, seed=9, threads=1).R_d)


@pytest.mark.parametrize("illumination", ["normal", "diffuse"])
def test_numba_engine_agrees_with_the_torch_step(illumination: str) -> None:
    """Both engines estimate the same R_d, T_d, ballistic T and absorption (4 combined standard errors)."""
    photons = 12_000
    a = simulate(STACK, photons, illumination=illumination, seed=3, engine="numba", r_edges_cm=None)
    b = simulate(STACK, photons, illumination=illumination, seed=4, engine="torch", compile=False,
                 dtype=torch.float64, r_edges_cm=None)
    for key, se in (("R_d", "R_d_stderr"), ("T_d", "T_d_stderr")):
        tol = 4.0 * np.hypot(getattr(a, se), getattr(b, se)) + 1e-4
        assert np.all(np.abs(getattr(a, key) - getattr(b, key)) < tol), (key, getattr(a, key), getattr(b, key))
    # ballistic transmission exp(-sigma_t d) through both layers, with Fresnel at the bottom only
    # (normal incidence) is known exactly; absorption within a loose bound (no per-photon error kept)
    np.testing.assert_allclose(a.absorbed, b.absorbed, atol=0.01)
    np.testing.assert_allclose(a.specular, b.specular, atol=0.005)  # random under diffuse light (se ~1e-3)
    if illumination == "normal":
        r = ((1.4 - 1.0) / 2.4) ** 2
        sigma_d = ((STACK.mua + STACK.mus) * STACK.thickness[:, None]).sum(0).numpy()
        exact = (1 - r) * np.exp(-sigma_d) * (1 - r)
        se = np.sqrt(exact * (1 - exact) / photons)
        assert np.all(np.abs(a.T_unscattered - exact) < 4 * se + 1e-6), (a.T_unscattered, exact)


def test_energy_balance_with_path_roulette() -> None:
    free = LayeredMedium(torch.zeros(1, 2), torch.tensor([[1.0, 1.0]]), torch.tensor([[0.0, 0.9]]),
                         torch.tensor([math.inf]), n_medium=1.4)
    rec = simulate_records(free, 4000, seed=2, max_steps=3000, path_roulette_n0=32)
    for c in range(2):
        m = rec.ch == c
        total = rec.w[m].sum() / rec.photons + rec.specular[c] - rec.roulette_balance[c]
        assert abs(total - 1.0) < 1e-9, total  # nothing is absorbed: every launched weight leaves or is rouletted


def test_engine_and_thread_choices() -> None:
    assert resolve_engine("auto", torch.device("cpu")) == "numba"
    assert resolve_engine("auto", torch.device("cuda")) == "torch"
    with pytest.raises(ValueError, match="CPU only"):
        resolve_engine("numba", torch.device("cuda"))
    with pytest.raises(ValueError, match="engine must be one of"):
        simulate(STACK, 10, engine="fortran")
    with pytest.raises(ValueError, match="threads must be in"):
        simulate(STACK, 10, threads=0)
    assert default_threads() >= 1


def test_cli_engines_and_threads(capsys: pytest.CaptureFixture[str]) -> None:
    args = ["--layer", "1", "99", "0.9", "inf", "--illumination", "normal", "--photons", "2000", "--json"]
    outs = []
    for extra in (["--threads", "1"], ["--threads", str(MAX_THREADS)], ["--engine", "torch", "--compile", "off"]):
        assert cli_main(args + extra) == 0
        outs.append(json.loads(capsys.readouterr().out))
    assert outs[0]["R_d"] == outs[1]["R_d"]  # same seed, other thread count: the same photons
    assert abs(outs[0]["R_d"] - outs[2]["R_d"]) < 4 * math.hypot(outs[0]["R_d_stderr"], outs[2]["R_d_stderr"])
    assert cli_main(args + ["--threads", "0"]) == 2
    assert cli_main(args + ["--threads", str(MAX_THREADS + 1)]) == 2


@pytest.mark.parametrize("illumination", ["normal", "diffuse"])
def test_the_torch_free_walk_gives_simulates_numbers(illumination: str) -> None:
    """The command line's torch-free walk and ``simulate`` on the numba engine: the same numbers, bit for bit."""
    below = LayeredMedium(STACK.mua, STACK.mus, STACK.g, STACK.thickness, n_medium=1.4, n_below=1.33)
    ref = simulate(below, 3000, illumination=illumination, seed=11, engine="numba", r_edges_cm=None)
    got = simulate_compiled(*(t.numpy() for t in (below.mua, below.mus, below.g, below.thickness)), 3000,
                            n_medium=1.4, n_below=1.33, illumination=illumination, seed=11)
    assert got["photons"] == 3000 and np.all(got["T_d"] > 0.01)
    for key in ("R_d", "R_d_stderr", "T_d", "T_d_stderr"):
        np.testing.assert_array_equal(got[key], getattr(ref, key), err_msg=key)


def test_the_cli_numba_run_loads_no_torch() -> None:
    """``simulate-layers`` on the CPU's numba engine never imports torch (seconds of a fresh process's start-up)."""
    code = (
        "import json, sys\n"
        "from training.commands.dispatch import main\n"
        "rc = main(['simulate-layers', '--layer', '1', '99', '0.9', 'inf', '--photons', '500', '--json'])\n"
        "assert rc == 0, rc\n"
        "print(json.dumps(sorted(m for m in sys.modules if m == 'torch' or m.startswith('torch.'))))\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", code], check=True, env=env, cwd=ROOT, timeout=300,
                          capture_output=True, text=True)
    lines = done.stdout.strip().splitlines()
    assert json.loads(lines[0])["photons"] == 500
    assert json.loads(lines[-1]) == []


def test_the_gpu_path_walks_the_same_packets_in_cudas_simulator(tmp_path) -> None:
    """engine "numba-cuda" (one CUDA thread per packet, the CPU kernel's own source) under numba's CUDA simulator
    gives the compiled CPU engine's records bit for bit."""
    out = tmp_path / "gpu.npz"
    code = (
        "import numpy as np, torch, warnings; warnings.simplefilter('ignore')\n"
        "from tests.test_sim_packet_loop import STACK\n"
        "from training.sim.transport import simulate_records\n"
        "r = simulate_records(STACK, 40, seed=5, engine='numba-cuda', path_roulette_n0=8)\n"
        f"np.savez({str(out)!r}, **{{k: getattr(r, k) for k in ('ch', 'pid', 'kind', 'w', 'r_cm', 'ncoll', "
        "'path_cm', 'specular', 'roulette_balance')})\n"
    )
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1", "NUMBA_DISABLE_JIT": "1",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    subprocess.run([sys.executable, "-c", code], check=True, env=env, cwd=ROOT, timeout=600)
    cpu = simulate_records(STACK, 40, seed=5, engine="numba", path_roulette_n0=8)
    with np.load(out) as gpu:
        assert gpu["kind"].size > 0
        for key in gpu.files:
            np.testing.assert_array_equal(gpu[key], getattr(cpu, key), err_msg=key)
    if not cuda.is_available():  # no GPU and no simulator in this process
        with pytest.raises(ValueError, match="CUDA GPU"):
            simulate(STACK, 10, engine="numba-cuda")


def test_the_walks_exponential_sampler_is_the_exponential_distribution() -> None:
    """The free paths' ziggurat sampler against the standard exponential: Kolmogorov-Smirnov over 2e6 draws,
    mean and variance 1 within 5 standard errors, and the tail beyond the ziggurat's base (x > 7.7, drawn by
    its slow path) and far beyond it (x > 12) as often as exp(-x) says (5 binomial standard errors)."""
    from scipy import stats

    from training.sim.packet_loop import exponential_samples

    n = 2_000_000
    x = exponential_samples(2024, n)
    assert np.all(np.isfinite(x)) and x.min() >= 0.0
    assert stats.kstest(x, "expon").pvalue > 1e-3
    assert abs(x.mean() - 1.0) < 5.0 / math.sqrt(n)
    assert abs(x.var() - 1.0) < 5.0 * math.sqrt(8.0 / n)  # var of (x - 1)^2 for Exp(1) is 8
    for edge in (7.69711747013104972, 12.0):
        p = math.exp(-edge)
        assert abs((x > edge).mean() - p) < 5.0 * math.sqrt(p * (1 - p) / n)
    assert not np.array_equal(x[:100], exponential_samples(2025, 100))
