"""Bake an albedo texture into the maps of SPEC §4 (bpy-free core of bake.py and of the Blender operator).

Pipeline per band of image rows (memory bounded: a band holds at most ``band_texels`` texels, an
inference chunk at most ``chunk`` distinct texels): distinct colours (exporters.inference.unique_rows) ->
onnxruntime (skin_inversion.onnx) -> collapse to Cycles' three channels (exporters.collapse) -> the rows
of every map, streamed to temporary EXR files beside their final names.  Only when every texel is done
are the maps moved into place (all or none), then ``S_maps.json`` is written.  Cancelling or any error
leaves the output folder as it was.

:class:`BakeJob` runs step by step (one inference chunk per step) so that Blender can drive it from a
timer with a progress bar; :func:`bake` runs it to the end.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from exporters import collapse, inference, maps, reflectance_tables

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


class BakeError(ValueError):
    """Bad input for a bake (targets, output folder, existing files); the message says what to do."""


@dataclass(frozen=True)
class MapSpec:
    """One output file: its name, kind (key of UNITS), component k (1-based, 0 for spectral), channels."""

    name: str
    kind: str
    k: int
    channels: tuple[str, ...]
    target: str


def parse_targets(text: str | list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """'cycles,physical' -> ('cycles', 'physical'); BakeError naming unknown targets."""
    items = [t.strip() for t in (text.split(",") if isinstance(text, str) else text) if t.strip()]
    bad = [t for t in items if t not in TARGETS]
    if bad or not items:
        raise BakeError(f"unknown target(s) {bad or items!r}; use a comma-separated subset of {','.join(TARGETS)}")
    return tuple(dict.fromkeys(items))


def map_specs(stem: str, k_count: int, targets: tuple[str, ...]) -> list[MapSpec]:
    """Every file a bake writes (SPEC §4 names), in a fixed order; the weight map is shared by the cycles
    and physical targets (it is the same array)."""
    rgb, one = maps.RGB_CHANNELS, maps.SINGLE_CHANNEL
    specs: dict[str, MapSpec] = {}
    for target in targets:
        if target == "spectral":
            specs[f"{stem}_biophysical.exr"] = MapSpec(f"{stem}_biophysical.exr", "biophysical", 0,
                                                       maps.BIOPHYSICAL_CHANNELS, target)
            continue
        kinds = (("color", rgb), ("radius", rgb), ("weight", rgb), ("anisotropy", one)) if target == "cycles" else \
            (("alpha", rgb), ("sigma_t", rgb), ("g", rgb), ("weight", rgb))
        for k in range(1, k_count + 1):
            for kind, channels in kinds:
                name = f"{stem}_k{k}_{kind}.exr"
                specs.setdefault(name, MapSpec(name, kind, k, channels, target))
    return list(specs.values())


@dataclass
class BakeOptions:
    """``targets`` of SPEC §4; ``unit_scale_m`` metres per Blender unit; ``threads`` for onnxruntime (0 =
    all cores); ``memory_mb`` budget of one inference chunk; ``chunk`` caps distinct texels per step
    (None: from the budget); ``match_exposure`` scales the target colour by the model's exposure (shows
    the painted brightness instead of the model's reflectance); ``ior``: the IOR the node group's closures
    use (its IOR input; it sets how view rays enter the medium, see exporters.reflectance_tables);
    ``min_mfp_m``: smallest mean free path given to Cycles, metres (exporters.collapse step 7);
    ``overwrite`` replaces existing files."""

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


@dataclass
class BakeResult:
    """What a finished bake wrote: ``files`` (paths in order), ``json_path``, K, notes for the user, the
    counts of collapse clamps (texels x components x channels), and timings in seconds."""

    out_dir: Path
    stem: str
    files: list[Path]
    json_path: Path
    k: int
    notes: list[str]
    stats: dict[str, int]
    timings_s: dict[str, float] = field(default_factory=dict)


def input_notes(albedo: maps.AlbedoImage) -> list[str]:
    """Remarks on valid but special inputs (shown to the user and stored in S_maps.json)."""
    notes = []
    if albedo.n_channels in (1, 2):
        notes.append("grayscale image: its gray value is used for R, G and B")
    if albedo.alpha is not None:
        notes.append("alpha channel ignored: the albedo is taken from the colour channels")
    if albedo.n_clamped:
        notes.append(f"{albedo.n_clamped} texel(s) with negative values clamped to 0")
    above = int(np.count_nonzero((albedo.rgb > 1.0).any(axis=-1)))
    if above:
        notes.append(f"{above} texel(s) above 1 (not a valid albedo) are treated as 1 by the model")
    h, w = albedo.rgb.shape[:2]
    if h * w == 1:
        notes.append("1 x 1 image: the maps are uniform")
    return notes


class BakeJob:
    """A bake in steps.  Construction checks everything that can be checked cheaply (targets, folder,
    existing names, unit scale); :meth:`steps` does the work and yields the fraction done; :meth:`finish`
    publishes the files; :meth:`cancel` (or any exception in a step) removes every temporary file."""

    def __init__(self, albedo: maps.AlbedoImage, out_dir: str | os.PathLike, stem: str,
                 model: inference.SkinModel, options: BakeOptions | None = None, input_image: str = "") -> None:
        self.options = options or BakeOptions()
        opts = self.options
        self.targets = parse_targets(opts.targets)
        if not (np.isfinite(opts.unit_scale_m) and opts.unit_scale_m > 0):
            raise BakeError(f"unit scale must be a positive number of metres per Blender unit, got {opts.unit_scale_m}")
        if not reflectance_tables.IOR_MIN <= opts.ior <= reflectance_tables.IOR_MAX:
            raise BakeError(f"IOR must lie in [{reflectance_tables.IOR_MIN}, {reflectance_tables.IOR_MAX}] "
                            f"(Cycles' range), got {opts.ior}")
        if not stem or os.sep in stem or (os.altsep and os.altsep in stem):
            raise BakeError(f"invalid map name stem {stem!r}")
        rgb = np.asarray(albedo.rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.shape[0] < 1 or rgb.shape[1] < 1:
            raise BakeError(f"albedo must be an (H, W, 3) image, got shape {rgb.shape}")
        if not np.all(np.isfinite(rgb)):
            raise BakeError("albedo has NaN/Inf texels; fix the texture")
        if np.any(rgb < 0):
            raise BakeError("albedo has negative texels; an albedo cannot be negative")
        self.albedo, self.model, self.stem = albedo, model, stem
        self.out_dir = Path(out_dir)
        self.input_image = input_image
        self.height, self.width = rgb.shape[:2]
        self.specs = map_specs(stem, model.k, self.targets)
        self._check_folder()
        self.chunk = opts.chunk or inference.chunk_rows(model, opts.memory_mb)
        self.band_rows = max(1, min(self.height, max(opts.band_texels, self.chunk) // self.width))
        self.notes = input_notes(albedo)
        self.stats = {"texels": self.height * self.width, "distinct_texels": 0, "alpha_raised_to_0.2": 0,
                      "weight_raised": 0, "unreachable_channels": 0, "sigma_t_capped": 0}
        self.timings = {"inference": 0.0, "collapse": 0.0, "write": 0.0}
        self._streams: list[maps.MapStream] | None = None
        self._done = False

    def _check_folder(self) -> None:
        if not self.out_dir.is_dir():
            raise BakeError(f"output folder does not exist: {self.out_dir}")
        if not os.access(self.out_dir, os.W_OK | os.X_OK):
            raise BakeError(f"output folder is not writable: {self.out_dir}")
        if not self.options.overwrite:
            names = [s.name for s in self.specs] + [f"{self.stem}_maps.json"]
            taken = [n for n in names if (self.out_dir / n).exists()]
            if taken:
                raise BakeError(f"{len(taken)} file(s) exist in {self.out_dir} (e.g. {taken[0]}); choose another "
                                "folder or allow overwriting (--overwrite)")

    @property
    def json_path(self) -> Path:
        return self.out_dir / f"{self.stem}_maps.json"

    def _open(self) -> list[maps.MapStream]:
        streams = []
        try:
            for spec in self.specs:
                streams.append(maps.MapStream(self.out_dir / spec.name, self.width, self.height, spec.channels,
                                              self._units(spec), overwrite=self.options.overwrite))
        except BaseException:
            for s in streams:
                s.discard()
            raise
        return streams

    def _units(self, spec: MapSpec) -> str:
        if spec.kind == "radius":
            return f"{UNITS['radius']}; 1 BU = {self.options.unit_scale_m:g} m"
        return UNITS[spec.kind]

    def steps(self) -> Iterator[float]:
        """Do the work; yields the fraction of texels done (0..1] after each inference chunk."""
        if self._streams is not None or self._done:
            raise RuntimeError("a BakeJob runs once")
        self._streams = self._open()
        try:
            yield from self._bands()
        except BaseException:
            self.cancel()
            raise

    def _bands(self) -> Iterator[float]:
        total = self.height * self.width
        for y0 in range(0, self.height, self.band_rows):
            y1 = min(self.height, y0 + self.band_rows)
            band = np.asarray(self.albedo.rgb[y0:y1], dtype=np.float32).reshape(-1, 3)
            uniq, inverse = inference.unique_rows(band)
            counts = np.bincount(inverse, minlength=len(uniq))
            self.stats["distinct_texels"] += len(uniq)
            values = {spec.name: np.empty((len(uniq), len(spec.channels)), np.float32) for spec in self.specs}
            for start in range(0, len(uniq), self.chunk):
                sl = slice(start, min(start + self.chunk, len(uniq)))
                self._chunk(uniq[sl], sl, values, counts[sl])
                yield (y0 * self.width + band.shape[0] * sl.stop / len(uniq)) / total
            t0 = time.perf_counter()
            for spec, stream in zip(self.specs, self._streams, strict=True):
                stream.write_rows(values[spec.name][inverse].reshape(y1 - y0, self.width, -1))
            self.timings["write"] += time.perf_counter() - t0

    def _chunk(self, rgb: np.ndarray, sl: slice, values: dict[str, np.ndarray], counts: np.ndarray) -> None:
        t0 = time.perf_counter()
        out = self.model.run(rgb)
        t1 = time.perf_counter()
        scale = out["exposure"][:, 0] if self.options.match_exposure else None
        media = collapse.collapse(out["reflectance"], out["alpha"], out["sigma_t"], out["g"], out["weight"],
                                  target_scale=scale, ior=self.options.ior,
                                  min_mfp_cm=self.options.min_mfp_m * 100.0)
        cyc = collapse.to_cycles(media, self.options.unit_scale_m) if "cycles" in self.targets else None
        self.stats["alpha_raised_to_0.2"] += int((media.low.sum(axis=(1, 2)) * counts).sum())
        self.stats["weight_raised"] += int((media.high.sum(axis=(1, 2)) * counts).sum())
        self.stats["unreachable_channels"] += int((media.unreachable.sum(axis=1) * counts).sum())
        self.stats["sigma_t_capped"] += int((media.mfp_capped.sum(axis=(1, 2)) * counts).sum())
        for spec in self.specs:
            values[spec.name][sl] = self._values(spec, media, cyc, out)
        self.timings["inference"] += t1 - t0
        self.timings["collapse"] += time.perf_counter() - t1

    @staticmethod
    def _values(spec: MapSpec, media: collapse.ChannelMedia, cyc: collapse.CyclesMaps | None,
                out: dict[str, np.ndarray]) -> np.ndarray:
        i = spec.k - 1
        if spec.kind == "biophysical":
            return np.concatenate([out["biophysical"], out["exposure"]], axis=1)
        if spec.kind == "weight":
            return media.weight[:, i]
        if spec.kind == "alpha":
            return media.alpha[:, i]
        if spec.kind == "sigma_t":
            return media.sigma_t_cm[:, i]
        if spec.kind == "g":
            return np.repeat(media.g[:, i, None], 3, axis=1)
        if spec.kind == "anisotropy":
            return cyc.anisotropy[:, i, None]
        return {"color": cyc.color, "radius": cyc.radius}[spec.kind][:, i]

    def cancel(self) -> None:
        """Stop and remove every temporary file; the output folder is left as it was."""
        for s in self._streams or []:
            s.discard()
        self._streams = []
        self._done = True

    def finish(self, extra_timings: dict[str, float] | None = None) -> BakeResult:
        """Publish the maps (all or none) and write S_maps.json; call after :meth:`steps` is exhausted."""
        if self._streams is None or self._done:
            raise RuntimeError("finish() needs a completed, not cancelled, run of steps()")
        t0 = time.perf_counter()
        try:
            files = maps.publish_maps(self._streams)
        finally:
            self._done = True
        self.timings["write"] += time.perf_counter() - t0
        timings = {**self.timings, **(extra_timings or {})}
        try:
            json_path = self._write_json(timings)
        except BaseException:
            for f in files:
                if not self.options.overwrite:
                    f.unlink(missing_ok=True)
            raise
        return BakeResult(out_dir=self.out_dir, stem=self.stem, files=files, json_path=json_path, k=self.model.k,
                          notes=list(self.notes), stats=dict(self.stats), timings_s=timings)

    def _write_json(self, timings: dict[str, float]) -> Path:
        files = {s.name: {"units": self._units(s), "channels": list(s.channels), "target": s.target,
                          "component": s.k or None, "kind": s.kind, "colorspace": "Non-Color"} for s in self.specs}
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
            "model": {"path": str(self.model.path), "K": self.model.k},
            "notes": self.notes,
            "stats": self.stats,
        }
        sha = {self.model.path.name: self.model.sha256}
        return maps.write_maps_json(self.json_path, files, self.model.k, sha, self.input_image,
                                    self.albedo.colorspace, timings, unit_scale_m=self.options.unit_scale_m,
                                    overwrite=self.options.overwrite, extra=extra)


def bake(albedo_path: str | os.PathLike, out_dir: str | os.PathLike, model_path: str | os.PathLike,
         options: BakeOptions | None = None, colorspace: maps.ColorSpace = "auto",
         progress: Callable[[float], None] | None = None) -> BakeResult:
    """Read ``albedo_path``, bake its maps into ``out_dir`` (stem = the image's file stem) and return what
    was written.  Errors: FileNotFoundError / maps.ImageError for the image, inference.ModelError for the
    model, BakeError for targets / folder / existing files; nothing is written on error."""
    options = options or BakeOptions()
    t0 = time.perf_counter()
    parse_targets(options.targets)
    albedo = maps.read_albedo(albedo_path, colorspace=colorspace)
    t1 = time.perf_counter()
    model = inference.load_model(model_path, threads=options.threads)
    t2 = time.perf_counter()
    job = BakeJob(albedo, out_dir, Path(albedo_path).stem, model, options, input_image=str(albedo_path))
    for fraction in job.steps():
        if progress is not None:
            progress(fraction)
    return job.finish({"read_albedo": t1 - t0, "load_model": t2 - t1, "total": time.perf_counter() - t0})
