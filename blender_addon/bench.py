"""Benchmarks of the Cycles mapping and the render-fidelity probe (collected by `python -m training bench`)."""

from __future__ import annotations

import time

import numpy as np

from exporters import cycles


def _bisection_inverse(alpha: np.ndarray, g: float, iterations: int = 60) -> np.ndarray:
    """Anchor: the plain 60-step bisection of notes/blender_cycles.md §2d (vectorised)."""
    lo = np.zeros_like(alpha)
    hi = np.full_like(alpha, float(cycles.saturation_color(g)))
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        below = cycles.rw_albedo_forward(mid, g) < alpha
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return 0.5 * (lo + hi)


def _inverse_row(quick: bool) -> dict:
    n = 250_000 if quick else 1_000_000
    alpha = np.random.default_rng(0).uniform(0.2, 0.9999, n)
    t0 = time.perf_counter()
    ours = cycles.rw_albedo_inverse(alpha, 0.7).color
    t1 = time.perf_counter()
    anchor = _bisection_inverse(alpha, 0.7)
    t2 = time.perf_counter()
    err = np.abs(cycles.rw_albedo_forward(ours, 0.7) - alpha).max()
    err_anchor = np.abs(cycles.rw_albedo_forward(anchor, 0.7) - alpha).max()
    return {"workload": f"Subsurface Color inverse, {n:,} texels, g=0.7 (CPU, float64)",
            "ours": f"{t1 - t0:.2f} s (safeguarded Newton)", "anchor": f"{t2 - t1:.2f} s (60-step bisection)",
            "ratio": f"{(t2 - t1) / (t1 - t0):.2f}x faster",
            "error": f"max |f(A)-alpha| {err:.1e} (bisection {err_anchor:.1e})", "notes": "2 shared cores"}


def _render_row(quick: bool) -> dict:
    import iadpython

    from blender_addon import probe

    alpha, g, sigma_t = np.array([0.7, 0.95, 0.99]), 0.5, np.array([20.0, 50.0, 120.0])
    cin = cycles.medium_to_cycles(alpha, sigma_t, np.full(3, g), unit_scale_m=0.01)
    samples = 256 if quick else 1024
    scene = probe.new_scene(samples=samples, resolution=16, seed=11)
    mat = probe.slab_material()
    node = probe.add_sss_node(mat.node_tree, cin.color, cin.radius, g)
    mat.node_tree.links.new(node.outputs["BSSRDF"], probe.material_output(mat).inputs["Surface"])
    mean, err, seconds = probe.render_mean(scene)
    ref = np.array([iadpython.Sample(a=a, b=np.inf, g=g, n=1.0, quad_pts=16).rt()[0] for a in alpha])
    rel = (mean / ref - 1.0) * 100
    return {"workload": f"Cycles RANDOM_WALK reflectance, g={g}, alpha={alpha.tolist()}, 16x16 @ {samples} spp",
            "ours": f"{np.round(mean, 4).tolist()} in {seconds:.2f} s",
            "anchor": f"iadpython UR1 (n=1) {np.round(ref, 4).tolist()}",
            "ratio": "-", "error": f"rel. err. % {np.round(rel, 2).tolist()} (stderr % "
                                  f"{np.round(err / ref * 100, 2).tolist()})",
            "notes": "Cycles CPU, pip bpy 5.0.1"}


def benchmarks(quick: bool) -> list[dict]:
    return [_inverse_row(quick), _render_row(quick)]
