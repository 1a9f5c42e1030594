"""The demo's subject: a procedural, life-sized head with ears (no asset ships with Blender, nothing is
downloaded).

The head is a metaball (Blender's implicit-surface primitive) of a few ellipsoids blended into one smooth
surface — cranium, face, chin, nose, lips, neck — converted to a mesh.  The ears are separate thin flaps
(flattened, cupped UV spheres, 5.6 mm thick at the centre and thinner towards the rim) that stand out from
the head, so a light behind the head reaches their back: the thin feature where skin's translucency shows.
Sizes are those of an adult head in metres (crown to chin 23 cm, 14 cm wide, ears 6.8 cm tall), so the scene
is built at Unit Scale 1 (1 Blender unit = 1 m).  Every part gets the same spherical UV projection about the
head's centre (face at u = 0.5, the seam at the back of the head), so one albedo texture covers them all.
"""

from __future__ import annotations

import math

import numpy as np

from exporters.colorimetry import srgb_decode, srgb_encode

#: Surface half-axis of an isolated metaball ellipsoid, per unit of radius x size, at Blender's default
#: threshold 0.6 and stiffness 2 (measured: a radius-0.1 ball meshes to a 0.0574 m sphere).
_METABALL_SURFACE = 0.574
#: Metaball ellipsoids of the head, metres, +z up, the face towards -y: (name, centre, surface half-axes).
HEAD_PARTS: tuple[tuple[str, tuple[float, float, float], tuple[float, float, float]], ...] = (
    ("cranium", (0.0, 0.015, 0.030), (0.071, 0.093, 0.087)),
    ("face", (0.0, -0.035, -0.035), (0.056, 0.064, 0.070)),
    ("chin", (0.0, -0.062, -0.088), (0.032, 0.030, 0.024)),
    ("nose bridge", (0.0, -0.098, -0.008), (0.011, 0.022, 0.028)),
    ("nose tip", (0.0, -0.111, -0.032), (0.014, 0.013, 0.012)),
    ("lips", (0.0, -0.089, -0.062), (0.019, 0.008, 0.007)),
    ("neck", (0.0, 0.020, -0.120), (0.048, 0.050, 0.075)),
)
#: Metaball mesh resolution (m): 3 mm, fine enough for smooth shading at the demo's size.
HEAD_RESOLUTION_M = 0.003
#: Ear flap: half height, half width, half thickness at the centre (m); cupping (1/m: the rim's outward bend
#: per squared distance from the centre); angle it stands out from the head (degrees); centre of the left ear.
EAR_HALF_SIZE_M = (0.034, 0.020, 0.0018)
EAR_CUP_PER_M = 6.0
EAR_ANGLE_DEG = 30.0
EAR_CENTRE_M = (-0.072, 0.012, -0.005)
#: Centre of the UV projection (m).
UV_CENTRE_M = (0.0, 0.0, -0.01)


def spherical_uv(points: np.ndarray, centre=UV_CENTRE_M) -> np.ndarray:
    """(N, 2) UVs in [0, 1] of (N, 3) points (m): u = azimuth about +z (0.5 facing -y), v = elevation."""
    d = np.asarray(points, np.float64) - np.asarray(centre)
    u = 0.5 + np.arctan2(d[:, 0], -d[:, 1]) / (2.0 * math.pi)
    v = 0.5 + np.arcsin(np.clip(d[:, 2] / np.maximum(np.linalg.norm(d, axis=1), 1e-12), -1.0, 1.0)) / math.pi
    return np.stack([u, v], axis=1)


def ear_vertices(unit_sphere: np.ndarray, side: int) -> np.ndarray:
    """Vertices (N, 3) m of an ear from those of a unit sphere: flattened to a flap (wider at the top), cupped,
    turned out from the head by EAR_ANGLE_DEG and placed beside it; ``side`` -1 left (-x), +1 right."""
    x, y, z = np.asarray(unit_sphere, np.float64).T
    half_h, half_w, half_t = EAR_HALF_SIZE_M
    y = y * half_w * (1.0 + 0.25 * z)
    z = z * half_h
    x = -(x * half_t + EAR_CUP_PER_M * (y**2 + 0.3 * z**2))  # the rim bends outwards (-x for the left ear)
    a = math.radians(EAR_ANGLE_DEG)  # turn about z: the back edge (+y) stands off the head (-x)
    xr, yr = x * math.cos(a) - y * math.sin(a), x * math.sin(a) + y * math.cos(a)
    local = np.stack([xr, yr, z], axis=1) + np.asarray(EAR_CENTRE_M)
    if side > 0:
        local[:, 0] *= -1.0
    return local


def _mesh_object(bpy, name: str, mesh, collection):
    for poly in mesh.polygons:
        poly.use_smooth = True
    uv = spherical_uv(_vertices(mesh))
    loops = np.empty(len(mesh.loops), np.int64)
    mesh.loops.foreach_get("vertex_index", loops)
    layer = mesh.uv_layers.new(name="UVMap")
    layer.data.foreach_set("uv", uv[loops].astype(np.float32).ravel())
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    return obj


def _vertices(mesh) -> np.ndarray:
    co = np.empty(3 * len(mesh.vertices), np.float32)
    mesh.vertices.foreach_get("co", co)
    return co.reshape(-1, 3).astype(np.float64)


def _head_mesh(bpy):
    meta = bpy.data.metaballs.new("HeadMetaball")
    meta.resolution = meta.render_resolution = HEAD_RESOLUTION_M
    for _, centre, half in HEAD_PARTS:
        el = meta.elements.new(type="ELLIPSOID")
        el.co, el.radius, el.stiffness = centre, 1.0, 2.0
        el.size_x, el.size_y, el.size_z = (h / _METABALL_SURFACE for h in half)
    tmp = bpy.data.objects.new("HeadMetaball", meta)
    bpy.context.scene.collection.objects.link(tmp)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = bpy.data.meshes.new_from_object(tmp.evaluated_get(depsgraph))
    bpy.data.objects.remove(tmp)
    bpy.data.metaballs.remove(meta)
    mesh.name = "Head"
    return mesh


def _ear_mesh(bpy, bmesh, side: int):
    mesh = bpy.data.meshes.new("Ear.L" if side < 0 else "Ear.R")
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=40, v_segments=20, radius=1.0)
    bm.to_mesh(mesh)
    bm.free()
    mesh.vertices.foreach_set("co", ear_vertices(_vertices(mesh), side).astype(np.float32).ravel())
    mesh.update()
    return mesh


def build_head(collection=None) -> list:
    """Add the head and its two ears to ``collection`` (default: the scene's); returns [head, left, right]
    (mesh objects, metres, smooth shaded, one UV map)."""
    import bmesh
    import bpy

    collection = collection or bpy.context.scene.collection
    head = _mesh_object(bpy, "Head", _head_mesh(bpy), collection)
    ears = [_mesh_object(bpy, f"Ear.{'L' if s < 0 else 'R'}", _ear_mesh(bpy, bmesh, s), collection) for s in (-1, 1)]
    return [head, *ears]


# --- The subject's skin: procedural albedo textures (numpy only; the demo renders and the decomposition study
# of training.validate use them) ------------------------------------------------------------------------------

#: Base colours of the three demo textures, sRGB 8-bit codes: painted albedos of light, medium and dark skin,
#: chosen for the demo (not measured).
TONES: dict[str, tuple[int, int, int]] = {"light": (224, 178, 155), "medium": (176, 120, 90), "dark": (96, 62, 46)}
#: Tint of red patches and of freckles, relative to the base colour (linear sRGB factors per channel).
REDNESS_TINT = (1.0, 0.6, 0.65)
FRECKLE_TINT = (0.45, 0.32, 0.25)


def _value_noise(rng: np.random.Generator, size: int, cells: int) -> np.ndarray:
    """Smooth noise in [0, 1], shape (size, size): a random (cells+1)^2 grid, bicubic-smoothstep interpolated."""
    grid = rng.uniform(0.0, 1.0, (cells + 1, cells + 1))
    t = np.linspace(0.0, cells, size, endpoint=False)
    i = t.astype(int)
    f = t - i
    f = f * f * (3.0 - 2.0 * f)
    rows = grid[i] * (1 - f)[:, None] + grid[i + 1] * f[:, None]  # (size, cells+1)
    return rows[:, i] * (1 - f)[None, :] + rows[:, i + 1] * f[None, :]


def _freckles(rng: np.random.Generator, size: int, count: int) -> np.ndarray:
    """(size, size) in [0, 1]: ``count`` small Gaussian spots (radius 0.8-2.6 texels at 512: 1-3 mm on the head)."""
    yy, xx = np.mgrid[0:size, 0:size]
    cy = rng.uniform(0, size, count)
    cx = rng.uniform(0, size, count)
    radius = rng.uniform(0.8, 2.6, count) * size / 512
    spots = np.zeros((size, size))
    for y0, x0, r in zip(cy, cx, radius, strict=True):
        y1, y2, x1, x2 = (int(max(0, y0 - 4 * r)), int(min(size, y0 + 4 * r + 1)), int(max(0, x0 - 4 * r)),
                          int(min(size, x0 + 4 * r + 1)))
        d2 = (yy[y1:y2, x1:x2] - y0) ** 2 + (xx[y1:y2, x1:x2] - x0) ** 2
        spots[y1:y2, x1:x2] = np.maximum(spots[y1:y2, x1:x2], np.exp(-d2 / (2 * r * r)))
    return spots


def skin_albedo_texture(size: int = 512, seed: int = 0, base: tuple[int, int, int] = TONES["light"]) -> np.ndarray:
    """(size, size, 3) uint8 sRGB skin albedo around ``base`` (sRGB codes): mottling (±15 % in brightness),
    red patches (cheek-like blotches), freckles (small dark spots) and pore noise.  Rows run top to bottom
    (v = 1 first)."""
    rng = np.random.default_rng(seed)
    lin = np.broadcast_to(srgb_decode(np.asarray(base, np.float64) / 255.0), (size, size, 3))
    mottle = 0.6 * _value_noise(rng, size, 5) + 0.4 * _value_noise(rng, size, 17) - 0.5
    lin = lin * (1.0 + 0.3 * mottle)[..., None]
    blotch = 0.7 * _value_noise(rng, size, 4) + 0.3 * _value_noise(rng, size, 13)
    redness = (0.6 * np.clip((blotch - 0.4) * 2.5, 0.0, 1.0) ** 1.5)[..., None]
    lin = lin * (1.0 - redness + redness * np.asarray(REDNESS_TINT))
    spots = (0.75 * _freckles(rng, size, size * size // 900))[..., None]
    lin = lin * (1.0 - spots + spots * np.asarray(FRECKLE_TINT))
    lin = lin * (1.0 + 0.03 * rng.standard_normal((size, size, 1)))
    return np.round(np.clip(srgb_encode(np.clip(lin, 0.0, 1.0)), 0.0, 1.0) * 255).astype(np.uint8)
