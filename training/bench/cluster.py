"""Benchmark of the Dask engine (collected by ``python -m training bench``): a dataset preset built by
``python -m training dataset`` in one process and on ``--scheduler local:2`` (a LocalCluster of two
single-threaded worker processes on this machine), each from scratch in a fresh folder, as subprocesses
timed by the wall clock; CPU seconds are the subprocess trees' (client, scheduler and workers).  The two
builds' files are compared bit for bit.  ``ci`` (``smoke`` with --quick).
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from training.data.presets import PRESETS
from training.data.reweight import WALK_CHUNK_PHOTONS

ROOT = Path(__file__).resolve().parents[2]


def _run(args: list[str]) -> tuple[float, float]:
    """Wall and CPU seconds of ``python -m training ARGS`` (raises on failure)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "training", *args], cwd=ROOT, env=env, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _identical(a: Path, b: Path) -> bool:
    for split in ("train", "validation"):
        with h5py.File(a / f"{split}.h5", "r") as fa, h5py.File(b / f"{split}.h5", "r") as fb:
            if sorted(fa) != sorted(fb) or not all(np.array_equal(fa[k][:], fb[k][:]) for k in fa):
                return False
    return True


def dataset_row(preset: str, workers: int = 2) -> dict:
    """One row: the ``preset`` dataset in one process against ``local:WORKERS``."""
    p = PRESETS[preset]
    chunk = p.walk_chunk_photons or WALK_CHUNK_PHOTONS
    walks = 2 * -(-p.photons // chunk)
    reweights = -(-p.n_train // p.reweighted_chunk_tones) + -(-p.n_validation // p.reweighted_chunk_tones)
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench_cluster_") as tmp:
        one = _run(["dataset", "--preset", preset, "--out", f"{tmp}/one", "--no-progress"])
        load1 = os.getloadavg()[0]
        dask = _run(["dataset", "--preset", preset, "--out", f"{tmp}/dask", "--no-progress",
                     "--scheduler", f"local:{workers}"])
        same = _identical(Path(tmp) / "one", Path(tmp) / "dask")
    load2 = os.getloadavg()[0]
    return {
        "workload": f"dataset `{preset}` ({p.n_train} + {p.n_validation} tones, {p.photons:,} photons): "
        f"{walks} walk tasks, then {reweights} reweighting tasks, on `--scheduler local:{workers}`",
        "ours": f"{dask[0]:.1f} s wall, {dask[1]:.1f} CPU-s",
        "anchor": f"one process: {one[0]:.1f} s wall, {one[1]:.1f} CPU-s",
        "ratio": f"{one[0] / dask[0]:.2f}x faster (wall)",
        "error": "files identical bit for bit" if same else "FILES DIFFER",
        "notes": f"at most {min(workers, walks)} walks run at once ({walks} walk chunks; the reweighting "
        "waits for its split's walk); the cluster adds its start (worker processes importing torch) and "
        f"each worker loads the walk it reweights: CPU-s {dask[1] / max(one[1], 1e-9):.2f}x; 1-minute load "
        f"average {load0:.1f} before, {load1:.1f} between, {load2:.1f} after (2 shared cores)",
    }


def benchmarks(quick: bool) -> list[dict]:
    """Rows for bench/results.md (see the module docstring)."""
    return [dataset_row("smoke" if quick else "ci")]


if __name__ == "__main__":
    for row in benchmarks(quick="--quick" in sys.argv):
        print(row)
