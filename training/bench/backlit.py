"""Scenes where subsurface light dominates, for the render-cost benchmark (training.bench.render_cost).

A head-sized skin-textured object, metres at Unit Scale 1, lit hard from behind by a small point light and softly
from the front by a large, dim area light, a near-black world, Cycles on the CPU without denoiser:

* ``"backlit_sphere"``: a sphere of radius :data:`SPHERE_RADIUS_M` (a head's size); the back light stands behind
  it a little off the camera axis, so the light reaching the camera comes through the sphere's rim, a crescent of
  skin lit from inside, beside the front fill.
* ``"backlit_plate"``: the same sphere flattened to :data:`PLATE_THICKNESS_M` along the view (the thickness of an
  ear or of the web of a hand, at a head's height and width) in front of the back light: most of the light the
  camera sees has crossed the plate.

Run inside a Blender process (bpy); the texture's UVs are the sphere primitive's.
"""

from __future__ import annotations

#: The two scenes, in the order of the benchmark's rows.
SCENES = ("backlit_sphere", "backlit_plate")
#: Radius of the sphere (metres): a head's half-width.
SPHERE_RADIUS_M = 0.09
#: Thickness of the plate along the view (metres).
PLATE_THICKNESS_M = 0.006
#: Camera: position (metres), looking at the origin, focal length (mm).
CAMERA_M, LENS_MM = (0.0, -0.65, 0.0), 100.0
#: Hard back light: (location m, power W, radius m) per scene.
BACK_LIGHTS = {"backlit_sphere": ((0.07, 0.30, 0.05), 60.0, 0.005),
               "backlit_plate": ((0.02, 0.25, 0.02), 30.0, 0.005)}
#: Soft front fill: an area light (location m, power W, size m) beside the camera.
FILL_LIGHT = ((-0.25, -0.60, 0.20), 1.5, 0.6)
WORLD_GREY = 0.01


def build(kind: str, resolution: int):
    """Empty factory scene holding scene ``kind`` (:data:`SCENES`) at ``resolution`` squared px, Cycles CPU, no
    denoiser.  Returns (scene, [object])."""
    import bpy

    from training import demo_render

    if kind not in SCENES:
        raise ValueError(f"scene must be one of {SCENES}, not {kind!r}")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 6
    scene.render.resolution_x = scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 1.0
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=SPHERE_RADIUS_M)
    obj = bpy.context.active_object
    obj.name = kind
    bpy.ops.object.shade_smooth()
    if kind == "backlit_plate":
        obj.scale = (1.0, PLATE_THICKNESS_M / (2.0 * SPHERE_RADIUS_M), 1.0)
        bpy.ops.object.transform_apply(scale=True)
    world = bpy.data.worlds.new("World")
    scene.world = world
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (WORLD_GREY,) * 3 + (1.0,)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = LENS_MM
    demo_render._look_at(cam, CAMERA_M, (0.0, 0.0, 0.0))
    scene.collection.objects.link(cam)
    scene.camera = cam
    demo_render._point_light(scene, "Back light", BACK_LIGHTS[kind])
    location, power, size = FILL_LIGHT
    fill = bpy.data.objects.new("Fill light", bpy.data.lights.new("Fill light", "AREA"))
    fill.data.energy, fill.data.size = power, size
    demo_render._look_at(fill, location, (0.0, 0.0, 0.0))
    scene.collection.objects.link(fill)
    return scene, [obj]
