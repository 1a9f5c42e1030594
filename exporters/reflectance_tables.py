"""Total diffuse reflectance of a semi-infinite Henyey-Greenstein medium, R(alpha, g), for two boundaries.

Both tables are the reflectance for *diffuse* (cosine-weighted) illumination of a semi-infinite,
homogeneous medium with single-scattering albedo ``alpha`` and HG anisotropy ``g``, computed once by
adding-doubling (iadpython 0.5.3, ``Sample(a, b=inf, g, n, quad_pts=16).rt()`` -> URU; Prahl's method,
checked against van de Hulst's tables) and stored in ``exporters/data/reflectance_tables.npz``:

* ``"cycles"``: n = 1 (index-matched).  What Cycles 5.0's RANDOM_WALK closure renders: the entry bounce
  has no Fresnel weight (ior 1.01 changes no direction), the exit is a Lambertian of weight 1, so under
  uniform white light a pixel seen from direction v is the directional-hemispherical reflectance R(v) of
  the index-matched medium, and the cosine-weighted mean over v (what a flat patch averaged over viewing
  directions, or a large sphere seen whole, shows) is URU.  Checked against Cycles renders in
  tests/test_bake_fidelity.py.
* ``"model"``: n = 1.4 below air, the specular surface reflection excluded (URU(alpha) - URU(0)): the
  boundary of the training simulator and lookup tables (training/sim/lut.py: "diffuse (cosine-weighted)
  illumination through the Fresnel boundary, specular reflection excluded"), i.e. the reflectance each
  mixture component k of the model carries, R(alpha_k, g_k).

Grid: u = sqrt(1 - alpha) uniform on [1e-3, 1] (129 nodes; near alpha -> 1, R ~ 1 - c u is nearly linear
in u, so bilinear interpolation in (u, g) is accurate to ~1e-4, see tests/test_collapse.py), and g from 0
to 0.95 in steps of 0.05.  alpha above 1 - 1e-6 is treated as 1 - 1e-6.

Regenerate with ``python -m exporters.reflectance_tables --build`` (needs iadpython, a test dependency;
about 10 minutes on one core).  Reading the tables needs numpy only.
"""

from __future__ import annotations

import argparse
import sys
import time
from functools import cache
from pathlib import Path
from typing import Literal

import numpy as np

Boundary = Literal["cycles", "model"]
BOUNDARIES: tuple[str, ...] = ("cycles", "model")
#: Refractive index below air for each table.
BOUNDARY_N: dict[str, float] = {"cycles": 1.0, "model": 1.4}
TABLE_PATH = Path(__file__).resolve().parent / "data" / "reflectance_tables.npz"
U_MIN: float = 1e-3
N_U: int = 129
G_STEP: float = 0.05
N_G: int = 20
#: Largest albedo the tables resolve (u = U_MIN).
ALPHA_TABLE_MAX: float = 1.0 - U_MIN**2


def u_grid() -> np.ndarray:
    """Nodes in u = sqrt(1 - alpha), increasing (so alpha decreasing), shape (N_U,)."""
    return np.linspace(U_MIN, 1.0, N_U)


def g_grid() -> np.ndarray:
    """Anisotropy nodes 0, 0.05, ..., 0.95, shape (N_G,)."""
    return np.arange(N_G) * G_STEP


def build_tables(path: str | Path = TABLE_PATH, quad_pts: int = 16) -> Path:
    """Compute both tables with iadpython (adding-doubling) and write them to ``path`` (.npz)."""
    import iadpython  # test/build dependency only; lazily imported

    u, g = u_grid(), g_grid()
    alpha = 1.0 - u**2
    out: dict[str, np.ndarray] = {"u": u, "g": g}
    for name in BOUNDARIES:
        n = BOUNDARY_N[name]
        table = np.empty((g.size, u.size))
        for i, gi in enumerate(g):
            t0 = time.perf_counter()
            sample = iadpython.Sample(a=alpha, b=np.full_like(alpha, np.inf), g=np.full_like(alpha, gi), n=n,
                                      quad_pts=quad_pts)
            uru = np.asarray(sample.rt()[2], dtype=np.float64)
            if n != 1.0:  # exclude the specular reflection of the smooth surface (the albedo-0 value)
                spec = iadpython.Sample(a=0.0, b=np.inf, g=gi, n=n, quad_pts=quad_pts).rt()[2]
                uru = uru - float(spec)
            table[i] = uru
            print(f"[tables] {name} g={gi:.2f}: R in [{uru.min():.4f}, {uru.max():.4f}] "
                  f"({time.perf_counter() - t0:.1f} s)", flush=True)
        if not np.all(np.isfinite(table)) or np.any(np.diff(table, axis=1) > 0):
            raise RuntimeError(f"{name} table is not finite or not decreasing in u")
        out[name] = table
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **out, source=np.array(
        f"iadpython {iadpython.__version__} Sample(a, b=inf, g, n, quad_pts={quad_pts}).rt() URU; "
        "model: n=1.4 minus the a=0 (specular) value"))
    return path


@cache
def _load() -> dict[str, np.ndarray]:
    if not TABLE_PATH.is_file():
        raise FileNotFoundError(f"reflectance tables missing: {TABLE_PATH} (python -m exporters.reflectance_tables "
                                "--build)")
    with np.load(TABLE_PATH) as data:
        tables = {key: np.array(data[key]) for key in ("u", "g", *BOUNDARIES)}
    for arr in tables.values():
        arr.setflags(write=False)
    return tables


def _check(boundary: str) -> None:
    if boundary not in BOUNDARIES:
        raise ValueError(f"boundary must be one of {BOUNDARIES}, not {boundary!r}")


def _g_index(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower g node index and fraction for bilinear interpolation (g clipped to the grid)."""
    x = np.clip(g, 0.0, (N_G - 1) * G_STEP) / G_STEP
    i = np.minimum(np.floor(x).astype(np.intp), N_G - 2)
    return i, x - i


def _u_of_alpha(alpha: np.ndarray) -> np.ndarray:
    return np.sqrt(np.clip(1.0 - alpha, U_MIN**2, 1.0))


def _finite(name: str, x) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: NaN or infinite value(s); all inputs must be finite")
    return arr


def reflectance(boundary: Boundary, alpha, g) -> np.ndarray:
    """R(alpha, g) of a semi-infinite medium under diffuse light for ``boundary`` ("cycles" or "model").

    ``alpha`` in [0, 1], ``g`` in [0, 0.95] (broadcastable; values outside are clipped to the table, alpha
    above 1 - 1e-6 counts as 1 - 1e-6).  Bilinear interpolation in (sqrt(1 - alpha), g); float64.
    """
    _check(boundary)
    al, gg = np.broadcast_arrays(_finite("alpha", alpha), _finite("g", g))
    t = _load()[boundary]
    u = _u_of_alpha(al)
    xu = (u - U_MIN) / (1.0 - U_MIN) * (N_U - 1)
    j = np.minimum(np.floor(xu).astype(np.intp), N_U - 2)
    fu = xu - j
    i, fg = _g_index(gg)
    lo = t[i, j] * (1.0 - fu) + t[i, j + 1] * fu
    hi = t[i + 1, j] * (1.0 - fu) + t[i + 1, j + 1] * fu
    return lo * (1.0 - fg) + hi * fg


def albedo_for_reflectance(boundary: Boundary, reflectance_target, g, iterations: int = 60) -> np.ndarray:
    """Inverse of :func:`reflectance` in alpha: the albedo whose table reflectance is ``reflectance_target``.

    R is strictly increasing in alpha on the table (checked when it is built), so the answer is unique;
    found by bisection in u = sqrt(1 - alpha) (60 halvings: below 1e-15 in u).  Targets outside
    [R(0, g), R(1 - 1e-6, g)] give the end albedo (0 or 1 - 1e-6): callers clamp targets first.
    """
    _check(boundary)
    target, gg = np.broadcast_arrays(_finite("reflectance", reflectance_target), _finite("g", g))
    lo = np.full(target.shape, U_MIN)  # u = U_MIN: highest reflectance
    hi = np.ones(target.shape)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        too_bright = reflectance(boundary, 1.0 - mid**2, gg) > target  # R decreases with u
        lo = np.where(too_bright, mid, lo)
        hi = np.where(too_bright, hi, mid)
    return 1.0 - (0.5 * (lo + hi)) ** 2


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m exporters.reflectance_tables", description=__doc__.splitlines()[0])
    parser.add_argument("--build", action="store_true", help="recompute the tables with iadpython")
    parser.add_argument("--out", type=Path, default=TABLE_PATH)
    args = parser.parse_args(argv)
    if not args.build:
        parser.print_help()
        return 0
    print(f"wrote {build_tables(args.out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
