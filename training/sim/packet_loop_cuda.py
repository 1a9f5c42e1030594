"""The compiled per-packet walk on a CUDA GPU: the CPU kernel's own ``_walk_one``, one GPU thread per packet.

numba compiles ``training.sim.packet_loop._walk_one`` for the GPU as well (a CUDA kernel may call an ``@njit``
function, which numba then compiles as a device function), so both targets run the same source, the same
physics and the same per-packet random streams: a packet's record is the same on either (up to the GPU's
rounding of transcendental functions).  Under numba's CUDA simulator (environment variable
NUMBA_ENABLE_CUDASIM=1, with NUMBA_DISABLE_JIT=1 since the simulator's arrays are not numba types) the launch
runs on the CPU, each simulated GPU thread running ``_walk_one``'s Python source: that is how the tests
exercise this path without a GPU.
"""

from __future__ import annotations

import numpy as np
from numba import config, cuda

from training.sim.packet_loop import _walk_one

if config.ENABLE_CUDASIM and not config.DISABLE_JIT:
    raise ImportError("numba's CUDA simulator runs the walk as Python: "
                      "set NUMBA_DISABLE_JIT=1 with NUMBA_ENABLE_CUDASIM=1")

#: GPU threads per block (one packet each).
THREADS_PER_BLOCK = 128


@cuda.jit
def _walk_kernel(ch, serial, key, t_mut, t_alb, t_g, t_ztop, t_zbot, n, n_below, n_layers, n_ch,
                 diffuse, cos_in, max_steps, roulette_threshold, roulette_keep, path_n0, path_keep, record_paths,
                 out_kind, out_w, out_x, out_y, out_ncoll, out_absorbed, out_path, out_specular,
                 out_roulette, out_steps):
    i = cuda.grid(1)
    if i < ch.shape[0]:
        _walk_one(i, ch, serial, key, t_mut, t_alb, t_g, t_ztop, t_zbot, n, n_below, n_layers, n_ch,
                  diffuse, cos_in, max_steps, roulette_threshold, roulette_keep, path_n0, path_keep, record_paths,
                  out_kind, out_w, out_x, out_y, out_ncoll, out_absorbed, out_path, out_specular,
                  out_roulette, out_steps)


def walk_batch_cuda(ch: np.ndarray, serial: np.ndarray, key: np.uint64, *args) -> None:
    """``training.sim.packet_loop.walk_batch`` on the GPU: same arguments, outputs written into the same
    host arrays (copied to the device and back around one launch of one thread per packet)."""
    arrays = [cuda.to_device(a) if isinstance(a, np.ndarray) else a for a in (ch, serial, key, *args)]
    blocks = (ch.shape[0] + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK
    _walk_kernel[blocks, THREADS_PER_BLOCK](*arrays)
    for host, dev in zip((ch, serial, key, *args), arrays, strict=True):
        if isinstance(host, np.ndarray) and host.flags.writeable and dev is not host:
            dev.copy_to_host(host)
