"""fog() through Python against closed forms (DESIGN.md section 3)."""

import numpy as np
import pytest

import libmr
from conftest import SAMPLES, sky_only_scene


def synthetic(rng, h=24, w=32):
    photo = rng.random((h, w, 3), dtype=np.float32)
    depth = rng.uniform(1.0, 400.0, (h, w)).astype(np.float32)
    depth[:3, :] = np.inf  # a band of sky
    return photo, depth


def test_sky_only_fog_is_koschmieder(rng):
    # Homogeneous fog, albedo 1, lit by the sky alone: T = exp(-sigma_t d), C = I T + L (1 - T)
    # (the required regression of DESIGN.md section 3). float32 outputs of a double-precision
    # core: |error| <= 2e-6 on T and R, <= 2e-6 relative on C.
    photo, depth = synthetic(rng)
    scene = sky_only_scene(libmr)
    layers = libmr.fog(photo, depth, scene)
    sigma = np.array(scene.medium.sigma_t_per_m, np.float64)
    sky = np.array(scene.lighting.sky_radiance, np.float64)
    t = np.exp(-sigma * depth[:, :, None].astype(np.float64))
    for name in ("composite", "transmittance", "inscatter"):
        a = getattr(layers, name)
        assert a.dtype == np.float32 and a.shape == photo.shape and not a.flags.owndata
    np.testing.assert_allclose(layers.transmittance, t, rtol=0, atol=2e-6)
    np.testing.assert_allclose(layers.inscatter, sky * (1 - t), rtol=0, atol=2e-6)
    np.testing.assert_allclose(layers.composite, photo * t + sky * (1 - t), rtol=2e-6, atol=2e-7)
    # sky pixels: T = 0, C = L (fog colour)
    assert (layers.transmittance[:3] == 0).all()
    np.testing.assert_allclose(layers.composite[:3], np.broadcast_to(sky, (3, 32, 3)), rtol=1e-6)
    assert layers.sky_radiance == pytest.approx(sky)
    assert layers.backend == "cpu" or layers.backend.startswith("vulkan")
    assert layers.sun_visibility.shape == (24, 32, 1)
    # optical depth AOV = sigma_t d
    np.testing.assert_allclose(layers.optical_depth[3:], (sigma * depth[3:, :, None]), rtol=1e-6)


def test_fog_homogeneous_closed_form(rng):
    photo, depth = synthetic(rng)
    layers = libmr.fog_homogeneous(photo, depth, 0.01, airlight=(0.7, 0.7, 0.8))
    t = np.exp(-0.01 * depth.astype(np.float64))[:, :, None]
    np.testing.assert_allclose(layers.transmittance, np.broadcast_to(t, photo.shape), atol=2e-6)
    np.testing.assert_allclose(layers.composite, photo * t + np.array([0.7, 0.7, 0.8]) * (1 - t), atol=2e-6)
    assert layers.sun_visibility is None


def test_height_fog_transmittance_closed_form(rng):
    # Exponential height fog, sky light only: optical depth to distance t along w is
    # k H (1 - exp(-t w_y / H)) / w_y with k = sigma_t0 exp(-(o_y - h0) / H) (DESIGN.md section 3).
    h, w = 20, 30
    cam = libmr.Camera.from_horizontal_fov(w, h, 70.0)
    scene = libmr.Scene()
    scene.pose.pitch_deg = 10.0
    scene.medium.sigma_t_per_m = (0.05, 0.05, 0.05)
    scene.medium.height_fog = libmr.Medium.HeightFog(base_height_m=0.0, scale_height_m=8.0)
    scene.lighting.sky_radiance = (1.0, 1.0, 1.0)
    depth = rng.uniform(5.0, 200.0, (h, w)).astype(np.float32)
    layers = libmr.fog(rng.random((h, w, 3), dtype=np.float32), depth, scene, camera=cam)
    o_y, big_h = scene.pose.position_m.y, 8.0
    k = 0.05 * np.exp(-(o_y - 0.0) / big_h)
    expected = np.empty((h, w))
    for y in range(h):
        for x in range(w):
            wy = scene.pose.ray_direction(cam, x, y).y
            t = float(depth[y, x])
            tau = k * t if abs(wy) < 1e-12 else k * big_h * (1 - np.exp(-t * wy / big_h)) / wy
            expected[y, x] = np.exp(-tau)
    np.testing.assert_allclose(layers.transmittance[:, :, 0], expected, rtol=1e-5, atol=1e-6)


def test_fog_with_sun_runs_the_core_and_is_deterministic():
    photo = libmr.read_image(SAMPLES / "aerial.jpg")
    depth = libmr.read_depth(SAMPLES / "aerial_depth.exr").distance_m
    scene = libmr.Scene()
    scene.medium.layer_top_m = 80.0
    scene.lighting.sun = libmr.Sun(direction_to_sun=libmr.direction_from_azimuth_elevation(40, 35),
                                   irradiance=(4, 4, 4))
    scene.lighting.sky_radiance = (0.5, 0.55, 0.6)
    scene.render.quality = libmr.Quality.draft
    a = libmr.fog(photo, depth, scene)
    b = libmr.fog(photo, depth, scene)
    np.testing.assert_array_equal(a.composite, b.composite)
    assert a.timings["total_s"] > 0 and a.timings["exact_pixels"] > 0
    assert 0 <= a.sun_visibility.min() and a.sun_visibility.max() <= 1
    assert a.warnings == []
    # fog dims what it covers and brightens nothing past the photo plus in-scatter
    np.testing.assert_allclose(a.composite, photo * a.transmittance + a.inscatter, rtol=1e-5, atol=1e-6)


def test_shadow_traversals_render_identically(rng):
    # Issue 17: the multi-index kd-tree answers every shadow ray as Embree does, so a sunlit CPU
    # render is bit-identical with either (the sun casts shadows of the depth map's relief).
    photo = rng.random((48, 64, 3), dtype=np.float32)
    depth = rng.uniform(3.0, 30.0, (48, 64)).astype(np.float32)
    s = libmr.Scene()
    s.lighting.sun = libmr.Sun(direction_to_sun=(0.6, 0.3, 0.4), irradiance=(3, 3, 3))
    s.lighting.sky_radiance = (0.5, 0.5, 0.5)
    s.render.quality = libmr.Quality.draft
    s.render.backend = libmr.Backend.cpu
    a = libmr.fog(photo, depth, s)
    s.render.shadow_traversal = libmr.ShadowTraversal.multi_index
    b = libmr.fog(photo, depth, s)
    assert a.backend == "cpu" and b.backend == "cpu"
    for name in ("inscatter", "transmittance", "sun_visibility"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    # not trivial: some pixels see the sun, some are in the relief's shadow
    shadowed = float((a.sun_visibility < 0.5).mean())
    assert 0.01 < shadowed < 0.99


def test_soften_seams_spreads_a_guessed_depth_step():
    # A depth step where the photo is flat is a seam in the fog; soften_seams=True (as
    # `mr fog --depth auto` does) spreads it into a ramp, keeping R = L (1 - T) (sky light only).
    h, w = 120, 120
    photo = np.full((h, w, 3), 0.18, np.float32)
    depth = np.full((h, w), 30.0, np.float32)
    depth[:, w // 2:] = 600.0
    scene = sky_only_scene(libmr)
    hard = libmr.fog(photo, depth, scene)
    soft = libmr.fog(photo, depth, scene, soften_seams=True)
    step = lambda c: np.abs(np.diff(c[h // 2, :, 1])).max()
    assert step(soft.composite) < 0.5 * step(hard.composite)
    sky = np.array(scene.lighting.sky_radiance, np.float32)
    np.testing.assert_allclose(soft.inscatter, sky * (1 - soft.transmittance), atol=2e-5)
    # away from the step nothing moved
    np.testing.assert_array_equal(soft.composite[:, :5], hard.composite[:, :5])
    # a smooth depth makes no seam: identical with and without
    smooth = np.tile(np.linspace(30, 40, w, dtype=np.float32), (h, 1))
    np.testing.assert_array_equal(libmr.fog(photo, smooth, scene, soften_seams=True).composite,
                                  libmr.fog(photo, smooth, scene).composite)


def test_working_size_fog_follows_the_full_size_outline():
    # `mr fog --depth auto`'s working size from Python: a dark near square on a bright far
    # background, fogged at half size and brought back. The result's T is the full-size truth
    # away from the outline, and on it closer to the truth than a plain bilinear upsampling.
    h, w = 200, 300
    photo = np.full((h, w, 3), (0.6, 0.65, 0.7), np.float32)
    depth = np.full((h, w), 800.0, np.float32)
    photo[61:141, 91:191] = (0.05, 0.04, 0.03)
    depth[61:141, 91:191] = 15.0
    size = libmr.working_size(w, h, 150)
    assert size == (150, 100)
    assert libmr.working_size(w, h, 300) is None
    work = libmr.working_copy(photo, *size)
    assert work.shape == (100, 150, 3)
    scene = sky_only_scene(libmr)
    camera = libmr.Camera.from_horizontal_fov(w, h, 60.0)
    small_camera = libmr.scale_camera(camera, *size)
    assert abs(small_camera.focal_px - camera.focal_px / 2) < 1e-9
    # the working fog over the working pixels' own distances (nearest)
    small_depth = np.ascontiguousarray(depth[1::2, 1::2])
    working = libmr.fog(work, small_depth, scene, camera=small_camera)
    full = libmr.upsample_fog(photo, work, working)
    truth = libmr.fog(photo, depth, scene, camera=camera)
    assert full.composite.shape == (h, w, 3) and full.transmittance.shape == (h, w, 3)
    assert abs(full.camera.focal_px - camera.focal_px) < 1e-9
    np.testing.assert_allclose(full.composite, photo * full.transmittance + full.inscatter,
                               rtol=1e-6, atol=1e-6)
    err = np.abs(full.transmittance - truth.transmittance)[..., 0]
    outline = np.zeros((h, w), bool)
    outline[58:144, 88:194] = True
    outline[64:138, 94:188] = False
    assert err[~outline].max() < 1e-5
    ys, xs = (np.arange(h) + 0.5) / 2 - 0.5, (np.arange(w) + 0.5) / 2 - 0.5
    bilinear = np.array([[np.interp(x, np.arange(150), row) for x in xs]
                         for row in working.transmittance[..., 0]])
    bilinear = np.array([np.interp(ys, np.arange(100), bilinear[:, j]) for j in range(w)]).T
    bilinear_err = np.abs(bilinear - truth.transmittance[..., 0])
    assert err[outline].mean() < 0.5 * bilinear_err[outline].mean()
