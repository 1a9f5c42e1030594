"""Image input for baking (docs/contracts.md §1): albedo images in, their colour space, their alpha and the
texel checks.

Every way an albedo reaches a bake goes through here: a file (:func:`read_albedo`, :func:`read_albedo_indexed`,
read with OpenImageIO) and, in the Blender add-on, an image's pixel buffer (blender_addon.baker reads the
buffer with bpy and hands it to :func:`albedo_texels`, as :func:`read_albedo` does with a file's pixels; the
colour-space name Blender shows goes to :func:`colorspace_of_name`).  So one image gets the same verdict however
it arrives.

Conventions:
* Albedo: returned as linear sRGB float64 (H, W, 3) plus alpha (H, W) or None (or as a palette and an index,
  :class:`IndexedAlbedo`).  Colour space ``auto`` follows docs/contracts.md §1: sRGB-encoded unless the file
  says linear / Non-Color, or it stores floats.  Only the transfer curve is undone: primaries are never
  converted (an image tagged ACEScg or Linear Rec.2020 is read as if its primaries were Rec.709's).
* Texel checks (:func:`check_texels`): NaN/Inf in any channel read (colour or alpha) is an error, negative
  colour an error unless clamped; the message counts the texels and names the first (x, y from the top left).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Literal

import numpy as np

from . import palette as _palette
from .colorimetry import srgb_decode

if TYPE_CHECKING:
    import OpenImageIO

ColorSpace = Literal["auto", "srgb", "linear"]
COLORSPACES: tuple[str, ...] = ("auto", "srgb", "linear")

# Colour-space names, lower case.  Neither Blender (bpy exposes no linearity flag) nor OpenImageIO 3.0's
# ColorConfig (no linearity query; it does not know Blender's names) says whether a name is linear, so the
# names are listed here: Blender 5.0's OCIO config (every name of ColorManagedInputColorspaceSettings.name),
# Blender <= 3.6's (Linear, Raw, XYZ, Linear ACES, Filmic Log ...), OpenImageIO 3.0's built-in OCIO CG config
# with its aliases (ColorConfig().getColorSpaceNames(), getAliases()) and the older OIIO names (linear,
# lin_srgb, srgb_rec709_scene ...).  tests/test_image_input.py checks every name the installed Blender and
# OpenImageIO list against a hand-made table.
#: Linear (values used as they are): data, scene-linear and linear encodings of any primaries.  Any other name
#: starting with one of ``LINEAR_PREFIXES`` (Linear Rec.709, lin_ap1, Utility - Linear - sRGB ...) is linear too.
LINEAR_COLORSPACES = frozenset({
    "non-color", "raw", "none", "data", "utility - raw", "scene_linear", "xyz", "cie-xyz-d65",
    "acescg", "aces - acescg", "aces2065-1", "aces2065_1", "aces", "aces - aces2065-1",
    "srgb-linear", "srgb_linear", "rec709_linear",
})
LINEAR_PREFIXES = ("lin", "utility - linear")
#: sRGB-encoded (the IEC 61966-2-1 curve, whatever the primaries): any name starting with "srgb" that is not
#: linear (sRGB, sRGB - Texture, srgb_rec709_scene, sRGB Encoded P3-D65 ...), and these: OCIO's texture aliases,
#: Display P3 (sRGB curve, P3 primaries) and the display-referred view transforms that end in the sRGB curve
#: (Filmic / AgX Base / Khronos PBR Neutral / ACES sRGB: their tone curve is not inverted, the sRGB curve is).
SRGB_COLORSPACES = frozenset({
    "utility - srgb - texture", "input - generic - srgb - texture", "display p3", "display p3 - display",
    "displayp3_display", "filmic srgb", "agx base srgb", "khronos pbr neutral srgb", "aces 1.3 srgb",
    "aces 2.0 srgb",
})
#: Log encodings (Blender's Filmic Log and AgX Log, ACEScc/ACEScct): neither sRGB nor linear, and far from
#: both; an albedo tagged with one is refused rather than misread.
LOG_COLORSPACES = frozenset({
    "filmic log", "agx log", "acescc", "acescct", "aces - acescc", "aces - acescct", "acescc_ap1", "acescct_ap1",
})
_FLOAT_TYPES = {"half", "float", "double"}
#: Bytes per texel that decoding and indexing take beyond the file's own channels: the packed colour key
#: and the index into the distinct colours (:func:`read_albedo_indexed`).
INDEX_BYTES_PER_TEXEL = 16
#: Bytes of the 24-bit colour bitmap that indexes 8-bit files (a flag and an int32 position per code); its
#: pages are zero until touched, so a texture touches at most two pages (flag, position) per texel.
BITMAP_BYTES = 5 << 24
PAGE_BYTES = 4096
_INT_MAX = {"uint8": 255.0, "uint16": 65535.0, "uint32": 4294967295.0}


class ImageError(ValueError):
    """An input image that cannot be used (unreadable, non-finite, negative ...); message says why."""


def openimageio() -> ModuleType:
    """The OpenImageIO module, imported on first use: Blender 4.2 bundles OpenImageIO's libraries but not its Python
    module, so nothing that only imports ``exporters`` may need it.  ImageError (one line, what to do) when it
    is missing."""
    try:
        import OpenImageIO
    except ImportError as exc:
        raise ImageError("reading and writing image files needs the OpenImageIO Python module, which this Python "
                         "does not have (Blender 4.2 does not bundle it): use Blender 4.5 or later, or "
                         "`pip install OpenImageIO` into this Python") from exc
    return OpenImageIO


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


# -- colour space ---------------------------------------------------------------------------------------------
#: The tile token of a UDIM (tiled) image's file name, as Blender writes it: ``skin.<UDIM>.png``.
UDIM_TOKEN = "<UDIM>"
#: UDIM tile numbers: 1001 + u + 10 v for tile column u (0-9) and row v (0-99).
UDIM_FIRST, UDIM_LAST = 1001, 1999


def udim_tiles(pattern: str | os.PathLike) -> list[tuple[int, Path]]:
    """The tiles of a UDIM image on disk: ``pattern`` holds :data:`UDIM_TOKEN` once (``skin.<UDIM>.png``); returns
    (tile number, file) for every existing file whose name has a tile number in its place, by tile.
    FileNotFoundError (one line) when none exists."""
    pattern = Path(pattern)
    head, token, tail = pattern.name.partition(UDIM_TOKEN)
    if not token or UDIM_TOKEN in tail or UDIM_TOKEN in str(pattern.parent):
        raise ValueError(f"{pattern}: a UDIM file name holds {UDIM_TOKEN} once, in the file name")
    tiles = []
    for path in pattern.parent.glob(f"{head}[0-9][0-9][0-9][0-9]{tail}"):
        number = int(path.name[len(head): len(head) + 4])
        if UDIM_FIRST <= number <= UDIM_LAST and path.is_file():
            tiles.append((number, path))
    if not tiles:
        raise FileNotFoundError(f"no UDIM tile of {pattern} found (files named {head}1001{tail}, {head}1002{tail} ...)")
    return sorted(tiles)


def udim_tile_stem(pattern: str | os.PathLike, tile: int) -> str:
    """The file stem of one tile of a UDIM pattern: ``skin.<UDIM>.png``, 1002 -> ``skin.1002``.  Baked per tile,
    its maps are ``skin.1002_k1_color.exr`` ... (docs/contracts.md §4), which Blender reads back as the UDIM image
    ``skin.<UDIM>_k1_color.exr``."""
    return Path(Path(pattern).name.replace(UDIM_TOKEN, f"{tile:04d}")).stem


def check_colorspace(colorspace: str) -> None:
    """ValueError unless ``colorspace`` is one a reader takes (``COLORSPACES``)."""
    if colorspace not in COLORSPACES:
        raise ValueError(f"colorspace must be auto, srgb or linear, not {colorspace!r}")


def colorspace_of_name(name: str, where: str = "image") -> Literal["srgb", "linear"] | None:
    """How values tagged with the colour-space ``name`` (Blender's, OCIO's or OpenImageIO's) are encoded:
    "linear", "srgb", or None when the name says neither (gamma 1.8/2.2/2.4 encodings, HDR displays, empty or
    unknown names: the caller falls back to its own rule).  A log
    encoding raises :class:`ImageError` (``where`` names the image in the message)."""
    key = str(name or "").strip().lower()
    if key in LINEAR_COLORSPACES or key.startswith(LINEAR_PREFIXES):
        return "linear"
    if key in SRGB_COLORSPACES or key.startswith("srgb"):
        return "srgb"
    if key in LOG_COLORSPACES:
        raise ImageError(f"{where}: colour space '{name}' is a log encoding, not an albedo's; set the image's colour "
                         "space to sRGB (painted textures) or a linear one, or choose the colour space to read it as")
    return None


def _detect_colorspace(spec: OpenImageIO.ImageSpec, where: str) -> Literal["srgb", "linear"]:
    """docs/contracts.md §1: sRGB-encoded unless the file says linear / Non-Color, or stores float pixels."""
    named = colorspace_of_name(spec.getattribute("oiio:ColorSpace") or "", where)
    if named is not None:
        return named
    gamma = spec.getattribute("oiio:Gamma")
    if gamma is not None and abs(float(gamma) - 1.0) < 1e-3:
        return "linear"
    return "linear" if str(spec.format) in _FLOAT_TYPES else "srgb"


# -- channels and checks ----------------------------------------------------------------------------------------
def channel_layout(channel_names: tuple[str, ...] | list[str], alpha_channel: int = -1,
                   where: str = "image") -> tuple[list[int], int]:
    """Which channels hold the colour and which the alpha: (colour indices, alpha index or -1).

    1 channel: gray; 2: gray + alpha; more: the first three channels other than the alpha, which is
    ``alpha_channel`` (the file's own mark, -1 for none) or else the channel named "A".  The colour is gray
    when one index is returned (replicated to RGB by the readers).  :class:`ImageError` without three colour
    channels."""
    names = [str(n).upper() for n in channel_names]
    c = len(names)
    if c == 1:
        return [0], -1
    if c == 2:
        return [0], 1
    alpha = alpha_channel if alpha_channel >= 0 else (names.index("A") if "A" in names else -1)
    colour = [i for i in range(c) if i != alpha][:3]
    if len(colour) < 3:
        raise ImageError(f"{where}: cannot find three colour channels in {list(channel_names)}")
    return colour, alpha


def _first(flagged: np.ndarray) -> tuple[int, int, int]:
    """(count of flagged texels, x, y of the first in row order) of an (H, W) bool array with one set."""
    y, x = np.argwhere(flagged)[0]
    return int(flagged.sum()), int(x), int(y)


def check_texels(colour: np.ndarray, where: str, clamp_negative: bool = False, index: np.ndarray | None = None,
                 alpha: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """The albedo checks: returns (``colour`` with negative values clamped to 0, texels clamped).

    ``colour``: (H, W, C) texels, or with ``index`` (H, W) a palette (M, C) of the colours the texels take;
    ``alpha`` (H, W) or None: checked for NaN/Inf too (a non-finite value anywhere means a broken file).
    :class:`ImageError` (``where`` names the image) for NaN/Inf texels, and for negative colour unless
    ``clamp_negative`` (then clamped and counted); both messages count the texels and name the first."""
    values = np.asarray(colour)
    per_entry = ~np.all(np.isfinite(values), axis=-1)
    bad = per_entry if index is None else per_entry[index]
    if alpha is not None:
        bad = bad | ~np.isfinite(alpha)
    if bad.any():
        n, x, y = _first(bad)
        raise ImageError(f"{where}: {n} texel(s) with NaN/Inf, first at (x={x}, y={y})")
    per_entry = np.any(values < 0.0, axis=-1)
    if not per_entry.any():
        return values, 0
    n, x, y = _first(per_entry if index is None else per_entry[index])
    if not clamp_negative:
        raise ImageError(f"{where}: {n} texel(s) with negative values, first at (x={x}, y={y}); "
                         "albedo cannot be negative (use clamp_negative to clamp them to 0)")
    return np.maximum(values, 0.0), n


def albedo_texels(pixels: np.ndarray, channel_names: tuple[str, ...] | list[str], where: str,
                  alpha_channel: int = -1, clamp_negative: bool = False
                  ) -> tuple[np.ndarray, np.ndarray | None, int]:
    """The colour and alpha of decoded pixels (H, W, C) float64 with the channels ``channel_names``, checked:
    (colour (H, W, 3), gray replicated; alpha (H, W) as stored or None; texels clamped).  The layout is
    :func:`channel_layout`'s, the checks :func:`check_texels`'s; the colour is still in its own colour space."""
    colour, a = channel_layout(channel_names, alpha_channel, where)
    alpha = pixels[..., a] if a >= 0 else None
    rgb, n_clamped = check_texels(pixels[..., colour], where, clamp_negative, alpha=alpha)
    if rgb.shape[2] == 1:
        rgb = np.repeat(rgb, 3, axis=2)
    return rgb, alpha, n_clamped


def to_linear(rgb: np.ndarray, used: str) -> np.ndarray:
    """Linear float64 values of colour values in colour space ``used`` ("srgb": the IEC 61966-2-1 curve undone,
    "linear": as they are)."""
    return np.asarray(srgb_decode(rgb) if used == "srgb" else rgb, dtype=np.float64)


# -- files ------------------------------------------------------------------------------------------------------
def decode_bytes(spec: OpenImageIO.ImageSpec) -> int:
    """Bytes that decoding and indexing the image of ``spec`` take (its header's size, channels and type): the
    pixels, the key and index per texel, and for 8-bit files the 24-bit colour bitmap of exporters.palette."""
    texels = int(spec.width) * int(spec.height) * max(int(spec.depth), 1)
    bitmap = min(BITMAP_BYTES, texels * 2 * PAGE_BYTES) if int(spec.format.size()) == 1 else 0
    return texels * (int(spec.nchannels) * int(spec.format.size()) + INDEX_BYTES_PER_TEXEL) + bitmap


def check_decode_budget(spec: OpenImageIO.ImageSpec, where: str, memory_mb: float | None) -> None:
    """:class:`ImageError` when decoding the image of ``spec`` would take more than ``memory_mb`` MiB (None: no
    limit); read from the header only, before any pixel is decoded."""
    if memory_mb is None:
        return
    need = decode_bytes(spec) / 2**20
    if need > memory_mb:
        raise ImageError(f"{where}: {spec.width} x {spec.height} texels need about {need:,.0f} MiB to decode, more "
                         f"than the memory budget of {memory_mb:g} MiB; use a smaller image or raise the budget "
                         f"(--memory-mb {int(need) + 1})")


def _read_pixels(path: Path, colorspace: str, integer_types: tuple[str, ...],
                 memory_mb: float | None = None) -> tuple[OpenImageIO.ImageSpec, str, object]:
    """Open an albedo image (alpha unassociated) and read all its channels: (spec, the pixel type read, the
    pixels).  Files whose type is in ``integer_types`` are read in that type (the callers scale them in
    float64: OIIO's float conversion is float32), others as float.  The header is checked against
    ``memory_mb`` (:func:`check_decode_budget`) before decoding.  Errors as :func:`read_albedo`."""
    check_colorspace(colorspace)
    if not path.is_file():
        raise FileNotFoundError(f"albedo image not found: {path}")
    inp = _open_image(path)
    try:
        spec = inp.spec()
        check_decode_budget(spec, str(path), memory_mb)
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
                clamp_negative: bool = False, memory_mb: float | None = None) -> AlbedoImage:
    """Read an albedo image (8/16-bit PNG or TIFF, float EXR, ...) as linear sRGB float64.

    * Missing file: FileNotFoundError; unreadable / not an image: :class:`ImageError`.
    * ``colorspace``: "auto" (docs/contracts.md §1 rule, see :func:`_detect_colorspace`), "srgb" (decode with the
      IEC 61966-2-1 curve) or "linear" (use values as they are).
    * 1 channel: gray replicated to RGB; 2 channels: gray + alpha; 4 channels: RGB + alpha (unassociated:
      OpenImageIO is asked not to premultiply); more channels: the first three non-alpha ones.
    * ``memory_mb``: refuse (:class:`ImageError`) an image whose header claims more texels than that many MiB
      can decode (:func:`check_decode_budget`); None: no limit.
    * Texels checked by :func:`check_texels` (NaN/Inf: ImageError; negative colour: ImageError, or clamped to
      0 and counted when ``clamp_negative``).
    """
    path = Path(path)
    spec, native, pixels = _read_pixels(path, colorspace, tuple(_INT_MAX), memory_mb)
    pixels = np.asarray(pixels, dtype=np.float64).reshape(spec.height, spec.width, spec.nchannels)
    if native in _INT_MAX:
        pixels /= _INT_MAX[native]
    rgb, alpha, n_clamped = albedo_texels(pixels, spec.channelnames, str(path), spec.alpha_channel, clamp_negative)
    used = _detect_colorspace(spec, str(path)) if colorspace == "auto" else colorspace
    return AlbedoImage(rgb=to_linear(rgb, used), alpha=None if alpha is None else np.clip(alpha, 0.0, 1.0),
                       colorspace=used, source_format=str(spec.format), n_clamped=n_clamped,
                       n_channels=int(spec.nchannels))


def read_albedo_indexed(path: str | os.PathLike, colorspace: ColorSpace = "auto",
                        clamp_negative: bool = False, memory_mb: float | None = None) -> IndexedAlbedo:
    """:func:`read_albedo` for large textures: the same decoding and checks, but each distinct colour is
    decoded once and the image is kept as a palette and an index (no (H, W, 3) float64 array).

    8-bit files are indexed by their packed codes (exporters.palette, no sort), 16-bit ones by a sort of
    the codes, float files by a hash of the float32 values.  Errors as :func:`read_albedo`.
    """
    path = Path(path)
    spec, native, pixels = _read_pixels(path, colorspace, ("uint8", "uint16"), memory_mb)
    fmt = str(spec.format)
    colour, a = channel_layout(spec.channelnames, spec.alpha_channel, str(path))
    pixels = np.asarray(pixels).reshape(spec.height, spec.width, spec.nchannels)
    alpha = pixels[..., a] if a >= 0 and native == "float" else None  # integer alpha is always finite
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
    pal, n_clamped = check_texels(pal, str(path), clamp_negative, index=index, alpha=alpha)
    if pal.shape[1] == 1:
        pal = np.repeat(pal, 3, axis=1)
    used = _detect_colorspace(spec, str(path)) if colorspace == "auto" else colorspace
    return IndexedAlbedo(palette=to_linear(pal, used), index=index, colorspace=used, source_format=fmt,
                         n_clamped=n_clamped, n_channels=int(spec.nchannels), has_alpha=a >= 0)


def _open_image(path: str | os.PathLike):
    """An OpenImageIO ImageInput of ``path`` with alpha unassociated (close it); ImageError when unreadable."""
    oiio = openimageio()
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise ImageError(f"cannot read image {path}: {oiio.geterror()}")
    return inp


#: Texels a sampled read decodes per call (:func:`sample_texels`): a few calls per image (a thread that reads waits
#: for Python's lock between calls), a few MB per block.
SAMPLE_BLOCK_TEXELS = 1 << 20


def sample_texels(path: str | os.PathLike, limit: int) -> tuple[np.ndarray, bool]:
    """About ``limit`` texels of an image file, on an even grid of rows and columns, without holding the whole
    image: (values (N, 3) float64 as stored, integers scaled to [0, 1] and not decoded; whether the file stores
    floats).  Grey images are repeated to RGB.  For a quick statistic (the live group's outside-domain report), not
    a bake: no checks beyond readability (ImageError).  The file is read in blocks of rows
    (:data:`SAMPLE_BLOCK_TEXELS`), 8- and 16-bit files as stored (converted once sampled): PNG and JPEG decode
    sequentially, so skipping rows would not save their decoding."""
    inp = _open_image(path)
    try:
        spec = inp.spec()
        stride = max(1, int(np.ceil(np.sqrt(spec.width * spec.height / max(limit, 1)))))
        fmt = str(spec.format)
        read_as = fmt if fmt in ("uint8", "uint16") else "float"
        block = stride * max(1, SAMPLE_BLOCK_TEXELS // max(spec.width * stride, 1))
        end = spec.y + spec.height
        parts = []
        for y in range(spec.y, end, block):
            px = inp.read_scanlines(0, 0, y, min(y + block, end), 0, 0, spec.nchannels, read_as)
            if px is None:
                raise ImageError(f"cannot read pixels of {path}")
            parts.append(np.asarray(px).reshape(-1, spec.width, spec.nchannels)[::stride, ::stride])
        is_float = fmt in ("half", "float", "double")
    finally:
        inp.close()
    px = np.concatenate(parts).reshape(-1, spec.nchannels).astype(np.float64)
    if read_as in _INT_MAX:
        px /= _INT_MAX[read_as]
    rgb = px[:, :3] if px.shape[1] >= 3 else np.repeat(px[:, :1], 3, axis=1)
    return np.nan_to_num(rgb, nan=0.0, posinf=1.0, neginf=0.0), is_float
