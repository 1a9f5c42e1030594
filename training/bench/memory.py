"""Benchmarks of a bake's peak memory (collected by `python -m training bench`): ``blender_addon/bake.py`` on a
texture of random colours at the default ``--memory-mb``, its peak RSS measured in a child process
(``ru_maxrss`` of the process's children), beside the anchor: the same bake of an 8 x 8 texture, which holds
only the fixed cost (Python, the libraries, the model session, the fast-path table)."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from exporters import inference, texel_table
from exporters.colorimetry import srgb_decode
from training.paths import SHIPPED_MODEL, SHIPPED_TABLE

BAKE = Path(__file__).resolve().parents[2] / "blender_addon" / "bake.py"
#: Distinct colours outside the fast-path table in the texture (they get the nearest skin colour's values).
OUTSIDE_COLOURS = 5000


def random_texture(size: int, outside: int = OUTSIDE_COLOURS, seed: int = 0) -> np.ndarray:
    """(size, size, 3) uint8 sRGB codes: ``outside`` random colours outside the fast-path table, the other texels
    drawn at random from ~400,000 random colours inside it."""
    rng = np.random.default_rng(seed)
    codes = rng.integers(0, 256, (1 << 22, 3), dtype=np.uint8)
    inside = texel_table.load(SHIPPED_TABLE).locate(srgb_decode(codes / 255.0).astype(np.float32))[0]
    pool = codes[inside]
    texels = np.concatenate([codes[~inside][:outside], pool[rng.integers(0, len(pool), size * size - outside)]])
    rng.shuffle(texels)
    return texels.reshape(size, size, 3)


def _write_png(path: Path, codes: np.ndarray) -> Path:
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(codes.shape[1], codes.shape[0], 3, "uint8"))
    out.write_image(np.ascontiguousarray(codes))
    out.close()
    return path


def peak_rss_mb(*args: str) -> tuple[float, float]:
    """(peak RSS in MiB, seconds) of ``bake.py args`` alone in a child process."""
    probe = ("import resource, subprocess, sys; p = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL); "
             "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); sys.exit(p.returncode)")
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", probe, sys.executable, str(BAKE), *args], capture_output=True,
                          text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"bake.py failed: {proc.stderr.strip()}")
    return int(proc.stdout.strip().splitlines()[-1]) / 1024.0, time.perf_counter() - t0


def _bake_row(size: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        big = _write_png(folder / f"random{size}.png", random_texture(size))
        tiny = _write_png(folder / "tiny.png", np.random.default_rng(1).integers(0, 256, (8, 8, 3), dtype=np.uint8))
        options = ("--model", str(SHIPPED_MODEL), "--quiet")
        fixed, _ = peak_rss_mb("--albedo", str(tiny), "--out", str(folder / "tiny"), *options)
        peak, seconds = peak_rss_mb("--albedo", str(big), "--out", str(folder / "big"), *options)
        distinct = len(np.unique(np.asarray(oiio.ImageBuf(str(big)).get_pixels(oiio.UINT8)).reshape(-1, 3)
                                 .view(np.dtype((np.void, 3)))))
    budget = inference.DEFAULT_MEMORY_MB
    return {"workload": f"bake.py peak RSS, {size}x{size} random colours ({distinct:,} distinct, {OUTSIDE_COLOURS:,} "
                        f"outside the table), default --memory-mb {budget}, default threads",
            "ours": f"{peak:.0f} MiB peak RSS ({seconds:.0f} s)", "anchor": f"{fixed:.0f} MiB (8x8 bake: fixed cost)",
            "ratio": f"{peak - fixed:.0f} MiB above the fixed cost ({(peak - fixed) / budget:.2f}x the budget)",
            "error": "-", "notes": "2 shared cores; the EXR writers' per-thread buffers count above the budget"}


def benchmarks(quick: bool) -> list[dict]:
    return [_bake_row(1024 if quick else 4096)]
