"""Render-fidelity probe: what reflectance does Cycles actually produce for a subsurface material?

Scene (built from an empty factory scene): a closed cube of side 100 BU whose top face (z = 0) fills the
view of an orthographic camera looking straight down; a uniform white world (radiance 1); Cycles CPU, fixed
seed, no denoising, no adaptive sampling, no light clamping, view transform 'Standard'.  The rendered
pixels are read back linear (float EXR) and averaged.

What the pixel value means (Cycles 5.0.1 kernel, integrator/subsurface.h): the camera ray enters the
medium at normal incidence through the RANDOM_WALK entry bounce (GGX refraction with roughness 0 and ior
1.01: no Fresnel weight, direction unchanged at normal incidence); the walk exits wherever it reaches the
surface, with no Fresnel term and no internal reflection, and the exit point gets a Lambertian BSDF of
weight 1 lit by the white world, which integrates to exactly 1.  So the pixel equals the total diffuse
reflectance of an *index-matched* (n = 1) semi-infinite medium for *collimated normal incidence*
(by reciprocity also the radiance factor seen from the normal under uniform illumination) -- iadpython's
UR1 with n = 1, not URU.  The cube is >= 1e3 transport mean free paths deep for the media tested, so it is
semi-infinite to far below the noise.

This module imports bpy; it is used by the tests and is handy for users who want to check a material.
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Sequence

import bpy
import numpy as np

from .core import reflectance_tables
from .nodes import random_walk_method

IOR_MIN = reflectance_tables.IOR_MIN

#: Cube half-size (BU); the camera sees the centre of the top face.
HALF_SIZE_BU: float = 50.0
#: Orthographic view width (BU).
VIEW_WIDTH_BU: float = 1.0


def new_scene(samples: int = 256, resolution: int = 16, seed: int = 1) -> bpy.types.Scene:
    """Reset Blender to an empty factory scene and build the probe (cube, camera, white world)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    cyc = scene.cycles
    cyc.device = "CPU"
    cyc.samples = samples
    cyc.use_denoising = False
    cyc.use_adaptive_sampling = False
    cyc.seed = seed
    cyc.sample_clamp_direct = 0.0
    cyc.sample_clamp_indirect = 0.0
    scene.render.resolution_x = scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0

    world = bpy.data.worlds.new("ProbeWorld")
    if world.node_tree is None:  # Blender 4.x: a new world has no nodes until use_nodes is set
        world.use_nodes = True
    scene.world = world
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    background.inputs["Strength"].default_value = 1.0

    mesh = cube_mesh("ProbeSlab", HALF_SIZE_BU)
    slab = bpy.data.objects.new("ProbeSlab", mesh)
    slab.location = (0.0, 0.0, -HALF_SIZE_BU)
    scene.collection.objects.link(slab)

    camera = bpy.data.cameras.new("ProbeCamera")
    camera.type = "ORTHO"
    camera.ortho_scale = VIEW_WIDTH_BU
    cam_obj = bpy.data.objects.new("ProbeCamera", camera)
    cam_obj.location = (0.0, 0.0, 10.0)
    scene.collection.objects.link(cam_obj)
    scene.camera = cam_obj

    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_depth = "32"
    settings.color_mode = "RGBA"
    return scene


def cube_mesh(name: str, half: float) -> bpy.types.Mesh:
    """A closed axis-aligned cube mesh with outward normals (6 quads)."""
    h = half
    verts = [(-h, -h, -h), (h, -h, -h), (h, h, -h), (-h, h, -h), (-h, -h, h), (h, -h, h), (h, h, h), (-h, h, h)]
    faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    mesh.update()
    return mesh


def slab_material(name: str = "ProbeMaterial") -> bpy.types.Material:
    """An empty material (only a Material Output) assigned to the probe slab."""
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender 4.x: a new material has no nodes until use_nodes is set
        mat.use_nodes = True
    tree = mat.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    tree.nodes.new("ShaderNodeOutputMaterial")
    slab = bpy.data.objects["ProbeSlab"]
    slab.data.materials.clear()
    slab.data.materials.append(mat)
    return mat


def material_output(mat: bpy.types.Material) -> bpy.types.Node:
    return next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")


def add_sss_node(tree: bpy.types.NodeTree, color: Sequence[float], radius: Sequence[float], g: float,
                 ior: float = IOR_MIN, roughness: float = 0.0) -> bpy.types.Node:
    """A Subsurface Scattering node (the random walk of blender_addon.nodes.random_walk_method, Scale 1) with
    constant inputs.

    Sockets are set *before* the method is (re)assigned: in Blender 5.0 unavailable sockets are not
    found by name.
    """
    node = tree.nodes.new("ShaderNodeSubsurfaceScattering")
    node.falloff = random_walk_method()
    node.inputs["Color"].default_value = (*map(float, color), 1.0)
    node.inputs["Scale"].default_value = 1.0
    node.inputs["Radius"].default_value = tuple(map(float, radius))
    node.inputs["IOR"].default_value = ior
    node.inputs["Roughness"].default_value = roughness
    node.inputs["Anisotropy"].default_value = g
    return node


def render_mean(scene: bpy.types.Scene | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """Render the probe, return (mean linear RGB (3,), standard error of that mean (3,), seconds).

    The standard error is the pixel standard deviation over sqrt(pixel count): pixels are independent
    samples of the same uniform quantity.
    """
    scene = scene or bpy.context.scene
    with tempfile.TemporaryDirectory(prefix="skin_probe_") as tmp:
        path = os.path.join(tmp, "probe.exr")
        scene.render.filepath = path
        start = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        seconds = time.perf_counter() - start
        image = bpy.data.images.load(path)
        try:
            n = image.size[0] * image.size[1]
            pixels = np.empty(n * 4, dtype=np.float32)
            image.pixels.foreach_get(pixels)
        finally:
            bpy.data.images.remove(image)
    rgb = pixels.reshape(n, 4)[:, :3].astype(np.float64)
    if not np.all(np.isfinite(rgb)):
        raise RuntimeError("Cycles produced non-finite pixels")
    return rgb.mean(axis=0), rgb.std(axis=0, ddof=1) / np.sqrt(n), seconds


def view_from(scene: bpy.types.Scene, mu: float) -> None:
    """Point the probe camera at the slab centre from polar angle arccos(mu) (mu = 1: straight down)."""
    if not 0.0 < mu <= 1.0:
        raise ValueError("mu = cos(view angle) must lie in (0, 1]")
    theta = float(np.arccos(mu))
    cam = scene.camera
    cam.location = (0.0, -10.0 * np.sin(theta), 10.0 * mu)
    cam.rotation_euler = (theta, 0.0, 0.0)


def hemispherical_nodes(n: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Jacobi nodes mu_i and weights w_i (sum 1) with sum_i w_i R(mu_i) ~ 2 int_0^1 R(mu) mu dmu.

    That integral is the cosine-weighted mean of the directional reflectance R(mu) over viewing directions:
    by reciprocity, the diffuse-incidence reflectance (what the model's reflectance is).  With 4 nodes the
    rule is exact to 0.01 % for the isotropic half-space (checked against the H-function).
    """
    from scipy.special import roots_jacobi  # scipy: a test dependency; the probe is a test tool

    x, w = roots_jacobi(n, 0.0, 1.0)
    return (1.0 + x) / 2.0, w / w.sum()


def render_hemispherical(scene: bpy.types.Scene | None = None, n: int = 4
                         ) -> tuple[np.ndarray, np.ndarray, float]:
    """Diffuse-incidence reflectance of the probe material: renders from ``n`` view angles combined by
    :func:`hemispherical_nodes`.  Returns (mean RGB (3,), standard error (3,), seconds)."""
    scene = scene or bpy.context.scene
    mus, weights = hemispherical_nodes(n)
    total, var, seconds = np.zeros(3), np.zeros(3), 0.0
    for mu, w in zip(mus, weights, strict=True):
        view_from(scene, float(mu))
        mean, err, sec = render_mean(scene)
        total += w * mean
        var += (w * err) ** 2
        seconds += sec
    view_from(scene, 1.0)
    return total, np.sqrt(var), seconds
