"""The research quick start runs as written: the six stages on toy settings, from the command block of
docs/research/index.md ("Quick start"), which the README's "Reproduce the paper" repeats word for word.

Each line of the block runs in a fresh folder, ``python`` being this interpreter; each must exit 0, and the files
the page says it writes must be there.  What the page says the toy numbers mean is checked too: the toy model's
colour round trip (``train``'s last line about it) is far from the shipped model's (ΔE76 ~15, not < 1).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GUIDE = ROOT / "docs" / "research" / "index.md"
#: What the page's table says each stage writes (relative to the folder the block runs in).
WRITES = ["toy/lut.npz", "toy/data/train.h5", "toy/data/validation.h5", "toy/fits/train_fits.h5",
          "toy/fits/validation_fits.h5", "toy/run/stage3.pt", "toy/run/model.pt", "toy/model/skin_inversion.onnx",
          "toy/model/skin_decoder.onnx", "toy/model/skin_inversion.json", "toy/validation/tables.md",
          "toy/validation/tables.json"]


def quick_start_block(text: str) -> str:
    """The first ```sh block after the "Quick start" heading."""
    start = text.index("## Quick start")
    found = re.search(r"```sh\n(.*?)```", text[start:], re.S)
    assert found is not None, "no ```sh block under the Quick start heading"
    return found.group(1)


def test_the_readme_repeats_the_guides_block():
    block = quick_start_block(GUIDE.read_text())
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("## Reproduce the paper"):]
    assert f"```sh\n{block}```" in section.split("\n## ", 1)[0]
    assert [line.split()[3] for line in block.splitlines() if line.startswith("python")] == \
        ["lut", "dataset", "fit", "train", "export", "validate"]


@pytest.mark.slow
def test_the_quick_start_runs_as_written(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    env.pop("SKIN_SSS_LUT", None)
    outputs = {}
    for line in quick_start_block(GUIDE.read_text()).splitlines():
        argv = shlex.split(line)
        if argv[:2] == ["mkdir", "-p"]:
            (tmp_path / argv[2]).mkdir(parents=True, exist_ok=True)
            continue
        assert argv[0] == "python", line
        done = subprocess.run([sys.executable, *argv[1:]], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=1800)
        assert done.returncode == 0, f"{line}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
        outputs[argv[3]] = done.stdout + done.stderr
    missing = [name for name in WRITES if not (tmp_path / name).is_file()]
    assert missing == [], missing
    round_trip = re.search(r"validation colour dE76 \(encoder round trip\): mean ([\d.]+)", outputs["train"])
    assert round_trip is not None, outputs["train"][-2000:]
    print(f"\ntoy colour round trip ΔE76 {round_trip.group(1)}")
    assert 5.0 < float(round_trip.group(1)) < 40.0  # "about ΔE76 15": a toy, far from the shipped 0.38
