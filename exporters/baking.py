"""Bake an albedo texture into the maps of SPEC §4 (bpy-free core of bake.py and of the Blender operator).

Pipeline.  Every value a bake writes depends on the texel's colour only, so:

1. **Distinct colours** (exporters.palette): the image becomes a palette and a per-texel index; with a UV
   coverage mask (``BakeOptions.texel_mask``, from the mesh) texels no face covers take the most common
   covered colour, so their colours are never evaluated.
2. **Records per distinct colour** (exporters.texel_records): by default from the fast-path table
   (exporters.texel_table: trilinear interpolation over skin colours, made from this very model — its
   SHA-256 is checked; colours outside it are evaluated exactly), or all exactly (``exact=True``:
   onnxruntime + the collapse).  Only what the targets need is computed (``spectral`` alone skips the
   collapse).  Chunks are spread over ``threads`` cores.
3. **Components** whose share of the rendered colour stays below ``prune_share`` for every texel are
   dropped (the remaining ones are numbered k1..kK').
4. **Maps**, band by band: each map's rows gathered through the index and written to temporary EXR files
   beside their final names, one map per thread, OpenEXR compressing on the same threads.  Only when
   every band is done are the maps moved into place (all or none), then ``S_maps.json`` is written.
   Cancelling or any error leaves the output folder as it was.

A bake that is already up to date — ``S_maps.json`` in the folder records the same key (image content,
model SHA-256, options) and every map it lists is unchanged — is reused: nothing is read, loaded,
evaluated or written (``force=True`` re-bakes).

When the distinct colours are too many to hold their values in memory (more than about
``4 x memory_mb`` MiB, e.g. a noisy float image), step 2 runs per band instead and step 3 is skipped.

:class:`BakeJob` runs step by step (one chunk per step) so that Blender can drive it from a timer with a
progress bar; :func:`bake` runs it to the end.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from exporters import collapse, inference, maps, reflectance_tables, texel_records, texel_table
from exporters.texel_records import CollapseOptions

TARGETS: tuple[str, ...] = ("cycles", "physical", "spectral")
#: Units strings stored in each EXR header and in S_maps.json.
UNITS = {
    "color": "1 (Cycles Subsurface Color, RANDOM_WALK)",
    "radius": "Blender units (Subsurface Radius with Scale = 1)",
    "weight": "1 (mixture weight per channel)",
    "anisotropy": "1 (Henyey-Greenstein g)",
    "alpha": "1 (single-scattering albedo)",
    "sigma_t": "cm^-1",
    "g": "1 (Henyey-Greenstein g)",
    "biophysical": "f_mel 1, f_blood 1, t_epi cm, so2 1, b_mel 1, exposure 1",
}
#: Default texels per band: bands bound the memory of the expanded maps (about 0.3 KB per texel).
DEFAULT_BAND_TEXELS = 1 << 19
#: A component is dropped when its share of the rendered colour stays below this for every texel and
#: channel: the colour then changes by less than 0.2 % (at most about 0.1 ΔE76).
DEFAULT_PRUNE_SHARE = 0.002
#: Distinct colours looked up in the fast-path table per step (the UI stays responsive: ~0.1 s each).
TABLE_CHUNK = 1 << 18
#: Mantissa bits of fast-path maps (BakeOptions.mantissa_bits).
FAST_MANTISSA_BITS = 16
#: Cycles map kinds bounded to [-1, 1] (colour, weights, anisotropy): the fast path stores them as half floats
#: (BakeOptions.half_maps).  Their rounding (<= 2.4e-4 below 1) is a tenth of the table's interpolation error in
#: the rendered colour, and halves what PIZ compresses.  Radius and the physical and biophysical maps stay float32:
#: radii span decades down to 1e-5 m (half's subnormal range), and 1 - alpha of a physical albedo near 1 needs
#: float's precision.
HALF_KINDS = frozenset({"color", "weight", "anisotropy"})
#: Version of the bake key (bump when the maps of the same inputs change).
KEY_VERSION = 1


class BakeError(ValueError):
    """Bad input for a bake (targets, output folder, existing files); the message says what to do."""


@dataclass(frozen=True)
class MapSpec:
    """One output file: its name, kind (key of UNITS), component k (1-based in the files, 0 for spectral),
    channels, target, and ``source_k``: the model's component it holds (differs from k when components
    were dropped)."""

    name: str
    kind: str
    k: int
    channels: tuple[str, ...]
    target: str
    source_k: int = 0


def parse_targets(text: str | list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """'cycles,physical' -> ('cycles', 'physical'); BakeError naming unknown targets."""
    items = [t.strip() for t in (text.split(",") if isinstance(text, str) else text) if t.strip()]
    bad = [t for t in items if t not in TARGETS]
    if bad or not items:
        raise BakeError(f"unknown target(s) {bad or items!r}; use a comma-separated subset of {','.join(TARGETS)}")
    return tuple(dict.fromkeys(items))


def map_specs(stem: str, k_count: int, targets: tuple[str, ...],
              components: tuple[int, ...] | list[int] | None = None) -> list[MapSpec]:
    """Every file a bake writes (SPEC §4 names), in a fixed order; the weight map is shared by the cycles
    and physical targets (it is the same array).  ``components``: the model's components to write (1-based,
    default all ``k_count``); they are numbered k1, k2, ... in the file names."""
    rgb, one = maps.RGB_CHANNELS, maps.SINGLE_CHANNEL
    kept = list(components) if components is not None else list(range(1, k_count + 1))
    specs: dict[str, MapSpec] = {}
    for target in targets:
        if target == "spectral":
            specs[f"{stem}_biophysical.exr"] = MapSpec(f"{stem}_biophysical.exr", "biophysical", 0,
                                                       maps.BIOPHYSICAL_CHANNELS, target)
            continue
        kinds = (("color", rgb), ("radius", rgb), ("weight", rgb), ("anisotropy", one)) if target == "cycles" else \
            (("alpha", rgb), ("sigma_t", rgb), ("g", rgb), ("weight", rgb))
        for k, source in enumerate(kept, start=1):
            for kind, channels in kinds:
                name = f"{stem}_k{k}_{kind}.exr"
                specs.setdefault(name, MapSpec(name, kind, k, channels, target, source))
    return list(specs.values())


@dataclass
class BakeOptions:
    """``targets`` of SPEC §4; ``unit_scale_m`` metres per Blender unit; ``threads`` for onnxruntime, the table
    lookups and OpenEXR (0 = all cores); ``memory_mb`` budget of one inference chunk; ``chunk`` caps distinct
    texels per exact step (None: from the budget); ``match_exposure`` scales the target colour by the model's
    exposure (shows the painted brightness instead of the model's reflectance); ``ior``: the IOR the node
    group's closures use (its IOR input; it sets how view rays enter the medium, see
    exporters.reflectance_tables); ``min_mfp_m``: smallest mean free path given to Cycles, metres
    (exporters.collapse step 7); ``overwrite`` replaces existing files.

    Fast path and skipping: ``exact`` evaluates every distinct colour with the model (no table);
    ``table_path``: the fast-path table (None: ``<model stem>_table.npz`` beside the model, then the user
    cache); ``cache_tables``: build and cache a table for option sets no shipped table covers when the image
    has enough distinct colours to pay for it; ``prune_share``: components below this share of the colour
    everywhere are dropped (0 keeps all); ``texel_mask`` (H, W) bool: texels the mesh's UVs cover (others
    take the maps of the most common covered colour); ``force`` re-bakes an up-to-date folder;
    ``compression`` of the EXR maps (exporters.maps.COMPRESSIONS); ``mantissa_bits``: float32 mantissa bits the
    maps keep (None: 16 when the table is used — relative 7.6e-6, far below its interpolation error, and 25 %
    faster to compress — and all 23 for exact bakes); ``half_maps``: the maps of ``HALF_KINDS`` stored as
    half floats (None: on the fast path, not with ``exact``); ``cache_min_colours``: distinct colours from which a
    bake without a usable table builds one (grid step ``cache_step``) into the user cache."""

    targets: tuple[str, ...] = ("cycles",)
    unit_scale_m: float = 1.0
    threads: int = 0
    memory_mb: float = inference.DEFAULT_MEMORY_MB
    chunk: int | None = None
    band_texels: int = DEFAULT_BAND_TEXELS
    match_exposure: bool = False
    ior: float = reflectance_tables.CYCLES_IOR
    min_mfp_m: float = collapse.MIN_MFP_CM / 100.0
    overwrite: bool = False
    exact: bool = False
    table_path: str | os.PathLike | None = None
    cache_tables: bool = True
    prune_share: float = DEFAULT_PRUNE_SHARE
    texel_mask: np.ndarray | None = field(default=None, repr=False)
    force: bool = False
    compression: str = maps.DEFAULT_COMPRESSION
    mantissa_bits: int | None = None
    half_maps: bool | None = None
    cache_min_colours: int = 50_000  # building evaluates ~34,000 grid nodes: it pays off from ~1.5x that
    cache_step: float = texel_table.DEFAULT_STEP

    def collapse_options(self) -> CollapseOptions:
        return CollapseOptions(match_exposure=bool(self.match_exposure), ior=float(self.ior),
                               min_mfp_cm=float(self.min_mfp_m) * 100.0)


@dataclass
class BakeResult:
    """What a finished bake wrote: ``files`` (paths in order), ``json_path``, K (components written), notes for
    the user, the counts of collapse clamps (texels x components x channels) and of how texels were
    evaluated, timings in seconds, and ``reused`` (True when an up-to-date bake was found and kept)."""

    out_dir: Path
    stem: str
    files: list[Path]
    json_path: Path
    k: int
    notes: list[str]
    stats: dict[str, int]
    timings_s: dict[str, float] = field(default_factory=dict)
    reused: bool = False
    components: list[int] = field(default_factory=list)


def input_notes(albedo: maps.AlbedoImage | maps.IndexedAlbedo) -> list[str]:
    """Remarks on valid but special inputs (shown to the user and stored in S_maps.json)."""
    notes = []
    if albedo.n_channels in (1, 2):
        notes.append("grayscale image: its gray value is used for R, G and B")
    has_alpha = albedo.has_alpha if isinstance(albedo, maps.IndexedAlbedo) else albedo.alpha is not None
    if has_alpha:
        notes.append("alpha channel ignored: the albedo is taken from the colour channels")
    if albedo.n_clamped:
        notes.append(f"{albedo.n_clamped} texel(s) with negative values clamped to 0")
    if isinstance(albedo, maps.IndexedAlbedo):
        above = int(albedo.counts[(albedo.palette > 1.0).any(axis=1)].sum())
        h, w = albedo.shape
    else:
        above = int(np.count_nonzero((albedo.rgb > 1.0).any(axis=-1)))
        h, w = albedo.rgb.shape[:2]
    if above:
        notes.append(f"{above} texel(s) above 1 (not a valid albedo) are treated as 1 by the model")
    if h * w == 1:
        notes.append("1 x 1 image: the maps are uniform")
    return notes


# -- up-to-date bakes --------------------------------------------------------------------------------------


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
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()


def _file_state(path: Path) -> dict[str, int]:
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
        if not path.is_file() or states.get(name) != _file_state(path):
            return None
        files.append(path)
    notes = [f"up to date: {json_path.name} records the same image, model and options and its maps are "
             "unchanged; nothing was recomputed (force / --force re-bakes)"]
    return BakeResult(out_dir=Path(out_dir), stem=stem, files=files, json_path=json_path, k=int(record["K"]),
                      notes=notes, stats=dict(record.get("stats") or {}), timings_s={}, reused=True,
                      components=list((record.get("components") or {}).get("kept") or range(1, record["K"] + 1)))


# -- the fast-path table --------------------------------------------------------------------------------------


def default_table_path(model_path: str | os.PathLike) -> Path:
    """Where a model's shipped table lives: ``<model stem>_table.npz`` beside the model."""
    p = Path(model_path)
    return p.with_name(f"{p.stem}_table.npz")


def table_cache_dir() -> Path:
    """Per-user folder of tables built for option sets no shipped table covers: $SPECTRAL_SKIN_SSS_CACHE, else
    $XDG_CACHE_HOME/spectral_skin_sss, else ~/.cache/spectral_skin_sss."""
    env = os.environ.get("SPECTRAL_SKIN_SSS_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "spectral_skin_sss"


def cached_table_path(model_sha256: str, options: CollapseOptions, step: float = texel_table.DEFAULT_STEP) -> Path:
    """The user-cache file of the table for a model, collapse options and grid step."""
    opts = hashlib.sha256(json.dumps(options.as_dict(), sort_keys=True).encode()).hexdigest()[:12]
    return table_cache_dir() / f"table_{model_sha256[:16]}_{opts}_step{step:g}.npz"


def find_table(model: inference.ModelFile, options: CollapseOptions, table_path=None,
               notes: list[str] | None = None, cache_step: float = texel_table.DEFAULT_STEP
               ) -> texel_table.TexelTable | None:
    """The fast-path table for ``model`` and ``options``: ``table_path`` (or the one beside the model), else
    the user cache.  A table made from another model (SHA-256 differs) is refused with a warning in
    ``notes`` (and Python's warnings): the bake then evaluates exactly."""
    notes = notes if notes is not None else []
    first = Path(table_path) if table_path else default_table_path(model.path)
    for path in dict.fromkeys([first, cached_table_path(model.sha256, options, cache_step)]):
        if not path.is_file():
            continue
        try:
            table = texel_table.load(path)
        except texel_table.TableError as exc:
            _warn(notes, f"{exc}; every texel is evaluated exactly")
            continue
        if table.model_sha256 != model.sha256:
            _warn(notes, f"fast-path table {path.name} was made from model {table.model_sha256[:12]}, not from "
                         f"{model.path.name} ({model.sha256[:12]}): refused, every texel is evaluated exactly; "
                         f"rebuild it: python -m exporters.texel_table --model {model.path} --out {path} --overwrite")
            continue
        if table.options == options:
            return table
    return None


def _warn(notes: list[str], text: str) -> None:
    notes.append(f"warning: {text}")
    warnings.warn(text, stacklevel=3)


# -- the job --------------------------------------------------------------------------------------------------


def mask_sha256(mask: np.ndarray | None, shape: tuple[int, int] | None = None) -> str:
    """Hash of a UV coverage mask for the bake key ("" without one); BakeError if it is not (H, W) = ``shape``."""
    if mask is None:
        return ""
    m = np.asarray(mask)
    if m.ndim != 2 or (shape is not None and m.shape != tuple(shape)):
        raise BakeError(f"UV coverage mask has shape {m.shape}, the image {tuple(shape or ())}: they must match")
    return hashlib.sha256(np.packbits(m.astype(bool)).tobytes() + str(m.shape).encode()).hexdigest()


def pixels_id(image: maps.IndexedAlbedo) -> str:
    """What identifies an image without a file in the bake key: a hash of its decoded colours and index."""
    digest = hashlib.sha256(np.ascontiguousarray(image.palette, np.float64).tobytes())
    digest.update(np.ascontiguousarray(image.index, np.int32).tobytes())
    return f"pixels:{digest.hexdigest()}:{image.colorspace}"


def _threads(n: int) -> int:
    return int(n) if n and n > 0 else (os.cpu_count() or 1)


def _apply_mask(image: maps.IndexedAlbedo, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Index and palette with uncovered texels set to the most common covered colour; returns (palette,
    index, number of uncovered texels)."""
    index = image.index
    covered = index[mask]
    if covered.size == 0:
        raise BakeError("the mesh's UVs cover no texel of the image: check the UV map or bake without the mesh")
    fill = int(np.argmax(np.bincount(covered, minlength=len(image.palette))))
    index = np.where(mask, index, fill)
    used = np.zeros(len(image.palette), bool)
    used[index] = True
    remap = np.cumsum(used) - 1
    return image.palette[used], remap[index].astype(np.int32), int(mask.size - np.count_nonzero(mask))


class BakeJob:
    """A bake in steps.  Construction checks everything that can be checked cheaply (targets, folder,
    existing names, unit scale) and finds an up-to-date bake; :meth:`steps` does the work and yields the
    fraction done; :meth:`finish` publishes the files; :meth:`cancel` (or any exception in a step) removes
    every temporary file.

    ``albedo``: a dense :class:`exporters.maps.AlbedoImage` or an :class:`exporters.maps.IndexedAlbedo`;
    ``model``: a loaded :class:`exporters.inference.SkinModel` or an :class:`exporters.inference.ModelFile`
    (loaded only if some colour must be evaluated exactly); ``image_id``: what identifies the image content
    in the bake key (default: a hash of its decoded colours).
    """

    def __init__(self, albedo: maps.AlbedoImage | maps.IndexedAlbedo, out_dir: str | os.PathLike, stem: str,
                 model: inference.SkinModel | inference.ModelFile, options: BakeOptions | None = None,
                 input_image: str = "", image_id: str | None = None) -> None:
        self.options = options or BakeOptions()
        opts = self.options
        self.targets = parse_targets(opts.targets)
        if not (np.isfinite(opts.unit_scale_m) and opts.unit_scale_m > 0):
            raise BakeError(f"unit scale must be a positive number of metres per Blender unit, got {opts.unit_scale_m}")
        if not reflectance_tables.IOR_MIN <= opts.ior <= reflectance_tables.IOR_MAX:
            raise BakeError(f"IOR must lie in [{reflectance_tables.IOR_MIN}, {reflectance_tables.IOR_MAX}] "
                            f"(Cycles' range), got {opts.ior}")
        if not (np.isfinite(opts.min_mfp_m) and opts.min_mfp_m >= 0):
            raise BakeError(f"smallest mean free path must be >= 0 m, got {opts.min_mfp_m}")
        if not (np.isfinite(opts.prune_share) and 0.0 <= opts.prune_share < 1.0):
            raise BakeError(f"prune share must lie in [0, 1), got {opts.prune_share}")
        if opts.mantissa_bits is not None and not 1 <= opts.mantissa_bits <= 23:
            raise BakeError(f"mantissa bits must lie in 1..23, got {opts.mantissa_bits}")
        if opts.compression not in maps.COMPRESSIONS:
            raise BakeError(f"EXR compression must be one of {', '.join(maps.COMPRESSIONS)}, not {opts.compression!r}")
        if not stem or os.sep in stem or (os.altsep and os.altsep in stem):
            raise BakeError(f"invalid map name stem {stem!r}")
        image = self._index(albedo)
        self.albedo, self.stem, self.input_image = albedo, stem, input_image
        self.out_dir = Path(out_dir)
        self.height, self.width = image.shape
        self.model = model if isinstance(model, inference.ModelFile) else inference.ModelFile.of(model)
        self.notes = input_notes(image)
        self.timings = {"load_model": 0.0, "evaluate": 0.0, "inference": 0.0, "table": 0.0, "write": 0.0}
        mask_sha = mask_sha256(opts.texel_mask, image.shape)
        if image_id is None:
            image_id = pixels_id(image)
        self.key = bake_key(image_id, self.model.sha256, stem, opts, mask_sha)
        self.reused = None if opts.force else find_up_to_date(self.out_dir, stem, self.key)
        self._streams: list[maps.MapStream] | None = None
        self._done = False
        if self.reused is not None:
            self.specs, self.components = [], list(self.reused.components)
            return
        uncovered = 0
        if opts.texel_mask is not None:
            self.palette, self.index, uncovered = _apply_mask(image, np.asarray(opts.texel_mask, bool))
        else:
            self.palette, self.index = image.palette, image.index
        self.counts = np.bincount(self.index.ravel(), minlength=len(self.palette))
        if uncovered:
            self.notes.append(f"{uncovered} texel(s) not covered by the mesh's UVs were not evaluated: they hold the "
                              "maps of the most common covered colour")
        self.stats: dict[str, int] = {"texels": self.height * self.width, "distinct_texels": len(self.palette),
                                      "texels_not_covered_by_uvs": uncovered}
        if texel_records.needs_media(self.targets):
            self.stats.update({name: 0 for name in texel_records.STAT_NAMES.values()})
        self.copts = opts.collapse_options()
        self.threads = _threads(opts.threads)
        self.table = None if opts.exact else find_table(self.model, self.copts, opts.table_path, self.notes,
                                                        opts.cache_step)
        self._build_table = (self.table is None and not opts.exact and opts.cache_tables
                             and len(self.palette) >= opts.cache_min_colours)
        if self.table is None and not opts.exact and not self._build_table:
            self.notes.append("no fast-path table for this model and these options: every distinct colour evaluated "
                              f"exactly (python -m exporters.texel_table --model {self.model.path} builds one; "
                              f"images with {opts.cache_min_colours:,}+ colours build and cache one themselves)")
        self.model_k = self.table.k if self.table is not None else self._load_model().k
        self.components = list(range(1, self.model_k + 1))
        self.specs = map_specs(stem, self.model_k, self.targets)
        self._check_folder()
        self.chunk = opts.chunk or inference.chunk_rows_for_k(self.model_k, opts.memory_mb)
        self.band_rows = max(1, min(self.height, max(opts.band_texels, 1) // self.width or 1))
        channels = sum(len(s.channels) for s in self.specs)
        self.global_values = len(self.palette) * channels * 4 <= 4 * opts.memory_mb * 2**20
        self.values: dict[str, np.ndarray] = {}
        self._max_share = np.zeros(self.model_k)
        self._counted = {"texels_from_table": 0, "texels_evaluated_exactly": 0}

    # -- set-up -----------------------------------------------------------------------------------------------
    @staticmethod
    def index(albedo) -> maps.IndexedAlbedo:
        """An albedo image as an :class:`exporters.maps.IndexedAlbedo`, checked (BakeError for NaN, negative
        texels or a bad shape)."""
        return BakeJob._index(albedo)

    @staticmethod
    def _index(albedo) -> maps.IndexedAlbedo:
        if isinstance(albedo, maps.IndexedAlbedo):
            image = albedo
        else:
            rgb = np.asarray(albedo.rgb)
            if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] < 1 or rgb.shape[1] < 1:
                raise BakeError(f"albedo must be an (H, W, 3) image, got shape {rgb.shape}")
            image = maps.IndexedAlbedo.from_dense(albedo)
        if image.index.ndim != 2 or min(image.index.shape) < 1:
            raise BakeError(f"albedo must be an (H, W, 3) image, got an index of shape {image.index.shape}")
        if not np.all(np.isfinite(image.palette)):
            raise BakeError("albedo has NaN/Inf texels; fix the texture")
        if np.any(image.palette < 0):
            raise BakeError("albedo has negative texels; an albedo cannot be negative")
        return image

    def _load_model(self) -> inference.SkinModel:
        if not self.model.loaded:
            t0 = time.perf_counter()
            self.model.load()
            self.timings["load_model"] += time.perf_counter() - t0
        return self.model.load()

    def _check_folder(self) -> None:
        if not self.out_dir.is_dir():
            raise BakeError(f"output folder does not exist: {self.out_dir}")
        if not os.access(self.out_dir, os.W_OK | os.X_OK):
            raise BakeError(f"output folder is not writable: {self.out_dir}")
        if not self.options.overwrite:
            names = [s.name for s in self.specs] + [f"{self.stem}_maps.json"]
            taken = [n for n in names if (self.out_dir / n).exists()]
            if taken:
                raise BakeError(f"{len(taken)} file(s) exist in {self.out_dir} (e.g. {taken[0]}) from another bake; "
                                "choose another folder or allow overwriting (--overwrite)")

    @property
    def json_path(self) -> Path:
        return self.out_dir / f"{self.stem}_maps.json"

    @property
    def k(self) -> int:
        """Components written (the model's K less dropped ones)."""
        return len(self.components)

    def _units(self, spec: MapSpec) -> str:
        if spec.kind == "radius":
            return f"{UNITS['radius']}; 1 BU = {self.options.unit_scale_m:g} m"
        return UNITS[spec.kind]

    # -- evaluation --------------------------------------------------------------------------------------------
    def _records(self, rgb: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Records of distinct colours ``rgb`` (n, 3) float32 (table where it covers them, else exact) and
        which rows came from the table."""
        inside = np.zeros(len(rgb), bool)
        parts: dict[str, np.ndarray] | None = None
        if self.table is not None:
            t0 = time.perf_counter()
            inside, base, frac = self.table.locate(rgb)
            if inside.any():
                vals = self.table.interpolate(base, frac, self.threads)
                parts = self.table.records(rgb[inside], vals, self.targets)
            self.timings["table"] += time.perf_counter() - t0
        n_in = int(inside.sum())
        if n_in == len(rgb):
            rec = parts if parts is not None else texel_records.empty_records(self.model_k, self.targets)
        else:
            model = self._load_model()
            t0 = time.perf_counter()
            exact = texel_records.exact_records(model, rgb[~inside], self.targets, self.copts)
            self.timings["inference"] += time.perf_counter() - t0
            if parts is None:
                rec = exact
            else:
                rec = {}
                for key, value in parts.items():
                    full = np.empty((len(rgb), *value.shape[1:]), value.dtype)
                    full[inside], full[~inside] = value, exact[key]
                    rec[key] = full
        return rec, inside

    def _values_of(self, rec: dict[str, np.ndarray], specs: list[MapSpec]) -> dict[str, np.ndarray]:
        out = {}
        for spec in specs:
            try:
                v = texel_records.map_values(spec.kind, spec.source_k or spec.k, rec, self.options.unit_scale_m)
            except ValueError as exc:
                raise BakeError(str(exc)) from None
            if not np.all(np.isfinite(v)):
                raise RuntimeError(f"non-finite values for {spec.name}")  # records are checked; never expected
            out[spec.name] = maps.round_mantissa(v, self.mantissa_bits)
        return out

    def _evaluate(self, ids: np.ndarray, counts: np.ndarray, specs: list[MapSpec],
                  into: dict[str, np.ndarray], progress: Callable[[float], float]) -> Iterator[float]:
        """Values of palette entries ``ids`` for ``specs`` into ``into`` (rows in ``ids`` order), in chunks."""
        step = TABLE_CHUNK if self.table is not None else self.chunk
        for spec in specs:
            into[spec.name] = np.empty((len(ids), len(spec.channels)), np.float32)
        for start in range(0, len(ids), step):
            sl = slice(start, min(start + step, len(ids)))
            t0 = time.perf_counter()
            rgb = self.palette[ids[sl]].astype(np.float32)
            rec, inside = self._records(rgb)
            for name, v in self._values_of(rec, specs).items():
                into[name][sl] = v
            c = counts[sl]
            self._counted["texels_from_table"] += int(c[inside].sum())
            self._counted["texels_evaluated_exactly"] += int(c[~inside].sum())
            for key, value in texel_records.count_stats(rec, c).items():
                self.stats[key] = int(self.stats.get(key, 0)) + value
            if "max_share" in rec and len(rec["max_share"]):
                self._max_share = np.maximum(self._max_share, rec["max_share"].max(axis=0))
            self.timings["evaluate"] += time.perf_counter() - t0
            yield progress(sl.stop / max(len(ids), 1))

    def _make_table(self) -> Iterator[float]:
        """Build the table for these options in the user cache (first step of a big bake without one)."""
        path = cached_table_path(self.model.sha256, self.copts, self.options.cache_step)
        t0 = time.perf_counter()
        table = yield from texel_table.build_steps(self._load_model(), self.copts, self.options.cache_step)
        path.parent.mkdir(parents=True, exist_ok=True)
        texel_table.save(table, path, overwrite=True)
        self.table = texel_table.load(path)
        self.timings["table_build"] = time.perf_counter() - t0
        self.notes.append(f"built a fast-path table for these options in {self.timings['table_build']:.0f} s, "
                          f"cached as {path} (reused by later bakes)")

    @property
    def mantissa_bits(self) -> int:
        """Mantissa bits the maps keep: the option, else 16 when the table is used (also one built by this bake)
        and 23 for exact bakes."""
        return self.options.mantissa_bits or (FAST_MANTISSA_BITS if self.table is not None else 23)

    @property
    def half_maps(self) -> bool:
        """Whether the maps of ``HALF_KINDS`` are half floats: the option, else when the table is used."""
        return self.options.half_maps if self.options.half_maps is not None else self.table is not None

    def _prune(self) -> None:
        """Drop components whose share of the colour is below ``prune_share`` for every texel (global mode)."""
        share = self.options.prune_share
        if share <= 0 or not texel_records.needs_media(self.targets) or self.model_k < 2:
            return
        keep = [k for k in range(1, self.model_k + 1) if self._max_share[k - 1] >= share]
        if not keep:
            keep = [int(np.argmax(self._max_share)) + 1]
        if len(keep) == self.model_k:
            return
        dropped = [k for k in range(1, self.model_k + 1) if k not in keep]
        old = {(s.kind, s.source_k): s.name for s in self.specs}
        self.components = keep
        self.specs = map_specs(self.stem, self.model_k, self.targets, keep)
        self.values = {s.name: self.values[old[(s.kind, s.source_k)]] for s in self.specs}
        self.notes.append(f"component(s) {dropped} of the model dropped: below {100 * share:g} % of the colour at "
                          f"every texel (largest share {100 * float(self._max_share[np.array(dropped) - 1].max()):.3g} "
                          f"%); maps numbered k1..k{len(keep)}")

    # -- running -----------------------------------------------------------------------------------------------
    def steps(self) -> Iterator[float]:
        """Do the work; yields the fraction done (0..1] after each chunk or band."""
        if self._streams is not None or self._done:
            raise RuntimeError("a BakeJob runs once")
        if self.reused is not None:
            self._streams = []
            yield 1.0
            return
        maps.set_threads(self.threads)
        pre = 0.0
        if self._build_table:
            pre = 0.3
            yield from (pre * f for f in self._make_table())
        for f in self._work():
            yield pre + (1.0 - pre) * f

    def _work(self) -> Iterator[float]:
        share_eval = 0.15 if self.table is not None else 0.6
        if self.global_values:
            ids = np.arange(len(self.palette))
            yield from self._evaluate(ids, self.counts, self.specs, self.values, lambda f: share_eval * f)
            self._prune()
        self._streams = self._open()
        try:
            yield from self._bands(share_eval)
        except BaseException:
            self.cancel()
            raise

    def _open(self) -> list[maps.MapStream]:
        streams = []
        try:
            for spec in self.specs:
                streams.append(maps.MapStream(self.out_dir / spec.name, self.width, self.height, spec.channels,
                                              self._units(spec), overwrite=self.options.overwrite,
                                              compression=self.options.compression,
                                              pixel_type="half" if self.half_maps and spec.kind in HALF_KINDS
                                              else "float"))
        except BaseException:
            for s in streams:
                s.discard()
            raise
        return streams

    def _bands(self, share_eval: float) -> Iterator[float]:
        pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        try:
            for y0 in range(0, self.height, self.band_rows):
                y1 = min(self.height, y0 + self.band_rows)
                ids = self.index[y0:y1].ravel()
                if self.global_values:
                    values, rows = self.values, ids
                else:  # this band's share of the progress: evaluation first, then writing
                    uniq, rows = np.unique(ids, return_inverse=True)
                    values = {}
                    base, span = y0 / self.height, share_eval * (y1 - y0) / self.height
                    yield from self._evaluate(uniq, np.bincount(rows, minlength=len(uniq)), self.specs, values,
                                              lambda f, b=base, s=span: b + s * f)
                t0 = time.perf_counter()

                def write(item, rows=rows, values=values, h=y1 - y0):
                    spec, stream = item
                    stream.write_rows(np.take(values[spec.name], rows, axis=0).reshape(h, self.width, -1), finite=True)

                items = list(zip(self.specs, self._streams, strict=True))
                if pool is None:
                    for item in items:
                        write(item)
                else:
                    list(pool.map(write, items))
                self.timings["write"] += time.perf_counter() - t0
                yield (share_eval + (1.0 - share_eval) * y1 / self.height) if self.global_values else y1 / self.height
        finally:
            if pool is not None:
                pool.shutdown()

    def cancel(self) -> None:
        """Stop and remove every temporary file; the output folder is left as it was."""
        for s in self._streams or []:
            s.discard()
        self._streams = []
        self._done = True

    def finish(self, extra_timings: dict[str, float] | None = None) -> BakeResult:
        """Publish the maps (all or none) and write S_maps.json; call after :meth:`steps` is exhausted."""
        if self.reused is not None:
            self._done = True
            self.reused.notes = list(self.reused.notes)
            return self.reused
        if self._streams is None or self._done:
            raise RuntimeError("finish() needs a completed, not cancelled, run of steps()")
        t0 = time.perf_counter()
        try:
            files = maps.publish_maps(self._streams)
        finally:
            self._done = True
        self.timings["write"] += time.perf_counter() - t0
        timings = {**self.timings, **(extra_timings or {})}
        self.stats.update(self._counted)
        try:
            json_path = self._write_json(timings, files)
        except BaseException:
            for f in files:
                if not self.options.overwrite:
                    f.unlink(missing_ok=True)
            raise
        return BakeResult(out_dir=self.out_dir, stem=self.stem, files=files, json_path=json_path, k=self.k,
                          notes=list(self.notes), stats=dict(self.stats), timings_s=timings,
                          components=list(self.components))

    def _write_json(self, timings: dict[str, float], files: list[Path]) -> Path:
        listed = {s.name: {"units": self._units(s), "channels": list(s.channels), "target": s.target,
                           "component": s.k or None, "kind": s.kind, "colorspace": "Non-Color"} for s in self.specs}
        table = self.table
        extra = {
            "image_size": [self.width, self.height],
            "targets": list(self.targets),
            "collapse": {"method": "exporters.collapse (per channel: Cycles reflectance share, diffusion length)",
                         "g_max": collapse.G_MAX, "alpha_min": collapse.ALPHA_MIN,
                         "alpha_star_soft_max": collapse.ALPHA_STAR_SOFT_MAX,
                         "match_exposure": bool(self.options.match_exposure),
                         "ior": float(self.options.ior),
                         "min_mean_free_path_m": float(self.options.min_mfp_m),
                         "target": "exposure x linear sRGB (D65) of the model reflectance" if
                         self.options.match_exposure else "linear sRGB (D65) of the model reflectance"},
            "model": {"path": str(self.model.path), "K": self.model_k},
            "evaluation": {"mode": "exact" if table is None else "table",
                           "table": None if table is None else {
                               "path": str(table.path), "sha256": table.sha256, "step": table.meta.get("step"),
                               "model_sha256": table.model_sha256, "command": table.meta.get("command")},
                           "exr_compression": self.options.compression,
                           "mantissa_bits": self.mantissa_bits,
                           "half_kinds": sorted(HALF_KINDS) if self.half_maps else []},
            "components": {"model_K": self.model_k, "kept": list(self.components),
                           "dropped": [k for k in range(1, self.model_k + 1) if k not in self.components],
                           "prune_share": float(self.options.prune_share),
                           "max_share": [round(float(s), 6) for s in self._max_share]},
            "notes": self.notes,
            "stats": self.stats,
            "bake": {"key": self.key, "files": {f.name: _file_state(f) for f in files}},
        }
        sha = {self.model.path.name: self.model.sha256}
        return maps.write_maps_json(self.json_path, listed, self.k, sha, self.input_image,
                                    self._colorspace(), timings, unit_scale_m=self.options.unit_scale_m,
                                    overwrite=self.options.overwrite, extra=extra)

    def _colorspace(self) -> str:
        return self.albedo.colorspace


def bake(albedo_path: str | os.PathLike, out_dir: str | os.PathLike, model_path: str | os.PathLike,
         options: BakeOptions | None = None, colorspace: maps.ColorSpace = "auto",
         progress: Callable[[float], None] | None = None) -> BakeResult:
    """Read ``albedo_path``, bake its maps into ``out_dir`` (stem = the image's file stem) and return what
    was written.  An up-to-date bake in ``out_dir`` is returned as it is (``reused``) without reading the
    image.  Errors: FileNotFoundError / maps.ImageError for the image, inference.ModelError for the model,
    BakeError for targets / folder / existing files; nothing is written on error."""
    options = options or BakeOptions()
    t0 = time.perf_counter()
    parse_targets(options.targets)
    if colorspace not in ("auto", "srgb", "linear"):
        raise ValueError(f"colorspace must be auto, srgb or linear, not {colorspace!r}")
    path = Path(albedo_path)
    if not path.is_file():
        raise FileNotFoundError(f"albedo image not found: {path}")
    model = inference.ModelFile(model_path, threads=options.threads)
    image_id = f"file:{maps.sha256_file(path)}:{colorspace}"
    if not options.force:
        key = bake_key(image_id, model.sha256, path.stem, options, mask_sha256(options.texel_mask))
        found = find_up_to_date(out_dir, path.stem, key)
        if found is not None:
            found.timings_s = {"total": time.perf_counter() - t0}
            return found
    maps.set_threads(_threads(options.threads))
    albedo = maps.read_albedo_indexed(path, colorspace=colorspace)
    t1 = time.perf_counter()
    job = BakeJob(albedo, out_dir, path.stem, model, options, input_image=str(path), image_id=image_id)
    for fraction in job.steps():
        if progress is not None:
            progress(fraction)
    return job.finish({"read_albedo": t1 - t0, "total": time.perf_counter() - t0})
