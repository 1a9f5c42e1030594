"""Image output of a bake (docs/contracts.md §4): float EXR maps written through OpenImageIO, read back, and the
``S_maps.json`` record.  (Albedo images come in through exporters.image_input.)

All file access goes through OpenImageIO.  Nothing existing is overwritten unless ``overwrite=True``
(files are written to a temporary name in the target folder, then hard-linked into place, which fails
atomically if the name was taken meanwhile).  One writer, :class:`MapStream` (band by band); :func:`write_exr`
writes a whole map through it.

Conventions:
* Maps are float32 (or half) EXR, scene-independent data (Blender must load them as Non-Color); the EXR header
  carries ``spectral_skin_sss:colorspace = "Non-Color"`` and ``spectral_skin_sss:units`` (OpenImageIO
  reports every EXR as ``lin_rec709`` on reading, whatever was written).
* Channel names: RGB maps ``R, G, B``; one-channel maps ``Y``; the biophysical map the names of docs/contracts.md §4
  (``f_mel, f_blood, t_epi, so2, b_mel, exposure``).
* Output folders: :func:`check_output_folder` and :func:`make_output_folder` raise the standard ``OSError``
  types (FileNotFoundError: missing, NotADirectoryError: not a folder, PermissionError: not writable), the
  same for every writer, the bake, bake.py and the add-on.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from . import exr
from .image_input import ImageError, openimageio

if TYPE_CHECKING:
    import OpenImageIO

RGB_CHANNELS: tuple[str, ...] = ("R", "G", "B")
SINGLE_CHANNEL: tuple[str, ...] = ("Y",)
BIOPHYSICAL_CHANNELS: tuple[str, ...] = ("f_mel", "f_blood", "t_epi", "so2", "b_mel", "exposure")
#: EXR compression of the maps.  PIZ (lossless wavelet + Huffman) measured on 4096^2 float maps: 1.2 CPU-s per
#: RGB map and 85 MB, against ZIP's 2.7 CPU-s and 88 MB (OpenEXR 3.3 via OpenImageIO 3.0); it also runs on
#: OpenEXR's threads (``set_threads``).  Blender reads every lossless EXR compression.
DEFAULT_COMPRESSION = "piz"
COMPRESSIONS = ("piz", "zip", "zips", "rle", "none")


def check_output_folder(folder: str | os.PathLike, what: str = "output folder") -> Path:
    """``folder`` as a Path if it is an existing, writable folder; else FileNotFoundError (missing),
    NotADirectoryError (a file) or PermissionError (not writable), each naming ``what`` and the folder."""
    folder = Path(folder)
    if not folder.exists():
        raise FileNotFoundError(f"{what} does not exist: {folder}")
    if not folder.is_dir():
        raise NotADirectoryError(f"{what} is a file, not a folder: {folder}")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise PermissionError(f"{what} is not writable: {folder}")
    return folder


def make_output_folder(folder: str | os.PathLike) -> bool:
    """Create ``folder`` (not its parents) if it is missing; True if it was created here (callers remove it
    again, if still empty, when they fail).  An existing folder is left to the writers to check (a read-only one
    may hold an up-to-date bake); a file of that name is NotADirectoryError, a missing or read-only parent the
    errors of :func:`check_output_folder`."""
    folder = Path(folder)
    if folder.exists():
        if not folder.is_dir():
            raise NotADirectoryError(f"output folder is a file, not a folder: {folder}")
        return False
    check_output_folder(folder.parent, f"the parent of the output folder {folder.name}")
    folder.mkdir()
    return True


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


def publish_file(tmp: str | os.PathLike, final: str | os.PathLike, overwrite: bool = False) -> None:
    """Move a finished temporary file (in the folder of ``final``) into place, as the maps are published: an existing
    ``final`` is FileExistsError unless ``overwrite``; the temporary file is gone afterwards either way."""
    _publish(Path(tmp), Path(final), overwrite)


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


def threads_of(threads: int) -> int:
    """Threads to use for a ``threads`` setting (0 or less: every core)."""
    return int(threads) if threads and threads > 0 else (os.cpu_count() or 1)


def set_threads(threads: int) -> None:
    """Threads OpenImageIO and OpenEXR may use for reading and (de)compressing images (0 = all cores); nothing
    where OpenImageIO's module is missing (exporters.exr writes without threads)."""
    n = threads_of(threads)
    try:
        oiio = openimageio()
    except ImageError:
        return
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
              pixel_type: str = "float") -> OpenImageIO.ImageSpec:
    if compression not in COMPRESSIONS:
        raise ValueError(f"EXR compression must be one of {COMPRESSIONS}, not {compression!r}")
    if pixel_type not in PIXEL_TYPES:
        raise ValueError(f"EXR pixel type must be one of {PIXEL_TYPES}, not {pixel_type!r}")
    spec = openimageio().ImageSpec(width, height, len(channels), pixel_type)
    spec.channelnames = tuple(channels)
    spec.attribute("oiio:ColorSpace", "Non-Color")
    spec.attribute("spectral_skin_sss:colorspace", "Non-Color")
    spec.attribute("compression", compression)
    spec.attribute("spectral_skin_sss:units", units)
    return spec


def _uncompressed(path: Path, width: int, height: int, channels: tuple[str, ...], units: str, compression: str,
                  pixel_type: str) -> exr.ExrScanlineWriter:
    """The writer of a map where OpenImageIO's module is missing: exporters.exr, uncompressed, same header strings."""
    if compression not in COMPRESSIONS:
        raise ValueError(f"EXR compression must be one of {COMPRESSIONS}, not {compression!r}")
    return exr.ExrScanlineWriter(path, width, height, channels, pixel_type, {
        "oiio:ColorSpace": "Non-Color", "spectral_skin_sss:colorspace": "Non-Color", "spectral_skin_sss:units": units})


def _temp_name(path: Path) -> Path:
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".exr", dir=path.parent)
    os.close(fd)
    return Path(tmp_name)


def write_exr(path: str | os.PathLike, data: np.ndarray, channels: tuple[str, ...] | list[str],
              units: str, overwrite: bool = False, compression: str = DEFAULT_COMPRESSION,
              pixel_type: str = "float") -> Path:
    """Write ``data`` (H, W) or (H, W, C) as one EXR map with the given channel names, through
    :class:`MapStream` and :func:`publish_maps` (the bake's writer); returns the path.

    ``units`` is stored in the header (e.g. "Blender units", "cm^-1", "1").  Non-finite data (or values beyond
    float32) raises ValueError (nothing is written); an existing file raises FileExistsError unless
    ``overwrite``; folders as :func:`check_output_folder`.
    """
    arr = np.asarray(data)
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.ndim != 3 or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"map data must be (H, W) or (H, W, C), got shape {np.shape(data)}")
    if arr.shape[2] != len(channels):
        raise ValueError(f"{arr.shape[2]} channels of data but {len(channels)} channel names {list(channels)}")
    stream = MapStream(path, arr.shape[1], arr.shape[0], channels, units, overwrite=overwrite,
                       compression=compression, pixel_type=pixel_type)
    try:
        stream.write_rows(arr)
    except BaseException:
        stream.discard()
        raise
    return publish_maps([stream])[0]


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
    check_output_folder(path.parent)
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
    oiio = openimageio()
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
    beside ``path``, with OpenImageIO, or uncompressed by exporters.exr where its module is missing.

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
        check_output_folder(self.path.parent)
        _refuse_existing(self.path, overwrite)
        self.overwrite = overwrite
        self.tmp = _temp_name(self.path)
        self._rows = 0
        try:
            oiio = openimageio()
        except ImageError:  # no OpenImageIO module (Blender 4.2): the same map, uncompressed
            self._out = _uncompressed(self.tmp, self.width, self.height, self.channels, units, compression,
                                      pixel_type)
            return
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
        if not finite and not np.all(np.isfinite(arr)):
            raise ValueError(f"map {self.path.name}: NaN/Inf values")
        if not finite and arr.dtype.itemsize > 4 and arr.size and np.abs(arr).max() > np.finfo(np.float32).max:
            raise ValueError(f"map {self.path.name}: values overflow float32")
        if not (self.pixel_type == "half" and arr.dtype == np.float16):
            arr = arr.astype(np.float32, copy=False)
        if arr.ndim == 2:
            arr = arr[..., None]
        h = arr.shape[0]
        if arr.shape[1:] != (self.width, len(self.channels)) or self._rows + h > self.height:
            raise ValueError(f"{self.path.name}: rows of shape {arr.shape} do not fit a "
                             f"{self.width} x {self.height} x {len(self.channels)} map at row {self._rows}")
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
