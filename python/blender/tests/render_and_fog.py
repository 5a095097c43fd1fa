"""Run inside Blender (blender -b --factory-startup --python render_and_fog.py -- OUT_DIR):
renders a small procedural scene (the factory cube on a ground plane under a sun) with Cycles and
the Z pass, fogs it through the mr_fog add-on, and writes for the test outside Blender:
passes as photo.exr + photo_depth.exr (planar Z), the add-on's scene (scene.json), its composite
(addon_composite.exr) and layered EXR (addon_layers.exr), and checks.json (what only Blender
knows: the ground's height seen through the converted camera)."""

import json
import math
import os
import sys

import bpy
import numpy as np

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(here))  # the add-on package (python/blender)
import libmr  # noqa: E402
import mr_fog  # noqa: E402

out = sys.argv[sys.argv.index("--") + 1]
os.makedirs(out, exist_ok=True)
mr_fog.register()

scene = bpy.context.scene
for name in ("Light",):
    if name in bpy.data.objects:
        bpy.data.objects.remove(bpy.data.objects[name], do_unlink=True)
bpy.ops.mesh.primitive_plane_add(size=80.0, location=(0.0, 0.0, -1.0))
bpy.ops.object.light_add(type="SUN", rotation=(math.radians(50), 0.0, math.radians(30)))
sun = bpy.context.active_object
sun.data.energy = 3.0
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = 8
scene.cycles.use_denoising = False  # Debian builds Cycles without OpenImageDenoise
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 96, 72, 100
scene.view_layers[0].use_pass_z = True
scene.render.film_transparent = False
bpy.ops.render.render()

layers, fog_scene, camera = mr_fog.fog_render_result(
    bpy.context, visibility_m=60.0, layer_top_m=8.0, sky_radiance=(0.5, 0.55, 0.6),
    exr_out=os.path.join(out, "addon_layers.exr"))
libmr.write_image(os.path.join(out, "addon_composite.exr"), layers.composite, pixel_type="float")
libmr.save_scene(os.path.join(out, "scene.json"), fog_scene)

# the passes, for `mr fog` outside Blender
mr_fog.save_render_passes(scene, os.path.join(out, "passes.exr"))
image, z = mr_fog.read_passes(os.path.join(out, "passes.exr"))
libmr.write_image(os.path.join(out, "photo.exr"), image, pixel_type="float")
libmr.write_image(os.path.join(out, "photo_depth.exr"), z, pixel_type="float")

# the converted camera and pose against Blender's geometry: the bottom rows show the ground
# plane (Blender z = -1, libmr y = -1); each pixel's point from its depth along the libmr ray
distance = libmr.depth_to_distance(z, camera, kind="z").distance_m[:, :, 0]
heights = []
for y in range(z.shape[0] - 8, z.shape[0]):
    for x in range(0, z.shape[1], 4):
        ray = fog_scene.pose.ray_direction(camera, x, y)
        heights.append(fog_scene.pose.position_m.y + float(distance[y, x]) * ray.y)
target = bpy.data.images.get("libmr fog")
checks = {
    "ground_heights_m": heights,
    "sky_pixels": int(np.count_nonzero(z >= 65504.0)),
    "image_size": list(target.size) if target else None,
    "image_mean": float(np.mean(np.array(target.pixels[:])[0::4])) if target else None,
    "composite_mean": float(layers.composite[:, :, 0].mean()),
    "operator": bpy.ops.image.mr_fog_render_result.idname(),
}
with open(os.path.join(out, "checks.json"), "w") as f:
    json.dump(checks, f)
print("render_and_fog: done")
