"""libmr fog for Blender (issue 15): physically based fog from a render's Image and Depth (Z)
passes, the scene camera and its sun lamp, written back as a Blender image and a layered EXR.

Install: copy or link this folder (mr_fog) into Blender's add-ons folder, or run Blender with
the libmr package importable (PYTHONPATH=<build>/python: Debian's blender runs the system
Python 3.11, so the same `libmr` module imports inside it). Render with the Z pass on
(View Layer Properties > Passes > Z), then Image editor / F3: "Fog Render Result (libmr)".

Conventions: Blender's world is Z up; libmr's is Y up with the camera looking along +Z at yaw 0,
image x right and y down. A Blender point (x, y, z) is libmr's (x, z, y) (metres), which maps
the camera's right, up and view axes onto libmr's. Cycles' and Eevee's Z pass is planar z-depth
(metres along the view axis; 1e10 for the background, libmr's sky). The focal length in pixels
comes from the lens and sensor (sensor fit), the sun's irradiance from its strength (W/m^2,
the units of the render's radiance) times its colour.
"""

bl_info = {
    "name": "libmr fog",
    "author": "libmr",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Image Editor > Image > Fog Render Result (libmr)",
    "description": "Physically based fog (single scattering, volumetric shadows) from the "
                   "render's Image and Depth passes with the scene camera and sun",
    "category": "Compositing",
}

import math
import os
import tempfile

import numpy as np

try:
    import bpy
    from bpy.props import BoolProperty, FloatProperty, FloatVectorProperty, StringProperty
except ImportError:  # imported outside Blender (docs, tests of the conversions)
    bpy = None

import libmr


def to_libmr(v):
    """A Blender world vector (Z up) as libmr's world frame (Y up): (x, y, z) -> (x, z, y)."""
    return (float(v[0]), float(v[2]), float(v[1]))


def camera_from_blender(cam, width, height):
    """libmr.Camera (pixels) of a Blender camera datablock at width x height pixels."""
    if cam.type != "PERSP":
        raise ValueError(f"camera {cam.name}: only perspective cameras are supported, not {cam.type}")
    fit = cam.sensor_fit
    if fit == "AUTO":
        fit = "HORIZONTAL" if width >= height else "VERTICAL"
    if fit == "HORIZONTAL":
        span = width
        sensor = cam.sensor_width
    else:
        span = height
        sensor = cam.sensor_height if cam.sensor_fit == "VERTICAL" else cam.sensor_width
    focal_px = cam.lens / sensor * span
    size = max(width, height)
    return libmr.Camera(width, height, focal_px, width / 2.0 - cam.shift_x * size,
                        height / 2.0 + cam.shift_y * size)


def pose_from_blender(matrix_world):
    """libmr.CameraPose of a Blender camera object's world matrix (it looks along its -Z, its
    +Y is up in the image)."""
    m = matrix_world
    position = to_libmr(m.translation)
    forward = np.array(to_libmr(-m.col[2].xyz.normalized()))
    up = np.array(to_libmr(m.col[1].xyz.normalized()))
    yaw = math.atan2(forward[0], forward[2])
    pitch = math.asin(max(-1.0, min(1.0, forward[1])))
    right0 = np.array([math.cos(yaw), 0.0, -math.sin(yaw)])
    up0 = np.cross(forward, right0)  # mr::CameraPose::axes
    roll = math.atan2(float(up @ right0), float(up @ up0))
    return libmr.CameraPose(position_m=position, yaw_deg=math.degrees(yaw),
                            pitch_deg=math.degrees(pitch), roll_deg=math.degrees(roll))


def sun_from_blender(light_object):
    """libmr.Sun of a Blender sun lamp: toward the sun = its +Z axis; irradiance = strength *
    colour (W/m^2, the render's units); its angle (diameter) as the angular radius."""
    light = light_object.data
    direction = to_libmr(light_object.matrix_world.col[2].xyz.normalized())
    e = light.energy
    return libmr.Sun(direction_to_sun=direction,
                     irradiance=tuple(float(e * c) for c in light.color),
                     angular_radius_deg=max(math.degrees(light.angle) / 2.0, 0.0))


def fog_scene(blender_scene, width, height, visibility_m=150.0, layer_top_m=50.0,
              sky_radiance=None, quality="normal"):
    """The libmr.Scene and libmr.Camera of a Blender scene: its camera, its first sun lamp
    (if any), fog of `visibility_m` metres (Koschmieder) up to `layer_top_m` metres above z = 0
    (0: no top), lit by `sky_radiance` (None: estimated from the image)."""
    cam_obj = blender_scene.camera
    if cam_obj is None:
        raise ValueError("the scene has no camera")
    camera = camera_from_blender(cam_obj.data, width, height)
    scene = libmr.Scene()
    scene.pose = pose_from_blender(cam_obj.matrix_world)
    sigma = libmr.extinction_from_visibility(visibility_m)
    scene.medium.sigma_t_per_m = (sigma, sigma, sigma)
    if layer_top_m > 0:
        scene.medium.layer_top_m = layer_top_m
    suns = [o for o in blender_scene.objects if o.type == "LIGHT" and o.data.type == "SUN"
            and not o.hide_render]
    if suns:
        scene.lighting.sun = sun_from_blender(suns[0])
    if sky_radiance is not None:
        scene.lighting.sky_radiance = tuple(float(c) for c in sky_radiance)
    scene.render.quality = getattr(libmr.Quality, quality)
    scene.camera = libmr.scene_camera(camera)
    return scene, camera


def read_passes(exr_path):
    """Combined RGB (H, W, 3) and Z (H, W) float32 from a Blender multilayer EXR."""
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(exr_path)
    if buf.has_error:
        raise RuntimeError(f"{exr_path}: {buf.geterror()}")
    names = list(buf.spec().channelnames)
    pixels = buf.get_pixels(oiio.FLOAT)

    def channel(suffix):
        for i, n in enumerate(names):
            if n.endswith(suffix):
                return pixels[:, :, i]
        raise ValueError(f"{exr_path}: no channel *{suffix} (channels: {', '.join(names)}); "
                         "render with the Z pass on")

    rgb = np.stack([channel("Combined.R"), channel("Combined.G"), channel("Combined.B")], -1)
    return np.ascontiguousarray(rgb, np.float32), np.ascontiguousarray(channel("Depth.Z"), np.float32)


def fog_passes(image, z, scene, camera, exr_out=None):
    """Fog through libmr: image (H, W, 3) scene-linear, z (H, W) planar z-depth in metres.
    Writes `exr_out` (R,G,B + transmittance + inscatter + depth.Z layers) when given."""
    depth = libmr.depth_to_distance(z, camera, kind="z")
    layers = libmr.fog(image, depth.distance_m, scene, camera=camera)
    if exr_out:
        libmr.write_exr_layers(exr_out, [("", layers.composite), ("transmittance", layers.transmittance),
                                         ("inscatter", layers.inscatter),
                                         ("depth", depth.distance_m, True, ["Z"])],
                               pixel_type="float")
    return layers


def save_render_passes(blender_scene, path):
    """Writes the Render Result (all passes) as a float multilayer EXR."""
    result = bpy.data.images.get("Render Result")
    if result is None:
        raise ValueError("no render result: render first (F12) with the Z pass on")
    settings = blender_scene.render.image_settings
    saved = (settings.file_format, settings.color_depth)
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    try:
        result.save_render(path, scene=blender_scene)
    finally:
        settings.file_format, settings.color_depth = saved


def fog_render_result(context, visibility_m=150.0, layer_top_m=50.0, sky_radiance=None,
                      exr_out=None, image_name="libmr fog"):
    """The operator's work: the last render's passes fogged into a Blender image (and
    `exr_out`). Returns (layers, scene, camera)."""
    blender_scene = context.scene
    with tempfile.TemporaryDirectory() as tmp:
        passes = os.path.join(tmp, "passes.exr")
        save_render_passes(blender_scene, passes)
        image, z = read_passes(passes)
    h, w = z.shape
    scene, camera = fog_scene(blender_scene, w, h, visibility_m, layer_top_m, sky_radiance)
    layers = fog_passes(image, z, scene, camera, exr_out)
    target = bpy.data.images.get(image_name) or bpy.data.images.new(image_name, w, h, alpha=True,
                                                                     float_buffer=True)
    if tuple(target.size) != (w, h):
        target.scale(w, h)
    rgba = np.ones((h, w, 4), np.float32)
    rgba[:, :, :3] = layers.composite[:, :, :3]
    target.pixels.foreach_set(np.ascontiguousarray(rgba[::-1]).ravel())  # Blender: bottom row first
    target.update()
    return layers, scene, camera


if bpy is not None:

    class MR_OT_fog_render_result(bpy.types.Operator):
        """Put physically based fog (libmr) into the last render, from its Image and Z passes"""

        bl_idname = "image.mr_fog_render_result"
        bl_label = "Fog Render Result (libmr)"
        bl_options = {"REGISTER"}

        visibility_m: FloatProperty(name="Visibility (m)", default=150.0, min=0.1,
                                    description="Meteorological visibility, metres (sigma_t = 3.912 / V)")
        layer_top_m: FloatProperty(name="Fog top (m)", default=50.0, min=0.0,
                                   description="Height of the fog layer's top above z = 0, metres (0: none)")
        sky_from_image: BoolProperty(name="Sky light from the image", default=True)
        sky_radiance: FloatVectorProperty(name="Sky radiance", default=(0.8, 0.8, 0.8), min=0.0,
                                          subtype="COLOR", size=3)
        exr_path: StringProperty(name="Layered EXR", default="", subtype="FILE_PATH",
                                 description="Also write R,G,B + transmittance + inscatter + depth here")

        def execute(self, context):
            try:
                fog_render_result(context, self.visibility_m, self.layer_top_m,
                                  None if self.sky_from_image else tuple(self.sky_radiance),
                                  bpy.path.abspath(self.exr_path) or None)
            except (libmr.Error, ValueError, RuntimeError) as e:
                self.report({"ERROR"}, str(e))
                return {"CANCELLED"}
            self.report({"INFO"}, "libmr fog: image 'libmr fog'")
            return {"FINISHED"}

    def _menu(self, context):
        self.layout.operator(MR_OT_fog_render_result.bl_idname)

    def register():
        bpy.utils.register_class(MR_OT_fog_render_result)
        bpy.types.IMAGE_MT_image.append(_menu)

    def unregister():
        bpy.types.IMAGE_MT_image.remove(_menu)
        bpy.utils.unregister_class(MR_OT_fog_render_result)
