// The assignment objective of seed 002 section 4.3.2: style distance of the synthesized target
// to the sample plus the smoothness of the material "gradient" over the region adjacency graph.
#include "photo/material/material_objective.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <string>

#include "mr/error.h"

namespace mr::photo {

namespace {

// The seed's parameter vector k of a candidate: diffuse albedo RGB, specular albedo, roughness
// (all in [0, 1], so no per-component scaling).
std::array<double, 5> parameters(const Material& m) {
  return {m.diffuse_albedo[0], m.diffuse_albedo[1], m.diffuse_albedo[2], m.specular_albedo,
          m.roughness};
}

}  // namespace

MaterialObjective::MaterialObjective(StyleStatistics sample,
                                     std::vector<std::vector<StyleStatistics>> region_stats,
                                     std::vector<Material> candidates,
                                     std::vector<std::pair<int, int>> adjacency,
                                     double smoothness_weight, StyleWeights weights)
    : sample_(std::move(sample)),
      region_stats_(std::move(region_stats)),
      candidates_(std::move(candidates)),
      adjacency_(std::move(adjacency)),
      smoothness_weight_(smoothness_weight),
      weights_(weights) {
  if (region_stats_.empty())
    throw Error(ErrorCode::invalid_argument, "MaterialObjective: no regions");
  if (candidates_.empty())
    throw Error(ErrorCode::invalid_argument, "MaterialObjective: no candidate materials");
  for (std::size_t c = 0; c < candidates_.size(); ++c)
    validate_material(candidates_[c], "candidate " + std::to_string(c));
  for (std::size_t r = 0; r < region_stats_.size(); ++r)
    if (region_stats_[r].size() != candidates_.size())
      throw Error(ErrorCode::invalid_argument,
                  "MaterialObjective: region " + std::to_string(r) + " has statistics for " +
                      std::to_string(region_stats_[r].size()) + " candidates, expected " +
                      std::to_string(candidates_.size()));
  const int n = regions();
  for (const auto& [i, j] : adjacency_)
    if (i < 0 || j >= n || i >= j)
      throw Error(ErrorCode::invalid_argument,
                  "MaterialObjective: adjacency pair (" + std::to_string(i) + ", " +
                      std::to_string(j) + ") is not i < j within 0.." + std::to_string(n - 1));
  if (!(smoothness_weight_ >= 0) || !std::isfinite(smoothness_weight_))
    throw Error(ErrorCode::invalid_argument,
                "MaterialObjective: smoothness_weight must be finite and >= 0, got " +
                    std::to_string(smoothness_weight_));
  if (sample_.count <= 0)
    throw Error(ErrorCode::invalid_argument, "MaterialObjective: the sample has no pixels");
}

int MaterialObjective::regions() const {
  return int(region_stats_.size());
}
int MaterialObjective::candidates() const {
  return int(candidates_.size());
}

double MaterialObjective::operator()(std::span<const int> assignment) const {
  const int n = regions(), m = candidates();
  if (int(assignment.size()) != n)
    throw Error(ErrorCode::invalid_argument, "MaterialObjective: assignment has " +
                                                 std::to_string(assignment.size()) +
                                                 " entries, expected " + std::to_string(n));
  for (int r = 0; r < n; ++r)
    if (assignment[r] < 0 || assignment[r] >= m)
      throw Error(ErrorCode::invalid_argument,
                  "MaterialObjective: region " + std::to_string(r) + " assigned candidate " +
                      std::to_string(assignment[r]) + ", expected 0.." + std::to_string(m - 1));
  StyleStatistics synthesized;
  for (int r = 0; r < n; ++r) synthesized += region_stats_[r][assignment[r]];
  const double style = style_distance(sample_, synthesized, weights_);
  if (smoothness_weight_ == 0 || adjacency_.empty()) return style;

  // grad k_i = sum over neighbours j of (k(x_i) - k(x_j)); the term is sum_i |grad k_i|^2.
  std::vector<std::array<double, 5>> gradient(n, std::array<double, 5>{});
  for (const auto& [i, j] : adjacency_) {
    const std::array<double, 5> ki = parameters(candidates_[assignment[i]]);
    const std::array<double, 5> kj = parameters(candidates_[assignment[j]]);
    for (int c = 0; c < 5; ++c) {
      gradient[i][c] += ki[c] - kj[c];
      gradient[j][c] += kj[c] - ki[c];
    }
  }
  double smoothness = 0;
  for (const auto& g : gradient)
    for (const double v : g) smoothness += v * v;
  return style + smoothness_weight_ * smoothness;
}

std::vector<std::pair<int, int>> region_adjacency(const Image& region_labels, int regions) {
  if (region_labels.channels() != 1)
    throw Error(ErrorCode::invalid_argument, "region_adjacency: labels must have 1 channel, have " +
                                                 std::to_string(region_labels.channels()));
  if (regions < 0)
    throw Error(ErrorCode::invalid_argument,
                "region_adjacency: regions must be >= 0, got " + std::to_string(regions));
  const int w = region_labels.width(), h = region_labels.height();
  std::vector<int> labels(region_labels.pixel_count());
  for (std::size_t i = 0; i < labels.size(); ++i) {
    const float v = region_labels.data()[i];
    if (!(v >= 0 && v <= float(regions)) || v != std::floor(v))
      throw Error(ErrorCode::invalid_argument,
                  "region_adjacency: label " + std::to_string(v) + " at pixel (" +
                      std::to_string(i % w) + ", " + std::to_string(i / w) +
                      ") is not an integer in 0.." + std::to_string(regions));
    labels[i] = int(v);
  }
  std::set<std::pair<int, int>> touching;
  auto mark = [&](int a, int b) {
    if (a != 0 && b != 0 && a != b) touching.emplace(std::min(a, b) - 1, std::max(a, b) - 1);
  };
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int a = labels[std::size_t(y) * w + x];
      if (x + 1 < w) mark(a, labels[std::size_t(y) * w + x + 1]);
      if (y + 1 < h) mark(a, labels[std::size_t(y + 1) * w + x]);
    }
  std::vector<std::pair<int, int>> pairs(touching.begin(), touching.end());
  return pairs;
}

}  // namespace mr::photo
