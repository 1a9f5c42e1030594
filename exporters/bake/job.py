"""The bake as a job run in steps (so that Blender can drive it from a timer with a progress bar), and
:func:`bake`, which runs one to the end.

Steps: a fast-path table built first if the options need one and the image pays for it; every distinct
colour evaluated (exporters.bake.evaluate) unless they are too many to hold, in which case each band of rows
evaluates its own; components below the prune share dropped; the maps gathered band by band and written
to temporary EXR files, one map per thread; :meth:`BakeJob.finish` publishes them all (or none) and writes
``S_maps.json``.  Cancelling or any error leaves the output folder as it was.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from .. import image_input, inference, maps, texel_records
from . import edits, masking, material_files, report, reuse
from .evaluate import Evaluator
from .options import FAST_MANTISSA_BITS, BakeOptions
from .report import BakeResult
from .table_cache import find_table
from .targets import HALF_KINDS, BakeError, MapSpec, map_specs, units_of

#: Bytes per texel of one band of rows: its palette ids and their distinct set (24 B), the map rows of its
#: distinct colours (4 B per channel, 120 B for K = 3 cycles maps) and each map's gathered rows, rounded up.
BAND_TEXEL_BYTES = 512
#: ``memory_mb`` is split in this many equal shares: the map rows held (a band's, or every colour's), one table
#: step, one inference chunk, and the decoded image's index with the rest.
WORK_SHARES = 4


class BakeJob:
    """A bake in steps.  Construction checks everything that can be checked cheaply (targets, folder,
    existing names, unit scale) and finds an up-to-date bake; :meth:`steps` does the work and yields the
    fraction done; :meth:`finish` publishes the files; :meth:`cancel` (or any exception in a step) removes
    every temporary file.

    ``albedo``: a dense :class:`exporters.image_input.AlbedoImage` or an
    :class:`exporters.image_input.IndexedAlbedo`;
    ``model``: a loaded :class:`exporters.inference.InversionSession` or an :class:`exporters.inference.ModelFile`
    (loaded only if some colour must be evaluated exactly); ``image_id``: what identifies the image content
    in the bake key (default: a hash of its decoded colours).
    """

    def __init__(self, albedo: image_input.AlbedoImage | image_input.IndexedAlbedo, out_dir: str | os.PathLike,
                 stem: str, model: inference.InversionSession | inference.ModelFile, options: BakeOptions | None = None,
                 input_image: str = "", image_id: str | None = None) -> None:
        self.options = opts = options or BakeOptions()
        self.targets = opts.check()
        if not stem or os.sep in stem or (os.altsep and os.altsep in stem):
            raise BakeError(f"invalid map name stem {stem!r}")
        image = masking.indexed(albedo)
        self.stem, self.input_image, self.albedo_colorspace = stem, input_image, image.colorspace
        self.out_dir = Path(out_dir)
        self.height, self.width = image.shape
        self.model = model if isinstance(model, inference.ModelFile) else inference.ModelFile.of(model)
        self.notes = report.input_notes(image)
        self.timings = {"load_model": 0.0, "evaluate": 0.0, "inference": 0.0, "table": 0.0, "write": 0.0}
        self.key = reuse.job_key(image_id or reuse.pixels_id(image), self.model.sha256, stem, opts, image.shape)
        self.reused = None if opts.force else reuse.find_up_to_date(self.out_dir, stem, self.key)
        self._streams: list[maps.MapStream] | None = None
        self._done = False
        if self.reused is not None:
            self.specs, self.components = [], list(self.reused.components)
            return
        self._set_up(image)

    def _set_up(self, image: image_input.IndexedAlbedo) -> None:
        opts = self.options
        if self.writes_material:
            material_files.require()  # before any work: a Python without the libraries says so in one line
        uncovered = 0
        if opts.texel_mask is not None:
            self.palette, self.index, uncovered = masking.apply_mask(image, np.asarray(opts.texel_mask, bool))
        else:
            self.palette, self.index = image.palette, image.index
        self.palette_edits = None
        if opts.edited:
            self.palette, self.index, self.palette_edits = edits.edited_palette(self.palette, self.index, opts.edit,
                                                                                opts.edit_masks)
        self.counts = np.bincount(self.index.ravel(), minlength=len(self.palette))
        if uncovered:
            self.notes.append(f"{uncovered} texel(s) not covered by the mesh's UVs were not evaluated: they hold the "
                              "maps of the most common covered colour")
        self.stats: dict[str, int] = {"texels": self.height * self.width, "distinct_texels": len(self.palette),
                                      "texels_not_covered_by_uvs": uncovered}
        if texel_records.needs_media(self.targets):
            self.stats.update({name: 0 for name in texel_records.STAT_NAMES.values()})
        copts = opts.collapse_options()
        self.threads = maps.threads_of(opts.threads)
        table = None if opts.exact else find_table(self.model, copts, opts.table_path, self.notes, opts.cache_step)
        self._build_table = (table is None and not opts.exact and opts.cache_tables
                             and len(self.palette) >= opts.cache_min_colours)
        if table is None and not opts.exact and not self._build_table:
            self.notes.append("no fast-path table for this model and these options: every distinct colour evaluated "
                              f"exactly (python -m training texel-table --model {self.model.path} builds one; "
                              f"images with {opts.cache_min_colours:,}+ colours build and cache one themselves)")
        # the budget is shared by what lives at once: the map rows of a band or of every colour, one table
        # step's records, one inference chunk (and the decoded image's index, counted when it was read)
        share_mb = opts.memory_mb / WORK_SHARES
        self.evaluator = Evaluator(self.palette, self.targets, self.model, table, copts, self.threads, self.timings,
                                   chunk=opts.chunk, memory_mb=share_mb, edits=self.palette_edits)
        self.model_k = self.evaluator.model_k
        if opts.edited and table is not None and self.evaluator.edit_table() is None:
            self.notes.append("no edit table made from this model and table beside the model: edited texels are "
                              "evaluated exactly (python -m training edit-table builds one)")
        self.components = list(range(1, self.model_k + 1))
        self.specs = map_specs(self.stem, self.model_k, self.targets)
        self._check_folder()
        share = share_mb * 2**20
        band_texels = int(max(1, min(opts.band_texels, share // BAND_TEXEL_BYTES)))
        self.band_rows = max(1, min(self.height, band_texels // self.width or 1))
        channels = sum(len(s.channels) for s in self.specs)
        self.global_values = len(self.palette) * channels * 4 <= share
        self.values: dict[str, np.ndarray] = {}
        self.pixel_types: dict[str, str] = {}

    # -- set-up -----------------------------------------------------------------------------------------------
    @staticmethod
    def index(albedo) -> image_input.IndexedAlbedo:
        """An albedo image as an :class:`exporters.image_input.IndexedAlbedo`, checked (exporters.bake.masking)."""
        return masking.indexed(albedo)

    def _check_folder(self) -> None:
        maps.check_output_folder(self.out_dir)
        if not self.options.overwrite:
            names = [s.name for s in self.specs] + [f"{self.stem}_maps.json"] + self.material_names
            taken = [n for n in names if (self.out_dir / n).exists()]
            if taken:
                raise BakeError(f"{len(taken)} file(s) exist in {self.out_dir} (e.g. {taken[0]}) from another bake; "
                                "choose another folder or allow overwriting (--overwrite)")

    @property
    def writes_material(self) -> bool:
        """Whether this bake writes the openpbr target's MaterialX and USD files."""
        return "openpbr" in self.targets and self.options.write_material

    @property
    def material_names(self) -> list[str]:
        """File names of the material files this bake writes (none without them)."""
        if not self.writes_material:
            return []
        names = material_files.material_names(self.options.material_stem or self.stem)
        return [names.mtlx, names.usda]

    @property
    def json_path(self) -> Path:
        return self.out_dir / f"{self.stem}_maps.json"

    @property
    def k(self) -> int:
        """Components written (the model's K less dropped ones)."""
        return len(self.components)

    @property
    def mantissa_bits(self) -> int:
        """Mantissa bits the maps keep: the option, else 16 when the table is used (also one built by this bake)
        and 23 for exact bakes."""
        return self.options.mantissa_bits or (FAST_MANTISSA_BITS if self.evaluator.table is not None else 23)

    @property
    def half_maps(self) -> bool:
        """Whether the maps of ``HALF_KINDS`` are half floats: the option, else when the table is used."""
        return self.options.half_maps if self.options.half_maps is not None else self.evaluator.table is not None

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
            yield from (pre * f for f in self.evaluator.make_table(self.options.cache_step, self.notes))
        for f in self._work():
            yield pre + (1.0 - pre) * f

    def _evaluate(self, ids, counts, into, progress) -> Iterator[float]:
        return self.evaluator.evaluate(ids, counts, self.specs, into, self.options.unit_scale_m, self.mantissa_bits,
                                       progress)

    def _work(self) -> Iterator[float]:
        share_eval = 0.15 if self.evaluator.table is not None else 0.6
        if self.global_values:
            yield from self._evaluate(np.arange(len(self.palette)), self.counts, self.values, lambda f: share_eval * f)
            self._prune()
        self._streams = self._open()
        try:
            yield from self._bands(share_eval)
        except BaseException:
            self.cancel()
            raise

    def _prune(self) -> None:
        """Drop components whose share of the colour is below ``prune_share`` for every texel (global mode)."""
        share, max_share = self.options.prune_share, self.evaluator.max_share
        if share <= 0 or not texel_records.needs_media(self.targets) or self.model_k < 2:
            return
        keep = [k for k in range(1, self.model_k + 1) if max_share[k - 1] >= share]
        if not keep:
            keep = [int(np.argmax(max_share)) + 1]
        if len(keep) == self.model_k:
            return
        dropped = [k for k in range(1, self.model_k + 1) if k not in keep]
        old = {(s.kind, s.source_k): s.name for s in self.specs}
        self.components = keep
        self.specs = map_specs(self.stem, self.model_k, self.targets, keep)
        self.values = {s.name: self.values[old[(s.kind, s.source_k)]] for s in self.specs}
        self.notes.append(f"component(s) {dropped} of the model dropped: below {100 * share:g} % of the colour at "
                          f"every texel (largest share {100 * float(max_share[np.array(dropped) - 1].max()):.3g} "
                          f"%); maps numbered k1..k{len(keep)}")

    def _pixel_type(self, spec: MapSpec) -> str:
        """half for the bounded kinds (HALF_KINDS) and, when every radius of the bake is known and lies in half's
        normal range, for the radius (relative rounding <= 2^-11 = 4.9e-4, 1/70 of the table's radius error,
        measured 3.4e-2 at most on skin textures); float for everything else, and without ``half_maps``."""
        if not self.half_maps:
            return "float"
        if spec.kind in HALF_KINDS:
            return "half"
        fits = spec.kind == "radius" and self.global_values and maps.fits_half(self.values[spec.name])
        return "half" if fits else "float"

    def _open(self) -> list[maps.MapStream]:
        self.pixel_types = {spec.name: self._pixel_type(spec) for spec in self.specs}
        if self.global_values:  # rounded to half once per distinct colour, not per texel
            self.values = _as_written(self.values, self.pixel_types)
        streams = []
        try:
            for spec in self.specs:
                streams.append(maps.MapStream(self.out_dir / spec.name, self.width, self.height, spec.channels,
                                              units_of(spec, self.options.unit_scale_m),
                                              overwrite=self.options.overwrite, compression=self.options.compression,
                                              pixel_type=self.pixel_types[spec.name]))
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
                    yield from self._evaluate(uniq, np.bincount(rows, minlength=len(uniq)), values,
                                              lambda f, b=base, s=span: b + s * f)
                    values = _as_written(values, self.pixel_types)
                t0 = time.perf_counter()
                self._write_band(pool, values, rows, y1 - y0)
                self.timings["write"] += time.perf_counter() - t0
                yield (share_eval + (1.0 - share_eval) * y1 / self.height) if self.global_values else y1 / self.height
        finally:
            if pool is not None:
                pool.shutdown()

    def _write_band(self, pool: ThreadPoolExecutor | None, values: dict[str, np.ndarray], rows: np.ndarray,
                    height: int) -> None:
        """Gather each map's rows of one band through the index and hand them to its stream (one map per thread)."""
        def write(item: tuple[MapSpec, maps.MapStream]) -> None:
            spec, stream = item
            stream.write_rows(np.take(values[spec.name], rows, axis=0).reshape(height, self.width, -1), finite=True)

        items = list(zip(self.specs, self._streams, strict=True))
        if pool is None:
            for item in items:
                write(item)
        else:
            list(pool.map(write, items))

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
        try:
            files += self._write_material()
        except BaseException:
            for f in files:
                if not self.options.overwrite:
                    f.unlink(missing_ok=True)
            raise
        self.timings["write"] += time.perf_counter() - t0
        timings = {**self.timings, **(extra_timings or {})}
        self.stats.update(self.evaluator.stats)
        self.stats.update(self.evaluator.counted)
        self.notes.extend(report.clamp_warnings(self.stats, self.height * self.width))
        try:
            json_path = report.write_record(self, timings, files, {f.name: reuse.file_state(f) for f in files})
        except BaseException:
            for f in files:
                if not self.options.overwrite:
                    f.unlink(missing_ok=True)
            raise
        return BakeResult(out_dir=self.out_dir, stem=self.stem, files=files, json_path=json_path, k=self.k,
                          notes=list(self.notes), stats=dict(self.stats), timings_s=timings,
                          components=list(self.components))


    def _write_material(self) -> list[Path]:
        """The openpbr target's MaterialX document and USD layer (exporters.bake.material_files), or nothing."""
        if not self.writes_material:
            return []
        opts = self.options
        return material_files.write_material(self.out_dir, self.specs, opts.material_stem or self.stem,
                                             opts.unit_scale_m, opts.overwrite, ior=opts.ior,
                                             map_stem=opts.material_maps_stem)


def _as_written(values: dict[str, np.ndarray], pixel_types: dict[str, str]) -> dict[str, np.ndarray]:
    """Map rows as the files store them: float16 for half maps (bounded values: no overflow), else as they are."""
    return {name: v.astype(np.float16) if pixel_types[name] == "half" else v for name, v in values.items()}


def bake(albedo_path: str | os.PathLike, out_dir: str | os.PathLike, model_path: str | os.PathLike,
         options: BakeOptions | None = None, colorspace: image_input.ColorSpace = "auto",
         progress: Callable[[float], None] | None = None) -> BakeResult:
    """Read ``albedo_path``, bake its maps into ``out_dir`` (stem = the image's file stem) and return what
    was written.  An up-to-date bake in ``out_dir`` is returned as it is (``reused``) without reading the
    image.  Errors: FileNotFoundError / image_input.ImageError for the image, inference.ModelError for the
    model, the OSErrors of exporters.maps.check_output_folder for the folder, BakeError for targets / existing
    files; nothing is written on error."""
    options = options or BakeOptions()
    t0 = time.perf_counter()
    options.check()
    image_input.check_colorspace(colorspace)
    path = Path(albedo_path)
    if not path.is_file():
        raise FileNotFoundError(f"albedo image not found: {path}")
    model = inference.ModelFile(model_path, threads=options.threads)
    image_id = reuse.file_id(path, colorspace)
    if not options.force:
        found = reuse.find_up_to_date(out_dir, path.stem, reuse.job_key(image_id, model.sha256, path.stem, options))
        if found is not None:
            found.timings_s = {"total": time.perf_counter() - t0}
            return found
    maps.set_threads(options.threads)
    albedo = image_input.read_albedo_indexed(path, colorspace=colorspace, memory_mb=options.memory_mb)
    t1 = time.perf_counter()
    job = BakeJob(albedo, out_dir, path.stem, model, options, input_image=str(path), image_id=image_id)
    for fraction in job.steps():
        if progress is not None:
            progress(fraction)
    return job.finish({"read_albedo": t1 - t0, "total": time.perf_counter() - t0})
