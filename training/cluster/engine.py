"""Run a stage's pieces on a Dask cluster: the ``--scheduler`` option, the client, and ``Job``.

    --scheduler local:N            a LocalCluster of N single-threaded worker processes on this machine
    --scheduler tcp://HOST:PORT    a running Dask scheduler (``dask scheduler`` + ``dask worker``, dask-cuda, ...)
    --scheduler slurm[:JOBS]       a dask_jobqueue.SLURMCluster of JOBS jobs (default 4), configured by
                                   dask's ``jobqueue.slurm`` settings (docs/research/scaling_out.md)

Without ``--scheduler`` a command runs in one process as before.  Nothing here schedules: Dask does
(placement, a worker that dies, retries).  This module only opens the client, submits a stage's pieces
as tasks with ``retries=RETRIES``, shows one progress bar over them (done / total, rate, ETA) and
hands each result to the stage's writer on the client as it arrives; a task that still fails after its
retries is reported by name (``TaskError``), never dropped.  The stages' tasks write (or return for the
client to write) exactly the files their single-process path writes, so workers must see the output
folder at the same path (a shared file system; ``check_shared`` verifies it).  Bit for bit: every seed
belongs to a piece, and a task runs torch on the command's ``--threads`` as one process does (sums whose
last bit depends on the thread count, such as OpenBLAS's threaded products, are kept off numpy's BLAS:
``training.sim.lut._matmul``).
"""

from __future__ import annotations

import argparse
import logging
import os
import re
import shutil
import socket
import sys
import threading
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: Re-runs of a task that raised (distributed's ``retries=``); a worker that dies mid-task is the
#: scheduler's business (its task goes to another worker, up to ``distributed.scheduler.allowed-failures``).
RETRIES = 2
#: SLURM jobs started by ``--scheduler slurm`` without ``:JOBS``.
SLURM_JOBS = 4
#: What a SLURM job asks for when dask's ``jobqueue.slurm`` config leaves it unset: one single-threaded
#: worker (the walker and the fitter run best on one thread per core), memory for a ``laptop`` walk.
SLURM_DEFAULTS: dict[str, Any] = {"cores": 1, "memory": "8GiB"}
#: The allocator settings of the workers we start.  distributed's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in
#: every worker by default, which also freezes glibc's mmap threshold at 128 KiB: each of the walker's
#: per-step tensors then becomes an mmap/munmap pair, and a walk took 4.2x the CPU of the same walk in one
#: process (85 s against 20 s, 500 photons x 376 wavelengths, 1,500 steps; measured here).  These are the
#: values glibc's own dynamic thresholds reach on 64-bit (32 MiB, twice that for trimming): the walk then
#: costs what it costs in one process.
WORKER_ENV = {"MALLOC_MMAP_THRESHOLD_": "33554432", "MALLOC_TRIM_THRESHOLD_": "67108864"}
#: Dask settings of the workers we start: WORKER_ENV, and no statistical profiler (it samples the task's
#: stack every 10 ms for the dashboard: ~9 % of a walk's CPU here).
WORKER_CONFIG = {**{f"distributed.nanny.pre-spawn-environ.{k}": v for k, v in WORKER_ENV.items()},
                 "distributed.worker.profile.enabled": False}
#: Seconds to wait for a tcp:// scheduler's port to answer before giving up (the client's own timeout then
#: bounds the handshake).
CONNECT_TIMEOUT_S = 10
SCHEDULER_HELP = ("run the work on a Dask cluster: local:N (N worker processes here), tcp://HOST:PORT (a running "
                  "scheduler) or slurm[:JOBS] (dask-jobqueue; docs/research/scaling_out.md); default: this process")


@dataclass(frozen=True)
class Scheduler:
    """A parsed ``--scheduler``: kind "local" (``n`` workers), "tcp" (``address``) or "slurm" (``n`` jobs)."""

    kind: str
    n: int = 0
    address: str = ""

    def __str__(self) -> str:
        return self.address if self.kind == "tcp" else f"{self.kind}:{self.n}"


def parse_scheduler(text: str) -> Scheduler:
    """argparse type of ``--scheduler``."""
    m = re.fullmatch(r"(local|slurm)(?::(\d+))?", text)
    if m and (m.group(1) == "slurm" or m.group(2)):
        n = int(m.group(2)) if m.group(2) else SLURM_JOBS
        if n < 1:
            raise argparse.ArgumentTypeError(f"--scheduler {text}: the number of workers/jobs must be >= 1")
        return Scheduler(m.group(1), n)
    if re.fullmatch(r"tcp://[\w.\-\[\]:]+:\d+", text):
        return Scheduler("tcp", address=text)
    raise argparse.ArgumentTypeError(
        f"--scheduler must be local:N, tcp://HOST:PORT or slurm[:JOBS], got {text!r}")


def add_option(parser: argparse.ArgumentParser) -> None:
    """Add ``--scheduler`` to a command's parser (default None: one process)."""
    parser.add_argument("--scheduler", type=parse_scheduler, default=None, metavar="SPEC", help=SCHEDULER_HELP)


def slurm_cluster(**overrides):
    """A ``dask_jobqueue.SLURMCluster`` from dask's ``jobqueue.slurm`` configuration (queue, account, walltime,
    job_extra_directives, ...: ``~/.config/dask/jobqueue.yaml`` or ``DASK_JOBQUEUE__SLURM__*`` variables),
    ``SLURM_DEFAULTS`` where it is silent, one worker process per core; no job is submitted yet."""
    try:
        from dask_jobqueue import SLURMCluster
    except ImportError:
        raise ValueError("--scheduler slurm needs dask-jobqueue: pip install 'dask-jobqueue==0.9.0' "
                         "(or the project's [cluster] extra)") from None
    import dask

    conf = dask.config.get("jobqueue.slurm")
    kwargs = {k: conf.get(k) or v for k, v in SLURM_DEFAULTS.items()}
    kwargs["processes"] = conf.get("processes") or kwargs["cores"]  # one thread per worker
    env = {**WORKER_ENV, "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False"}
    kwargs["job_script_prologue"] = [*(conf.get("job-script-prologue") or []),
                                     "export " + " ".join(f"{k}={v}" for k, v in env.items())]
    return SLURMCluster(**{**kwargs, **overrides})


def check_reachable(spec: Scheduler) -> None:
    """ValueError (one line, within ``CONNECT_TIMEOUT_S``) when the scheduler of ``spec`` cannot start: no
    ``sbatch`` on PATH for slurm, nothing listening at a tcp:// address."""
    if spec.kind == "slurm" and shutil.which("sbatch") is None:
        raise ValueError("--scheduler slurm: no `sbatch` on PATH (SLURM is not installed here); run on a SLURM login "
                         "node, or use --scheduler local:N or tcp://HOST:PORT")
    if spec.kind == "tcp":
        host, _, port = spec.address.removeprefix("tcp://").rpartition(":")
        try:
            socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT_S).close()
        except OSError as exc:
            raise ValueError(f"--scheduler {spec}: cannot reach the scheduler ({exc.strerror or exc}); start it "
                             "(dask scheduler) or check the address") from None


@contextmanager
def client(spec: Scheduler) -> Iterator[Any]:
    """A ``distributed.Client`` on the cluster ``spec`` names (closed, and a cluster we started shut down, on exit)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ValueError("--scheduler needs dask and distributed: pip install 'distributed==2026.8.0' "
                         "(or the project's [cluster] extra)") from None
    import dask

    check_reachable(spec)
    cluster = None
    with dask.config.set(WORKER_CONFIG):  # read by the nannies when they start (and restart) workers
        if spec.kind == "local":
            # memory_limit=0: no worker pause/kill on memory (one process has no limit either)
            cluster = LocalCluster(n_workers=spec.n, threads_per_worker=1, processes=True, dashboard_address=None,
                                   memory_limit=0, silence_logs=logging.ERROR)
        elif spec.kind == "slurm":
            cluster = slurm_cluster()
            cluster.scale(jobs=spec.n)
    try:
        try:
            c = Client(cluster) if cluster is not None else Client(spec.address, timeout="30s")
        except OSError as exc:  # no scheduler at the address
            raise ValueError(f"--scheduler {spec}: cannot reach the scheduler ({exc})") from None
        with c:
            yield c
    finally:
        if cluster is not None:
            cluster.close()


def check_shared(dask_client, paths: list[Path]) -> None:
    """ValueError unless every connected worker sees ``paths`` (absolute) as the client does: a file must
    exist there; a folder (created if missing) must show a probe file the client writes into it (the same
    folder, not one of the same name on another disk)."""
    for path in paths:
        made = path.is_dir() or not path.exists()
        if made:
            path.mkdir(parents=True, exist_ok=True)
        probe = path / f".scheduler-probe-{uuid.uuid4().hex}" if made else path
        if made:
            probe.write_text("")
        try:
            blind = [w for w, seen in dask_client.run(os.path.exists, str(probe)).items() if not seen]
        finally:
            if made:
                probe.unlink(missing_ok=True)
        if blind:
            raise ValueError(f"workers {blind} do not see {path}: --scheduler needs the data on a file system "
                             "shared by the client and every worker, at the same path")


def check_worker_env(dask_client) -> list[str]:
    """Workers whose allocator runs with distributed's slow default (MALLOC_TRIM_THRESHOLD_ set, no
    MALLOC_MMAP_THRESHOLD_; see WORKER_ENV); the command warns about them (workers started by hand)."""
    def env() -> tuple[str | None, str | None]:
        return os.environ.get("MALLOC_TRIM_THRESHOLD_"), os.environ.get("MALLOC_MMAP_THRESHOLD_")

    return [w for w, (trim, mmap) in dask_client.run(env).items() if trim is not None and mmap is None]


class TaskError(RuntimeError):
    """Tasks that still failed after their retries; the message names each one and its exception."""


def _call(threads: int, fn: Callable, *args):
    """What a worker runs: ``fn(*args)`` with ``threads`` torch threads (as the commands' ``--threads``) and as
    many threads for the walker's numba kernel (workers share a machine: one walk per worker, not per CPU)."""
    import numba
    import torch

    torch.set_num_threads(threads)
    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    return fn(*args)


class Job:
    """A stage's tasks on a Dask client: one progress bar, bounded retries, results written on the client.

    ``submit(label, fn, *args, on_done=...)`` starts ``fn(*args)`` on a worker (futures among ``args`` are
    its inputs: Dask waits for them) and returns its future; ``wait()`` waits for everything submitted so
    far, calls ``on_done(result)`` on the client as each task finishes (where a stage writes its HDF5 rows:
    one writer per file), and raises ``TaskError`` naming the tasks that failed.  ``wait`` may be called
    again after more submissions (a stage with client-side steps between its phases); the bar counts all.
    """

    def __init__(self, dask_client, desc: str, *, threads: int = 1, progress: bool = True,
                 retries: int = RETRIES) -> None:
        self.client, self.desc, self.threads, self.retries = dask_client, desc, int(threads), int(retries)
        self.progress = progress
        self._pending: dict[str, tuple[Any, str, Callable | None]] = {}
        self._bar = None

    def submit(self, label: str, fn: Callable, *args, on_done: Callable[[Any], None] | None = None):
        key = re.sub(r"[^\w.-]+", "-", label) + "-" + uuid.uuid4().hex[:12]
        fut = self.client.submit(_call, self.threads, fn, *args, key=key, retries=self.retries, pure=False)
        self._pending[key] = (fut, label, on_done)
        return fut

    def wait(self) -> None:
        from distributed import as_completed
        from tqdm import tqdm

        if self._bar is None:
            self._bar = tqdm(total=len(self._pending), desc=self.desc, unit="task", disable=not self.progress,
                             smoothing=0.1)
        else:
            self._bar.total += len(self._pending)
            self._bar.refresh()
        failed = []
        try:
            for fut in as_completed([f for f, _, _ in self._pending.values()]):
                _, label, on_done = self._pending.pop(fut.key)
                if fut.status == "finished":
                    if on_done is not None:
                        on_done(fut.result())
                else:
                    exc = fut.exception() if fut.status == "error" else fut.status
                    failed.append(f"{label}: {type(exc).__name__}: {exc}")
                    self._bar.set_postfix(failed=len(failed))
                fut.release()  # the result has been written: free it on the cluster
                self._bar.update(1)
        except BaseException:
            self.client.cancel([f for f, _, _ in self._pending.values()])
            self._pending.clear()
            raise
        if failed:
            raise TaskError(f"{len(failed)} task(s) failed after {self.retries} retries (the pieces done are "
                            "kept: run the same command again to resume): " + "; ".join(failed))

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


@contextmanager
def job(spec: Scheduler | None, desc: str, *, shared: list[Path] = (), threads: int = 1,
        progress: bool = True) -> Iterator[Job | None]:
    """``Job`` on the cluster ``spec`` (None: yields None, the caller runs in this process); ``shared``:
    the absolute paths that the tasks read or write, which every worker must see (``check_shared``)."""
    if spec is None:
        yield None
        return
    with client(spec) as c:
        check_shared(c, [Path(p) for p in shared])
        slow = check_worker_env(c)
        if slow:
            print(f"warning: {len(slow)} worker(s) run with MALLOC_TRIM_THRESHOLD_ but no MALLOC_MMAP_THRESHOLD_ "
                  "(distributed's default): the walker is ~4x slower there; start them with "
                  + " ".join(f"{k}={v}" for k, v in WORKER_ENV.items()), file=sys.stderr)
        j = Job(c, desc, threads=threads, progress=progress)
        try:
            yield j
        finally:
            j.close()


_MEMO: dict[str, tuple[Any, Any]] = {}
_MEMO_LOCK = threading.Lock()


def memo(kind: str, key: Any, make: Callable[[], Any]) -> Any:
    """Per-process cache of one value per ``kind`` (a worker's LUT, its loaded walk): ``make()`` when ``key``
    differs from the cached one (the old value is dropped first, so two never sit in memory together).
    Thread-safe: the tasks of a multi-threaded worker share one copy."""
    with _MEMO_LOCK:
        held = _MEMO.get(kind)
        if held is not None and held[0] == key:
            return held[1]
        _MEMO.pop(kind, None)
        value = make()
        _MEMO[kind] = (key, value)
        return value


def forget(kind: str) -> None:
    """Drop the per-process value of ``kind`` that ``memo`` holds (no-op when none)."""
    with _MEMO_LOCK:
        _MEMO.pop(kind, None)
