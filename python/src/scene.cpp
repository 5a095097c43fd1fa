// The fog scene (mr::FogScene and its parts) with attribute access, its JSON document, and the
// camera. Nested structures are edited in place (scene.medium.g = 0.3, scene.lighting.sun.
// irradiance = (5, 5, 5)); optional parts read as None when unset and are set by assigning an
// object (or None to remove them).
#include <optional>
#include <sstream>

#include "common.h"
#include "mr/camera.h"
#include "mr/scattering.h"
#include "mr/scene.h"
#include "mr/scene_json.h"

namespace mrpy {
namespace {

// Every structure takes its fields as keyword arguments: libmr.Sun(irradiance=(5, 5, 5)).
// An unknown keyword is an AttributeError naming it.
template <class T>
auto kwargs_init() {
  return py::init([](py::kwargs kwargs) {
    T value{};
    py::object self = py::cast(&value, py::return_value_policy::reference);
    for (auto item : kwargs) {
      const std::string name = py::str(item.first);
      if (!py::hasattr(self, name.c_str()) || name.rfind("_", 0) == 0)
        throw py::attribute_error(std::string(py::str(py::type::handle_of(self).attr("__name__"))) +
                                  " has no field '" + name + "'");
      self.attr(name.c_str()) = item.second;
    }
    return value;
  });
}

// An optional structure member: None when unset, else the object itself (edits go to the
// scene); assigning an object sets it (a copy), None clears it.
template <class C, class T>
void def_optional(py::class_<C>& cls, const char* name, std::optional<T> C::*member,
                  const char* doc) {
  cls.def_property(
      name,
      [member](C& self) -> T* {
        std::optional<T>& o = self.*member;
        return o ? &*o : nullptr;
      },
      [member](C& self, std::optional<T> value) { self.*member = std::move(value); },
      py::return_value_policy::reference_internal, doc);
}

template <class T>
std::string repr_via(const T& value, const char* name) {
  py::object self = py::cast(value);
  std::ostringstream s;
  s << "libmr." << name << "(";
  bool first = true;
  for (py::handle field : self.attr("_fields")) {
    s << (first ? "" : ", ") << std::string(py::str(field)) << "="
      << std::string(py::repr(self.attr(field)));
    first = false;
  }
  s << ")";
  return s.str();
}

// A __repr__ and a _fields tuple (for repr and for tests that walk the structure).
template <class T>
void def_fields(py::class_<T>& cls, const char* name, std::vector<const char*> fields) {
  py::tuple names(fields.size());
  for (std::size_t i = 0; i < fields.size(); ++i) names[i] = py::str(fields[i]);
  cls.attr("_fields") = names;
  cls.def("__repr__", [name](const T& v) { return repr_via(v, name); });
  cls.def("__copy__", [](const T& v) { return T(v); });
  cls.def(
      "__deepcopy__", [](const T& v, py::dict) { return T(v); }, py::arg("memo"));
}

std::string scene_json_or_empty(const mr::FogScene& s) {
  try {
    return mr::scene_to_json(s);
  } catch (const mr::Error&) {
    return {};
  }
}

}  // namespace

void bind_scene(py::module_& m) {
  py::class_<mr::Vec3> vec3(m, "Vec3",
                            "A 3D vector (metres for positions; unit-less for directions). World "
                            "frame: +Y up, the ground at y = 0; the camera at yaw 0 looks along "
                            "+Z. Anywhere a Vec3 is expected a 3-tuple or list works too.");
  vec3.def(py::init([](double x, double y, double z) {
             return mr::Vec3{x, y, z};
           }),
           py::arg("x") = 0.0, py::arg("y") = 0.0, py::arg("z") = 0.0)
      .def(py::init([](py::sequence s) {
             if (py::len(s) != 3)
               invalid("Vec3: expected 3 numbers, got " + std::to_string(py::len(s)));
             return mr::Vec3{s[0].cast<double>(), s[1].cast<double>(), s[2].cast<double>()};
           }),
           py::arg("xyz"))
      .def_readwrite("x", &mr::Vec3::x)
      .def_readwrite("y", &mr::Vec3::y)
      .def_readwrite("z", &mr::Vec3::z)
      .def("__iter__", [](const mr::Vec3& v) { return py::iter(py::make_tuple(v.x, v.y, v.z)); })
      .def("__len__", [](const mr::Vec3&) { return 3; })
      .def("__getitem__",
           [](const mr::Vec3& v, int i) {
             if (i < -3 || i > 2) throw py::index_error("Vec3 index out of range");
             return i % 3 == 0 ? v.x : (i + 3) % 3 == 1 ? v.y : v.z;
           })
      .def("__eq__", [](const mr::Vec3& a,
                        const mr::Vec3& b) { return a.x == b.x && a.y == b.y && a.z == b.z; })
      .def("__repr__", [](const mr::Vec3& v) {
        return "libmr.Vec3(" + std::string(py::repr(py::float_(v.x))) + ", " +
               std::string(py::repr(py::float_(v.y))) + ", " +
               std::string(py::repr(py::float_(v.z))) + ")";
      });
  py::implicitly_convertible<py::tuple, mr::Vec3>();
  py::implicitly_convertible<py::list, mr::Vec3>();
  m.def("direction_from_azimuth_elevation", &mr::direction_from_azimuth_elevation,
        py::arg("azimuth_deg"), py::arg("elevation_deg"),
        "World direction from azimuth (degrees, 0 = +Z, 90 = +X) and elevation above the "
        "horizon (degrees): (cos(el) sin(az), sin(el), cos(el) cos(az)).");

  // --- camera ---
  py::class_<mr::Camera> camera(m, "Camera",
                                "A pinhole camera in pixel units (x right, y down; pixel (x, y) "
                                "covers [x, x+1) x [y, y+1)).");
  camera
      .def(py::init([](int width, int height, double focal_px, std::optional<double> cx,
                       std::optional<double> cy) {
             return mr::Camera{width, height, focal_px, cx ? *cx : width / 2.0,
                               cy ? *cy : height / 2.0};
           }),
           py::arg("width"), py::arg("height"), py::arg("focal_px"), py::arg("cx") = py::none(),
           py::arg("cy") = py::none(),
           "focal_px: focal length in pixels; (cx, cy): principal point in pixels (default: "
           "the image centre).")
      .def_readwrite("width", &mr::Camera::width)
      .def_readwrite("height", &mr::Camera::height)
      .def_readwrite("focal_px", &mr::Camera::focal_px, "focal length, pixels")
      .def_readwrite("cx", &mr::Camera::cx, "principal point x, pixels")
      .def_readwrite("cy", &mr::Camera::cy, "principal point y, pixels")
      .def_static("from_horizontal_fov", &mr::Camera::from_horizontal_fov, py::arg("width"),
                  py::arg("height"), py::arg("fov_deg"),
                  "Horizontal field of view in degrees (0, 180), principal point at the centre.")
      .def_static("from_focal_px", &mr::Camera::from_focal_px, py::arg("width"), py::arg("height"),
                  py::arg("focal_px"))
      .def_static(
          "from_metadata",
          [](int width, int height, std::optional<mr::Metadata> md, double fallback_fov_deg) {
            return mr::Camera::from_metadata(width, height, md ? *md : mr::Metadata(),
                                             fallback_fov_deg);
          },
          py::arg("width"), py::arg("height"), py::arg("metadata") = py::none(),
          py::arg("fallback_fov_deg") = 60.0,
          "From EXIF FocalLengthIn35mmFormat (36 mm across the long side), else "
          "fallback_fov_deg across.")
      .def("horizontal_fov_deg", &mr::Camera::horizontal_fov_deg)
      .def("z_to_distance", &mr::Camera::z_to_distance, py::arg("x"), py::arg("y"),
           "|ray(x, y)| / z: planar z-depth of the pixel centre -> distance along its ray.")
      .def("ray_direction", &mr::Camera::ray_direction, py::arg("x"), py::arg("y"),
           "Unit ray through the centre of pixel (x, y), camera frame (+z forward, y down).")
      .def("__eq__",
           [](const mr::Camera& a, const mr::Camera& b) {
             return a.width == b.width && a.height == b.height && a.focal_px == b.focal_px &&
                    a.cx == b.cx && a.cy == b.cy;
           })
      .def("__repr__", [](const mr::Camera& c) {
        std::ostringstream s;
        s.precision(17);
        s << "libmr.Camera(width=" << c.width << ", height=" << c.height
          << ", focal_px=" << c.focal_px << ", cx=" << c.cx << ", cy=" << c.cy << ")";
        return s.str();
      });

  py::class_<mr::SceneCamera> scene_camera(
      m, "SceneCamera",
      "The camera a scene was made for: image size (pixels), focal length (pixels) and "
      "principal point (pixels; None = the centre).");
  scene_camera.def(kwargs_init<mr::SceneCamera>())
      .def_readwrite("width", &mr::SceneCamera::width)
      .def_readwrite("height", &mr::SceneCamera::height)
      .def_readwrite("focal_px", &mr::SceneCamera::focal_px)
      .def_readwrite("principal_point_px", &mr::SceneCamera::principal_point_px);
  def_fields(scene_camera, "SceneCamera", {"width", "height", "focal_px", "principal_point_px"});
  m.def("camera_for_image", &mr::camera_for_image, py::arg("camera"), py::arg("width"),
        py::arg("height"),
        "The Camera of a width x height photo from a scene's recorded camera (scaled for a "
        "resized photo of the same aspect ratio; InvalidArgumentError otherwise).");
  m.def("scene_camera", &mr::scene_camera, py::arg("camera"),
        "The SceneCamera recording a Camera.");

  // --- pose ---
  py::class_<mr::CameraPose> pose(m, "CameraPose",
                                  "Where the camera stands (metres) and how it is turned "
                                  "(degrees): yaw turns right, pitch tilts up, roll clockwise.");
  pose.def(kwargs_init<mr::CameraPose>())
      .def_readwrite("position_m", &mr::CameraPose::position_m, "metres, world frame")
      .def_readwrite("yaw_deg", &mr::CameraPose::yaw_deg)
      .def_readwrite("pitch_deg", &mr::CameraPose::pitch_deg)
      .def_readwrite("roll_deg", &mr::CameraPose::roll_deg)
      .def(
          "axes",
          [](const mr::CameraPose& p) {
            const auto a = p.axes();
            return py::make_tuple(a[0], a[1], a[2]);
          },
          "The camera's unit axes in the world: (forward, right, up).")
      .def("ray_direction", &mr::CameraPose::ray_direction, py::arg("camera"), py::arg("x"),
           py::arg("y"), "Unit world direction through the centre of pixel (x, y).");
  def_fields(pose, "CameraPose", {"position_m", "yaw_deg", "pitch_deg", "roll_deg"});

  // --- medium ---
  py::class_<mr::Medium> medium(
      m, "Medium",
      "The fog: extinction sigma_t(x) = sigma_t_per_m * rho(x) (1/m, RGB), scattering "
      "sigma_s = albedo * sigma_t, Henyey-Greenstein g in (-1, 1). Visibility V (m) is "
      "sigma_t = 3.912 / V (extinction_from_visibility).");
  py::class_<mr::Medium::HeightFog> height_fog(
      medium, "HeightFog", "rho(y) = exp(-(y - base_height_m) / scale_height_m), metres.");
  height_fog.def(kwargs_init<mr::Medium::HeightFog>())
      .def_readwrite("base_height_m", &mr::Medium::HeightFog::base_height_m)
      .def_readwrite("scale_height_m", &mr::Medium::HeightFog::scale_height_m, "> 0");
  def_fields(height_fog, "Medium.HeightFog", {"base_height_m", "scale_height_m"});
  py::class_<mr::Medium::Noise> noise(
      medium, "Noise",
      "Wisps: rho *= max(0, 1 + amplitude * fbm(x / scale_m)); amplitude in [0, 1] (0 = off), "
      "scale_m metres, octaves 1..8, seed.");
  noise.def(kwargs_init<mr::Medium::Noise>())
      .def_readwrite("amplitude", &mr::Medium::Noise::amplitude)
      .def_readwrite("scale_m", &mr::Medium::Noise::scale_m)
      .def_readwrite("octaves", &mr::Medium::Noise::octaves)
      .def_readwrite("seed", &mr::Medium::Noise::seed);
  def_fields(noise, "Medium.Noise", {"amplitude", "scale_m", "octaves", "seed"});
  medium.def(kwargs_init<mr::Medium>())
      .def_readwrite("sigma_t_per_m", &mr::Medium::sigma_t_per_m,
                     "extinction at density 1, 1/m, (R, G, B); assign a whole 3-tuple")
      .def_readwrite("albedo", &mr::Medium::albedo, "(R, G, B) in [0, 1]")
      .def_readwrite("g", &mr::Medium::g, "Henyey-Greenstein asymmetry in (-1, 1)")
      .def_readwrite("layer_bottom_m", &mr::Medium::layer_bottom_m,
                     "world height (m) below which the density is 0 (-inf: none)")
      .def_readwrite("layer_top_m", &mr::Medium::layer_top_m,
                     "world height (m) above which the density is 0 (inf: none)")
      .def_readwrite("noise", &mr::Medium::noise);
  def_optional(medium, "height_fog", &mr::Medium::height_fog,
               "Medium.HeightFog or None (homogeneous)");
  def_fields(
      medium, "Medium",
      {"sigma_t_per_m", "albedo", "g", "height_fog", "layer_bottom_m", "layer_top_m", "noise"});

  // --- lights ---
  py::class_<mr::Sun> sun(m, "Sun",
                          "Sunlight: parallel rays from direction_to_sun (a Vec3, normalised by "
                          "the core) with irradiance (scene-linear RGB per unit area, "
                          "perpendicular to the rays) above the fog; angular_radius_deg > 0 "
                          "softens shaft edges; irradiance_auto: set per photo from its exposure.");
  sun.def(kwargs_init<mr::Sun>())
      .def_readwrite("direction_to_sun", &mr::Sun::direction_to_sun)
      .def_readwrite("irradiance", &mr::Sun::irradiance)
      .def_readwrite("angular_radius_deg", &mr::Sun::angular_radius_deg)
      .def_readwrite("irradiance_auto", &mr::Sun::irradiance_auto);
  def_fields(sun, "Sun",
             {"direction_to_sun", "irradiance", "angular_radius_deg", "irradiance_auto"});

  py::class_<mr::Lamp> lamp(m, "Lamp",
                            "A point lamp at position_m (metres) with radiant intensity "
                            "intensity_per_sr (RGB per steradian); a spot when outer_angle_deg "
                            "< 180 (cone around spot_direction, full within inner_angle_deg).");
  lamp.def(kwargs_init<mr::Lamp>())
      .def_readwrite("position_m", &mr::Lamp::position_m)
      .def_readwrite("intensity_per_sr", &mr::Lamp::intensity_per_sr)
      .def_readwrite("spot_direction", &mr::Lamp::spot_direction)
      .def_readwrite("inner_angle_deg", &mr::Lamp::inner_angle_deg)
      .def_readwrite("outer_angle_deg", &mr::Lamp::outer_angle_deg)
      .def_readwrite("intensity_auto", &mr::Lamp::intensity_auto);
  def_fields(lamp, "Lamp",
             {"position_m", "intensity_per_sr", "spot_direction", "inner_angle_deg",
              "outer_angle_deg", "intensity_auto"});
  py::bind_vector<std::vector<mr::Lamp>>(m, "LampList", "The scene's lamps (a mutable list).")
      .def("__repr__", [](const std::vector<mr::Lamp>& lamps) {
        std::string s = "libmr.LampList([";
        for (std::size_t i = 0; i < lamps.size(); ++i)
          s += (i ? ", " : "") + repr_via(lamps[i], "Lamp");
        return s + "])";
      });
  py::implicitly_convertible<py::list, std::vector<mr::Lamp>>();
  py::implicitly_convertible<py::tuple, std::vector<mr::Lamp>>();

  py::class_<mr::Lighting> lighting(m, "Lighting");
  lighting.def(kwargs_init<mr::Lighting>())
      .def_readwrite("sky_radiance", &mr::Lighting::sky_radiance,
                     "isotropic sky radiance L_sky (scene-linear RGB); None: estimated from the "
                     "photo (dark channel prior)")
      .def_readwrite("lamps", &mr::Lighting::lamps);
  def_optional(lighting, "sun", &mr::Lighting::sun, "Sun or None");
  def_fields(lighting, "Lighting", {"sun", "sky_radiance", "lamps"});

  // --- rendering ---
  py::enum_<mr::Quality>(m, "Quality", "Render presets (README, 'Quality presets').")
      .value("draft", mr::Quality::draft)
      .value("normal", mr::Quality::normal)
      .value("final", mr::Quality::final);
  py::enum_<mr::Backend>(m, "Backend",
                         "automatic: Vulkan on a GPU when usable, else the CPU; cpu; vulkan.")
      .value("automatic", mr::Backend::automatic)
      .value("cpu", mr::Backend::cpu)
      .value("vulkan", mr::Backend::vulkan);
  py::enum_<mr::ShadowTraversal>(
      m, "ShadowTraversal",
      "How the CPU backend answers shadow rays (issue 17; same answers): embree (Embree's BVH, "
      "the default and faster, README 'Shadow-ray traversal') or multi_index (seed 004's "
      "multi-index kd-tree). Scene documents spell them \"embree\" and \"multi-index\".")
      .value("embree", mr::ShadowTraversal::embree)
      .value("multi_index", mr::ShadowTraversal::multi_index);
  py::class_<mr::RenderSettings> render(m, "RenderSettings",
                                        "How the core renders; 0 fields come from the preset.");
  render.def(kwargs_init<mr::RenderSettings>())
      .def_readwrite("quality", &mr::RenderSettings::quality)
      .def_readwrite("backend", &mr::RenderSettings::backend)
      .def_readwrite("march_steps", &mr::RenderSettings::march_steps)
      .def_readwrite("grid_step", &mr::RenderSettings::grid_step)
      .def_readwrite("gradient_acceleration", &mr::RenderSettings::gradient_acceleration)
      .def_readwrite("volumetric_shadows", &mr::RenderSettings::volumetric_shadows)
      .def_readwrite("light_path_attenuation", &mr::RenderSettings::light_path_attenuation)
      .def_readwrite("max_distance_m", &mr::RenderSettings::max_distance_m,
                     "how far sky rays march, metres; 0 = automatic")
      .def_readwrite("seed", &mr::RenderSettings::seed)
      .def_readwrite("threads", &mr::RenderSettings::threads, "0: all cores")
      .def_readwrite("shadow_traversal", &mr::RenderSettings::shadow_traversal,
                     "ShadowTraversal; the CPU backend only");
  def_fields(render, "RenderSettings",
             {"quality", "backend", "march_steps", "grid_step", "gradient_acceleration",
              "volumetric_shadows", "light_path_attenuation", "max_distance_m", "seed", "threads",
              "shadow_traversal"});

  // --- blockers (docs/scene.md "blockers") ---
  py::class_<mr::Blockers> blockers(m, "Blockers",
                                    "Shadow casters the photo does not show (docs/scene.md).");
  py::class_<mr::Blockers::Completion> completion(blockers, "Completion");
  completion.def(kwargs_init<mr::Blockers::Completion>())
      .def_readwrite("enabled", &mr::Blockers::Completion::enabled)
      .def_readwrite("max_height_m", &mr::Blockers::Completion::max_height_m)
      .def_readwrite("max_extent_m", &mr::Blockers::Completion::max_extent_m)
      .def_readwrite("prism_max_width_m", &mr::Blockers::Completion::prism_max_width_m);
  def_fields(completion, "Blockers.Completion",
             {"enabled", "max_height_m", "max_extent_m", "prism_max_width_m"});
  py::class_<mr::Blockers::SkylineSample> sample(blockers, "SkylineSample");
  sample.def(kwargs_init<mr::Blockers::SkylineSample>())
      .def_readwrite("azimuth_deg", &mr::Blockers::SkylineSample::azimuth_deg)
      .def_readwrite("height_m", &mr::Blockers::SkylineSample::height_m);
  def_fields(sample, "Blockers.SkylineSample", {"azimuth_deg", "height_m"});
  py::class_<mr::Blockers::Skyline> skyline(blockers, "Skyline");
  skyline.def(kwargs_init<mr::Blockers::Skyline>())
      .def_readwrite("distance_m", &mr::Blockers::Skyline::distance_m)
      .def_readwrite("samples", &mr::Blockers::Skyline::samples, "a list; assign a whole list");
  def_fields(skyline, "Blockers.Skyline", {"distance_m", "samples"});
  py::class_<mr::Blockers::Polygon> polygon(blockers, "Polygon");
  polygon.def(kwargs_init<mr::Blockers::Polygon>())
      .def_readwrite("corners_m", &mr::Blockers::Polygon::corners_m, "list of Vec3, metres");
  def_fields(polygon, "Blockers.Polygon", {"corners_m"});
  py::class_<mr::Blockers::Canopy> canopy(blockers, "Canopy");
  canopy.def(kwargs_init<mr::Blockers::Canopy>())
      .def_readwrite("height_m", &mr::Blockers::Canopy::height_m)
      .def_readwrite("gap_fraction", &mr::Blockers::Canopy::gap_fraction)
      .def_readwrite("radius_m", &mr::Blockers::Canopy::radius_m)
      .def_readwrite("cell_m", &mr::Blockers::Canopy::cell_m)
      .def_readwrite("seed", &mr::Blockers::Canopy::seed);
  def_fields(canopy, "Blockers.Canopy", {"height_m", "gap_fraction", "radius_m", "cell_m", "seed"});
  blockers.def(kwargs_init<mr::Blockers>())
      .def_readwrite("completion", &mr::Blockers::completion)
      .def_readwrite("polygons", &mr::Blockers::polygons, "a list; assign a whole list");
  def_optional(blockers, "skyline", &mr::Blockers::skyline, "Blockers.Skyline or None");
  def_optional(blockers, "canopy", &mr::Blockers::canopy, "Blockers.Canopy or None");
  def_fields(blockers, "Blockers", {"completion", "skyline", "polygons", "canopy"});

  // --- the scene ---
  py::class_<mr::FogScene> scene(
      m, "Scene",
      "A whole fog scene (mr::FogScene; the JSON scene document, docs/scene.md): pose, medium, "
      "lighting, render settings, the camera it was made for, blockers. Attributes are edited "
      "in place: scene.medium.sigma_t_per_m = (0.02, 0.02, 0.02). Nothing is checked on "
      "assignment: validate() (and every render) raises InvalidArgumentError naming the first "
      "bad field ('medium.g = 1.2: must be in (-1, 1)'). Pickles as its JSON document.");
  scene.def(kwargs_init<mr::FogScene>())
      .def_readwrite("pose", &mr::FogScene::pose)
      .def_readwrite("medium", &mr::FogScene::medium)
      .def_readwrite("lighting", &mr::FogScene::lighting)
      .def_readwrite("render", &mr::FogScene::render)
      .def_readwrite("blockers", &mr::FogScene::blockers)
      .def("validate", &mr::validate_scene,
           "Raises InvalidArgumentError naming the first bad field by its path.")
      .def("warnings", &mr::scene_warnings,
           "Things in a valid scene that are almost certainly not meant (one sentence each).")
      .def("to_json", &mr::scene_to_json,
           "The scene document (newest version, every field, exact round trip).")
      .def_static(
          "from_json",
          [](const std::string& text, const std::string& source_name) {
            return mr::scene_from_json(text, source_name);
          },
          py::arg("text"), py::arg("source_name") = "<scene>")
      .def("copy", [](const mr::FogScene& s) { return mr::FogScene(s); })
      .def(
          "__eq__",
          [](const mr::FogScene& a, const mr::FogScene& b) {
            const std::string ja = scene_json_or_empty(a), jb = scene_json_or_empty(b);
            return !ja.empty() && ja == jb;
          },
          "Equal documents (scene_to_json); invalid scenes equal nothing.")
      .def(py::pickle(
          [](const mr::FogScene& s) { return mr::scene_to_json(s); },
          [](const std::string& json) { return mr::scene_from_json(json, "<pickle>"); }));
  def_optional(scene, "camera", &mr::FogScene::camera, "SceneCamera or None");
  def_fields(scene, "Scene", {"pose", "medium", "lighting", "render", "camera", "blockers"});

  m.def(
      "scene_from_json",
      [](const std::string& text, const std::string& source_name) {
        return mr::scene_from_json(text, source_name);
      },
      py::arg("text"), py::arg("source_name") = "<scene>",
      "Parses a scene document (docs/scene.md); missing keys take the defaults. Raises "
      "InvalidArgumentError naming the source and JSON pointer ('s.json: /medium/g: ...').");
  m.def("scene_to_json", &mr::scene_to_json, py::arg("scene"));
  m.def(
      "load_scene", [](py::handle path) { return mr::load_scene(path_arg(path, "path")); },
      py::arg("path"), "Reads a scene file. FileError / InvalidArgumentError naming the file.");
  m.def(
      "save_scene",
      [](py::handle path, const mr::FogScene& s) { mr::save_scene(path_arg(path, "path"), s); },
      py::arg("path"), py::arg("scene"),
      "Writes the scene document atomically. InvalidArgumentError for an invalid scene "
      "(nothing written), FileError.");
  m.def("validate_scene", &mr::validate_scene, py::arg("scene"));
  m.def("scene_warnings", &mr::scene_warnings, py::arg("scene"));
  m.attr("SCENE_FORMAT_VERSION") = mr::kSceneFormatVersion;
}

}  // namespace mrpy
