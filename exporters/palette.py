"""Distinct colours of an image: a palette and, per texel, its index into it (fast enough for 4096² textures).

Every bake value depends on the texel's colour only, so a bake evaluates each distinct colour once and
expands the results through the index.  How the distinct colours are found depends on the pixel type:

* 8-bit codes with up to 3 channels: the packed code (24 bits) marks a 2^24 bitmap, whose set entries
  are the palette in code order — no sort (about 0.1 s for 16.7 M texels).
* 16-bit codes: the packed code (48 bits) is sorted (``np.unique`` on uint64, about 2 s for 16.7 M).
* float32 rows: the three bit patterns are hashed to 64 bits and the hashes sorted; then every texel is
  compared bit for bit with its palette entry, and if two different colours shared a hash (never seen,
  but possible) the rows are sorted exactly as 12-byte records instead (slower, same result).

Rows compare bit for bit (-0.0 is first made +0.0); the palette order is an implementation detail.  NaN
rows are not rejected here (callers check for non-finite texels first and say where they are).
"""

from __future__ import annotations

import numpy as np

#: Odd 64-bit multipliers of the float-row hash (from SplitMix64 / Murmur3's finaliser constants).
_HASH_MULT = (np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB))


def _index_dtype(n: int) -> type:
    return np.int32 if n < 2**31 else np.int64


def _check_rows(rows: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(rows)
    if arr.ndim != 2 or not 1 <= arr.shape[1] <= 4:
        raise ValueError(f"{name} must have shape (N, C) with 1 <= C <= 4, got {arr.shape}")
    return arr


def unique_codes(codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct rows of integer pixel codes (N, C) (uint8 or uint16, C <= 4) and the inverse index.

    Returns ``(palette (M, C) of the same dtype, inverse (N,) int32)`` with ``palette[inverse] == codes``,
    the palette in increasing packed-code order.  Empty input gives empty outputs.
    """
    arr = _check_rows(codes, "codes")
    if arr.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"codes must be uint8 or uint16, got {arr.dtype}")
    n, c = arr.shape
    bits = 8 * arr.dtype.itemsize
    if bits * c <= 24:  # bitmap: no sort
        key32 = np.zeros(n, np.uint32)
        for j in range(c):
            key32 <<= np.uint32(bits)
            key32 |= arr[:, j]
        used = np.zeros(1 << (bits * c), bool)
        used[key32] = True
        found = np.flatnonzero(used)
        position = np.zeros(used.size, _index_dtype(max(len(found), 1)))
        position[found] = np.arange(len(found))
        inverse = position[key32]
        uniq = found.astype(np.uint64)
    else:
        key = np.zeros(n, np.uint64)
        for j in range(c):
            key = (key << np.uint64(bits)) | arr[:, j].astype(np.uint64)
        uniq, inverse = _unique_u64(key)
    palette = np.empty((len(uniq), c), arr.dtype)
    mask = np.uint64((1 << bits) - 1)
    for j in range(c - 1, -1, -1):
        palette[:, j] = (uniq & mask).astype(arr.dtype)
        uniq = uniq >> np.uint64(bits)
    return palette, inverse


def _unique_u64(key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted distinct values of a uint64 array and the inverse index: a sort and a binary search, about 1.5x as
    fast as ``np.unique(return_inverse=True)`` (an argsort) when the distinct values are few (textures)."""
    srt = np.sort(key)
    keep = np.empty(len(srt), bool)
    keep[:1] = True
    np.not_equal(srt[1:], srt[:-1], out=keep[1:])
    uniq = srt[keep]
    if 4 * len(uniq) > len(key):  # many distinct values: the binary search would cost more than an argsort
        return uniq, np.unique(key, return_inverse=True)[1].ravel().astype(_index_dtype(max(len(uniq), 1)))
    return uniq, np.searchsorted(uniq, key).astype(_index_dtype(max(len(uniq), 1)))


def _exact_float_unique(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    keys = np.ascontiguousarray(x).view(np.dtype((np.void, 4 * x.shape[1]))).ravel()
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    return x[first], inverse.ravel().astype(_index_dtype(max(len(first), 1)))


def unique_float_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct rows of a float32 array (N, C), C <= 4, and the inverse index (``palette[inverse] == rows``).

    Exact (bit for bit after -0.0 -> +0.0): a 64-bit hash groups the rows, then every row is checked
    against its group's first row; on a hash collision the rows are grouped by an exact sort instead.
    """
    x = np.ascontiguousarray(_check_rows(rows, "rows"), dtype=np.float32) + np.float32(0.0)
    n, c = x.shape
    if n == 0:
        return x.copy(), np.zeros(0, np.int32)
    bits = x.view(np.uint32).astype(np.uint64)
    h = np.zeros(n, np.uint64)
    with np.errstate(over="ignore"):
        for j in range(c):
            h = (h ^ bits[:, j]) * _HASH_MULT[j % 3]
            h ^= h >> np.uint64(31)
    hashes, inverse = _unique_u64(h)
    first = np.empty(len(hashes), np.int64)
    first[inverse[::-1]] = np.arange(n - 1, -1, -1)  # the first row of each hash (last write wins)
    palette = x[first]
    if not np.array_equal(palette.view(np.uint32)[inverse], x.view(np.uint32)):
        return _exact_float_unique(x)  # two colours shared a hash
    return palette, inverse
