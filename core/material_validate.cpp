// mr::validate_material: the ranges documented on mr::Material (mr/material.h). The message
// shape follows validate_scene: "<what>.<field> = <value>: <rule>".
#include <charconv>
#include <cmath>
#include <string>

#include "mr/error.h"
#include "mr/material_model.h"

namespace mr {

namespace {

std::string show(float v) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

// Written so that NaN fails the comparison.
void closed(const std::string& path, float v, float lo, float hi) {
  if (!(std::isfinite(v) && v >= lo && v <= hi))
    throw Error(ErrorCode::invalid_argument,
                path + " = " + show(v) + ": must be in [" + show(lo) + ", " + show(hi) + "]");
}

}  // namespace

void validate_material(const Material& material, const std::string& what) {
  static const char* const kChannel[3] = {"[0]", "[1]", "[2]"};
  for (int c = 0; c < 3; ++c)
    closed(what + ".diffuse_albedo" + kChannel[c], material.diffuse_albedo[c], 0.0f, 1.0f);
  closed(what + ".specular_albedo", material.specular_albedo, 0.0f, 1.0f);
  closed(what + ".roughness", material.roughness, 0.02f, 1.0f);
}

}  // namespace mr
