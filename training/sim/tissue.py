"""A skin tone as the simulator's two-layer medium (epidermis over a semi-infinite dermis, n = 1.4)."""

from __future__ import annotations

import math

import numpy as np
import torch

from exporters.constants import N_TISSUE
from training.sim.medium import LayeredMedium
from training.skin.model import layer_optics


def skin_medium(tone: np.ndarray | torch.Tensor | list[float], absorbing: bool = True) -> LayeredMedium:
    """The LayeredMedium (2 layers x 376 wavelengths) of one tone (5,) in docs/contracts.md §1 order.

    ``absorbing=False`` gives the same geometry and scattering with mu_a = 0 (for absorption reweighting).
    """
    optics = layer_optics(tone)
    if optics.t_epi.numel() != 1:
        raise ValueError("skin_medium takes one tone (5,); loop over a batch")
    mua = torch.cat([optics.mua_epi, optics.mua_derm])
    return LayeredMedium(
        mua=mua if absorbing else torch.zeros_like(mua),
        mus=torch.cat([optics.mus_epi, optics.mus_derm]),
        g=torch.cat([optics.g_epi, optics.g_derm]),
        thickness=torch.tensor([float(optics.t_epi), math.inf], dtype=torch.float64),
        n_medium=N_TISSUE,
    )
