"""The edit table: how the Melanin, Blood and Oxygenation controls (exporters.skin_edits) change a painted colour,
tabulated over skin colours so that a shader (blender_addon.live_edits) and the fast bake can apply them.

What the live group computes for a painted colour c and controls (m, b, o):

1. control coordinates s = (log2 m, log2 b, o), each clamped to its range (exporters.skin_edits.CONTROL_RANGES);
2. per control j, hat-function weights of s_j on the levels ``LEVELS[j]`` (equally spaced, h apart, the neutral
   level 0 left out: w_i = max(0, 1 - |s_j - level_i| / h)); at neutral every weight is exactly 0.  At most two
   adjacent levels weigh: the nodes read just those two (linear interpolation between them, the neutral level
   holding zero);
3. the shift D(c, s) = sum_j sum_i w_ji T_ji(c), where T_ji(c) (6 channels) is trilinear in a coarse grid over skin
   space (the grid, box and projection of exporters.texel_table / exporters.live_table: colours outside the box take
   the nearest skin colour's shift, so the answer is continuous) holding at level i of control j:
   channels 0-2 = ln(C_edited / C_painted) per channel (exporters.skin_edits.colour_ratio), channels 3-5 = the
   log-radius correction per channel (below);
4. edited colour c' = c exp(D_0..2) (the lookups clamp it to [0, 1]): the media are the texel table's at c' (the
   inversion of the edited colour) with every component's radius in channel ch times exp(D_3+ch).  The correction
   of channel ch is ln(r_exact / r_table(c')) of that channel's effective radius sum_k w_k r_k: how much the edited
   tone's (exporters.skin_edits.edited_records) differs from that of the tone the inversion finds for c' (melanin
   sits in the epidermis and blood in the dermis, so tones of one colour can differ in depth, and differently in
   red light, which reaches the dermis, than in blue, which the epidermis absorbs).

The controls combine additively in log space (step 3): measured against the exact answer by
``python -m training edit-table --check`` (docs/research/skin_model.md).  At neutral the shift is exactly 0 and
c' = c bit for bit.

The live group's caches hold an edit's shift precombined: a constant edit's at the grid's nodes
(:func:`combined_values`, :func:`combined_atlas`), an edit painted by a mask at a few masks along its line
(:func:`mask_line`, :func:`line_atlas`; the nodes' reading of it: :func:`masked_shift`).

File (``.npz``): ``steps`` int16 (n0, n1, n2, 3 controls, levels, 6), the values (:func:`encode_values`; NaN-free:
nodes outside the RGB cube filled by exporters.live_table.fill_outside_cube), the grid, and a JSON header with the
SHA-256 of the model, decoder and texel table it was made from.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import inference, live_table, skin_edits, texel_records, texel_table
from .cli_io import atomic_file
from .maps import sha256_file

FORMAT = "spectral_skin_sss edit table v2"
#: Grid step in skin space: coarser than the texel table's (the shifts vary slowly with the colour).
DEFAULT_STEP: float = 0.03
#: Levels of each control coordinate (log2 m, log2 b, o), equally spaced, 0 (neutral) left out.
LEVELS: dict[str, tuple[float, ...]] = {
    "melanin": (-2.0, -1.5, -1.0, -0.5, 0.5, 1.0, 1.5, 2.0), "blood": (-2.0, -1.5, -1.0, -0.5, 0.5, 1.0, 1.5, 2.0),
    "oxygenation": (-0.5, -0.375, -0.25, -0.125, 0.125, 0.25, 0.375, 0.5)}
#: Spacing h of each control's levels.
SPACING: dict[str, float] = {"melanin": 0.5, "blood": 0.5, "oxygenation": 0.125}
#: Channels per level: ln colour ratio (R, G, B) and log-radius correction (R, G, B).
CHANNELS = 6
#: Constant edits the live group holds precombined at once (blender_addon.live_edits' caches): each one atlas per kind
#: (:func:`combined_atlas`), 0.20 MB for the shipped table; twelve keep the edit images within 8 MB (7.7 MB with the
#: table's six images and the mask cache's two).
CACHE_SLOTS = 12


class EditTableError(ValueError):
    """An edit table that cannot be used (missing, wrong format, another model); the message says what to do."""


@dataclass
class EditTable:
    """``values`` (n0, n1, n2, 3, L, 4) float32; ``origin``, ``step`` of the grid in skin space; ``meta``."""

    values: np.ndarray
    origin: np.ndarray
    step: float
    meta: dict
    sha256: str = ""

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.values.shape[:3])

    def layout(self) -> live_table.AtlasLayout:
        """The slice-atlas layout of the grid (exporters.live_table): every slice in one row, so that the nodes
        reach slice s + 1 by a fixed offset, then a copy of the last slice (s + 1 exists for every s they read); the
        tiles without borders (the same answer in three quarters of the memory: live_table.AtlasLayout)."""
        n0, n1, n2 = self.shape
        return live_table.AtlasLayout(shape=(n0, n1, n2), origin=tuple(float(o) for o in self.origin),
                                      step=float(self.step), columns=n0 + 1, border=0)

    def shift_bounds(self) -> dict[str, tuple[float, float]]:
        """Per image kind (:data:`KINDS`): the range of the shift D the lookups can give, every channel and every
        combination of controls (the sum over controls of each one's range over its levels, 0 included)."""
        out = {}
        for kind, channels in KINDS.items():
            lo = hi = 0.0
            for j in range(self.values.shape[3]):
                values = self.values[:, :, :, j, :, channels]
                lo += min(0.0, float(np.nanmin(values)))
                hi += max(0.0, float(np.nanmax(values)))
            out[kind] = (lo, hi)
        return out

    def atlases(self) -> dict[str, np.ndarray]:
        """Image name (:func:`image_name`) -> one control's colour or radius channels at its levels, the atlases
        stacked bottom to top in the order of :data:`BLOCK_LEVELS` (the neutral level's shift is 0 and is not
        stored): (STACKED x height, width, 4) float32, alpha 1."""
        layout = self.layout()
        out = {}
        for j in range(len(skin_edits.CONTROLS)):
            for kind, channels in KINDS.items():
                values = self.values[:, :, :, j, :, channels]
                rgb = np.concatenate([live_table.atlas_of(values[:, :, :, i], layout) for i in BLOCK_LEVELS],
                                     axis=0)
                out[image_name(j, kind)] = np.concatenate([rgb, np.ones_like(rgb[..., :1])], axis=-1)
        return out


#: Atlases stacked per control image: its levels (:data:`LEVELS`; no neutral level).
STACKED = len(LEVELS["melanin"])
#: The level (index into :data:`LEVELS`) of each stacked atlas, bottom to top: the levels above neutral, then those
#: below, each in increasing order.  With the control coordinate in level steps k (-4 .. 4 for eight levels), the
#: atlas of step k lies at block (k - 1) mod (STACKED + 1): so the two levels around any coordinate are two adjacent
#: blocks, and neutral (step 0) is block -1 below the image or block STACKED above it, where a lookup with Clip
#: extension reads 0 (blender_addon.live_edits).
BLOCK_LEVELS: tuple[int, ...] = (*range(STACKED // 2, STACKED), *range(STACKED // 2))
#: Tag of the control images' layout (:data:`BLOCK_LEVELS`, tiles without borders): images of another layout are
#: made again.
IMAGE_LAYOUT = "levels above neutral, then below; no tile borders"
#: The two images of each control: which channels of a level each holds.
KINDS: dict[str, slice] = {"colour": slice(0, 3), "radius": slice(3, 6)}


def image_name(control: int, kind: str) -> str:
    """``"Melanin Colour"``, ``"Melanin Radius"``, ...: a control's image of one kind (:data:`KINDS`)."""
    return f"{skin_edits.CONTROLS[control].title()} {kind.title()}"


def control_coords(edits: np.ndarray) -> np.ndarray:
    """(N, 3): log2 melanin, log2 blood, oxygenation of edit rows (N, 3), clamped to the controls' ranges."""
    e = skin_edits.clamp_controls(edits)
    return np.stack([np.log2(e[:, 0]), np.log2(e[:, 1]), e[:, 2]], axis=1)


def level_weights(coords: np.ndarray) -> np.ndarray:
    """(N, 3, L): hat weights of each control's levels (module docstring step 2)."""
    out = []
    for j, name in enumerate(skin_edits.CONTROLS):
        lv = np.array(LEVELS[name])
        out.append(np.maximum(0.0, 1.0 - np.abs(coords[:, j:j + 1] - lv) / SPACING[name]))
    return np.stack(out, axis=1)


def shift(table: EditTable, rgb: np.ndarray, edits: np.ndarray) -> np.ndarray:
    """Reference of the nodes: D (N, 4) (module docstring step 3) at painted colours (N, 3) under edits (N, 3)."""
    rgb = np.asarray(rgb, np.float64).reshape(-1, 3)
    w = level_weights(control_coords(np.broadcast_to(edits, rgb.shape) if np.size(edits) == 3 else edits))
    layout = table.layout()
    out = np.zeros((len(rgb), CHANNELS))
    for j in range(table.values.shape[3]):
        for i in range(table.values.shape[4]):
            if np.any(w[:, j, i] != 0.0):
                out += w[:, j, i, None] * live_table.lookup(table.values[:, :, :, j, i], layout, rgb)
    return out


def stack_weights(edit) -> np.ndarray:
    """(3, STACKED): the weight of each control's stacked atlases under one edit (Melanin, Blood, Oxygenation): the
    hat weights of :func:`level_weights`."""
    return level_weights(control_coords(np.asarray(edit, np.float64).reshape(1, 3)))[0]


def combined_values(table: EditTable, edit) -> np.ndarray:
    """(n0, n1, n2, 6): the shift D of one edit (Melanin, Blood, Oxygenation) at the grid's nodes, its levels and
    controls summed with their weights.  The lookups are linear in the table, so its trilinear lookup at a colour is
    :func:`shift` at that colour: what the live group's edit cache holds (blender_addon.live_edits)."""
    return np.einsum("abcjlk,jl->abck", table.values.astype(np.float64), stack_weights(edit))


def combined_atlas(stacked: list[np.ndarray], edit) -> np.ndarray:
    """One atlas (height, width, 4) of one kind: the images of each control (``stacked``: per control (STACKED x
    height, width, 4), as :meth:`EditTable.atlases` makes them and the live group holds them) summed with the edit's
    weights (:func:`stack_weights`, in the images' order :data:`BLOCK_LEVELS`); alpha 1.  Equal to the atlas of
    :func:`combined_values`' channels of that kind.  A neutral ``edit`` gives zeros."""
    weights = stack_weights(edit)[:, BLOCK_LEVELS]
    out = None
    for j, image in enumerate(stacked):
        blocks = np.asarray(image, np.float64).reshape(STACKED, -1, *image.shape[1:])
        part = np.tensordot(weights[j], blocks, axes=1)
        out = part if out is None else out + part
    out = out.astype(np.float32)
    out[..., 3] = 1.0
    return out


#: Points of the mask cache (blender_addon.live_edits): one edit's shift at up to this many masks along the line from
#: neutral to its values (:func:`mask_line`), 0.26 MB each for the shipped table; three keep the edit images within
#: 8 MB and hold every edit whose largest control spans three of its levels' spacings or fewer (the presets).
MASK_POINTS = 3


def masked_edits(edit, masks) -> np.ndarray:
    """Edit rows (N, 3): ``edit`` (Melanin, Blood, Oxygenation) weighed by masks (N,) in [0, 1] (clipped) as bake
    masks and the live group's Edit Mask weigh it: control = neutral + mask x (value - neutral)."""
    neutral = np.array(skin_edits.NEUTRAL)
    m = np.clip(np.asarray(masks, np.float64).reshape(-1, 1), 0.0, 1.0)
    return neutral + m * (np.asarray(edit, np.float64).reshape(1, 3) - neutral)


@dataclass(frozen=True)
class MaskLine:
    """How the mask cache holds an edit painted by a mask: its shift at ``masks`` (the points 1 .. n; point 0, the
    mask 0, is the zero shift), read linearly in the position :meth:`position` of the mask.  The points lie where the
    edit's ``control`` (the one spanning the most level spacings) crosses the table's levels, the last at mask 1:
    between two of them that control's shift is linear in its coordinate and the position is that coordinate (the
    last stretch rescaled), so the cache gives the table's answer for that control exactly and the other controls'
    to within their own levels' curvature."""

    edit: tuple[float, float, float]
    control: int
    masks: tuple[float, ...]

    def _spacings(self, masks) -> np.ndarray:
        """|s_control| / h at masks (N,): how many level spacings the control spans there."""
        name = skin_edits.CONTROLS[self.control]
        return np.abs(control_coords(masked_edits(self.edit, masks))[:, self.control]) / SPACING[name]

    def position(self, masks) -> np.ndarray:
        """(N,) position in [0, n] of masks (N,) (clipped to [0, 1]): point i at position i."""
        n = len(self.masks)
        a = self._spacings(masks)
        end = float(self._spacings([1.0])[0])
        return np.minimum(a, n - 1.0) + np.maximum(0.0, a - (n - 1.0)) / (end - (n - 1.0))


def mask_line(edit) -> MaskLine | None:
    """The :class:`MaskLine` of ``edit`` (Melanin, Blood, Oxygenation), or None where the mask cache cannot hold it:
    neutral, not finite, outside the controls' ranges, or its largest control spanning more than
    :data:`MASK_POINTS` level spacings."""
    e = np.asarray(edit, np.float64).reshape(3)
    if not np.all(np.isfinite(e)) or np.any(skin_edits.clamp_controls(e) != e) or skin_edits.neutral_rows(e)[0]:
        return None
    coords = control_coords(e.reshape(1, 3))[0]
    spans = np.abs(coords) / np.array([SPACING[n] for n in skin_edits.CONTROLS])
    j = int(np.argmax(spans))
    n = int(np.ceil(spans[j] - 1e-6))
    if n > MASK_POINTS:
        return None
    name = skin_edits.CONTROLS[j]
    sign = np.sign(coords[j])
    crossings = sign * SPACING[name] * np.arange(1, n)  # the control's coordinate at the levels it crosses
    neutral = skin_edits.NEUTRAL[j]
    masks = (crossings / (e[j] - neutral) if name == "oxygenation"
             else (np.exp2(crossings) - neutral) / (e[j] - neutral))
    return MaskLine(edit=tuple(float(v) for v in e), control=j, masks=(*map(float, masks), 1.0))


def line_atlas(stacked: list[np.ndarray], line: MaskLine) -> np.ndarray:
    """The mask cache's image of one kind: :data:`MASK_POINTS` atlases stacked bottom to top, point i the
    :func:`combined_atlas` of ``line``'s edit at its i-th mask, points past the line's zero: (MASK_POINTS x height,
    width, 4) float32."""
    atlases = [combined_atlas(stacked, row) for row in masked_edits(line.edit, line.masks)]
    blank = np.zeros_like(atlases[0])
    return np.concatenate(atlases + [blank] * (MASK_POINTS - len(atlases)), axis=0)


def masked_shift(table: EditTable, rgb: np.ndarray, line: MaskLine, masks) -> np.ndarray:
    """Reference of the nodes reading the mask cache: D (N, 6) at painted colours (N, 3) under masks (N,) of
    ``line``'s edit (the points' shifts read linearly at :meth:`MaskLine.position`)."""
    rgb = np.asarray(rgb, np.float64).reshape(-1, 3)
    points = [np.zeros((len(rgb), CHANNELS))] + [shift(table, rgb, row) for row in masked_edits(line.edit, line.masks)]
    u = line.position(np.broadcast_to(np.asarray(masks, np.float64).ravel(), (len(rgb),)))
    k = np.minimum(np.floor(u), len(line.masks) - 1).astype(int)
    f = (u - k)[:, None]
    stack = np.stack(points)
    rows = np.arange(len(rgb))
    return (1.0 - f) * stack[k, rows] + f * stack[k + 1, rows]


def edited_colour(rgb: np.ndarray, d: np.ndarray) -> np.ndarray:
    """c' = c exp(D_RGB) (N, 3) of painted colours (N, 3) and shifts (N, 4), as the nodes compute it (the lookups
    clamp it to [0, 1]; NaN/Inf painted values are first made finite, as the lookups do)."""
    c = np.nan_to_num(np.asarray(rgb, np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    return c * np.exp(d[:, :3])


def table_records(texels: texel_table.TexelTable, rgb: np.ndarray, targets: tuple[str, ...],
                  extended: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Records of colours (N, 3) as the live group looks them up (the texel table at the colour projected onto its
    box, nodes outside the cube extended: exporters.live_table)."""
    values = extended if extended is not None else live_table.extended_values(texels)
    found = live_table.lookup(values, live_table.layout_of(texels), rgb).astype(np.float32)
    return texels.records(np.asarray(rgb, np.float64), found, targets)


def approx_records(texels: texel_table.TexelTable, table: EditTable, rgb: np.ndarray, edits: np.ndarray,
                   targets: tuple[str, ...], extended: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Records of painted colours (N, 3) under edits (N, 3) as the live group renders them (module docstring)."""
    d = shift(table, rgb, edits)
    rec = table_records(texels, edited_colour(rgb, d), targets, extended)
    if "radius_m" in rec:
        factor = np.exp(d[:, None, 3:6])
        rec["radius_m"] = rec["radius_m"] * factor
        if "sigma_t_cm" in rec:
            rec["sigma_t_cm"] = rec["sigma_t_cm"] / factor
    return rec


def effective_radius(rec: dict[str, np.ndarray]) -> np.ndarray:
    """(N, 3): sum_k w_k r_k per channel (m), the radius the live group gives EEVEE."""
    return np.sum(rec["weight"] * rec["radius_m"], axis=1)


def log_radius_ratio(exact: np.ndarray, base: np.ndarray) -> np.ndarray:
    """(N, 3): ln(exact / base) of effective radii (N, 3) per channel, 0 where either is not positive (a black
    channel has no radius to correct)."""
    ok = (exact > 0.0) & (base > 0.0)
    return np.where(ok, np.log(np.where(ok, exact, 1.0) / np.where(ok, base, 1.0)), 0.0)


def build(model: inference.InversionSession, texels: texel_table.TexelTable,
          decoder: str | os.PathLike, step: float = DEFAULT_STEP,
          box: tuple[tuple[float, float], ...] = texel_table.DEFAULT_BOX, chunk: int = 1024) -> EditTable:
    """Evaluate every grid node inside the RGB cube at every level of every control (exact: the network, the
    decoder and the collapse) and fill the rest; the texel table ``texels`` gives the correction's baseline."""
    if not (np.isfinite(step) and 0.005 <= step <= 0.5):
        raise ValueError(f"step must lie in [0.005, 0.5], got {step}")
    origin = np.array([b[0] for b in box], np.float64)
    shape = tuple(int(np.floor((b[1] - b[0]) / step + 1e-9)) + 1 for b in box)
    axes = [origin[d] + step * np.arange(shape[d]) for d in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    rgb, ok = texel_table.rgb_of_coords(nodes)
    n_levels = len(LEVELS["melanin"])
    values = np.full((len(nodes), 3, n_levels, CHANNELS), np.nan)
    extended = live_table.extended_values(texels)
    options = texels.options
    todo = np.flatnonzero(ok)
    t0 = time.perf_counter()
    for start in range(0, len(todo), chunk):
        idx = todo[start:start + chunk]
        x = rgb[idx].astype(np.float32)
        out = model.run(x)
        for j, name in enumerate(skin_edits.CONTROLS):
            for i, level in enumerate(LEVELS[name]):
                row = np.array(skin_edits.NEUTRAL, np.float64)
                row[j] = 2.0 ** level if name != "oxygenation" else level
                edits = np.tile(row, (len(idx), 1))
                tone = skin_edits.tones_of(out, x, edits, decoder)
                outputs = {"biophysical": tone["edited"].astype(np.float32), "exposure": tone["exposure"][:, None],
                           **{n: tone[n] for n in ("reflectance", "alpha", "sigma_t", "g", "weight")}}
                exact = texel_records.records_of(outputs, tone["colour"] if options.painted else None, ("cycles",),
                                                 options)
                base = table_records(texels, tone["colour"], ("cycles",), extended)
                corr = log_radius_ratio(effective_radius(exact), effective_radius(base))
                values[idx, j, i] = np.column_stack([np.log(tone["ratio"]), corr])
    seconds = time.perf_counter() - t0
    grid = values.reshape(*shape, 3 * n_levels * CHANNELS)
    filled = live_table.fill_outside_cube(grid).reshape(*shape, 3, n_levels, CHANNELS)
    meta = {"format": FORMAT, "model_sha256": model.sha256, "decoder_sha256": sha256_file(decoder),
            "texel_table_sha256": texels.sha256, "controls": list(skin_edits.CONTROLS),
            "levels": {k: list(v) for k, v in LEVELS.items()}, "box": [list(map(float, b)) for b in box],
            "step": float(step), "shape": list(shape), "valid_nodes": int(ok.sum()),
            "build_seconds": round(seconds, 2),
            "created_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")}
    return EditTable(values=filled.astype(np.float32), origin=origin, step=float(step), meta=meta)


def save(table: EditTable, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Write ``table`` as a compressed .npz; refuses to replace a file unless ``overwrite``."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass --overwrite to replace it")
    with atomic_file(path) as f:
        np.savez_compressed(f, steps=encode_values(table.values), origin=table.origin, step=np.float64(table.step),
                            meta=np.array(json.dumps(table.meta)))
    return path


#: The file stores the values in steps of 1 / QUANTUM (ln units: 1.2e-4 at most off, 0.012 % of a ratio) as int16
#: differences along the first grid axis: the shifts vary smoothly, so the differences are small and compress to
#: a third of the float32 values, which keeps the add-on's model folder small.
QUANTUM = 4096.0


def encode_values(values: np.ndarray) -> np.ndarray:
    """int16 differences along axis 0 of ``values`` rounded to steps of 1 / QUANTUM (ValueError beyond +-4)."""
    q = np.rint(np.asarray(values, np.float64) * QUANTUM)
    if not np.all(np.abs(q) < 32767 / 2):
        raise ValueError("edit table values beyond +-4 cannot be stored; check the build")
    return np.diff(q, axis=0, prepend=0.0).astype(np.int16)


def decode_values(steps: np.ndarray) -> np.ndarray:
    """The float32 values of :func:`encode_values`' output."""
    return (np.cumsum(steps.astype(np.int64), axis=0) / QUANTUM).astype(np.float32)


def load(path: str | os.PathLike) -> EditTable:
    """Read a table written by :func:`save`; EditTableError if it is missing or not one."""
    path = Path(path)
    if not path.is_file():
        raise EditTableError(f"no edit table at {path}: build it with python -m training edit-table")
    try:
        with np.load(path, allow_pickle=False) as data:
            values, origin, step = decode_values(data["steps"]), data["origin"], float(data["step"])
            meta = json.loads(str(data["meta"]))
    except (OSError, KeyError, ValueError) as exc:
        raise EditTableError(f"{path} is not an edit table ({exc}); rebuild it with python -m training edit-table"
                             ) from None
    if meta.get("format") != FORMAT:
        raise EditTableError(f"{path}: format {meta.get('format')!r}, expected {FORMAT!r}; rebuild it")
    if not np.all(np.isfinite(values)):
        raise EditTableError(f"{path} holds NaN/Inf values; rebuild it")
    return EditTable(values=values, origin=np.asarray(origin, np.float64), step=step, meta=meta,
                     sha256=sha256_file(path))


def default_path(model_path: str | os.PathLike) -> Path:
    """``<model stem>_edits.npz`` beside the model (the shipped edit table)."""
    p = Path(model_path)
    return p.with_name(f"{p.stem}_edits.npz")


def check(model: inference.InversionSession, texels: texel_table.TexelTable, table: EditTable, rgb: np.ndarray,
          edits: np.ndarray, decoder: str | os.PathLike) -> dict[str, float]:
    """The live group's answer (:func:`approx_records`) against the exact one (exporters.skin_edits) for every
    painted colour of ``rgb`` (N, 3) under every edit of ``edits`` (M, 3): ΔE76 of the colour (mean, max; against
    the exact edited colour c' and against the skin model's colour exposure x C(edited tone)), relative error of the
    effective radius per channel (mean, max) and, for comparison, that of the media at c' without the correction."""
    from .colorimetry import delta_e76, linear_srgb_to_lab

    rgb = np.asarray(rgb, np.float64).reshape(-1, 3)
    edits = np.asarray(edits, np.float64).reshape(-1, 3)
    x = np.repeat(rgb, len(edits), axis=0)
    e = np.tile(edits, (len(rgb), 1))
    tone = skin_edits.edited_tones(model, x, e, decoder)
    exact = skin_edits.edited_records(model, x, e, ("cycles",), texels.options, decoder)
    extended = live_table.extended_values(texels)
    approx = approx_records(texels, table, x, e, ("cycles",), extended)
    colour = edited_colour(x, shift(table, x, e))
    lab = linear_srgb_to_lab(colour)
    de = delta_e76(lab, linear_srgb_to_lab(tone["colour"]))
    de_ref = delta_e76(lab, linear_srgb_to_lab(np.clip(tone["reference"], 0.0, 1.0)))
    r_exact = effective_radius(exact)
    rel = np.abs(effective_radius(approx) / r_exact - 1.0)
    rel_plain = np.abs(effective_radius(table_records(texels, tone["colour"], ("cycles",), extended)) / r_exact - 1.0)
    return {"cases": len(x), "de_mean": float(de.mean()), "de_max": float(de.max()),
            "de_reference_mean": float(de_ref.mean()), "de_reference_max": float(de_ref.max()),
            "radius_rel_mean": float(rel.mean()), "radius_rel_max": float(rel.max()),
            "radius_share_over_10pct": float((rel > 0.10).mean()),
            "radius_rel_uncorrected_mean": float(rel_plain.mean()),
            "radius_rel_uncorrected_max": float(rel_plain.max())}
