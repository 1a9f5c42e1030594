"""The counted-work benchmark's reading of Callgrind's output (training.bench.instructions.parse)."""

import shutil
import subprocess
import sys

import pytest

from training.bench import instructions

#: A Callgrind file as ``--dump-instr=yes`` writes it (positions: instruction address, then line; relative
#: addresses follow the previous position line, call lines included): a kernel function calls the shader VM twice
#: (inclusive 300 for both calls) and the walk once (inclusive 50); names are compressed after their first use.
SAMPLE = """\
version: 1
creator: callgrind-3.22.0
positions: instr line
events: Ir
summary: 1000

ob=(1) /lib/bpy.so
fl=(1) ???
fn=(1) ccl::kernel_megakernel(ccl::KG*)
0x10 0 40
+4 0 2
cfn=(2) void ccl::svm_eval_nodes<16779195u, (ccl::ShaderType)0, ccl::IntegratorStateCPU*>(ccl::KG*)
calls=2 0x100 0
* 0 300
cfn=(3) ccl::integrator_intersect_subsurface(ccl::KG*, ccl::State*)
calls=1 0x900 0
+4 0 50

fn=(2)
0x100 0 7
+1 0 7
+2 0 3
cfn=(4) ccl::svm_node_tex_image(ccl::KG*)
calls=3 0x500 0
+1 0 240
-3 0 2

fn=(3)
0x900 0 20
cfn=(5) rtcOccluded1
calls=4 0x990 0
+8 0 30

fn=(4)
0x500 0 240
"""


def test_parse_reads_totals_inclusive_costs_dispatches_and_evaluations(tmp_path):
    path = tmp_path / "callgrind.out"
    path.write_text(SAMPLE)
    counts = instructions.parse(path)
    assert counts.total == 1000
    # the VM's own instructions 7 + 7 + 3 + 2, and the texture reads it calls: 240
    assert counts.shading == 19 + 240
    # the walk's own 20 and its ray casts 30
    assert counts.walks == 20 + 30
    # 0x101 runs 7 times and, 3 before the call line's 0x104, 2 more: 9, more than any other instruction
    assert counts.dispatches == 9
    assert counts.evaluations == 2


def test_parse_of_a_file_without_the_functions_gives_zeros(tmp_path):
    path = tmp_path / "callgrind.out"
    path.write_text("positions: line\nevents: Ir\nsummary: 12\nfn=(1) main\n3 12\n")
    counts = instructions.parse(path)
    assert (counts.total, counts.shading, counts.walks, counts.dispatches, counts.evaluations) == (12, 0, 0, 0, 0)


@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind not installed")
def test_parse_reads_a_real_callgrind_file(tmp_path):
    """A real run (a tiny Python program): the file's totals are read, no function of Cycles appears."""
    out = tmp_path / "cg.out"
    subprocess.run(["valgrind", "--tool=callgrind", "--dump-instr=yes", f"--callgrind-out-file={out}",
                    sys.executable, "-c", "sum(range(1000))"], check=True, capture_output=True, timeout=600)
    counts = instructions.parse(out)
    assert counts.total > 1_000_000 and counts.shading == 0 and counts.dispatches == 0
