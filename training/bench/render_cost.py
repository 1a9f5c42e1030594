"""Benchmark of render cost: time to equal noise of the live group against Principled BSDF Random Walk (Skin).

Scene: the demo head (training.demo_render: procedural head with ears, a back light behind the ear and a key
light, metres), ``RESOLUTION`` squared px, Cycles CPU on one thread, denoiser off, the medium tone's albedo
texture.  Materials: Principled BSDF with Subsurface Weight 1, Random Walk (Skin) and a skin-like radius
(:data:`SKIN_RADIUS_MM`, the mean free paths of Jensen et al. 2001's skin, in metres at Unit Scale 1); the
live group (Invert Skin Albedo's default) on the same texture; optionally its Bake mode.  Each material renders
in its own fresh Blender process, at every sample count of ``SAMPLES`` with two seeds; ``ROUNDS`` rounds (the
materials in alternating order) re-time the same deterministic renders and keep each render's least CPU time.

Noise: for two independent renders A, B at N samples (seeds 1 and 2) of the same scene, mean((A - B)^2) / 2 is
the per-pixel variance of one render, i.e. the mean squared error against the infinite-sample reference (the
renders share no bias to cancel: each material is its own reference).  RMSE is taken on linear RGB over every
pixel.  The fit RMSE(N) = c / sqrt(N) (least squares in log space, slope fixed at -1/2) and CPU seconds
t(N) = t0 + a N (least squares) give the time to reach an RMSE e as a (c / e)^2 (the per-render sync t0
excluded), so the ratio live / Principled is (a_live c_live^2) / (a_P c_P^2), whatever e.  CPU time is the
render's (training.bench.render_clock: the process's user + system time around bpy.ops.render.render less that of
the scheduler thread that waits for the render by spinning), robust to the machine being shared.

Paired timing (:func:`paired_time_per_sample`, one row per scene): the fresh processes above time each material
minutes apart, so the machine's other work moves their time ratio by 10-30 % from run to run.  One process holds
both Principled and the live group and swaps them on the objects, ``PAIRED_ROUNDS`` rounds in alternating order;
in each round each material renders at the two sample counts of ``PAIRED_SAMPLES``, the difference of the two
times over the difference of the samples being its time per sample (sync and compilation cancel).  The row gives
the median of the rounds' ratios with a bootstrap interval (training.bench.render_clock.paired_ratio) and, times the
square of the noise ratio at equal samples, the time to equal noise; that noise comes from ten seeds' renders in
the same process (:func:`noise_rmse` over all of them), where the rows above take two seeds.
"""

from __future__ import annotations

import shutil
import statistics
import tempfile
from pathlib import Path

import numpy as np

from training.bench.live import run_script
from training.bench.render_clock import paired_ratio

ROOT = Path(__file__).resolve().parents[2]
RESOLUTION = 128
SAMPLES = (8, 16, 32)
ROUNDS = 2
SEEDS = (1, 2)
TEXTURE = 256
#: Skin mean free paths (R, G, B) in mm (Jensen et al. 2001, skin 1): the Principled anchor's Subsurface Radius.
SKIN_RADIUS_MM = (3.67, 1.37, 0.68)
#: The paired timing (:func:`paired_time_per_sample`): rounds, and the two sample counts each material renders per
#: round (the difference of their times is the samples' own).
PAIRED_ROUNDS = 20
PAIRED_SAMPLES = (8, 40)
#: The paired row's noise: renders at NOISE_SAMPLES samples with each of NOISE_SEEDS (the two seeds of the rows
#: above moved the noise ratio by up to 4 % between seed pairs: five pairs gave 0.856-0.912 on the demo head).
NOISE_SAMPLES = 32
NOISE_SEEDS = tuple(range(1, 11))

#: Both children's start: the scene (``scene``: "head" or a scene of training.bench.backlit) on one render thread,
#: denoiser and adaptive sampling off, and the medium tone's albedo texture loaded as ``image``.
_SETUP = """
import json, sys, time
sys.path.insert(0, {root!r})
import bpy, numpy as np
import blender_addon
from training import demo_render
from training.demo_subject import TONES, skin_albedo_texture
from training.bench.render_clock import RenderClock
if {scene!r} == "head":
    scene, parts = demo_render._scene({resolution}, 1)
else:
    from training.bench import backlit
    scene, parts = backlit.build({scene!r}, {resolution})
scene.cycles.use_denoising = False
scene.cycles.use_adaptive_sampling = False
scene.render.threads_mode, scene.render.threads = "FIXED", 1
image = bpy.data.images.load(str(demo_render.write_image({texture_path!r},
                                  skin_albedo_texture({texture}, seed=0, base=TONES["medium"]))))
"""

_CHILD = _SETUP + """mode = {mode!r}
mat = demo_render._material("skin", image, "principled_skin" if mode == "principled" else "principled")
if mode == "principled":
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Subsurface Radius"].default_value = {radius!r}
    p.inputs["Subsurface Scale"].default_value = 0.001
demo_render._assign(parts, mat)
blender_addon.register()
if mode == "live":
    demo_render._invert(parts[0], mat)
elif mode == "bake":
    parts[0].active_material = mat
    with bpy.context.temp_override(object=parts[0], active_object=parts[0]):
        assert bpy.ops.spectral_skin.invert_albedo(mode="BAKE", storage="PACK") == {{"FINISHED"}}
{variant}
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
renders = []
for samples in {samples!r}:
    for seed in {seeds!r}:
        scene.cycles.samples, scene.cycles.seed = samples, seed
        scene.render.filepath = f"{out}/{{mode}}_{{samples}}_{{seed}}.exr"
        clock = RenderClock()
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        wall = time.perf_counter() - t0
        cpu = clock.seconds()
        renders.append({{"samples": samples, "seed": seed, "cpu_s": cpu, "wall_s": wall,
                         "path": scene.render.filepath}})
print("RESULT" + json.dumps(renders))
"""

#: The paired timing's child: both materials in one process, swapped on the scene's objects round by round (the
#: order alternating), each rendered at every sample count of ``samples`` per round; prints the render clock's
#: seconds per round, material and sample count.
_PAIRED_CHILD = _SETUP + """principled = demo_render._material("skin", image, "principled_skin")
node = principled.node_tree.nodes["Principled BSDF"]
node.inputs["Subsurface Radius"].default_value = {radius!r}
node.inputs["Subsurface Scale"].default_value = 0.001
live = demo_render._material("skin live", image, "principled")
demo_render._assign(parts, live)
blender_addon.register()
demo_render._invert(parts[0], live)
materials = {{"principled": principled, "live": live}}
times = {{mode: [] for mode in materials}}
for r in range({rounds}):
    for mode in ("principled", "live") if r % 2 == 0 else ("live", "principled"):
        demo_render._assign(parts, materials[mode])
        seconds = {{}}
        for samples in {samples!r}:
            scene.cycles.samples = samples
            clock = RenderClock()
            bpy.ops.render.render(write_still=False)
            seconds[samples] = clock.seconds()
        times[mode].append(seconds)
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.cycles.samples = {noise_samples}
noise = {{mode: [] for mode in materials}}
for mode, material in materials.items():
    demo_render._assign(parts, material)
    for seed in {noise_seeds!r}:
        scene.cycles.seed = seed
        scene.render.filepath = f"{out}/{{mode}}_{{seed}}.exr"
        bpy.ops.render.render(write_still=True)
        noise[mode].append(scene.render.filepath)
print("RESULT" + json.dumps({{"times": times, "noise": noise}}))
"""

_LIVE_GROUP = """
live_node = next(n for n in mat.node_tree.nodes
                 if n.type == "GROUP" and n.node_tree.name.startswith("Spectral Skin SSS Live"))
"""
_ONE_COMPONENT = """
mixture = next(n for n in live_node.node_tree.nodes if n.type == "GROUP" and "k1 Weight" in n.inputs)
for k in range(2, 10):
    sock = mixture.inputs.get(f"k{k} Weight")
    if sock is not None:
        for link in list(sock.links):
            live_node.node_tree.links.remove(link)
        sock.default_value = (0.0, 0.0, 0.0, 1.0)
"""
_MIXTURE = """
mixture = next(n for n in live_node.node_tree.nodes if n.type == "GROUP" and "k1 Weight" in n.inputs)
tree = mixture.node_tree
gin = next(n for n in tree.nodes if n.type == "GROUP_INPUT")
"""
_FRESNEL_COAT = """
spec = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
fresnel = tree.nodes.new("ShaderNodeFresnel")
tree.links.new(gin.outputs["IOR"], fresnel.inputs["IOR"])
glossy = tree.nodes.new("ShaderNodeBsdfGlossy")
glossy.distribution = "MULTI_GGX"
tree.links.new(gin.outputs["Roughness"], glossy.inputs["Roughness"])
coat = tree.nodes.new("ShaderNodeMixShader")
tree.links.new(fresnel.outputs["Fac"], coat.inputs["Fac"])
tree.links.new(glossy.outputs[0], coat.inputs[2])
for link in list(spec.outputs[0].links):
    tree.links.new(coat.outputs[0], link.to_socket)
tree.nodes.remove(spec)
"""
_PER_CHANNEL = """
from blender_addon import nodes as mixture_nodes
k_count = sum(1 for s in mixture.inputs if s.name.startswith("k") and s.name.endswith(" Weight"))
mixture.node_tree = mixture_nodes.build_svm_group(k_count, "per-channel mixture", design="per_channel")
"""
_OSL = """
from blender_addon import nodes as mixture_nodes
k_count = sum(1 for s in mixture.inputs if s.name.startswith("k") and s.name.endswith(" Weight"))
mixture.node_tree = mixture_nodes.build_osl_group(k_count, "OSL mixture")
scene.cycles.shading_system = True
"""
_DOUBLED = """
for node in tree.nodes:
    fac = node.inputs["Fac"] if node.type == "MIX_SHADER" else None
    source = fac.links[0].from_node if fac is not None and fac.links else None
    spill = source is not None and source.type == "MATH" and source.operation == "SUBTRACT" \
        and not source.inputs[1].links  # w - 1: a copy's share
    if spill or (source is not None and source.type == "MATH" and source.operation == "GREATER_THAN"):
        tree.links.remove(fac.links[0])
        fac.default_value = 1.0 if source.operation == "GREATER_THAN" else 1e-3
"""
_SSS = """
tree = mat.node_tree
tex = next(n for n in tree.nodes if n.type == "TEX_IMAGE")
sep = tree.nodes.new("ShaderNodeSeparateColor")
tree.links.new(tex.outputs["Color"], sep.inputs[0])
total = None
for c in {channels}:
    sss = tree.nodes.new("ShaderNodeSubsurfaceScattering")
    sss.falloff = "RANDOM_WALK"
    sss.inputs["Scale"].default_value = 0.001
    if c is None:
        tree.links.new(tex.outputs["Color"], sss.inputs["Color"])
        sss.inputs["Radius"].default_value = {radius!r}
    else:
        comb = tree.nodes.new("ShaderNodeCombineColor")
        tree.links.new(sep.outputs[c], comb.inputs[c])
        tree.links.new(comb.outputs[0], sss.inputs["Color"])
        sss.inputs["Radius"].default_value = tuple(r if i == c else 0.0 for i, r in enumerate({radius!r}))
    if total is None:
        total = sss.outputs[0]
    else:
        add = tree.nodes.new("ShaderNodeAddShader")
        tree.links.new(total, add.inputs[0])
        tree.links.new(sss.outputs[0], add.inputs[1])
        total = add.outputs[0]
tree.links.new(total, tree.nodes["Material Output"].inputs["Surface"])
"""

#: Diagnostic materials, built in the child on ``mat``.  On the plain material (texture into an untouched
#: Principled BSDF): one RGB random-walk Subsurface Scattering closure of the texture's colour and the skin radius,
#: and the same split into three single-channel closures (colour and radius non-zero in one channel), as the
#: mixture group splits each of its components.  On the live material: the coat switched off (Specular IOR Level
#: 0), every component but the first weighted 0 (Cycles skips zero-weight closures: 3 closures instead of 3K), the
#: coat as the Fresnel node's F over a white Multiscatter GGX lobe instead of the Principled specular layer, and
#: every closure's copy for the part of a weight above 1 at Fac 0.001 behind an open gate, so Cycles emits each closure
#: twice.
VARIANTS = {
    "live_no_coat": _LIVE_GROUP + "live_node.inputs['Specular IOR Level'].default_value = 0.0\n",
    "live_fresnel_coat": _LIVE_GROUP + _MIXTURE + _FRESNEL_COAT,
    "live_doubled": _LIVE_GROUP + _MIXTURE + _DOUBLED,
    "live_k1": _LIVE_GROUP + _ONE_COMPONENT,
    "live_per_channel": _LIVE_GROUP + _MIXTURE + _PER_CHANNEL,
    "live_osl": _LIVE_GROUP + _MIXTURE + _OSL,
    "sss_rgb": _SSS.replace("{channels}", "(None,)").replace("{radius!r}", repr(SKIN_RADIUS_MM)),
    "sss_split": _SSS.replace("{channels}", "(0, 1, 2)").replace("{radius!r}", repr(SKIN_RADIUS_MM)),
}


def _read_exr(path: str) -> np.ndarray:
    """Linear RGB (H, W, 3) float64 of a rendered EXR."""
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(path)
    return np.asarray(buf.get_pixels(oiio.FLOAT), np.float64)[..., :3]


def noise_rmse(*renders: np.ndarray) -> float:
    """RMSE of one render against the infinite-sample reference, from two or more independent renders (H, W, 3) of
    one scene at equal samples (different seeds): the per-pixel variance over the renders (unbiased; for two renders
    A, B it is (A - B)^2 / 2), averaged over pixels and channels, is one render's mean squared error."""
    return float(np.sqrt(np.mean(np.stack(renders).var(axis=0, ddof=1))))


def fit_cost(samples: np.ndarray, rmse: np.ndarray, cpu_s: np.ndarray) -> dict:
    """c of RMSE = c / sqrt(N), and t0, a of CPU seconds = t0 + a N; cost = a c^2 (CPU s to reach RMSE 1)."""
    c = float(np.exp(np.mean(np.log(rmse * np.sqrt(samples)))))
    a, t0 = np.polyfit(samples.astype(np.float64), cpu_s, 1)
    return {"c": c, "a": float(a), "t0": float(t0), "cost": float(a) * c * c}


def measure(modes: tuple[str, ...] = ("principled", "live"), samples: tuple[int, ...] = SAMPLES,
            resolution: int = RESOLUTION, rounds: int = ROUNDS, scene: str = "head",
            keep: Path | None = None) -> dict[str, dict]:
    """Per mode: the RMSE and CPU time per sample count and the fit (:func:`fit_cost`).  The renders are
    deterministic (fixed seeds), so repeated rounds (modes in alternating order) only re-time them: each render's
    CPU time is the least over the rounds, the one least disturbed by other work on the machine."""
    renders: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory(prefix="bench_cost_") as tmp:
        for round_ in range(rounds):
            for mode in modes if round_ % 2 == 0 else modes[::-1]:
                for r in run_script(_child_script(mode, samples, resolution, Path(tmp), scene)):
                    same = [q for q in renders.setdefault(mode, []) if q["samples"] == r["samples"]
                            and q["seed"] == r["seed"]]
                    if same:
                        same[0]["cpu_s"] = min(same[0]["cpu_s"], r["cpu_s"])
                    else:
                        renders[mode].append(r)
        if keep is not None:
            keep.mkdir(parents=True, exist_ok=True)
            for mode in modes:
                for r in renders[mode]:
                    shutil.copy(r["path"], keep / f"{scene}_{Path(r['path']).name}")
        return {mode: _fit_renders(renders[mode], samples) for mode in modes}


def paired_time_per_sample(scene: str = "head", rounds: int = PAIRED_ROUNDS, samples: tuple[int, int] = PAIRED_SAMPLES,
                           resolution: int = RESOLUTION, seeds: tuple[int, ...] = NOISE_SEEDS) -> dict:
    """Principled ("principled") and the live group ("live") in one process (:data:`_PAIRED_CHILD`): per material,
    ``"per_sample"``, the seconds per sample in each round, (t(high) - t(low)) / (high - low) of the round's renders
    at ``samples`` = (low, high), so what each render spends besides its samples (scene sync, shader compilation)
    cancels; ``"c"``, the noise constant of RMSE = c / sqrt(N) from :data:`NOISE_SAMPLES`-sample renders at every
    seed of ``seeds`` (:func:`noise_rmse` times sqrt(N)); ``"seeds"``, their number."""
    low, high = samples
    with tempfile.TemporaryDirectory(prefix="bench_paired_") as tmp:
        result = run_script(_PAIRED_CHILD.format(root=str(ROOT), scene=scene, resolution=resolution, texture=TEXTURE,
                                                 texture_path=str(Path(tmp) / "skin.png"), radius=SKIN_RADIUS_MM,
                                                 rounds=rounds, samples=(low, high), noise_samples=NOISE_SAMPLES,
                                                 noise_seeds=tuple(seeds), out=tmp))
        return {mode: {"per_sample": [(r[str(high)] - r[str(low)]) / (high - low) for r in result["times"][mode]],
                       "c": noise_rmse(*(_read_exr(path) for path in result["noise"][mode])) * NOISE_SAMPLES ** 0.5,
                       "seeds": len(seeds)}
                for mode in result["times"]}


def _child_script(mode: str, samples: tuple[int, ...], resolution: int, tmp: Path, scene: str = "head",
                  seeds: tuple[int, ...] = SEEDS, variant: str | None = None) -> str:
    """The child's script rendering ``mode`` (a material mode or a key of :data:`VARIANTS`; ``variant``: the code
    that changes the material, instead of the mode's) at each of ``samples`` and ``seeds``, in ``tmp``."""
    base = mode if mode in ("principled", "live", "bake") else "live" if mode.startswith("live_") else "plain"
    return _CHILD.format(root=str(ROOT), resolution=resolution, texture=TEXTURE, scene=scene,
                         texture_path=str(tmp / "skin.png"), mode=base, radius=SKIN_RADIUS_MM,
                         variant=VARIANTS.get(mode, "") if variant is None else variant, samples=tuple(samples),
                         seeds=tuple(seeds), out=str(tmp)).replace("{mode}_", f"{mode}_")


def _fit_renders(renders: list[dict], samples: tuple[int, ...]) -> dict:
    rows = []
    for n in samples:
        pair = [r for r in renders if r["samples"] == n]
        imgs = [_read_exr(r["path"]) for r in pair]
        cpu = float(np.mean([r["cpu_s"] for r in pair]))
        rows.append({"samples": n, "rmse": noise_rmse(*imgs), "cpu_s": cpu, "mean": float(np.mean(imgs[0]))})
    fit = fit_cost(np.array([r["samples"] for r in rows]), np.array([r["rmse"] for r in rows]),
                   np.array([r["cpu_s"] for r in rows]))
    return {"rows": rows, **fit}


#: The rows: (mode, label, anchor mode) — the live group and the baked maps against Principled Random Walk (Skin),
#: and diagnostics: the live group with the earlier single-channel closures, and the split of one RGB random-walk
#: closure into three single-channel closures.  The coat's diagnostics (VARIANTS "live_no_coat", "live_fresnel_coat",
#: "live_doubled", "live_k1") run with measure() when asked; they are not part of the default rows.
ROWS = (("live", "live group (default)", "principled"),
        ("bake", "baked maps (Bake, packed)", "principled"),
        ("live_per_channel", "live group with single-channel closures (the earlier design; diagnostic)", "principled"),
        ("live", "live group (default)", "live_per_channel"),
        ("sss_split", "3 single-channel random-walk closures (diagnostic)", "sss_rgb"))
MODES = ("principled", "live", "bake", "live_per_channel", "sss_rgb", "sss_split")
#: The back-lit scenes (training.bench.backlit): their rows and modes.
BACKLIT_ROWS = (("live", "live group (default)", "principled"),
                ("live_per_channel", "live group with single-channel closures (the earlier design; diagnostic)",
                 "principled"),
                ("live_osl", "live group with the OSL mixture: K RGB closures (OSL; diagnostic of the noise)",
                 "principled"),
                ("live", "live group (default)", "live_per_channel"))
BACKLIT_MODES = ("principled", "live", "live_per_channel", "live_osl")
LABELS = {"principled": "Principled BSDF, Random Walk (Skin), skin radius",
          "sss_rgb": "1 RGB random-walk Subsurface Scattering closure",
          "live": "the live group (default)",
          "live_per_channel": "the live group with single-channel closures"}
#: Where the 32-sample renders of the back-lit scenes go (one PNG per scene: Principled, the live group, the live
#: group with single-channel closures), to look for coloured speckle.
FIGURE = ROOT / "docs" / "figures" / "render_cost_{scene}.png"


def _describe(fit: dict) -> str:
    noise = ", ".join(f"{r['samples']}: {r['rmse']:.4f}" for r in fit["rows"])
    mean = fit["rows"][0]["mean"]
    return (f"RMSE c/sqrt(N), c = {fit['c']:.3f} (N: RMSE {noise}; image mean {mean:.3f}); "
            f"CPU {fit['a'] * 1000:.0f} ms/sample (+{fit['t0']:.2f} s per render)")


def _ratio(ours: dict, ref: dict) -> str:
    relative = ours["c"] / ref["c"] * ref["rows"][0]["mean"] / ours["rows"][0]["mean"]
    time = ours["a"] / ref["a"]
    return (f"time to equal noise {ours['cost'] / ref['cost']:.2f}x (noise at equal samples "
            f"{ours['c'] / ref['c']:.2f}x, relative to the image mean {relative:.2f}x; time per sample "
            f"{time:.2f}x); time to equal noise relative to the image mean {time * relative ** 2:.2f}x")


def _row(scene: str, samples, rounds: int, label: str, anchor: str, ours: dict, ref: dict) -> dict:
    return {"workload": f"render cost, {_where(scene)} {RESOLUTION}² px, Cycles CPU 1 thread, no denoiser, {samples} "
                        f"spp x 2 seeds, least CPU time of {rounds} rounds: {label} vs {LABELS[anchor]}",
            "ours": _describe(ours),
            "anchor": _describe(ref),
            "ratio": _ratio(ours, ref),
            "error": "-",
            "notes": "RMSE: linear RGB, all pixels, from two seeds (mean((A-B)^2)/2 = MSE against the "
                     "infinite-sample reference); CPU s of the render's threads (training.bench.render_clock); "
                     "time to equal noise = a c^2 (per-render sync excluded); fresh process per material"}


def speckle_figure(renders: Path, scene: str, samples: int, path: Path) -> Path:
    """Side by side (Principled, the live group, the live group with single-channel closures) the ``samples``-sample
    renders (seed 1) of ``scene`` kept in ``renders``, sRGB-encoded, each pixel 3 x 3: a PNG at ``path``."""
    from training import demo_render

    images = []
    for mode in ("principled", "live", "live_per_channel"):
        rgb = np.clip(_read_exr(str(renders / f"{scene}_{mode}_{samples}_1.exr")), 0.0, 1.0)
        images.append(np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * rgb ** (1.0 / 2.4) - 0.055))
    row = np.repeat(np.repeat(np.concatenate(images, axis=1), 3, axis=0), 3, axis=1)
    path.parent.mkdir(parents=True, exist_ok=True)
    return demo_render.write_image(path, np.round(row * 255.0).astype(np.uint8))


def _where(scene: str) -> str:
    return "demo head" if scene == "head" else f"{scene.replace('_', ' ').replace('backlit', 'back-lit')} scene"


def _paired_row(scene: str, rounds: int, paired: dict) -> dict:
    """The paired timing's row (:func:`paired_time_per_sample`): the live group's time per sample against
    Principled's (median of the rounds' ratios, bootstrap interval) and, times the square of the noise ratio at equal
    samples from the same process's seeded renders, its time to equal noise."""
    live, ref = paired["live"], paired["principled"]
    ratio, low, high = paired_ratio(live["per_sample"], ref["per_sample"])
    noise = live["c"] / ref["c"]
    low_n, high_n = PAIRED_SAMPLES

    def describe(m: dict) -> str:
        values = m["per_sample"]
        return f"median {1000 * statistics.median(values):.0f} ms/sample ({1000 * min(values):.0f}-" \
               f"{1000 * max(values):.0f}); noise c = {m['c']:.4f}"

    return {"workload": f"render cost, {_where(scene)} {RESOLUTION}² px, Cycles CPU 1 thread, no denoiser, time per "
                        f"sample paired in one process ({rounds} rounds, each material at {low_n} and {high_n} spp "
                        f"per round; noise from {live['seeds']} seeds at {NOISE_SAMPLES} spp): live group "
                        f"(default) vs {LABELS['principled']}",
            "ours": describe(live),
            "anchor": describe(ref),
            "ratio": f"paired time per sample {ratio:.2f}x (95 % interval {low:.2f}-{high:.2f}); noise at equal "
                     f"samples {noise:.3f}x; time to equal noise {ratio * noise ** 2:.2f}x "
                     f"({low * noise ** 2:.2f}-{high * noise ** 2:.2f})",
            "error": "-",
            "notes": "time per sample = (t(high) - t(low)) / (high - low) of each material's renders in a round "
                     "(render clock; per-render sync cancels); the two materials swapped on the objects in one "
                     "process, order alternating; median of the rounds' ratios and its bootstrap interval "
                     "(training.bench.render_clock.paired_ratio: the spread of one run's rounds, not the drift "
                     "between runs); noise: per-pixel variance over the seeds' renders, linear RGB, all pixels"}


def benchmarks(quick: bool) -> list[dict]:
    samples = SAMPLES[:2] if quick else SAMPLES
    rounds = 1 if quick else ROUNDS
    paired_rounds = 4 if quick else PAIRED_ROUNDS
    res = measure(MODES, samples, rounds=rounds)
    rows = [_row("head", samples, rounds, label, anchor, res[mode], res[anchor]) for mode, label, anchor in ROWS]
    rows.append(_paired_row("head", paired_rounds, paired_time_per_sample("head", paired_rounds)))
    from training.bench import backlit

    with tempfile.TemporaryDirectory(prefix="bench_cost_keep_") as keep:
        for scene in backlit.SCENES:
            res = measure(BACKLIT_MODES, samples, rounds=rounds, scene=scene, keep=Path(keep))
            rows += [_row(scene, samples, rounds, label, anchor, res[mode], res[anchor])
                     for mode, label, anchor in BACKLIT_ROWS]
            rows.append(_paired_row(scene, paired_rounds, paired_time_per_sample(scene, paired_rounds)))
            speckle_figure(Path(keep), scene, samples[-1], Path(str(FIGURE).format(scene=scene)))
    return rows
