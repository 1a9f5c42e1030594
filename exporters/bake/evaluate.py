"""Records per distinct colour: from the fast-path table (colours outside its domain get the nearest skin
colour's media, exactly as the live group answers: exporters.live_table), or, without a table, by the model and
the collapse (exporters.texel_records), in chunks; the map rows made from them; the statistics of what was done."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import numpy as np

from .. import edit_table, inference, live_table, maps, skin_edits, texel_records, texel_table
from ..texel_records import CollapseOptions
from .table_cache import cached_table_path
from .targets import BakeError, MapSpec

#: Most distinct colours looked up in the fast-path table per step (the UI stays responsive: ~0.1 s each).
TABLE_CHUNK = 1 << 18
#: Bytes per distinct colour of one table step: the interpolated values (184 B for K = 3), their records
#: (376 B) and the map rows (120 B), measured for K = 3, and for a colour outside the table the nearest-colour
#: lookup's float64 arrays (~1.2 kB at their peak, counted from live_table.lookup's arrays for the table's 46
#: channels); rounded up: a step holds no more rows than the memory budget pays for at this rate.
TABLE_ROW_BYTES = 2048


def table_rows_for(memory_mb: float) -> int:
    """Distinct colours per table step within ``memory_mb`` MiB (at most ``TABLE_CHUNK``, at least 1)."""
    return int(max(1, min(TABLE_CHUNK, memory_mb * 2**20 // TABLE_ROW_BYTES)))


class Evaluator:
    """Evaluates distinct colours of ``palette`` (n, 3) linear sRGB for ``targets``: ``table`` (or None: every
    colour exactly), ``model`` (loaded only when a colour must be evaluated exactly), ``options`` of the
    collapse, ``threads`` for the table lookups, ``chunk`` rows per exact step.  Accumulates ``timings``
    (seconds), ``stats`` (clamp counts over texels), ``counted`` (texels from the table, outside its domain
    and answered by the nearest skin colour, or evaluated exactly) and
    ``max_share`` (K,): each component's largest share of the colour over every texel evaluated.  K comes
    from the table, else from the model (then loaded here)."""

    def __init__(self, palette: np.ndarray, targets: tuple[str, ...], model: inference.ModelFile,
                 table: texel_table.TexelTable | None, options: CollapseOptions, threads: int,
                 timings: dict[str, float], chunk: int | None = None,
                 memory_mb: float = inference.DEFAULT_MEMORY_MB, edits: np.ndarray | None = None) -> None:
        self.palette, self.targets, self.model, self.table = palette, targets, model, table
        self.edits = edits
        self._edit_table: edit_table.EditTable | None = None
        self.options, self.threads, self.timings = options, threads, timings
        self.model_k = table.k if table is not None else self.load_model().k
        self.chunk = chunk or inference.chunk_rows_for_k(self.model_k, memory_mb)
        self.table_step = table_rows_for(memory_mb)
        self.stats: dict[str, int] = {}
        self.counted = {"texels_from_table": 0, "texels_outside_table": 0, "texels_evaluated_exactly": 0}
        self._extended: np.ndarray | None = None
        self.max_share = np.zeros(self.model_k)

    def load_model(self) -> inference.InversionSession:
        if not self.model.loaded:
            t0 = time.perf_counter()
            self.model.load()
            self.timings["load_model"] += time.perf_counter() - t0
        return self.model.load()

    def records(self, rgb: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Records of distinct colours ``rgb`` (n, 3) float32 (the table where it covers them, its nearest skin
        colour outside; without a table, exact) and which rows lie in the table's domain."""
        inside = np.zeros(len(rgb), bool)
        parts: dict[str, np.ndarray] | None = None
        if self.table is not None:
            t0 = time.perf_counter()
            inside, base, frac = self.table.locate(rgb)
            if inside.any():
                vals = self.table.interpolate(base, frac, self.threads)
                parts = self.table.records(rgb[inside], vals, self.targets)
            self.timings["table"] += time.perf_counter() - t0
        if inside.all():
            rec = parts if parts is not None else texel_records.empty_records(self.model_k, self.targets,
                                                                             self.options.painted)
            return rec, inside
        rest = self.exact_records(rgb) if self.table is None else self.nearest_records(rgb[~inside])
        if parts is None:
            return rest, inside
        rec = {}
        for key, value in parts.items():
            full = np.empty((len(rgb), *value.shape[1:]), value.dtype)
            full[inside], full[~inside] = value, rest[key]
            rec[key] = full
        return rec, inside

    def edited_records(self, rgb: np.ndarray, edits: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """:meth:`records` of colours ``rgb`` (n, 3) under edit rows ``edits`` (n, 3): neutral rows exactly as
        without edits; edited rows from the edit table (exporters.edit_table, as the live group) on the fast path,
        else by the network and the decoder (exporters.skin_edits)."""
        neutral = skin_edits.neutral_rows(edits)
        if neutral.all():
            return self.records(rgb)
        edited = ~neutral
        part, inside_n = self.records(rgb[neutral])
        t0 = time.perf_counter()
        table = self.edit_table() if self.table is not None else None
        if table is not None:
            if self._extended is None:
                self._extended = live_table.extended_values(self.table)
            rest = edit_table.approx_records(self.table, table, rgb[edited], edits[edited], self.targets,
                                             self._extended)
            self.timings["table"] += time.perf_counter() - t0
        else:
            model = self.load_model()
            decoder = skin_edits.decoder_beside(model.path)
            rest = texel_records.concat_records([
                skin_edits.edited_records(model, rgb[edited][s:s + self.chunk], edits[edited][s:s + self.chunk],
                                          self.targets, self.options, decoder)
                for s in range(0, int(edited.sum()), self.chunk)])
            self.timings["inference"] += time.perf_counter() - t0
        rec = {}
        for key in [k for k in rest if k in part or not neutral.any()]:
            full = np.empty((len(rgb), *rest[key].shape[1:]), rest[key].dtype)
            full[edited] = rest[key]
            if neutral.any():
                full[neutral] = part[key]
            rec[key] = full
        inside = np.zeros(len(rgb), bool)
        inside[neutral] = inside_n
        inside[edited] = table is not None
        return rec, inside

    def edit_table(self) -> edit_table.EditTable | None:
        """The edit table beside the model, made from it (else None: edited colours are evaluated exactly)."""
        if self._edit_table is None:
            path = edit_table.default_path(self.model.path)
            try:
                table = edit_table.load(path)
            except edit_table.EditTableError:
                return None
            if table.meta.get("model_sha256") != self.model.sha256 or \
                    table.meta.get("texel_table_sha256") != self.table.sha256:
                return None
            self._edit_table = table
        return self._edit_table

    def nearest_records(self, rgb: np.ndarray) -> dict[str, np.ndarray]:
        """Records of rows ``rgb`` (n, 3) outside the table's domain: the table at the colour projected onto its box,
        with the nodes outside the RGB cube extended from their skin neighbours (exporters.live_table: the values
        the live group's images hold, so a bake and the live group agree on every colour)."""
        t0 = time.perf_counter()
        if self._extended is None:
            self._extended = live_table.extended_values(self.table)
        values = live_table.lookup(self._extended, live_table.layout_of(self.table), rgb).astype(np.float32)
        rec = self.table.records(rgb, values, self.targets)
        self.timings["table"] += time.perf_counter() - t0
        return rec

    def exact_records(self, rgb: np.ndarray) -> dict[str, np.ndarray]:
        """Records of rows ``rgb`` (n, 3) float32 by the model, ``chunk`` rows per inference (the memory budget
        holds however many colours fall outside the table)."""
        if len(rgb) == 0:
            return texel_records.empty_records(self.model_k, self.targets, self.options.painted)
        model = self.load_model()
        t0 = time.perf_counter()
        pieces = [texel_records.exact_records(model, rgb[s:s + self.chunk], self.targets, self.options)
                  for s in range(0, len(rgb), self.chunk)]
        self.timings["inference"] += time.perf_counter() - t0
        if len(pieces) == 1:
            return pieces[0]
        return {key: np.concatenate([p[key] for p in pieces]) for key in pieces[0]}

    def values(self, rec: dict[str, np.ndarray], specs: list[MapSpec], unit_scale_m: float,
               mantissa_bits: int) -> dict[str, np.ndarray]:
        """Map rows (n, channels) float32 of ``specs`` from records, rounded to ``mantissa_bits``."""
        out = {}
        if any(spec.target == "openpbr" for spec in specs):
            texel_records.add_single_medium(rec, self.options.ior, unit_scale_m)
        for spec in specs:
            try:
                v = texel_records.map_values(spec.kind, spec.source_k or spec.k, rec, unit_scale_m)
            except ValueError as exc:
                raise BakeError(str(exc)) from None
            if not np.all(np.isfinite(v)):
                raise RuntimeError(f"non-finite values for {spec.name}")  # records are checked; never expected
            out[spec.name] = maps.round_mantissa(v, mantissa_bits)
        return out

    def evaluate(self, ids: np.ndarray, counts: np.ndarray, specs: list[MapSpec], into: dict[str, np.ndarray],
                 unit_scale_m: float, mantissa_bits: int, progress: Callable[[float], float]) -> Iterator[float]:
        """Values of palette entries ``ids`` for ``specs`` into ``into`` (rows in ``ids`` order), in chunks;
        ``counts``: texels per entry (for the statistics).  Yields ``progress(fraction of ids done)``."""
        step = self.table_step if self.table is not None else self.chunk
        for spec in specs:
            into[spec.name] = np.empty((len(ids), len(spec.channels)), np.float32)
        for start in range(0, len(ids), step):
            sl = slice(start, min(start + step, len(ids)))
            t0 = time.perf_counter()
            rgb = self.palette[ids[sl]].astype(np.float32)
            rec, inside = self.records(rgb) if self.edits is None else self.edited_records(rgb, self.edits[ids[sl]])
            for name, v in self.values(rec, specs, unit_scale_m, mantissa_bits).items():
                into[name][sl] = v
            c = counts[sl]
            self.counted["texels_from_table"] += int(c[inside].sum())
            self.counted["texels_outside_table" if self.table is not None else "texels_evaluated_exactly"] += int(
                c[~inside].sum())
            for key, value in texel_records.count_stats(rec, c, self.targets).items():
                self.stats[key] = int(self.stats.get(key, 0)) + value
            if "max_share" in rec and len(rec["max_share"]):
                self.max_share = np.maximum(self.max_share, rec["max_share"].max(axis=0))
            self.timings["evaluate"] += time.perf_counter() - t0
            yield progress(sl.stop / max(len(ids), 1))

    def make_table(self, step: float, notes: list[str]) -> Iterator[float]:
        """Build the table for these options into the user cache (first step of a big bake without one) and
        use it; yields the fraction built."""
        path = cached_table_path(self.model.sha256, self.options, step)
        t0 = time.perf_counter()
        table = yield from texel_table.build_steps(self.load_model(), self.options, step)
        path.parent.mkdir(parents=True, exist_ok=True)
        texel_table.save(table, path, overwrite=True)
        self.table = texel_table.load(path)
        self.timings["table_build"] = time.perf_counter() - t0
        notes.append(f"built a fast-path table for these options in {self.timings['table_build']:.0f} s, "
                     f"cached as {path} (reused by later bakes)")
