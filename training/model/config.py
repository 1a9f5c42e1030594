"""Sizes of the chained networks and the physical ranges their outputs are mapped to (paper §5).

Every constant with a physical meaning lives here, with its source:

* ``SIGMA_T_RANGE_CM``: the extinction of a mixture component is predicted on a log scale between
  1e-1 and 1e5 cm^-1.  The fits of ``training.fit`` leave sigma_t unbounded (paper §4); skin's
  extinction is 1e2-1e3 cm^-1 in the visible (docs/research/skin_optics.md) and the mixture components of
  the fits spread a few decades around it, so the range leaves >= 2 decades of margin on each side.
* ``G_ABS_MAX``: |g| <= 0.99, as in the fitter (``training.fit.mixture``) and the simulator; the
  anisotropy range is further narrowed to the LUT's g axis when a LUT is given (``g_range``).
* ``SLAB_C`` = 3 and ``SLAB_DEPTH_INIT`` = 0.30: the slab-depth factor of paper eq. (slab_factor),
  R_k = R(alpha_k, g_k) (1 - exp(-C sigma_t,k c(lambda))), c learned per wavelength.  c is read in cm
  (sigma_t is in cm^-1); the paper gives no unit.
* ``log_params`` (``ModelConfig``): the parameters the networks see (Dec_R, Dec_T inputs) and produce (Enc
  outputs) on a log scale over their range: the dataset draws f_mel and f_blood log-uniformly
  (``training.data.sampling.LOG_SCALED``), so on a linear scale half the training tones would
  sit in the lowest ~4 % of the input interval and the encoder's sigmoid would have to reach f_mel = 0.005
  at u = 0.006.  Models made before (no key in their config) keep the linear scale.
* ``WEIGHT_SMOOTHING_NM`` = 6: Dec_T's mixture weights pass through a fixed Gaussian low-pass along
  wavelength (standard deviation 6 nm = 3 grid steps, ``ModelConfig.weight_smoothing_nm``).  A normalised
  kernel maps valid weights to valid weights, and no component's weight can then change by more than the
  kernel's peak, 0.133, between neighbouring 2 nm steps: the "weight jump > 0.2" of the spectral coherence
  measure (``training.validate.coherence.JUMP_DW``) cannot happen, whatever the network learns.  The
  prototypes without it jumped at a few fixed steps (docs/research/training.md, "L_smooth").  6 nm is
  well below the width
  of the skin chromophores' bands (haemoglobin's Q bands ~20 nm) and only the weights are smoothed;
  alpha, g and sigma_t keep the full resolution.  Ours, not the paper's.  Models made before (no key in
  their config) have none.
* ``FALLBACK_ALBEDO_RGB``: what the inversion graph uses in place of an input row with a NaN or Inf
  component (see ``training.model.chain``): a mid skin tone, so a corrupt texel renders as plausible
  skin instead of poisoning the render.  Linear sRGB (D65), chosen by us; not from the paper.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from exporters.constants import N_WAVELENGTHS, PARAM_NAMES, PARAM_RANGES
from training.data.sampling import LOG_SCALED

SIGMA_T_RANGE_CM: tuple[float, float] = (1e-1, 1e5)
G_ABS_MAX: float = 0.99
SLAB_C: float = 3.0
SLAB_DEPTH_INIT: float = 0.30
FALLBACK_ALBEDO_RGB: tuple[float, float, float] = (0.45, 0.30, 0.24)
WEIGHT_SMOOTHING_NM: float = 6.0
#: Smallest luminance of a predicted spectrum's colour used as a divisor in the exposure (Y of
#: white = 1).  A sigmoid spectrum never reaches it in practice; it only keeps the division finite.
Y_FLOOR: float = 1e-6
#: Network sizes by name (``python -m training train --size``): paper = the paper's networks (Dec_R 512,
#: Dec_T 4 x 768); small / tiny = narrower networks for quick experiments and tests.
SIZES: dict[str, dict[str, int]] = {
    "paper": {"enc_hidden": 70, "decr_hidden": 512, "dect_hidden": 768, "dect_layers": 4},
    "small": {"enc_hidden": 70, "decr_hidden": 256, "dect_hidden": 256, "dect_layers": 4},
    "tiny": {"enc_hidden": 16, "decr_hidden": 32, "dect_hidden": 32, "dect_layers": 3},
}


@dataclass
class ModelConfig:
    """Architecture of Enc, Dec_R and Dec_T (paper §5; BioSkin sizes for Enc and Dec_R).

    enc_hidden: Enc is 3 -> H -> H -> 5 (BioSkin: 70).  decr_hidden: Dec_R is 5 -> H -> H -> 376
    (BioSkin: 512-620).  dect_hidden / dect_layers: Dec_T is a ``dect_layers``-layer MLP 381 -> H ...
    -> 376 * 4K (paper: 4 layers, 768).  k: mixture components.  g_range: anisotropy interval of the
    outputs (the LUT's g axis within +-0.99).  sigma_t_range_cm: log-mapped extinction interval.
    weight_smoothing_nm: standard deviation (nm) of the Gaussian low-pass of Dec_T's weights along
    wavelength (module docstring; 0: none).
    log_params: parameters scaled logarithmically over their range in the networks (module docstring).
    """

    k: int = 3
    enc_hidden: int = 70
    decr_hidden: int = 512
    dect_hidden: int = 768
    dect_layers: int = 4
    g_range: tuple[float, float] = (-G_ABS_MAX, G_ABS_MAX)
    sigma_t_range_cm: tuple[float, float] = SIGMA_T_RANGE_CM
    n_wavelengths: int = N_WAVELENGTHS
    param_names: tuple[str, ...] = PARAM_NAMES
    param_ranges: dict[str, tuple[float, float]] = field(default_factory=lambda: dict(PARAM_RANGES))
    log_params: tuple[str, ...] = LOG_SCALED
    weight_smoothing_nm: float = WEIGHT_SMOOTHING_NM

    def __post_init__(self) -> None:
        if self.k < 1:
            raise ValueError(f"k must be >= 1, got {self.k}")
        if min(self.enc_hidden, self.decr_hidden, self.dect_hidden) < 1:
            widths = (self.enc_hidden, self.decr_hidden, self.dect_hidden)
            raise ValueError(f"hidden widths must be >= 1, got {widths}")
        if self.dect_layers < 2:
            raise ValueError(f"dect_layers must be >= 2, got {self.dect_layers}")
        lo, hi = (float(v) for v in self.g_range)
        if not (-G_ABS_MAX - 1e-9 <= lo < hi <= G_ABS_MAX + 1e-9):
            raise ValueError(f"g_range must lie within +-{G_ABS_MAX} and increase, got {self.g_range}")
        s_lo, s_hi = (float(v) for v in self.sigma_t_range_cm)
        if not (0 < s_lo < s_hi):
            raise ValueError(f"sigma_t_range_cm must be 0 < lo < hi, got {self.sigma_t_range_cm}")
        self.g_range = (lo, hi)
        self.sigma_t_range_cm = (s_lo, s_hi)
        self.param_names = tuple(self.param_names)
        self.param_ranges = {k: (float(v[0]), float(v[1])) for k, v in dict(self.param_ranges).items()}
        self.log_params = tuple(self.log_params)
        if not self.weight_smoothing_nm >= 0:
            raise ValueError(f"weight_smoothing_nm must be >= 0 nm, got {self.weight_smoothing_nm}")
        self.weight_smoothing_nm = float(self.weight_smoothing_nm)
        for name in self.log_params:
            if name not in self.param_names or self.param_ranges[name][0] <= 0:
                raise ValueError(f"log_params: {name!r} must be a parameter with a positive range")

    def to_dict(self) -> dict:
        """JSON-friendly form (lists for tuples)."""
        d = asdict(self)
        d["g_range"] = list(self.g_range)
        d["sigma_t_range_cm"] = list(self.sigma_t_range_cm)
        d["param_names"] = list(self.param_names)
        d["param_ranges"] = {k: list(v) for k, v in self.param_ranges.items()}
        d["log_params"] = list(self.log_params)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> ModelConfig:
        d = dict(d)
        d["g_range"] = tuple(d["g_range"])
        d["sigma_t_range_cm"] = tuple(d["sigma_t_range_cm"])
        d["param_names"] = tuple(d["param_names"])
        d["param_ranges"] = {k: tuple(v) for k, v in d["param_ranges"].items()}
        d["log_params"] = tuple(d.get("log_params", ()))  # models made before the key: linear scale
        d["weight_smoothing_nm"] = float(d.get("weight_smoothing_nm", 0.0))  # models made before: none
        return cls(**d)


def g_range_for_lut(g_axis_first: float, g_axis_last: float) -> tuple[float, float]:
    """The anisotropy interval of the outputs: the LUT's g axis within +-G_ABS_MAX (as the fitter)."""
    return max(float(g_axis_first), -G_ABS_MAX), min(float(g_axis_last), G_ABS_MAX)
