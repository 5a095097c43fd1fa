// Private to libmr: Tabu search over assignments of m values (candidate materials) to n variables
// (target regions), seed 002 section 4.3.3: the neighbourhood of an assignment is every
// assignment differing in one variable; the best non-tabu neighbour is taken each iteration
// (a tabu move is taken when it beats the best so far: aspiration); the variable just changed
// stays tabu for `tenure` iterations, and an assignment already visited is not stepped on again
// while another move exists (breaks the cycles a short tenure lets through); the search stops after
// max_iterations (all starts together) or `patience` iterations without a new best.
// Deterministic for a seed.
#pragma once
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

namespace mr::photo {

struct TabuOptions {
  int max_iterations = 200;
  int patience = 40;
  int tenure = 0;  ///< 0: from n (about n / 3, at least 1)
  int restarts = 0;  ///< extra random starts after patience runs out (the best overall is kept)
  std::uint32_t seed = 1;
};

struct TabuResult {
  std::vector<int> assignment;
  double objective = 0;
  std::vector<double> best_history;  ///< best-so-far: [0] the start, then after each iteration
                                     ///< (never increases)
  long evaluations = 0;
  bool exhaustive = false;  ///< every assignment was evaluated (minimise_assignment)
};

using AssignmentObjective = std::function<double(std::span<const int> assignment)>;

/// Minimises `objective` over assignments in {0..values-1}^variables. Throws
/// mr::Error(invalid_argument) for variables < 1 or values < 1.
TabuResult tabu_search(int variables, int values, const AssignmentObjective& objective,
                       const TabuOptions& options = {});

/// Exhaustive minimum (for tests and tiny instances; values^variables evaluations).
TabuResult brute_force_search(int variables, int values, const AssignmentObjective& objective);

/// The assignment search of a material transfer: every assignment (brute_force_search, the
/// global minimum, `exhaustive` set) when there are at most exhaustive_limit of them, else
/// tabu_search. A photo's few painted regions and candidates (4 regions of 8: 4096) cost
/// milliseconds to enumerate, and Tabu search's local minimum could jump to another assignment
/// when a region changed by a few pixels. best_history of an exhaustive search: the first
/// assignment's objective, then each new best (never increases, ends at `objective`).
TabuResult minimise_assignment(int variables, int values, const AssignmentObjective& objective,
                               const TabuOptions& options = {}, double exhaustive_limit = 65536);

}  // namespace mr::photo
