// Private to libmr: the objective the Tabu search minimises (seed 002 section 4.3.2):
//   f(x) = E(S, V(x)) + w * sum_i |grad k_i|^2,  grad k_i = sum_{j in N(i)} (k(x_i) - k(x_j)),
// E the style distance between the sample S and the synthesized target V(x) (regions rendered with
// the assigned candidates; statistics precomputed per region and candidate and summed), k the
// candidate's parameter vector (diffuse albedo RGB, specular albedo, roughness).
#pragma once
#include <span>
#include <utility>
#include <vector>
#include "mr/material_model.h"
#include "photo/material/style.h"

namespace mr::photo {

class MaterialObjective {
 public:
  /// region_stats[r][c]: statistics of region r rendered with candidate c. adjacency: pairs of
  /// neighbouring regions (i < j). Throws mr::Error(invalid_argument) on inconsistent sizes.
  MaterialObjective(StyleStatistics sample, std::vector<std::vector<StyleStatistics>> region_stats,
                    std::vector<Material> candidates, std::vector<std::pair<int, int>> adjacency,
                    double smoothness_weight, StyleWeights weights = {});
  double operator()(std::span<const int> assignment) const;
  int regions() const;
  int candidates() const;

 private:
  StyleStatistics sample_;
  std::vector<std::vector<StyleStatistics>> region_stats_;
  std::vector<Material> candidates_;
  std::vector<std::pair<int, int>> adjacency_;
  double smoothness_weight_;
  StyleWeights weights_;
};

/// Pairs (i < j) of regions of a label image (0 = none, 1..n) whose pixels touch (4-neighbours),
/// as 0-based region indices (label - 1, the indexing of MaterialObjective), sorted. Throws
/// mr::Error(invalid_argument) for a label that is not an integer in 0..regions.
std::vector<std::pair<int, int>> region_adjacency(const Image& region_labels, int regions);

}  // namespace mr::photo
