"""Benchmark of the skin edits' cost: the live group with its Melanin, Blood and Oxygenation inputs against the same
group built without them, side by side.

Renders: the demo head (training.demo_render, ``RESOLUTION`` squared px, Cycles CPU on one thread, denoiser off,
``SAMPLES`` samples) with the medium tone's albedo texture through Invert Skin Albedo's default (the live group with the
edit inputs). One Blender process renders, ``ROUNDS`` times in turn, the live group of the same table built without the
edit nodes (blender_addon.live.build_live_group without an edit table: the unedited group) and the group with the edit
inputs at neutral, under the presets tan, flush and pallor (exporters.skin_edits.PRESETS) and every control between
two of its table's levels (:data:`EDITS`, "three"), each set as the add-on sets it (read from the edit group's cache),
and that edit read from the table ("three_table": the most lookups an edit makes; a node whose edit is not cached) and
from a spare cache ("three_spare": an atlas of the mask cache's images, as a thirteenth to fifteenth constant edit of a
file), and edits painted by a mask (:data:`MASKED`: through the Edit Mask, from the mask cache; fed to each control,
from the table) or keyframed along a line and rendered at a frame no cache holds (:data:`KEYED`: from the mask
cache), swapping the material's group between renders; each round starts one material later than the one
before, so that no material always follows the swap from the other group.
Each render's CPU time (training.bench.render_clock, scene sync included) is kept. The ratio is paired: each render
against the unedited group's render of the same round, the median of the rounds' ratios with a 95 % bootstrap interval
(training.bench.render_clock.paired_ratio; the ratio of the medians of all renders moved by 10 % between runs). Equal
samples, so an edited row also carries the change of the physics (an edit changes how far light walks in the tone), not
only the nodes' cost. Images: the bytes the edit table's images and its caches, all filled, take in Blender (float
RGBA, 16 bytes a pixel).
Operator: Invert Skin Albedo on a 4096² albedo with the edit table shipped (training.bench.live's set-up).
"""

from __future__ import annotations

import statistics
import tempfile
from pathlib import Path

from exporters import skin_edits
from exporters.cli_io import OneLineParser
from training.bench import live as live_bench
from training.bench.render_clock import paired_ratio

ROOT = Path(__file__).resolve().parents[2]
RESOLUTION = 128
SAMPLES = 16
ROUNDS = 40
TEXTURE = 256
PRESETS = ("tan", "flush", "pallor")
#: The edits timed (Melanin, Blood, Oxygenation): the presets and every control between two levels of the edit
#: table (exporters.edit_table.LEVELS: log2 1.5 = 0.58 between 0.5 and 1; log2 2.5 = 1.32 between 1 and 1.5; -0.2
#: between -0.25 and -0.125), each set as the add-on sets it (blender_addon.live_edits.set_edit: read from a cache,
#: two images at two slices); and that edit read from the table ("three_table": 24 lookups, the most an edit makes;
#: what a node renders whose edit is not cached: inputs fed by a mask, more constant edits than caches).
EDITS: dict[str, tuple[float, float, float]] = {
    **{p: tuple(float(v) for v in skin_edits.PRESETS[p].row()) for p in PRESETS},
    "three": (1.5, 2.5, -0.2), "three_table": (1.5, 2.5, -0.2), "three_spare": (1.5, 2.5, -0.2),
    **{mode: tuple(float(v) for v in skin_edits.PRESETS["flush"].row())
       for mode in ("flush_mask", "flush_linked", "flush_frame", "flush_frame_table")},
    "blood_linked": (1.0, 2.5, 0.0)}
#: The edits read from the table (their node's cache input left at 0).
UNCACHED = ("three_table",)
#: The edits held in a spare cache (:data:`SPARE_CODE`).
SPARE = ("three_spare",)
#: The edits painted by a mask (:data:`MASK_CODE`): through the group's Edit Mask (read from the mask cache), or
#: fed to each control the edit moves (read from the table, as every control fed by a node).
MASKED = {"flush_mask": False, "flush_linked": True, "blood_linked": True}
#: The edits keyframed (:data:`KEY_CODE`): from as painted at frame 1 to the edit at frame 21 on every control, the
#: render at frame 11 with no frame's edit cached, as Blender's interface renders an animation (its frames evaluated
#: outside the main thread): from the mask cache, which the add-on's handlers make hold the keys' line
#: (blender_addon.live_edits.hold_line; True), or with the mask cache holding no edit, from the table (False).
KEYED = {"flush_frame": True, "flush_frame_table": False}
#: What the edits besides the presets are, in the rows' labels.
DESCRIPTIONS = {"three": "every control between two levels, from its cache",
                "three_table": "every control between two levels, read from the table (not cached)",
                "three_spare": "every control between two levels, from a spare cache (the mask cache's images)",
                "flush_mask": "flush painted by the Edit Mask (the albedo's red), from the mask cache",
                "flush_linked": "flush painted by a mask fed to each control (the albedo's red), read from the table",
                "blood_linked": "Blood alone painted by a mask fed to it (the albedo's red), read from the table",
                "flush_frame": "flush keyframed from as painted (frame 1) to the preset (frame 21), frame 11 with no "
                               "frame cached (as the interface renders an animation), from the mask cache's line",
                "flush_frame_table": "the same frame with the mask cache holding no edit, read from the table"}
#: Blender code (in a bench child with the material ``mat``, its albedo image ``image`` and exporters.skin_edits'
#: NEUTRAL imported): ``mask_edit(node, edit, each)`` paints the edit with a mask, the albedo's red channel (a
#: per-texel value, as a painted mask is): linked to the group's Edit Mask, or (``each``) feeding each control the
#: edit moves neutral + mask x (value - neutral) through Math nodes of the material (bake.py's mask convention);
#: ``unmask(node)`` removes the links again.
MASK_CODE = """
def mask_edit(node, edit, each):
    tree = mat.node_tree
    tex = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeTexImage" and n.image == image)
    sep = tree.nodes.new("ShaderNodeSeparateColor")
    tree.links.new(tex.outputs["Color"], sep.inputs[0])
    if not each:
        tree.links.new(sep.outputs[0], node.inputs["Edit Mask"])
        return
    for name, value, neutral in zip(("Melanin", "Blood", "Oxygenation"), edit, NEUTRAL):
        if value != neutral:
            math = tree.nodes.new("ShaderNodeMath")
            math.operation = "MULTIPLY_ADD"
            tree.links.new(sep.outputs[0], math.inputs[0])
            math.inputs[1].default_value, math.inputs[2].default_value = value - neutral, neutral
            tree.links.new(math.outputs[0], node.inputs[name])


def unmask(node):
    for link in list(mat.node_tree.links):
        if link.to_node == node and link.to_socket.name in ("Melanin", "Blood", "Oxygenation", "Edit Mask"):
            mat.node_tree.links.remove(link)
"""
#: Blender code (as :data:`MASK_CODE`'s, with the bench child's ``scene``): ``key_edit(node, edit)`` keyframes the
#: node's controls from neutral at frame 1 to ``edit`` at frame 21, holds the keys' line in the mask cache as the
#: add-on's handlers do (``hold``; else empties the mask cache), and goes to frame 11; ``unkey()`` removes the
#: material's keyframes again.
KEY_CODE = """
def key_edit(node, edit, hold):
    scene.frame_start, scene.frame_end = 1, 21
    for frame, row in ((1, NEUTRAL), (21, edit)):
        for name, value in zip(("Melanin", "Blood", "Oxygenation"), row):
            node.inputs[name].default_value = value
            node.inputs[name].keyframe_insert("default_value", frame=frame)
    if hold:
        assert live_edits.hold_line(node, scene)
    else:
        live_edits.empty_mask_cache(node.node_tree)
    scene.frame_set(11)


def unkey():
    mat.node_tree.animation_data_clear()
"""
#: Blender code (in a bench child, ``live_edits`` imported): ``spare_edit(node, edit)`` sets the edit and holds it in
#: the last spare cache (blender_addon.live_edits.SPARE_SLOTS), where the add-on puts a file's fifteenth constant edit
#: while the mask cache holds no line, and points the node at it; ``unspare(node)`` empties that cache again, so that
#: the other modes' edits of the same values take their own caches.
SPARE_CODE = """
def spare_edit(node, edit):
    live_edits.set_edit(node, edit, cache=False)
    group = live_edits._edit_group(node.node_tree)
    slot = live_edits.SPARE_SLOTS[-1]
    live_edits._fill(group, live_edits._group_images(node.node_tree), slot, live_edits.cache_key(node))
    node.inputs["Edit Cache"].default_value = slot


def unspare(node):
    group = live_edits._edit_group(node.node_tree)
    slot = live_edits.SPARE_SLOTS[-1]
    live_edits._set_cached_values(group, slot, (float("nan"),) * len(live_edits._cache_inputs(slot)))
"""
MODES = ("plain", "neutral", *EDITS)
#: Bytes a pixel of a float RGBA image takes in Blender.
FLOAT_RGBA_BYTES = 16

_CHILD = """
import json, sys
sys.path.insert(0, {root!r})
import bpy
import blender_addon
from blender_addon import live, live_edits, preferences
from exporters.skin_edits import NEUTRAL
from training import demo_render
from training.demo_subject import TONES, skin_albedo_texture
from training.bench.render_clock import RenderClock
scene, parts = demo_render._scene({resolution}, {samples})
scene.cycles.use_denoising = False
scene.cycles.use_adaptive_sampling = False
scene.render.threads_mode, scene.render.threads = "FIXED", 1
image = bpy.data.images.load(str(demo_render.write_image({texture_path!r},
                                  skin_albedo_texture({texture}, seed=0, base=TONES["medium"]))))
mat = demo_render._material("skin", image, "principled")
demo_render._assign(parts, mat)
blender_addon.register()
live_edits.unregister_handlers()  # each mode's cache input as set_edit leaves it
demo_render._invert(parts[0], mat)
node = live_edits.live_node(mat)
edited = node.node_tree
table = live.table_for_model(preferences.DEFAULT_MODEL)
layout, images = live.ensure_images(table)
plain = live.build_live_group(table, layout, images)
values = {{"neutral": NEUTRAL, **{edits!r}}}
modes = {modes!r}
times = {{mode: [] for mode in modes}}
{mask_code}
{key_code}
{spare_code}
for r in range({rounds}):
    for mode in modes[r % len(modes):] + modes[:r % len(modes)]:  # each round one material later
        node.node_tree = plain if mode == "plain" else edited
        if mode != "plain":
            unmask(node)
            unkey()
            unspare(node)
        if mode in {spare!r}:
            spare_edit(node, values[mode])
        elif mode in {keyed!r}:
            key_edit(node, values[mode], {keyed!r}[mode])
            live_edits.set_edit(node, tuple(node.inputs[n].default_value for n in ("Melanin", "Blood", "Oxygenation")),
                                cache=False)
        else:
            if mode in {masked!r}:
                mask_edit(node, values[mode], {masked!r}[mode])
            live_edits.set_edit(node, values.get(mode, NEUTRAL), cache=mode not in {uncached!r})  # plain: nothing
        clock = RenderClock()
        bpy.ops.render.render(write_still=False)
        times[mode].append(clock.seconds())
print("RESULT" + json.dumps(times))
"""


def selected_modes(wanted: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The modes to render for ``wanted`` (names from :data:`MODES`; empty: all), in :data:`MODES`' order, the
    unedited group ("plain", the anchor of every ratio) always first.  ValueError naming an unknown mode."""
    unknown = [mode for mode in wanted if mode not in MODES]
    if unknown:
        raise ValueError(f"unknown edit-cost mode(s) {', '.join(unknown)}: choose from {', '.join(MODES[1:])}")
    return tuple(mode for mode in MODES if mode == "plain" or not wanted or mode in wanted)


def measure(rounds: int = ROUNDS, samples: int = SAMPLES, resolution: int = RESOLUTION,
            modes: tuple[str, ...] = ()) -> dict[str, list[float]]:
    """CPU seconds of each render, per mode (:func:`selected_modes` of ``modes``: by default all of :data:`MODES`),
    the modes in turn in one process."""
    modes = selected_modes(modes)
    edits = {mode: EDITS[mode] for mode in modes if mode in EDITS}
    with tempfile.TemporaryDirectory(prefix="bench_edit_") as tmp:
        return live_bench.run_script(_CHILD.format(root=str(ROOT), resolution=resolution, samples=samples,
                                                   texture=TEXTURE, texture_path=str(Path(tmp) / "skin.png"),
                                                   edits=edits, modes=modes, rounds=rounds,
                                                   uncached=UNCACHED, masked=MASKED, mask_code=MASK_CODE,
                                                   keyed=KEYED, key_code=KEY_CODE, spare=SPARE,
                                                   spare_code=SPARE_CODE))


def image_megabytes() -> float:
    """MB (1e6 bytes) of the shipped edit table's images as Blender holds them."""
    from exporters import edit_table
    from training.paths import SHIPPED_EDIT_TABLE

    atlases = edit_table.load(SHIPPED_EDIT_TABLE).atlases()
    table = sum(a.shape[0] * a.shape[1] * FLOAT_RGBA_BYTES for a in atlases.values())
    one = next(iter(atlases.values()))  # a constant edit's cache: one atlas of each kind; the mask cache's: three
    atlas = one.shape[0] // edit_table.STACKED * one.shape[1]
    caches = (edit_table.CACHE_SLOTS + edit_table.MASK_POINTS) * len(edit_table.KINDS) * atlas
    return (table + caches * FLOAT_RGBA_BYTES) / 1e6


def _label(mode: str) -> str:
    if mode == "neutral":
        return "at neutral (1, 1, 0)"
    if mode in DESCRIPTIONS:
        return "at ({:g}, {:g}, {:g}): {}".format(*EDITS[mode], DESCRIPTIONS[mode])
    return f"at preset {mode}"


def benchmarks(quick: bool) -> list[dict]:
    rounds = 3 if quick else ROUNDS
    times = measure(rounds)
    ref = statistics.median(times["plain"])
    rows = []
    for mode in MODES[1:]:
        ours = statistics.median(times[mode])
        ratio, low, high = paired_ratio(times[mode], times["plain"])
        spread = f"{min(times[mode]):.2f}-{max(times[mode]):.2f}"
        rows.append({"workload": f"edit cost, demo head {RESOLUTION}² px, Cycles CPU 1 thread, no denoiser, {SAMPLES} "
                                 f"spp, {rounds} rounds in turn in one process: live group with the edit inputs "
                                 f"{_label(mode)} vs the live group without edit nodes",
                     "ours": f"median {ours:.2f} CPU-s per render ({spread})",
                     "anchor": f"median {ref:.2f} CPU-s per render ({min(times['plain']):.2f}-"
                               f"{max(times['plain']):.2f})",
                     "ratio": f"time at equal samples {ratio:.3f}x (95 % interval {low:.3f}-{high:.3f})",
                     "error": f"ratio of the medians {ours / ref:.3f}x",
                     "notes": "CPU s of each render's threads (training.bench.render_clock, scene sync "
                              "included); paired: median of each round's ratio to the unedited group's render "
                              "of the same round, bootstrap interval of that median; an edit also changes the "
                              "light's walk (the physics)"})
    size = 2048 if quick else live_bench.SIZE
    setup = live_bench.measure(size, ("live",))["live"]
    rows.append({"workload": f"edit table in Blender: images the edit inputs add; Invert Skin Albedo on a {size}² "
                             "8-bit albedo with the edit table shipped",
                 "ours": f"images {image_megabytes():.2f} MB; operator {setup['operator_s']:.2f} s wall "
                         f"({setup['operator_cpu_s']:.2f} CPU-s)",
                 "anchor": "limits: images 8 MB, operator 2 s",
                 "ratio": "-", "error": "-",
                 "notes": "float RGBA images, 16 bytes a pixel; operator wall and process CPU time in a fresh "
                          "process (training.bench.live; CPU time counts every thread, the inference's too)"})
    return rows


def main(argv: list[str] | None = None) -> int:
    """Time some of the edit modes over more rounds than the bench's, without writing bench/results.md: e.g. the
    masked rows over sixty rounds (``python -m training.bench.edit_cost --rounds 60 neutral flush_linked
    blood_linked flush_mask``).  Prints each mode's paired ratio to the unedited group with its 95 % interval."""
    parser = OneLineParser(prog="python -m training.bench.edit_cost", description=main.__doc__)
    parser.add_argument("modes", nargs="*", metavar="MODE", help=f"modes to time (default all): {', '.join(MODES[1:])}")
    parser.add_argument("--rounds", type=int, default=ROUNDS, help=f"rounds of every mode in turn (default {ROUNDS})")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds must be at least 1, not {args.rounds}")
    try:
        modes = selected_modes(tuple(args.modes))
    except ValueError as err:
        parser.error(str(err))
    times = measure(args.rounds, modes=modes)
    anchor = times["plain"]
    print(f"unedited group: median {statistics.median(anchor):.2f} CPU-s per render, {args.rounds} round(s)")
    for mode in modes[1:]:
        ratio, low, high = paired_ratio(times[mode], anchor)
        print(f"{mode}: {ratio:.3f}x (95 % interval {low:.3f}-{high:.3f}), median {statistics.median(times[mode]):.2f}"
              f" CPU-s; {_label(mode)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
