"""OSL source and Script-node helpers for the mixture (Cycles CPU / OptiX only).

Cycles 4.5 and later read a compiled Script node's parameters with the ``oslquery`` module (Cycles 4.2 does
not use it).  A Blender binary has ``oslquery`` in its bundled ``site-packages``; the pip ``bpy`` module ships
that folder but leaves it off ``sys.path`` (docs/research/blender_cycles.md §1), so :func:`ensure_oslquery`
loads ``oslquery`` from it by file, leaving ``sys.path`` alone.  ``oslquery`` returns OpenImageIO ``TypeDesc``
objects, whose Python type is registered by Blender's *bundled* OpenImageIO (3.0.9 in bpy 5.0.1); where
``import OpenImageIO`` finds a pip OpenImageIO instead (another pybind11 registry), the bundled one is loaded
under a private alias just to register the type (found by trial: without it socket creation fails with
"Unregistered type : OpenImageIO_v3_0::TypeDesc").  A real Blender binary needs none of this.  Whether a
node compiled is judged by its result (:func:`script_node`), never by the presence of ``oslquery``.
"""

from __future__ import annotations

import glob
import importlib.util
import os
import sys

import bpy

from .core import constants, cycles

#: OSL parameter suffix for each map kind of nodes.KINDS.
_PARAM_SUFFIX = {"Color": "color", "Radius": "radius", "Weight": "weight", "Anisotropy": "anisotropy"}


def param_name(k: int, kind: str) -> str:
    """OSL parameter for component k and map kind, e.g. ``k2_radius``."""
    return f"k{k}_{_PARAM_SUFFIX[kind]}"


_OIIO_ALIAS = "_spectral_skin_sss_bundled.OpenImageIO"


def _bundled_site_packages() -> list[str]:
    pattern = os.path.join(bpy.utils.resource_path("LOCAL"), "python", "lib", "python3*", "site-packages")
    return glob.glob(pattern)


def _register_bundled_oiio_types(site_packages: list[str]) -> None:
    """Load Blender's bundled OpenImageIO under a private name (registers TypeDesc for oslquery)."""
    if _OIIO_ALIAS in sys.modules:
        return
    for path in site_packages:
        for so in glob.glob(os.path.join(path, "OpenImageIO", "OpenImageIO*.so")) + glob.glob(
            os.path.join(path, "OpenImageIO", "OpenImageIO*.pyd")
        ):
            spec = importlib.util.spec_from_file_location(_OIIO_ALIAS, so)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            sys.modules[_OIIO_ALIAS] = module
            return


def _load_package_from(folder: str, name: str) -> bool:
    """Import the package ``folder/name`` as the top-level module ``name`` (Cycles imports it by that name)."""
    init = os.path.join(folder, name, "__init__.py")
    if not os.path.isfile(init):
        return False
    spec = importlib.util.spec_from_file_location(name, init,
                                                  submodule_search_locations=[os.path.join(folder, name)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return True


def ensure_oslquery() -> None:
    """Make Cycles' Script-node compilation work in the pip bpy module: ``oslquery`` loaded from the bundled
    ``site-packages`` when it is not importable (no-op in a Blender binary, and where there is none: Cycles 4.2
    compiles without it).  Once ``oslquery`` is loaded (by Cycles, or here with its types) nothing is done again:
    loading Blender's OpenImageIO a second time, after ``oslquery`` imported it, fails (pybind11: "type already
    registered"): in Blender 5.3, whose ``oslquery`` is importable, every OSL group after the first would fail."""
    if "oslquery" in sys.modules or importlib.util.find_spec("oslquery") is not None:
        return
    site_packages = _bundled_site_packages()
    if not any(_load_package_from(p, "oslquery") for p in site_packages):
        return
    _register_bundled_oiio_types(site_packages)


def mixture_source(k_count: int, entry_roughness: float, method: str = "random_walk") -> str:
    """OSL shader: the body below the specular coat, the mixture of K random-walk media (blender_addon/nodes.py)::

        (1 - F)/(1 - F_dr(ior)) * sum_k (weight_scale * w_k * A_k) * bssrdf(...)

    The coat itself (a Principled BSDF's specular layer) is a node beside the script in the group, shared with
    the SVM group (nodes.principled_specular).

    The factor A_k cancels the kernel's division of the throughput by the albedo, so the expected
    contribution of component k in channel c is w_kc times the walk in medium k.  F is Cycles' Fresnel node
    (``fresnel_dielectric_cos`` of node_fresnel.h, 1/IOR on back faces) at ``coat_ior`` (the coat's index: the group's
    IOR with its Specular IOR Level; the closures keep ``ior``), F_dr the same polynomial as the SVM
    group (exporters.cycles.DIFFUSE_FRESNEL_POLY); the closures' entry has roughness ``entry_roughness`` (the
    group's nodes.ENTRY_ROUGHNESS: smooth) and ``method`` is the bssrdf() method (nodes.random_walk_method, in
    lower case).  A zero ``Normal`` (an unlinked group input on some paths) falls back
    to N, as Cycles' closures do.
    """
    params = []
    terms = []
    for k in range(1, k_count + 1):
        c, r, w, g = (param_name(k, kind) for kind in ("Color", "Radius", "Weight", "Anisotropy"))
        params += [f"    color {c} = 0.0,", f"    color {r} = 0.0,", f"    color {w} = {1.0 / k_count!r},",
                   f"    float {g} = 0.0,"]
        terms.append(
            f"    mixture += (weight_scale * {w} * {c}) * bssrdf(\"{method}\", Nn, vector({r}), {c},\n"
            f"        \"ior\", ior, \"anisotropy\", {g}, \"roughness\", {float(entry_roughness)!r});"
        )
    fresnel = cycles.DIFFUSE_FRESNEL_POLY
    poly = " + x * (".join(repr(c) for c in fresnel) + ")" * (len(fresnel) - 1)
    return "\n".join(
        [
            "// Spectral Skin SSS: the body under the coat, a mixture of K random-walk media with per-channel weights"
            " (generated).",
            '#include "stdcycles.h"',
            '#include "node_fresnel.h"',
            "",
            f"shader spectral_skin_sss_k{k_count}(",
            *params,
            "    color weight_scale = 1.0,",
            f"    float ior = {constants.N_TISSUE!r},",
            f"    float coat_ior = {constants.N_TISSUE!r},",
            "    normal Normal = N,",
            "    output closure color BSSRDF = 0)",
            "{",
            "    normal Nn = (length(Normal) > 0.0) ? normalize(Normal) : N;",
            "    float eta = max(coat_ior, 1.0);",
            "    float F = fresnel_dielectric_cos(dot(I, Nn), backfacing() ? 1.0 / eta : eta);",
            "    float x = (eta - 1.0) / (eta + 1.0);",
            f"    float F_dr = x * ({poly});",
            "    closure color mixture = 0;",
            *terms,
            "    BSSRDF = ((1.0 - F) / (1.0 - F_dr)) * mixture;",
            "}",
            "",
        ]
    )


def script_node(nodes, source: str, text_name: str) -> bpy.types.Node:
    """An internal Script node compiled from ``source``; RuntimeError if compilation failed."""
    ensure_oslquery()
    text = bpy.data.texts.get(text_name) or bpy.data.texts.new(text_name)
    text.clear()
    text.write(source)
    node = nodes.new("ShaderNodeScript")
    node.mode = "INTERNAL"
    # Assigning the text compiles it through the *current* render engine's update_script_node, so
    # Cycles must be the scene's engine at that moment (restored afterwards).
    render = bpy.context.scene.render
    engine = render.engine
    render.engine = "CYCLES"
    try:
        node.script = text  # compiles (Cycles' osl.update_script_node) and creates the sockets
    finally:
        render.engine = engine
    if not node.bytecode or "BSSRDF" not in node.outputs:
        raise RuntimeError(f"OSL script {text_name!r} did not compile (compiler messages are on stderr)")
    return node
