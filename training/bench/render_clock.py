"""CPU time of a render without the threads that only wait for it: the clock of the render benchmarks.

While Cycles renders, a thread of Blender's task scheduler that existed before the render waits for it by yielding
the CPU in a loop (``sched_yield``; an ``strace -f -c`` of a one-thread render counts ~37,000 calls).  On an idle
2-core machine that thread's user and system time equals the render's wall time, so the process's CPU time
(``getrusage(RUSAGE_SELF)``) is about twice the render's own, and less when other work takes the second core: the
process's time mixes the render's cost with the machine's load.  :class:`RenderClock` counts the process's CPU time
less that of every thread which existed before the render and still exists after it, the main thread excepted:
what is left is the main thread (scene sync runs there) and the threads the render starts and ends (Cycles' session
and its workers).  Per-thread times come from ``/proc/self/task/<tid>/schedstat`` (Linux: the
nanoseconds the thread ran, as exact as the process's own time; the per-thread ``stat`` file gives user and system
time only in 10 ms ticks, statistically split); where /proc has no tasks the clock is the process's time.
"""

from __future__ import annotations

import os
import random
import resource
import statistics
from pathlib import Path

_TASKS = Path("/proc/self/task")
#: Bootstrap resamples of a paired ratio's median (:func:`paired_ratio`), and their seed.
BOOTSTRAP, SEED = 2000, 0


def _process_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _threads_s() -> dict[int, float]:
    """CPU seconds of each thread of this process but the main one ({} where /proc has no tasks)."""
    out = {}
    main = os.getpid()
    try:
        tids = [int(t) for t in os.listdir(_TASKS)]
    except OSError:
        return out
    for tid in tids:
        if tid == main:
            continue
        try:
            out[tid] = int((_TASKS / str(tid) / "schedstat").read_text().split()[0]) * 1e-9
        except (OSError, ValueError, IndexError):  # the thread ended meanwhile
            continue
    return out


class RenderClock:
    """Started at construction; :meth:`seconds` gives the CPU seconds since then of the main thread and of the threads
    started meanwhile (those still running and those already ended)."""

    def __init__(self) -> None:
        # the process first, its threads after (and the reverse at the end): a waiting thread's time between the two
        # reads is then counted by neither or by the process alone, never subtracted for time the process did not hold
        self._process = _process_s()
        self._threads = _threads_s()

    def seconds(self) -> float:
        now = _threads_s()
        process = _process_s() - self._process
        waiting = sum(now[tid] - before for tid, before in self._threads.items() if tid in now)
        return max(process - waiting, 0.0)


def paired_ratio(ours: list[float], anchor: list[float]) -> tuple[float, float, float]:
    """Median of the rounds' ratios ours[i] / anchor[i] and the 2.5 and 97.5 percentiles of that median over
    :data:`BOOTSTRAP` resamples of the rounds (fixed seed).  Renders of one round ran seconds apart in one process and
    met the same spell of other work on the machine, which the ratio cancels; the interval holds the spread of the
    rounds of one run, not the machine's drift between runs."""
    ratios = [a / b for a, b in zip(ours, anchor, strict=True)]
    rng = random.Random(SEED)
    medians = sorted(statistics.median(rng.choices(ratios, k=len(ratios))) for _ in range(BOOTSTRAP))
    return statistics.median(ratios), medians[int(0.025 * BOOTSTRAP)], medians[int(0.975 * BOOTSTRAP) - 1]
