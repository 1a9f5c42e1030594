"""Grazing light in a render: the live group in Cycles against the oblique Monte Carlo, without and with the
grazing-light correction (exporters.oblique_correction).

* :func:`slab` — the probe block (blender_addon.probe: a block 1 m deep at 1 BU = 1 cm, a uniform white world,
  an orthographic camera) painted one tone's colour through the live group, seen from polar angles 0, 45, 70, 85
  degrees.  By reciprocity the radiance seen from angle theta under a uniform white world is the reflectance of a
  beam arriving at theta, the quantity the Monte Carlo (``training.validate.oblique``) walks: the skin's body
  reflectance R_d(theta) is the render less the render of the same group painted black (its specular coat alone;
  black takes every weight to 0).  The Monte Carlo's skin is semi-infinite (a finite epidermis over a
  semi-infinite dermis), so the block is deep, not thin.
* :func:`head` — the demo head (training.demo_subject) painted the demo's dark tone, lit from behind and grazing
  (the demo's lights): the live group without and with the correction, and their difference.

``python -m training.oblique_render --out docs/validation`` writes ``oblique_render.json`` and
``fig_oblique_render.png``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from exporters.colorimetry import linear_srgb_to_lab
from training.paths import SHIPPED_MODEL_DIR
from training.validate import oblique, oblique_fit

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "blender_addon" / "models" / "skin_inversion.onnx"
#: The block's unit scale (m per BU) and the view angles rendered (degrees).
UNIT_SCALE_M = 0.01
VIEW_DEG: tuple[float, ...] = oblique.THETAS_DEG
#: Seeds of walks not fitted (``training.validate.oblique --seed``): the renders are compared with their truth too,
#: where they are cached.
HELD_OUT_SEEDS: tuple[int, ...] = (1, 2)
#: The thin slab: thickness (mm), tones; the emitting plane that lights it (side and height, BU).
THIN_MM = 2.0
THIN_TONES: tuple[str, ...] = ("R01", "R05", "R08", "R09")
SKY_SIDE_BU, SKY_HEIGHT_BU = 4000.0, 2.0
#: Tones rendered on the block.
SLAB_TONES: tuple[str, ...] = ("R01", "R05", "R07", "R08", "R09", "R10")


def _bpy():
    import bpy

    return bpy


def live_groups():
    """The live group of the shipped table without and with the grazing-light correction (no edit inputs)."""
    from blender_addon import live

    table = live.table_for_model(str(MODEL))
    return live.ensure_live_group(table, None, grazing=False), live.ensure_live_group(table, None, grazing=True)


def _slab_node(group, colour) -> object:
    from blender_addon import probe

    mat = probe.slab_material("Oblique slab")
    node = mat.node_tree.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    node.inputs["Color"].default_value = (*map(float, colour), 1.0)
    node.inputs["Unit Scale"].default_value = UNIT_SCALE_M
    mat.node_tree.links.new(node.outputs["Cycles"], probe.material_output(mat).inputs["Surface"])
    return node


def thin_scene(scene, thickness_bu: float) -> None:
    """Make the probe's block a slab ``thickness_bu`` thick (its top face where the block's was) lit from above only:
    the world black, a square emitting plane of radiance 1 and side ``SKY_SIDE_BU`` ``SKY_HEIGHT_BU`` above it
    (reaching 89.9 degrees from the normal), invisible to the camera.  Seen from angle theta the slab's radiance
    is then its reflectance of a beam arriving at theta, what crosses the slab being lost below."""
    import mathutils

    from blender_addon import probe

    bpy = _bpy()
    block = bpy.data.objects["ProbeSlab"]
    mesh = probe.cube_mesh("ThinSlab", 1.0)
    mesh.transform(mathutils.Matrix.Diagonal((probe.HALF_SIZE_BU, probe.HALF_SIZE_BU, thickness_bu / 2.0, 1.0)))
    block.data = mesh
    block.location = (0.0, 0.0, -thickness_bu / 2.0)
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    sky_mesh = bpy.data.meshes.new("Sky")
    h = SKY_SIDE_BU / 2.0
    sky_mesh.from_pydata([(-h, -h, 0.0), (h, -h, 0.0), (h, h, 0.0), (-h, h, 0.0)], [], [(0, 3, 2, 1)])
    sky = bpy.data.objects.new("Sky", sky_mesh)
    sky.location = (0.0, 0.0, SKY_HEIGHT_BU)
    sky.visible_camera = False
    mat = bpy.data.materials.new("Sky")
    tree = mat.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    tree.links.new(emission.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    sky_mesh.materials.append(mat)
    scene.collection.objects.link(sky)


def thin_walks(tones, thetas, thickness_cm: float, photons: int, cache: Path, seed: int = 0) -> dict:
    """(tone, theta) -> {"truth_R", "mix_R", "truth_T", "mix_T"} (W,): the two-layer skin of total thickness
    ``thickness_cm`` (the epidermis over dermis of the rest) and the mixture's components as homogeneous slabs of
    that thickness, under a beam at theta (training.validate.oblique's walk, its wavelengths), cached per walk."""
    cache.mkdir(parents=True, exist_ok=True)
    decoder = SHIPPED_MODEL_DIR / "skin_decoder.onnx"
    out = {}
    for name, tone in zip(tones.names, tones.values, strict=True):
        for theta in thetas:
            path = cache / f"{name}_{theta:g}_{thickness_cm * 10:g}mm_{photons}_s{seed}.npz"
            if not path.is_file():
                m = oblique.tone_media(tone, decoder, oblique.columns())
                truth = oblique._walk(m["mua"], m["mus"], m["g"], np.array([float(tone[2]), thickness_cm - tone[2]]),
                                      photons, theta, seed)
                comp = oblique._walk(m["mix_mua"], m["mix_mus"], m["mix_g"], np.array([thickness_cm]), photons, theta,
                                     seed + 1)
                w = m["weight"]
                res = {"truth_R": truth["R_d"], "truth_T": truth["T_d"],
                       "mix_R": np.sum(w * comp["R_d"].reshape(w.shape), axis=0),
                       "mix_T": np.sum(w * comp["T_d"].reshape(w.shape), axis=0)}
                tmp = path.with_suffix(".part.npz")
                np.savez_compressed(tmp, **res)
                tmp.replace(path)
            with np.load(path) as f:
                out[(name, float(theta))] = {k: f[k] for k in f.files}
    return out


def slab(colours: dict[str, np.ndarray], samples: int = 128, resolution: int = 12, views=VIEW_DEG, seed: int = 5,
         corrected: bool = True, thickness_bu: float | None = None) -> dict:
    """Rendered linear RGB of the block seen from each of ``views`` (degrees): {"coat": (A, 3), tone: {"shipped":
    (A, 3), "corrected": (A, 3) (with ``corrected``), "stderr": (A, 3)}} (the coat: the group painted black; the
    live group without the grazing-light correction is "shipped"), and the seconds."""
    from blender_addon import probe

    scene = probe.new_scene(samples=samples, resolution=resolution, seed=seed)
    if thickness_bu is not None:
        thin_scene(scene, thickness_bu)
    shipped, with_correction = live_groups()
    out: dict = {"views_deg": list(views)}
    start = time.perf_counter()

    def render(group, colour) -> tuple[np.ndarray, np.ndarray]:
        _slab_node(group, colour)
        got = []
        for theta in views:
            probe.view_from(scene, float(np.cos(np.radians(theta))))
            got.append(probe.render_mean(scene)[:2])
        return np.array([g[0] for g in got]), np.array([g[1] for g in got])

    out["coat"] = render(shipped, (0.0, 0.0, 0.0))[0].tolist()
    for name, colour in colours.items():
        s, err = render(shipped, colour)
        out[name] = {"colour": list(map(float, colour)), "shipped": s.tolist(), "stderr": err.tolist()}
        if corrected:
            out[name]["corrected"] = render(with_correction, colour)[0].tolist()
    out["seconds"] = time.perf_counter() - start
    return out


def compare(render: dict, runs: dict) -> list[dict]:
    """Per (tone, angle) walked and rendered: the rendered body reflectance (render less coat) as shipped and
    corrected, and the Monte Carlo's truth and mixture (linear sRGB), with Delta E76 of each against the truth."""
    rows = []
    for (name, theta), body in oblique_fit.bodies(render).items():
        if (name, theta) not in runs:
            continue
        walk = runs[(name, theta)]
        truth, mix = oblique_fit.rgb(walk["truth_R"]), oblique_fit.rgb(walk["mix_R"])
        lab_t = linear_srgb_to_lab(truth)

        def de(v: np.ndarray, lab_t=lab_t) -> float:
            return float(np.linalg.norm(linear_srgb_to_lab(np.clip(v, 1e-6, None)) - lab_t))

        row = {"tone": name, "theta_deg": theta, "truth": truth.tolist(), "mc_mix": mix.tolist(),
               "dE76_mc_mix": de(mix)}
        for k, v in body.items():
            row[f"render_{k}"] = v.tolist()
            row[f"dE76_render_{k}"] = de(v)
        rows.append(row)
    return rows


def head(tmp: Path, samples: int = 32, size: int = 96, tone: str = "dark") -> dict:
    """The demo head painted ``tone`` through the live group without and with the correction (linear renders)."""
    import blender_addon
    from blender_addon import live
    from training import demo_render, openpbr_check
    from training.demo_subject import TONES, skin_albedo_texture

    png = demo_render.write_image(tmp / f"head_{tone}.png", skin_albedo_texture(64, 0, TONES[tone]))
    scene, parts = demo_render._scene(size, samples)
    scene.cycles.use_denoising = False
    mat = openpbr_check.live_material("Live head", png, 0.5, 1.4)
    blender_addon.register()
    try:
        openpbr_check.invert_live(parts[0], mat)
    finally:
        blender_addon.unregister()
    demo_render._assign(parts, mat)
    node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeGroup"
                and n.node_tree.name.startswith(live.GROUP_NAME))
    corrected = node.node_tree
    table = live.table_for_model(str(MODEL))
    edits = live.live_edits.table_for_model(str(MODEL), table.sha256)
    shipped = live.ensure_live_group(table, edits, grazing=False)
    out = {}
    for label, group in (("shipped", shipped), ("corrected", corrected)):
        node.node_tree = group
        out[label] = openpbr_check._render_linear(scene, tmp / f"head_{label}.exr")
    out["facing"] = _facing(scene, parts, tmp / "head_facing.exr")
    return out


def _facing(scene, parts, path: Path) -> np.ndarray:
    """(H, W) the mean of 1 - |N . I| (Layer Weight's Facing, what the correction reads) over each pixel of the
    head (0 where the camera sees no head): an emission-only render, no world, no denoising."""
    from training import demo_render, openpbr_check

    bpy = _bpy()
    mat = bpy.data.materials.new("Facing")
    tree = mat.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    layer = tree.nodes.new("ShaderNodeLayerWeight")
    layer.inputs["Blend"].default_value = 0.5
    emission = tree.nodes.new("ShaderNodeEmission")
    tree.links.new(layer.outputs["Facing"], emission.inputs["Color"])
    tree.links.new(emission.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    demo_render._assign(parts, mat)
    saved = (scene.cycles.samples, scene.world)
    scene.cycles.samples, scene.world = 16, None
    try:
        return openpbr_check._render_linear(scene, path)[..., 0]
    finally:
        scene.cycles.samples, scene.world = saved


#: Bands of the head's pixels by the facing angle (degrees from the view) that :func:`rim_numbers` reports.
FACING_BANDS: tuple[tuple[float, float], ...] = ((0.0, 45.0), (45.0, 70.0), (70.0, 90.0))


def rim_numbers(heads: dict) -> list[dict]:
    """Per band of ``FACING_BANDS``: the head's pixels, their mean linear colour as shipped and corrected and the
    Delta E76 between the two means."""
    facing = heads["facing"]
    rows = []
    for lo, hi in FACING_BANDS:
        f_lo, f_hi = 1.0 - np.cos(np.radians(lo)), 1.0 - np.cos(np.radians(hi))
        mask = (facing > max(f_lo, 1e-4)) & (facing <= f_hi) if lo == 0.0 else (facing > f_lo) & (facing <= f_hi)
        means = {k: heads[k][mask].mean(axis=0) for k in ("shipped", "corrected")}
        rows.append({"band_deg": [lo, hi], "pixels": int(mask.sum()),
                     **{k: v.tolist() for k, v in means.items()},
                     "dE76": float(np.linalg.norm(linear_srgb_to_lab(means["shipped"])
                                                  - linear_srgb_to_lab(means["corrected"])))})
    return rows


def figure(rows: list[dict], heads: dict, path: Path) -> Path:
    """Left: swatches of the block's body colour per tone (rows) and view angle (groups of four: the Monte Carlo's
    truth and mixture, the render as shipped and corrected), each row scaled alike (its truth at 0 degrees to 0.8);
    middle: Delta E76 of the renders against the truth; right: the dark head as shipped, corrected, difference."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from exporters.colorimetry import srgb_encode

    tones = list(dict.fromkeys(r["tone"] for r in rows))
    cols = ("truth", "mc_mix", "render_shipped", "render_corrected")
    width = len(cols) + 1
    img = np.ones((len(tones), len(VIEW_DEG) * width, 3))
    for r in rows:
        i, j = tones.index(r["tone"]), VIEW_DEG.index(r["theta_deg"])
        top = max(next(q for q in rows if q["tone"] == r["tone"] and q["theta_deg"] == 0.0)["truth"])
        for c, key in enumerate(cols):
            img[i, j * width + c] = srgb_encode(np.clip(np.asarray(r[key]) * 0.8 / top, 0.0, 1.0))
    fig = plt.figure(figsize=(17, 5.0))
    ax = fig.add_axes([0.03, 0.1, 0.3, 0.8])
    ax.imshow(img, aspect="auto", interpolation="nearest")
    ax.set_yticks(range(len(tones)), tones)
    ax.set_xticks([j * width + 1.5 for j in range(len(VIEW_DEG))], [f"θ = {t:g}°" for t in VIEW_DEG])
    ax.set_title("block, white world, seen at θ: MC truth | MC mixture | render | render corrected", fontsize=8)
    ax = fig.add_axes([0.37, 0.1, 0.17, 0.8])
    for n, tone in enumerate(tones):
        rr = [r for r in rows if r["tone"] == tone]
        th = [r["theta_deg"] for r in rr]
        ax.plot(th, [r["dE76_render_shipped"] for r in rr], "o-", color=f"C{n}", label=f"{tone} render")
        ax.plot(th, [r["dE76_render_corrected"] for r in rr], "s--", color=f"C{n}", label=f"{tone} corrected")
    ax.axhline(1.0, color="grey", lw=0.8, ls=":")
    ax.set(xlabel="view angle θ (°)", ylabel="ΔE76 render vs Monte Carlo truth")
    ax.legend(fontsize=6, ncol=2)
    for k, label in enumerate(("shipped", "corrected", "difference")):
        a = fig.add_axes([0.57 + 0.14 * k, 0.1, 0.13, 0.8])
        if label == "difference":
            a.imshow(np.clip((heads["corrected"] - heads["shipped"]) * 20.0 + 0.5, 0, 1), interpolation="nearest")
            a.set_title("corrected − shipped (×20, grey = 0)", fontsize=8)
        else:
            a.imshow(srgb_encode(np.clip(heads[label] * 3.0, 0, 1)), interpolation="nearest")
            a.set_title(f"dark head, live group {label} (×3)", fontsize=8)
        a.axis("off")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m training.oblique_render", description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, required=True, help="folder for oblique_render.json and the figure")
    p.add_argument("--samples", type=int, default=256, help="Cycles samples per pixel of the block")
    p.add_argument("--resolution", type=int, default=16, help="pixels across the block's view")
    p.add_argument("--seed", type=int, default=5, help="Cycles seed of the block")
    p.add_argument("--views", default=",".join(f"{t:g}" for t in VIEW_DEG), help="view angles, degrees")
    p.add_argument("--head-samples", type=int, default=32)
    p.add_argument("--tones", default=",".join(SLAB_TONES))
    p.add_argument("--shipped-only", action="store_true",
                   help="render the block without the correction only (what oblique_fit --render reads); no head")
    p.add_argument("--name", default="oblique_render", help="stem of the JSON and of the figure (fig_<stem>.png)")
    p.add_argument("--cache", type=Path, default=oblique.DEFAULT_CACHE, help="the oblique walks (10,000 photons)")
    p.add_argument("--thin-mm", type=float, default=None,
                   help="render a slab this thick (mm) lit from above only, against the Monte Carlo of that slab "
                   f"(walked here into CACHE/thin; tones {','.join(THIN_TONES)} unless --tones is given)")
    p.add_argument("--photons", type=int, default=10000, help="photons per wavelength of the thin slab's walks")
    args = p.parse_args(argv)
    decoder = SHIPPED_MODEL_DIR / "skin_decoder.onnx"
    if args.thin_mm is not None:
        return _thin(args, decoder)
    try:
        tones = oblique_fit._tones(args.tones)
        views = tuple(float(v) for v in args.views.split(","))
        runs = oblique.run(tones, decoder, 10000, args.cache, 0, log=lambda s: print(s, file=sys.stderr))
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    runs |= oblique_fit.cached_runs(args.cache, tones.names, views)
    colours = dict(zip(tones.names, oblique_fit.tone_colours(tones, decoder), strict=True))
    args.out.mkdir(parents=True, exist_ok=True)
    render = slab(colours, args.samples, args.resolution, views, args.seed, corrected=not args.shipped_only)
    rows = compare(render, runs)
    held_out = {f"rows_truth_seed{s}": compare(render, oblique_fit.cached_runs(args.cache, tones.names, views, seed=s))
                for s in HELD_OUT_SEEDS}
    (args.out / f"{args.name}.json").write_text(json.dumps(
        {"samples": args.samples, "resolution": args.resolution, "seed": args.seed, "render": render, "rows": rows,
         **held_out}, indent=1))
    if not args.shipped_only:
        with tempfile.TemporaryDirectory(prefix="oblique_head_") as tmp:
            heads = head(Path(tmp), args.head_samples)
        figure([r for r in rows if r["theta_deg"] in VIEW_DEG], heads, args.out / f"fig_{args.name}.png")
        result = json.loads((args.out / f"{args.name}.json").read_text())
        result["head"] = {"samples": args.head_samples, "bands": rim_numbers(heads)}
        (args.out / f"{args.name}.json").write_text(json.dumps(result, indent=1))
        for band in result["head"]["bands"]:
            print(f"head, facing {band['band_deg']}: {band['pixels']} px, dE76 shipped vs corrected "
                  f"{band['dE76']:.2f}")
    for r in rows:
        print(f"{r['tone']} {r['theta_deg']:g}: dE76 MC mix {r['dE76_mc_mix']:.2f}, render "
              + " -> ".join(f"{r[f'dE76_render_{k}']:.2f}" for k in ("shipped", "corrected") if f"render_{k}" in r))
    return 0


def _thin(args, decoder: Path) -> int:
    """``--thin-mm``: the thin slab's walks, renders and comparison (``<name>_thin.json``)."""
    try:
        if not 0.2 <= args.thin_mm <= 20.0:
            raise ValueError("--thin-mm must lie in [0.2, 20] (the epidermis is up to 0.15 mm thick)")
        tones = oblique_fit._tones(args.tones if args.tones != ",".join(SLAB_TONES) else ",".join(THIN_TONES))
        views = tuple(float(v) for v in args.views.split(","))
        runs = thin_walks(tones, views, args.thin_mm / 10.0, args.photons, args.cache / "thin")
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    colours = dict(zip(tones.names, oblique_fit.tone_colours(tones, decoder), strict=True))
    render = slab(colours, args.samples, args.resolution, views, args.seed, thickness_bu=args.thin_mm / 10.0)
    rows = compare(render, runs)
    for r in rows:
        walk = runs[(r["tone"], r["theta_deg"])]
        r["truth_T"], r["mc_mix_T"] = (oblique_fit.rgb(walk[k]).tolist() for k in ("truth_T", "mix_T"))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}_thin.json").write_text(json.dumps(
        {"thickness_mm": args.thin_mm, "photons": args.photons, "samples": args.samples, "seed": args.seed,
         "render": render, "rows": rows}, indent=1))
    for r in rows:
        print(f"{r['tone']} {r['theta_deg']:g}: dE76 MC mix {r['dE76_mc_mix']:.2f}, render "
              f"{r['dE76_render_shipped']:.2f} -> {r['dE76_render_corrected']:.2f}; truth R "
              f"{np.round(r['truth'], 4).tolist()} T {np.round(r['truth_T'], 4).tolist()}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
