"""The layered medium simulated by the Monte Carlo walker.

Geometry: z points into the tissue, the top surface is z = 0, layers are stacked top first.  Air
(index 1) is above; every layer has the same refractive index ``n_medium`` (index-matched internal
boundaries); below a finite stack is a medium of index ``n_below`` (1 = air).  Each layer has its own
optical properties per channel (a channel is a wavelength, or a g column of the lookup table).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from training.sim.medium_check import check_layer_values


@dataclass
class LayeredMedium:
    """Optical properties of L layers over W channels.

    Attributes:
        mua: (L, W) absorption coefficient, cm^-1, >= 0.
        mus: (L, W) scattering coefficient, cm^-1, >= 0.
        g: (L, W) Henyey-Greenstein anisotropy, in [-0.99, 0.99] (wider values are rejected: the
            walk cost explodes and the sampler loses precision).
        thickness: (L,) cm, > 0; only the last may be +inf (semi-infinite).
        n_medium: refractive index of every layer (air above).
        n_below: refractive index below a finite stack (ignored when the last layer is semi-infinite).
    """

    mua: torch.Tensor
    mus: torch.Tensor
    g: torch.Tensor
    thickness: torch.Tensor
    n_medium: float = 1.4
    n_below: float = 1.0

    def __post_init__(self) -> None:
        self.mua = torch.as_tensor(self.mua, dtype=torch.float64)
        self.mus = torch.as_tensor(self.mus, dtype=torch.float64)
        self.g = torch.as_tensor(self.g, dtype=torch.float64)
        self.thickness = torch.as_tensor(self.thickness, dtype=torch.float64).reshape(-1)
        self._validate()

    def _validate(self) -> None:
        if self.mua.ndim != 2:
            raise ValueError(f"mua must have shape (L, W), got {tuple(self.mua.shape)}")
        shape = self.mua.shape
        for name in ("mus", "g"):
            t = getattr(self, name)
            if t.shape != shape:
                raise ValueError(f"{name} must have the shape of mua {tuple(shape)}, got {tuple(t.shape)}")
        n_layers = shape[0]
        if n_layers < 1 or shape[1] < 1:
            raise ValueError("the medium needs at least one layer and one channel")
        if self.thickness.shape != (n_layers,):
            raise ValueError(f"thickness must have shape ({n_layers},), got {tuple(self.thickness.shape)}")
        host = lambda t: t.detach().cpu().numpy()  # noqa: E731
        check_layer_values(host(self.mua), host(self.mus), host(self.g), host(self.thickness),
                           self.n_medium, self.n_below)

    @property
    def n_layers(self) -> int:
        return int(self.mua.shape[0])

    @property
    def n_channels(self) -> int:
        return int(self.mua.shape[1])

    @property
    def semi_infinite(self) -> bool:
        return bool(torch.isinf(self.thickness[-1]))

    def boundaries(self) -> torch.Tensor:
        """Depths of the layer boundaries, shape (L + 1,), cm: 0, t0, t0 + t1, ... (last may be inf)."""
        return torch.cat([torch.zeros(1, dtype=torch.float64), torch.cumsum(self.thickness, 0)])

    def select_channels(self, index) -> LayeredMedium:
        """The same layers at a subset of the channels (``index``: indices or a boolean mask over W)."""
        idx = torch.as_tensor(index)
        return LayeredMedium(self.mua[:, idx], self.mus[:, idx], self.g[:, idx], self.thickness,
                             self.n_medium, self.n_below)

    @classmethod
    def homogeneous(
        cls, mua, mus, g, thickness: float = math.inf, n_medium: float = 1.4, n_below: float = 1.0
    ) -> LayeredMedium:
        """One layer; ``mua``, ``mus``, ``g`` are scalars or (W,) arrays."""
        mua, mus, g = (torch.as_tensor(v, dtype=torch.float64).reshape(1, -1) for v in (mua, mus, g))
        mua, mus, g = torch.broadcast_tensors(mua, mus, g)
        return cls(mua.clone(), mus.clone(), g.clone(), torch.tensor([thickness]), n_medium, n_below)
