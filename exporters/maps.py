"""Image I/O for baking (docs/contracts.md §4): float EXR maps out, albedo images in, and the ``S_maps.json`` record.

All file access goes through OpenImageIO.  Nothing existing is overwritten unless ``overwrite=True``
(files are written to a temporary name in the target folder, then hard-linked into place, which fails
atomically if the name was taken meanwhile).

Conventions:
* Maps are float32 EXR, scene-independent data (Blender must load them as Non-Color); the EXR header
  carries ``spectral_skin_sss:colorspace = "Non-Color"`` and ``spectral_skin_sss:units`` (OpenImageIO
  reports every EXR as ``lin_rec709`` on reading, whatever was written).
* Channel names: RGB maps ``R, G, B``; one-channel maps ``Y``; the biophysical map the names of docs/contracts.md §4
  (``f_mel, f_blood, t_epi, so2, b_mel, exposure``).
* Albedo input: returned as linear sRGB float64 (H, W, 3) plus alpha (H, W) or None.  Colour space
  ``auto`` follows docs/contracts.md §1: sRGB-encoded unless the file says linear / Non-Color, or it stores floats.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import OpenImageIO as oiio

from exporters import palette as _palette
from exporters.colorimetry import srgb_decode

ColorSpace = Literal["auto", "srgb", "linear"]

RGB_CHANNELS: tuple[str, ...] = ("R", "G", "B")
SINGLE_CHANNEL: tuple[str, ...] = ("Y",)
BIOPHYSICAL_CHANNELS: tuple[str, ...] = ("f_mel", "f_blood", "t_epi", "so2", "b_mel", "exposure")
#: Colour-space names (lower case, as OpenImageIO / OCIO configs spell them) that mean "not sRGB-encoded".
_LINEAR_NAMES = {"linear", "scene_linear", "lin_rec709", "lin_srgb", "linear rec.709", "linear rec.709 (srgb)",
                 "srgb-linear", "lin_rec709_scene", "raw", "non-color", "data", "acescg", "aces2065-1",
                 "linear_srgb", "srgb_linear", "rec709_linear"}
_FLOAT_TYPES = {"half", "float", "double"}
#: EXR compression of the maps.  PIZ (lossless wavelet + Huffman) measured on 4096^2 float maps: 1.2 CPU-s per
#: RGB map and 85 MB, against ZIP's 2.7 CPU-s and 88 MB (OpenEXR 3.3 via OpenImageIO 3.0); it also runs on
#: OpenEXR's threads (``set_threads``).  Blender reads every lossless EXR compression.
DEFAULT_COMPRESSION = "piz"
COMPRESSIONS = ("piz", "zip", "zips", "rle", "none")
_INT_MAX = {"uint8": 255.0, "uint16": 65535.0, "uint32": 4294967295.0}


class ImageError(ValueError):
    """An input image that cannot be used (unreadable, non-finite, negative ...); message says why."""


def _ensure_writable_dir(folder: Path) -> None:
    if not folder.is_dir():
        raise FileNotFoundError(f"output folder does not exist: {folder}")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise PermissionError(f"output folder is not writable: {folder}")


def _publish(tmp: Path, final: Path, overwrite: bool) -> None:
    """Move the finished temporary file to ``final``; never replaces an existing file unless asked."""
    try:
        if overwrite:
            os.replace(tmp, final)
        else:
            os.link(tmp, final)  # fails with FileExistsError if ``final`` exists
    except FileExistsError:
        raise FileExistsError(f"{final} exists; pass overwrite=True (--overwrite) to replace it") from None
    finally:
        if tmp.exists():
            tmp.unlink()


def _refuse_existing(path: Path, overwrite: bool) -> None:
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True (--overwrite) to replace it")


def round_mantissa(values: np.ndarray, bits: int) -> np.ndarray:
    """float32 ``values`` rounded to ``bits`` (1..23) mantissa bits, to nearest (ties away from zero): relative
    error at most 2^-(bits+1) (16 bits: 7.6e-6).  Finite input only; 23 returns the values unchanged.

    Used for fast-path maps, whose table error is ~100x larger: PIZ then compresses a 4096^2 map 25 % faster
    and 17 % smaller (measured on baked maps).
    """
    x = np.ascontiguousarray(values, dtype=np.float32)
    if not 1 <= bits <= 23:
        raise ValueError(f"mantissa bits must lie in 1..23, got {bits}")
    if bits == 23:
        return x
    if not np.all(np.isfinite(x)):
        raise ValueError("round_mantissa needs finite values")
    drop = 23 - bits
    u = x.view(np.uint32)
    sign = u & np.uint32(0x80000000)
    mag = (u & np.uint32(0x7FFFFFFF)).astype(np.uint64) + np.uint64(1 << (drop - 1))
    mag &= np.uint64((0xFFFFFFFF << drop) & 0x7FFFFFFF)
    mag = np.minimum(mag, np.uint64(0x7F7FFFFF) & np.uint64((0xFFFFFFFF << drop) & 0x7FFFFFFF))  # no overflow to inf
    return (mag.astype(np.uint32) | sign).view(np.float32)


def set_threads(threads: int) -> None:
    """Threads OpenImageIO and OpenEXR may use for reading and (de)compressing images (0 = all cores)."""
    n = int(threads) if threads and threads > 0 else (os.cpu_count() or 1)
    oiio.attribute("threads", n)
    oiio.attribute("exr_threads", n)


#: Pixel types of the maps: 32-bit float, or 16-bit half (10 mantissa bits: relative 4.9e-4; subnormal,
#: with an absolute step of 6e-8, below 6.1e-5; largest 65504): half suits values bounded to [-1, 1].
PIXEL_TYPES = ("float", "half")
HALF_MAX = 65504.0
#: Smallest normal half: above it half keeps 11 significant bits (relative rounding <= 2^-11 = 4.9e-4).
HALF_MIN_NORMAL = 2.0**-14


def fits_half(values: np.ndarray) -> bool:
    """Whether every value is 0 or has a magnitude in half's normal range [2^-14, 65504] (relative rounding
    <= 4.9e-4: no subnormal loss of precision, no overflow)."""
    a = np.abs(np.asarray(values))
    nonzero = a[a != 0]
    return bool(np.all(np.isfinite(a)) and (nonzero.size == 0 or (nonzero.min() >= HALF_MIN_NORMAL
                                                                    and nonzero.max() <= HALF_MAX)))


def _exr_spec(width: int, height: int, channels, units: str, compression: str = DEFAULT_COMPRESSION,
              pixel_type: str = "float") -> oiio.ImageSpec:
    if compression not in COMPRESSIONS:
        raise ValueError(f"EXR compression must be one of {COMPRESSIONS}, not {compression!r}")
    if pixel_type not in PIXEL_TYPES:
        raise ValueError(f"EXR pixel type must be one of {PIXEL_TYPES}, not {pixel_type!r}")
    spec = oiio.ImageSpec(width, height, len(channels), pixel_type)
    spec.channelnames = tuple(channels)
    spec.attribute("oiio:ColorSpace", "Non-Color")
    spec.attribute("spectral_skin_sss:colorspace", "Non-Color")
    spec.attribute("compression", compression)
    spec.attribute("spectral_skin_sss:units", units)
    return spec


def _temp_name(path: Path) -> Path:
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".exr", dir=path.parent)
    os.close(fd)
    return Path(tmp_name)


def write_exr(path: str | os.PathLike, data: np.ndarray, channels: tuple[str, ...] | list[str],
              units: str, overwrite: bool = False) -> Path:
    """Write ``data`` (H, W) or (H, W, C) as a float32 EXR with the given channel names; returns the path.

    ``units`` is stored in the header (e.g. "Blender units", "cm^-1", "1").  Non-finite data raises
    ValueError (nothing is written); an existing file raises FileExistsError unless ``overwrite``.
    """
    path = Path(path)
    arr = np.asarray(data, dtype=np.float64)
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.ndim != 3 or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"map data must be (H, W) or (H, W, C), got shape {np.shape(data)}")
    if arr.shape[2] != len(channels):
        raise ValueError(f"{arr.shape[2]} channels of data but {len(channels)} channel names {list(channels)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"map {path.name}: {int(np.size(arr) - np.isfinite(arr).sum())} NaN/Inf values")
    if np.any(np.abs(arr) > np.finfo(np.float32).max):
        raise ValueError(f"map {path.name}: values overflow float32")
    _ensure_writable_dir(path.parent)
    _refuse_existing(path, overwrite)
    h, w, c = arr.shape
    spec = _exr_spec(w, h, channels, units)
    tmp = _temp_name(path)
    try:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), spec):
            raise OSError(f"cannot write {path}: {oiio.geterror() or (out.geterror() if out else '')}")
        ok = out.write_image(np.ascontiguousarray(arr, dtype=np.float32))
        err = out.geterror()
        out.close()
        if not ok:
            raise OSError(f"cannot write {path}: {err}")
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _publish(tmp, path, overwrite)
    return path


@dataclass(frozen=True)
class AlbedoImage:
    """A decoded albedo image.

    ``rgb``: (H, W, 3) float64 linear sRGB (grayscale replicated); ``alpha``: (H, W) in [0, 1] or None,
    unassociated (colour is never divided or multiplied by it); ``colorspace``: "srgb" or "linear" as
    used; ``source_format``: OpenImageIO pixel type of the file ("uint8", "uint16", "half", "float", ...);
    ``n_clamped``: texels whose negative values were clamped to 0 (only with ``clamp_negative``);
    ``n_channels``: channels in the file (1 or 2: grayscale, replicated to RGB).
    """

    rgb: np.ndarray
    alpha: np.ndarray | None
    colorspace: Literal["srgb", "linear"]
    source_format: str
    n_clamped: int
    n_channels: int = 3


def _detect_colorspace(spec: oiio.ImageSpec) -> Literal["srgb", "linear"]:
    """docs/contracts.md §1: sRGB-encoded unless the file says linear / Non-Color, or stores float pixels."""
    name = str(spec.getattribute("oiio:ColorSpace") or "").strip().lower()
    if name in _LINEAR_NAMES or name.startswith("lin"):
        return "linear"
    if name in {"srgb", "srgb_texture", "srgb - texture", "srgb_rec709_scene", "srgb_tx"}:
        return "srgb"
    gamma = spec.getattribute("oiio:Gamma")
    if gamma is not None and abs(float(gamma) - 1.0) < 1e-3:
        return "linear"
    return "linear" if str(spec.format) in _FLOAT_TYPES else "srgb"


def _split_channels(pixels: np.ndarray, spec: oiio.ImageSpec, path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    names = [n.upper() for n in spec.channelnames]
    c = pixels.shape[2]
    alpha_idx = spec.alpha_channel if spec.alpha_channel >= 0 else (names.index("A") if "A" in names else -1)
    if c == 1:
        return np.repeat(pixels, 3, axis=2), None
    if c == 2:  # gray + alpha
        return np.repeat(pixels[..., :1], 3, axis=2), pixels[..., 1]
    if c >= 3:
        colour_idx = [i for i in range(c) if i != alpha_idx][:3]
        if len(colour_idx) < 3:
            raise ImageError(f"{path}: cannot find three colour channels in {spec.channelnames}")
        alpha = pixels[..., alpha_idx] if alpha_idx >= 0 else None
        return pixels[..., colour_idx], alpha
    raise ImageError(f"{path}: unsupported channel layout {spec.channelnames}")


def _read_pixels(path: Path, colorspace: str, integer_types: tuple[str, ...]) -> tuple[oiio.ImageSpec, str, object]:
    """Open an albedo image (alpha unassociated) and read all its channels: (spec, the pixel type read, the
    pixels).  Files whose type is in ``integer_types`` are read in that type (the callers scale them in
    float64: OIIO's float conversion is float32), others as float.  Errors as :func:`read_albedo`."""
    if colorspace not in ("auto", "srgb", "linear"):
        raise ValueError(f"colorspace must be auto, srgb or linear, not {colorspace!r}")
    if not path.is_file():
        raise FileNotFoundError(f"albedo image not found: {path}")
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise ImageError(f"cannot read image {path}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        fmt = str(spec.format)
        native = fmt if fmt in integer_types else "float"
        pixels = inp.read_image(0, 0, 0, spec.nchannels, native)
        err = inp.geterror()
    finally:
        inp.close()
    if pixels is None or err:
        raise ImageError(f"cannot read pixels of {path}: {err}")
    return spec, native, pixels


def read_albedo(path: str | os.PathLike, colorspace: ColorSpace = "auto",
                clamp_negative: bool = False) -> AlbedoImage:
    """Read an albedo image (8/16-bit PNG or TIFF, float EXR, ...) as linear sRGB float64.

    * Missing file: FileNotFoundError; unreadable / not an image: :class:`ImageError`.
    * ``colorspace``: "auto" (docs/contracts.md §1 rule, see :func:`_detect_colorspace`), "srgb" (decode with the
      IEC 61966-2-1 curve) or "linear" (use values as they are).
    * 1 channel: gray replicated to RGB; 2 channels: gray + alpha; 4 channels: RGB + alpha (unassociated:
      OpenImageIO is asked not to premultiply); more channels: the first three non-alpha ones.
    * NaN/Inf texels: ImageError with the count and the first texel.  Negative texels (float files only):
      ImageError, or clamped to 0 and counted when ``clamp_negative``.
    """
    path = Path(path)
    spec, native, pixels = _read_pixels(path, colorspace, tuple(_INT_MAX))
    pixels = np.asarray(pixels, dtype=np.float64).reshape(spec.height, spec.width, spec.nchannels)
    if native in _INT_MAX:
        pixels /= _INT_MAX[native]
    bad = ~np.isfinite(pixels)
    if bad.any():
        y, x, _ = np.argwhere(bad)[0]
        raise ImageError(f"{path}: {int(bad.any(axis=2).sum())} texel(s) with NaN/Inf, first at (x={x}, y={y})")
    rgb, alpha = _split_channels(pixels, spec, path)
    neg = rgb < 0.0
    n_clamped = int(neg.any(axis=2).sum())
    if n_clamped and not clamp_negative:
        y, x, _ = np.argwhere(neg)[0]
        raise ImageError(f"{path}: {n_clamped} texel(s) with negative values, first at (x={x}, y={y}); "
                         "albedo cannot be negative (use clamp_negative to clamp them to 0)")
    rgb = np.maximum(rgb, 0.0)
    used = _detect_colorspace(spec) if colorspace == "auto" else colorspace
    if used == "srgb":
        rgb = np.asarray(srgb_decode(rgb), dtype=np.float64)
    alpha = None if alpha is None else np.clip(alpha, 0.0, 1.0)
    return AlbedoImage(rgb=rgb, alpha=alpha, colorspace=used, source_format=str(spec.format),
                       n_clamped=n_clamped if clamp_negative else 0, n_channels=int(spec.nchannels))


@dataclass(frozen=True)
class IndexedAlbedo:
    """A decoded albedo image as its distinct colours and, per texel, which one (exporters.palette).

    ``palette`` (M, 3) float64 linear sRGB (grayscale replicated); ``index`` (H, W) int32 into it;
    ``counts`` (M,) texels per colour; ``has_alpha``: the file has an alpha channel (ignored); other fields as
    in :class:`AlbedoImage`.  ``rgb`` (property) expands to the dense (H, W, 3) image.
    """

    palette: np.ndarray
    index: np.ndarray
    colorspace: Literal["srgb", "linear"]
    source_format: str
    n_clamped: int
    n_channels: int = 3
    has_alpha: bool = False

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.index.shape)

    @property
    def counts(self) -> np.ndarray:
        return np.bincount(self.index.ravel(), minlength=len(self.palette))

    @property
    def rgb(self) -> np.ndarray:
        return self.palette[self.index]

    @classmethod
    def from_dense(cls, albedo: AlbedoImage) -> IndexedAlbedo:
        """Index a dense :class:`AlbedoImage` (colours compared as float32, as the model takes them)."""
        rgb = np.asarray(albedo.rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ValueError(f"albedo must be an (H, W, 3) image, got shape {rgb.shape}")
        pal, inv = _palette.unique_float_rows(rgb.reshape(-1, 3).astype(np.float32))
        return cls(palette=pal.astype(np.float64), index=inv.reshape(rgb.shape[:2]), colorspace=albedo.colorspace,
                   source_format=albedo.source_format, n_clamped=albedo.n_clamped, n_channels=albedo.n_channels,
                   has_alpha=albedo.alpha is not None)


def _colour_channels(spec: oiio.ImageSpec, path: Path) -> tuple[list[int], bool]:
    """Indices of the colour channels (1 for gray, 3 for colour) and whether an alpha channel exists."""
    names = [n.upper() for n in spec.channelnames]
    c = spec.nchannels
    alpha_idx = spec.alpha_channel if spec.alpha_channel >= 0 else (names.index("A") if "A" in names else -1)
    if c == 1:
        return [0], False
    if c == 2:
        return [0], True
    colour = [i for i in range(c) if i != alpha_idx][:3]
    if len(colour) < 3:
        raise ImageError(f"{path}: cannot find three colour channels in {spec.channelnames}")
    return colour, alpha_idx >= 0


def _first_texel(mask_palette: np.ndarray, index: np.ndarray) -> tuple[int, int, int]:
    """(count of texels, x, y of the first) whose palette entry is flagged."""
    flagged = mask_palette[index]
    y, x = np.argwhere(flagged)[0]
    return int(flagged.sum()), int(x), int(y)


def read_albedo_indexed(path: str | os.PathLike, colorspace: ColorSpace = "auto",
                        clamp_negative: bool = False) -> IndexedAlbedo:
    """:func:`read_albedo` for large textures: the same decoding and checks, but each distinct colour is
    decoded once and the image is kept as a palette and an index (no (H, W, 3) float64 array).

    8-bit files are indexed by their packed codes (exporters.palette, no sort), 16-bit ones by a sort of
    the codes, float files by a hash of the float32 values.  Errors as :func:`read_albedo`.
    """
    path = Path(path)
    spec, native, pixels = _read_pixels(path, colorspace, ("uint8", "uint16"))
    fmt = str(spec.format)
    colour, has_alpha = _colour_channels(spec, path)
    pixels = np.asarray(pixels).reshape(spec.height, spec.width, spec.nchannels)
    rows = pixels[..., colour].reshape(-1, len(colour))
    del pixels
    if native in ("uint8", "uint16"):
        codes, inverse = _palette.unique_codes(np.ascontiguousarray(rows))
        pal = codes.astype(np.float64) / _INT_MAX[native]
    else:
        found, inverse = _palette.unique_float_rows(rows)
        pal = found.astype(np.float64)
    del rows
    index = inverse.reshape(spec.height, spec.width)
    bad = ~np.all(np.isfinite(pal), axis=1)
    if bad.any():
        n, x, y = _first_texel(bad, index)
        raise ImageError(f"{path}: {n} texel(s) with NaN/Inf, first at (x={x}, y={y})")
    neg = np.any(pal < 0.0, axis=1)
    n_clamped = 0
    if neg.any():
        n_clamped, x, y = _first_texel(neg, index)
        if not clamp_negative:
            raise ImageError(f"{path}: {n_clamped} texel(s) with negative values, first at (x={x}, y={y}); "
                             "albedo cannot be negative (use clamp_negative to clamp them to 0)")
        pal = np.maximum(pal, 0.0)
    if pal.shape[1] == 1:
        pal = np.repeat(pal, 3, axis=1)
    used = _detect_colorspace(spec) if colorspace == "auto" else colorspace
    if used == "srgb":
        pal = np.asarray(srgb_decode(pal), dtype=np.float64)
    return IndexedAlbedo(palette=pal, index=index, colorspace=used, source_format=fmt, n_clamped=n_clamped,
                         n_channels=int(spec.nchannels), has_alpha=has_alpha)


def sha256_file(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file, read in 1 MiB blocks (model files in S_maps.json; LUTs in training records)."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def write_maps_json(path: str | os.PathLike, files: dict[str, dict], k: int, model_sha256: dict[str, str],
                    input_image: str, input_colorspace: str, timings_s: dict[str, float],
                    unit_scale_m: float | None = None, overwrite: bool = False, extra: dict | None = None) -> Path:
    """Write ``S_maps.json`` (docs/contracts.md §4): every file written with its units/channels, K, model SHA-256s,
    the input image and colour space used, and timings in seconds.

    ``files`` maps file name -> {"units": str, "channels": [...], ...}; every listed file must exist next to
    the JSON.  Non-finite timings raise ValueError.  ``extra``: further JSON-serialisable keys (options,
    notes, statistics), added after the standard ones.
    """
    path = Path(path)
    if k < 1:
        raise ValueError("K must be >= 1")
    for name in files:
        if not (path.parent / name).is_file():
            raise FileNotFoundError(f"S_maps.json lists {name}, which is not in {path.parent}")
    if not all(np.isfinite(v) for v in timings_s.values()):
        raise ValueError("timings must be finite")
    _ensure_writable_dir(path.parent)
    _refuse_existing(path, overwrite)
    record = {
        "format": "spectral_skin_sss maps v1",
        "created_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "K": int(k),
        "input": {"image": input_image, "colorspace": input_colorspace},
        "unit_scale_m_per_blender_unit": unit_scale_m,
        "model_sha256": dict(model_sha256),
        "files": files,
        "timings_s": {key: float(v) for key, v in timings_s.items()},
        **(extra or {}),
    }
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".json", dir=path.parent)
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        json.dump(record, fh, indent=2, sort_keys=False)
        fh.write("\n")
    _publish(Path(tmp_name), path, overwrite)
    return path


def read_exr(path: str | os.PathLike, channels: tuple[str, ...] | list[str] | None = None
             ) -> tuple[np.ndarray, tuple[str, ...], dict[str, str]]:
    """Read a map back: (H, W, C) float32 array, channel names, and the string header attributes.

    EXR stores channels sorted by name (other than R, G, B, A), so a map written as
    ``BIOPHYSICAL_CHANNELS`` comes back alphabetically; pass ``channels`` to get them in that order
    (KeyError naming the missing channel otherwise).
    """
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ImageError(f"cannot read {path}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        data = inp.read_image(0, 0, 0, spec.nchannels, "float")
    finally:
        inp.close()
    attrs = {p.name: str(p.value) for p in spec.extra_attribs}
    arr = np.asarray(data, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    names = tuple(spec.channelnames)
    if channels is not None:
        missing = [c for c in channels if c not in names]
        if missing:
            raise KeyError(f"{path}: no channel(s) {missing}; it has {list(names)}")
        arr = arr[..., [names.index(c) for c in channels]]
        names = tuple(channels)
    return arr, names, attrs


class MapStream:
    """A float32 (or half: ``pixel_type``) EXR map written band by band (memory bounded) to a temporary file
    beside ``path``.

    Nothing appears under ``path`` until :func:`publish_maps`; :meth:`discard` removes the temporary file.
    Checks at creation: the folder exists and is writable, and ``path`` does not exist (unless
    ``overwrite``), so that a bake fails before any work if it could not finish.
    """

    def __init__(self, path: str | os.PathLike, width: int, height: int, channels: tuple[str, ...] | list[str],
                 units: str, overwrite: bool = False, compression: str = DEFAULT_COMPRESSION,
                 pixel_type: str = "float") -> None:
        self.path = Path(path)
        self.pixel_type = pixel_type
        self.channels = tuple(channels)
        self.units = units
        self.width, self.height = int(width), int(height)
        if self.width < 1 or self.height < 1:
            raise ValueError(f"map size must be at least 1 x 1, got {width} x {height}")
        _ensure_writable_dir(self.path.parent)
        _refuse_existing(self.path, overwrite)
        self.overwrite = overwrite
        self.tmp = _temp_name(self.path)
        self._rows = 0
        self._out = oiio.ImageOutput.create(str(self.tmp))
        if self._out is None or not self._out.open(str(self.tmp), _exr_spec(self.width, self.height, self.channels,
                                                                             units, compression, pixel_type)):
            err = oiio.geterror() or (self._out.geterror() if self._out else "")
            self.discard()
            raise OSError(f"cannot write {self.path}: {err}")

    def write_rows(self, data: np.ndarray, finite: bool = False) -> None:
        """Append the next rows, ``data`` (h, W) or (h, W, C), top to bottom; finite values only (checked here
        unless the caller passes ``finite=True`` because it checked the values they were gathered from).  A
        half map takes float16 data as it is (no conversion: the caller rounded once per distinct value)."""
        arr = np.asarray(data)
        if not (self.pixel_type == "half" and arr.dtype == np.float16):
            arr = arr.astype(np.float32, copy=False)
        if arr.ndim == 2:
            arr = arr[..., None]
        h = arr.shape[0]
        if arr.shape[1:] != (self.width, len(self.channels)) or self._rows + h > self.height:
            raise ValueError(f"{self.path.name}: rows of shape {arr.shape} do not fit a "
                             f"{self.width} x {self.height} x {len(self.channels)} map at row {self._rows}")
        if not finite and not np.all(np.isfinite(arr)):
            raise ValueError(f"map {self.path.name}: NaN/Inf values")
        if self.pixel_type == "half" and arr.dtype != np.float16 and np.any(np.abs(arr) > HALF_MAX):
            raise ValueError(f"map {self.path.name}: values beyond the half-float range (|v| > {HALF_MAX:g}): "
                             "write it as float")
        if not self._out.write_scanlines(self._rows, self._rows + h, 0, np.ascontiguousarray(arr)):
            raise OSError(f"cannot write {self.path}: {self._out.geterror()}")
        self._rows += h

    def close(self) -> None:
        """Finish the temporary file (all rows must have been written)."""
        if self._rows != self.height:
            raise ValueError(f"{self.path.name}: {self._rows} of {self.height} rows written")
        if self._out is not None:
            self._out.close()
            self._out = None

    def discard(self) -> None:
        if self._out is not None:
            self._out.close()
            self._out = None
        self.tmp.unlink(missing_ok=True)


def publish_maps(streams: list[MapStream]) -> list[Path]:
    """Close every stream and move all of them into place, or none: if one cannot be published (e.g. the
    name was taken meanwhile), the ones already published are removed again and every temporary file is
    deleted before the error propagates."""
    published: list[Path] = []
    try:
        for s in streams:
            s.close()
        for s in streams:
            _publish(s.tmp, s.path, s.overwrite)
            published.append(s.path)
    except BaseException:
        for p in published:
            if not any(s.overwrite and s.path == p for s in streams):
                p.unlink(missing_ok=True)
        for s in streams:
            s.discard()
        raise
    return published
