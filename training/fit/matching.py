"""Component identity along wavelength: a permutation of the K mixture components per wavelength.

A K-media fit is defined up to the order of its components, and the fitter's order is arbitrary (it
depends on which start won, and the K - 1 fallback appends a copy).  Sorting by sigma_t at every
(tone, wavelength) (the trainer's ``targets="fitted"``) makes the k-th output "the k-th slowest medium"
at each wavelength on its own: wherever two components' sigma_t cross, their identities swap, and the
targets jump between neighbouring wavelengths (a comb in the decoder trained on them).

``match_along_wavelength`` keeps each component's identity continuous instead:

* at a reference wavelength (``ref``; default ``REFERENCE_NM``) the components are sorted by increasing
  sigma_t, so that identities agree from tone to tone (component 0 is the slowest-decaying medium
  *there*);
* from it, wavelength by wavelength outwards in both directions, the permutation (of the K! <= 6; brute
  force) is chosen that minimises the distance to the previous, already matched wavelength:

      d = sum_k c_k [ (dlogit alpha / S_ALPHA)^2 + (dln sigma_t / S_SIGMA)^2 + (dg / S_G)^2 ] + (dw / S_W)^2,
      c_k = (w_prev,k + w_cur,k) / 2 + C_MIN

  The parameters of a component that carries almost no weight do not show in the profile and are
  whatever the optimiser left there, so they count in proportion to the weight (``c_k``); the weight
  itself always counts.

The permutation leaves the mixture (its profile and reflectance) unchanged, so it can be applied to
any fits: the trainer applies it on loading, and ``fit --dataset`` stores its fits matched.  Applying
it twice gives the same order (the matched order is the minimiser at every step).
"""

from __future__ import annotations

import itertools

import numpy as np

from exporters.constants import WAVELENGTHS_NM

#: Fields of a mixture in the arrays this module permutes, each (N, K, W).
FIELDS: tuple[str, ...] = ("alpha", "g", "sigma_t", "weight")
#: Wavelength (nm) at which the components are sorted by sigma_t: mid-visible, where the profiles are
#: broad (high albedo) and resolved over many bins, so the fitted media are well separated.
REFERENCE_NM: float = 600.0
#: Scales of the distance (our choice): a unit in logit alpha or ln sigma_t, 0.2 in g or in weight.
S_ALPHA: float = 1.0
S_SIGMA: float = 1.0
S_G: float = 0.2
S_W: float = 0.2
#: Floor of the parameter terms' weight c_k, so that zero-weight components still break ties.
C_MIN: float = 0.02
#: logit alpha is clipped to +-LOGIT_MAX (alpha within 6e-6 of 0 or 1 is one value for the distance).
LOGIT_MAX: float = 12.0


def permutations(k: int) -> np.ndarray:
    """All K! orders of range(K), shape (K!, K), the identity first."""
    return np.array(list(itertools.permutations(range(k))), dtype=np.int64)


def _features(a: dict[str, np.ndarray], col: int) -> tuple[np.ndarray, np.ndarray]:
    """(scaled (logit alpha, ln sigma_t, g) (N, K, 3), weight (N, K)) at wavelength column ``col``."""
    alpha = np.clip(a["alpha"][..., col], 1e-12, 1 - 1e-12)
    logit = np.clip(np.log(alpha) - np.log1p(-alpha), -LOGIT_MAX, LOGIT_MAX)
    feat = np.stack([logit / S_ALPHA, np.log(np.maximum(a["sigma_t"][..., col], 1e-30)) / S_SIGMA,
                     a["g"][..., col] / S_G], axis=-1)
    return feat, a["weight"][..., col]


def _step_order(prev: tuple[np.ndarray, np.ndarray], cur: tuple[np.ndarray, np.ndarray],
                perms: np.ndarray) -> np.ndarray:
    """The order (N, K) of the current components that is nearest to the previous (matched) ones."""
    fp, wp = prev
    fc, wc = cur
    fc_p, wc_p = fc[:, perms], wc[:, perms]  # (N, P, K, 3), (N, P, K)
    c = 0.5 * (wp[:, None] + wc_p) + C_MIN
    d = (c * ((fc_p - fp[:, None]) ** 2).sum(-1)).sum(-1) + (((wc_p - wp[:, None]) / S_W) ** 2).sum(-1)
    return perms[d.argmin(1)]


def match_along_wavelength(arrays: dict[str, np.ndarray], wavelength_nm: np.ndarray | None = None,
                           ref_nm: float = REFERENCE_NM) -> np.ndarray:
    """The matched order of the components: index array (N, K, W) such that ``np.take_along_axis(x,
    order, axis=1)`` is matched (module docstring) for every field x of ``arrays`` ({alpha, g, sigma_t,
    weight}: (N, K, W)).  ``wavelength_nm`` (W,): the wavelengths of the columns (default the 376 of the
    grid when W = 376, else the reference is the middle column); the reference is the column nearest
    ``ref_nm``.  Raises ValueError on NaN/Inf or inconsistent shapes."""
    shape = arrays["alpha"].shape
    if len(shape) != 3 or any(arrays[f].shape != shape for f in FIELDS):
        raise ValueError(f"fields {FIELDS} must all be (N, K, W) arrays of one shape")
    if not all(np.all(np.isfinite(arrays[f])) for f in FIELDS):
        raise ValueError("mixture parameters contain NaN/Inf")
    n, k, w = shape
    order = np.empty(shape, dtype=np.int64)
    if wavelength_nm is None and w == WAVELENGTHS_NM.size:
        wavelength_nm = WAVELENGTHS_NM
    ref = w // 2 if wavelength_nm is None else int(np.abs(np.asarray(wavelength_nm) - ref_nm).argmin())
    order[..., ref] = np.argsort(arrays["sigma_t"][..., ref], axis=1, kind="stable")
    if k == 1 or w == 1:
        order[:] = order[..., ref : ref + 1]
        return order
    perms = permutations(k)
    for cols in (range(ref + 1, w), range(ref - 1, -1, -1)):
        last = ref
        for col in cols:
            feat_p, w_p = _features(arrays, last)
            prev = (np.take_along_axis(feat_p, order[..., last, None], 1), np.take_along_axis(w_p, order[..., last], 1))
            feat_c, w_c = _features(arrays, col)
            order[..., col] = _step_order(prev, (feat_c, w_c), perms)
            last = col
    return order


def apply_order(arrays: dict[str, np.ndarray], order: np.ndarray) -> dict[str, np.ndarray]:
    """Every (N, K, W) array of ``arrays`` reordered along K by ``order`` (N, K, W)."""
    return {name: np.take_along_axis(v, order, axis=1) for name, v in arrays.items()}


def matched(arrays: dict[str, np.ndarray], wavelength_nm: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """``arrays`` with their components matched along wavelength (``match_along_wavelength``)."""
    return apply_order(arrays, match_along_wavelength(arrays, wavelength_nm))
