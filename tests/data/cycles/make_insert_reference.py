# Cycles references for issue 16's acceptance scene (tests/insert_scene.h): the "photo" (ground,
# side wall, back wall, pillar) and the same scene with the inserted sphere and box, rendered by
# Blender's path tracer with the product's light model: direct light only (no bounces), a sun
# with its disk, a uniform sky over the upper hemisphere (black below the horizon), Lambert +
# GGX (Schlick F, F0 0.04) surfaces, box-filtered pixels. A development tool, not run by CI:
#
#   blender -b --factory-startup -P tests/data/cycles/make_insert_reference.py -- tests/data/cycles [samples]
#
# writes photo.exr and with_objects.exr (linear RGB, half float, 128 x 96). The product's
# coordinates (x right, y up, z forward) map to Blender's as (x, z, y).
import math
import os
import sys

import bpy
from mathutils import Vector

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
out_dir = argv[0] if argv else "."
samples = int(argv[1]) if len(argv) > 1 else 4096


def b(v):  # product (x, y, z) -> Blender (x, z, y)
    return (v[0], v[2], v[1])


def direction_from_azimuth_elevation(az_deg, el_deg):
    ce = math.cos(math.radians(el_deg))
    return (ce * math.sin(math.radians(az_deg)), math.sin(math.radians(el_deg)),
            ce * math.cos(math.radians(az_deg)))


def material(name, albedo, specular, roughness):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (*albedo, 1)
    diffuse.inputs["Roughness"].default_value = 0.0  # Lambert
    if not specular:
        nt.links.new(diffuse.outputs[0], out.inputs["Surface"])
        return m
    # f_r = albedo / pi + F D G / (4 n.l n.v): Cycles' GGX lobe tinted by a Fresnel of F0 = 0.04
    # (IOR 1.5, the exact dielectric Fresnel on the shading normal; the product uses Schlick's
    # on the half vector: they differ at grazing angles only).
    glossy = nt.nodes.new("ShaderNodeBsdfGlossy")
    glossy.distribution = "GGX"
    glossy.inputs["Roughness"].default_value = roughness  # Blender squares it: alpha = r^2
    fres = nt.nodes.new("ShaderNodeFresnel")
    fres.inputs["IOR"].default_value = 1.5
    nt.links.new(fres.outputs[0], glossy.inputs["Color"])
    add = nt.nodes.new("ShaderNodeAddShader")
    nt.links.new(diffuse.outputs[0], add.inputs[0])
    nt.links.new(glossy.outputs[0], add.inputs[1])
    nt.links.new(add.outputs[0], out.inputs["Surface"])
    return m


def add_box(name, lo, hi, mat):
    c = [(lo[i] + hi[i]) / 2 for i in range(3)]
    s = [(hi[i] - lo[i]) / 2 for i in range(3)]
    bpy.ops.mesh.primitive_cube_add(location=b(c))
    o = bpy.context.object
    o.name = name
    o.scale = b(s)
    o.data.materials.append(mat)
    return o


def build(with_objects):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 0  # direct light only, as the product's differential renderer
    scene.cycles.sample_clamp_direct = 0
    scene.cycles.sample_clamp_indirect = 0
    scene.cycles.seed = 1
    scene.cycles.filter_type = "BOX"
    scene.cycles.filter_width = 1.0
    scene.render.resolution_x, scene.render.resolution_y = 128, 96
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_mode = "RGB"
    scene.render.image_settings.color_depth = "16"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"

    # Camera: from_horizontal_fov(128, 96, 60), at (0, 1.6, 0), pitch -9 degrees.
    cam_data = bpy.data.cameras.new("camera")
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.angle_x = math.radians(60)
    cam = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = b((0, 1.6, 0))
    cam.rotation_euler = (math.radians(90 - 9), 0, 0)
    scene.camera = cam

    # Sun: azimuth 125, elevation 38, irradiance (3.0, 2.9, 2.7), angular radius 0.27 degrees.
    sun_data = bpy.data.lights.new("sun", "SUN")
    e = (3.0, 2.9, 2.7)
    sun_data.energy = max(e)
    sun_data.color = tuple(c / max(e) for c in e)
    sun_data.angle = math.radians(2 * 0.27)
    sun = bpy.data.objects.new("sun", sun_data)
    scene.collection.objects.link(sun)
    to_sun = Vector(b(direction_from_azimuth_elevation(125, 38)))
    sun.rotation_euler = to_sun.to_track_quat("Z", "Y").to_euler()

    # Sky: (0.30, 0.36, 0.48) over the upper hemisphere, black below the horizon.
    world = bpy.data.worlds.new("world")
    scene.world = world
    world.use_nodes = True
    nt = world.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputWorld")
    bg = nt.nodes.new("ShaderNodeBackground")
    coord = nt.nodes.new("ShaderNodeTexCoord")
    sep = nt.nodes.new("ShaderNodeSeparateXYZ")
    above = nt.nodes.new("ShaderNodeMath")
    above.operation = "GREATER_THAN"
    above.inputs[1].default_value = 0.0
    mix = nt.nodes.new("ShaderNodeMixRGB")
    mix.inputs[1].default_value = (0, 0, 0, 1)
    mix.inputs[2].default_value = (0.30, 0.36, 0.48, 1)
    nt.links.new(coord.outputs["Generated"], sep.inputs[0])
    nt.links.new(sep.outputs["Z"], above.inputs[0])
    nt.links.new(above.outputs[0], mix.inputs[0])
    nt.links.new(mix.outputs[0], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = 1.0
    nt.links.new(bg.outputs[0], out.inputs["Surface"])

    ground = material("ground", (0.40, 0.38, 0.35), False, 1)
    wall = material("wall", (0.60, 0.55, 0.50), False, 1)
    pillar = material("pillar", (0.30, 0.30, 0.32), False, 1)
    bpy.ops.mesh.primitive_plane_add(size=2000, location=(0, 0, 0))
    bpy.context.object.data.materials.append(ground)
    add_box("side_wall", (3.5, 0, 5), (4.5, 3.5, 20), wall)
    add_box("back_wall", (-10, 0, 20), (10, 6, 21), wall)
    add_box("pillar", (-2.4, 0, 5), (-1.9, 2.2, 5.5), pillar)
    if with_objects:
        sphere_mat = material("sphere", (0.80, 0.25, 0.20), True, 0.5)
        box_mat = material("box", (0.20, 0.45, 0.75), True, 0.7)
        r = 0.7
        bpy.ops.mesh.primitive_uv_sphere_add(segments=192, ring_count=96, radius=r,
                                             location=b((-0.6, r, 9)))
        bpy.ops.object.shade_smooth()
        bpy.context.object.data.materials.append(sphere_mat)
        add_box("box", (0.9, 0, 10), (2.1, 1.2, 11.2), box_mat)


for name, objects in (("photo", False), ("with_objects", True)):
    build(objects)
    bpy.context.scene.render.filepath = os.path.abspath(os.path.join(out_dir, name + ".exr"))
    bpy.ops.render.render(write_still=True)
