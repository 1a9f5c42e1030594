"""What drawing the table's texels does to a render (blender_addon.live_edits, "Drawn texels"): the demo head
rendered, in one Blender process, with an edit read from the table (its texels drawn per sample) and with the same
edit from a cache (interpolated), in two cases:

* **constant**: every control between two levels (:data:`CONSTANT`), from the table (the node's cache input 0, as a
  file's sixteenth constant edit) against from its own cache, which holds the table's interpolated answer exactly;
* **fed**: the flush painted by a mask (the albedo's red, training.bench.edit_cost.MASK_CODE) fed to each control it
  moves, from the table, against the same mask through the Edit Mask, from the mask cache (whose answer lies within
  a few thousandths of the table's).

Per case:

* **bias**: the mean over the skin's pixels (linear RGB above 0.02) of a long render drawn against one cached, per
  channel, beside the same for two cached renders of other seeds (the renders' own noise);
* **noise**: the RMS error of short renders against the mean of the two long cached ones, per seed, cached and drawn.

``python -m training.bench.edit_draws`` prints them (the skin-edit page quotes a run).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from exporters.cli_io import OneLineParser
from training.bench import edit_cost
from training.bench import live as live_bench

ROOT = Path(__file__).resolve().parents[2]

#: The constant edit of the constant case (Melanin, Blood, Oxygenation): every control between two levels.
CONSTANT = (1.5, 2.5, -0.2)
#: The cases (module docstring) and what each compares, as the bench prints them.
CASES = {"constant": f"every control between two levels {CONSTANT}: drawn from the table, against its cache",
         "fed": "flush painted by a mask fed to each control: drawn from the table, against Edit Mask's mask cache"}

_CHILD = """
import json, sys
sys.path.insert(0, {root!r})
import bpy
import numpy as np
import OpenImageIO as oiio
import blender_addon
from blender_addon import live_edits
from exporters.skin_edits import NEUTRAL, PRESETS
from training import demo_render
from training.demo_subject import TONES, skin_albedo_texture
scene, parts = demo_render._scene({resolution}, 1)
scene.cycles.use_denoising = False
scene.cycles.use_adaptive_sampling = False
image = bpy.data.images.load(str(demo_render.write_image({folder!r} + "/skin.png",
                                  skin_albedo_texture({texture}, seed=0, base=TONES["medium"]))))
mat = demo_render._material("skin", image, "principled")
demo_render._assign(parts, mat)
blender_addon.register()
live_edits.unregister_handlers()
demo_render._invert(parts[0], mat)
node = live_edits.live_node(mat)
{mask_code}
flush = tuple(float(v) for v in PRESETS["flush"].row())


def constant(drawn):
    live_edits.set_edit(node, {constant!r})
    if drawn:
        node.inputs["Edit Cache"].default_value = 0


def fed(drawn):
    unmask(node)
    live_edits.set_edit(node, NEUTRAL)
    mask_edit(node, flush, drawn)
    live_edits.set_edit(node, flush)


def render(setup, drawn, samples, seed):
    setup(drawn)
    scene.cycles.samples, scene.cycles.seed = samples, seed
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = {folder!r} + f"/r_{{setup.__name__}}_{{drawn}}_{{samples}}_{{seed}}.exr"
    bpy.ops.render.render(write_still=True)
    return oiio.ImageBuf(scene.render.filepath).get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)


out = {{}}
for setup in (constant, fed):
    first, drawn, second = (render(setup, False, {long}, 100), render(setup, True, {long}, 101),
                            render(setup, False, {long}, 102))
    setup(True)
    case = {{"cache input": node.inputs["Edit Cache"].default_value}}
    skin = first.mean(axis=-1) > 0.02
    reference = 0.5 * (first + second)
    case["bias"] = (drawn[skin].mean(axis=0) / first[skin].mean(axis=0) - 1).tolist()
    case["seeds"] = (second[skin].mean(axis=0) / first[skin].mean(axis=0) - 1).tolist()
    for label, drawn in (("cached", False), ("drawn", True)):
        case[label] = [float(np.sqrt(((render(setup, drawn, {short}, s) - reference)[skin] ** 2).mean()))
                       for s in range({seeds})]
    out[setup.__name__] = case
print("RESULT" + json.dumps(out))
"""


def measure(resolution: int = 128, long: int = 1024, short: int = 16, seeds: int = 4, texture: int = 256) -> dict:
    """The bias and noise of drawn texels against cached ones (module docstring), per case (:data:`CASES`): ``cache
    input`` (the node's, drawn), ``bias`` and ``seeds`` (3 relative differences of the skin's mean), ``cached`` and
    ``drawn`` (RMS errors of ``seeds`` renders of ``short`` samples against the ``long`` ones)."""
    with tempfile.TemporaryDirectory(prefix="bench_draws_") as tmp:
        return live_bench.run_script(_CHILD.format(root=str(ROOT), resolution=resolution, long=long, short=short,
                                                   seeds=seeds, texture=texture, folder=tmp,
                                                   mask_code=edit_cost.MASK_CODE, constant=CONSTANT))


def main(argv: list[str] | None = None) -> int:
    """Print the bias and noise of drawn texels in each case (module docstring)."""
    parser = OneLineParser(prog="python -m training.bench.edit_draws", description=main.__doc__)
    parser.add_argument("--resolution", type=int, default=128, help="square render size in pixels (default 128)")
    parser.add_argument("--long", type=int, default=1024, help="samples of the long renders (default 1024)")
    parser.add_argument("--short", type=int, default=16, help="samples of the short renders (default 16)")
    parser.add_argument("--seeds", type=int, default=4, help="short renders per path (default 4)")
    args = parser.parse_args(argv)
    for name in ("resolution", "long", "short", "seeds"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be at least 1, not {getattr(args, name)}")
    out = measure(args.resolution, args.long, args.short, args.seeds)
    for name, case in out.items():
        print(f"{CASES[name]} (cache input {case['cache input']:g})")
        print("  bias, drawn against cached (R, G, B): " + ", ".join(f"{100 * v:+.2f} %" for v in case["bias"]))
        print("  two cached seeds (R, G, B): " + ", ".join(f"{100 * v:+.2f} %" for v in case["seeds"]))
        for label in ("cached", "drawn"):
            print(f"  RMS error at {args.short} samples, {label}: " + ", ".join(f"{v:.4f}" for v in case[label]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
