"""Bake an albedo texture into the maps of docs/contracts.md §4 (bpy-free core of bake.py and of the Blender operator).

Pipeline.  Every value a bake writes depends on the texel's colour only, so:

1. **Distinct colours** (exporters.palette, :mod:`exporters.bake.masking`): the image becomes a palette and a
   per-texel index; with a UV coverage mask (``BakeOptions.texel_mask``, from the mesh) texels no face covers
   take the most common covered colour, so their colours are never evaluated.
2. **Records per distinct colour** (:mod:`exporters.bake.evaluate`, exporters.texel_records): by default from
   the fast-path table (exporters.texel_table: trilinear interpolation over skin colours, made from this very
   model — its SHA-256 is checked, :mod:`exporters.bake.table_cache`; colours outside its domain get the
   nearest skin colour's values, as the live group gives them: exporters.live_table), or all exactly
   (``exact=True``, or no table for the options: onnxruntime + the collapse).  Only what the targets need is
   computed (``spectral`` alone skips the collapse).  By default the maps render the painted albedo
   (exporters.painted); ``model_colour`` renders the model's own reflectance.
3. **Components** whose share of the rendered colour stays below ``prune_share`` for every texel are
   dropped (the remaining ones are numbered k1..kK').
4. **Maps**, band by band (:mod:`exporters.bake.job`): each map's rows gathered through the index and written
   to temporary EXR files beside their final names, one map per thread, OpenEXR compressing on the same
   threads.  Only when every band is done are the maps moved into place (all or none), then ``S_maps.json``
   is written (:mod:`exporters.bake.report`).  Cancelling or any error leaves the output folder as it was.

Skin edits (exporters.skin_edits, :mod:`exporters.bake.edits`): ``BakeOptions.edit`` and ``edit_masks`` change the
tone of every texel, or of the texels a mask paints; the distinct entries are then (colour, edit) pairs, neutral
ones evaluated as without edits, edited ones from the edit table (exporters.edit_table, as the live group) or, with
``exact``, by the network and the decoder.

A bake that is already up to date (:mod:`exporters.bake.reuse`) — ``S_maps.json`` in the folder records the
same key (image content, model SHA-256, options) and every map it lists is unchanged — is reused: nothing is
read, loaded, evaluated or written (``force=True`` re-bakes).

Memory: ``memory_mb`` bounds the bake's working arrays whatever the texture.  It is split in equal shares
(:data:`exporters.bake.job.WORK_SHARES`): the map rows held (every distinct colour's, or one band's), one table step
(:func:`exporters.bake.evaluate.table_rows_for`), one inference chunk (exact bakes evaluate
that many colours at a time) and the decoded image, whose header is checked against the whole budget before decoding
(:func:`exporters.image_input.check_decode_budget`).  When the distinct colours' map rows exceed their share
(e.g. a noisy image), step 2 runs per band instead and step 3 is skipped.  Fixed costs (the libraries, the model
session, the fast-path table) and OpenEXR's per-thread write buffers are not counted.

:class:`BakeJob` runs step by step (one chunk per step) so that Blender can drive it from a timer with a
progress bar; :func:`bake` runs it to the end.  What to ask for: :class:`BakeOptions`
(:mod:`exporters.bake.options`); what is written: :mod:`exporters.bake.targets`.
"""

from .job import BakeJob, bake
from .material_files import udim_tile_options
from .options import DEFAULT_BAND_TEXELS, DEFAULT_PRUNE_SHARE, FAST_MANTISSA_BITS, BakeOptions
from .report import BakeResult, input_notes, one_line
from .reuse import KEY_VERSION, bake_key, file_id, find_up_to_date, job_key, mask_sha256, pixels_id
from .table_cache import cached_table_path, default_table_path, find_table, table_cache_dir
from .targets import HALF_KINDS, TARGETS, UNITS, BakeError, MapSpec, map_specs, parse_targets

__all__ = ["DEFAULT_BAND_TEXELS", "DEFAULT_PRUNE_SHARE", "FAST_MANTISSA_BITS", "HALF_KINDS", "KEY_VERSION", "TARGETS",
           "UNITS", "BakeError", "BakeJob", "BakeOptions", "BakeResult", "MapSpec", "bake", "bake_key",
           "cached_table_path", "default_table_path", "file_id", "find_table", "find_up_to_date", "input_notes",
           "job_key", "map_specs", "mask_sha256", "one_line", "parse_targets", "pixels_id", "table_cache_dir",
           "udim_tile_options"]
