"""Constants shared by the walk engines (the vectorised torch step and the compiled per-packet loop).

Torch-free, so that the compiled engine and the command line that drives it load without torch.
"""

from __future__ import annotations

#: Longest single hop, cm: bounds pathological hops (transparent layer at grazing incidence); a
#: physical hop is <= 17.3 / sigma_t <= 1730 cm for sigma_t >= 1e-2 cm^-1 (uniforms >= 2^-25).
MAX_HOP_CM = 1e6

#: Below this |g| the HG inversion formula loses precision; sample isotropically instead (exact at
#: g = 0, and the HG cosine mean differs by at most |g|/3 < 3e-7 from isotropic there).
G_ISOTROPIC_EPS = 1e-6

#: Weight roulette (MCML's): a packet below this weight survives 1 / ROULETTE_BOOST of the time, with its
#: weight multiplied by ROULETTE_BOOST.
ROULETTE_THRESHOLD = 1e-4
ROULETTE_BOOST = 10.0

#: Packets walked at once on a CPU: ~2^18 keeps the float32 working set of the torch step in cache, and is the
#: compiled walk's batch.
POOL_PACKETS_CPU = 1 << 18

# Packet fates (``kind`` of a finished record).
KIND_ABSORBED = 0  #: killed by roulette or weight exhausted: all its weight is in ``absorbed``
KIND_REFLECTED = 1  #: escaped through the top surface
KIND_TRANSMITTED = 2  #: escaped through the bottom of a finite stack after >= 1 scattering
KIND_UNSCATTERED = 3  #: escaped through the bottom without any scattering (ballistic)
KIND_TRUNCATED = 4  #: still alive at the walk cap; its weight w is reported as truncated

#: Walk engines: "numba" (the compiled per-packet loop on CPU threads), "numba-cuda" (the same loop, one CUDA
#: thread per packet: ``training.sim.packet_loop_cuda``) and "torch" (the vectorised step, CPU or CUDA,
#: optionally torch.compile'd); "auto" picks numba on a CPU and torch on CUDA.
ENGINES = ("auto", "numba", "numba-cuda", "torch")
