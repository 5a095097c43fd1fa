"""The Scene object: attribute access, in-place edits, JSON round trips, validation errors."""

import copy
import json
import pickle

import pytest

import libmr


def test_defaults_are_the_cpp_defaults():
    s = libmr.Scene()
    assert s.medium.sigma_t_per_m == pytest.approx([0.0261] * 3)
    assert s.medium.albedo == [1.0, 1.0, 1.0]
    assert s.medium.g == 0.0
    assert s.medium.height_fog is None
    assert s.pose.position_m == libmr.Vec3(0, 1.6, 0)
    assert s.lighting.sun is None and s.lighting.sky_radiance is None and len(s.lighting.lamps) == 0
    assert s.render.quality == libmr.Quality.normal
    assert s.camera is None
    # the default scene is what an empty document of the current version reads as
    doc = json.dumps({"format": "libmr-scene", "version": libmr.SCENE_FORMAT_VERSION})
    assert libmr.scene_from_json(doc) == s


def test_nested_edits_reach_the_scene():
    s = libmr.Scene()
    s.medium.g = 0.3
    s.pose.position_m.y = 2.5
    s.medium.noise.amplitude = 0.4
    s.lighting.sun = libmr.Sun(direction_to_sun=libmr.direction_from_azimuth_elevation(90, 30))
    s.lighting.sun.irradiance = (5.0, 4.0, 3.0)  # edits the scene's sun, not a copy
    s.lighting.lamps.append(libmr.Lamp(position_m=(1, 2, 3), intensity_per_sr=(10, 20, 30)))
    s.lighting.lamps[0].outer_angle_deg = 60.0
    s.lighting.lamps[0].inner_angle_deg = 30.0
    s.medium.height_fog = libmr.Medium.HeightFog(base_height_m=1.0, scale_height_m=15.0)
    s.medium.height_fog.scale_height_m = 25.0
    s.camera = libmr.SceneCamera(width=640, height=480, focal_px=500.0)
    doc = json.loads(s.to_json())
    assert doc["medium"]["g"] == pytest.approx(0.3)
    assert doc["camera_pose"]["position_m"][1] == 2.5
    assert doc["lighting"]["sun"]["irradiance"] == [5.0, 4.0, 3.0]
    assert doc["lighting"]["lamps"][0]["position_m"] == [1.0, 2.0, 3.0]
    assert doc["lighting"]["lamps"][0]["outer_angle_deg"] == 60.0
    assert doc["medium"]["height_fog"]["scale_height_m"] == 25.0
    assert doc["camera"]["focal_px"] == 500.0
    s.lighting.sun = None
    assert s.lighting.sun is None and json.loads(s.to_json())["lighting"]["sun"] is None


def test_json_round_trip_is_exact(tmp_path):
    s = libmr.Scene()
    s.medium.sigma_t_per_m = (0.1, 0.2, 0.30000001)
    s.medium.layer_top_m = 60.0
    s.lighting.sun = libmr.Sun(direction_to_sun=(0.3, 0.8, 0.1), irradiance=(7, 6, 5))
    s.lighting.sky_radiance = (0.5, 0.6, 0.7)
    s.render.quality = libmr.Quality.final
    s.render.seed = 7
    s.blockers.canopy = libmr.Blockers.Canopy(height_m=9.0)
    text = libmr.scene_to_json(s)
    back = libmr.scene_from_json(text, "t.json")
    assert back == s and back.to_json() == text
    libmr.save_scene(tmp_path / "s.json", s)
    assert libmr.load_scene(tmp_path / "s.json") == s
    assert pickle.loads(pickle.dumps(s)) == s
    c = copy.deepcopy(s)
    c.medium.g = 0.5
    assert s.medium.g == 0.0 and c != s


def test_validation_errors_carry_code_and_field():
    s = libmr.Scene()
    s.medium.g = 1.2  # nothing checked on assignment ...
    with pytest.raises(libmr.InvalidArgumentError) as e:
        s.validate()  # ... but on validation, naming the field
    assert e.value.code == libmr.ErrorCode.invalid_argument
    assert "medium.g" in e.value.message and "1.2" in e.value.message
    assert str(e.value) == e.value.message
    with pytest.raises(libmr.InvalidArgumentError, match="medium.g"):
        libmr.save_scene("/nonexistent/never.json", s)  # invalid: nothing written


def test_bad_documents_name_source_and_pointer(tmp_path):
    with pytest.raises(libmr.InvalidArgumentError) as e:
        libmr.scene_from_json('{"format": "libmr-scene", "version": 3, "medium": {"g": "x"}}', "a.json")
    assert e.value.message.startswith("a.json: /medium/g")
    with pytest.raises(libmr.InvalidArgumentError, match="b.json: line 1"):
        libmr.scene_from_json("{", "b.json")
    with pytest.raises(libmr.FileError) as f:
        libmr.load_scene(tmp_path / "missing.json")
    assert f.value.code == libmr.ErrorCode.io and "missing.json" in f.value.message
    assert isinstance(f.value, OSError)


def test_keyword_construction_rejects_unknown_fields():
    assert libmr.Sun(irradiance=(1, 2, 3)).irradiance == [1.0, 2.0, 3.0]
    with pytest.raises(AttributeError, match="irradiance_typo"):
        libmr.Sun(irradiance_typo=1)
    with pytest.raises(TypeError):
        libmr.Sun(irradiance="bright")
    v = libmr.Vec3(1, 2, 3)
    assert list(v) == [1.0, 2.0, 3.0] and v[2] == 3.0
    with pytest.raises(libmr.InvalidArgumentError):
        libmr.Vec3([1, 2])


def test_scene_warnings():
    s = libmr.Scene()
    s.lighting.sun = libmr.Sun()
    assert any("sun" in w for w in s.warnings())  # homogeneous fog with no top: no sunlight
    s.medium.layer_top_m = 50.0
    assert s.warnings() == []


def test_shadow_traversal_is_a_render_option():
    # Issue 17 (format version 5): Embree by default; written always ("multi-index" with a dash
    # in documents); round trips; read in version-4 documents too, refused in versions 1-3.
    assert libmr.SCENE_FORMAT_VERSION == 5
    s = libmr.Scene()
    assert s.render.shadow_traversal == libmr.ShadowTraversal.embree
    assert json.loads(s.to_json())["render"]["shadow_traversal"] == "embree"
    s.render.shadow_traversal = libmr.ShadowTraversal.multi_index
    doc = json.loads(s.to_json())
    assert doc["version"] == 5 and doc["render"]["shadow_traversal"] == "multi-index"
    back = libmr.scene_from_json(s.to_json())
    assert back == s and back.render.shadow_traversal == libmr.ShadowTraversal.multi_index
    assert libmr.RenderSettings(shadow_traversal=libmr.ShadowTraversal.multi_index).shadow_traversal == (
        libmr.ShadowTraversal.multi_index
    )
    v4 = {"format": "libmr-scene", "version": 4, "render": {"shadow_traversal": "multi-index"}}
    assert libmr.scene_from_json(json.dumps(v4)).render.shadow_traversal == libmr.ShadowTraversal.multi_index
    with pytest.raises(libmr.InvalidArgumentError, match="/render/shadow_traversal: shadow_traversal is part"):
        libmr.scene_from_json(json.dumps(dict(v4, version=3)), "old.json")
    with pytest.raises(libmr.InvalidArgumentError, match="/render/shadow_traversal"):
        libmr.scene_from_json(json.dumps({"format": "libmr-scene", "version": 5, "render": {"shadow_traversal": "kd"}}))
