"""Mitsuba 3 scenes of the network's K-media mixture: the independent renderer of the validation path.

What is rendered (docs/research/mitsuba.md has the verified facts this module relies on):

* **The media.**  For one tone (a biophysical vector run through ``skin_decoder.onnx``, :func:`decode`)
  the K homogeneous media with their single-scattering albedo alpha(lambda), extinction sigma_t(lambda)
  (cm^-1) and Henyey-Greenstein g(lambda), inside a smooth ``dielectric`` boundary of index 1.4
  (``N_TISSUE``) with air outside.
* **The mixture.**  Mitsuba's built-in ``homogeneous`` medium holds one medium, so the mixture is rendered
  as the weighted sum of per-component renders, ``I(lambda) = sum_k w_k(lambda) I_k(lambda)``.  This is
  exact by linearity of light transport: a path that picks medium k with probability w_k when it enters
  (the paper's integrator, and ``training.validate.mixture``) has expectation ``sum_k w_k I_k``.  Images
  split their samples per component in proportion to w_k (the same cost as a per-path choice).
* **One wavelength per render.**  The built-in ``hg`` phase function takes one float g, and a path that
  carries wavelengths with different g would need ratio weights that blow up over many bounces
  (docs/research/mitsuba.md §3), so every render is monochromatic.  In ``*_rgb`` / ``*_mono`` variants the medium is
  given the three numbers at that wavelength; in ``*_spectral`` variants (the spectral path) alpha and sigma_t
  are ``regular`` spectra over the whole 250-1000 nm grid and a ``specfilm`` with a 1 nm wide response
  around the wavelength makes Mitsuba sample it (``hdrfilm`` samples only 360-830 nm).  Emitters use a
  ``uniform`` spectrum (an ``rgb`` emitter is zero outside the visible in spectral variants).
* **Total diffuse reflectance** (:func:`slab_reflectance`): a semi-infinite slab (a box of +-1000 mean
  free paths; for the semi-infinite slab the reflectance depends on alpha, g and n only, so sigma_t = 1)
  under a constant environment of radiance 1, seen by an ``irradiancemeter`` on a small downward-facing
  disk with a ``null`` BSDF just above the surface.  The meter integrates the radiance leaving the slab
  over the lower hemisphere with a cosine weight, which is pi times the hemispherical-hemispherical
  reflectance; by reciprocity (f_r(i->o) = f_r(o->i) holds for the external BSSRDF with a refracting
  boundary) this equals the reflectance for light entering from a cosine-weighted (Lambertian) lobe,
  which is the dataset's ``illumination="diffuse"``.  That total includes the specular reflection of the
  boundary, whose value for cosine-weighted incidence is known exactly (``training.sim.physics.diffuse_specular``,
  0.07681 for n = 1.4); R_d excludes it (docs/contracts.md §1), so it is removed: by subtracting the exact value,
  or (LLVM variants, ``specular="paired"``) by subtracting a twin render of a non-scattering (alpha = 0) slab with
  the same seed, whose paths make the same reflect/refract choices: the specular samples cancel one by
  one (Mitsuba's LLVM sampler has one random stream per lane), which removes their noise.
  Collimated beams are not used: delta lights seen through a smooth dielectric render black in
  ``volpath`` (docs/research/mitsuba.md §4, P0); measuring from the sensor side is what makes the boundary work.
* **Russian roulette** (docs/research/mitsuba.md §4, P1): volpath's roulette is very noisy while the path throughput
  stays near 1, so it starts only once alpha^depth < 0.1 (:func:`roulette_depth`); after that the throughput is
  small and roulette is efficient.  Roulette is unbiased; ``MAX_DEPTH`` only stops runaway paths.
* **Objects** (:func:`object_scene`): a sphere (or one of Mitsuba's built-in shapes) with the same
  dielectric boundary and medium, in centimetres, lit from one side by a spherical area light (not a
  point or spot light: pitfall P0), for the teaser-like strips.

Variants: ``scalar_rgb`` / ``scalar_spectral`` need nothing but the wheel (the tests use them);
``llvm_ad_*`` need libLLVM 19 (``make mitsuba`` installs Debian's ``libllvm19``; LLVM 14 is refused by
Dr.Jit and LLVM 15 aborts volpath renders), found by :func:`configure_llvm`.  Mitsuba itself is imported
only when a function needs it.  The validation renderer lives in ``training.validate`` (the shipped
``exporters`` holds only the runtime) and decodes tones with the runtime's one cached decoder session
(``exporters.inference.run_decoder``).
"""

from __future__ import annotations

import glob
import math
import os
from dataclasses import dataclass

import numpy as np

from exporters.constants import N_TISSUE, WAVELENGTHS_NM
from exporters.inference import run_decoder
from training.paths import SHIPPED_DECODER
from training.sim.physics import diffuse_specular
from training.validate.mixture import combine, neyman_allocation, precision_target

#: The decoder graph shipped with the add-on (docs/contracts.md §3).
DEFAULT_DECODER = SHIPPED_DECODER
#: Half-size of the slab box in mean free paths (sigma_t = 1); far beyond the diffusion length
#: 1 / sqrt(3 sigma_a sigma_t'), about 13 mfp at alpha = 0.99, g = 0.8 (docs/research/mitsuba.md §4).
SLAB_HALF_SIZE_MFP: float = 1000.0
#: Hard cap of volpath's path length (paths end by roulette or escape long before).
MAX_DEPTH: int = 65536
#: Roulette starts once alpha^depth falls below this throughput (see roulette_depth).
ROULETTE_THROUGHPUT: float = 0.1
#: Half-width of the spectral response of a monochromatic ``specfilm`` channel, nm.
SPECFILM_HALF_WIDTH_NM: float = 0.5
#: Libraries tried for the LLVM variants, newest first (Debian's libllvm19 layout).
LLVM_CANDIDATES: tuple[str, ...] = (
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.19*",
    "/usr/lib/x86_64-linux-gnu/libLLVM-19.so*",
    "/usr/lib/llvm-19/lib/libLLVM*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM.so.19*",
    "/usr/lib/aarch64-linux-gnu/libLLVM-19.so*",
)
INSTALL_HINT = "run `make mitsuba` (pip extra `mitsuba` = mitsuba 3.9.1 + drjit 1.5.0, and libllvm19 for llvm_ad_*)"


class MitsubaUnavailable(RuntimeError):
    """Mitsuba, or the libLLVM its LLVM variants need, is not installed; the message says how to get it."""


# ----------------------------------------------------------------------------------------------------
# Installation and variants


def find_libllvm() -> str | None:
    """Path of a libLLVM 19 shared library, or None (Debian: package ``libllvm19``)."""
    for pattern in LLVM_CANDIDATES:
        hits = sorted(glob.glob(pattern))
        if hits:
            return hits[0]
    return None


def configure_llvm() -> str | None:
    """Point Dr.Jit at libLLVM 19 (``DRJIT_LIBLLVM_PATH``) unless the user already set it.

    Dr.Jit otherwise loads whichever libLLVM comes first (15 on Debian 12 if installed, which aborts
    volpath renders).  Returns the path in use, or None if none is known.
    """
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return os.environ["DRJIT_LIBLLVM_PATH"]
    path = find_libllvm()
    if path:
        os.environ["DRJIT_LIBLLVM_PATH"] = path
    return path


def llvm_available() -> bool:
    """True when the LLVM variants can run here (libLLVM 19 found and Mitsuba installed)."""
    try:
        import mitsuba  # noqa: F401
    except ImportError:
        return False
    return configure_llvm() is not None


def default_variant(spectral: bool = False) -> str:
    """``llvm_ad_rgb`` (``llvm_ad_spectral``) when libLLVM 19 is installed, else the scalar variant."""
    kind = "spectral" if spectral else "rgb"
    return f"llvm_ad_{kind}" if configure_llvm() else f"scalar_{kind}"


def load_mitsuba(variant: str):
    """Import Mitsuba and set ``variant``; raises MitsubaUnavailable with the install command if missing."""
    if variant.startswith("llvm"):
        if configure_llvm() is None:
            raise MitsubaUnavailable(f"variant {variant!r} needs libLLVM 19, which is not installed: {INSTALL_HINT}, "
                                     "or use a scalar_* variant.")
    try:
        import mitsuba as mi
    except ImportError as exc:
        raise MitsubaUnavailable(f"Mitsuba 3 is not installed: {INSTALL_HINT}.") from exc
    if variant not in mi.variants():
        raise ValueError(f"unknown Mitsuba variant {variant!r}; this wheel has {sorted(mi.variants())}.")
    mi.set_variant(variant)
    return mi


def is_spectral(variant: str) -> bool:
    """True for the spectral variants (media as spectra, ``specfilm`` sensors)."""
    return "spectral" in variant


# ----------------------------------------------------------------------------------------------------
# The mixture of one tone


@dataclass(frozen=True)
class MitsubaMixture:
    """K homogeneous media per wavelength: ``alpha``, ``sigma_t`` (cm^-1), ``g``, ``weight`` of shape (K, W)
    at ``wavelength_nm`` (W,); weights sum to 1 over K.  ``reflectance`` (W,): the network's own R.  One tone in
    numpy, what the Mitsuba scenes render (the fitter's batch of torch media is ``training.fit.mixture.Mixture``)."""

    wavelength_nm: np.ndarray
    alpha: np.ndarray
    sigma_t: np.ndarray
    g: np.ndarray
    weight: np.ndarray
    reflectance: np.ndarray

    @property
    def k(self) -> int:
        return int(self.alpha.shape[0])

    def painted(self, albedo_rgb) -> MitsubaMixture:
        """The mixture with the painted colour ``albedo_rgb`` (3,) linear sRGB (exporters.painted, what a bake
        renders by default): alpha and sigma_t corrected in the visible, the rest unchanged.  On the 376-sample
        grid only (decode first, then :meth:`at`)."""
        from exporters.painted import paint_mixture

        if self.wavelength_nm.shape != WAVELENGTHS_NM.shape or not np.allclose(self.wavelength_nm, WAVELENGTHS_NM):
            raise ValueError("paint the mixture on the model's 376-sample grid (before MitsubaMixture.at)")
        p = paint_mixture(self.alpha[None], self.sigma_t[None], self.g[None], self.weight[None],
                          np.asarray(albedo_rgb, np.float64).reshape(1, 3))
        return MitsubaMixture(self.wavelength_nm, p.alpha[0], p.sigma_t[0], self.g, self.weight, self.reflectance)

    def at(self, wavelengths_nm) -> MitsubaMixture:
        """The mixture at other wavelengths (W',) inside its range: every field linearly interpolated
        (exact at the 2 nm grid points); weights renormalised to sum to 1."""
        wl = check_wavelengths(wavelengths_nm, self.wavelength_nm[0], self.wavelength_nm[-1])
        lerp = lambda a: np.stack([np.interp(wl, self.wavelength_nm, row) for row in a])  # noqa: E731
        w = lerp(self.weight)
        return MitsubaMixture(wl, lerp(self.alpha), lerp(self.sigma_t), lerp(self.g), w / w.sum(axis=0),
                       np.interp(wl, self.wavelength_nm, self.reflectance))


def check_wavelengths(wavelengths_nm, lo: float = WAVELENGTHS_NM[0], hi: float = WAVELENGTHS_NM[-1]) -> np.ndarray:
    """Wavelengths as a float64 (W,) array, all finite and within [lo, hi] nm; ValueError otherwise."""
    wl = np.atleast_1d(np.asarray(wavelengths_nm, dtype=np.float64))
    if wl.ndim != 1 or wl.size == 0:
        raise ValueError("give at least one wavelength (nm), e.g. 300,450,550,650,950.")
    if not np.all(np.isfinite(wl)) or wl.min() < lo - 1e-9 or wl.max() > hi + 1e-9:
        raise ValueError(f"wavelengths must lie in [{lo:g}, {hi:g}] nm (the model's grid), got {wl.tolist()}.")
    return wl


def decode(biophysical, model_path: str | os.PathLike = DEFAULT_DECODER) -> MitsubaMixture:
    """The network's mixture of one tone: ``biophysical`` (5,) (docs/contracts.md §1) through ``skin_decoder.onnx``.

    Returns the MitsubaMixture on the 376-sample grid (float64).  ValueError for a bad vector or model output.
    """
    p = np.asarray(biophysical, dtype=np.float64).reshape(-1)
    if p.shape != (5,) or not np.all(np.isfinite(p)):
        raise ValueError(f"biophysical must be 5 finite numbers (f_mel f_blood t_epi so2 b_mel), got {p.tolist()}.")
    out = run_decoder(p[None], model_path)
    fields = {n: out[n][0] for n in ("alpha", "sigma_t", "g", "weight", "reflectance")}
    for name, arr in fields.items():
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"the decoder returned NaN/Inf in {name!r} for {p.tolist()}.")
    return MitsubaMixture(WAVELENGTHS_NM.astype(np.float64), **fields)


# ----------------------------------------------------------------------------------------------------
# Scene pieces


def _spectrum(variant: str, value: float | np.ndarray):
    """A constant (rgb/mono) or a ``regular`` 250-1000 nm spectrum (spectral variants, (376,) values)."""
    if np.ndim(value) == 0:
        return {"type": "uniform", "value": float(value)}
    values = np.asarray(value, dtype=np.float64)
    if values.shape != WAVELENGTHS_NM.shape:
        raise ValueError(f"a spectrum needs {WAVELENGTHS_NM.size} values on the model grid, got {values.shape}.")
    return {"type": "regular", "wavelength_min": float(WAVELENGTHS_NM[0]), "wavelength_max": float(WAVELENGTHS_NM[-1]),
            "values": ", ".join(f"{v:.9g}" for v in values)}


def medium_dict(variant: str, alpha, sigma_t, g: float, scale: float = 1.0) -> dict:
    """A ``homogeneous`` medium.  ``alpha``, ``sigma_t``: floats (one wavelength) or, in spectral variants,
    (376,) arrays on the model grid; ``g``: the HG anisotropy at the rendered wavelength; sigma_t is in
    scene units^-1 after multiplication by ``scale``."""
    if not -0.999 < float(g) < 0.999:
        raise ValueError(f"g must lie in (-0.999, 0.999), got {g}.")
    a = np.asarray(alpha, dtype=np.float64)
    s = np.asarray(sigma_t, dtype=np.float64)
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(s))) or a.min() < 0 or a.max() > 1 or s.min() < 0:
        raise ValueError("alpha must lie in [0, 1] and sigma_t be >= 0 and finite.")
    if not is_spectral(variant) and (a.ndim or s.ndim):
        raise ValueError(f"variant {variant!r} takes alpha and sigma_t at one wavelength (floats).")
    return {"type": "homogeneous", "albedo": _spectrum(variant, alpha), "sigma_t": _spectrum(variant, sigma_t),
            "scale": float(scale), "phase": {"type": "hg", "g": float(g)}}


def film_dict(variant: str, wavelength_nm: float | None, width: int = 1, height: int = 1) -> dict:
    """A film: ``hdrfilm`` (rgb/mono), or a one-channel ``specfilm`` whose 1 nm response around
    ``wavelength_nm`` makes a spectral variant sample that wavelength (also outside 360-830 nm)."""
    base = {"width": int(width), "height": int(height), "rfilter": {"type": "box"}}
    if not is_spectral(variant):
        return {"type": "hdrfilm", "pixel_format": "rgb", **base}
    if wavelength_nm is None:
        raise ValueError("spectral variants render one wavelength at a time: give wavelength_nm.")
    lo, hi = wavelength_nm - SPECFILM_HALF_WIDTH_NM, wavelength_nm + SPECFILM_HALF_WIDTH_NM
    srf = {"type": "regular", "wavelength_min": lo, "wavelength_max": hi, "values": "1, 1"}
    return {"type": "specfilm", **base, "band": srf}


def roulette_depth(alpha: float) -> int:
    """Path depth after which volpath may play Russian roulette: the first depth with alpha^d < 0.1.

    Before it the throughput stays near 1, where volpath's roulette (q = min(throughput eta^2, 0.95))
    inflates the weights of long paths by (alpha / 0.95)^depth (docs/research/mitsuba.md §4, P1).
    """
    a = min(max(float(alpha), 1e-6), 1 - 1e-9)
    return int(min(max(math.ceil(math.log(ROULETTE_THROUGHPUT) / math.log(a)), 5), MAX_DEPTH // 2))


def integrator_dict(alpha_max: float) -> dict:
    """``volpath`` with the roulette depth of the highest albedo in the scene."""
    return {"type": "volpath", "max_depth": MAX_DEPTH, "rr_depth": roulette_depth(alpha_max)}


def _dielectric() -> dict:
    return {"type": "dielectric", "int_ior": float(N_TISSUE), "ext_ior": 1.0}


def slab_scene_dict(variant: str, alpha, g: float, wavelength_nm: float | None = None) -> dict:
    """The reflectance scene: a semi-infinite slab (sigma_t = 1 per scene unit) of one medium in a
    constant unit environment, with an ``irradiancemeter`` facing it (see the module docstring).

    ``alpha``: float, or (376,) on the grid in spectral variants (then ``wavelength_nm`` is rendered).
    """
    from mitsuba import ScalarTransform4f as T

    half = SLAB_HALF_SIZE_MFP
    a_max = float(alpha) if np.ndim(alpha) == 0 else float(np.interp(wavelength_nm, WAVELENGTHS_NM, alpha))
    return {
        "type": "scene",
        "integrator": integrator_dict(a_max),
        "env": {"type": "constant", "radiance": _spectrum(variant, 1.0)},
        "meter": {
            "type": "disk",
            # a small disk just above the surface, its normal turned down towards the slab
            "to_world": T().translate([0.0, 0.0, 1e-3]).scale(0.01) @ T().rotate([1.0, 0.0, 0.0], 180.0),
            "bsdf": {"type": "null"},
            "sensor": {"type": "irradiancemeter", "film": film_dict(variant, wavelength_nm)},
        },
        "slab": {
            "type": "cube",
            "to_world": T().translate([0.0, 0.0, -half]).scale(half),
            "bsdf": _dielectric(),
            "interior": medium_dict(variant, alpha, 1.0, g),
        },
    }


# ----------------------------------------------------------------------------------------------------
# Rendering


@dataclass(frozen=True)
class Estimate:
    """A Monte Carlo value (mean over ``batches`` independent renders) and its standard error."""

    value: float
    stderr: float
    samples: int
    seconds: float


def _pixel_mean(image) -> float:
    """Mean of the colour channels of a 1x1 film (all equal in rgb variants; one channel in specfilm)."""
    return float(np.mean(np.asarray(image, dtype=np.float64)))


def _batch_estimate(values: list[float], samples: int, seconds: float) -> Estimate:
    v = np.asarray(values, dtype=np.float64)
    se = float(v.std(ddof=1) / math.sqrt(v.size)) if v.size > 1 else float("nan")
    return Estimate(float(v.mean()), se, samples, seconds)


def slab_reflectance(alpha, g: float, *, spp: int, variant: str = "scalar_rgb", wavelength_nm: float | None = None,
                     batches: int = 8, seed: int = 0, specular: str = "auto") -> Estimate:
    """Total diffuse reflectance R_d (specular excluded) of a semi-infinite slab of one medium for
    cosine-weighted (diffuse) illumination, n = 1.4: Mitsuba's estimate with its standard error.

    Args:
        alpha: single-scattering albedo (float), or (376,) on the grid for spectral variants.
        g: HG anisotropy at the rendered wavelength.
        spp: paths in total, split over ``batches`` renders with seeds seed*1000 + b; the standard error
            is the spread of the batch means (batches >= 2).
        wavelength_nm: the wavelength a spectral variant renders (a 1 nm band around it).
        specular: "exact" (subtract diffuse_specular()), "paired" (subtract an alpha = 0 twin render
            with the same seeds: needs an LLVM variant, whose sampler has one stream per lane), "auto"
            (paired for llvm, exact otherwise).
    """
    import time

    if batches < 2 or spp < batches:
        raise ValueError(f"need batches >= 2 and spp >= batches, got spp={spp}, batches={batches}.")
    if specular == "auto":
        specular = "paired" if variant.startswith("llvm") else "exact"
    if specular not in ("exact", "paired"):
        raise ValueError(f"specular must be 'exact', 'paired' or 'auto', got {specular!r}.")
    if specular == "paired" and not variant.startswith("llvm"):
        raise ValueError("specular='paired' needs an llvm_* variant (scalar samplers share one stream per block).")
    mi = load_mitsuba(variant)
    t0 = time.perf_counter()
    scene = mi.load_dict(slab_scene_dict(variant, alpha, g, wavelength_nm))
    twin = None
    if specular == "paired":
        twin = mi.load_dict(slab_scene_dict(variant, 0.0, g, wavelength_nm))
    per = int(spp) // int(batches)
    values = []
    for b in range(int(batches)):
        s = int(seed) * 1000 + b
        total = _pixel_mean(mi.render(scene, spp=per, seed=s)) / math.pi
        spec = _pixel_mean(mi.render(twin, spp=per, seed=s)) / math.pi if twin is not None else diffuse_specular()
        if not math.isfinite(total - spec):
            raise RuntimeError(f"Mitsuba returned a non-finite reflectance (alpha={alpha}, g={g}, seed={s}).")
        values.append(total - spec)
    return _batch_estimate(values, per * int(batches), time.perf_counter() - t0)


@dataclass(frozen=True)
class MixtureEstimate:
    """Mixture R_d (W,) with standard errors, and the per-component values R_k, R_k_stderr (K, W)."""

    wavelength_nm: np.ndarray
    R_d: np.ndarray
    R_d_stderr: np.ndarray
    R_k: np.ndarray
    R_k_stderr: np.ndarray
    spp: np.ndarray
    variant: str
    seconds: float

    @property
    def per_path_sd(self) -> np.ndarray:
        """(K, W): the standard deviation of one path's estimate of R_k (stderr x sqrt(paths))."""
        return self.R_k_stderr * np.sqrt(self.spp)


def mixture_reflectance(mixture: MitsubaMixture, *, spp: int | np.ndarray, variant: str = "scalar_rgb",
                        batches: int = 8, seed: int = 0, specular: str = "auto", progress=None) -> MixtureEstimate:
    """R_d of the mixture at each of its wavelengths: sum_k w_k R_k, one slab render per (k, lambda).

    Exact by linearity (see the module docstring); stderr = sqrt(sum_k w_k^2 se_k^2).  ``spp``: paths per
    component and wavelength, one number or a (K, W) array (:func:`paths_for_precision`); components of zero
    weight are not rendered.  ``progress``: optional callable(done, total).
    """
    import time

    t0 = time.perf_counter()
    k, w = mixture.alpha.shape
    paths = np.broadcast_to(np.asarray(spp, dtype=np.int64), (k, w))
    r = np.zeros((k, w))
    se = np.zeros((k, w))
    spectral = is_spectral(variant)
    full = decode_grid_alpha(mixture) if spectral else None
    for j, lam in enumerate(mixture.wavelength_nm):
        for c in range(k):
            if mixture.weight[c, j] > 0:
                alpha = full[c] if spectral else float(mixture.alpha[c, j])
                est = slab_reflectance(alpha, float(mixture.g[c, j]), spp=int(paths[c, j]), variant=variant,
                                       wavelength_nm=float(lam) if spectral else None, batches=batches,
                                       seed=seed * 7919 + j * 31 + c, specular=specular)
                r[c, j], se[c, j] = est.value, est.stderr
            if progress:
                progress(j * k + c + 1, k * w)
    total, total_se = combine(mixture.weight, r, se)
    return MixtureEstimate(mixture.wavelength_nm, total, total_se, r, se, (paths // batches) * batches, variant,
                           time.perf_counter() - t0)


def paths_for_precision(mixture: MitsubaMixture, rel_stderr: float, *, variant: str = "scalar_rgb",
                        batches: int = 16, pilot_spp: int = 65536, pilot_batches: int = 8, seed: int = 0,
                        specular: str = "auto") -> np.ndarray:
    """Paths per component and wavelength (K, W) for :func:`mixture_reflectance` (with ``batches``) to reach a
    standard error of about ``rel_stderr`` x R_d at every wavelength: a pilot render of ``pilot_spp`` paths per
    component, in ``pilot_batches`` renders, measures each component's spread; then
    training.validate.mixture.neyman_allocation (floor: pilot_spp / 4).  The pilot's spread is itself noisy
    (about 1 / sqrt(2 (pilot_batches - 1)), 27 % at 8 batches), but its cost is mostly per render (a render of
    10^5 paths costs little more than one of 256), hence few batches.  Give the real render another ``seed``
    than the pilot's, so that its estimate and standard error do not reuse the pilot's paths."""
    pilot = mixture_reflectance(mixture, spp=pilot_spp, variant=variant, batches=pilot_batches, seed=seed,
                                specular=specular)
    return neyman_allocation(mixture.weight, pilot.per_path_sd, precision_target(pilot.R_d, rel_stderr),
                             multiple=batches, floor=max(pilot_spp // 4, batches))


def decode_grid_alpha(mixture: MitsubaMixture) -> np.ndarray:
    """alpha (K, 376) on the full grid for spectral variants' ``regular`` spectra (interpolated if the
    mixture is held at other wavelengths; exact when it was decoded on the grid)."""
    return np.stack([np.interp(WAVELENGTHS_NM, mixture.wavelength_nm, row) for row in mixture.alpha])


# ----------------------------------------------------------------------------------------------------
# Objects for images


@dataclass(frozen=True)
class ObjectSetup:
    """A side-lit object in centimetres: shape ``"sphere"`` (radius ``size_cm``) or ``"cube"`` (half-size),
    camera on +z looking at the origin (horizontal field of view ``fov_deg``), image ``width`` x ``height``.

    The light is an environment that is ``light_radiance`` (flat spectrum) inside a cone of half-angle
    ``light_half_angle_deg`` around ``light_direction`` (left of the object: -x, a little up and towards
    the camera) and black elsewhere, with a soft edge of ``light_edge_deg``.  A wide source keeps the
    noise low (a path inside the dielectric can reach a light only by escaping towards it: there is no
    next-event estimation through a smooth boundary), and a point or spot light would render black
    (docs/research/mitsuba.md §4, P0).
    """

    shape: str = "sphere"
    size_cm: float = 1.0
    width: int = 64
    height: int = 64
    fov_deg: float = 22.0
    camera_distance_cm: float = 6.0
    light_direction: tuple[float, float, float] = (-1.0, 0.35, 0.25)
    light_half_angle_deg: float = 35.0
    light_edge_deg: float = 10.0
    light_radiance: float = 1.0
    env_resolution: int = 256

    def light_unit(self) -> np.ndarray:
        """Unit vector towards the light's centre."""
        d = np.asarray(self.light_direction, dtype=np.float64)
        return d / np.linalg.norm(d)

    def light_profile(self, cos_angle: np.ndarray) -> np.ndarray:
        """Radiance of the light for directions at cos_angle to its centre (smoothstep edge)."""
        ang = np.degrees(np.arccos(np.clip(cos_angle, -1.0, 1.0)))
        half, edge = self.light_half_angle_deg, self.light_edge_deg / 2
        lo, hi = half - edge, half + edge
        t = np.clip((hi - ang) / (hi - lo), 0.0, 1.0)
        return self.light_radiance * t * t * (3 - 2 * t)


def environment_image(setup: ObjectSetup) -> np.ndarray:
    """Latitude-longitude image (H, 2H, 3) of the light for Mitsuba's ``envmap`` (float32).

    Mitsuba's mapping: u = atan2(x, -z) / 2 pi, v = acos(y) / pi for a world direction (x, y, z).
    """
    h = setup.env_resolution
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(2 * h) + 0.5) / (2 * h)
    theta, phi = np.meshgrid(v * np.pi, u * 2 * np.pi, indexing="ij")
    d = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)], axis=-1)
    radiance = setup.light_profile(d @ setup.light_unit())
    return np.repeat(radiance[..., None], 3, axis=2).astype(np.float32)


def object_scene_dict(variant: str, alpha: float, sigma_t_cm: float, g: float, setup: ObjectSetup = ObjectSetup(),
                      wavelength_nm: float | None = None) -> dict:
    """A scene with one homogeneous medium inside the dielectric boundary of ``setup.shape``, at one
    wavelength (floats), lit by the environment of :func:`environment_image`.  rgb/mono variants (an
    ``envmap`` is an RGB image; in spectral variants it would be zero outside the visible)."""
    import mitsuba as mi
    from mitsuba import ScalarTransform4f as T

    if is_spectral(variant):
        raise ValueError("object scenes take an rgb or mono variant (one wavelength per render).")
    if setup.shape not in ("sphere", "cube"):
        raise ValueError(f"shape must be 'sphere' or 'cube', got {setup.shape!r}.")
    turn = T().rotate([1.0, 0.0, 0.0], 25.0) @ T().rotate([0.0, 1.0, 0.0], 35.0) if setup.shape == "cube" else T()
    shape = {"type": setup.shape, "to_world": T().scale(setup.size_cm) @ turn}
    return {
        "type": "scene",
        "integrator": integrator_dict(alpha),
        "sensor": {
            "type": "perspective", "fov": setup.fov_deg,
            "to_world": T().look_at(origin=[0.0, 0.0, setup.camera_distance_cm], target=[0.0, 0.0, 0.0],
                                    up=[0.0, 1.0, 0.0]),
            "film": film_dict(variant, wavelength_nm, setup.width, setup.height),
        },
        "light": {"type": "envmap", "bitmap": mi.Bitmap(environment_image(setup))},
        "object": {**shape, "bsdf": _dielectric(), "interior": medium_dict(variant, alpha, sigma_t_cm, g)},
    }


class ObjectRenderer:
    """Renders one object scene for many media without reloading it.  rgb/mono variants only (one
    wavelength per render through the medium's numbers; the light is flat).

    The medium's numbers are updated in place and made opaque, and the integrator is passed per render
    with the roulette depth of that medium rounded up to a power of two, so the LLVM variants compile a
    handful of kernels in all (Dr.Jit also caches them on disk) instead of one per render.
    """

    def __init__(self, variant: str, setup: ObjectSetup = ObjectSetup()) -> None:
        if is_spectral(variant):
            raise ValueError("ObjectRenderer takes an rgb or mono variant (one wavelength per render).")
        self.mi = load_mitsuba(variant)
        self.variant, self.setup = variant, setup
        self.scene = self.mi.load_dict(object_scene_dict(variant, 0.5, 10.0, 0.0, setup))
        self.params = self.mi.traverse(self.scene)
        self._prefix = "object.interior_medium."
        self._integrators: dict[int, object] = {}
        #: pixels whose Mitsuba value was NaN/Inf and was set to 0 (reported by the strips)
        self.nonfinite_pixels = 0

    def _integrator(self, alpha: float):
        depth = 1 << max(3, math.ceil(math.log2(roulette_depth(alpha))))
        if depth not in self._integrators:
            self._integrators[depth] = self.mi.load_dict({"type": "volpath", "max_depth": MAX_DEPTH, "rr_depth": depth})
        return self._integrators[depth]

    def render(self, alpha: float, sigma_t_cm: float, g: float, spp: int, seed: int = 0) -> np.ndarray:
        """Radiance image (height, width), float64, for one medium (the light's radiance is setup.light_radiance)."""
        if spp < 1:
            return np.zeros((self.setup.height, self.setup.width))
        medium_dict(self.variant, float(alpha), float(sigma_t_cm), float(g))  # validates the numbers
        import drjit as dr

        p = self.params
        for key, value in (("albedo.value.value", alpha), ("sigma_t.value.value", sigma_t_cm),
                           ("phase_function.g", g)):
            v = self.mi.Float(float(value))
            dr.make_opaque(v)
            p[self._prefix + key] = v
        p.update()
        img = self.mi.render(self.scene, spp=int(spp), seed=int(seed), integrator=self._integrator(float(alpha)))
        out = np.asarray(img, dtype=np.float64).mean(axis=-1)
        bad = ~np.isfinite(out)
        if bad.any():  # rare NaN samples of Mitsuba's LLVM volpath (about 1 pixel in 10^5): dropped, counted
            out[bad] = 0.0
            self.nonfinite_pixels += int(bad.sum())
        return out

    def render_mixture(self, mixture: MitsubaMixture, j: int, spp: int, seed: int = 0) -> np.ndarray:
        """Image of the mixture at its wavelength index ``j``: sum_k w_k I_k with spp_k ~ w_k spp rounded to
        a power of two (at least 1 per component of non-zero weight; any spp_k keeps the sum unbiased, and
        few distinct values keep the LLVM kernels cached)."""
        out = np.zeros((self.setup.height, self.setup.width))
        for c in range(mixture.k):
            w = float(mixture.weight[c, j])
            if w <= 0.0:
                continue
            n = 1 << max(0, round(math.log2(max(w * spp, 1.0))))
            out += w * self.render(mixture.alpha[c, j], mixture.sigma_t[c, j], mixture.g[c, j], n,
                                   seed=seed * 101 + c)
        return out
