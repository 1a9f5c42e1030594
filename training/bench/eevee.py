"""Benchmark of EEVEE's first render of the live material against the artist's Principled BSDF with subsurface.

What an artist waits for when switching to EEVEE or to Material Preview is the material's shader compilation, which
happens on its first render.  Scene: the demo head (training.demo_render, ``RESOLUTION`` squared px, EEVEE,
``TAA_SAMPLES`` samples) with the medium tone's albedo texture.  In a fresh process per material, EEVEE first renders
the head with a plain Diffuse BSDF (EEVEE's own shaders and the scene get compiled: not the material's cost), then
with the material under test twice: the first of those is the material's first render (its shader compiled, then
rendered), the second the same render with everything compiled.  Materials: Principled BSDF with Subsurface Weight 1
(Random Walk (Skin), the texture as Base Color: the anchor) and Invert Skin Albedo's default (the live group, whose
EEVEE output is one Principled BSDF fed by the table's images).  Wall seconds of ``bpy.ops.render.render``.

EEVEE needs OpenGL: on a machine without a GPU it runs on Mesa's software rasteriser through EGL
(``EGL_PLATFORM=surfaceless``), where every compilation takes far longer than on a GPU (the ratio is what compares).
Each process gets an empty Mesa shader cache (``MESA_SHADER_CACHE_DIR``), so no run reuses another's compiled shaders.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from training.bench.live import run_script

ROOT = Path(__file__).resolve().parents[2]
RESOLUTION = 64
TAA_SAMPLES = 4
TEXTURE = 256
ROUNDS = 4

_CHILD = """
import json, sys, time
sys.path.insert(0, {root!r})
import bpy
import blender_addon
from training import demo_render
from training.demo_subject import TONES, skin_albedo_texture
scene, parts = demo_render._scene({resolution}, 1)
scene.render.engine = "BLENDER_EEVEE"
scene.eevee.taa_render_samples = {taa}
scene.render.filepath = {out!r}
image = bpy.data.images.load(str(demo_render.write_image({texture_path!r},
                                  skin_albedo_texture({texture}, seed=0, base=TONES["medium"]))))
demo_render._assign(parts, demo_render._material("warm-up", image, "diffuse"))

def timed():
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return time.perf_counter() - t0

warm = timed()
mat = demo_render._material("skin", image, "principled_skin" if {mode!r} == "principled" else "principled")
demo_render._assign(parts, mat)
if {mode!r} == "live":
    blender_addon.register()
    demo_render._invert(parts[0], mat)
first = timed()
again = timed()
print("RESULT" + json.dumps([warm, first, again]))
"""


def measure(modes: tuple[str, ...] = ("principled", "live"), rounds: int = ROUNDS) -> dict[str, dict]:
    """Per mode: wall seconds of the warm-up render, of the material's first render and of the render after it,
    each the least over ``rounds`` rounds (the modes in alternating order; a fresh process and shader cache each)."""
    saved = {name: os.environ.get(name) for name in ("EGL_PLATFORM", "MESA_SHADER_CACHE_DIR")}
    os.environ.setdefault("EGL_PLATFORM", "surfaceless")
    try:
        out = {}
        with tempfile.TemporaryDirectory(prefix="bench_eevee_") as tmp:
            for round_, mode in ((r, m) for r in range(rounds) for m in (modes if r % 2 == 0 else modes[::-1])):
                os.environ["MESA_SHADER_CACHE_DIR"] = str(Path(tmp) / f"mesa_cache_{mode}_{round_}")
                script = _CHILD.format(root=str(ROOT), resolution=RESOLUTION, taa=TAA_SAMPLES, mode=mode,
                                       texture=TEXTURE, texture_path=str(Path(tmp) / "skin.png"),
                                       out=str(Path(tmp) / f"{mode}.png"))
                times = dict(zip(("warm_up_s", "first_s", "again_s"), run_script(script), strict=True))
                out[mode] = {k: min(v, out.get(mode, times)[k]) for k, v in times.items()}
        return out
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def benchmarks(quick: bool) -> list[dict]:
    res = measure(rounds=1 if quick else ROUNDS)
    live, anchor = res["live"], res["principled"]

    def describe(r: dict) -> str:
        return (f"first render {r['first_s']:.1f} s, the same render again {r['again_s']:.1f} s; EEVEE's own "
                f"warm-up (Diffuse BSDF) {r['warm_up_s']:.0f} s")

    return [{"workload": f"EEVEE first render of the material, demo head {RESOLUTION}² px, {TAA_SAMPLES} TAA samples: "
                         "live group (default) vs Principled BSDF, Random Walk (Skin), texture as Base Color",
             "ours": describe(live),
             "anchor": describe(anchor),
             "ratio": f"first render {live['first_s'] / anchor['first_s']:.2f}x",
             "error": "-",
             "notes": "wall s of bpy.ops.render.render after a warm-up render with a Diffuse BSDF (EEVEE's own "
                      f"shaders), fresh process per material, least of {1 if quick else ROUNDS} rounds; "
                      + ("software OpenGL (Mesa, EGL surfaceless): compilation is far slower than on a GPU"
                         if os.environ.get("EGL_PLATFORM", "surfaceless") == "surfaceless" else "OpenGL")}]
