"""Benchmark of the skin edits' cost: the live group with its Melanin, Blood and Oxygenation inputs against the same
group built without them, side by side.

Renders: the scene, samples, seeds and fits of :mod:`training.bench.render_cost` (the demo head, 128² px, Cycles CPU
on one thread, least CPU time over rounds), one fresh Blender process per material.  Materials: Invert Skin
Albedo's default on the medium tone's texture (the live group with the edit inputs) at neutral inputs and under the
presets tan, flush and pallor (exporters.skin_edits.PRESETS), against the live group of the same table built
without the edit nodes (blender_addon.live.build_live_group without an edit table: the unedited group).  "At equal
samples" is the CPU time per sample; an edit changes the tone, hence how far light walks in it, so the edited rows
also carry the change of the physics, not only that of the nodes.  Images: the bytes the edit table's images take
in Blender (float RGBA, 16 bytes a pixel).  Operator: Invert Skin Albedo on a 4096² albedo with the edit table
shipped (training.bench.live's set-up).
"""

from __future__ import annotations

from training.bench import live as live_bench
from training.bench import render_cost

#: The live group rebuilt without the edit nodes (the same table and images).
_PLAIN = render_cost._LIVE_GROUP + """
from blender_addon import live, preferences
table = live.table_for_model(preferences.DEFAULT_MODEL)
layout, images = live.ensure_images(table)
live_node.node_tree = live.build_live_group(table, layout, images)
assert "Melanin" not in live_node.inputs
"""
_PRESET = render_cost._LIVE_GROUP + """
from exporters.skin_edits import PRESETS
for name, value in zip(("Melanin", "Blood", "Oxygenation"), PRESETS[{preset!r}].row()):
    live_node.inputs[name].default_value = float(value)
"""
PRESETS = ("tan", "flush", "pallor")
VARIANTS = {"live_plain": _PLAIN, "live_neutral": render_cost._LIVE_GROUP,
            **{f"live_{p}": _PRESET.format(preset=p) for p in PRESETS}}
MODES = ("live_plain", "live_neutral", *(f"live_{p}" for p in PRESETS))
LABELS = {"live_neutral": "live group with the edit inputs at neutral (1, 1, 0)",
          **{f"live_{p}": f"live group with the edit inputs at preset {p}" for p in PRESETS}}
#: Bytes a pixel of a float RGBA image takes in Blender.
FLOAT_RGBA_BYTES = 16


def image_megabytes() -> float:
    """MB (1e6 bytes) of the shipped edit table's images as Blender holds them."""
    from exporters import edit_table
    from training.paths import SHIPPED_EDIT_TABLE

    atlases = edit_table.load(SHIPPED_EDIT_TABLE).atlases()
    return sum(a.shape[0] * a.shape[1] * FLOAT_RGBA_BYTES for a in atlases.values()) / 1e6


def benchmarks(quick: bool) -> list[dict]:
    samples = render_cost.SAMPLES[:2] if quick else render_cost.SAMPLES
    rounds = 1 if quick else render_cost.ROUNDS
    res = render_cost.measure(MODES, samples, rounds=rounds, variants=VARIANTS)
    ref = res["live_plain"]
    rows = []
    for mode in MODES[1:]:
        ours = res[mode]
        rows.append({"workload": f"edit cost, demo head {render_cost.RESOLUTION}² px, Cycles CPU 1 thread, no "
                                 f"denoiser, {samples} spp x 2 seeds, least CPU time of {rounds} rounds: "
                                 f"{LABELS[mode]} vs the live group without edit nodes",
                     "ours": render_cost._describe(ours),
                     "anchor": render_cost._describe(ref),
                     "ratio": f"time per sample {ours['a'] / ref['a']:.2f}x (time to equal noise "
                              f"{ours['cost'] / ref['cost']:.2f}x)",
                     "error": "-",
                     "notes": "fresh process per material; CPU s from getrusage around the render; time per sample "
                              "= slope of CPU s over samples (per-render sync excluded); an edit also changes the "
                              "light's walk (the physics)"})
    size = 2048 if quick else live_bench.SIZE
    operator = live_bench.measure(size, ("live",))["live"]["operator_s"]
    rows.append({"workload": f"edit table in Blender: images the edit inputs add; Invert Skin Albedo on a {size}² "
                             "8-bit albedo with the edit table shipped",
                 "ours": f"images {image_megabytes():.2f} MB; operator {operator:.2f} s",
                 "anchor": "limits: images 8 MB, operator 2 s",
                 "ratio": "-", "error": "-",
                 "notes": "float RGBA images, 16 bytes a pixel; operator wall time in a fresh process "
                          "(training.bench.live)"})
    return rows
