"""What drawing a fed control's texels does to a render (blender_addon.live_edits, "Controls fed by nodes"): the flush
painted by a mask fed to each control it moves (the albedo's red, training.bench.edit_cost.MASK_CODE), the demo head
rendered with the controls' texels drawn per sample (the node flagged as the add-on flags it) and interpolated (the
node unflagged: cache input 0), in one Blender process.

* **bias**: the mean over the skin's pixels (linear RGB above 0.02) of a long render drawn against one interpolated,
  per channel, beside the same for two interpolated renders of other seeds (the renders' own noise);
* **noise**: the RMS error of short renders against the mean of the two long interpolated ones, per seed, drawn and
  interpolated.

``python -m training.bench.edit_draws`` prints them (the skin-edit page quotes a run).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from exporters.cli_io import OneLineParser
from training.bench import edit_cost
from training.bench import live as live_bench

ROOT = Path(__file__).resolve().parents[2]

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
edit = tuple(float(v) for v in PRESETS["flush"].row())
mask_edit(node, edit, True)
live_edits.set_edit(node, edit)
flags = node.inputs["Edit Cache"].default_value


def render(cache, samples, seed):
    node.inputs["Edit Cache"].default_value = cache
    scene.cycles.samples, scene.cycles.seed = samples, seed
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = {folder!r} + f"/r_{{cache}}_{{samples}}_{{seed}}.exr"
    bpy.ops.render.render(write_still=True)
    return oiio.ImageBuf(scene.render.filepath).get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)


first, drawn, second = render(0, {long}, 100), render(flags, {long}, 101), render(0, {long}, 102)
skin = first.mean(axis=-1) > 0.02
reference = 0.5 * (first + second)
out = {{"flags": flags,
        "bias": (drawn[skin].mean(axis=0) / first[skin].mean(axis=0) - 1).tolist(),
        "seeds": (second[skin].mean(axis=0) / first[skin].mean(axis=0) - 1).tolist()}}
for label, cache in (("interpolated", 0), ("drawn", flags)):
    out[label] = [float(np.sqrt(((render(cache, {short}, s) - reference)[skin] ** 2).mean())) for s in range({seeds})]
print("RESULT" + json.dumps(out))
"""


def measure(resolution: int = 128, long: int = 1024, short: int = 16, seeds: int = 4, texture: int = 256) -> dict:
    """The bias and noise of drawn texels against interpolated ones (module docstring): ``flags`` (the node's cache
    input), ``bias`` and ``seeds`` (3 relative differences of the skin's mean), ``interpolated`` and ``drawn`` (RMS
    errors of ``seeds`` renders of ``short`` samples against the ``long`` ones)."""
    with tempfile.TemporaryDirectory(prefix="bench_draws_") as tmp:
        return live_bench.run_script(_CHILD.format(root=str(ROOT), resolution=resolution, long=long, short=short,
                                                   seeds=seeds, texture=texture, folder=tmp,
                                                   mask_code=edit_cost.MASK_CODE))


def main(argv: list[str] | None = None) -> int:
    """Print the bias and noise of drawn texels (module docstring)."""
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
    print(f"flags on the node: {out['flags']:g}")
    print("bias, drawn against interpolated (R, G, B): " + ", ".join(f"{100 * v:+.2f} %" for v in out["bias"]))
    print("two interpolated seeds (R, G, B): " + ", ".join(f"{100 * v:+.2f} %" for v in out["seeds"]))
    for label in ("interpolated", "drawn"):
        print(f"RMS error at {args.short} samples, {label}: " + ", ".join(f"{v:.4f}" for v in out[label]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
