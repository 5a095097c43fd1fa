// The JSON scene document (docs/scene.md): reading with errors that point at the offending
// value, writing that reads back exactly, and atomic saving.
#include "mr/scene_json.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string_view>
#include <utility>
#include <vector>

#include "atomic_file.h"
#include "blockers_json.h"
#include "json_reading.h"
#include "mr/error.h"
#include "mr/fog.h"
#include "mr/object_io.h"
#include "mr/scattering.h"

namespace mr {

namespace {

namespace fs = std::filesystem;
using json::Json;
using json::Keys;

constexpr double kInf = std::numeric_limits<double>::infinity();

// ------------------------------------------------------------------------------------------
// Reading
// ------------------------------------------------------------------------------------------

using json::describe;
using json::member;
using json::parse_text;
using json::pointer_token;
using Reader = json::JsonReader;

Medium read_medium(const Json& j, const std::string& p, const Reader& r) {
  r.object(j, p);
  r.check_keys(j, p,
               {"sigma_t_per_m", "visibility_m", "albedo", "g", "height_fog", "layer_bottom_m",
                "layer_top_m", "noise"});
  Medium m;
  const Json* sigma = member(j, "sigma_t_per_m");
  const Json* visibility = member(j, "visibility_m");
  if (sigma && visibility)
    r.fail(p,
           "give either sigma_t_per_m or visibility_m, not both (visibility_m sets sigma_t_per_m)");
  if (sigma) m.sigma_t_per_m = r.rgb(*sigma, p + "/sigma_t_per_m");
  if (visibility) {
    // Koschmieder: sigma_t = 3.912 / V. Per channel when given as [r, g, b].
    const std::string vp = p + "/visibility_m";
    std::array<double, 3> v{};
    if (visibility->is_number()) {
      v.fill(r.number(*visibility, vp));
    } else if (visibility->is_array() && visibility->size() == 3) {
      for (std::size_t i = 0; i < 3; ++i)
        v[i] = r.number((*visibility)[i], vp + "/" + std::to_string(i));
    } else {
      r.expected(vp, "a number or an array of 3 numbers (metres)", *visibility);
    }
    for (std::size_t i = 0; i < 3; ++i) {
      const std::string ep = visibility->is_array() ? vp + "/" + std::to_string(i) : vp;
      if (!(v[i] > 0))
        r.fail(ep, "visibility must be > 0 metres, found " +
                       (visibility->is_array() ? (*visibility)[i] : *visibility).dump());
      m.sigma_t_per_m[i] = static_cast<float>(extinction_from_visibility(v[i]));
    }
  }
  if (const Json* a = member(j, "albedo")) m.albedo = r.rgb(*a, p + "/albedo");
  if (const Json* g = member(j, "g")) m.g = r.number(*g, p + "/g");
  if (const Json* h = member(j, "height_fog"); h && !h->is_null()) {
    const std::string hp = p + "/height_fog";
    if (!h->is_object()) r.expected(hp, "null or an object", *h);
    r.check_keys(*h, hp, {"base_height_m", "scale_height_m"});
    Medium::HeightFog fog;
    if (const Json* b = member(*h, "base_height_m"))
      fog.base_height_m = r.number(*b, hp + "/base_height_m");
    if (const Json* s = member(*h, "scale_height_m"))
      fog.scale_height_m = r.number(*s, hp + "/scale_height_m");
    m.height_fog = fog;
  }
  // null = unbounded on that side (JSON has no infinity).
  if (const Json* b = member(j, "layer_bottom_m"))
    m.layer_bottom_m = b->is_null() ? -kInf : r.number(*b, p + "/layer_bottom_m");
  if (const Json* t = member(j, "layer_top_m"))
    m.layer_top_m = t->is_null() ? kInf : r.number(*t, p + "/layer_top_m");
  if (const Json* n = member(j, "noise")) {
    const std::string np = p + "/noise";
    r.object(*n, np);
    r.check_keys(*n, np, {"amplitude", "scale_m", "octaves", "seed"});
    if (const Json* v = member(*n, "amplitude"))
      m.noise.amplitude = r.number(*v, np + "/amplitude");
    if (const Json* v = member(*n, "scale_m")) m.noise.scale_m = r.number(*v, np + "/scale_m");
    if (const Json* v = member(*n, "octaves"))
      m.noise.octaves = static_cast<int>(r.integer(
          *v, np + "/octaves", std::numeric_limits<int>::min(), std::numeric_limits<int>::max()));
    if (const Json* v = member(*n, "seed"))
      m.noise.seed = static_cast<std::uint32_t>(
          r.integer(*v, np + "/seed", 0, std::numeric_limits<std::uint32_t>::max()));
  }
  return m;
}

Sun read_sun(const Json& j, const std::string& p, const Reader& r) {
  if (!j.is_object()) r.expected(p, "null or an object", j);
  r.check_keys(
      j, p,
      {"direction_to_sun", "azimuth_deg", "elevation_deg", "irradiance", "angular_radius_deg"});
  Sun sun;
  const Json* dir = member(j, "direction_to_sun");
  const Json* az = member(j, "azimuth_deg");
  const Json* el = member(j, "elevation_deg");
  if (dir && (az || el))
    r.fail(p, "give either direction_to_sun or azimuth_deg + elevation_deg, not both");
  if (dir) sun.direction_to_sun = r.vec3(*dir, p + "/direction_to_sun");
  if (az || el) {
    if (!az) r.fail(p, "elevation_deg needs azimuth_deg beside it");
    if (!el) r.fail(p, "azimuth_deg needs elevation_deg beside it");
    const double azimuth = r.number(*az, p + "/azimuth_deg");
    const double elevation = r.number(*el, p + "/elevation_deg");
    if (!(elevation >= -90 && elevation <= 90))
      r.fail(p + "/elevation_deg", el->dump() + ": must be in [-90, 90]");
    sun.direction_to_sun = direction_from_azimuth_elevation(azimuth, elevation);
  }
  // No irradiance, or "auto": relative to each photo's exposure (Sun::irradiance_auto).
  const Json* irradiance = member(j, "irradiance");
  sun.irradiance_auto = !irradiance || (irradiance->is_string() && *irradiance == "auto");
  if (irradiance && !sun.irradiance_auto) sun.irradiance = r.rgb(*irradiance, p + "/irradiance");
  if (const Json* v = member(j, "angular_radius_deg"))
    sun.angular_radius_deg = r.number(*v, p + "/angular_radius_deg");
  return sun;
}

Lamp read_lamp(const Json& j, const std::string& p, const Reader& r) {
  r.object(j, p);
  r.check_keys(j, p,
               {"position_m", "intensity_per_sr", "color", "spot_direction", "inner_angle_deg",
                "outer_angle_deg"});
  Lamp lamp;
  if (const Json* v = member(j, "position_m")) lamp.position_m = r.vec3(*v, p + "/position_m");
  // No intensity, or "auto": relative to each photo's exposure (Lamp::intensity_auto), in the
  // colour of "color" (default: the default intensity's warm white).
  const Json* intensity = member(j, "intensity_per_sr");
  lamp.intensity_auto = !intensity || (intensity->is_string() && *intensity == "auto");
  if (intensity && !lamp.intensity_auto)
    lamp.intensity_per_sr = r.rgb(*intensity, p + "/intensity_per_sr");
  if (const Json* v = member(j, "color")) {
    if (!lamp.intensity_auto)
      r.fail(p + "/color",
             "only with intensity_per_sr \"auto\" (a given intensity has its colour)");
    lamp.intensity_per_sr = r.rgb(*v, p + "/color");
  }
  if (const Json* v = member(j, "spot_direction"))
    lamp.spot_direction = r.vec3(*v, p + "/spot_direction");
  if (const Json* v = member(j, "inner_angle_deg"))
    lamp.inner_angle_deg = r.number(*v, p + "/inner_angle_deg");
  if (const Json* v = member(j, "outer_angle_deg"))
    lamp.outer_angle_deg = r.number(*v, p + "/outer_angle_deg");
  return lamp;
}

Lighting read_lighting(const Json& j, const std::string& p, const Reader& r) {
  r.object(j, p);
  r.check_keys(j, p, {"sun", "sky_radiance", "lamps", "sky_by_direction"});
  Lighting l;
  if (const Json* s = member(j, "sun"); s && !s->is_null()) l.sun = read_sun(*s, p + "/sun", r);
  if (const Json* s = member(j, "sky_radiance")) {
    // null or "auto": estimated from the photo.
    if (s->is_string()) {
      if (s->get_ref<const std::string&>() != "auto")
        r.expected(p + "/sky_radiance", "\"auto\", null, a number or an array of 3 numbers", *s);
    } else if (!s->is_null()) {
      l.sky_radiance = r.rgb(*s, p + "/sky_radiance");
    }
  }
  if (const Json* lamps = member(j, "lamps")) {
    const std::string lp = p + "/lamps";
    if (!lamps->is_array()) r.expected(lp, "an array of lamp objects", *lamps);
    for (std::size_t i = 0; i < lamps->size(); ++i)
      l.lamps.push_back(read_lamp((*lamps)[i], lp + "/" + std::to_string(i), r));
  }
  // Sky light by direction (mr/sky_light.h): true, false, or "auto" / null / absent (the front
  // end decides).
  if (const Json* v = member(j, "sky_by_direction"); v && !v->is_null()) {
    if (v->is_boolean())
      l.sky_by_direction = v->get<bool>();
    else if (!(v->is_string() && v->get_ref<const std::string&>() == "auto"))
      r.expected(p + "/sky_by_direction", "true, false or \"auto\"", *v);
  }
  return l;
}

CameraPose read_pose(const Json& j, const std::string& p, const Reader& r) {
  r.object(j, p);
  r.check_keys(j, p, {"position_m", "yaw_deg", "pitch_deg", "roll_deg"});
  CameraPose pose;
  if (const Json* v = member(j, "position_m")) pose.position_m = r.vec3(*v, p + "/position_m");
  if (const Json* v = member(j, "yaw_deg")) pose.yaw_deg = r.number(*v, p + "/yaw_deg");
  if (const Json* v = member(j, "pitch_deg")) pose.pitch_deg = r.number(*v, p + "/pitch_deg");
  if (const Json* v = member(j, "roll_deg")) pose.roll_deg = r.number(*v, p + "/roll_deg");
  return pose;
}

RenderSettings read_render(const Json& j, const std::string& p, long long version,
                           const Reader& r) {
  r.object(j, p);
  r.check_keys(j, p,
               {"quality", "backend", "march_steps", "grid_step", "gradient_acceleration",
                "volumetric_shadows", "light_path_attenuation", "max_distance_m", "seed", "threads",
                "shadow_traversal"});
  constexpr long long kIntMin = std::numeric_limits<int>::min();
  constexpr long long kIntMax = std::numeric_limits<int>::max();
  RenderSettings s;
  if (const Json* v = member(j, "quality"))
    s.quality = static_cast<Quality>(r.choice(*v, p + "/quality", {"draft", "normal", "final"}));
  if (const Json* v = member(j, "backend"))
    s.backend = static_cast<Backend>(r.choice(*v, p + "/backend", {"auto", "cpu", "vulkan"}));
  if (const Json* v = member(j, "march_steps"))
    s.march_steps = static_cast<int>(r.integer(*v, p + "/march_steps", kIntMin, kIntMax));
  if (const Json* v = member(j, "grid_step"))
    s.grid_step = static_cast<int>(r.integer(*v, p + "/grid_step", kIntMin, kIntMax));
  if (const Json* v = member(j, "gradient_acceleration"))
    s.gradient_acceleration = r.boolean(*v, p + "/gradient_acceleration");
  if (const Json* v = member(j, "volumetric_shadows"))
    s.volumetric_shadows = r.boolean(*v, p + "/volumetric_shadows");
  if (const Json* v = member(j, "light_path_attenuation"))
    s.light_path_attenuation = r.boolean(*v, p + "/light_path_attenuation");
  if (const Json* v = member(j, "max_distance_m"))
    s.max_distance_m = r.number(*v, p + "/max_distance_m");
  if (const Json* v = member(j, "seed"))
    s.seed = static_cast<std::uint32_t>(
        r.integer(*v, p + "/seed", 0, std::numeric_limits<std::uint32_t>::max()));
  if (const Json* v = member(j, "threads"))
    s.threads = static_cast<int>(r.integer(*v, p + "/threads", kIntMin, kIntMax));
  // Issue 17, version 5; absent: Embree. Version-4 documents may hold it too: the builds that
  // added it before the version went up wrote it there when it was not "embree".
  if (const Json* v = member(j, "shadow_traversal")) {
    if (version < 4)
      r.fail(p + "/shadow_traversal",
             "shadow_traversal is part of the format from version 5 on (read in version 4 "
             "too); this document is version " +
                 std::to_string(version));
    s.shadow_traversal = static_cast<ShadowTraversal>(
        r.choice(*v, p + "/shadow_traversal", {"embree", "multi-index"}));
  }
  return s;
}

// The shortest decimal of a double that reads back as it ("-5", "1234.5", "nan").
std::string shortest(double v) {
  char buf[64];
  return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
}

// The camera's rules, shared by reading (pointer = where the value is) and writing.
void check_camera(const SceneCamera& c, const std::string& p, const Reader& r) {
  if (c.width < 1) r.fail(p + "/width", "must be >= 1, found " + std::to_string(c.width));
  if (c.height < 1) r.fail(p + "/height", "must be >= 1, found " + std::to_string(c.height));
  if (!(c.focal_px > 0) || !std::isfinite(c.focal_px))
    r.fail(p + "/focal_px", "must be > 0 pixels, found " + shortest(c.focal_px));
  if (c.principal_point_px) {
    const auto& pp = *c.principal_point_px;
    const int size[2] = {c.width, c.height};
    for (int a = 0; a < 2; ++a)
      if (!(pp[a] >= 0 && pp[a] <= size[a]))
        r.fail(p + "/principal_point_px/" + std::to_string(a),
               "must be inside the " + std::to_string(c.width) + "x" + std::to_string(c.height) +
                   " image (0.." + std::to_string(size[a]) + "), found " + shortest(pp[a]));
  }
}

SceneCamera read_camera(const Json& j, const std::string& p, const Reader& r) {
  r.object(j, p);
  r.check_keys(j, p, {"width", "height", "focal_px", "horizontal_fov_deg", "principal_point_px"});
  SceneCamera c;
  for (const char* key : {"width", "height"}) {
    const Json* v = member(j, key);
    if (!v)
      r.fail(p + "/" + key,
             "missing; the camera's focal length refers to an image size (width and height)");
    (key[0] == 'w' ? c.width : c.height) = static_cast<int>(r.integer(
        *v, p + "/" + key, std::numeric_limits<int>::min(), std::numeric_limits<int>::max()));
  }
  const Json* focal = member(j, "focal_px");
  const Json* fov = member(j, "horizontal_fov_deg");
  if (focal && fov) r.fail(p, "give either focal_px or horizontal_fov_deg, not both");
  if (!focal && !fov) r.fail(p + "/focal_px", "missing; give focal_px or horizontal_fov_deg");
  if (focal) c.focal_px = r.number(*focal, p + "/focal_px");
  if (fov) {
    const double deg = r.number(*fov, p + "/horizontal_fov_deg");
    if (!(deg > 0 && deg < 180))
      r.fail(p + "/horizontal_fov_deg", "must be in (0, 180) degrees, found " + fov->dump());
    if (c.width >= 1)
      c.focal_px = 0.5 * c.width / std::tan(0.5 * deg * 3.14159265358979323846 / 180);
  }
  if (const Json* v = member(j, "principal_point_px")) {
    const std::string pp = p + "/principal_point_px";
    if (!v->is_array() || v->size() != 2) r.expected(pp, "an array of 2 numbers [cx, cy]", *v);
    c.principal_point_px =
        std::array<double, 2>{r.number((*v)[0], pp + "/0"), r.number((*v)[1], pp + "/1")};
  }
  check_camera(c, p, r);
  return c;
}

Blockers read_blockers(const Json& j, const std::string& p, const Reader& r) {
  r.object(j, p);
  r.check_keys(j, p, {"completion", "skyline", "polygons", "canopy"});
  Blockers b;
  if (const Json* c = member(j, "completion")) {
    const std::string cp = p + "/completion";
    r.object(*c, cp);
    r.check_keys(*c, cp, {"enabled", "max_height_m", "max_extent_m", "prism_max_width_m"});
    Blockers::Completion& k = b.completion;
    if (const Json* v = member(*c, "enabled")) k.enabled = r.boolean(*v, cp + "/enabled");
    if (const Json* v = member(*c, "max_height_m")) k.max_height_m = r.number(*v, cp + "/max_height_m");
    if (const Json* v = member(*c, "max_extent_m")) k.max_extent_m = r.number(*v, cp + "/max_extent_m");
    if (const Json* v = member(*c, "prism_max_width_m"))
      k.prism_max_width_m = r.number(*v, cp + "/prism_max_width_m");
  }
  if (const Json* sk = member(j, "skyline"); sk && !sk->is_null()) {
    const std::string sp = p + "/skyline";
    r.object(*sk, sp);
    r.check_keys(*sk, sp, {"distance_m", "samples"});
    Blockers::Skyline line;
    if (const Json* v = member(*sk, "distance_m")) line.distance_m = r.number(*v, sp + "/distance_m");
    const Json* samples = member(*sk, "samples");
    if (!samples) r.fail(sp + "/samples", "missing; give [[azimuth_deg, height_m], ...]");
    if (!samples->is_array()) r.expected(sp + "/samples", "an array of [azimuth_deg, height_m]", *samples);
    for (std::size_t i = 0; i < samples->size(); ++i) {
      const std::string ip = sp + "/samples/" + std::to_string(i);
      const Json& e = (*samples)[i];
      if (!e.is_array() || e.size() != 2) r.expected(ip, "an array of 2 numbers [azimuth_deg, height_m]", e);
      line.samples.push_back({r.number(e[0], ip + "/0"), r.number(e[1], ip + "/1")});
    }
    b.skyline = line;
  }
  if (const Json* polys = member(j, "polygons")) {
    const std::string pp = p + "/polygons";
    if (!polys->is_array()) r.expected(pp, "an array of polygon objects", *polys);
    for (std::size_t i = 0; i < polys->size(); ++i) {
      const std::string ip = pp + "/" + std::to_string(i);
      const Json& e = (*polys)[i];
      r.object(e, ip);
      r.check_keys(e, ip, {"corners_m"});
      const Json* corners = member(e, "corners_m");
      if (!corners) r.fail(ip + "/corners_m", "missing; give [[x, y, z], ...] (3 or more)");
      if (!corners->is_array()) r.expected(ip + "/corners_m", "an array of [x, y, z]", *corners);
      Blockers::Polygon poly;
      for (std::size_t k = 0; k < corners->size(); ++k)
        poly.corners_m.push_back(r.vec3((*corners)[k], ip + "/corners_m/" + std::to_string(k)));
      b.polygons.push_back(std::move(poly));
    }
  }
  if (const Json* c = member(j, "canopy"); c && !c->is_null()) {
    const std::string cp = p + "/canopy";
    r.object(*c, cp);
    r.check_keys(*c, cp, {"height_m", "gap_fraction", "radius_m", "cell_m", "seed"});
    Blockers::Canopy k;
    if (const Json* v = member(*c, "height_m")) k.height_m = r.number(*v, cp + "/height_m");
    if (const Json* v = member(*c, "gap_fraction")) k.gap_fraction = r.number(*v, cp + "/gap_fraction");
    if (const Json* v = member(*c, "radius_m")) k.radius_m = r.number(*v, cp + "/radius_m");
    if (const Json* v = member(*c, "cell_m")) k.cell_m = r.number(*v, cp + "/cell_m");
    if (const Json* v = member(*c, "seed"))
      k.seed = static_cast<std::uint32_t>(
          r.integer(*v, cp + "/seed", 0, std::numeric_limits<std::uint32_t>::max()));
    b.canopy = k;
  }
  return b;
}

// The "objects" list (version 4): 3D objects inserted into the photo (mr/objects.h).
Material read_material(const Json& j, const std::string& p, const Reader& r) {
  r.object(j, p);
  r.check_keys(j, p, {"diffuse_albedo", "specular_albedo", "roughness"});
  Material m;
  if (const Json* v = member(j, "diffuse_albedo")) m.diffuse_albedo = r.rgb(*v, p + "/diffuse_albedo");
  if (const Json* v = member(j, "specular_albedo"))
    m.specular_albedo = r.single(*v, p + "/specular_albedo");
  if (const Json* v = member(j, "roughness")) m.roughness = r.single(*v, p + "/roughness");
  return m;
}

ObjectPlacement read_placement(const Json& j, const std::string& p, const Reader& r) {
  r.object(j, p);
  r.check_keys(j, p, {"position_m", "up", "yaw_deg", "scale"});
  ObjectPlacement o;
  if (const Json* v = member(j, "position_m")) o.position_m = r.vec3(*v, p + "/position_m");
  if (const Json* v = member(j, "up")) o.up = r.vec3(*v, p + "/up");
  if (const Json* v = member(j, "yaw_deg")) o.yaw_deg = r.number(*v, p + "/yaw_deg");
  if (const Json* v = member(j, "scale")) o.scale = r.number(*v, p + "/scale");
  return o;
}

std::vector<SceneObject> read_objects(const Json& j, const std::string& p, const Reader& r) {
  if (!j.is_array()) r.expected(p, "an array of objects", j);
  std::vector<SceneObject> objects;
  for (std::size_t i = 0; i < j.size(); ++i) {
    const std::string ip = p + "/" + std::to_string(i);
    const Json& o = j[i];
    r.object(o, ip);
    r.check_keys(o, ip, {"mesh", "placement", "material"});
    SceneObject obj;
    const Json* mesh = member(o, "mesh");
    if (!mesh)
      r.fail(ip + "/mesh", "missing; give a model file (relative to this document) or "
                           "\"primitive:sphere\", \"primitive:box\", ...");
    if (!mesh->is_string()) r.expected(ip + "/mesh", "a string", *mesh);
    obj.mesh = mesh->get<std::string>();
    if (const Json* v = member(o, "placement")) obj.placement = read_placement(*v, ip + "/placement", r);
    if (const Json* v = member(o, "material"); v && !v->is_null())
      obj.material = read_material(*v, ip + "/material", r);
    objects.push_back(std::move(obj));
  }
  return objects;
}

FogScene read_document(const Json& doc, const Reader& r) {
  if (!doc.is_object())
    r.fail("", "expected a JSON object at the top level, found " + describe(doc));
  // Format and version first: a JSON file that is not a scene (or a newer one) should say so,
  // not complain about its first unknown key.
  const Json* format = member(doc, "format");
  if (!format)
    r.fail("/format", std::string("missing; a scene document starts with \"format\": \"") +
                          kSceneFormatName + "\"");
  if (!format->is_string() || format->get_ref<const std::string&>() != kSceneFormatName)
    r.expected("/format", std::string("\"") + kSceneFormatName + "\"", *format);
  const std::string supported = kSceneFormatVersion == 1
                                    ? "version 1"
                                    : "versions 1 to " + std::to_string(kSceneFormatVersion);
  const Json* version = member(doc, "version");
  if (!version) r.fail("/version", "missing; this libmr reads " + supported);
  const long long v = r.integer(*version, "/version", std::numeric_limits<int>::min(),
                                std::numeric_limits<int>::max());
  if (v > kSceneFormatVersion)
    r.fail("/version", "version " + std::to_string(v) +
                           " is newer than this libmr supports (it reads " + supported +
                           "); upgrade libmr to read this scene");
  if (v < 1)
    r.fail("/version",
           "version " + std::to_string(v) + " does not exist; this libmr reads " + supported);

  r.check_keys(doc, "",
               {"format", "version", "camera_pose", "medium", "lighting", "render", "camera",
                "blockers", "objects"});
  FogScene s;
  // Completing structures cut by the frame came with version 3; older documents keep rendering
  // as they did.
  if (v < 3) s.blockers.completion.enabled = false;
  if (const Json* j = member(doc, "blockers")) {
    if (v < 3)
      r.fail("/blockers", "blockers are part of the format from version 3 on; this document is "
                          "version " + std::to_string(v));
    s.blockers = read_blockers(*j, "/blockers", r);
  }
  if (const Json* j = member(doc, "camera_pose")) s.pose = read_pose(*j, "/camera_pose", r);
  if (const Json* j = member(doc, "medium")) s.medium = read_medium(*j, "/medium", r);
  if (const Json* j = member(doc, "lighting")) s.lighting = read_lighting(*j, "/lighting", r);
  if (const Json* j = member(doc, "render")) s.render = read_render(*j, "/render", v, r);
  if (const Json* j = member(doc, "camera"); j && !j->is_null()) {
    if (v < 2)
      r.fail("/camera",
             "the camera is part of the format from version 2 on; this document is "
             "version " +
                 std::to_string(v));
    s.camera = read_camera(*j, "/camera", r);
  }
  if (const Json* j = member(doc, "objects")) {
    if (v < 4)
      r.fail("/objects", "objects are part of the format from version 4 on; this document is "
                         "version " + std::to_string(v));
    s.objects = read_objects(*j, "/objects", r);
  }
  return s;
}

// The JSON pointer of the value validate_scene complained about, from its C++ path
// ("lighting.lamps[2].position_m.y" -> "/lighting/lamps/2/position_m/1"), cut to the part that
// exists in the document (a colour given as one number, a default left out).
std::string json_pointer_for(const std::string& cpp_path, const Json& doc) {
  std::vector<std::string> tokens;
  std::string word;
  auto flush = [&] {
    if (!word.empty()) tokens.push_back(word);
    word.clear();
  };
  for (char c : cpp_path) {
    if (c == '.' || c == '[' || c == ']')
      flush();
    else
      word += c;
  }
  flush();
  for (std::string& t : tokens) {
    if (t == "x") t = "0";
    if (t == "y") t = "1";
    if (t == "z") t = "2";
  }
  if (!tokens.empty() && tokens[0] == "pose") tokens[0] = "camera_pose";
  // sigma_t set through visibility_m: point at what the user wrote.
  if (tokens.size() >= 2 && tokens[0] == "medium" && tokens[1] == "sigma_t_per_m") {
    const Json* m = member(doc, "medium");
    if (m && m->is_object() && member(*m, "visibility_m")) tokens[1] = "visibility_m";
  }
  std::string pointer;
  const Json* node = &doc;
  for (const std::string& t : tokens) {
    const Json* next = nullptr;
    if (node->is_object()) {
      next = member(*node, t.c_str());
    } else if (node->is_array() && !t.empty() &&
               std::all_of(t.begin(), t.end(), [](char c) { return c >= '0' && c <= '9'; })) {
      const std::size_t i = std::stoul(t);
      if (i < node->size()) next = &(*node)[i];
    }
    if (!next) break;
    pointer += "/" + pointer_token(t);
    node = next;
  }
  return pointer;
}

// ------------------------------------------------------------------------------------------
// Writing
// ------------------------------------------------------------------------------------------

// The shortest decimal that reads back as the same float ("0.0261", not the double expansion
// "0.026100000366568565"), as the double JSON readers will parse it to. Reading goes text ->
// double -> float, and that double rounding could in principle land on the neighbouring float
// (no case was found in a scan of every 7th float): then write the float's exact double value,
// which always reads back exactly.
double float_for_json(float f) {
  char buf[64];
  const auto end = std::to_chars(buf, buf + sizeof buf, f).ptr;
  double d = 0;
  std::from_chars(buf, end, d);
  return static_cast<float>(d) == f ? d : static_cast<double>(f);
}

Json rgb_json(const Rgb& c) {
  return Json::array({float_for_json(c[0]), float_for_json(c[1]), float_for_json(c[2])});
}
Json vec3_json(const Vec3& v) {
  return Json::array({v.x, v.y, v.z});
}
Json bound_json(double v) {
  return std::isinf(v) ? Json(nullptr) : Json(v);
}

// The "blockers" object (scenes, and annotations documents since they carry the same schema).
Json blockers_document(const Blockers& b) {
  Json blockers = Json::object();
  blockers["completion"] = Json{{"enabled", b.completion.enabled},
                                {"max_height_m", b.completion.max_height_m},
                                {"max_extent_m", b.completion.max_extent_m},
                                {"prism_max_width_m", b.completion.prism_max_width_m}};
  if (b.skyline) {
    Json samples = Json::array();
    for (const Blockers::SkylineSample& k : b.skyline->samples)
      samples.push_back(Json::array({k.azimuth_deg, k.height_m}));
    blockers["skyline"] =
        Json{{"distance_m", b.skyline->distance_m}, {"samples", std::move(samples)}};
  }
  if (!b.polygons.empty()) {
    Json polys = Json::array();
    for (const Blockers::Polygon& poly : b.polygons) {
      Json corners = Json::array();
      for (const Vec3& c : poly.corners_m) corners.push_back(vec3_json(c));
      polys.push_back(Json{{"corners_m", std::move(corners)}});
    }
    blockers["polygons"] = std::move(polys);
  }
  if (b.canopy)
    blockers["canopy"] = Json{{"height_m", b.canopy->height_m},
                              {"gap_fraction", b.canopy->gap_fraction},
                              {"radius_m", b.canopy->radius_m},
                              {"cell_m", b.canopy->cell_m},
                              {"seed", b.canopy->seed}};
  return blockers;
}

Json to_document(const FogScene& s) {
  Json doc = Json::object();
  doc["format"] = kSceneFormatName;
  doc["version"] = kSceneFormatVersion;

  Json& pose = doc["camera_pose"] = Json::object();
  pose["position_m"] = vec3_json(s.pose.position_m);
  pose["yaw_deg"] = s.pose.yaw_deg;
  pose["pitch_deg"] = s.pose.pitch_deg;
  pose["roll_deg"] = s.pose.roll_deg;

  const Medium& m = s.medium;
  Json& medium = doc["medium"] = Json::object();
  medium["sigma_t_per_m"] = rgb_json(m.sigma_t_per_m);
  medium["albedo"] = rgb_json(m.albedo);
  medium["g"] = m.g;
  medium["height_fog"] = m.height_fog ? Json{{"base_height_m", m.height_fog->base_height_m},
                                             {"scale_height_m", m.height_fog->scale_height_m}}
                                      : Json(nullptr);
  medium["layer_bottom_m"] = bound_json(m.layer_bottom_m);
  medium["layer_top_m"] = bound_json(m.layer_top_m);
  medium["noise"] = Json{{"amplitude", m.noise.amplitude},
                         {"scale_m", m.noise.scale_m},
                         {"octaves", m.noise.octaves},
                         {"seed", m.noise.seed}};

  const Lighting& l = s.lighting;
  Json& lighting = doc["lighting"] = Json::object();
  lighting["sun"] = l.sun ? Json{{"direction_to_sun", vec3_json(l.sun->direction_to_sun)},
                                 {"irradiance", l.sun->irradiance_auto
                                                    ? Json("auto")
                                                    : rgb_json(l.sun->irradiance)},
                                 {"angular_radius_deg", l.sun->angular_radius_deg}}
                          : Json(nullptr);
  lighting["sky_radiance"] = l.sky_radiance ? rgb_json(*l.sky_radiance) : Json("auto");
  Json lamps = Json::array();
  for (const Lamp& lamp : l.lamps) {
    Json j{
        {"position_m", vec3_json(lamp.position_m)},
        {"intensity_per_sr", lamp.intensity_auto ? Json("auto") : rgb_json(lamp.intensity_per_sr)}};
    if (lamp.intensity_auto) j["color"] = rgb_json(lamp.intensity_per_sr);
    j["spot_direction"] = vec3_json(lamp.spot_direction);
    j["inner_angle_deg"] = lamp.inner_angle_deg;
    j["outer_angle_deg"] = lamp.outer_angle_deg;
    lamps.push_back(std::move(j));
  }
  lighting["lamps"] = std::move(lamps);
  lighting["sky_by_direction"] = l.sky_by_direction ? Json(*l.sky_by_direction) : Json("auto");

  const RenderSettings& r = s.render;
  static constexpr const char* kQuality[] = {"draft", "normal", "final"};
  doc["render"] =
      Json{{"quality", kQuality[static_cast<int>(r.quality)]},
           {"backend", r.backend == Backend::cpu      ? "cpu"
                       : r.backend == Backend::vulkan ? "vulkan"
                                                      : "auto"},
           {"march_steps", r.march_steps},
           {"grid_step", r.grid_step},
           {"gradient_acceleration", r.gradient_acceleration},
           {"volumetric_shadows", r.volumetric_shadows},
           {"light_path_attenuation", r.light_path_attenuation},
           {"max_distance_m", r.max_distance_m},
           {"seed", r.seed},
           {"threads", r.threads},
           // Issue 17, version 5: written always, like every key (a version-4
           // reader refuses the whole document for its version anyway).
           {"shadow_traversal",
            r.shadow_traversal == ShadowTraversal::multi_index ? "multi-index" : "embree"}};
  if (s.camera) {  // optional: documents without it read as before
    Json camera = Json{
        {"width", s.camera->width}, {"height", s.camera->height}, {"focal_px", s.camera->focal_px}};
    if (s.camera->principal_point_px)
      camera["principal_point_px"] =
          Json::array({(*s.camera->principal_point_px)[0], (*s.camera->principal_point_px)[1]});
    doc["camera"] = std::move(camera);
  }
  doc["blockers"] = blockers_document(s.blockers);
  Json objects = Json::array();
  for (const SceneObject& o : s.objects) {
    Json j{{"mesh", o.mesh},
           {"placement", Json{{"position_m", vec3_json(o.placement.position_m)},
                              {"up", vec3_json(o.placement.up)},
                              {"yaw_deg", o.placement.yaw_deg},
                              {"scale", o.placement.scale}}}};
    j["material"] = o.material ? Json{{"diffuse_albedo", rgb_json(o.material->diffuse_albedo)},
                                      {"specular_albedo", float_for_json(o.material->specular_albedo)},
                                      {"roughness", float_for_json(o.material->roughness)}}
                               : Json(nullptr);
    objects.push_back(std::move(j));
  }
  doc["objects"] = std::move(objects);
  return doc;
}

// Pretty printing like dump(2), except that arrays of plain values stay on one line
// ("position_m": [0.0, 1.6, 0.0]), which keeps vectors and colours readable.
void write_pretty(const Json& j, int indent, std::string& out) {
  const std::string pad(static_cast<std::size_t>(indent) + 2, ' ');
  const std::string close_pad(static_cast<std::size_t>(indent), ' ');
  if (j.is_object() && !j.empty()) {
    out += "{\n";
    bool first = true;
    for (const auto& [key, value] : j.items()) {
      if (!first) out += ",\n";
      first = false;
      out += pad + Json(key).dump() + ": ";
      write_pretty(value, indent + 2, out);
    }
    out += "\n" + close_pad + "}";
  } else if (j.is_array() && !j.empty()) {
    const bool flat =
        std::none_of(j.begin(), j.end(), [](const Json& e) { return e.is_structured(); });
    out += flat ? "[" : "[\n";
    for (std::size_t i = 0; i < j.size(); ++i) {
      if (i > 0) out += flat ? ", " : ",\n";
      if (!flat) out += pad;
      write_pretty(j[i], indent + 2, out);
    }
    out += flat ? "]" : "\n" + close_pad + "]";
  } else {
    out += j.dump();
  }
}

}  // namespace

FogScene scene_from_json(const std::string& text, const std::string& source_name) {
  const Reader r(source_name.empty() ? "<scene>" : source_name);
  const Json doc = parse_text(text, r);
  FogScene scene = read_document(doc, r);
  try {
    validate_scene(scene);
  } catch (const Error& e) {
    // e.what() is "<C++ path> = <value>: <rule>" (scene_validate.cpp); keep it whole after the
    // JSON pointer so the message names the field both ways.
    const std::string what = e.what();
    const auto eq = what.find(" = ");
    r.fail(eq == std::string::npos ? "" : json_pointer_for(what.substr(0, eq), doc), what);
  }
  return scene;
}

std::string scene_to_json(const FogScene& scene) {
  validate_scene(scene);  // NaN and friends have no JSON spelling: refuse rather than corrupt
  if (scene.camera) check_camera(*scene.camera, "/camera", Reader("scene_to_json"));
  std::string out;
  write_pretty(to_document(scene), 0, out);
  out += "\n";
  return out;
}

Camera camera_for_image(const SceneCamera& c, int width, int height) {
  check_camera(c, "/camera", Reader("scene camera"));
  if (width < 1 || height < 1)
    throw Error(ErrorCode::invalid_argument, "scene camera: image size " + std::to_string(width) +
                                                 "x" + std::to_string(height) + " is not positive");
  const std::string sizes = "the scene's camera was recorded for a " + std::to_string(c.width) +
                            "x" + std::to_string(c.height) + " image, this one is " +
                            std::to_string(width) + "x" + std::to_string(height);
  Camera out;
  out.width = width;
  out.height = height;
  if (width == c.width && height == c.height) {
    out.focal_px = c.focal_px;
    out.cx = c.principal_point_px ? (*c.principal_point_px)[0] : 0.5 * width;
    out.cy = c.principal_point_px ? (*c.principal_point_px)[1] : 0.5 * height;
    return out;
  }
  // A resized copy keeps the aspect ratio up to rounding of its size to whole pixels.
  const double aspect = double(width) / height, recorded = double(c.width) / c.height;
  if (std::abs(aspect / recorded - 1) > 0.01)
    throw Error(ErrorCode::invalid_argument,
                sizes +
                    ": another aspect ratio (rotated or cropped?), so its focal length "
                    "does not carry over");
  const double sx = double(width) / c.width, sy = double(height) / c.height;
  out.focal_px = c.focal_px * sx;
  out.cx = c.principal_point_px ? (*c.principal_point_px)[0] * sx : 0.5 * width;
  out.cy = c.principal_point_px ? (*c.principal_point_px)[1] * sy : 0.5 * height;
  return out;
}

SceneCamera scene_camera(const Camera& camera) {
  SceneCamera c;
  c.width = camera.width;
  c.height = camera.height;
  c.focal_px = camera.focal_px;
  if (camera.cx != 0.5 * camera.width || camera.cy != 0.5 * camera.height)
    c.principal_point_px = std::array<double, 2>{camera.cx, camera.cy};
  return c;
}

FogScene load_scene(const fs::path& path) {
  const std::string name = path.string();
  const std::string text = json::read_document_file(path, "a scene file");
  FogScene scene = scene_from_json(text, name);
  // Model files are relative to the document: only here is its folder known.
  for (std::size_t i = 0; i < scene.objects.size(); ++i) {
    const fs::path model = object_mesh_path(scene.objects[i], path.parent_path());
    std::error_code ec;
    if (!model.empty() && !fs::is_regular_file(model, ec))
      throw Error(ErrorCode::io, name + ": /objects/" + std::to_string(i) + "/mesh: model file " +
                                     model.string() + (fs::exists(model, ec) ? " is not a regular file"
                                                                              : " not found"));
  }
  return scene;
}

void save_scene(const fs::path& path, const FogScene& scene) {
  const std::string text = scene_to_json(scene);  // throws before anything touches the disk
  detail::write_text_atomically(path, text);
}

namespace detail {

Blockers read_blockers_json(const json::Json& j, const std::string& pointer,
                            const json::JsonReader& reader) {
  return read_blockers(j, pointer, reader);
}

json::Json blockers_json(const Blockers& blockers) {
  return blockers_document(blockers);
}

}  // namespace detail

}  // namespace mr
