"""Suite-wide settings."""

import pytest
import torch


@pytest.fixture(scope="session", autouse=True)
def _one_torch_thread():
    """One intra-op torch thread for the whole suite: the walker's and the fitter's small batched ops gain
    nothing from two threads, and on a busy 2-core machine OpenMP threads waiting for each other cost
    10-70x (measured).  Commands set the same default through their --threads option."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
