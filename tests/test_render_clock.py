"""The render benchmarks' clock (training.bench.render_clock): a thread that waits by spinning is not the render's."""

import hashlib
import statistics
import threading
import time
from pathlib import Path

import pytest

from training.bench.render_clock import RenderClock, paired_ratio

pytestmark = pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="per-thread times come from /proc")


def _burn(seconds: float) -> float:
    """Spin for ``seconds`` of this thread's CPU time; returns the CPU time spent."""
    start = time.thread_time()
    while time.thread_time() - start < seconds:
        pass
    return time.thread_time() - start


def test_counts_the_threads_started_after_it_and_not_a_spinning_one_started_before():
    stop = threading.Event()

    block = bytes(4 << 20)

    def spin():  # a thread that burns CPU without Python's lock, as Blender's waiting thread does
        while not stop.is_set():
            hashlib.sha256(block).digest()  # hashlib releases the GIL for data this large

    waiter = threading.Thread(target=spin, daemon=True)
    waiter.start()
    try:
        _burn(0.05)
        clock = RenderClock()
        spent = []
        worker = threading.Thread(target=lambda: spent.append(_burn(0.4)))  # the render's thread
        process0 = time.process_time()
        worker.start()
        worker.join()
        seconds = clock.seconds()
        process = time.process_time() - process0
    finally:
        stop.set()
        waiter.join()
    assert spent[0] >= 0.4
    # the waiting thread ran alongside: the process's time holds it
    assert process > spent[0] + 0.1
    # the clock holds the worker's time and the main thread's joining, not the waiting thread's
    assert spent[0] - 0.01 <= seconds <= spent[0] + 0.05


def test_never_negative_and_zero_for_no_work():
    clock = RenderClock()
    assert 0.0 <= clock.seconds() < 0.05


def test_paired_ratio_cancels_what_slows_both_renders_of_a_round():
    """Rounds whose both renders a busy machine slowed (by up to 3x) leave the paired ratio at the edit's own 1.08,
    where the ratio of the medians of all renders does not recover it."""
    anchor = [1.0, 3.0, 1.2, 2.5, 1.1, 2.8, 1.0]
    ours = [1.08 * a for a in anchor]
    ours[0] = 1.9  # one edited render slowed alone
    ratio, low, high = paired_ratio(ours, anchor)
    assert abs(ratio - 1.08) < 1e-12
    assert low <= ratio <= high and abs(low - 1.08) < 1e-12
    assert high <= 1.9 / 1.0
    assert statistics.median(ours) / statistics.median(anchor) > 1.5  # what the ratio of medians says


def test_paired_ratio_interval_spans_the_spread_of_the_rounds():
    """Rounds that disagree give an interval around their median, inside their range."""
    anchor = [1.0] * 9
    ours = [1.00, 1.02, 1.04, 1.06, 1.08, 1.10, 1.12, 1.14, 1.16]
    ratio, low, high = paired_ratio(ours, anchor)
    assert abs(ratio - 1.08) < 1e-12
    assert 1.0 <= low < ratio < high <= 1.16
