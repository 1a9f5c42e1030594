"""The Dask engine (training/cluster): `lut`, `dataset` and `fit --dataset` on a real cluster of 2 worker
processes write the single-process files bit for bit; a worker killed mid-run and a whole run killed and
started again both complete the job; a failing task is retried, then reported by name; `--scheduler` parsing;
the SLURM cluster built from dask's configuration (no job submitted).

Sizes: the `smoke` dataset preset (6 + 4 tones, 3 walk chunks per split; the `ci` preset takes ~65 s in one
process, too long to run here several times), a LUT of 3 batches of g nodes, 2 tones fitted at 4 wavelengths.
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import psutil
import pytest

from training.cluster import engine
from training.commands.dataset import main as dataset_main
from training.commands.fit import main as fit_main
from training.commands.lut import main as lut_main

ROOT = Path(__file__).resolve().parents[1]
LUT_ARGS = ["--albedo-n", "8", "--g-n", "24", "--photons", "100", "--max-steps", "500", "--no-progress"]
FIT_ARGS = ["--split", "validation", "--max-tones", "2", "--k", "1,2", "--wavelength-stride", "94",
            "--chunk-tones", "1", "--no-progress"]


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "training", *args]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}


def _same_h5(a: Path, b: Path) -> None:
    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        assert sorted(fa) == sorted(fb)
        for name in fa:
            np.testing.assert_array_equal(fa[name][:], fb[name][:], err_msg=f"{a.name}: {name}")
        assert bool(fa["done"][:].all())


def _same_dataset(a: Path, b: Path) -> None:
    for split in ("train", "validation"):
        _same_h5(a / f"{split}.h5", b / f"{split}.h5")


def _same_npz(a: Path, b: Path) -> None:
    with np.load(a) as x, np.load(b) as y:
        assert sorted(x.files) == sorted(y.files)
        for k in x.files:
            np.testing.assert_array_equal(x[k], y[k], err_msg=k)


@pytest.fixture(scope="module")
def single(tmp_path_factory) -> Path:
    """The single-process references: the smoke dataset, a small LUT, fits of the dataset through it."""
    d = tmp_path_factory.mktemp("single")
    assert dataset_main(["--preset", "smoke", "--out", str(d / "ds"), "--no-progress"]) == 0
    assert lut_main([*LUT_ARGS, "--out", str(d / "lut.npz")]) == 0
    assert fit_main(["--dataset", str(d / "ds"), "--lut", str(d / "lut.npz"), "--out", str(d / "fits"),
                     *FIT_ARGS]) == 0
    return d


@pytest.fixture(scope="module")
def cluster():
    """A LocalCluster of 2 single-threaded worker processes, started as docs/research/scaling_out.md says workers
    started by hand should be (engine.WORKER_ENV), reached by its tcp:// address."""
    import dask
    from distributed import LocalCluster

    with dask.config.set(engine.WORKER_CONFIG), LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, memory_limit=0,
            silence_logs=logging.ERROR) as c:
        yield c


def _wait_for(predicate, proc: subprocess.Popen, what: str, timeout: float = 300.0) -> None:
    t0 = time.monotonic()
    while not predicate():
        assert proc.poll() is None, f"the run ended before {what}: {proc.communicate()[1][-2000:]}"
        assert time.monotonic() - t0 < timeout, f"timed out waiting for {what}"
        time.sleep(0.05)


def _workers(proc: subprocess.Popen) -> list[psutil.Process]:
    """The LocalCluster's worker processes under ``proc`` (spawned by its nannies)."""
    found = []
    for child in psutil.Process(proc.pid).children(recursive=True):
        try:
            if any("spawn_main" in part for part in child.cmdline()):
                found.append(child)
        except psutil.Error:  # gone meanwhile
            pass
    return found


def test_dataset_on_two_workers_survives_a_killed_worker_and_matches_one_process(single, tmp_path):
    out = tmp_path / "ds"
    proc = subprocess.Popen(_cli("dataset", "--preset", "smoke", "--out", str(out), "--scheduler", "local:2",
                                 "--no-progress"), cwd=ROOT, env=_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: any(out.glob("trajectories_*/chunk*.npz")), proc, "the first walk chunk")
        _wait_for(lambda: len(_workers(proc)) == 2, proc, "two workers")
        before = len(list(out.glob("trajectories_*/chunk*.npz")))
        assert before < 6  # mid-run: the other worker is walking a chunk, more are queued
        _workers(proc)[0].kill()  # SIGKILL: its task in flight is lost; Dask restarts it and runs the task again
        _, err = proc.communicate(timeout=600)
    finally:
        proc.kill()
    assert proc.returncode == 0, err[-3000:]
    _same_dataset(single / "ds", out)


def test_a_killed_lut_run_resumes_with_the_same_command(single, tmp_path):
    out = tmp_path / "lut.npz"
    cmd = _cli("lut", *LUT_ARGS, "--out", str(out), "--scheduler", "local:2")
    proc = subprocess.Popen(cmd, cwd=ROOT, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    parts = tmp_path / "lut.npz.parts"
    try:
        _wait_for(lambda: len(list(parts.glob("g_*.npz"))) >= 8, proc, "the first batch of g nodes")
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the client, the cluster and its workers
        proc.communicate()
    done = len(list(parts.glob("g_*.npz")))
    assert not out.exists() and 8 <= done < 24
    rerun = subprocess.run(cmd, cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stderr[-3000:]
    _same_npz(single / "lut.npz", out)


def test_fit_through_a_running_scheduler_matches_one_process(single, cluster, tmp_path):
    address = cluster.scheduler_address
    assert engine.parse_scheduler(address) == engine.Scheduler("tcp", address=address)
    from distributed import Client

    with Client(address) as client:  # the allocator settings reached the workers (else: a warning, 4x slower)
        assert engine.check_worker_env(client) == []
    assert fit_main(["--dataset", str(single / "ds"), "--lut", str(single / "lut.npz"), "--out",
                     str(tmp_path / "fits"), *FIT_ARGS, "--scheduler", address]) == 0
    _same_h5(single / "fits" / "validation_fits.h5", tmp_path / "fits" / "validation_fits.h5")


def test_failing_tasks_are_retried_then_reported_by_name(cluster, tmp_path):
    from distributed import Client

    def flaky(marker: str) -> int:  # fails on its first run only (pickled by value: defined here)
        if not os.path.exists(marker):
            Path(marker).write_text("")
            raise OSError("first try fails")
        return 7

    def broken(counter: str) -> None:
        with open(counter, "a") as f:
            f.write("x")
        raise ValueError("no such tone")

    results = []
    with Client(cluster) as client:
        job = engine.Job(client, "test", progress=False)
        job.submit("flaky task", flaky, str(tmp_path / "marker"), on_done=results.append)
        job.submit("walk train chunk 7", broken, str(tmp_path / "counter"))
        with pytest.raises(engine.TaskError, match=r"1 task\(s\) failed.*walk train chunk 7: ValueError: no such tone"):
            job.wait()
        job.close()
    assert results == [7]  # retried and written
    assert (tmp_path / "counter").read_text() == "x" * (1 + engine.RETRIES)  # bounded: 1 + RETRIES runs


def test_scheduler_option_and_refusals(tmp_path, capsys):
    assert engine.parse_scheduler("local:3") == engine.Scheduler("local", 3)
    assert engine.parse_scheduler("slurm") == engine.Scheduler("slurm", engine.SLURM_JOBS)
    assert engine.parse_scheduler("slurm:16") == engine.Scheduler("slurm", 16)
    for bad in ("local", "local:0", "tcp://host", "sge", "slurm:x"):
        with pytest.raises(Exception, match="--scheduler"):
            engine.parse_scheduler(bad)
    # sharding by hand and the cluster exclude each other: refused before any cluster starts
    assert dataset_main(["--preset", "smoke", "--out", str(tmp_path), "--shard", "0/2", "--scheduler", "local:2"]) == 2
    assert "exclude each other" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_slurm_cluster_from_dask_configuration(monkeypatch):
    import dask

    conf = {"jobqueue.slurm.queue": "gpu", "jobqueue.slurm.account": "skin", "jobqueue.slurm.walltime": "02:00:00",
            "jobqueue.slurm.cores": 4, "jobqueue.slurm.job-extra-directives": ["--gres=gpu:4"]}
    with dask.config.set(conf):
        cluster = engine.slurm_cluster(scheduler_options={"dashboard_address": ":0"})  # any free port
        try:
            script = cluster.job_script()
        finally:
            cluster.close()
    # one single-threaded worker per core, memory from SLURM_DEFAULTS (the configuration is silent on it)
    for line in ("#SBATCH -p gpu", "#SBATCH -A skin", "#SBATCH -t 02:00:00", "#SBATCH --gres=gpu:4",
                 "#SBATCH --cpus-per-task=4", "#SBATCH --mem=8G", "--nworkers 4", "--nthreads 1",
                 "export MALLOC_MMAP_THRESHOLD_=33554432 MALLOC_TRIM_THRESHOLD_=67108864"):
        assert line in script, script
    monkeypatch.setitem(sys.modules, "dask_jobqueue", None)  # as if it were not installed
    with pytest.raises(ValueError, match="needs dask-jobqueue: pip install"):
        engine.slurm_cluster()
