// The annotations document (docs/annotations.md): strict reading with errors that point at the
// offending value, validation, writing that reads back exactly, and atomic saving.
#include "mr/annotations.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string_view>
#include <utility>

#include "atomic_file.h"
#include "blockers_json.h"
#include "json_reading.h"
#include "mr/error.h"
#include "mr/scattering.h"

namespace mr {

namespace {

namespace fs = std::filesystem;
using json::Json;
using json::Keys;
using json::member;
using json::parse_text;

// The shared strict reader, plus the annotations' own value kinds.
class Reader : public json::JsonReader {
 public:
  using JsonReader::JsonReader;

  PixelPoint point(const Json& j, const std::string& pointer) const {
    if (!j.is_array() || j.size() != 2) expected(pointer, "a point [x, y] (2 numbers)", j);
    return {number(j[0], pointer + "/0"), number(j[1], pointer + "/1")};
  }

  std::vector<PixelPoint> points(const Json& j, const std::string& pointer) const {
    if (!j.is_array()) expected(pointer, "an array of points [[x, y], ...]", j);
    std::vector<PixelPoint> out;
    out.reserve(j.size());
    for (std::size_t i = 0; i < j.size(); ++i)
      out.push_back(point(j[i], pointer + "/" + std::to_string(i)));
    return out;
  }

  std::array<PixelPoint, 2> two_points(const Json& j, const std::string& pointer) const {
    if (!j.is_array() || j.size() != 2) expected(pointer, "two points [[x0, y0], [x1, y1]]", j);
    return {point(j[0], pointer + "/0"), point(j[1], pointer + "/1")};
  }
};

Annotations from_document(const Json& doc, const Reader& r) {
  r.object(doc, "");
  r.check_keys(doc, "",
               {"format", "version", "horizon", "camera_height_m", "known_length", "planes",
                "distance_hints", "shadow_pairs", "sunlit_patch", "shadowed_patch", "lamps",
                "lamp_patches", "interior_box", "blockers"});
  const Json* format = member(doc, "format");
  if (!format)
    r.fail("/format", std::string("missing; expected \"") + kAnnotationsFormatName + "\"");
  if (!format->is_string() || format->get<std::string>() != kAnnotationsFormatName)
    r.expected("/format", std::string("\"") + kAnnotationsFormatName + "\"", *format);
  const Json* version = member(doc, "version");
  if (!version) r.fail("/version", "missing; expected 1");
  if (!version->is_number_integer() && !version->is_number_unsigned())
    r.expected("/version", "an integer", *version);
  const long long v = version->get<long long>();
  if (v < 1 || v > kAnnotationsFormatVersion)
    r.fail("/version", "version " + std::to_string(v) +
                           " is not supported (this libmr reads 1 to " +
                           std::to_string(kAnnotationsFormatVersion) + ")");

  Annotations a;
  if (const Json* h = member(doc, "horizon")) a.horizon = r.two_points(*h, "/horizon");
  if (const Json* h = member(doc, "camera_height_m"))
    a.camera_height_m = r.number(*h, "/camera_height_m");
  if (const Json* k = member(doc, "known_length")) {
    r.object(*k, "/known_length");
    r.check_keys(*k, "/known_length", {"a", "b", "length_m"});
    Annotations::KnownLength kl;
    for (const char* key : {"a", "b", "length_m"})
      if (!member(*k, key)) r.fail(std::string("/known_length/") + key, "missing");
    kl.a = r.point((*k)["a"], "/known_length/a");
    kl.b = r.point((*k)["b"], "/known_length/b");
    kl.length_m = r.number((*k)["length_m"], "/known_length/length_m");
    a.known_length = kl;
  }
  if (const Json* planes = member(doc, "planes")) {
    if (!planes->is_array()) r.expected("/planes", "an array of planes", *planes);
    for (std::size_t i = 0; i < planes->size(); ++i) {
      const std::string p = "/planes/" + std::to_string(i);
      const Json& j = (*planes)[i];
      r.object(j, p);
      r.check_keys(j, p, {"polygon", "base"});
      if (!member(j, "polygon")) r.fail(p + "/polygon", "missing");
      Annotations::Plane plane;
      plane.polygon = r.points(j["polygon"], p + "/polygon");
      if (const Json* b = member(j, "base")) plane.base = r.two_points(*b, p + "/base");
      a.planes.push_back(std::move(plane));
    }
  }
  if (const Json* hints = member(doc, "distance_hints")) {
    if (!hints->is_array()) r.expected("/distance_hints", "an array of distance hints", *hints);
    for (std::size_t i = 0; i < hints->size(); ++i) {
      const std::string p = "/distance_hints/" + std::to_string(i);
      const Json& j = (*hints)[i];
      r.object(j, p);
      r.check_keys(j, p, {"polygon", "distance_m"});
      for (const char* key : {"polygon", "distance_m"})
        if (!member(j, key)) r.fail(p + "/" + key, "missing");
      a.distance_hints.push_back(
          {r.points(j["polygon"], p + "/polygon"), r.number(j["distance_m"], p + "/distance_m")});
    }
  }
  if (const Json* pairs = member(doc, "shadow_pairs")) {
    if (!pairs->is_array()) r.expected("/shadow_pairs", "an array of shadow pairs", *pairs);
    for (std::size_t i = 0; i < pairs->size(); ++i) {
      const std::string p = "/shadow_pairs/" + std::to_string(i);
      const Json& j = (*pairs)[i];
      r.object(j, p);
      r.check_keys(j, p, {"caster_top", "caster_foot", "shadow_tip"});
      for (const char* key : {"caster_top", "caster_foot", "shadow_tip"})
        if (!member(j, key)) r.fail(p + "/" + key, "missing");
      a.shadow_pairs.push_back({r.point(j["caster_top"], p + "/caster_top"),
                                r.point(j["caster_foot"], p + "/caster_foot"),
                                r.point(j["shadow_tip"], p + "/shadow_tip")});
    }
  }
  if (const Json* s = member(doc, "sunlit_patch")) a.sunlit_patch = r.points(*s, "/sunlit_patch");
  if (const Json* s = member(doc, "shadowed_patch"))
    a.shadowed_patch = r.points(*s, "/shadowed_patch");
  // An RGB triple [r, g, b]; a single number means grey (the same in all three channels).
  auto rgb = [&](const Json& j, const std::string& p) -> std::array<double, 3> {
    if (j.is_number()) {
      const double v = r.number(j, p);
      return {v, v, v};
    }
    if (!j.is_array() || j.size() != 3) r.expected(p, "a number or [r, g, b] (3 numbers)", j);
    return {r.number(j[0], p + "/0"), r.number(j[1], p + "/1"), r.number(j[2], p + "/2")};
  };
  if (const Json* lamps = member(doc, "lamps")) {
    if (!lamps->is_array()) r.expected("/lamps", "an array of lamps", *lamps);
    for (std::size_t i = 0; i < lamps->size(); ++i) {
      const std::string p = "/lamps/" + std::to_string(i);
      const Json& j = (*lamps)[i];
      r.object(j, p);
      r.check_keys(j, p, {"pixel", "offset_m", "color"});
      if (!member(j, "pixel")) r.fail(p + "/pixel", "missing");
      Annotations::Lamp lamp;
      lamp.pixel = r.point(j["pixel"], p + "/pixel");
      if (const Json* o = member(j, "offset_m")) lamp.offset_m = r.number(*o, p + "/offset_m");
      if (const Json* c = member(j, "color")) lamp.color = rgb(*c, p + "/color");
      a.lamps.push_back(lamp);
    }
  }
  if (const Json* patches = member(doc, "lamp_patches")) {
    if (!patches->is_array()) r.expected("/lamp_patches", "an array of lamp patches", *patches);
    for (std::size_t i = 0; i < patches->size(); ++i) {
      const std::string p = "/lamp_patches/" + std::to_string(i);
      const Json& j = (*patches)[i];
      r.object(j, p);
      r.check_keys(j, p, {"polygon", "albedo"});
      if (!member(j, "polygon")) r.fail(p + "/polygon", "missing");
      Annotations::LampPatch patch;
      patch.polygon = r.points(j["polygon"], p + "/polygon");
      if (const Json* al = member(j, "albedo")) patch.albedo = rgb(*al, p + "/albedo");
      a.lamp_patches.push_back(std::move(patch));
    }
  }
  if (const Json* box = member(doc, "interior_box")) {
    r.object(*box, "/interior_box");
    r.check_keys(*box, "/interior_box", {"floor", "ceiling_height_m", "ceiling_point"});
    if (!member(*box, "floor")) r.fail("/interior_box/floor", "missing");
    Annotations::InteriorBox b;
    b.floor = r.points((*box)["floor"], "/interior_box/floor");
    if (const Json* c = member(*box, "ceiling_height_m"))
      b.ceiling_height_m = r.number(*c, "/interior_box/ceiling_height_m");
    if (const Json* c = member(*box, "ceiling_point"))
      b.ceiling_point = r.point(*c, "/interior_box/ceiling_point");
    a.interior_box = std::move(b);
  }
  if (const Json* b = member(doc, "blockers"))
    a.blockers = detail::read_blockers_json(*b, "/blockers", r);
  validate_annotations(a, "");  // re-thrown below with the source name
  return a;
}

// The JSON pointer of a field validate_scene names by its C++ path, within the blockers
// object: "blockers.skyline.samples[3].height_m" -> "/blockers/skyline/samples/3/1" (a sample
// is [azimuth_deg, height_m], a corner [x, y, z]).
std::string blockers_pointer(const std::string& cpp_path) {
  std::vector<std::string> tokens;
  std::string word;
  for (char c : cpp_path + ".") {
    if (c == '.' || c == '[' || c == ']') {
      if (!word.empty()) tokens.push_back(word);
      word.clear();
    } else {
      word += c;
    }
  }
  std::string pointer;
  for (std::size_t i = 0; i < tokens.size(); ++i) {
    std::string t = tokens[i];
    const std::string parent = i >= 2 ? tokens[i - 2] : "";
    if (parent == "samples" && t == "azimuth_deg") t = "0";
    if (parent == "samples" && t == "height_m") t = "1";
    if (parent == "corners_m") t = t == "x" ? "0" : t == "y" ? "1" : t == "z" ? "2" : t;
    pointer += "/" + json::pointer_token(t);
  }
  return pointer;
}

Json point_json(const PixelPoint& p) {
  return Json::array({p[0], p[1]});
}
Json points_json(const std::vector<PixelPoint>& ps) {
  Json j = Json::array();
  for (const auto& p : ps) j.push_back(point_json(p));
  return j;
}

}  // namespace

void validate_annotations(const Annotations& a, const std::string& source_name) {
  const std::string prefix = source_name.empty() ? "" : source_name + ": ";
  auto fail = [&](const std::string& pointer, const std::string& problem) {
    throw Error(ErrorCode::invalid_argument, prefix + pointer + ": " + problem);
  };
  auto finite = [&](double v, const std::string& pointer) {
    if (!std::isfinite(v)) fail(pointer, "expected a finite number, found " + std::to_string(v));
  };
  auto point = [&](const PixelPoint& p, const std::string& pointer) {
    finite(p[0], pointer + "/0");
    finite(p[1], pointer + "/1");
  };
  auto polygon = [&](const std::vector<PixelPoint>& ps, const std::string& pointer) {
    for (std::size_t i = 0; i < ps.size(); ++i) point(ps[i], pointer + "/" + std::to_string(i));
    if (ps.size() < 3)
      fail(pointer, "expected a polygon of at least 3 points, found " + std::to_string(ps.size()));
  };
  auto apart = [&](const PixelPoint& p, const PixelPoint& q, const std::string& pointer,
                   const char* what) {
    if (std::hypot(p[0] - q[0], p[1] - q[1]) < 1.0)
      fail(pointer, std::string("the two ") + what + " points are less than 1 pixel apart");
  };
  auto positive = [&](double v, const std::string& pointer) {
    finite(v, pointer);
    if (!(v > 0)) fail(pointer, "must be > 0, found " + std::to_string(v));
  };

  if (a.horizon) {
    point((*a.horizon)[0], "/horizon/0");
    point((*a.horizon)[1], "/horizon/1");
    apart((*a.horizon)[0], (*a.horizon)[1], "/horizon", "horizon");
  }
  if (a.camera_height_m) positive(*a.camera_height_m, "/camera_height_m");
  if (a.known_length) {
    if (a.camera_height_m) fail("/known_length", "give camera_height_m or known_length, not both");
    point(a.known_length->a, "/known_length/a");
    point(a.known_length->b, "/known_length/b");
    positive(a.known_length->length_m, "/known_length/length_m");
    apart(a.known_length->a, a.known_length->b, "/known_length", "known-length");
  }
  for (std::size_t i = 0; i < a.planes.size(); ++i) {
    const std::string p = "/planes/" + std::to_string(i);
    polygon(a.planes[i].polygon, p + "/polygon");
    if (a.planes[i].base) {
      point((*a.planes[i].base)[0], p + "/base/0");
      point((*a.planes[i].base)[1], p + "/base/1");
      apart((*a.planes[i].base)[0], (*a.planes[i].base)[1], p + "/base", "base");
    }
  }
  for (std::size_t i = 0; i < a.distance_hints.size(); ++i) {
    const std::string p = "/distance_hints/" + std::to_string(i);
    polygon(a.distance_hints[i].polygon, p + "/polygon");
    positive(a.distance_hints[i].distance_m, p + "/distance_m");
  }
  for (std::size_t i = 0; i < a.shadow_pairs.size(); ++i) {
    const std::string p = "/shadow_pairs/" + std::to_string(i);
    point(a.shadow_pairs[i].caster_top, p + "/caster_top");
    point(a.shadow_pairs[i].caster_foot, p + "/caster_foot");
    point(a.shadow_pairs[i].shadow_tip, p + "/shadow_tip");
  }
  if (!a.sunlit_patch.empty()) polygon(a.sunlit_patch, "/sunlit_patch");
  if (!a.shadowed_patch.empty()) polygon(a.shadowed_patch, "/shadowed_patch");
  for (std::size_t i = 0; i < a.lamps.size(); ++i) {
    const std::string p = "/lamps/" + std::to_string(i);
    point(a.lamps[i].pixel, p + "/pixel");
    finite(a.lamps[i].offset_m, p + "/offset_m");
    if (a.lamps[i].offset_m < 0)
      fail(p + "/offset_m", "must be >= 0, found " + std::to_string(a.lamps[i].offset_m));
    if (const auto& c = a.lamps[i].color) {
      for (int k = 0; k < 3; ++k) {
        finite((*c)[k], p + "/color/" + std::to_string(k));
        if ((*c)[k] < 0)
          fail(p + "/color/" + std::to_string(k), "must be >= 0, found " + std::to_string((*c)[k]));
      }
      if (!((*c)[0] > 0 || (*c)[1] > 0 || (*c)[2] > 0)) fail(p + "/color", "must not be black");
    }
  }
  for (std::size_t i = 0; i < a.lamp_patches.size(); ++i) {
    const std::string p = "/lamp_patches/" + std::to_string(i);
    polygon(a.lamp_patches[i].polygon, p + "/polygon");
    if (const auto& al = a.lamp_patches[i].albedo)
      for (int k = 0; k < 3; ++k) {
        finite((*al)[k], p + "/albedo/" + std::to_string(k));
        if (!((*al)[k] > 0 && (*al)[k] <= 1))
          fail(p + "/albedo/" + std::to_string(k),
               "must be in (0, 1], found " + std::to_string((*al)[k]));
      }
  }
  if (const auto& box = a.interior_box) {
    for (std::size_t i = 0; i < box->floor.size(); ++i)
      point(box->floor[i], "/interior_box/floor/" + std::to_string(i));
    if (box->floor.size() < 3)
      fail("/interior_box/floor",
           "expected at least 3 points (two walls), found " + std::to_string(box->floor.size()));
    for (std::size_t i = 1; i < box->floor.size(); ++i)
      apart(box->floor[i - 1], box->floor[i], "/interior_box/floor/" + std::to_string(i),
            "consecutive floor");
    if (box->ceiling_height_m) positive(*box->ceiling_height_m, "/interior_box/ceiling_height_m");
    if (box->ceiling_point) point(*box->ceiling_point, "/interior_box/ceiling_point");
    if (box->ceiling_height_m && box->ceiling_point && (a.camera_height_m || a.known_length))
      fail("/interior_box/ceiling_height_m",
           "with ceiling_point it fixes the camera height; give camera_height_m or known_length, "
           "or drop one of ceiling_height_m and ceiling_point");
  }
  if (a.blockers) {
    // The scene's rules, not a copy of them: the same fields are valid in both documents.
    FogScene probe;
    probe.blockers = *a.blockers;
    try {
      validate_scene(probe);
    } catch (const Error& e) {
      const std::string what = e.what();
      const auto eq = what.find(" = ");
      fail(eq == std::string::npos ? "/blockers" : blockers_pointer(what.substr(0, eq)), what);
    }
  }
  if (a.lamps.empty() != a.lamp_patches.empty())
    fail(a.lamps.empty() ? "/lamps" : "/lamp_patches",
         "missing: lamps are fitted to the shading of lamp_patches; mark both or neither");
  if (a.sunlit_patch.empty() != a.shadowed_patch.empty())
    fail(a.sunlit_patch.empty() ? "/sunlit_patch" : "/shadowed_patch",
         "missing: sunlit_patch and shadowed_patch are marked together");
}

Annotations annotations_from_json(const std::string& text, const std::string& source_name) {
  const Reader r(source_name);
  const Json doc = parse_text(text, r);
  try {
    return from_document(doc, r);
  } catch (const Error& e) {
    const std::string what = e.what();
    if (what.rfind(source_name + ": ", 0) == 0) throw;
    throw Error(e.code(), source_name + ": " + what);  // from validate_annotations(a, "")
  }
}

std::string annotations_to_json(const Annotations& a) {
  validate_annotations(a);
  Json doc = Json::object();
  doc["format"] = kAnnotationsFormatName;
  doc["version"] = kAnnotationsFormatVersion;
  if (a.horizon)
    doc["horizon"] = Json::array({point_json((*a.horizon)[0]), point_json((*a.horizon)[1])});
  if (a.camera_height_m) doc["camera_height_m"] = *a.camera_height_m;
  if (a.known_length)
    doc["known_length"] = {{"a", point_json(a.known_length->a)},
                           {"b", point_json(a.known_length->b)},
                           {"length_m", a.known_length->length_m}};
  if (!a.planes.empty()) {
    Json planes = Json::array();
    for (const auto& p : a.planes) {
      Json j = {{"polygon", points_json(p.polygon)}};
      if (p.base) j["base"] = Json::array({point_json((*p.base)[0]), point_json((*p.base)[1])});
      planes.push_back(std::move(j));
    }
    doc["planes"] = std::move(planes);
  }
  if (!a.distance_hints.empty()) {
    Json hints = Json::array();
    for (const auto& h : a.distance_hints)
      hints.push_back({{"polygon", points_json(h.polygon)}, {"distance_m", h.distance_m}});
    doc["distance_hints"] = std::move(hints);
  }
  if (!a.shadow_pairs.empty()) {
    Json pairs = Json::array();
    for (const auto& s : a.shadow_pairs)
      pairs.push_back({{"caster_top", point_json(s.caster_top)},
                       {"caster_foot", point_json(s.caster_foot)},
                       {"shadow_tip", point_json(s.shadow_tip)}});
    doc["shadow_pairs"] = std::move(pairs);
  }
  if (!a.sunlit_patch.empty()) doc["sunlit_patch"] = points_json(a.sunlit_patch);
  if (!a.shadowed_patch.empty()) doc["shadowed_patch"] = points_json(a.shadowed_patch);
  auto rgb_json = [](const std::array<double, 3>& c) { return Json::array({c[0], c[1], c[2]}); };
  if (!a.lamps.empty()) {
    Json lamps = Json::array();
    for (const auto& l : a.lamps) {
      Json j = {{"pixel", point_json(l.pixel)}};
      if (l.offset_m != 0 || std::signbit(l.offset_m)) j["offset_m"] = l.offset_m;
      if (l.color) j["color"] = rgb_json(*l.color);
      lamps.push_back(std::move(j));
    }
    doc["lamps"] = std::move(lamps);
  }
  if (!a.lamp_patches.empty()) {
    Json patches = Json::array();
    for (const auto& p : a.lamp_patches) {
      Json j = {{"polygon", points_json(p.polygon)}};
      if (p.albedo) j["albedo"] = rgb_json(*p.albedo);
      patches.push_back(std::move(j));
    }
    doc["lamp_patches"] = std::move(patches);
  }
  if (const auto& box = a.interior_box) {
    Json j = {{"floor", points_json(box->floor)}};
    if (box->ceiling_height_m) j["ceiling_height_m"] = *box->ceiling_height_m;
    if (box->ceiling_point) j["ceiling_point"] = point_json(*box->ceiling_point);
    doc["interior_box"] = std::move(j);
  }
  if (a.blockers) doc["blockers"] = detail::blockers_json(*a.blockers);
  return doc.dump(2) + "\n";
}

Annotations load_annotations(const fs::path& path) {
  const std::string name = path.string();
  const std::string text = json::read_document_file(path, "an annotations file");
  return annotations_from_json(text, name);
}

void save_annotations(const fs::path& path, const Annotations& annotations) {
  const std::string text = annotations_to_json(annotations);
  detail::write_text_atomically(path, text);
}

}  // namespace mr
