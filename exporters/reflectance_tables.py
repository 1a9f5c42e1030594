"""Reflectance of a semi-infinite Henyey-Greenstein medium: Cycles' random-walk boundary and the model's.

Computed once by adding-doubling (iadpython 0.5.3, Prahl's method, checked against van de Hulst's tables)
and stored in ``exporters/data/reflectance_tables.npz``; reading needs numpy only.

* ``"cycles"``: what Cycles 5.0's RANDOM_WALK closure renders under uniform white light, averaged over
  viewing directions with the cosine weight (what a flat patch seen from everywhere, or a large sphere
  seen whole, shows; by reciprocity the reflectance for diffuse illumination).  The kernel
  (integrator/subsurface.h) refracts the camera ray into the medium by Snell's law with the closure's IOR
  (roughness 0), applies **no** Fresnel weight, and ends the walk at the first surface crossing with a
  Lambertian of weight 1, so a pixel seen from mu = cos(view angle) is the directional reflectance
  R1(mu_t) of the *index-matched* medium at the refracted cosine mu_t = sqrt(1 - (1 - mu^2) / eta^2).
  Averaged: H(alpha, g; eta) = 2 int_0^1 mu R1(mu_t(mu)) dmu = eta^2 2 int_{mu_0}^1 mu_t R1(mu_t) dmu_t,
  mu_0 = sqrt(1 - 1/eta^2).  eta = 1 gives iadpython's URU.  Stored: R1 at 16 quadrature cosines
  (``Sample(n=1, quad_pts=16).rt_matrices()``); H is integrated on load for the IOR asked for
  (natural cubic spline of R1 in mu, 2049-point trapezoid).  Checked against Cycles renders in
  tests/test_bake_fidelity.py.
* ``"model"``: n = 1.4 below air, diffuse illumination, the specular surface reflection excluded
  (URU(alpha) - URU(0)): the boundary of the training simulator and lookup tables (training/sim/lut.py),
  i.e. the reflectance each mixture component k of the model carries, R(alpha_k, g_k).

Grid: u = sqrt(1 - alpha) uniform on [1e-3, 1] (129 nodes; near alpha -> 1, R ~ 1 - c u is nearly linear
in u, so bilinear interpolation in (u, g) is accurate to ~1e-3, see tests/test_collapse.py), and g from 0
to 0.95 in steps of 0.05.  alpha above 1 - 1e-6 is treated as 1 - 1e-6.

Regenerate with ``python -m training reflectance-tables --build`` (:func:`build_tables`; needs iadpython, a
test dependency; about 10 minutes on one core).
"""

from __future__ import annotations

import time
from functools import cache
from pathlib import Path
from typing import Literal

import numpy as np

from .constants import N_TISSUE

Boundary = Literal["cycles", "model"]
BOUNDARIES: tuple[str, ...] = ("cycles", "model")
TABLE_PATH = Path(__file__).resolve().parent / "data" / "reflectance_tables.npz"
U_MIN: float = 1e-3
N_U: int = 129
G_STEP: float = 0.05
N_G: int = 20
#: Largest g of the tables' grid (0.95): larger g are clipped to it (by the lookups and their callers).
G_TABLE_MAX: float = round((N_G - 1) * G_STEP, 12)
#: Refractive index of the model's boundary: the tissue index (exporters.constants.N_TISSUE).
MODEL_N: float = N_TISSUE
#: Quadrature cosines of the stored directional reflectance R1(mu) (16: iadpython is less accurate at 32 as
#: alpha -> 1, e.g. URU(0.999) 0.92847 vs van de Hulst 0.92971; at 16 it is 0.9297).
N_MU: int = 16
#: Cycles clamps the closure IOR to this range (closure/bssrdf.h bssrdf_setup).
IOR_MIN, IOR_MAX = 1.01, 3.8
#: Largest albedo the tables resolve (u = U_MIN).
ALPHA_TABLE_MAX: float = 1.0 - U_MIN**2


def u_grid() -> np.ndarray:
    """Nodes in u = sqrt(1 - alpha), increasing (so alpha decreasing), shape (N_U,)."""
    return np.linspace(U_MIN, 1.0, N_U)


def g_grid() -> np.ndarray:
    """Anisotropy nodes 0, 0.05, ..., 0.95, shape (N_G,)."""
    return np.arange(N_G) * G_STEP


def build_tables(path: str | Path = TABLE_PATH) -> Path:
    """Compute the tables with iadpython (adding-doubling) and write them to ``path`` (.npz)."""
    import iadpython  # test/build dependency only; lazily imported

    u, g = u_grid(), g_grid()
    alpha = 1.0 - u**2
    directional = np.empty((g.size, u.size, N_MU))
    model = np.empty((g.size, u.size))
    mu = None
    for i, gi in enumerate(g):
        t0 = time.perf_counter()
        for j, aj in enumerate(alpha):
            s = iadpython.Sample(a=aj, b=np.inf, g=gi, n=1.0, quad_pts=N_MU)
            s.update_quadrature()
            r_mat = s.rt_matrices()[0]
            directional[i, j] = (r_mat * s.twonuw[None, :]).sum(axis=1)  # R1(mu_i), diffuse-integrated
            mu = np.array(s.nu, dtype=np.float64) if mu is None else mu
        sample = iadpython.Sample(a=alpha, b=np.full_like(alpha, np.inf), g=np.full_like(alpha, gi), n=MODEL_N,
                                  quad_pts=16)
        spec = iadpython.Sample(a=0.0, b=np.inf, g=gi, n=MODEL_N, quad_pts=16).rt()[2]
        model[i] = np.asarray(sample.rt()[2], dtype=np.float64) - float(spec)
        print(f"[tables] g={gi:.2f}: R1 in [{directional[i].min():.4f}, {directional[i].max():.4f}], model R in "
              f"[{model[i].min():.4f}, {model[i].max():.4f}] ({time.perf_counter() - t0:.1f} s)", flush=True)
    for name, table in (("directional", directional), ("model", model)):
        if not np.all(np.isfinite(table)) or np.any(np.diff(table, axis=1) > 0):
            raise RuntimeError(f"{name} table is not finite or not decreasing in u")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, u=u, g=g, mu=mu, directional=directional, model=model, source=np.array(
        f"iadpython {iadpython.__version__}: directional = Sample(a, b=inf, g, n=1, quad_pts={N_MU}).rt_matrices() "
        "R summed against 2 nu w; model = Sample(a, b=inf, g, n=1.4, quad_pts=16).rt() URU minus its a=0 value"))
    return path


@cache
def _load() -> dict[str, np.ndarray]:
    if not TABLE_PATH.is_file():
        raise FileNotFoundError(f"reflectance tables missing: {TABLE_PATH} (python -m training reflectance-tables "
                                "--build)")
    with np.load(TABLE_PATH) as data:
        tables = {key: np.array(data[key]) for key in ("u", "g", "mu", "directional", "model")}
    for arr in tables.values():
        arr.setflags(write=False)
    return tables


def _natural_spline(nodes: np.ndarray, values: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Natural cubic spline through (nodes, values[..., i]) evaluated at x (constant outside the nodes).

    Hand-written (a 16-node tridiagonal system, solved densely) because the add-on runs inside Blender,
    whose Python has numpy but not scipy.
    """
    n = nodes.size
    h = np.diff(nodes)
    a = np.zeros((n, n))
    rhs = np.zeros(values.shape[:-1] + (n,))
    a[0, 0] = a[-1, -1] = 1.0
    for i in range(1, n - 1):
        a[i, i - 1], a[i, i], a[i, i + 1] = h[i - 1], 2.0 * (h[i - 1] + h[i]), h[i]
    slopes = np.diff(values, axis=-1) / h
    rhs[..., 1:-1] = 6.0 * np.diff(slopes, axis=-1)
    m = np.linalg.solve(a, rhs.reshape(-1, n).T).T.reshape(rhs.shape)  # second derivatives
    xc = np.clip(x, nodes[0], nodes[-1])
    i = np.clip(np.searchsorted(nodes, xc) - 1, 0, n - 2)
    t0, t1 = nodes[i + 1] - xc, xc - nodes[i]
    hi = h[i]
    return (m[..., i] * t0**3 / (6 * hi) + m[..., i + 1] * t1**3 / (6 * hi)
            + (values[..., i] / hi - m[..., i] * hi / 6) * t0 + (values[..., i + 1] / hi - m[..., i + 1] * hi / 6) * t1)


@cache
def _cycles_table(ior: float) -> np.ndarray:
    """H[g, u] for entry IOR ``ior``: eta^2 int_{mu_0}^1 2 mu R1(mu) dmu (module docstring), with R1 a
    natural cubic spline through the 16 stored cosines and a 2049-point trapezoid."""
    t = _load()
    mu0 = np.sqrt(1.0 - 1.0 / ior**2)
    x = np.linspace(mu0, 1.0, 2049)
    # The spline and the trapezoid rule are linear in the stored values: integrate the spline of each unit vector
    # once (one weight per stored cosine), then the table is a matrix product instead of (G, U, 2049) spline work.
    basis = 2.0 * x * _natural_spline(t["mu"], np.eye(t["mu"].size), x)  # (n_mu, X)
    weights = np.sum(0.5 * (basis[:, 1:] + basis[:, :-1]) * np.diff(x), axis=-1)  # trapezoid rule, (n_mu,)
    table = ior**2 * (t["directional"] @ weights)
    table.setflags(write=False)
    return table


def _table(boundary: str, ior: float | None) -> np.ndarray:
    if boundary == "model":
        return _load()["model"]
    if boundary != "cycles":
        raise ValueError(f"boundary must be one of {BOUNDARIES}, not {boundary!r}")
    eta = CYCLES_IOR if ior is None else float(ior)
    if not (1.0 <= eta <= IOR_MAX):  # 1.0: the index-matched limit (URU), useful as a reference
        raise ValueError(f"Cycles' subsurface IOR must lie in [{IOR_MIN}, {IOR_MAX}] (the kernel clamps it), "
                         f"got {eta}")
    return _cycles_table(round(eta, 6))


#: Default entry IOR of the Cycles closures: the tissue index (exporters.constants.N_TISSUE), also the node
#: group's default (blender_addon.nodes.DEFAULT_IOR) and bake.py's --ior.
CYCLES_IOR: float = N_TISSUE


def _g_index(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower g node index and fraction for bilinear interpolation (g clipped to the grid)."""
    x = np.clip(g, 0.0, G_TABLE_MAX) * (1.0 / G_STEP)
    i = np.minimum(x.astype(np.intp), N_G - 2)  # x >= 0: truncation is floor
    return i, x - i.astype(x.dtype)


def _u_of_alpha(alpha: np.ndarray) -> np.ndarray:
    return np.sqrt(np.clip(1.0 - alpha, U_MIN**2, 1.0))


def _finite(name: str, x) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: NaN or infinite value(s); all inputs must be finite")
    return arr


@cache
def _table32(boundary: str, ior: float | None) -> np.ndarray:
    t = _table(boundary, ior).astype(np.float32)
    t.setflags(write=False)
    return t


def reflectance(boundary: Boundary, alpha, g, ior: float | None = None) -> np.ndarray:
    """Diffuse reflectance R(alpha, g) of a semi-infinite medium for ``boundary`` ("cycles" or "model").

    ``alpha`` in [0, 1], ``g`` in [0, 0.95] (broadcastable; values outside are clipped to the table, alpha
    above 1 - 1e-6 counts as 1 - 1e-6); ``ior``: the Cycles closure's IOR (default :data:`CYCLES_IOR`;
    ignored for "model").  Bilinear interpolation in (sqrt(1 - alpha), g); float64, or float32 when both
    inputs are float32 arrays (the collapse's per-wavelength work, where float32 is plenty).
    """
    single = isinstance(alpha, np.ndarray) and isinstance(g, np.ndarray) and alpha.dtype == g.dtype == np.float32
    if single:
        if not (np.all(np.isfinite(alpha)) and np.all(np.isfinite(g))):
            raise ValueError("alpha, g: NaN or infinite value(s); all inputs must be finite")
        t = _table32(boundary, ior)
        al, gg = np.broadcast_arrays(alpha, g)
    else:
        t = _table(boundary, ior)
        al, gg = np.broadcast_arrays(_finite("alpha", alpha), _finite("g", g))
    return _bilinear(t, al, gg)


def normal_reflectance(alpha, g) -> np.ndarray:
    """What Cycles' RANDOM_WALK renders for a camera straight above under uniform white light: R1(mu_t = 1),
    the stored directional reflectance at its quadrature cosine 1 (the view ray enters along the normal
    whatever the IOR).  Bilinear in (sqrt(1 - alpha), g) as :func:`reflectance`; float64."""
    t = _load()
    if not np.isclose(t["mu"][-1], 1.0):
        raise RuntimeError(f"{TABLE_PATH} has no directional reflectance at mu = 1; rebuild it")
    al, gg = np.broadcast_arrays(_finite("alpha", alpha), _finite("g", g))
    return _bilinear(t["directional"][..., -1], al, gg)


def _bilinear(t: np.ndarray, al: np.ndarray, gg: np.ndarray) -> np.ndarray:
    """Table t[g node, u node] at (alpha, g), bilinear in (u, g)."""
    u = _u_of_alpha(al)
    xu = (u - U_MIN) * ((N_U - 1) / (1.0 - U_MIN))
    j = np.minimum(xu.astype(np.intp), N_U - 2)  # xu >= 0: truncation is floor
    fu = xu - j.astype(xu.dtype)
    i, fg = _g_index(gg)
    lo = t[i, j] * (1.0 - fu) + t[i, j + 1] * fu
    hi = t[i + 1, j] * (1.0 - fu) + t[i + 1, j + 1] * fu
    return lo * (1.0 - fg) + hi * fg


def albedo_for_reflectance(boundary: Boundary, reflectance_target, g, ior: float | None = None) -> np.ndarray:
    """Inverse of :func:`reflectance` in alpha: the albedo whose table reflectance is ``reflectance_target``.

    For a fixed g the interpolant is piecewise linear in u = sqrt(1 - alpha) on the table nodes and
    strictly decreasing (checked when the table is built), so the inverse is exact and unique: find the
    segment, solve the linear piece.  Targets outside [R(0, g), R(1 - 1e-6, g)] give the end albedo
    (0 or 1 - 1e-6): callers clamp targets first.
    """
    t = _table(boundary, ior)
    target, gg = np.broadcast_arrays(_finite("reflectance", reflectance_target), _finite("g", g))
    shape = target.shape
    target, gg = target.ravel(), gg.ravel()
    i, fg = _g_index(gg)
    rows = t[i] * (1.0 - fg)[:, None] + t[i + 1] * fg[:, None]  # (M, N_U), decreasing along u
    j = np.clip(np.sum(rows > target[:, None], axis=1) - 1, 0, N_U - 2)  # rows[j] > target >= rows[j + 1]
    m = np.arange(target.size)
    r0, r1 = rows[m, j], rows[m, j + 1]
    frac = np.clip((r0 - target) / np.where(r0 > r1, r0 - r1, 1.0), 0.0, 1.0)
    u = U_MIN + (j + frac) * (1.0 - U_MIN) / (N_U - 1)
    return (1.0 - u**2).reshape(shape)
