"""Benchmark of the live node group against Principled BSDF and baked maps (collected by `python -m training bench`).

One skin-like sRGB albedo (``SIZE`` squared, 8-bit, smooth colour variation so nearly every texel differs) on a UV
sphere with a key and a back light, 200 x 200 px, Cycles CPU, ``SAMPLES`` samples, denoiser off.  Three materials of
the same scene: the artist's Principled BSDF on the albedo (anchor), Invert Skin Albedo's default (the live group)
and its Bake mode (maps packed into the .blend, the default storage).  Each setup runs in its own process, which saves
the .blend; each render runs in another fresh process that opens it, so its peak resident memory (ru_maxrss) is the
render's alone (the process's peak, ru_maxrss, and the largest "Mem" of Cycles' render statistics: the memory of the
render itself).  Operator time is wall time of the operator call, with its CPU time on the calling thread (the
critical path: the live group's operator reads the albedo and makes the table's atlases on worker threads meanwhile)
and in all threads.

A further row renders three skins appended into one file from a file each, as an artist appends characters: with
the add-on's merge (one copy of its groups and tables per file, blender_addon.merge), without it, and as the artists'
Principled BSDFs.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SIZE = 4096
SAMPLES = 16
RESOLUTION = 200

_SETUP = """
import json, sys, time
sys.path.insert(0, {root!r})
import bpy, numpy as np
import blender_addon
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = "CPU", {samples}, False
scene.cycles.use_adaptive_sampling = False
scene.render.resolution_x = scene.render.resolution_y = {resolution}
scene.unit_settings.system, scene.unit_settings.scale_length = "METRIC", 0.1
bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=1.0)
obj = bpy.context.active_object
bpy.ops.object.shade_smooth()
mat = bpy.data.materials.new("Skin")
obj.data.materials.append(mat)
tree = mat.node_tree
tex = tree.nodes.new("ShaderNodeTexImage")
tex.image = bpy.data.images.load({albedo!r})
tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
tree.nodes.active = tex
cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
cam.location, cam.rotation_euler = (0.0, -4.0, 0.0), (np.pi / 2, 0.0, 0.0)
scene.collection.objects.link(cam)
scene.camera = cam
for name, loc, energy in (("Key", (3.0, -3.0, 2.0), 800.0), ("Back", (-1.0, 3.0, 0.5), 600.0)):
    light = bpy.data.objects.new(name, bpy.data.lights.new(name, "POINT"))
    light.location, light.data.energy = loc, energy
    scene.collection.objects.link(light)
seconds = cpu = thread = 0.0
if {mode!r} != "principled":
    blender_addon.register()
    t0, c0, m0 = time.perf_counter(), time.process_time(), time.thread_time()
    with bpy.context.temp_override(object=obj, active_object=obj):
        assert bpy.ops.spectral_skin.invert_albedo(mode={mode!r}.upper(), backend="SVM") == {{"FINISHED"}}
    seconds, cpu, thread = time.perf_counter() - t0, time.process_time() - c0, time.thread_time() - m0
bpy.ops.wm.save_as_mainfile(filepath={blend!r})
print("RESULT" + json.dumps({{"operator_s": seconds, "operator_cpu_s": cpu, "operator_thread_s": thread}}))
"""

_RENDER = """
import json, re, resource, sys, time
import bpy
bpy.ops.wm.open_mainfile(filepath={blend!r})
scene = bpy.context.scene
scene.render.filepath = {out!r}
stats = []
bpy.app.handlers.render_stats.append(lambda text: stats.append(text))
t0 = time.perf_counter()
bpy.ops.render.render(write_still=True)
seconds = time.perf_counter() - t0
peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
found = [m for text in stats for m in re.findall(r"Mem: *([0-9.]+)([MG])", text)]
sizes = [float(v) * (1024 if unit == "G" else 1) for v, unit in found]
cycles_peak = max(sizes or [float("nan")])
print("RESULT" + json.dumps({{"render_s": seconds, "peak_mb": peak_mb, "cycles_peak_mb": cycles_peak}}))
"""


#: Three skins, each from a file of its own, appended into the first file on spheres beside its own (File > Append as
#: an artist appends characters): ``merge`` True with the add-on on (it keeps one copy of its groups and tables),
#: False with its merge handlers off (Blender's own append: a copy per file).
_APPEND = """
import json, sys
sys.path.insert(0, {root!r})
import bpy
import blender_addon
from blender_addon import merge
blender_addon.register()
if not {merge!r}:
    merge.unregister_handlers()
bpy.ops.wm.open_mainfile(filepath={first!r})
obj = bpy.data.objects["Sphere"]
for i, path in enumerate({others!r}):
    with bpy.data.libraries.load(path) as (_, target):
        target.materials = ["Skin"]
    copy = obj.copy()
    copy.data = obj.data.copy()
    bpy.context.scene.collection.objects.link(copy)
    copy.location.x += 2.2 * (i + 1)
    copy.data.materials.clear()
    copy.data.materials.append(target.materials[0])
    bpy.context.view_layer.update()
merge.remove_merged()  # the timer of Blender's main loop, which this process has not
bpy.ops.wm.save_as_mainfile(filepath={blend!r})
print("RESULT" + json.dumps({{"groups": len(bpy.data.node_groups)}}))
"""


def appended(size: int = 1024, skins: int = 3) -> dict[str, dict]:
    """Cycles' and the process's peak memory rendering ``skins`` skin materials appended from a file each (albedo
    ``size`` squared): the live group with the add-on's merge (``merged``), without it (``copies``), and the
    artists' Principled BSDFs (``principled``), each render in a fresh process."""
    out = {}
    with tempfile.TemporaryDirectory(prefix="bench_appended_") as tmp:
        folder = Path(tmp)
        files: dict[str, list[str]] = {"live": [], "principled": []}
        for i in range(skins):
            albedo = skin_albedo(folder / f"albedo{i}.png", size)
            for mode, paths in files.items():
                paths.append(str(folder / f"{mode}{i}.blend"))
                run_script(_SETUP.format(root=str(ROOT), samples=SAMPLES, resolution=RESOLUTION, albedo=str(albedo),
                                         mode=mode, blend=paths[-1]))
        for name, mode, merge in (("merged", "live", True), ("copies", "live", False),
                                  ("principled", "principled", True)):
            blend = str(folder / f"{name}.blend")
            setup = run_script(_APPEND.format(root=str(ROOT), merge=merge, first=files[mode][0],
                                              others=files[mode][1:], blend=blend))
            render = run_script(_RENDER.format(blend=blend, out=str(folder / f"{name}.png")))
            out[name] = {**setup, **render, "blend_mb": os.path.getsize(blend) / 2 ** 20}
    return out


def _appended_row() -> dict:
    size, skins = 1024, 3
    res = appended(size, skins)
    merged, copies, anchor = res["merged"], res["copies"], res["principled"]

    def peaks(r: dict) -> str:
        return f"Cycles' own peak {r['cycles_peak_mb']:.0f} MB"

    return {"workload": f"{skins} skins appended from a file each ({size}² albedo), {RESOLUTION}² px @ {SAMPLES} spp, "
                        "Cycles CPU: live group, one copy of the add-on's tables per file (merged) vs "
                        "Principled BSDF",
            "ours": f"{peaks(merged)}, {merged['groups']} node groups, .blend {merged['blend_mb']:.0f} MB; without "
                    f"the merge: {peaks(copies)}, {copies['groups']} node groups, .blend {copies['blend_mb']:.0f} MB",
            "anchor": f"Principled: {peaks(anchor)}",
            "ratio": f"Cycles memory {merged['cycles_peak_mb'] / anchor['cycles_peak_mb']:.2f}x (without the "
                     f"merge {copies['cycles_peak_mb'] / anchor['cycles_peak_mb']:.2f}x)",
            "error": "-",
            "notes": "the skins appended in one process (bpy.data.libraries.load), rendered in a fresh one; "
                     "shared 2-core machine"}


def skin_albedo(path: Path, size: int) -> Path:
    """A smooth skin-coloured 8-bit sRGB texture (size, size, 3): blends of light and dark skin."""
    import OpenImageIO as oiio

    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    t = 0.5 + 0.25 * np.sin(9.0 * x + 3.0 * np.cos(7.0 * y)) + 0.2 * np.sin(31.0 * y + 5.0 * x)
    light, dark = np.array([226, 180, 158], np.float32), np.array([110, 66, 48], np.float32)
    red = 1.0 + 0.08 * np.sin(53.0 * x * y)[..., None] * np.array([1.0, -0.5, -0.5], np.float32)
    pixels = np.clip((light + (dark - light) * np.clip(t, 0, 1)[..., None]) * red, 0, 255).astype(np.uint8)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(size, size, 3, "uint8"))
    out.write_image(pixels)
    out.close()
    return path


def run_script(script: str, prefix: tuple[str, ...] = ()):
    """Run ``script`` in a fresh Python process with the repository on its path (``prefix``: a command the process
    runs under, e.g. a profiler's); returns the JSON value its ``RESULT`` line carries (RuntimeError with the
    process's output when there is none)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run([*prefix, sys.executable, "-c", script], capture_output=True, text=True, env=env,
                          timeout=1800)
    line = next((ln for ln in done.stdout.splitlines() if ln.startswith("RESULT")), None)
    if line is None:
        raise RuntimeError(f"benchmark subprocess failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
    return json.loads(line[len("RESULT"):])


def measure(size: int = SIZE, modes: tuple[str, ...] = ("principled", "live", "bake")) -> dict[str, dict]:
    """Operator time, render time and render peak memory of each mode (in fresh processes)."""
    out = {}
    with tempfile.TemporaryDirectory(prefix="bench_live_") as tmp:
        albedo = skin_albedo(Path(tmp) / "albedo.png", size)
        for mode in modes:
            blend = str(Path(tmp) / f"{mode}.blend")
            setup = run_script(_SETUP.format(root=str(ROOT), samples=SAMPLES, resolution=RESOLUTION, albedo=str(albedo),
                                       mode=mode, blend=blend))
            render = run_script(_RENDER.format(blend=blend, out=str(Path(tmp) / f"{mode}.png")))
            out[mode] = {**setup, **render, "blend_mb": os.path.getsize(blend) / 2 ** 20}
    return out


def benchmarks(quick: bool) -> list[dict]:
    size = 2048 if quick else SIZE
    res = measure(size)
    anchor = res["principled"]
    rows = []
    for mode, label in (("live", "live group (default)"), ("bake", "baked maps (Bake, packed)")):
        r = res[mode]
        rows.append({"workload": f"{size}² 8-bit albedo on a sphere, {RESOLUTION}² px @ {SAMPLES} spp, Cycles CPU: "
                                 f"{label} vs Principled BSDF",
                     "ours": f"process peak {r['peak_mb']:.0f} MB (Cycles' own peak {r['cycles_peak_mb']:.0f} MB), "
                             f"render {r['render_s']:.1f} s, operator {r['operator_s']:.2f} s wall (CPU "
                             f"{r['operator_thread_s']:.2f} s on the calling thread, {r['operator_cpu_s']:.2f} s in "
                             f"all), .blend {r['blend_mb']:.0f} MB",
                     "anchor": f"Principled: process peak {anchor['peak_mb']:.0f} MB (Cycles' own peak "
                               f"{anchor['cycles_peak_mb']:.0f} MB), render {anchor['render_s']:.1f} s, .blend "
                               f"{anchor['blend_mb']:.0f} MB",
                     "ratio": f"process memory {r['peak_mb'] / anchor['peak_mb']:.2f}x (Cycles "
                              f"{r['cycles_peak_mb'] / anchor['cycles_peak_mb']:.2f}x), "
                              f"time {r['render_s'] / anchor['render_s']:.2f}x",
                     "error": "-",
                     "notes": "fresh process per setup and per render (ru_maxrss); render time includes scene sync "
                              "and image loading; shared 2-core machine"})
    rows.append(_appended_row())
    return rows
