"""The node group **Spectral Skin SSS Mixture** (SPEC §5) and its wiring into a user's material.

Inputs, for each component k = 1..K (the baked maps of SPEC §4, ``--target cycles``):
``k{k} Color`` (Subsurface Color, RGB), ``k{k} Radius`` (RANDOM_WALK radius in Blender units, RGB),
``k{k} Weight`` (RGB, summing to 1 over k per channel), ``k{k} Anisotropy`` (one g in [0, 0.9]);
plus ``IOR`` and ``Roughness`` of Cycles' refractive entry bounce.  Output: ``BSSRDF`` (a shader).

Why a sum of closures weighted by w_k *is* "pick component k with probability w_k, then walk in medium k"
(Cycles 5.0.1 kernel): shader nodes never choose a closure; Mix/Add Shader only scale and collect closure
weights (svm_node_mix_closure).  At a surface hit the integrator picks ONE of the collected closures with
probability proportional to its ``sample_weight`` and divides by that probability
(surface_shader_bsdf_bssrdf_pick, surface_shader_bssrdf_sample_weight), then the random walk divides the
throughput by the closure albedo A (subsurface_random_walk_coefficients).  A closure of weight ``w_kc A_kc``
in channel c therefore contributes, in expectation, exactly ``w_kc x (walk in medium k)`` to channel c, and
the sum over k is the mixture: E[pixel_c] = sum_k w_kc RW_kc.  Only the pick probabilities (proportional
to avg(w A), not to w) differ from a literal "pick k with probability w_k", which changes the variance,
never the mean.  Per-channel weights need the closure weight to differ from A per channel:

* SVM (works on every Cycles device): the Subsurface Scattering node ties its weight to its Color, so each
  component is split into three single-channel closures (Color and Radius non-zero only in channel c;
  the other channels have radius 0 and weight 0, so Cycles drops them), each scaled by w_kc with a Mix
  Shader (Fac = w_kc, other input empty) and summed with Add Shaders: 3K closures (Cycles allows 64).
  Splitting also lets every channel walk alone, which is what the per-channel medium means anyway.
* OSL (CPU and OptiX only): one ``(w_k * A_k) * bssrdf("random_walk", N, r_k, A_k, ...)`` per component;
  the factor A_k is required because the kernel divides by the albedo (as Blender's own
  node_subsurface_scattering.osl does).

Both paths are checked against each other and against single-component renders in
tests/test_cycles_mixture.py.
"""

from __future__ import annotations

import bpy

from . import osl

GROUP_NAME = "Spectral Skin SSS Mixture"
GROUP_NAME_OSL = "Spectral Skin SSS Mixture (OSL)"
CHANNELS = ("Red", "Green", "Blue")
#: Map kinds of SPEC §4 (--target cycles), in socket order.
KINDS = ("Color", "Radius", "Weight", "Anisotropy")
FRAME_LABEL = "Spectral Skin SSS"
#: Custom property remembering what fed the Material Output before wiring (for the user to restore).
PREVIOUS_SURFACE_PROP = "spectral_skin_sss_previous_surface"
#: Entry bounce defaults: tissue index (SPEC §1) and a smooth interface.
DEFAULT_IOR = 1.4
DEFAULT_ROUGHNESS = 0.0


def socket_name(k: int, kind: str) -> str:
    """Group input name for component k (1-based) and map kind, e.g. ``k2 Radius``."""
    return f"k{k} {kind}"


def _new_interface(group: bpy.types.NodeTree, k_count: int) -> None:
    iface = group.interface
    for k in range(1, k_count + 1):
        for kind in KINDS:
            stype = "NodeSocketFloat" if kind == "Anisotropy" else "NodeSocketColor"
            sock = iface.new_socket(socket_name(k, kind), in_out="INPUT", socket_type=stype)
            if kind == "Anisotropy":
                sock.min_value, sock.max_value, sock.default_value = 0.0, 0.9, 0.0
            elif kind == "Weight":
                sock.default_value = (1.0 / k_count,) * 3 + (1.0,)
            else:
                sock.default_value = (0.0, 0.0, 0.0, 1.0)
    ior = iface.new_socket("IOR", in_out="INPUT", socket_type="NodeSocketFloat")
    ior.min_value, ior.max_value, ior.default_value = 1.01, 3.8, DEFAULT_IOR
    rough = iface.new_socket("Roughness", in_out="INPUT", socket_type="NodeSocketFloat")
    rough.min_value, rough.max_value, rough.default_value = 0.0, 1.0, DEFAULT_ROUGHNESS
    iface.new_socket("BSSRDF", in_out="OUTPUT", socket_type="NodeSocketShader")


def _group_io(group: bpy.types.NodeTree) -> tuple[bpy.types.Node, bpy.types.Node]:
    gin = group.nodes.new("NodeGroupInput")
    gout = group.nodes.new("NodeGroupOutput")
    gin.location, gout.location = (-1200.0, 0.0), (900.0, 0.0)
    return gin, gout


def _single_channel(group, separate, channel: int, x: float, y: float) -> bpy.types.Node:
    """Combine Color carrying only ``channel`` of ``separate`` (others 0)."""
    comb = group.nodes.new("ShaderNodeCombineColor")
    comb.location = (x, y)
    for c in range(3):
        comb.inputs[c].default_value = 0.0
    group.links.new(separate.outputs[channel], comb.inputs[channel])
    return comb


def _fresh_group(name: str, k_count: int, backend: str):
    """A new, empty shader node group ``name`` (replacing an old one) with the mixture's interface.

    Returns (group, group input node, group output node).
    """
    old = bpy.data.node_groups.get(name)
    if old is not None and old.users == 0:  # never pull a group out from under a material using it
        bpy.data.node_groups.remove(old)
    group = bpy.data.node_groups.new(name, "ShaderNodeTree")  # Blender suffixes the name if still taken
    group["spectral_skin_sss_k"] = k_count
    group["spectral_skin_sss_backend"] = backend
    _new_interface(group, k_count)
    gin, gout = _group_io(group)
    return group, gin, gout


def build_svm_group(k_count: int = 3, name: str = GROUP_NAME) -> bpy.types.NodeTree:
    """Build (or rebuild) the SVM node group with ``k_count`` components; returns the node tree."""
    if not 1 <= k_count <= 7:  # 3K closures + margin must stay below Cycles' MAX_CLOSURE = 64
        raise ValueError("k_count must be in 1..7")
    group, gin, gout = _fresh_group(name, k_count, "SVM")
    total = None
    for k in range(1, k_count + 1):
        y0 = -(k - 1) * 1500.0
        seps = {}
        for j, kind in enumerate(("Color", "Radius", "Weight")):
            sep = group.nodes.new("ShaderNodeSeparateColor")
            sep.location = (-950.0, y0 - j * 200.0)
            group.links.new(gin.outputs[socket_name(k, kind)], sep.inputs[0])
            seps[kind] = sep
        for c in range(3):
            y = y0 - c * 450.0
            col = _single_channel(group, seps["Color"], c, -700.0, y)
            rad = _single_channel(group, seps["Radius"], c, -700.0, y - 150.0)
            sss = group.nodes.new("ShaderNodeSubsurfaceScattering")
            sss.location = (-450.0, y)
            sss.label = f"k{k} {CHANNELS[c]}"
            sss.inputs["Scale"].default_value = 1.0
            sss.falloff = "RANDOM_WALK"
            group.links.new(col.outputs[0], sss.inputs["Color"])
            group.links.new(rad.outputs[0], sss.inputs["Radius"])
            group.links.new(gin.outputs[socket_name(k, "Anisotropy")], sss.inputs["Anisotropy"])
            group.links.new(gin.outputs["IOR"], sss.inputs["IOR"])
            group.links.new(gin.outputs["Roughness"], sss.inputs["Roughness"])
            mix = group.nodes.new("ShaderNodeMixShader")
            mix.location = (-200.0, y)
            group.links.new(seps["Weight"].outputs[c], mix.inputs["Fac"])
            group.links.new(sss.outputs["BSSRDF"], mix.inputs[2])
            if total is None:
                total = mix
            else:
                add = group.nodes.new("ShaderNodeAddShader")
                add.location = (50.0 + 20.0 * k, y)
                group.links.new(total.outputs[0], add.inputs[0])
                group.links.new(mix.outputs[0], add.inputs[1])
                total = add
    group.links.new(total.outputs[0], gout.inputs["BSSRDF"])
    return group


def build_osl_group(k_count: int = 3, name: str = GROUP_NAME_OSL) -> bpy.types.NodeTree:
    """The same interface as :func:`build_svm_group`, computed by one OSL Script node (CPU/OptiX only).

    Needs ``scene.cycles.shading_system = True`` to render.  Raises RuntimeError if the script does not
    compile (no sockets appear, or no bytecode).
    """
    if not 1 <= k_count <= 16:
        raise ValueError("k_count must be in 1..16")
    group, gin, gout = _fresh_group(name, k_count, "OSL")
    script = osl.script_node(group.nodes, osl.mixture_source(k_count), f"spectral_skin_sss_k{k_count}.osl")
    for k in range(1, k_count + 1):
        for kind in KINDS:
            group.links.new(gin.outputs[socket_name(k, kind)], script.inputs[osl.param_name(k, kind)])
    group.links.new(gin.outputs["IOR"], script.inputs["ior"])
    group.links.new(gin.outputs["Roughness"], script.inputs["roughness"])
    group.links.new(script.outputs["BSSRDF"], gout.inputs["BSSRDF"])
    return group


#: Custom property marking the group layout version (bump when the generated nodes change).
GROUP_VERSION = 1


def ensure_group(k_count: int, backend: str) -> bpy.types.NodeTree:
    """The mixture group for ``k_count`` components and ``backend`` ("SVM" or "OSL"): an existing group of
    this add-on with the same K, backend and version is reused (several materials share it), else a new
    one is built (existing groups are never replaced while used)."""
    if backend not in ("SVM", "OSL"):
        raise ValueError(f"backend must be SVM or OSL, not {backend!r}")
    base = GROUP_NAME if backend == "SVM" else GROUP_NAME_OSL
    for group in bpy.data.node_groups:
        if (group.name.startswith(base) and group.get("spectral_skin_sss_k") == k_count
                and group.get("spectral_skin_sss_backend") == backend
                and group.get("spectral_skin_sss_version") == GROUP_VERSION):
            return group
    group = build_osl_group(k_count) if backend == "OSL" else build_svm_group(k_count)
    group["spectral_skin_sss_version"] = GROUP_VERSION
    return group


def set_constant_inputs(node: bpy.types.Node, components: list[dict]) -> None:
    """Set a group node's unlinked inputs from ``[{"Color": rgb, "Radius": rgb, "Weight": rgb,
    "Anisotropy": g}, ...]`` (uniform maps; used by tests and for previews)."""
    for k, comp in enumerate(components, start=1):
        for kind, value in comp.items():
            sock = node.inputs[socket_name(k, kind)]
            sock.default_value = float(value) if kind == "Anisotropy" else (*map(float, value), 1.0)


def _material_output(tree: bpy.types.NodeTree) -> bpy.types.Node:
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    active = [n for n in outputs if n.is_active_output]
    if active:
        return active[0]
    if outputs:
        return outputs[0]
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    out.location = (400.0, 0.0)
    return out


def wire_into_material(material: bpy.types.Material, group: bpy.types.NodeTree,
                       images: dict[tuple[int, str], bpy.types.Image] | None = None,
                       interpolation: str = "Closest") -> bpy.types.Node:
    """Add the group (and Image Texture nodes for ``images[(k, kind)]``) to ``material``.

    Every existing node and link is kept except the link into the active Material Output's Surface,
    which now comes from the group; the name of the node that fed it is stored in
    ``material[PREVIOUS_SURFACE_PROP]``.  New nodes sit in a frame labelled "Spectral Skin SSS".  Images are
    set to Non-Color.  ``interpolation`` defaults to Closest because the maps hold Cycles' colour A, not
    the albedo alpha = f(A), and f is non-linear (linear filtering gives a small bias at texel edges).
    Undo: call from an operator with ``bl_options = {'REGISTER', 'UNDO'}``.
    """
    tree = material.node_tree
    out = _material_output(tree)
    frame = tree.nodes.new("NodeFrame")
    frame.label = FRAME_LABEL
    gnode = tree.nodes.new("ShaderNodeGroup")
    gnode.node_tree = group
    gnode.label = group.name
    gnode.location = (out.location.x - 300.0, out.location.y)
    gnode.parent = frame
    surface = out.inputs["Surface"]
    for link in list(surface.links):
        material[PREVIOUS_SURFACE_PROP] = link.from_node.name
        tree.links.remove(link)
    tree.links.new(gnode.outputs["BSSRDF"], surface)
    for i, ((k, kind), image) in enumerate(sorted((images or {}).items())):
        image.colorspace_settings.name = "Non-Color"
        tex = tree.nodes.new("ShaderNodeTexImage")
        tex.image = image
        tex.interpolation = interpolation
        tex.label = socket_name(k, kind)
        tex.location = (gnode.location.x - 400.0, gnode.location.y - 60.0 * i)
        tex.parent = frame
        tree.links.new(tex.outputs["Color"], gnode.inputs[socket_name(k, kind)])
    return gnode
