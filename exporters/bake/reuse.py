"""Up-to-date bakes: the key of everything a bake's maps depend on, and finding a folder that already holds them.

``S_maps.json`` records the key and each map's size and modification time; a bake with the same key into a
folder whose maps are unchanged does nothing (no image read, no model loaded, no inference).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from .. import maps
from ..image_input import ColorSpace, IndexedAlbedo
from .options import BakeOptions
from .report import BakeResult
from .targets import BakeError, parse_targets

#: Version of the bake key (bump when the maps of the same inputs change).  2: the painted colour by default.
KEY_VERSION = 2


def bake_key(image_id: str, model_sha256: str, stem: str, options: BakeOptions, mask_sha256: str = "") -> str:
    """SHA-256 over everything a bake's maps depend on: the image content (``image_id``: a hash of the file or
    of the pixels, with the colour space asked for), the model, the map stem and every option that changes
    values or files.  The evaluation path (table or exact for colours in the table) is part of the options
    only through ``exact``."""
    spec = {"version": KEY_VERSION, "image": image_id, "model_sha256": model_sha256, "stem": stem,
            "targets": sorted(parse_targets(options.targets)), "unit_scale_m": float(options.unit_scale_m),
            **options.collapse_options().as_dict(), "exact": bool(options.exact),
            "prune_share": float(options.prune_share), "uv_mask": mask_sha256, "compression": options.compression,
            "mantissa_bits": options.mantissa_bits, "half_maps": options.half_maps}
    if "openpbr" in spec["targets"]:
        spec["material"] = [options.write_material, options.material_stem, options.material_maps_stem]
    if options.edited:  # absent when neutral: the keys of unedited bakes stay as they were
        spec["edit"] = [float(v) for v in options.edit.row()]
        spec["edit_masks"] = {name: hashlib.sha256(np.ascontiguousarray(mask, np.float32).tobytes()
                                                   + str(np.shape(mask)).encode()).hexdigest()
                              for name, mask in sorted((options.edit_masks or {}).items())}
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()


def file_id(path: str | os.PathLike, colorspace: ColorSpace | str) -> str:
    """What identifies an image file in the bake key: a hash of its bytes and the colour space asked for."""
    return f"file:{maps.sha256_file(path)}:{colorspace}"


def job_key(image_id: str, model_sha256: str, stem: str, options: BakeOptions,
            shape: tuple[int, int] | None = None) -> str:
    """The key of a bake (:func:`bake_key`) with its UV coverage mask (``options.texel_mask``) hashed in;
    ``shape``: the image's (H, W), checked against the mask when known (BakeError)."""
    return bake_key(image_id, model_sha256, stem, options, mask_sha256(options.texel_mask, shape))


def mask_sha256(mask: np.ndarray | None, shape: tuple[int, int] | None = None) -> str:
    """Hash of a UV coverage mask for the bake key ("" without one); BakeError if it is not (H, W) = ``shape``."""
    if mask is None:
        return ""
    m = np.asarray(mask)
    if m.ndim != 2 or (shape is not None and m.shape != tuple(shape)):
        raise BakeError(f"UV coverage mask has shape {m.shape}, the image {tuple(shape or ())}: they must match")
    return hashlib.sha256(np.packbits(m.astype(bool)).tobytes() + str(m.shape).encode()).hexdigest()


def pixels_id(image: IndexedAlbedo) -> str:
    """What identifies an image without a file in the bake key: a hash of its decoded colours and index."""
    digest = hashlib.sha256(np.ascontiguousarray(image.palette, np.float64).tobytes())
    digest.update(np.ascontiguousarray(image.index, np.int32).tobytes())
    return f"pixels:{digest.hexdigest()}:{image.colorspace}"


def file_state(path: Path) -> dict[str, int]:
    """What tells a map file was not touched since it was written: size and modification time."""
    st = path.stat()
    return {"bytes": int(st.st_size), "mtime_ns": int(st.st_mtime_ns)}


def find_up_to_date(out_dir: str | os.PathLike, stem: str, key: str) -> BakeResult | None:
    """The bake recorded in ``out_dir/<stem>_maps.json`` if its key is ``key`` and every map it lists still has
    the size and modification time it had when written; else None."""
    json_path = Path(out_dir) / f"{stem}_maps.json"
    try:
        record = json.loads(json_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    bake = record.get("bake") or {}
    if bake.get("key") != key or not isinstance(record.get("files"), dict):
        return None
    states = bake.get("files") or {}
    files = []
    for name in record["files"]:
        path = Path(out_dir) / name
        if not path.is_file() or states.get(name) != file_state(path):
            return None
        files.append(path)
    notes = [f"up to date: {json_path.name} records the same image, model and options and its maps are "
             "unchanged; nothing was recomputed (force / --force re-bakes)"]
    return BakeResult(out_dir=Path(out_dir), stem=stem, files=files, json_path=json_path, k=int(record["K"]),
                      notes=notes, stats=dict(record.get("stats") or {}), timings_s={}, reused=True,
                      components=list((record.get("components") or {}).get("kept") or range(1, record["K"] + 1)))
