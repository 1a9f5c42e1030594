"""An uncompressed scanline OpenEXR writer in numpy, for Pythons without OpenImageIO's module (Blender 4.2).

exporters.maps writes its maps with OpenImageIO where it is importable (compressed, the default).  Blender 4.2's
Python has no OpenImageIO module, and the extension cannot bring one (docs/user/install.md), so there
:class:`ExrScanlineWriter` writes the same maps uncompressed: the single-part scanline layout of the OpenEXR
file format (magic, version 2, a header of attributes, a table of scanline offsets, one block per scanline
holding each channel's values in the header's channel order), channels HALF or FLOAT.  Files are larger than
compressed ones (4 or 2 bytes per value) and otherwise equal: every OpenEXR reader reads them.

The writer has the three methods of OpenImageIO's ImageOutput that exporters.maps.MapStream uses.
"""

from __future__ import annotations

import os
import struct

import numpy as np

#: OpenEXR's magic number and the version field of a single-part scanline file.
MAGIC, VERSION = 20000630, 2
#: OpenEXR pixel types by name: (code in the channel list, little-endian numpy dtype).
PIXEL_TYPES = {"half": (1, np.dtype("<f2")), "float": (2, np.dtype("<f4"))}


def _attribute(name: str, kind: str, value: bytes) -> bytes:
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value


def _header(width: int, height: int, channels: tuple[str, ...], pixel_type: str,
            strings: dict[str, str]) -> bytes:
    code = PIXEL_TYPES[pixel_type][0]
    chlist = b"".join(c.encode() + b"\0" + struct.pack("<iB3xii", code, 0, 1, 1) for c in channels) + b"\0"
    window = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    attrs = [
        _attribute("channels", "chlist", chlist),
        _attribute("compression", "compression", b"\0"),  # NO_COMPRESSION
        _attribute("dataWindow", "box2i", window),
        _attribute("displayWindow", "box2i", window),
        _attribute("lineOrder", "lineOrder", b"\0"),  # INCREASING_Y
        _attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
        _attribute("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
        _attribute("screenWindowWidth", "float", struct.pack("<f", 1.0)),
        *(_attribute(k, "string", v.encode()) for k, v in sorted(strings.items())),
    ]
    return struct.pack("<ii", MAGIC, VERSION) + b"".join(attrs) + b"\0"


class ExrScanlineWriter:
    """An uncompressed EXR of ``width`` x ``height`` with ``channels`` of ``pixel_type`` ("half" or "float") and
    string attributes ``strings``, written scanline by scanline from the top.  Channels are stored sorted by name,
    as OpenEXR requires; rows are given in the order of ``channels``."""

    def __init__(self, path: str | os.PathLike, width: int, height: int, channels: tuple[str, ...] | list[str],
                 pixel_type: str = "float", strings: dict[str, str] | None = None) -> None:
        if pixel_type not in PIXEL_TYPES:
            raise ValueError(f"EXR pixel type must be one of {tuple(PIXEL_TYPES)}, not {pixel_type!r}")
        self.width, self.height, self.channels = int(width), int(height), tuple(channels)
        self.order = sorted(range(len(self.channels)), key=lambda i: self.channels[i])
        self.dtype = PIXEL_TYPES[pixel_type][1]
        header = _header(self.width, self.height, tuple(self.channels[i] for i in self.order), pixel_type,
                         strings or {})
        self.line_bytes = self.width * len(self.channels) * self.dtype.itemsize
        first = len(header) + 8 * self.height
        offsets = first + np.arange(self.height, dtype="<u8") * (8 + self.line_bytes)
        self._file = open(path, "wb")  # closed by close()
        self._file.write(header + offsets.tobytes())
        self._error = ""

    def write_scanlines(self, ybegin: int, yend: int, z: int, pixels: np.ndarray) -> bool:
        """Rows ``ybegin`` to ``yend`` (exclusive) of ``pixels`` (rows, width, channels); False on a bad shape."""
        arr = np.asarray(pixels)
        if arr.ndim == 2:
            arr = arr[..., None]
        if arr.shape != (yend - ybegin, self.width, len(self.channels)):
            self._error = (f"rows of shape {arr.shape} for scanlines {ybegin}-{yend} of a {self.width} x "
                           f"{len(self.channels)}-channel image")
            return False
        planar = np.ascontiguousarray(arr[..., self.order].astype(self.dtype).transpose(0, 2, 1))
        for i, y in enumerate(range(ybegin, yend)):
            self._file.write(struct.pack("<ii", y, self.line_bytes) + planar[i].tobytes())
        return True

    def geterror(self) -> str:
        return self._error

    def close(self) -> bool:
        self._file.close()
        return True
