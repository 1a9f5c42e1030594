"""Scenes where subsurface light dominates, for the render-cost benchmark (training.bench.render_cost).

Head-sized skin-textured objects, metres at Unit Scale 1, lit hard from behind by a small point light and softly
from the front by a large, dim area light beside the camera, a near-black world, Cycles on the CPU without
denoiser:

* ``"backlit_head"``: the demo head (training.demo_subject: head with ears, training.demo_render's camera) with the
  demo's key light replaced by the soft fill and the back light behind the ear made harder and
  :data:`HEAD_BACK_POWER_W` strong: the ear and the head's rim glow with light that came through the skin.
* ``"backlit_plate"``: a sphere of a head's radius (:data:`PLATE_RADIUS_M`) flattened to :data:`PLATE_THICKNESS_M`
  along the view (the thickness of an ear), the point light straight behind it: most of the light the camera sees
  has crossed the plate.

Run inside a Blender process (bpy); the plate's texture coordinates are the sphere primitive's UVs.
"""

from __future__ import annotations

#: The scenes, in the order of the benchmark's rows.
SCENES = ("backlit_head", "backlit_plate")
#: Back light of the head: power (W) and radius (m); it stays where the demo puts it (behind the ear).
HEAD_BACK_POWER_W, HEAD_BACK_RADIUS_M = 80.0, 0.005
PLATE_RADIUS_M = 0.09
PLATE_THICKNESS_M = 0.006
#: Camera of the plate: position (metres), looking at the origin, focal length (mm).
PLATE_CAMERA_M, LENS_MM = (0.0, -0.65, 0.0), 100.0
#: Hard back light of the plate: (location m, power W, radius m).
PLATE_LIGHT = ((0.02, 0.25, 0.02), 30.0, 0.005)
#: Soft front fill: an area light (power W, size m) at this offset (m) from the camera, aimed at its target.
FILL_POWER_W, FILL_SIZE_M, FILL_OFFSET_M = 1.5, 0.6, (-0.25, 0.05, 0.20)
WORLD_GREY = 0.01


def build(kind: str, resolution: int):
    """Empty factory scene holding scene ``kind`` (:data:`SCENES`) at ``resolution`` squared px, Cycles CPU, no
    denoiser.  Returns (scene, objects to give the material)."""
    import bpy

    from training import demo_render

    if kind not in SCENES:
        raise ValueError(f"scene must be one of {SCENES}, not {kind!r}")
    if kind == "backlit_head":
        scene, parts = demo_render._scene(resolution, 1)
        bpy.data.objects.remove(bpy.data.objects["Key light"])
        back = bpy.data.objects["Back light"].data
        back.energy, back.shadow_soft_size = HEAD_BACK_POWER_W, HEAD_BACK_RADIUS_M
        camera, target = demo_render.CAMERA_M, demo_render.TARGET_M
    else:
        scene, parts = _plate_scene(resolution)
        camera, target = PLATE_CAMERA_M, (0.0, 0.0, 0.0)
    scene.cycles.use_denoising = False
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (WORLD_GREY,) * 3 + (1.0,)
    fill = bpy.data.objects.new("Fill light", bpy.data.lights.new("Fill light", "AREA"))
    fill.data.energy, fill.data.size = FILL_POWER_W, FILL_SIZE_M
    demo_render._look_at(fill, tuple(c + o for c, o in zip(camera, FILL_OFFSET_M, strict=True)), target)
    scene.collection.objects.link(fill)
    return scene, parts


def _plate_scene(resolution: int):
    import bpy

    from training import demo_render

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.max_bounces = 6
    scene.render.resolution_x = scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 1.0
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=PLATE_RADIUS_M)
    obj = bpy.context.active_object
    obj.name = "backlit_plate"
    bpy.ops.object.shade_smooth()
    obj.scale = (1.0, PLATE_THICKNESS_M / (2.0 * PLATE_RADIUS_M), 1.0)
    bpy.ops.object.transform_apply(scale=True)
    scene.world = bpy.data.worlds.new("World")
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = LENS_MM
    demo_render._look_at(cam, PLATE_CAMERA_M, (0.0, 0.0, 0.0))
    scene.collection.objects.link(cam)
    scene.camera = cam
    demo_render._point_light(scene, "Back light", PLATE_LIGHT)
    return scene, [obj]
