"""Benchmark of render cost in counted work: instructions and shader-node dispatches per sample, under Callgrind.

Time per sample on a shared machine moves by 3-40 % from run to run (docs/user/live_group.md, render cost); what a
render executes does not.  This module renders the scenes of :mod:`training.bench.render_cost` (the demo head,
``RESOLUTION`` squared px, ``SAMPLES`` samples, one seed, Cycles CPU on one thread) under Valgrind's Callgrind
(``valgrind --tool=callgrind``, counting only inside Cycles' path-tracing work,
``ccl::PathTraceWorkCPU::render_samples_full_pipeline``: scene sync, BVH build and shader compilation are left out)
and reads from its output, per material:

* **instructions** executed per camera sample (every pixel's sample; the counts are the same in every run);
* of those, **shading**: everything Cycles' shader virtual machine runs (``ccl::svm_eval_nodes`` and what it calls:
  texture reads, curves, closure set-up), and **walks**: the random walks inside the skin
  (``ccl::integrator_intersect_subsurface`` and what it calls, ray casts included);
* **SVM dispatches**: how many nodes the shader virtual machine executes per shading evaluation.  Its loop reads and
  dispatches one node per pass, so the instruction at the loop's head is the one executed most often in
  ``svm_eval_nodes``: its count is the number of dispatches (``--dump-instr=yes``).  Besides the graph's nodes that
  count holds the loads of the nodes' unlinked inputs (Cycles' SVM compiler gives each unlinked input of a node it
  compiles a node of its own that writes the value to the stack, unused inputs included, such as a Vector Math
  node's Scale);
* **evaluations**: how often a shader was evaluated (the calls of ``svm_eval_nodes``).

Materials: Principled BSDF Random Walk (Skin) (the anchor of :mod:`training.bench.render_cost`), the Bake mode's
maps, the live group (Invert Skin Albedo's default, edit inputs at neutral) and the live group under each edit of
training.bench.edit_cost.EDITS (the presets tan, flush and pallor and every control between two levels, each read from
its cache as the add-on sets it, and that edit read from the table; the masked edits of edit_cost.MASKED and a frame of
a keyframed flush no cache holds, edit_cost.KEYED: an edit's cost against the group at neutral).
Instructions are not time: a walk's ray casts wait on memory where the node loop does not, so the live group's
instruction ratio is larger than its time ratio; what the counts give is a change's effect without the machine's
noise.  Needs ``valgrind`` on the PATH (about 100 s per material, two at a time); without it the rows say so.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from training.bench import edit_cost, render_cost
from training.bench.live import run_script

RESOLUTION = render_cost.RESOLUTION
SAMPLES = 4
#: Callgrind's counting: only inside this function (and what it calls), Cycles' CPU path-tracing work.
COUNTED = "ccl::PathTraceWorkCPU::render_samples_full_pipeline*"
#: The functions (a part of their names, as Callgrind writes them) whose inclusive counts are reported.
SHADING = "ccl::svm_eval_nodes<"
WALKS = "ccl::integrator_intersect_subsurface("
#: The live group's edit inputs set to an edit (after Invert Skin Albedo), as the child's variant code; ``{edit}`` is
#: its (Melanin, Blood, Oxygenation).
_EDIT = """
from blender_addon import live_edits
live_edits.unregister_handlers()  # the cache input as set_edit leaves it
live_edits.set_edit(live_edits.live_node(mat), {edit!r}, cache={cache!r})
"""
#: The edits counted against the live group at neutral: those the edit cost bench times.
EDITS = edit_cost.EDITS


#: A keyframed edit (edit_cost.KEYED) at a frame no cache holds, as the child's variant code: its keys (and the
#: mask cache's line, or none) by edit_cost.KEY_CODE, the node's cache input then left at 0 as a frame the
#: interface renders finds it.
_KEYED = """
from blender_addon import live_edits
from exporters.skin_edits import NEUTRAL
live_edits.unregister_handlers()
node = live_edits.live_node(mat)
{key_code}
key_edit(node, {edit!r}, {hold!r})
live_edits.set_edit(node, tuple(node.inputs[n].default_value for n in ("Melanin", "Blood", "Oxygenation")), cache=False)
"""


def _variant(name: str, edit: tuple[float, float, float]) -> str:
    """The child's code setting the edit ``name``; a masked one's mask (edit_cost.MASK_CODE) linked first, so that
    set_edit caches it as the add-on does; a keyframed one's keys (:data:`_KEYED`); one held in a spare cache by
    edit_cost.SPARE_CODE."""
    if name in edit_cost.KEYED:
        return _KEYED.format(key_code=edit_cost.KEY_CODE, edit=edit, hold=edit_cost.KEYED[name])
    if name in edit_cost.SPARE:
        return ("from blender_addon import live_edits\nlive_edits.unregister_handlers()\n" + edit_cost.SPARE_CODE
                + f"spare_edit(live_edits.live_node(mat), {edit!r})\n")
    code = _EDIT.format(edit=edit, cache=name not in edit_cost.UNCACHED)
    if name in edit_cost.MASKED:
        image = ("image = next(n.image for n in mat.node_tree.nodes if n.bl_idname == 'ShaderNodeTexImage' "
                 "and n.image is not None and not n.image.name.startswith('Spectral Skin SSS'))\n")
        code = ("from blender_addon import live_edits\nfrom exporters.skin_edits import NEUTRAL\n" + image
                + edit_cost.MASK_CODE + f"mask_edit(live_edits.live_node(mat), {edit!r}, "
                f"{edit_cost.MASKED[name]!r})\n" + code)
    return code


#: Materials: (name, render_cost mode, variant code or None for the mode's own).
MATERIALS = (("principled", "principled", None), ("bake", "bake", None), ("live", "live", None),
             *((f"live_{name}", f"live_{name}", _variant(name, edit)) for name, edit in EDITS.items()))


@dataclass
class Counts:
    """What one render executed: instructions in all (``total``), inside the shader VM (``shading``) and inside the
    random walks (``walks``), the VM's node dispatches and its evaluations."""

    total: int
    shading: int
    walks: int
    dispatches: int
    evaluations: int


def _position(token: str, previous: int) -> int:
    """A Callgrind position: absolute (decimal or 0x hex), relative (+n, -n) or the same (*)."""
    if token == "*":
        return previous
    if token[0] in "+-":
        return previous + int(token, 0)
    return int(token, 0)


def parse(path: str | os.PathLike) -> Counts:
    """The :class:`Counts` of a Callgrind output file (event Ir, written with ``--dump-instr=yes``).  A function's
    inclusive cost is its own cost plus the costs of the calls it makes (each call line carries its callee's inclusive
    cost); the dispatches are the largest count of one instruction in any ``svm_eval_nodes`` (its loop's head)."""
    names: dict[str, str] = {}
    own: dict[str, int] = {}
    called: dict[str, int] = {}
    counts: dict[tuple[str, int], int] = {}
    evaluations = total = 0
    fn = ""
    columns = 1
    address = 0
    call_line = False
    callee = ""
    with open(path) as fh:
        for line in fh:
            if line.startswith("positions:"):
                columns = len(line.split()) - 1
            elif line.startswith(("totals:", "summary:")):
                total = max(total, int(line.split()[1]))
            elif line.startswith(("fn=", "cfn=")):
                key, _, rest = line.rstrip("\n").partition("=")
                ident, _, name = rest.partition(" ")
                if name:
                    names[ident] = name
                if key == "fn":
                    fn = names.get(ident, ident)
                else:
                    callee = names.get(ident, ident)
            elif line.startswith("calls="):
                call_line = True
                if SHADING in callee:
                    evaluations += int(line.split("=")[1].split()[0])
            elif line[:1] in "0123456789+-*":
                parts = line.split()
                if len(parts) <= columns:
                    continue
                address = _position(parts[0], address)
                cost = int(parts[columns])
                if call_line:
                    called[fn] = called.get(fn, 0) + cost
                    call_line = False
                else:
                    own[fn] = own.get(fn, 0) + cost
                    if SHADING in fn:
                        counts[(fn, address)] = counts.get((fn, address), 0) + cost
    def inclusive(name: str) -> int:
        return sum(own.get(f, 0) + called.get(f, 0) for f in set(own) | set(called) if name in f)
    return Counts(total=total, shading=inclusive(SHADING), walks=inclusive(WALKS),
                  dispatches=max(counts.values(), default=0), evaluations=evaluations)


def _run(name: str, mode: str, variant: str | None, tmp: Path) -> Counts:
    """Render one material under Callgrind in ``tmp`` (its own folder: the child writes its texture there)."""
    tmp.mkdir(parents=True, exist_ok=True)
    script = render_cost._child_script(mode, (SAMPLES,), RESOLUTION, tmp, seeds=(1,), variant=variant)
    out = tmp / "callgrind.out"
    run_script(script, ("valgrind", "--tool=callgrind", "--dump-instr=yes", "--collect-atstart=no",
                        f"--toggle-collect={COUNTED}", f"--callgrind-out-file={out}"))
    if not out.is_file():
        raise RuntimeError(f"callgrind wrote no output for {name} ({out})")
    return parse(out)


def measure(materials=MATERIALS) -> dict[str, Counts]:
    """:class:`Counts` of every material of ``materials`` ((name, mode, variant) triples), two runs at a time."""
    with tempfile.TemporaryDirectory(prefix="bench_instructions_") as tmp, ThreadPoolExecutor(2) as pool:
        jobs = {name: pool.submit(_run, name, mode, variant, Path(tmp) / name) for name, mode, variant in materials}
        return {name: job.result() for name, job in jobs.items()}


def _per_evaluation(c: Counts) -> float:
    return c.dispatches / max(c.evaluations, 1)


def _describe(c: Counts, samples: int) -> str:
    return (f"{c.total / samples:,.0f} instructions per camera sample (shading {c.shading / samples:,.0f}, walks "
            f"{c.walks / samples:,.0f}); {_per_evaluation(c):.1f} SVM dispatches per shading "
            f"evaluation ({c.evaluations:,} evaluations)")


def _row(label: str, anchor_label: str, ours: Counts, ref: Counts, samples: int) -> dict:
    return {"workload": f"counted work, demo head {RESOLUTION}² px @ {SAMPLES} spp, 1 seed, Cycles CPU 1 thread, under "
                        f"Callgrind: {label} vs {anchor_label}",
            "ours": _describe(ours, samples),
            "anchor": _describe(ref, samples),
            "ratio": f"instructions {ours.total / ref.total:.3f}x (shading {ours.shading / max(ref.shading, 1):.2f}x, "
                     f"walks {ours.walks / max(ref.walks, 1):.2f}x); SVM dispatches per evaluation "
                     f"{_per_evaluation(ours) / max(_per_evaluation(ref), 1e-9):.2f}x",
            "error": "- (deterministic: the same counts in every run)",
            "notes": "valgrind --tool=callgrind --dump-instr=yes, counting inside "
                     "PathTraceWorkCPU::render_samples_full_pipeline; dispatches: the count of the SVM loop's head; "
                     "instructions are not time (walks wait on memory, the node loop on its jumps)"}


def _edit_label(name: str) -> str:
    if name in edit_cost.PRESETS:
        return f"live group under the {name} preset"
    return "live group at ({:g}, {:g}, {:g}), {}".format(*EDITS[name], edit_cost.DESCRIPTIONS[name])


#: The rows: (material, label, anchor material, anchor label).
ROWS = (("live", "live group (default)", "principled", "Principled BSDF, Random Walk (Skin), skin radius"),
        ("bake", "baked maps (Bake, packed)", "principled", "Principled BSDF, Random Walk (Skin), skin radius"),
        *((f"live_{name}", _edit_label(name), "live", "the live group (edit inputs at neutral)") for name in EDITS))


def benchmarks(quick: bool) -> list[dict]:
    if shutil.which("valgrind") is None:
        return [{"workload": "counted work under Callgrind", "ours": "-", "anchor": "-", "ratio": "-", "error": "-",
                 "notes": "skipped: valgrind is not installed (apt install valgrind)"}]
    res = measure()
    samples = RESOLUTION * RESOLUTION * SAMPLES
    return [_row(label, anchor_label, res[name], res[anchor], samples) for name, label, anchor, anchor_label in ROWS]


def main() -> None:
    """Print the counts of the materials named on the command line (default: all), e.g. to compare two builds."""
    wanted = set(sys.argv[1:]) or {m[0] for m in MATERIALS}
    samples = RESOLUTION * RESOLUTION * SAMPLES
    for name, counts in measure(tuple(m for m in MATERIALS if m[0] in wanted)).items():
        print(f"{name}: {counts.total:,} instructions, {_describe(counts, samples)}")


if __name__ == "__main__":
    main()
