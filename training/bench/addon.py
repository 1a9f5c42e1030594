"""Benchmarks of the Cycles mapping and the render-fidelity probe (collected by `python -m training bench`)."""

from __future__ import annotations

import time

import numpy as np

from exporters import cycles
from training.paths import SHIPPED_MODEL


def _bisection_inverse(alpha: np.ndarray, g: float, iterations: int = 60) -> np.ndarray:
    """Anchor: the plain 60-step bisection of docs/research/blender_cycles.md §2d (vectorised)."""
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


def _mixture_render_rows(quick: bool) -> list[dict]:
    """Cycles render time of the Spectral Skin SSS Mixture for one baked skin texel: SVM vs OSL, all K components
    vs one dropped (the smallest share: the time of a pruned group; that component is not negligible for the
    shipped model, so the colour changes, reported as the error)."""
    from blender_addon import nodes, probe
    from exporters import inference, texel_records
    from exporters.colorimetry import delta_e76, linear_srgb_to_lab

    model = inference.load_model(SHIPPED_MODEL, threads=2)
    rec = texel_records.exact_records(model, np.array([[0.55, 0.36, 0.27]], np.float32), ("cycles",),
                                      texel_records.CollapseOptions())
    unit = 0.005  # 5 mm per Blender unit: the probe slab is semi-infinite for every component
    comps = [{"Color": rec["color"][0, k], "Radius": rec["radius_m"][0, k] / unit, "Weight": rec["weight"][0, k],
              "Anisotropy": float(rec["anisotropy"][0, k])} for k in range(model.k)]
    drop = int(np.argmin(rec["max_share"][0]))
    samples, size = (256, 32) if quick else (1024, 64)
    results = {}
    for backend in ("SVM", "OSL"):
        for label, use in (("all", comps), ("pruned", [c for i, c in enumerate(comps) if i != drop])):
            scene = probe.new_scene(samples=samples, resolution=size, seed=3)
            if backend == "OSL":
                scene.cycles.shading_system = True
            group = nodes.build_osl_group(len(use)) if backend == "OSL" else nodes.build_svm_group(len(use))
            gnode = nodes.wire_into_material(probe.slab_material(), group)
            nodes.set_constant_inputs(gnode, use)
            probe.render_mean(scene)  # warm-up (kernel and OSL compilation)
            results[backend, label] = probe.render_mean(scene)
    rows = []
    for backend in ("SVM", "OSL"):
        (m_all, _, t_all), (m_pr, _, t_pr) = results[backend, "all"], results[backend, "pruned"]
        de = float(delta_e76(linear_srgb_to_lab(m_all), linear_srgb_to_lab(m_pr)))
        rows.append({"workload": f"Cycles render of the mixture group, {backend}, one baked skin texel, {size}x{size} "
                                 f"@ {samples} spp, K={model.k} vs K={model.k - 1} (component {drop + 1} dropped)",
                     "ours": f"K={model.k - 1}: {t_pr:.2f} s", "anchor": f"K={model.k}: {t_all:.2f} s",
                     "ratio": f"{t_all / t_pr:.2f}x",
                     "error": f"colour change from dropping it: ΔE76 {de:.2f} (share {rec['max_share'][0, drop]:.2f}; "
                              "the bake drops only components below 0.2 %)",
                     "notes": "Cycles CPU; " + ("OSL: one script node, K bssrdf closures" if backend == "OSL" else
                                                "SVM: 3K single-channel closures")})
    (m_svm, e_svm, t_svm), (m_osl, e_osl, t_osl) = results["SVM", "all"], results["OSL", "all"]
    rows.append({"workload": f"Cycles render of the mixture group, K={model.k}: OSL vs SVM, {size}x{size} @ "
                             f"{samples} spp",
                 "ours": f"OSL {t_osl:.2f} s", "anchor": f"SVM {t_svm:.2f} s", "ratio": f"{t_svm / t_osl:.2f}x",
                 "error": f"rel. difference OSL/SVM - 1: {np.round((m_osl / m_svm - 1) * 100, 2).tolist()} % (stderr % "
                          f"{np.round(np.hypot(e_osl, e_svm) / m_svm * 100, 2).tolist()})",
                 "notes": "the add-on picks OSL on CPU/OptiX, SVM on other GPUs"})
    return rows


def benchmarks(quick: bool) -> list[dict]:
    return [_inverse_row(quick), _render_row(quick), *_mixture_render_rows(quick)]
