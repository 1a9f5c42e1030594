"""Teaser-like strips (paper Fig. 1): a side-lit sphere of each representative tone rendered by Mitsuba 3.

For every tone the network's mixture (``skin_decoder.onnx``) fills a sphere (radius 0.5 cm, dielectric
boundary n = 1.4) lit from the left by a cone of light (25 degrees half-angle) from the environment,
rendered one wavelength at a time (``training.validate.mitsuba_scene.ObjectRenderer``; the mixture is sum_k w_k I_k
with samples split by w_k):

* ``uv``: 250-380 nm, flat spectrum: mean over 5 equal sub-bands (midpoint wavelengths), grey;
* ``vis_E`` / ``vis_A``: 380-740 nm every 20 nm, the spectral image interpolated onto the 2 nm grid,
  seen under illuminant E or A (CIE 1931 2°, CAT02 to D65, sRGB; ``exporters.colorimetry``);
* ``nir``: 780-1000 nm, illuminant A: 5 equal sub-bands weighted by A's power, grey.

Each band is one PNG strip, the tones left (light) to right (dark) with one exposure for the whole strip
(so darker tones look darker), plus ``mitsuba_strips.png`` with all bands labelled and
``mitsuba_strips.json`` with the translucency measure: the mean radiance of the sphere where its
surface sees none of the light (more than 2 degrees beyond the cone's edge) over the mean where it
faces the light (cos > 0.5 to the light's centre).  Light can reach the far side only through the
medium, so the ratio is ~0 for an opaque tone and grows with translucency.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from exporters.colorimetry import SRGB_LUMINANCE, srgb_encode, xyz_to_linear_srgb, xyz_weights
from exporters.constants import WAVELENGTHS_NM
from exporters.maps import sha256_file
from training.paths import portable_strings
from training.skin.tones import load_tones
from training.validate import mitsuba_scene as em

BANDS = ("uv", "vis_E", "vis_A", "nir")
UV_NM = np.linspace(250.0, 380.0, 6)
NIR_NM = np.linspace(780.0, 1000.0, 6)
VIS_NM = np.arange(380.0, 740.0 + 1e-9, 20.0)
#: Exposure: the strip's EXPOSURE_PERCENTILE-th percentile of sphere pixels (specular highlights of the
#: light excluded by the percentile) is displayed at this linear value.
WHITE_POINT = 0.8
EXPOSURE_PERCENTILE = 97.0
#: The object: a sphere of radius 0.5 cm (an ear lobe's or a fingertip's scale, where skin translucency
#: shows), lit by a cone of 25 degrees half-angle (soft edge 10 degrees).
SETUP = dict(size_cm=0.5, camera_distance_cm=3.0, light_half_angle_deg=25.0, light_edge_deg=10.0)
#: Lit side for the translucency ratio: cos(normal, direction to the light's centre) above this.
LIT_COS = 0.5
#: Margin (degrees) beyond the light's outer edge for the far side (no direct light at all).
FAR_MARGIN_DEG = 2.0
FILES = {band: f"mitsuba_strip_{band}.png" for band in BANDS} | {"figure": "mitsuba_strips.png",
                                                                 "metrics": "mitsuba_strips.json"}


def _midpoints(edges: np.ndarray) -> np.ndarray:
    return 0.5 * (edges[:-1] + edges[1:])


def illuminant_a(wavelength_nm: np.ndarray) -> np.ndarray:
    """CIE illuminant A (relative, 100 at 560 nm) at any wavelengths (colour-science's analytic form)."""
    import colour

    wl = np.asarray(wavelength_nm, dtype=np.float64)
    sd = colour.sd_CIE_standard_illuminant_A(colour.SpectralShape(250, 1000, 1))
    return np.interp(wl, sd.wavelengths, sd.values)


def band_wavelengths() -> dict[str, np.ndarray]:
    """Wavelengths rendered per band (nm)."""
    return {"uv": _midpoints(UV_NM), "vis": VIS_NM, "nir": _midpoints(NIR_NM)}


def _interp_matrix(samples_nm: np.ndarray) -> np.ndarray:
    """(376, J) matrix: linear interpolation of J samples onto the grid (flat beyond the ends)."""
    eye = np.eye(samples_nm.size)
    return np.stack([np.interp(WAVELENGTHS_NM, samples_nm, eye[j]) for j in range(samples_nm.size)], axis=1)


def visible_linear_srgb(images: np.ndarray, samples_nm: np.ndarray, illuminant: str) -> np.ndarray:
    """Linear sRGB (H, W, 3) of a spectral image (J, H, W) at ``samples_nm`` seen under ``illuminant``."""
    m = xyz_weights(illuminant) @ _interp_matrix(samples_nm)  # (3, J)
    xyz = np.einsum("cj,jhw->hwc", m, images)
    return xyz_to_linear_srgb(xyz, illuminant)


def sphere_cosines(setup: em.ObjectSetup) -> np.ndarray:
    """Per pixel, cos(angle) between the sphere's normal and the direction to the light; NaN off the sphere.

    Pinhole camera of ``setup`` (Mitsuba's ``fov`` is horizontal; square images here), analytic ray-sphere hits.
    """
    h, w = setup.height, setup.width
    t = np.tan(np.radians(setup.fov_deg) / 2)
    x = (np.arange(w) + 0.5) / w * 2 - 1
    y = 1 - (np.arange(h) + 0.5) / h * 2
    xx, yy = np.meshgrid(x * t, y * t * h / w)
    d = np.stack([xx, yy, -np.ones_like(xx)], axis=-1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.array([0.0, 0.0, setup.camera_distance_cm])
    b = d @ o
    disc = b * b - (o @ o - setup.size_cm**2)
    hit = disc > 0
    s = -b - np.sqrt(np.where(hit, disc, 0.0))
    p = o + s[..., None] * d
    n = p / setup.size_cm
    return np.where(hit, n @ setup.light_unit(), np.nan)


def far_cos(setup: em.ObjectSetup) -> float:
    """Cosine below which a surface point sees none of the light (its outer edge plus FAR_MARGIN_DEG)."""
    return float(np.cos(np.radians(90.0 + setup.light_half_angle_deg + setup.light_edge_deg / 2 + FAR_MARGIN_DEG)))


def translucency(image: np.ndarray, cosines: np.ndarray, far_cosine: float) -> float:
    """Mean radiance where the sphere sees no light (cos < far_cosine) over the mean where it faces the
    light (cos > LIT_COS): 0 for an opaque medium, growing with translucency."""
    far, lit = cosines < far_cosine, cosines > LIT_COS
    lit_mean = float(image[lit].mean())
    return float(image[far].mean() / lit_mean) if lit_mean > 0 else 0.0


@dataclass(frozen=True)
class StripConfig:
    """Image size (pixels per tone), samples per pixel per wavelength (split over the K components by
    weight), Mitsuba variant (None: llvm_ad_rgb if available, else scalar_rgb), seed, decoder path."""

    size: int = 64
    spp: int = 48
    variant: str | None = None
    seed: int = 0
    decoder: str = str(em.DEFAULT_DECODER)


def render_tone_bands(renderer: em.ObjectRenderer, tone: np.ndarray, spp: int, seed: int, decoder) -> dict:
    """Linear images of one tone: ``uv``, ``nir`` (H, W) and ``vis`` (J, H, W) at band_wavelengths()."""
    out = {}
    for band, wl in band_wavelengths().items():
        mix = em.decode(tone, decoder).at(wl)
        out[band] = np.stack([renderer.render_mixture(mix, j, spp, seed=seed * 1000 + j) for j in range(wl.size)])
    return out


def band_images(raw: dict) -> dict[str, np.ndarray]:
    """Linear band images of one tone from its per-wavelength renders: uv, nir (H, W); vis_E, vis_A (H, W, 3)."""
    wl = band_wavelengths()
    a = illuminant_a(wl["nir"])
    return {
        "uv": raw["uv"].mean(axis=0),
        "vis_E": visible_linear_srgb(raw["vis"], wl["vis"], "E"),
        "vis_A": visible_linear_srgb(raw["vis"], wl["vis"], "A"),
        "nir": np.tensordot(a / a.sum(), raw["nir"], axes=1),
    }


def _luminance(image: np.ndarray) -> np.ndarray:
    """Grey images as they are; linear sRGB (H, W, 3) -> Rec. 709 luminance (H, W)."""
    return image if image.ndim == 2 else image @ SRGB_LUMINANCE


def _to_uint8(linear: np.ndarray, exposure: float) -> np.ndarray:
    enc = srgb_encode(np.clip(linear * exposure, 0.0, 1.0))
    return np.round(np.clip(enc, 0.0, 1.0) * 255).astype(np.uint8)


def render_strips(out_dir: Path, config: StripConfig = StripConfig(), overwrite: bool = False,
                  progress: bool = False) -> dict:
    """Render the representative tones, write the PNG strips, the labelled figure and the metrics JSON.

    Refuses (FileExistsError) to replace existing files unless ``overwrite``.  Returns the metrics record.
    """
    out_dir = Path(out_dir)
    targets = [out_dir / name for name in FILES.values()]
    existing = [str(p) for p in targets if p.exists()]
    if existing and not overwrite:
        raise FileExistsError(f"{', '.join(existing)} exist; pass --overwrite to replace them.")
    tones = load_tones().select("representative")
    variant = config.variant or em.default_variant()
    setup = em.ObjectSetup(width=config.size, height=config.size, **SETUP)
    renderer = em.ObjectRenderer(variant, setup)
    cos = sphere_cosines(setup)
    t0 = time.perf_counter()
    per_tone = []
    iterator = range(len(tones.names))
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, desc="tones", unit="tone")
    for i in iterator:
        raw = render_tone_bands(renderer, tones.values[i], config.spp, config.seed * 100 + i, config.decoder)
        per_tone.append(band_images(raw))
    seconds = time.perf_counter() - t0
    strips, metrics = {}, {}
    on_sphere = np.isfinite(cos)
    for band in BANDS:
        row = np.concatenate([imgs[band] for imgs in per_tone], axis=1)
        lum = [_luminance(imgs[band]) for imgs in per_tone]
        level = np.percentile(np.concatenate([x[on_sphere] for x in lum]), EXPOSURE_PERCENTILE)
        strips[band] = _to_uint8(row, WHITE_POINT / max(float(level), 1e-12))
        metrics[band] = [translucency(x, cos, far_cos(setup)) for x in lum]
    out_dir.mkdir(parents=True, exist_ok=True)
    _write_pngs(out_dir, strips)
    _write_figure(out_dir / FILES["figure"], strips, tones.names, config.size)
    record = {"tones": list(tones.names), "biophysical": tones.values.tolist(), "translucency": metrics,
              "band_wavelengths_nm": {k: v.tolist() for k, v in band_wavelengths().items()},
              "config": asdict(config) | {"variant": variant}, "seconds": seconds,
              "nonfinite_pixels_dropped": renderer.nonfinite_pixels,
              "decoder": Path(config.decoder).name, "decoder_sha256": sha256_file(config.decoder),
              "translucency_definition": f"mean radiance where cos(normal, light centre) < {far_cos(setup):.3f} "
                                         f"(no direct light) over the mean where it is > {LIT_COS}"}
    (out_dir / FILES["metrics"]).write_text(json.dumps(portable_strings(record), indent=1))
    return record


def _write_pngs(out_dir: Path, strips: dict[str, np.ndarray]) -> None:
    import matplotlib.image as mpimg

    for band, img in strips.items():
        mpimg.imsave(out_dir / FILES[band], img if img.ndim == 3 else np.repeat(img[..., None], 3, axis=2))


LABELS = {"uv": "UV 250-380 nm (flat)", "vis_E": "visible, illuminant E", "vis_A": "visible, illuminant A",
          "nir": "NIR 780-1000 nm (illuminant A)"}


def _write_figure(path: Path, strips: dict[str, np.ndarray], names, size: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    width = strips["uv"].shape[1]
    fig, axes = plt.subplots(len(BANDS), 1, figsize=(width / 100 + 0.4, len(BANDS) * (size / 100 + 0.3)))
    for ax, band in zip(axes, BANDS, strict=True):
        img = strips[band]
        ax.imshow(img if img.ndim == 3 else img, cmap=None if img.ndim == 3 else "gray", vmin=0, vmax=255)
        ax.set_title(LABELS[band], fontsize=8, loc="left")
        ax.set_xticks([(i + 0.5) * size for i in range(len(names))], names, fontsize=7)
        ax.set_yticks([])
    fig.suptitle("Mitsuba 3, the shipped model's K-media mixture, side-lit spheres (r = 0.5 cm)", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
