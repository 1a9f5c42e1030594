"""Benchmarks of baking (collected by `python -m training bench`): ONNX inference, the collapse, a whole bake.

Anchors are measured here on the same machine: the model evaluated in one call (no chunking) for the
chunked inference, and the inference time for the collapse (how much the per-channel collapse adds).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from exporters import baking, collapse, inference, maps

MODEL = Path(__file__).resolve().parents[1] / "blender_addon" / "models" / "skin_inversion.onnx"


def _skin_rows(n: int, seed: int = 0) -> np.ndarray:
    """n distinct skin-like linear-sRGB albedos."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0.0, 1.0, (n, 1))
    light, dark = np.array([0.80, 0.55, 0.42]), np.array([0.10, 0.05, 0.03])
    return np.clip(light * (1 - t) + dark * t + rng.normal(0, 0.02, (n, 3)), 0.005, 1.0)


def _inference_rows(quick: bool) -> list[dict]:
    n = 4096 if quick else 16384
    rgb = _skin_rows(n)
    rows = []
    for threads in (1, 2):
        model = inference.load_model(MODEL, threads=threads)
        model.run(rgb[:64])
        t0 = time.perf_counter()
        chunked = {k: [] for k in ("alpha",)}
        for _, out in model.run_chunks(rgb, 1024):
            chunked["alpha"].append(out["alpha"])
        t1 = time.perf_counter()
        whole = model.run(rgb)
        t2 = time.perf_counter()
        err = float(np.abs(np.concatenate(chunked["alpha"]) - whole["alpha"]).max())
        rows.append({"workload": f"skin_inversion.onnx, {n:,} texels, chunks of 1024, {threads} thread(s)",
                     "ours": f"{n / (t1 - t0):,.0f} texels/s", "anchor": f"{n / (t2 - t1):,.0f} texels/s (one call)",
                     "ratio": f"{(t2 - t1) / (t1 - t0):.2f}x", "error": f"max |alpha diff| {err:.1e}",
                     "notes": f"K={model.k}; shared 2-core machine"})
    return rows


def _collapse_row(quick: bool) -> dict:
    n = 2048 if quick else 8192
    model = inference.load_model(MODEL, threads=1)
    warm = model.run(_skin_rows(8, 3))  # tables loaded and integrated once per process
    collapse.collapse(warm["reflectance"], warm["alpha"], warm["sigma_t"], warm["g"], warm["weight"])
    t0 = time.perf_counter()
    out = model.run(_skin_rows(n, 1))
    t1 = time.perf_counter()
    media = collapse.collapse(out["reflectance"], out["alpha"], out["sigma_t"], out["g"], out["weight"])
    collapse.to_cycles(media)
    t2 = time.perf_counter()
    err = float(np.abs(media.cycles_reflectance() / np.maximum(media.target, 1e-12) - 1.0).max())
    return {"workload": f"collapse 376 wavelengths -> RGB Cycles inputs, {n:,} texels",
            "ours": f"{n / (t2 - t1):,.0f} texels/s", "anchor": f"inference {n / (t1 - t0):,.0f} texels/s (1 thread)",
            "ratio": f"collapse/inference time {(t2 - t1) / (t1 - t0):.2f}",
            "error": f"max rel. error of the reproduced channel reflectance {err:.1e}",
            "notes": "numpy; float32 spectral sums, float64 solve"}


def _bake_row(quick: bool) -> dict:
    import resource

    side = 128 if quick else 512
    rgb = _skin_rows(side * side, 2).reshape(side, side, 3)
    with tempfile.TemporaryDirectory() as tmp:
        exr = maps.write_exr(Path(tmp) / "alb.exr", rgb.astype(np.float32), maps.RGB_CHANNELS, "1")
        out = Path(tmp) / "maps"
        out.mkdir()
        rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        t0 = time.perf_counter()
        result = baking.bake(exr, out, MODEL, baking.BakeOptions(threads=2, memory_mb=128))
        seconds = time.perf_counter() - t0
        rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    n = side * side
    t = result.timings_s
    grew = max(rss1 - rss0, 0) / 1024
    return {"workload": f"bake.py core, {side}x{side} float EXR, all texels distinct, --target cycles",
            "ours": f"{seconds:.1f} s ({n / seconds:,.0f} texels/s)",
            "anchor": f"inference {t['inference']:.1f} s, collapse {t['collapse']:.1f} s, write {t['write']:.2f} s",
            "ratio": "-", "error": "-", "notes": f"2 threads, 128 MiB chunk budget; peak RSS grew {grew:.0f} MiB"}


def benchmarks(quick: bool) -> list[dict]:
    return [*_inference_rows(quick), _collapse_row(quick), _bake_row(quick)]
