"""The fast bake path: a table of per-texel records (exporters.texel_records) over the colours of skin.

Everything a bake writes depends on the texel's RGB only, so the model and the collapse are evaluated
once per model on a grid of colours, and a bake interpolates.  Colours outside the grid (or in a cell
with a corner outside the RGB cube) get the nearest skin colour's values, as the live group answers them
(exporters.live_table), so every texel gets a value; with the painted colour every texel's media are then
brought to its painted colour, the translucency kept (exporters.painted_gain, :meth:`TexelTable.records`), as the
live group does; ``--exact`` bakes evaluate the model everywhere.

Colour space of the grid ("skin space")
---------------------------------------
With e = the sRGB encoding (IEC 61966-2-1) of the linear albedo clamped to [0, 1] (as the model clamps it),
the coordinates are  l = (e_R + e_G + e_B) / 3,  c1 = e_R - e_G,  c2 = e_G - e_B.  The encoding is close
to perceptually uniform, so equal steps give roughly equal colour error at every lightness; skin is a
thin region of c1, c2 (red above green above blue), so a box l in [0, 1], c1 in [-0.06, 0.40],
c2 in [-0.08, 0.24] holds it with far fewer nodes than the RGB cube (the decoder's whole biophysical
range at exposures 0.7-2.5 falls 99.7 % inside).  8-bit sRGB textures
map their codes linearly onto e.

Stored per node (K components; :func:`channel_names`): Cycles colour, log radius (m), weight (K x 3 each),
anisotropy (K), each component's largest share of the colour (K), unreachable flags (3), clamp counts (3), the
painted spectral media's clamp flag (1; 0 for the model's colour),
biophysical (5, as the logit of each parameter's position in its range: the encoder's output before its
sigmoid, smooth where the parameters saturate), log luminance of the model's colour (1: the exposure is
Y(albedo) / that, so it stays exact in the albedo's brightness).  Interpolation is trilinear.
The physical maps are derived from the Cycles ones by Cycles' own forward maps (alpha = f(color, g),
sigma_t = 4 pi / (radius (1 - g))), which invert exactly what the collapse did.

File (``.npz``): values as 16-bit fixed point per channel between the channel's min and max (65535 marks
nodes outside the RGB cube), the grid, and a JSON header with the SHA-256 of the model it was made from,
K, the collapse options, the channel names and the command that built it.  A table whose model SHA-256
differs from the model's is refused (the bake falls back to exact evaluation with a warning).

Build (about 30 s of CPU for the shipped step 0.015 on 2 cores; the painted colour solves a 3 x 3 system per node)::

    python -m training texel-table --model blender_addon/models/skin_inversion.onnx \\
        --out blender_addon/models/skin_inversion_table.npz --overwrite

(the command lives in ``training.commands.texel_table``; this module holds only what a bake needs and the
builder it calls).
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import cycles, inference, painted_gain, texel_records
from .cli_io import atomic_file
from .colorimetry import srgb_decode, srgb_encode
from .constants import PARAM_NAMES, PARAM_RANGES
from .maps import sha256_file
from .texel_records import CollapseOptions

#: v4: components collapsed to isotropic media (exporters.collapse.G_MAX = 0); v3 tables hold g up to 0.7.
FORMAT = "spectral_skin_sss texel table v4"
#: skin space = COORDS @ sRGB-encoded RGB (module docstring).
COORDS = np.array([[1 / 3, 1 / 3, 1 / 3], [1.0, -1.0, 0.0], [0.0, 1.0, -1.0]])
COORDS_INV = np.linalg.inv(COORDS)
#: Box of the grid in skin space: l, c1, c2.
DEFAULT_BOX: tuple[tuple[float, float], ...] = ((0.0, 1.0), (-0.06, 0.40), (-0.08, 0.24))
#: Grid step in skin space (the same on every axis).  Measured against exact evaluation (training.bench.runtime):
#: 0.015 keeps the baked Cycles appearance (painted colour) within mean ΔE76 0.017, max 0.05 on skin, in a 2.7 MB file.
DEFAULT_STEP: float = 0.015
#: The biophysical vector is stored as the logit of its position in its range, clipped this far from 0 and 1.
_LOGIT_EPS = 1e-7
#: 16-bit code marking a node outside the RGB cube.
INVALID = 65535
_Q_MAX = 65534
#: Rows interpolated per block (bounded temporaries: 8 corners x block x channels float32).
_BLOCK = 1 << 15


class TableError(ValueError):
    """A table file that cannot be used (missing, wrong format, another model); the message says what to do."""


def channel_names(k: int) -> tuple[str, ...]:
    """Names of the stored channels for K components, in storage order."""
    names = []
    for base in ("color", "log_radius_m", "weight"):
        names += [f"{base}_k{i}_{c}" for i in range(1, k + 1) for c in "rgb"]
    names += [f"anisotropy_k{i}" for i in range(1, k + 1)]
    names += [f"share_k{i}" for i in range(1, k + 1)]
    names += [f"unreachable_{c}" for c in "rgb"]
    names += ["n_low", "n_high", "n_capped", "spectral_clamped"]
    names += [f"logit_{p}" for p in PARAM_NAMES]
    names += ["log_y_model"]
    return tuple(names)


def skin_coords(rgb: np.ndarray) -> np.ndarray:
    """Skin-space coordinates (N, 3) (l, c1, c2) of linear-sRGB rows (N, 3), clamped to [0, 1] first (as the
    model clamps them); ValueError for NaN/Inf."""
    x = np.asarray(rgb, np.float64)
    if not np.all(np.isfinite(x)):
        raise ValueError("albedo rows contain NaN or Inf; fix the texture")
    e = srgb_encode(np.clip(x, 0.0, 1.0))
    return e @ COORDS.T


def rgb_of_coords(coords: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear sRGB (N, 3) of skin-space points and whether each lies in the RGB cube (else clamped)."""
    e = np.asarray(coords, np.float64) @ COORDS_INV.T
    ok = np.all((e >= -1e-9) & (e <= 1.0 + 1e-9), axis=1)
    return srgb_decode(np.clip(e, 0.0, 1.0)), ok


@dataclass
class TexelTable:
    """A loaded table.  ``values`` (n0, n1, n2, C) float32, NaN at nodes outside the RGB cube; ``origin`` and
    ``step`` (3,) of the grid in skin space; ``meta`` the file's JSON header; ``sha256`` of the file."""

    values: np.ndarray
    origin: np.ndarray
    step: np.ndarray
    k: int
    model_sha256: str
    options: CollapseOptions
    meta: dict
    sha256: str = ""
    path: Path | None = None
    _flat: np.ndarray = field(init=False, repr=False)
    _cell_ok: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        n0, n1, n2, c = self.values.shape
        if min(n0, n1, n2) < 2 or c != len(channel_names(self.k)):
            raise TableError(f"table grid {self.values.shape[:3]} / {c} channels does not fit K = {self.k}")
        self._flat = np.ascontiguousarray(self.values.reshape(-1, c))
        ok = np.all(np.isfinite(self.values), axis=3)
        self._cell_ok = (ok[:-1, :-1, :-1] & ok[1:, :-1, :-1] & ok[:-1, 1:, :-1] & ok[:-1, :-1, 1:] & ok[1:, 1:, :-1]
                         & ok[1:, :-1, 1:] & ok[:-1, 1:, 1:] & ok[1:, 1:, 1:])

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.values.shape[:3])

    def channel(self, name: str) -> int:
        return channel_names(self.k).index(name)

    def locate(self, rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For rows (N, 3): inside (N,) bool (in the box and in a cell whose corners all lie in the RGB cube),
        and for the inside rows the flat index of their cell's lower corner and the fractions (n_in, 3)."""
        x = (skin_coords(rgb) - self.origin) / self.step
        n = np.array(self.shape)
        inside = np.all((x >= 0.0) & (x <= n - 1), axis=1)
        i = np.clip(np.floor(x).astype(np.int64), 0, n - 2)
        inside &= self._cell_ok[i[:, 0], i[:, 1], i[:, 2]]
        i, x = i[inside], x[inside]
        base = (i[:, 0] * n[1] + i[:, 1]) * n[2] + i[:, 2]
        return inside, base, (x - i).astype(np.float32)

    def _interp_block(self, base: np.ndarray, frac: np.ndarray) -> np.ndarray:
        n1, n2 = self.shape[1:]
        f0, f1, f2 = frac[:, 0:1], frac[:, 1:2], frac[:, 2:3]
        g0, g1, g2 = 1.0 - f0, 1.0 - f1, 1.0 - f2
        t = self._flat
        s0, s1 = n1 * n2, n2
        out = (g0 * g1 * g2) * t[base]
        out += (g0 * g1 * f2) * t[base + 1]
        out += (g0 * f1 * g2) * t[base + s1]
        out += (g0 * f1 * f2) * t[base + s1 + 1]
        out += (f0 * g1 * g2) * t[base + s0]
        out += (f0 * g1 * f2) * t[base + s0 + 1]
        out += (f0 * f1 * g2) * t[base + s0 + s1]
        out += (f0 * f1 * f2) * t[base + s0 + s1 + 1]
        return out

    def interpolate(self, base: np.ndarray, frac: np.ndarray, threads: int = 1) -> np.ndarray:
        """Trilinear values (n, C) float32 at cells ``base`` with fractions ``frac`` (from :meth:`locate`), in
        blocks spread over ``threads`` threads (numpy releases the GIL in these loops)."""
        n = len(base)
        out = np.empty((n, self._flat.shape[1]), np.float32)
        blocks = [slice(s, min(s + _BLOCK, n)) for s in range(0, n, _BLOCK)]

        def work(sl: slice) -> None:
            out[sl] = self._interp_block(base[sl], frac[sl])

        if threads > 1 and len(blocks) > 1:
            with ThreadPoolExecutor(threads) as pool:
                list(pool.map(work, blocks))
        else:
            for sl in blocks:
                work(sl)
        return out

    def records(self, rgb: np.ndarray, values: np.ndarray, targets: tuple[str, ...]) -> dict[str, np.ndarray]:
        """Records (exporters.texel_records) of rows ``rgb`` (n, 3) from their interpolated ``values`` (n, C); with
        the painted colour, colours and weights brought to ``rgb`` (exporters.painted_gain)."""
        n, k = len(values), self.k
        col = {name: i for i, name in enumerate(channel_names(k))}

        def block(prefix: str) -> np.ndarray:
            return values[:, col[f"{prefix}_k1_r"]:col[f"{prefix}_k{k}_b"] + 1].astype(np.float64).reshape(n, k, 3)

        lo = np.array([PARAM_RANGES[p][0] for p in PARAM_NAMES])
        hi = np.array([PARAM_RANGES[p][1] for p in PARAM_NAMES])
        z = values[:, col[f"logit_{PARAM_NAMES[0]}"]:col[f"logit_{PARAM_NAMES[-1]}"] + 1].astype(np.float64)
        bio = np.clip(lo + (hi - lo) / (1.0 + np.exp(-z)), lo, hi)
        y_model = np.exp(values[:, col["log_y_model"]].astype(np.float64))
        rec = {"biophysical": bio.astype(np.float64),
               "exposure": texel_records.albedo_luminance(rgb) / np.maximum(y_model, 1e-6)}
        if self.options.painted:
            rec["spectral_clamped"] = (values[:, col["spectral_clamped"]] > 0.5).astype(np.int64)
        if not texel_records.needs_media(targets):
            return rec
        g = np.clip(values[:, col["anisotropy_k1"]:col[f"anisotropy_k{k}"] + 1].astype(np.float64), cycles.G_MIN,
                    cycles.RECOMMENDED_G_MAX)
        color, weight = np.clip(block("color"), 0.0, 1.0), np.maximum(block("weight"), 0.0)
        if self.options.painted:  # the painted colour, whatever the colour (exporters.painted_gain)
            rho = painted_gain.body_reflectance(color, self.options.ior)
            color, weight = painted_gain.painted_media(rho, weight, rgb, painted_gain.body_fit(self.options.ior))
        radius_m = np.exp(block("log_radius_m"))
        unreachable = (values[:, col["unreachable_r"]:col["unreachable_b"] + 1] > 0.5).astype(np.float64)
        share = np.clip(values[:, col["share_k1"]:col[f"share_k{k}"] + 1].astype(np.float64), 0.0, 1.0)
        rec.update(color=color, radius_m=radius_m, weight=weight, anisotropy=g,
                   max_share=share, unreachable=unreachable, n_unreachable=unreachable.sum(axis=1).astype(np.int64))
        for name in ("n_low", "n_high", "n_capped"):
            rec[name] = np.rint(values[:, col[name]]).astype(np.int64)
        if "physical" in targets or "openpbr" in targets:
            rec["alpha"] = cycles.rw_albedo_forward(color, g[..., None])
            rec["sigma_t_cm"] = 4.0 * np.pi / (radius_m * (1.0 - g[..., None]) * cycles.CM_PER_M)
        return rec


def _quantise(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ok = np.isfinite(values)
    lo = np.where(ok, values, np.inf).min(axis=(0, 1, 2))
    hi = np.where(ok, values, -np.inf).max(axis=(0, 1, 2))
    lo, hi = np.where(np.isfinite(lo), lo, 0.0), np.where(np.isfinite(hi), hi, 0.0)
    span = np.where(hi > lo, hi - lo, 1.0)
    q = np.rint((np.where(ok, values, lo) - lo) / span * _Q_MAX)
    return np.where(ok, q, INVALID).astype(np.uint16), lo, hi


def _dequantise(q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    span = np.where(hi > lo, hi - lo, 0.0)
    values = (lo + q.astype(np.float64) / _Q_MAX * span).astype(np.float32)
    values[q == INVALID] = np.nan
    return values


def build(model: inference.InversionSession, options: CollapseOptions | None = None, step: float = DEFAULT_STEP,
          box: tuple[tuple[float, float], ...] = DEFAULT_BOX, chunk: int = 2048) -> TexelTable:
    """Evaluate ``model`` (and the collapse with ``options``) at every grid node inside the RGB cube.

    ``step``: grid step in skin space; ``box``: ((l_lo, l_hi), (c1_lo, c1_hi), (c2_lo, c2_hi)).  Returns the
    table in memory (values quantised as they will be stored).
    """
    steps = build_steps(model, options, step, box, chunk)
    while True:
        try:
            next(steps)
        except StopIteration as done:
            return done.value


def build_steps(model: inference.InversionSession, options: CollapseOptions | None = None, step: float = DEFAULT_STEP,
                box: tuple[tuple[float, float], ...] = DEFAULT_BOX, chunk: int = 2048):
    """:func:`build` as a generator yielding the fraction of nodes done; its return value is the table."""
    options = options or CollapseOptions()
    if not (np.isfinite(step) and 1e-3 <= step <= 0.5):
        raise ValueError(f"step must lie in [0.001, 0.5], got {step}")
    origin = np.array([b[0] for b in box], np.float64)
    shape = tuple(int(np.floor((b[1] - b[0]) / step + 1e-9)) + 1 for b in box)
    if min(shape) < 2:
        raise ValueError(f"box {box} holds fewer than 2 nodes per axis at step {step}")
    axes = [origin[d] + step * np.arange(shape[d]) for d in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    rgb, ok = rgb_of_coords(nodes)
    names = channel_names(model.k)
    values = np.full((len(nodes), len(names)), np.nan)
    todo = np.flatnonzero(ok)
    t0 = time.perf_counter()
    for start in range(0, len(todo), chunk):
        idx = todo[start:start + chunk]
        rec = texel_records.exact_records(model, rgb[idx].astype(np.float32), ("cycles", "spectral"), options,
                                          with_luminance=True)
        values[idx] = _node_channels(rec, model.k)
        yield min(1.0, (start + chunk) / max(len(todo), 1))
    seconds = time.perf_counter() - t0
    q, lo, hi = _quantise(values.reshape(*shape, len(names)))
    meta = {"format": FORMAT, "model_sha256": model.sha256, "model_file": model.path.name, "K": model.k,
            "options": options.as_dict(), "channels": list(names), "space": "l, c1, c2 of sRGB-encoded RGB "
            "(exporters.texel_table)", "box": [list(map(float, b)) for b in box], "step": float(step),
            "shape": list(shape), "valid_nodes": int(ok.sum()), "build_seconds": round(seconds, 2),
            "created_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
            "command": "python -m training texel-table " + " ".join(_command_args(model, options, step)),
            "quantisation": {"lo": lo.tolist(), "hi": hi.tolist(), "levels": _Q_MAX}}
    return TexelTable(values=_dequantise(q, lo, hi), origin=origin, step=np.full(3, float(step)), k=model.k,
                      model_sha256=model.sha256, options=options, meta=meta)


def _command_args(model: inference.InversionSession, options: CollapseOptions, step: float) -> list[str]:
    root = Path(__file__).resolve().parents[1]
    path = model.path.resolve()
    shown = path.relative_to(root) if path.is_relative_to(root) else path
    args = ["--model", str(shown), "--step", f"{step:g}"]
    if not options.painted:
        args.append("--model-colour")
    if options.ior != CollapseOptions().ior:
        args += ["--ior", f"{options.ior:g}"]
    if options.min_mfp_cm != CollapseOptions().min_mfp_cm:
        args += ["--min-mfp-m", f"{options.min_mfp_cm / 100:g}"]
    return args


def _node_channels(rec: dict[str, np.ndarray], k: int) -> np.ndarray:
    n = len(rec["exposure"])
    counts = np.stack([rec["n_low"], rec["n_high"], rec["n_capped"],
                       rec.get("spectral_clamped", np.zeros(n, np.int64))], axis=1)
    parts = [rec["color"].reshape(n, 3 * k), np.log(rec["radius_m"]).reshape(n, 3 * k), rec["weight"].reshape(n, 3 * k),
             rec["anisotropy"], rec["max_share"], rec["unreachable"], counts,
             bio_logit(rec["biophysical"]), np.log(np.maximum(rec["y_model"], 1e-30))[:, None]]
    return np.concatenate([np.asarray(p, np.float64) for p in parts], axis=1)


def bio_logit(p: np.ndarray) -> np.ndarray:
    """Logit of the biophysical vector (N, 5) over its ranges: the encoder's output before its sigmoid, which
    interpolates far better near saturation (measured: so2 error 0.8 % -> 0.06 % of its range at step 0.015)."""
    lo = np.array([PARAM_RANGES[q][0] for q in PARAM_NAMES])
    hi = np.array([PARAM_RANGES[q][1] for q in PARAM_NAMES])
    u = np.clip((np.asarray(p, np.float64) - lo) / (hi - lo), _LOGIT_EPS, 1.0 - _LOGIT_EPS)
    return np.log(u) - np.log1p(-u)


def save(table: TexelTable, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Write ``table`` as a compressed .npz (16-bit values + JSON header); refuses to replace a file unless
    ``overwrite``.  Returns the path."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass --overwrite to replace it")
    q, lo, hi = _quantise(table.values.astype(np.float64))
    meta = dict(table.meta, quantisation={"lo": lo.tolist(), "hi": hi.tolist(), "levels": _Q_MAX})
    with atomic_file(path) as f:  # a unique temporary file: two processes may save the same table
        np.savez_compressed(f, q=q, origin=table.origin, step=table.step, meta=np.array(json.dumps(meta)))
    return path


def load(path: str | os.PathLike) -> TexelTable:
    """Read a table written by :func:`save`; TableError if it is missing or not one."""
    path = Path(path)
    if not path.is_file():
        raise TableError(f"no fast-path table at {path}: build it with python -m training texel-table")
    try:
        with np.load(path, allow_pickle=False) as data:
            q, origin, step = data["q"], data["origin"], data["step"]
            meta = json.loads(str(data["meta"]))
    except (OSError, KeyError, ValueError) as exc:
        raise TableError(f"{path} is not a texel table ({exc}); rebuild it with python -m training texel-table"
                         ) from None
    if meta.get("format") != FORMAT:
        raise TableError(f"{path}: format {meta.get('format')!r}, expected {FORMAT!r}; rebuild it")
    quant = meta["quantisation"]
    values = _dequantise(q, np.asarray(quant["lo"]), np.asarray(quant["hi"]))
    opts = CollapseOptions(**meta["options"])
    return TexelTable(values=values, origin=np.asarray(origin, np.float64), step=np.asarray(step, np.float64),
                      k=int(meta["K"]), model_sha256=meta["model_sha256"], options=opts, meta=meta,
                      sha256=sha256_file(path), path=path)
