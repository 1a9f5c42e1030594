"""The texel table (exporters.texel_table) as small float images a shader can read: the live node group.

Everything the Cycles maps hold is a function of the albedo colour, so a node group can look the K media up
per shading point instead of reading baked maps.  This module holds the numpy side (no bpy): the image
layout, the atlases and a reference evaluation of exactly what the nodes compute.

What the nodes compute, for a linear colour ``rgb`` (any node's output):

1. e = sRGB encoding of clamp(rgb, 0, 1) (IEC 61966-2-1, as exporters.texel_table.skin_coords);
2. skin space (l, c1, c2) = COORDS @ e, then grid coordinates x_d = (coord_d - origin_d) / step;
3. **outside the table's box** each x_d is clamped to [0, n_d - 1]: the colour is projected onto the nearest
   point of the box in skin space (the box is axis-aligned, so the clamp is the Euclidean projection).  The
   answer is continuous in the colour and finite for every input, NaN included (Cycles' vector maximum of NaN
   and 0 is 0, so a NaN channel reads as 0);
4. trilinear interpolation of the table's channels, where nodes outside the RGB cube (NaN in the table)
   were filled by :func:`fill_outside_cube` (means of filled neighbours, layer by layer): inside cells whose
   corners all lie in the cube the values are exactly the fast bake's; in the few cells that straddle the
   cube's faces (very light or saturated colours) they are a smooth extension, which a bake through the table
   uses too (exporters.bake.evaluate), so bakes and the live group agree on every colour.
   :func:`outside_fraction` counts the texels that fall outside these exact cells;
5. **the painted colour** (exporters.painted_gain): the media looked up so far render the skin colour nearest the
   painted one (or, in the extended cells, about it).  Each channel is brought to the painted colour P
   (clamped to [0, 1]) in the reflectance domain, the media's translucency (radius, anisotropy) kept.  The
   closure of component k in channel c adds w_kc rho(A_kc) to the channel (blender_addon.nodes: the mixture
   is a sum of closures), with rho(A) the reflectance Cycles' walk renders for Subsurface Color A
   (exporters.reflectance_tables, "cycles", at the table's IOR; exporters.painted_gain.BodyFit).  With
   Q = sum_k w_k rho(A_k) and gain G = P / Q, every component's light becomes G w_k rho(A_k), exactly as the
   collapse shares a colour among the components (exporters.collapse, step 4): the weight takes it while it
   stays at most 1 (exact: the light is linear in the weight, the walk unchanged), the albedo the rest
   (weight 1, rho' = G w rho, at most rho of the largest albedo).  Skin colours have G = 1 up to the fit
   (0.1 %); a colour outside the box keeps the radii of the skin colour it was projected onto, so its
   translucency changes continuously across the box's edge while its colour is the painted one.

Image layout ("slice atlas"): the grid is cut into its n0 slices of constant l; slice s is a tile of
(n1 + 2) x (n2 + 2) pixels (x1 along the width, x2 along the height) with a one-pixel border repeating the
tile's edge, so bilinear filtering at a clamped coordinate never reads the next tile.  Tiles sit in
``columns`` columns, row 0 at the bottom (Blender's pixel order); the live group's atlases hold every slice in one
row (:func:`layout_of`), so that the nodes reach slice s + 1 by a fixed offset of the UV (a few vector nodes
instead of a row and column per slice: every node costs each shading point its time), and a copy of the last slice
after it, so that s = floor(x0) needs no clamp (at x0 = n0 - 1 the fraction is 0).  A pixel's centre is at
u = (px + 0.5) / width, as Cycles' and the GPU's bilinear filters assume.  The third axis is interpolated by
two lookups (slices s and s + 1) mixed with the fraction of x0.

Images (float32 RGBA, Non-Color, alpha channel-packed), for each component k: ``k{k} Color`` (RGB the body
reflectance rho of the Subsurface Color, exporters.painted_gain.body_reflectance: step 5 works on it, and the
nodes turn it back into a colour; A the anisotropy g), ``k{k} Log Radius`` (RGB natural log of the radius in metres),
``k{k} Weight`` (RGB the weight).  With the shipped table (67 x 31 x 22 nodes, K = 3): nine images of
2244 x 24 pixels, 7.8 MB (7.4 MiB) in all (:func:`atlas_bytes`), whatever the textures and however many materials
share them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import cycles, painted_gain
from .texel_table import TexelTable, channel_names, skin_coords

#: The images of one component, in order: (name suffix, table channels for R, G, B, A or None).
IMAGE_KINDS = ("Color", "Log Radius", "Weight")
#: Tile border (pixels) repeating each slice's edge, in the texel table's atlases (:func:`layout_of`).
BORDER = 1


@dataclass(frozen=True)
class AtlasLayout:
    """Where grid node (i0, i1, i2) lies in the atlas: tile i0 at (column, row) = (i0 % columns, i0 // columns),
    pixel (column * tile_w + border + i1, row * tile_h + border + i2).  ``border``: pixels around each tile repeating
    its edge.  The nodes clamp a colour's texel to the grid's edge nodes, where a bilinear lookup weighs the texel
    beyond by 0 (float rounding aside): a tile without a border gives the same answer to about 1e-7 of the
    difference between neighbouring tiles, in three quarters of the memory of one with a border of 1 on 16 x 11
    nodes."""

    shape: tuple[int, int, int]
    origin: tuple[float, float, float]
    step: float
    columns: int
    border: int = BORDER

    @property
    def rows(self) -> int:
        return -(-self.shape[0] // self.columns)

    @property
    def tile(self) -> tuple[int, int]:
        return self.shape[1] + 2 * self.border, self.shape[2] + 2 * self.border

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.columns * self.tile[0], self.rows * self.tile[1]


def layout_of(table: TexelTable) -> AtlasLayout:
    """The atlas layout of ``table``: every slice in one row, then a copy of the last slice (module docstring: the
    nodes read slices s and s + 1 for s = floor(x0) up to n0 - 1, where the fraction is 0, with no clamp of s)."""
    n0, n1, n2 = table.shape
    if not np.allclose(table.step, table.step[0]):
        raise ValueError("the live table needs the same step on every axis")
    return AtlasLayout(shape=(n0, n1, n2), origin=tuple(float(o) for o in table.origin), step=float(table.step[0]),
                       columns=n0 + 1)


def fill_outside_cube(values: np.ndarray) -> np.ndarray:
    """``values`` (n0, n1, n2, C) with every NaN node replaced by the mean of its already filled 6-neighbours,
    one layer at a time outward from the valid nodes (a smooth, bounded extension).  Returns a new array."""
    shape = values.shape[:3]
    flat = np.array(values, np.float64).reshape(-1, values.shape[3])
    filled = np.all(np.isfinite(flat), axis=1)
    if not filled.any():
        raise ValueError("the table has no valid node")
    index = np.indices(shape).reshape(3, -1).T
    strides = np.array([shape[1] * shape[2], shape[2], 1])
    while not filled.all():
        todo = np.flatnonzero(~filled)
        total = np.zeros((len(todo), flat.shape[1]))
        count = np.zeros(len(todo))
        for axis in range(3):
            for shift in (1, -1):
                pos = index[todo, axis] + shift
                inside = (pos >= 0) & (pos < shape[axis])
                nb = np.where(inside, todo + shift * strides[axis], 0)
                use = inside & filled[nb]
                total[use] += flat[nb[use]]
                count += use
        grow = count > 0
        flat[todo[grow]] = total[grow] / count[grow, None]
        filled[todo[grow]] = True
    return flat.reshape(values.shape)


def extended_values(table: TexelTable) -> np.ndarray:
    """Every channel of ``table`` (n0, n1, n2, C) float64 with its nodes outside the RGB cube filled by
    :func:`fill_outside_cube`: what the live group's images hold (:func:`grid_values` picks their channels), for
    all channels."""
    return fill_outside_cube(table.values)


def _channels(table: TexelTable, k: int, kind: str) -> list[int | None]:
    names = channel_names(table.k)
    base = {"Color": "color", "Log Radius": "log_radius_m", "Weight": "weight"}[kind]
    rgb = [names.index(f"{base}_k{k}_{c}") for c in "rgb"]
    return rgb + [names.index(f"anisotropy_k{k}") if kind == "Color" else None]


def grid_values(table: TexelTable) -> dict[str, np.ndarray]:
    """The filled grid (n0, n1, n2, 4) float64 of each image name ``k{k} {kind}``, alpha 1 where unused; weight and
    anisotropy clipped to the ranges a bake clips them to (exporters.texel_table.TexelTable.records), the colour
    (clipped to [0, 1]) as its body reflectance rho (exporters.painted_gain.body_reflectance)."""
    filled = extended_values(table)
    ones = np.ones(table.shape)
    out = {}
    for k in range(1, table.k + 1):
        for kind in IMAGE_KINDS:
            grid = np.stack([filled[..., i] if i is not None else ones for i in _channels(table, k, kind)], axis=-1)
            if kind == "Color":  # the body reflectance of the colour (exporters.painted_gain): what the nodes use
                grid[..., :3] = painted_gain.body_reflectance(grid[..., :3], table.options.ior)
                grid[..., 3] = _atlas_anisotropy(grid[..., 3])
            elif kind == "Weight":
                grid[..., :3] = np.maximum(grid[..., :3], 0.0)
            out[f"k{k} {kind}"] = grid
    return out


def _atlas_anisotropy(g: np.ndarray) -> np.ndarray:
    """The anisotropy as the atlases hold it: clipped to the range a bake clips it to."""
    return np.clip(g, cycles.G_MIN, cycles.RECOMMENDED_G_MAX)


@dataclass(frozen=True)
class AtlasRanges:
    """What the atlases of a table hold (:func:`grid_values`), as the live group's nodes need it: ``log_radius``
    the range (min, max) of the log radii (natural log of metres, every component and channel); ``rho_max`` the
    largest body reflectance."""

    log_radius: tuple[float, float]
    rho_max: float


def atlas_ranges(table: TexelTable) -> AtlasRanges:
    """:class:`AtlasRanges` of ``table`` from its valid nodes, without filling its grid: the filled nodes are means
    of valid ones (:func:`fill_outside_cube`), so they add no value outside these ranges."""
    names = channel_names(table.k)
    values = table.values
    log_r = values[..., [i for i, n in enumerate(names) if n.startswith("log_radius_m_")]]
    colours = values[..., [i for i, n in enumerate(names) if n.startswith("color_")]]
    return AtlasRanges(log_radius=(float(np.nanmin(log_r)), float(np.nanmax(log_r))),
                       rho_max=float(painted_gain.body_reflectance(np.nanmax(colours), table.options.ior)))


def atlas_of(grid: np.ndarray, layout: AtlasLayout) -> np.ndarray:
    """The atlas (height, width, C) float32 of one grid (n0, n1, n2, C), rows bottom to top (Blender's order)."""
    n0 = layout.shape[0]
    tw, th = layout.tile
    b = layout.border
    tiles = np.pad(grid.astype(np.float32), ((0, layout.rows * layout.columns - n0), (b, b), (b, b), (0, 0)),
                   mode="edge")  # (slots, tile_w, tile_h, C); slots past n0 repeat the last slice
    tiles = tiles.reshape(layout.rows, layout.columns, tw, th, grid.shape[3])
    return np.ascontiguousarray(tiles.transpose(0, 3, 1, 2, 4).reshape(layout.rows * th, layout.columns * tw, -1))


def atlases(table: TexelTable) -> tuple[AtlasLayout, dict[str, np.ndarray]]:
    """The layout and every image (height, width, 4) float32 of ``table``."""
    layout = layout_of(table)
    return layout, {name: atlas_of(grid, layout) for name, grid in grid_values(table).items()}


def atlas_bytes(layout: AtlasLayout, image_count: int) -> int:
    """Memory of ``image_count`` float RGBA atlases (bytes)."""
    width, height = layout.size
    return image_count * width * height * 4 * 4


def grid_coords(rgb: np.ndarray, layout: AtlasLayout) -> np.ndarray:
    """Clamped grid coordinates (N, 3) of linear colours (N, 3), as the nodes compute them (NaN -> 0)."""
    x = np.nan_to_num(np.asarray(rgb, np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    g = (skin_coords(x) - np.array(layout.origin)) / layout.step
    return np.clip(g, 0.0, np.array(layout.shape) - 1.0)


def lookup(grid: np.ndarray, layout: AtlasLayout, rgb: np.ndarray) -> np.ndarray:
    """Reference of the nodes: trilinear values (N, 4) of one filled grid (n0, n1, n2, 4) at colours (N, 3)."""
    x = grid_coords(rgb, layout)
    i = np.minimum(np.floor(x).astype(np.int64), np.array(layout.shape) - 2)
    f = x - i
    out = np.zeros((len(x), grid.shape[3]))
    for corner in range(8):
        bits = [(corner >> d) & 1 for d in range(3)]
        w = np.prod([f[:, d] if b else 1.0 - f[:, d] for d, b in enumerate(bits)], axis=0)
        out += w[:, None] * grid[i[:, 0] + bits[0], i[:, 1] + bits[1], i[:, 2] + bits[2]]
    return out


def outside_fraction(table: TexelTable, rgb: np.ndarray) -> float:
    """Fraction of colours (N, 3) outside the table's exact domain (outside its box, or in a cell with a corner
    outside the RGB cube): where the live group answers with the projected/extended value."""
    rgb = np.asarray(rgb, np.float64).reshape(-1, 3)
    if len(rgb) == 0:
        return 0.0
    inside, _, _ = table.locate(np.nan_to_num(rgb, nan=0.0, posinf=1.0, neginf=0.0))
    return float(1.0 - inside.mean())


# -- the group's media -----------------------------------------------------------------------------------------
def group_media(table: TexelTable, rgb: np.ndarray, grids: dict[str, np.ndarray] | None = None
                ) -> dict[str, np.ndarray]:
    """Reference of the live group's media at linear colours ``rgb`` (N, 3) (the colour entering the table):
    ``{"k{k} Color": (N, 3), "k{k} Radius": (N, 3) in metres, "k{k} Weight": (N, 3), "k{k} Anisotropy": (N,)}``
    after steps 1-5.  ``grids``: :func:`grid_values` of ``table`` when already made."""
    grids = grids if grids is not None else grid_values(table)
    layout = layout_of(table)
    rgb = painted_gain.painted_target(rgb)  # the group clamps the colour before its lookup
    looked = {name: lookup(grid, layout, rgb) for name, grid in grids.items()}
    ks = range(1, table.k + 1)
    rho = np.stack([looked[f"k{k} Color"][:, :3] for k in ks], axis=1)
    weight = np.stack([looked[f"k{k} Weight"][:, :3] for k in ks], axis=1)
    colour, weight = painted_gain.painted_media(rho, weight, rgb, painted_gain.body_fit(table.options.ior))
    out = {}
    for i, k in enumerate(ks):
        out[f"k{k} Color"], out[f"k{k} Weight"] = colour[:, i], weight[:, i]
        out[f"k{k} Radius"] = np.exp(looked[f"k{k} Log Radius"][:, :3])
        out[f"k{k} Anisotropy"] = looked[f"k{k} Color"][:, 3]
    return out
