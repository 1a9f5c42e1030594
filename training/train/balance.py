"""Stage 3's tone balance: draw the training tones of sparse corners of the parameter box more often.

The laptop dataset draws most tones where skin colours are (``training.data.sampling``), so the corners of the
parameter box (the outlier tones: thinnest epidermis with the darkest melanin, maximum blood, the lower corner of
every range) hold few fitted tones, and the decoder is worst there.  With ``balance`` = b > 0 an epoch draws
its items with replacement (``loop.epoch_order``) from

    P(i) = (1 - b) / N + b * w_i / sum(w),   w_i = min(r_k(i) ** 5, CAP * median(r_k ** 5)),

where r_k(i) is the distance of tone i to its ``K_NEIGHBOURS``-th nearest neighbour in the box scaled to
the unit cube (f_mel, f_blood and t_epi on a log scale, as colour changes fastest at their low end; so2 and
b_mel linear).  r_k ** 5 is proportional to the inverse of the local density (the k-nearest-neighbour
density estimate in 5 dimensions, Loftsgaarden and Quesenberry 1965), so b = 1 draws the tones as if they
covered the box uniformly; CAP bounds how often one isolated tone is drawn.  b = 0 is a plain permutation.
"""

from __future__ import annotations

import numpy as np

from exporters.constants import PARAM_NAMES, PARAM_RANGES

#: Neighbour whose distance estimates the local density.
K_NEIGHBOURS: int = 8
#: Largest inverse-density weight, as a multiple of the median one.
CAP: float = 10.0
#: Parameters scaled logarithmically to the unit cube (the others linearly).
LOG_PARAMS: tuple[str, ...] = ("f_mel", "f_blood", "t_epi")


def unit_box(tone: np.ndarray) -> np.ndarray:
    """Tones (N, 5) in the parameter box (``PARAM_RANGES``) -> (N, 5) in [0, 1]^5 (``LOG_PARAMS`` on a log scale)."""
    out = np.empty(tone.shape, dtype=np.float64)
    for j, name in enumerate(PARAM_NAMES):
        lo, hi = PARAM_RANGES[name]
        x = np.clip(np.asarray(tone[:, j], dtype=np.float64), lo, hi)
        out[:, j] = (np.log(x / lo) / np.log(hi / lo)) if name in LOG_PARAMS else (x - lo) / (hi - lo)
    return out


def inverse_density_weights(tone: np.ndarray, chunk: int = 1024) -> np.ndarray:
    """Inverse-density weights (N,) of tones (N, 5), capped and normalised to sum 1 (module docstring)."""
    x = unit_box(tone)
    n = len(x)
    if n <= K_NEIGHBOURS:
        return np.full(n, 1.0 / n)
    r = np.empty(n)
    for s in range(0, n, chunk):
        d = np.sqrt(((x[s : s + chunk, None, :] - x[None, :, :]) ** 2).sum(-1))
        r[s : s + chunk] = np.partition(d, K_NEIGHBOURS, axis=1)[:, K_NEIGHBOURS]  # column 0 is the tone itself
    w = np.maximum(r, 1e-12) ** x.shape[1]
    w = np.minimum(w, CAP * np.median(w))
    return w / w.sum()


def sampling_probabilities(tone: np.ndarray, balance: float) -> np.ndarray:
    """P(i) (N,) of drawing tone i: (1 - balance) uniform + balance inverse density."""
    if not 0.0 <= balance <= 1.0:
        raise ValueError(f"balance must be in [0, 1], got {balance}")
    n = len(tone)
    return (1.0 - balance) / n + balance * inverse_density_weights(tone)
