"""The node group **Spectral Skin SSS Mixture** (docs/contracts.md §5) and its wiring into a user's material.

Inputs, for each component k = 1..K (the baked maps of docs/contracts.md §4, ``--target cycles``): ``k{k} Color``
(Subsurface Color, RGB), ``k{k} Radius`` (RANDOM_WALK radius in Blender units, RGB), ``k{k} Weight`` (RGB, summing to 1
over k per channel), ``k{k} Anisotropy`` (one g in [0, 0.9]); then ``Weight Scale`` (RGB, default 1: a factor on every
component's weight, per channel, computed once for all of them: the live group's Subsurface Weight and the grazing-light
correction's weight factors), ``Translucency`` (default 1: a factor on every component's radius, each closure's Scale;
the artist's control over baked maps, where the live group scales its radii itself), ``IOR`` (the tissue index: the
specular coat's Fresnel and the closures' refractive entry, which the bake's tables assume), ``Roughness`` (the coat's
specular roughness, Blender's perceptual roughness, GGX alpha = Roughness^2) and ``Normal`` (normal/bump map; unlinked:
the shading normal), which feeds the coat, its Fresnel weight and every subsurface closure; then the Principled BSDF's
specular inputs (below) and ``Body`` (a shader added beside the mixture under the clear coat and sheen: the live group's
diffuse body where Subsurface Weight is below 1; unlinked, nothing). Output: ``BSSRDF`` (the whole surface shader: coat
plus mixture; the name is kept for files wired before the coat existed).

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

* SVM (works on every Cycles device): the Subsurface Scattering node ties its weight to its Color (weight =
  Color x mix weight, albedo = Color), so one closure can only carry its channels at one scalar weight.  Each
  component is therefore split over **nested channel sets**: with lo <= mid <= hi its weights w_kc sorted over
  channels, one RGB closure of weight lo, one over the channels with w_kc >= mid (the others' Color 0) of weight
  mid - lo and one over the channels with w_kc = hi of weight hi - mid; per channel these add up to w_kc exactly
  (ties give a closure of weight 0, which Cycles skips).  Each closure is scaled with a Mix Shader (Fac = its
  weight, other input empty) and the closures are summed with Add Shaders: at most 3K closures (Cycles allows 64).
  Why nested sets and not three single-channel closures per component (``build_svm_group(design="per_channel")``,
  the earlier design): a single-channel closure carries one channel per path, so each channel sees only the paths
  that picked it and the random walk's per-channel MIS is lost, which shows as coloured speckle where subsurface
  light dominates; an RGB closure carries all three channels in every path.  The table's weights do not sum to the
  same per channel (they carry the painted colour: R > G > B for skin), so the RGB closure holds the blue weight
  and most of the green, and only the red surplus walks alone.  A channel left out of a closure keeps its radius,
  so Cycles counts it in the closure's pick weight (the mean weight times the number of channels with a radius,
  closure/bssrdf.h) with weight 0: the pick weight stays the sum of the channels' weights.  Why not a Principled
  BSDF per component, whose Coat Tint would give exact per-channel weights to one RGB closure: its subsurface
  closure enters at the Principled's specular index (1 when Specular IOR Level is 0, else with a specular lobe of
  the entry's roughness on top), while the bake's tables assume a smooth entry at the tissue's index; at index 1
  the cosine-averaged reflectance rises by 1-70 % (exporters.reflectance_tables), beyond what a redesign of the
  closures may change.
* OSL (CPU and OptiX only): one ``(w_k * A_k) * bssrdf("random_walk", N, r_k, A_k, ...)`` per component;
  the factor A_k is required because the kernel divides by the albedo (as Blender's own
  node_subsurface_scattering.osl does).

The specular coat (skin's surface reflection: highlights, pores and wrinkles through the normal map)::

    shader = Principled BSDF(black base; Roughness, IOR, Normal, Specular IOR Level, Specular Tint)
             + sum over k, c of w_kc s_c (1 - F(cos)) / (1 - F_dr) x closure_kc

with s_c the Weight Scale, F the Fresnel reflectance of the view direction at the shading normal (Cycles'
Fresnel node) and F_dr the cosine-weighted mean of F (exporters.cycles.DIFFUSE_FRESNEL_POLY).  Why this layering
and not another:

* **The coat is the artist's specular.**  A Principled BSDF whose base is black keeps only its dielectric
  specular layer (the black diffuse closure has weight 0 and is dropped), so highlights, rim light and
  roughness are exactly those of the artist's Principled material.  A Fresnel-weighted white Multiscatter GGX
  lobe (F at the shading normal, albedo 1) reflects up to 3x more at grazing angles than the Principled layer
  (its microfacet Fresnel and shadowing): 0.42 against 0.14 of a white world at cos 0.15 (roughness 0.5),
  which on the demo head's backlit rim made a highlight 1.3-2.5x Principled's: 1.49x the noise and 2.4x the
  time to equal noise of the group with the Principled coat (training.bench.render_cost, variant "live_fresnel_coat").
* **The maps already hold the body reflectance behind the boundary.**  A bake targets the model's
  reflectance, which excludes the specular part and includes the Fresnel losses of entering and leaving
  (exporters.collapse step 1).  Weighting the mixture by 1 - F alone would take those losses twice and
  darken skin by F_dr (7.7 % at n = 1.4).  Dividing by 1 - F_dr keeps the cosine-weighted mean of the
  mixture's weight at exactly 1 while its angular shape is the physical 1 - F (brighter than the bare
  mixture face-on, darker at grazing where the coat takes over): the flat-slab test renders the model's
  colour plus the coat's reflection within 3 % (tests/test_bake_fidelity.py).  The coat and the body's
  weight are not one energy budget (the Principled layer reflects less than F at grazing, so a little light
  is lost there), never above 1.
* **Why not the Principled BSDF's own layering** (Subsurface Weight 1): a Principled BSDF holds ONE
  BSSRDF (one colour, radius, anisotropy); K x 3 of them would add the specular 3 times (sum over k, c of
  w_kc = 3) and would weight the mixture by 1 - (specular albedo), the double loss above.
* **The body weight sits in each closure's own Mix Shader** (Fac w_kc x scale), so the summed mixture needs no
  further Mix Shaders.  A Mix Shader clamps its Fac to 1, so the part of a weight above 1 goes to a copy of the
  closure (same inputs; :data:`OVERFLOW_ROUGHNESS` keeps Cycles from merging the two) in a Mix Shader of Fac
  w_kc x scale - 1, and every copy sits behind one Mix Shader whose Fac is 1 where any component's largest
  weight exceeds 1, else 0.  A weight exceeds 1 only where the body weight and the grazing-light factor lift a
  large weight (the body weight alone is at most 1 / (1 - F_dr), 1.08 at IOR 1.4; the shipped fast-path table's
  largest weight is 0.82).  SVM evaluates the nodes that feed only one side of a Mix Shader inside that side and
  jumps over them while its Fac is 0 (svm.cpp, generate_multi_closure), so a shading point pays one Mix Shader
  per closure and the gate's three nodes; a closure reached along two Mix Shaders would pay both and the sum of
  their weights at every shading point (ShaderGraph::transform_multi_closure): about 7 % of the demo head's
  time per sample (training.bench.render_cost).
* **Why not OSL's ``layer()``** on the OSL path: SVM has no equivalent, and both paths must render the same
  (tests/test_cycles_mixture.py compares them); the OSL script computes the weighted body and the same
  Principled coat node sits beside it.
* The body weight's Fresnel uses the shading normal, not each microfacet's.
* The subsurface closures keep a smooth entry (roughness 0) and the group's IOR, exactly as the bake's
  Cycles reflectance tables assume (exporters.reflectance_tables); IOR 1 switches the coat off.

The Principled BSDF's specular inputs (:data:`SPECULAR_INPUTS`, taken from the artist's Principled BSDF when the
group is wired) keep their effect: **Specular IOR Level** scales the coat's F0 by 2 x level (the coat's index
becomes (1 + sqrt F0) / (1 - sqrt F0); the closures keep the tissue's IOR, which the bake's tables assume) and
**Specular Tint** colours the coat's lobe (both paths: the coat is the same Principled node, and the body
weight takes F of the coat's index); **Anisotropic** (Rotation, Tangent) and the **Thin Film** (Thickness, IOR)
shape and colour that lobe as they do the Principled BSDF's (the body weight keeps F without the film).  The
**clear coat** (Coat Weight, Roughness, IOR, Tint, Normal) is that Principled node's own coat, which layers the
coat's lobe over its specular lobe and tints that as Cycles' Principled BSDF does; the mixture and the diffuse
body under it keep 1 - Coat Weight x F(Coat IOR) of the light, the mixture also the Coat Tint's colour
(:func:`_under_coat`).  A **Sheen** BSDF (colour Sheen Tint, weighted Sheen Weight) is added on top; the share of
the light the sheen takes from below is not modelled (the live group tints its diffuse body by the Coat Tint
with :func:`coat_tint`).  At their
defaults none of them changes the render or adds a closure (Cycles folds their nodes to constants).

Both paths are checked against each other and against single-component renders in
tests/test_cycles_mixture.py; the coat's highlight, normal map and wiring in tests/test_skin_specular.py.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import bpy

from . import osl, wiring
from .core import cycles, reflectance_tables

GROUP_NAME = "Spectral Skin SSS Mixture"
GROUP_NAME_OSL = "Spectral Skin SSS Mixture (OSL)"
CHANNELS = ("Red", "Green", "Blue")
#: Map kinds of docs/contracts.md §4 (--target cycles), in socket order.
KINDS = ("Color", "Radius", "Weight", "Anisotropy")
FRAME_LABEL = wiring.FRAME_LABEL
#: Custom property remembering what fed the Material Output before wiring.
PREVIOUS_SURFACE_PROP = wiring.PREVIOUS_SURFACE_PROP
#: The tissue index (docs/contracts.md §1): the coat's Fresnel and the closures' entry bounce (the bake's default IOR).
DEFAULT_IOR = reflectance_tables.CYCLES_IOR
#: Smallest IOR the group takes: 1 turns the coat off (Cycles clamps the closures' IOR to
#: reflectance_tables.IOR_MIN; the largest is its IOR_MAX).
GROUP_IOR_MIN = 1.0
#: Roughness of the subsurface closures' refractive entry: smooth, as the bake's Cycles tables assume.
ENTRY_ROUGHNESS = 0.0
#: The Subsurface Scattering method of Blender 5.3 on that scales the radius as earlier Blenders' Random Walk did.
LEGACY_RANDOM_WALK = "RANDOM_WALK_LEGACY"
#: Entry roughness of the closures that carry the part of a weight above 1 (nodes._svm_mixture): smooth as well
#: (Cycles' GGX alpha 1e-6 tilts the entry by about 1e-6 rad), but not equal to :data:`ENTRY_ROUGHNESS`, so that
#: Cycles does not merge them with the closures of the same inputs (ShaderGraph::deduplicate_nodes), which would
#: bring their weights back out of the gate that skips them.
OVERFLOW_ROUGHNESS = 1e-6
#: rms facet slope of facial skin, Beckmann m: Weyrich et al. 2006 ("Analysis of human faces using a
#: measurement-based skin reflectance model", ACM TOG 25(3):1013) fit a Torrance-Sparrow lobe per face region,
#: m between about 0.3 and 0.45; 0.4 is used for a whole face (training/realskin takes 0.35 for the smoother
#: forearm).
SKIN_FACET_SLOPE = 0.4
#: Default specular Roughness of the coat when the material has no Principled BSDF to take it from.  Cycles'
#: Roughness socket is perceptual: GGX alpha = Roughness^2, and GGX alpha matches Beckmann m (Walter et al.
#: 2007), so Roughness = sqrt(m) = 0.63 (typing 0.4 into the socket would mean m = 0.16, a wet look).
SKIN_ROUGHNESS = math.sqrt(SKIN_FACET_SLOPE)


def random_walk_method() -> str:
    """The Subsurface Scattering method (``falloff``) whose radius the media conversion targets: Cycles divides a
    Random Walk radius by 4 pi (exporters.cycles.RADIUS_TO_D), as the bake's tables and every test assume.  Blender
    5.3's "RANDOM_WALK" takes the radius as the mean free path itself (Cycles commit e5f4164, "Removing legacy
    scaling of the subsurface radius to match MaterialX": 4 pi = 12.6x the translucency of the same radius) and
    keeps the old scaling as :data:`LEGACY_RANDOM_WALK`, to which it versions files of earlier Blenders; so that is
    the method where Blender has it, "RANDOM_WALK" elsewhere.  OSL's ``bssrdf()`` takes the same name in lower
    case."""
    items = bpy.types.ShaderNodeSubsurfaceScattering.bl_rna.properties["falloff"].enum_items
    return LEGACY_RANDOM_WALK if LEGACY_RANDOM_WALK in items else "RANDOM_WALK"


#: Smallest Translucency a group takes (the mean free paths scaled by it; 0 would make them 0).
TRANSLUCENCY_MIN = 1e-3


#: The Principled BSDF's specular inputs the mixture takes (name: socket type, Blender's default).  The defaults
#: leave the coat exactly as without them: Specular IOR Level 0.5 keeps F0 of the IOR, white tint, no coat or sheen.
SPECULAR_INPUTS: dict[str, tuple[str, object]] = {
    "Specular IOR Level": ("NodeSocketFloat", 0.5),
    "Specular Tint": ("NodeSocketColor", (1.0, 1.0, 1.0, 1.0)),
    "Coat Weight": ("NodeSocketFloat", 0.0),
    "Coat Roughness": ("NodeSocketFloat", 0.03),
    "Coat IOR": ("NodeSocketFloat", 1.5),
    "Sheen Weight": ("NodeSocketFloat", 0.0),
    "Sheen Roughness": ("NodeSocketFloat", 0.5),
    "Sheen Tint": ("NodeSocketColor", (1.0, 1.0, 1.0, 1.0)),
    "Coat Tint": ("NodeSocketColor", (1.0, 1.0, 1.0, 1.0)),
    "Coat Normal": ("NodeSocketVector", None),
    "Anisotropic": ("NodeSocketFloat", 0.0),
    "Anisotropic Rotation": ("NodeSocketFloat", 0.0),
    "Tangent": ("NodeSocketVector", None),
    "Thin Film Thickness": ("NodeSocketFloat", 0.0),
    "Thin Film IOR": ("NodeSocketFloat", 1.33),
}
#: The specular coat's inputs taken straight from the group's (:func:`principled_specular`).
COAT_INPUTS = ("Roughness", "IOR", "Normal", "Specular IOR Level", "Specular Tint", "Anisotropic",
               "Anisotropic Rotation", "Tangent", "Thin Film Thickness", "Thin Film IOR", "Coat Weight",
               "Coat Roughness", "Coat IOR", "Coat Tint", "Coat Normal")
#: Float inputs' ranges where not [0, 1] (the Principled BSDF's own).
_RANGES = {"Coat IOR": (1.0, 4.0), "Emission Strength": (0.0, 1e6), "Thin Film Thickness": (0.0, 100000.0),
           "Thin Film IOR": (1.0, 1000.0)}


#: The Principled BSDF's inputs besides the specular ones that the live group takes (name: socket type, its default
#: in the group): Subsurface Weight (0: the painted colour as a diffuse body under the coat, 1: the skin; a mask
#: works), Alpha (a Transparent BSDF mixed in) and Emission (added).  At these defaults none changes the render.
ARTIST_INPUTS: dict[str, tuple[str, object]] = {
    "Subsurface Weight": ("NodeSocketFloat", 1.0),
    "Alpha": ("NodeSocketFloat", 1.0),
    "Emission Color": ("NodeSocketColor", (1.0, 1.0, 1.0, 1.0)),
    "Emission Strength": ("NodeSocketFloat", 0.0),
}
#: The surface inputs a group takes over from the Principled BSDF it renders for (besides Base Color: the live
#: group's Color), at wiring and afterwards (blender_addon.follow).
TAKEN_INPUTS = ("Normal", "Roughness", *SPECULAR_INPUTS, *ARTIST_INPUTS)


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
                sock.min_value, sock.max_value, sock.default_value = cycles.G_MIN, cycles.G_MAX, 0.0
            elif kind == "Weight":
                sock.default_value = (1.0 / k_count,) * 3 + (1.0,)
            else:
                sock.default_value = (0.0, 0.0, 0.0, 1.0)
    iface.new_socket("Weight Scale", in_out="INPUT", socket_type="NodeSocketColor").default_value = (1.0,) * 4
    translucency = iface.new_socket("Translucency", in_out="INPUT", socket_type="NodeSocketFloat")
    translucency.default_value, translucency.min_value, translucency.max_value = 1.0, TRANSLUCENCY_MIN, 100.0
    ior = iface.new_socket("IOR", in_out="INPUT", socket_type="NodeSocketFloat")
    ior.min_value, ior.max_value, ior.default_value = GROUP_IOR_MIN, reflectance_tables.IOR_MAX, DEFAULT_IOR
    rough = iface.new_socket("Roughness", in_out="INPUT", socket_type="NodeSocketFloat")
    rough.min_value, rough.max_value, rough.default_value = 0.0, 1.0, SKIN_ROUGHNESS
    normal = iface.new_socket("Normal", in_out="INPUT", socket_type="NodeSocketVector")
    normal.hide_value = True  # like the Principled BSDF's Normal: unlinked means the shading normal
    add_specular_inputs(group)
    iface.new_socket("Body", in_out="INPUT", socket_type="NodeSocketShader")  # added under the coat (live group)
    iface.new_socket("BSSRDF", in_out="OUTPUT", socket_type="NodeSocketShader")


def add_specular_inputs(group: bpy.types.NodeTree, inputs: dict[str, tuple[str, object]] = SPECULAR_INPUTS) -> None:
    """The Principled BSDF's specular inputs (:data:`SPECULAR_INPUTS`, or ``inputs``: its names and defaults) on
    ``group``."""
    for name, (stype, default) in inputs.items():
        sock = group.interface.new_socket(name, in_out="INPUT", socket_type=stype)
        if stype == "NodeSocketVector":
            sock.hide_value = True  # like the Principled BSDF's: unlinked means the shading normal or tangent
            continue
        sock.default_value = default
        if stype == "NodeSocketFloat":
            sock.min_value, sock.max_value = _RANGES.get(name, (0.0, 1.0))


def _group_io(group: bpy.types.NodeTree) -> tuple[bpy.types.Node, bpy.types.Node]:
    gin = group.nodes.new("NodeGroupInput")
    gout = group.nodes.new("NodeGroupOutput")
    gin.location, gout.location = (-1200.0, 0.0), (1250.0, 0.0)
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


#: Gain of the difference of a weight from the smallest in the middle closure's channel mask (nodes._masked).
MASK_GAIN = 1e6
#: How the SVM group splits each component into closures (module docstring): "nested" (the default: up to three
#: closures per component over nested channel sets, all three channels, the two of largest weight, the largest) or
#: "per_channel" (three single-channel closures per component: the earlier design, kept for comparison).
SVM_DESIGNS = ("nested", "per_channel")


def build_svm_group(k_count: int = 3, name: str = GROUP_NAME, design: str = "nested") -> bpy.types.NodeTree:
    """Build (or rebuild) the SVM node group with ``k_count`` components and closure ``design``
    (:data:`SVM_DESIGNS`); returns the node tree."""
    if not 1 <= k_count <= 7:  # 3K closures + coat + margin must stay below Cycles' MAX_CLOSURE = 64
        raise ValueError("k_count must be in 1..7")
    if design not in SVM_DESIGNS:
        raise ValueError(f"design must be one of {SVM_DESIGNS}, not {design!r}")
    group, gin, gout = _fresh_group(name, k_count, "SVM")
    group["spectral_skin_sss_design"] = design
    build = _svm_mixture if design == "nested" else _svm_mixture_per_channel
    body, fresnel = _body_scale(group, gin)
    zero = computed_zero(group, fresnel)
    through, tint = _under_coat(group, gin)
    scale = product(group, body, _vec(group, "MULTIPLY", gin.outputs["Weight Scale"], tint, x=-1250.0, y=500.0),
                    zero.vector, x=-1150.0, y=500.0)
    mixture = build(group, gin, k_count, scale, zero)
    surface = _add_shader(group, principled_specular(group, gin), mixture, 1050.0, 700.0)
    surface = _add_shader(group, surface, _mix_shader(group, through, gin.outputs["Body"], 1050.0, 500.0), 1150.0,
                          700.0)
    group.links.new(_sheen(group, gin, surface), gout.inputs["BSSRDF"])
    return group


def _svm_mixture(group: bpy.types.NodeTree, gin: bpy.types.Node, k_count: int, scale: bpy.types.NodeSocket,
                 zero: Zero) -> bpy.types.NodeSocket:
    """The nested closures of every component (module docstring), each scaled by its share of w_kc x ``scale``
    (per channel: the Weight Scale times the coat's body weight) and summed; returns the sum.

    With lo <= mid <= hi the component's weights times ``scale`` (one vector node before the sort), sorted over
    channels, w_c = lo + (mid - lo) [w_c >= mid] +
    (hi - mid) [w_c >= hi] exactly (ties included: mid is one of the three weights, picked by min/max, never
    computed).  So closure 1 carries all channels at weight lo, closure 2 the channels with w_c >= mid at mid - lo,
    closure 3 those with w_c >= hi at hi - mid; a channel left out has Color 0 (no weight, no walk) but keeps its
    radius, so Cycles still counts it in the closure's pick weight (closure/bssrdf.h: sample_weight is the mean
    weight times the number of channels with a radius), which keeps every closure's pick weight the sum of its
    channels' weights (a masked channel without its radius would lower the pick weight of the masked closures: 1.23x
    the demo head's noise at equal samples).  A closure of weight 0 is skipped by Cycles."""
    total, overflow, highest = None, None, None
    for k in range(1, k_count + 1):
        y0 = -(k - 1) * 1500.0
        scaled = product(group, gin.outputs[socket_name(k, "Weight")], scale, zero.vector, x=-1050.0, y=y0 - 400.0)
        lo, hi, mid_share, hi_share = _sorted_levels(group, scaled, y0)
        for j, share in enumerate((lo, mid_share, hi_share)):
            y = y0 - j * 450.0
            colour = gin.outputs[socket_name(k, "Color")] if j == 0 \
                else _masked(group, gin.outputs[socket_name(k, "Color")], scaled, lo if j == 1 else hi, zero, y,
                             top=j == 2)
            sss = _closure(group, gin, colour, gin.outputs[socket_name(k, "Radius")], k, y, zero.value)
            sss.label = f"k{k} " + ("RGB", "two largest weights", "largest weight")[j]
            part = _mix_shader(group, share, sss.outputs["BSSRDF"], -150.0, y)
            total = part if total is None else _add_shader(group, total, part, 50.0 + 20.0 * k, y)
            spill = _closure(group, gin, colour, gin.outputs[socket_name(k, "Radius")], k, y - 200.0,
                             roughness=OVERFLOW_ROUGHNESS)
            spill.label = sss.label + " (weight above 1)"
            part = _mix_shader(group, _math(group, "SUBTRACT", share, 1.0, x=-250.0, y=y - 250.0),
                               spill.outputs["BSSRDF"], -150.0, y - 250.0)
            overflow = part if overflow is None else _add_shader(group, overflow, part, 50.0 + 20.0 * k, y - 250.0)
        highest = hi if highest is None else _math(group, "MAXIMUM", highest, hi, x=-700.0, y=y0 - 50.0)
    gate = _math(group, "GREATER_THAN", highest, 1.0, x=-600.0, y=300.0)
    return _add_shader(group, total, _mix_shader(group, gate, overflow, 0.0, 300.0), 150.0, 300.0)


def _sorted_levels(group: bpy.types.NodeTree, scaled: bpy.types.NodeSocket, y: float) -> tuple:
    """(lo, hi, mid - lo, hi - mid) as float sockets: lo <= mid <= hi the channels of ``scaled`` (a component's
    weights) sorted, mid = max(min(w_R, w_G), min(max(w_R, w_G), w_B)), so that each is one of the weights exactly.
    Scalar Math nodes on one Separate Color: a Math node runs in about a third of the instructions of a Vector Math
    node, so eight of them per component cost less than sorting three components at once in vector nodes (a Combine
    per channel, eight vector nodes and four Separates: ``training.bench.instructions``)."""
    sep = group.nodes.new("ShaderNodeSeparateColor")
    sep.location = (-950.0, y - 400.0)
    group.links.new(scaled, sep.inputs[0])
    red, green, blue = sep.outputs
    low_rg = _math(group, "MINIMUM", red, green, x=-850.0, y=y - 350.0)
    high_rg = _math(group, "MAXIMUM", red, green, x=-850.0, y=y - 450.0)
    lo = _math(group, "MINIMUM", low_rg, blue, x=-750.0, y=y - 300.0)
    hi = _math(group, "MAXIMUM", high_rg, blue, x=-750.0, y=y - 400.0)
    mid = _math(group, "MAXIMUM", low_rg, _math(group, "MINIMUM", high_rg, blue, x=-750.0, y=y - 500.0), x=-650.0,
                y=y - 500.0)
    return (lo, hi, _math(group, "SUBTRACT", mid, lo, x=-550.0, y=y - 450.0),
            _math(group, "SUBTRACT", hi, mid, x=-550.0, y=y - 550.0))


class Zero(NamedTuple):
    """A zero computed at each shading point (:func:`computed_zero`), as a float and as a vector."""

    value: bpy.types.NodeSocket
    vector: bpy.types.NodeSocket


def computed_zero(tree: bpy.types.NodeTree, finite: bpy.types.NodeSocket) -> Zero:
    """0 computed from ``finite`` (a float that is finite at every shading point) as finite - finite, for the nodes
    that would otherwise hold 0 as an unlinked input.  Why: Cycles' SVM compiler gives each unlinked input of every
    node it compiles a node of its own that writes the value to the stack at each shading point (a vector costs about
    25 instructions there), and folds a node whose inputs are all constant; a difference of a linked value with
    itself is not folded, so every node linked to it reads one zero from the stack."""
    value = _math(tree, "SUBTRACT", finite, finite, x=-550.0, y=650.0)
    vector = tree.nodes.new("ShaderNodeCombineColor")
    vector.location = (-450.0, 650.0)
    for socket in vector.inputs:
        tree.links.new(value, socket)
    return Zero(value=value, vector=vector.outputs[0])


def product(tree: bpy.types.NodeTree, factor, value: bpy.types.NodeSocket, zero: bpy.types.NodeSocket,
            x: float = 0.0, y: float = 0.0) -> bpy.types.NodeSocket:
    """``factor`` x ``value`` per channel (``factor`` a vector socket, or a float socket or number for every channel)
    as a Mix node (vector; non-uniform for a vector factor; factor unclamped) from ``zero`` (a vector socket that is
    0: :func:`computed_zero`) to ``value``: 0 (1 - t) + v t is v t exactly for finite t.  A Vector Math Multiply
    or Scale runs in about twice the instructions of a Mix in Cycles' SVM and writes its unused inputs (its Scale) to
    the stack at each shading point (``training.bench.instructions``)."""
    mix = tree.nodes.new("ShaderNodeMix")
    mix.location = (x, y)
    mix.data_type = "VECTOR"
    mix.clamp_factor = False
    uniform = not (isinstance(factor, bpy.types.NodeSocket) and factor.type in ("VECTOR", "RGBA"))
    mix.factor_mode = "UNIFORM" if uniform else "NON_UNIFORM"
    fac, a, b = (s for s in mix.inputs if s.enabled)
    if isinstance(factor, bpy.types.NodeSocket):
        tree.links.new(factor, fac)
    else:
        fac.default_value = float(factor)
    tree.links.new(zero, a)
    tree.links.new(value, b)
    return next(s for s in mix.outputs if s.enabled)


def _mix_shader(group: bpy.types.NodeTree, fac: bpy.types.NodeSocket, closure: bpy.types.NodeSocket, x: float,
                y: float) -> bpy.types.NodeSocket:
    """``closure`` x ``fac`` (a Mix Shader of an empty first input; it clamps Fac to [0, 1] itself)."""
    mix = group.nodes.new("ShaderNodeMixShader")
    mix.location = (x, y)
    group.links.new(fac, mix.inputs["Fac"])
    group.links.new(closure, mix.inputs[2])
    return mix.outputs[0]


def _separated(group: bpy.types.NodeTree, gin: bpy.types.Node, k: int, y0: float) -> dict[str, bpy.types.Node]:
    """Separate Color nodes of component k's Color, Radius and Weight inputs, by kind."""
    seps = {}
    for j, kind in enumerate(("Color", "Radius", "Weight")):
        sep = group.nodes.new("ShaderNodeSeparateColor")
        sep.location = (-950.0, y0 - j * 200.0)
        group.links.new(gin.outputs[socket_name(k, kind)], sep.inputs[0])
        seps[kind] = sep
    return seps


def _vec(group: bpy.types.NodeTree, operation: str, a, b=None, x: float = 0.0, y: float = 0.0) -> bpy.types.NodeSocket:
    """A Vector Math node ``operation`` of inputs a, b (sockets, or numbers for all three components; for SCALE, b is
    the Scale, a float socket or number); returns its vector output."""
    node = group.nodes.new("ShaderNodeVectorMath")
    node.operation = operation
    node.location = (x, y)
    for socket, value in ((node.inputs[0], a), (node.inputs["Scale" if operation == "SCALE" else 1], b)):
        if isinstance(value, bpy.types.NodeSocket):
            group.links.new(value, socket)
        elif value is not None:
            socket.default_value = float(value) if socket.name == "Scale" else (float(value),) * 3
    return node.outputs["Vector"]


def _masked(group: bpy.types.NodeTree, colour: bpy.types.NodeSocket, weight: bpy.types.NodeSocket,
            threshold: bpy.types.NodeSocket, zero: Zero, y: float, top: bool = False) -> bpy.types.NodeSocket:
    """``colour`` (RGB, in [0, 1]) where the channel's ``weight`` is >= ``threshold`` (a scalar, one of the weights),
    0 elsewhere.  The largest weight (``top``): colour x floor(weight / threshold), the ratio at most 1, exactly 1 at
    the largest.  The middle one: used only while it exceeds the smallest (else its closure has weight 0, which
    Cycles skips), so the channels it takes are those above the smallest, min(colour, (weight - smallest) x
    :data:`MASK_GAIN`): 0 at the smallest exactly (it is one of the weights, picked by min/max, so the difference is
    exactly 0), the colour wherever a weight exceeds it by 1 / MASK_GAIN, and in between (a weight within 1e-6 of the
    smallest) a part of the colour on a closure whose weight, at most that difference, is below 1e-6.  A threshold of
    0 (Cycles' safe divide: 0) masks every channel, and is only used by a closure of weight 0.  Products are Mix
    nodes from ``zero`` (:func:`product`)."""
    if top:
        ratio = _vec(group, "DIVIDE", weight, threshold, x=-700.0, y=y)
        return product(group, _vec(group, "FLOOR", ratio, x=-600.0, y=y), colour, zero.vector, x=-550.0, y=y)
    above = _vec(group, "SUBTRACT", weight, threshold, x=-700.0, y=y)
    return _vec(group, "MINIMUM", colour, product(group, MASK_GAIN, above, zero.vector, x=-600.0, y=y), x=-550.0, y=y)


def _closure(group: bpy.types.NodeTree, gin: bpy.types.Node, colour: bpy.types.NodeSocket,
             radius: bpy.types.NodeSocket, k: int, y: float, smooth: bpy.types.NodeSocket | None = None,
             roughness: float = ENTRY_ROUGHNESS) -> bpy.types.Node:
    """Subsurface Scattering node of component k (:func:`random_walk_method`, smooth entry at the group's IOR) of
    ``colour`` and ``radius``; its entry Roughness ``smooth`` (a socket that is :data:`ENTRY_ROUGHNESS`, 0: the
    node reads it where it would write a constant at each shading point, :func:`computed_zero`) or else
    ``roughness``."""
    sss = group.nodes.new("ShaderNodeSubsurfaceScattering")
    sss.location = (-450.0, y)
    sss.falloff = random_walk_method()
    group.links.new(gin.outputs["Translucency"], sss.inputs["Scale"])  # 1 (unlinked): the radius as it is
    sss.inputs["Roughness"].default_value = roughness
    if smooth is not None:
        group.links.new(smooth, sss.inputs["Roughness"])
    group.links.new(colour, sss.inputs["Color"])
    group.links.new(radius, sss.inputs["Radius"])
    group.links.new(gin.outputs[socket_name(k, "Anisotropy")], sss.inputs["Anisotropy"])
    group.links.new(gin.outputs["IOR"], sss.inputs["IOR"])
    group.links.new(gin.outputs["Normal"], sss.inputs["Normal"])
    return sss


def _svm_mixture_per_channel(group: bpy.types.NodeTree, gin: bpy.types.Node, k_count: int,
                             scale: bpy.types.NodeSocket, zero: Zero) -> bpy.types.NodeSocket:
    """The 3K single-channel closures, each scaled by w_kc x ``scale`` (per channel: the Weight Scale times the coat's
    body weight) and summed (module docstring); returns the sum."""
    total = None
    factor = group.nodes.new("ShaderNodeSeparateColor")
    factor.location = (-1050.0, 500.0)
    group.links.new(scale, factor.inputs[0])
    for k in range(1, k_count + 1):
        y0 = -(k - 1) * 1500.0
        seps = _separated(group, gin, k, y0)
        for c in range(3):
            y = y0 - c * 450.0
            sss = _channel_closure(group, gin, seps, k, c, y, zero)
            weight = _math(group, "MULTIPLY", seps["Weight"].outputs[c], factor.outputs[c], x=-300.0, y=y + 100.0)
            for part in _weighted(group, sss.outputs["BSSRDF"], weight, y):
                total = part if total is None else _add_shader(group, total, part, 50.0 + 20.0 * k, y)
    return total


def _weighted(group: bpy.types.NodeTree, closure: bpy.types.NodeSocket, weight: bpy.types.NodeSocket,
              y: float) -> list[bpy.types.NodeSocket]:
    """``closure`` x ``weight`` for any weight >= 0: Mix Shaders of Fac weight and weight - 1, which the Mix
    Shader clamps to [0, 1] itself (svm_node_mix_closure), i.e. min(weight, 1) and max(weight - 1, 0) with no node
    of their own; Cycles sums a closure reached along both and skips the second while its Fac is 0, i.e. unless
    the weight exceeds 1."""
    return [_mix_shader(group, fac, closure, -150.0, y - 100.0 * i)
            for i, fac in enumerate((weight, _math(group, "SUBTRACT", weight, 1.0, x=-250.0, y=y - 50.0)))]


def _channel_closure(group, gin, seps: dict, k: int, c: int, y: float, zero: Zero) -> bpy.types.Node:
    """Subsurface Scattering node of component k, channel c (smooth entry at the group's IOR)."""
    col = _single_channel(group, seps["Color"], c, -700.0, y)
    rad = _single_channel(group, seps["Radius"], c, -700.0, y - 150.0)
    sss = _closure(group, gin, col.outputs[0], rad.outputs[0], k, y, zero.value)
    sss.label = f"k{k} {CHANNELS[c]}"
    return sss


def _math(group: bpy.types.NodeTree, operation: str, a, b=None, c=None, x: float = 0.0,
          y: float = 0.0) -> bpy.types.NodeSocket:
    """A Math node ``operation`` of inputs a, b, c (sockets or numbers); returns its output socket."""
    node = group.nodes.new("ShaderNodeMath")
    node.operation = operation
    node.location = (x, y)
    for i, value in enumerate((a, b, c)):
        if isinstance(value, bpy.types.NodeSocket):
            group.links.new(value, node.inputs[i])
        elif value is not None:
            node.inputs[i].default_value = float(value)
    return node.outputs[0]


def _diffuse_fresnel(group: bpy.types.NodeTree, ior: bpy.types.NodeSocket) -> bpy.types.NodeSocket:
    """F_dr(IOR) with Math nodes: Horner's rule on exporters.cycles.DIFFUSE_FRESNEL_POLY in x = (n-1)/(n+1)."""
    n = _math(group, "MAXIMUM", ior, 1.0, x=-950.0, y=900.0)
    x = _math(group, "DIVIDE", _math(group, "SUBTRACT", n, 1.0, x=-800.0, y=950.0),
              _math(group, "ADD", n, 1.0, x=-800.0, y=850.0), x=-650.0, y=900.0)
    poly = cycles.DIFFUSE_FRESNEL_POLY[-1]
    for i, coeff in enumerate(reversed(cycles.DIFFUSE_FRESNEL_POLY[:-1])):
        poly = _math(group, "MULTIPLY_ADD", poly, x, coeff, x=-500.0 + 120.0 * i, y=900.0)
    return _math(group, "MULTIPLY", poly, x, x=0.0, y=900.0)


def principled_specular(group: bpy.types.NodeTree, gin: bpy.types.Node) -> bpy.types.NodeSocket:
    """The coat: a Principled BSDF with a black base (its dielectric specular layer alone, the diffuse closure
    has weight 0 and is dropped) fed the group's Roughness, IOR, Normal, Specular IOR Level, Specular Tint,
    anisotropy (Anisotropic, Anisotropic Rotation, Tangent) and thin film (:data:`COAT_INPUTS`); returns its BSDF
    output."""
    spec = group.nodes.new("ShaderNodeBsdfPrincipled")
    spec.location = (450.0, 1150.0)
    spec.label = "Specular coat"
    spec.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    for name in COAT_INPUTS:
        group.links.new(gin.outputs[name], spec.inputs[name])
    return spec.outputs["BSDF"]


def _body_scale(group: bpy.types.NodeTree,
                gin: bpy.types.Node) -> tuple[bpy.types.NodeSocket, bpy.types.NodeSocket]:
    """(1 - F)/(1 - F_dr) of the coat's index (module docstring): the weight of the mixture below the coat, as
    F (-1 / (1 - F_dr)) + 1 / (1 - F_dr): one node at each shading point (F_dr depends on the index alone, so
    Cycles folds its nodes to constants when the index is one), and the Fresnel node's F (in [0, 1])."""
    coat_ior = _level_ior(group, gin.outputs["IOR"], gin.outputs["Specular IOR Level"])
    fresnel = group.nodes.new("ShaderNodeFresnel")
    fresnel.location = (-650.0, 700.0)
    group.links.new(coat_ior, fresnel.inputs["IOR"])
    group.links.new(gin.outputs["Normal"], fresnel.inputs["Normal"])
    inverse = _math(group, "DIVIDE", 1.0, _math(group, "SUBTRACT", 1.0, _diffuse_fresnel(group, coat_ior), x=150.0,
                                                y=900.0), x=200.0, y=850.0)
    body = _math(group, "MULTIPLY_ADD", fresnel.outputs["Fac"], _math(group, "MULTIPLY", inverse, -1.0, x=250.0,
                                                                      y=850.0), inverse, x=300.0, y=800.0)
    return body, fresnel.outputs["Fac"]


def _add_shader(group: bpy.types.NodeTree, a: bpy.types.NodeSocket, b: bpy.types.NodeSocket, x: float,
                y: float) -> bpy.types.NodeSocket:
    add = group.nodes.new("ShaderNodeAddShader")
    add.location = (x, y)
    group.links.new(a, add.inputs[0])
    group.links.new(b, add.inputs[1])
    return add.outputs[0]


def _level_ior(group: bpy.types.NodeTree, ior: bpy.types.NodeSocket,
               level: bpy.types.NodeSocket) -> bpy.types.NodeSocket:
    """The coat's index with the Principled BSDF's Specular IOR Level: F0 = ((n - 1) / (n + 1))^2 scaled by 2 x level
    (0.5 keeps it, 0 switches the coat off), back to an index (1 + sqrt F0) / (1 - sqrt F0).  The closures keep
    the tissue's IOR."""
    n = _math(group, "MAXIMUM", ior, 1.0, x=-1250.0, y=1100.0)
    r = _math(group, "DIVIDE", _math(group, "SUBTRACT", n, 1.0, x=-1150.0, y=1150.0),
              _math(group, "ADD", n, 1.0, x=-1150.0, y=1050.0), x=-1050.0, y=1100.0)
    gain = _math(group, "SQRT", _math(group, "MULTIPLY", level, 2.0, x=-1150.0, y=1250.0), x=-1050.0, y=1250.0)
    root = _math(group, "MINIMUM", _math(group, "MULTIPLY", r, gain, x=-950.0, y=1150.0), 0.999, x=-850.0, y=1150.0)
    return _math(group, "DIVIDE", _math(group, "ADD", 1.0, root, x=-750.0, y=1200.0),
                 _math(group, "SUBTRACT", 1.0, root, x=-750.0, y=1100.0), x=-650.0, y=1150.0)


def _mix(group: bpy.types.NodeTree, data_type: str, fac: bpy.types.NodeSocket, a, b, x: float,
         y: float) -> bpy.types.NodeSocket:
    """A Mix node of ``data_type`` ("FLOAT", "VECTOR"): ``a`` (1 - fac) + ``b`` fac, factor clamped to [0, 1];
    ``a`` and ``b`` sockets or constants.  Cycles folds it to ``a`` where ``fac`` is a constant 0."""
    mix = group.nodes.new("ShaderNodeMix")
    mix.location = (x, y)
    mix.data_type = data_type
    mix.clamp_factor = True
    fac_in, a_in, b_in = (s for s in mix.inputs if s.enabled)
    group.links.new(fac, fac_in)
    for value, socket in ((a, a_in), (b, b_in)):
        if isinstance(value, bpy.types.NodeSocket):
            group.links.new(value, socket)
        else:
            socket.default_value = value
    return next(s for s in mix.outputs if s.enabled)


def _under_coat(group: bpy.types.NodeTree, gin: bpy.types.Node) -> tuple[bpy.types.NodeSocket, bpy.types.NodeSocket]:
    """What the Principled BSDF's clear coat leaves of the light of the layers under it (the coat itself is the
    coat's Principled node's, :func:`principled_specular`, which layers its own specular under it): (the share
    1 - Coat Weight x F(Coat IOR) through the coat, F the Fresnel reflectance at the view direction and Coat Normal:
    the coat's reflectance, a float; that share times the Coat Tint's colour mix(1, tint^(1/cos t), Coat Weight), per
    channel, cos t the view direction's cosine refracted into the coat, as Cycles' Principled BSDF tints what is
    under its coat).  At Coat Weight 0 both are constant 1 (Cycles folds the Mix nodes to their first input)."""
    weight = gin.outputs["Coat Weight"]
    fresnel = group.nodes.new("ShaderNodeFresnel")
    fresnel.location = (-1650.0, 1500.0)
    group.links.new(gin.outputs["Coat IOR"], fresnel.inputs["IOR"])
    group.links.new(gin.outputs["Coat Normal"], fresnel.inputs["Normal"])
    through = _mix(group, "FLOAT", weight, 1.0, _math(group, "SUBTRACT", 1.0, fresnel.outputs["Fac"], x=-1500.0,
                                                      y=1500.0), -1350.0, 1500.0)
    return through, _vec(group, "SCALE", coat_tint(group, gin), through, x=-500.0, y=1450.0)


def coat_tint(group: bpy.types.NodeTree, gin: bpy.types.Node) -> bpy.types.NodeSocket:
    """The colour the Principled BSDF's clear coat gives what is under it: mix(1, tint^(1/cos t), Coat Weight) per
    channel, cos t the view direction's cosine (at the Coat Normal) refracted into the coat of index Coat IOR, as
    Cycles' Principled BSDF tints the layers under its coat; ``gin`` a node with outputs Coat Weight, Coat IOR, Coat
    Normal and Coat Tint.  At Coat Weight 0 it is constant 1 (Cycles folds the Mix node to its first input)."""
    facing = group.nodes.new("ShaderNodeLayerWeight")  # Facing = 1 - |cos i| at Blend 0.5
    facing.location = (-1650.0, 1300.0)
    facing.inputs["Blend"].default_value = 0.5
    group.links.new(gin.outputs["Coat Normal"], facing.inputs["Normal"])
    cos_i = _math(group, "SUBTRACT", 1.0, facing.outputs["Facing"], x=-1500.0, y=1300.0)
    n = _math(group, "MAXIMUM", gin.outputs["Coat IOR"], 1.0, x=-1500.0, y=1200.0)
    sin_t2 = _math(group, "DIVIDE", _math(group, "SUBTRACT", 1.0, _math(group, "MULTIPLY", cos_i, cos_i, x=-1400.0,
                                                                        y=1300.0), x=-1300.0, y=1300.0),
                   _math(group, "MULTIPLY", n, n, x=-1400.0, y=1200.0), x=-1200.0, y=1300.0)
    depth = _math(group, "DIVIDE", 1.0, _math(group, "SQRT", _math(group, "SUBTRACT", 1.0, sin_t2, x=-1100.0,
                                                                   y=1300.0), x=-1000.0, y=1300.0), x=-900.0, y=1300.0)
    separate = group.nodes.new("ShaderNodeSeparateColor")
    separate.location = (-900.0, 1450.0)
    group.links.new(gin.outputs["Coat Tint"], separate.inputs["Color"])
    combine = group.nodes.new("ShaderNodeCombineXYZ")
    combine.location = (-700.0, 1450.0)
    for i, channel in enumerate(CHANNELS):
        group.links.new(_math(group, "POWER", separate.outputs[channel], depth, x=-800.0, y=1500.0 - 50.0 * i),
                        combine.inputs[i])
    return _mix(group, "VECTOR", gin.outputs["Coat Weight"], (1.0, 1.0, 1.0), combine.outputs["Vector"], -600.0,
                1450.0)


def _sheen(group: bpy.types.NodeTree, gin: bpy.types.Node, surface: bpy.types.NodeSocket) -> bpy.types.NodeSocket:
    """The Principled BSDF's sheen over ``surface``: a Sheen BSDF of colour Sheen Tint weighted Sheen Weight (a Mix
    Shader: in [0, 1], the Principled BSDF's range) added.  Sheen Weight 0 adds no closure: Cycles folds a Mix
    Shader of constant factor 0 away with what feeds it."""
    sheen = group.nodes.new("ShaderNodeBsdfSheen")
    sheen.location = (1250.0, 1100.0)
    group.links.new(gin.outputs["Sheen Tint"], sheen.inputs["Color"])
    group.links.new(gin.outputs["Sheen Roughness"], sheen.inputs["Roughness"])
    group.links.new(gin.outputs["Normal"], sheen.inputs["Normal"])
    weighted = _mix_shader(group, gin.outputs["Sheen Weight"], sheen.outputs[0], 1400.0, 1100.0)
    return _add_shader(group, surface, weighted, 1550.0, 900.0)


def build_osl_group(k_count: int = 3, name: str = GROUP_NAME_OSL) -> bpy.types.NodeTree:
    """The same interface and shader as :func:`build_svm_group`, computed by one OSL Script node (CPU/OptiX only).

    Needs ``scene.cycles.shading_system = True`` to render.  Raises RuntimeError if the script does not
    compile (no sockets appear, or no bytecode).
    """
    if not 1 <= k_count <= 16:
        raise ValueError("k_count must be in 1..16")
    group, gin, gout = _fresh_group(name, k_count, "OSL")
    source = osl.mixture_source(k_count, ENTRY_ROUGHNESS, random_walk_method().lower())
    script = osl.script_node(group.nodes, source, f"spectral_skin_sss_k{k_count}.osl")
    for k in range(1, k_count + 1):
        for kind in KINDS:
            source = gin.outputs[socket_name(k, kind)]
            if kind == "Radius":
                source = _vec(group, "SCALE", source, gin.outputs["Translucency"], x=-450.0, y=-300.0 * k)
            group.links.new(source, script.inputs[osl.param_name(k, kind)])
    for name, param in (("IOR", "ior"), ("Normal", "Normal")):
        group.links.new(gin.outputs[name], script.inputs[param])
    through, tint = _under_coat(group, gin)
    group.links.new(_vec(group, "MULTIPLY", gin.outputs["Weight Scale"], tint, x=-250.0, y=500.0),
                    script.inputs["weight_scale"])
    group.links.new(_level_ior(group, gin.outputs["IOR"], gin.outputs["Specular IOR Level"]), script.inputs["coat_ior"])
    surface = _add_shader(group, principled_specular(group, gin), script.outputs["BSSRDF"], 1050.0, 700.0)
    surface = _add_shader(group, surface, _mix_shader(group, through, gin.outputs["Body"], 1050.0, 500.0), 1150.0,
                          700.0)
    group.links.new(_sheen(group, gin, surface), gout.inputs["BSSRDF"])
    return group


#: Custom property marking the group layout version (bump when the generated nodes change).
GROUP_VERSION = 15


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


def wire_into_material(material: bpy.types.Material, group: bpy.types.NodeTree,
                       images: dict[tuple[int, str], bpy.types.Image] | None = None,
                       interpolation: str = "Closest", output: str = "BSSRDF",
                       eevee_output: str | None = None, into_group: bool = False) -> bpy.types.Node:
    """Add the group (and Image Texture nodes for ``images[(k, kind)]``) to ``material``.

    Every node and link of the artist's is kept: the active Material Output stays fed by what fed it (the Principled
    BSDF, which Blender's exporters read), and the group's ``output`` feeds a Material Output of target Cycles, its
    ``eevee_output`` (default: the same output) one of target EEVEE (blender_addon.wiring: what each renderer
    renders; where the Principled BSDF reaches the output through Mix Shader or Add Shader layers, through a copy of
    them: wiring.shader_chain).  Whatever was wired by the add-on before is removed first.  The name of the node
    that fed the active output is stored in ``material[PREVIOUS_SURFACE_PROP]``.  If that node (or the Principled
    BSDF under its layers) is a Principled BSDF (or a group wired here before), what feeds its Normal (normal map,
    bump chain) also feeds the group's Normal, and its Roughness (the link, else the value) becomes the coat's;
    otherwise the coat gets :data:`SKIN_ROUGHNESS`.  EEVEE's Thickness From Shadow is turned on
    (wiring.use_shadow_thickness: back-lit thin parts glow in EEVEE too).  New nodes sit in a frame labelled
    "Spectral Skin SSS" and are tagged (``wiring.ADDED_PROP``) for removal.  Images are set to Non-Color.
    ``interpolation`` defaults to Closest because the maps hold Cycles' colour A, not the albedo alpha = f(A), and f
    is non-linear (linear filtering gives a small bias at texel edges).  Where the Principled BSDF sits in a node
    group (wiring.grouped_skin) the group goes inside it (:func:`_wire_grouped`): always without ``images`` (the live
    group), with them where ``into_group`` (wiring.bake_into_group).
    Raises ValueError for a linked material (wiring.linked_error).
    Undo: call from an operator with ``bl_options = {'REGISTER', 'UNDO'}``.
    """
    error = wiring.linked_error(material)
    if error:
        raise ValueError(error)
    skin = wiring.grouped_skin(material.node_tree) if (into_group or not images) and wiring.shader_chain(
        material.node_tree)[0] is None else None
    if skin is not None:
        error = next(filter(None, (wiring.group_linked_error(node.node_tree)
                                   for node in (skin.node, *(level.node for level in skin.levels)))), None)
        if error:
            raise ValueError(error)
        wiring.unwire(material)
        gnode = _wire_grouped(material, group, skin, output, eevee_output or output)
        _add_maps(gnode, images or {}, interpolation)
        return gnode
    wiring.unwire(material)
    tree = material.node_tree
    out = wiring.active_output(tree)
    x, y = (out.location.x, out.location.y) if out is not None else (400.0, 0.0)
    frame = wiring.tag(tree.nodes.new("NodeFrame"))
    frame.label = FRAME_LABEL
    gnode = wiring.tag(tree.nodes.new("ShaderNodeGroup"))
    gnode.node_tree = group
    gnode.label = group.name
    gnode.location = (x - 300.0, y - 400.0)
    gnode.parent = frame
    feed = wiring.feeding_socket(out.inputs["Surface"]) if out is not None else None
    previous = feed.node if feed is not None else None
    if previous is not None:
        material[PREVIOUS_SURFACE_PROP] = previous.name
    principled, chain = wiring.shader_chain(tree)  # layers between the Principled BSDF and the output, if any
    wiring.feed_render_outputs(material, {"CYCLES": gnode.outputs[output],
                                          "EEVEE": gnode.outputs[eevee_output or output]}, gnode, chain)
    wiring.use_shadow_thickness(material)
    _take_surface_inputs(tree, principled if chain else previous, gnode)
    if principled is not None:
        wiring.insert_base_layers(tree, principled, gnode)
    _add_maps(gnode, images or {}, interpolation)
    return gnode


def _add_maps(gnode: bpy.types.Node, images: dict[tuple[int, str], bpy.types.Image], interpolation: str) -> None:
    """Image Texture nodes (tagged, Non-Color, in the group node's frame) for ``images[(k, kind)]``, each feeding
    the mixture group node ``gnode``'s input of that map."""
    tree = gnode.id_data
    for i, ((k, kind), image) in enumerate(sorted(images.items())):
        image.colorspace_settings.name = "Non-Color"
        tex = wiring.tag(tree.nodes.new("ShaderNodeTexImage"))
        tex.image = image
        tex.interpolation = interpolation
        tex.label = socket_name(k, kind)
        tex.location = (gnode.location.x - 400.0, gnode.location.y - 60.0 * i)
        tex.parent = gnode.parent
        tree.links.new(tex.outputs["Color"], gnode.inputs[socket_name(k, kind)])


def _wire_grouped(material: bpy.types.Material, group: bpy.types.NodeTree, skin: wiring.GroupedSkin, output: str,
                  eevee_output: str) -> bpy.types.Node:
    """:func:`wire_into_material` where the artist's Principled BSDF sits in a node group (wiring.grouped_skin): the
    group node goes into the node group it sits in (the innermost, where groups are nested) beside it, taking its
    inputs there, and feeds two outputs added to that node group's interface (wiring.feed_group_outputs), which each
    node group around it passes up the same way; the material's Material Outputs of target Cycles and EEVEE are fed
    by those outputs of the artist's group node.  Another material already wired through the same node group keeps
    its group node there (one for every material using it)."""
    inner = skin.principled.id_data  # the node group the Principled BSDF sits in
    gnode = wiring.grouped_group_node(inner)
    if gnode is None or gnode.node_tree != group:
        wiring.unwire_group(inner)
        principled = skin.principled
        frame = wiring.tag(inner.nodes.new("NodeFrame"))
        frame.label = FRAME_LABEL
        gnode = wiring.tag(inner.nodes.new("ShaderNodeGroup"))
        gnode.node_tree = group
        gnode.label = group.name
        gnode.location = (principled.location.x, principled.location.y - 700.0)
        gnode.parent = frame
        gnode[wiring.SKIN_OUTPUT_PROP] = skin.skin_output.identifier
        wiring.feed_group_outputs(inner, {"CYCLES": gnode.outputs[output], "EEVEE": gnode.outputs[eevee_output]},
                                  gnode, skin.inner)
        _take_surface_inputs(inner, principled, gnode)
        wiring.insert_base_layers(inner, principled, gnode)
    for level in reversed(skin.levels):  # the node groups around it pass the outputs up
        wiring.feed_group_outputs(level.node.id_data, wiring.added_outputs_of(level.node), level.node, level.chain)
    material[PREVIOUS_SURFACE_PROP] = skin.node.name
    wiring.feed_render_outputs(material, wiring.added_outputs_of(skin.node), skin.node, skin.outer)
    wiring.use_shadow_thickness(material)
    return gnode


def taken_socket(source: bpy.types.Node, name: str) -> bpy.types.NodeSocket | None:
    """The input of ``source`` (a Principled BSDF, or a group wired before) that a group's input ``name`` takes:
    its input of that name, but a Principled BSDF's Normal for an unlinked Coat Normal (the Principled BSDF's coat
    then takes its Normal; the group's unlinked Coat Normal would be the shading normal); None where it has none."""
    if (name == "Coat Normal" and source.bl_idname == "ShaderNodeBsdfPrincipled"
            and wiring.feeding_socket(source.inputs[name]) is None):
        return source.inputs["Normal"]
    return source.inputs.get(name)


def _surface_source(node: bpy.types.Node | None) -> bpy.types.Node | None:
    """``node`` if it is a Principled BSDF or a mixture group of this add-on (a re-wire), else None."""
    if node is None:
        return None
    if node.bl_idname == "ShaderNodeBsdfPrincipled":
        return node
    tree = getattr(node, "node_tree", None)
    if node.bl_idname == "ShaderNodeGroup" and tree is not None and "spectral_skin_sss_k" in tree:
        return node
    return None


def _take_surface_inputs(tree: bpy.types.NodeTree, previous: bpy.types.Node | None,
                        gnode: bpy.types.Node) -> None:
    """Give the group node ``gnode`` the Normal, Roughness and specular inputs (:data:`SPECULAR_INPUTS`) of the
    surface node it replaces (a Principled BSDF or an earlier mixture or live group): the same links, or their
    values; Roughness :data:`SKIN_ROUGHNESS` when ``previous`` is anything else.  Nothing of the user's is
    changed."""
    source = _surface_source(previous)
    if source is None:
        gnode.inputs["Roughness"].default_value = SKIN_ROUGHNESS
        return
    for name in TAKEN_INPUTS:
        theirs, ours = taken_socket(source, name), gnode.inputs.get(name)
        if theirs is None or ours is None:  # a group wired by an older version, or one without these inputs
            continue
        if name == "Subsurface Weight" and source.bl_idname == "ShaderNodeBsdfPrincipled" \
                and wiring.feeding_socket(theirs) is None and theirs.default_value == 0.0:
            ours.default_value = 1.0  # Blender's default: subsurface never switched on; the operator asks for skin
        else:
            wiring.take_input(tree, theirs, ours)
